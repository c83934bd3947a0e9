//! A step whose every warm and cold attempt, wider activation and sub-step fail still has a
//! last resort that converges: the whole step with every contact candidate active from its
//! first attempt (`step::long_solve`).
#[allow(dead_code)]
#[path = "../examples/common/workload.rs"]
mod workload;
use ukemi_engine::{Coordinates, Linearization, Workspace, Wrt, qpos, qvel, set_minimal, step};

/// The shared humanoid under `step_bench` seed 2's controls, its step 143 taken from the state
/// rebuilt from its minimal coordinates (what `rollout_vjp` and the JAX layer step from): the
/// left lower arm wedged between the waist and the floor, the right one on the left shin, five
/// contacts at gaps ~1e-12 m. Before the all-active last resort, every attempt crawled at step
/// lengths ~1e-3 (~1350 iterations) and the step failed; with every candidate active from the
/// start it converges in ~20 iterations.
#[test]
fn a_wedged_humanoid_step_converges() {
    let Some(model) = workload::shared("humanoid") else {
        return;
    };
    let mut state = workload::start_state(&model);
    let mut ws = Workspace::new(&model);
    let mut controls = workload::Controls::with_seed(2);
    for _ in 0..143 {
        let u = controls.next(&model);
        let report = step(&model, &mut state, &mut ws, &u).unwrap();
        assert!(report.status.is_success());
    }
    let u = controls.next(&model);
    // its Jacobians (minimal coordinates rebuild the same start and solve it the same way)
    let mut lin = Linearization::new(
        &model,
        &state,
        &u,
        Coordinates::Minimal,
        Wrt::STATE_CTRL,
        Some(1e-4),
    )
    .unwrap();
    let jac = lin.jacobians(&model).unwrap();
    assert!(jac.a.iter().chain(jac.b.iter()).all(|x| x.is_finite()));
    let mut rebuilt = state.clone();
    set_minimal(
        &model,
        &mut rebuilt,
        &qpos(&model, &state),
        &qvel(&model, &state),
    )
    .unwrap();
    let report = step(&model, &mut rebuilt, &mut Workspace::new(&model), &u).unwrap();
    assert!(report.status.is_success(), "{report:?}");
    // a contact step: nothing sinks
    let deepest = ukemi_engine::contact::signed_distances(&model, &rebuilt)
        .into_iter()
        .fold(f64::INFINITY, f64::min);
    assert!(deepest > -1e-8, "penetration {deepest:e} m");
}
