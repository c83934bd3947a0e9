//! A step that fails every attempt with `drop_redundant_friction`'s shortcuts converges on the
//! exact problem, which `step` and the gradients' forward pass solve last of all.
#[allow(dead_code)]
#[path = "../examples/common/workload.rs"]
mod workload;
use ukemi_engine::{Coordinates, Linearization, Workspace, Wrt, step};

/// The shared humanoid under `step_bench` seed 13's controls, its step 127 from the exact
/// state: the right knee at its limit, the foot folded against the thigh. Its whole solve,
/// sub-steps and long solves all failed (~1100 iterations) with the separated-friction holds
/// of the first attempt; without them it converges (~200 iterations).
#[test]
fn a_folded_leg_step_converges() {
    let Some(model) = workload::shared("humanoid") else {
        return;
    };
    let mut state = workload::start_state(&model);
    let mut ws = Workspace::new(&model);
    let mut controls = workload::Controls::with_seed(13);
    for _ in 0..127 {
        let u = controls.next(&model);
        let report = step(&model, &mut state, &mut ws, &u).unwrap();
        assert!(report.status.is_success());
    }
    let u = controls.next(&model);
    // the gradients' forward pass decides the same way
    let mut lin = Linearization::new(
        &model,
        &state,
        &u,
        Coordinates::Maximal,
        Wrt::STATE_CTRL,
        None,
    )
    .unwrap();
    let jac = lin.jacobians(&model).unwrap();
    assert!(jac.a.iter().chain(jac.b.iter()).all(|x| x.is_finite()));
    let report = step(&model, &mut state, &mut ws, &u).unwrap();
    assert!(report.status.is_success(), "{report:?}");
    // the same root both ways
    let (p, q) = (lin.next_state().pose(1).pos, state.pose(1).pos);
    assert!((p - q).norm() < 1e-9, "{p:?} vs {q:?}");
    // a contact step: nothing sinks
    let deepest = ukemi_engine::contact::signed_distances(&model, &state)
        .into_iter()
        .fold(f64::INFINITY, f64::min);
    assert!(deepest > -1e-8, "penetration {deepest:e} m");
}
