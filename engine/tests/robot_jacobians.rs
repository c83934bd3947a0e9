//! Every step of the Table V workload that solves can be linearised: step Jacobians fail only
//! with the step they belong to. (The Panda's finger pads make the solves that keep an
//! acceptable iterate while retrying; its friction holds must come back with it.)
#[allow(dead_code)]
#[path = "../examples/common/workload.rs"]
mod workload;
use ukemi_engine::{Coordinates, Linearization, Workspace, Wrt, step};

#[test]
fn every_converged_panda_step_has_jacobians() {
    let Some(model) = workload::shared("panda") else {
        return;
    };
    let mut linearised = 0;
    // (`step_bench` seeds; seed 10's step 250 ended an acceptable attempt with a candidate held
    // apart, whose hold the retries had released: a singular Newton matrix at the solution)
    for seed in [1, 3, 4, 10] {
        let mut state = workload::start_state(&model);
        let mut ws = Workspace::new(&model);
        let mut controls = workload::Controls::with_seed(seed);
        for k in 0..300 {
            let u = controls.next(&model);
            let start = state.clone();
            let report = step(&model, &mut state, &mut ws, &u).unwrap();
            if !report.status.is_success() {
                continue;
            }
            // maximal coordinates: the same start as the step, so the same solve
            let lin = Linearization::new(
                &model,
                &start,
                &u,
                Coordinates::Maximal,
                Wrt::STATE_CTRL,
                None,
            );
            assert!(lin.is_ok(), "seed {seed} step {k}: {:?}", lin.err());
            linearised += 1;
        }
    }
    assert!(linearised > 1100, "{linearised} steps linearised");
}
