//! Steps that fail every ordinary attempt and converge through a step's last resorts
//! (`step::long_solve`, then the exact problem without `drop_redundant_friction`'s shortcuts,
//! then the step from the start rebuilt from its minimal coordinates, then the pyramid friction
//! cones), and a first attempt retried with the gentle warm-start widening.
#[path = "common/fixtures.rs"]
mod fixtures;
#[allow(dead_code)]
#[path = "../examples/common/workload.rs"]
mod workload;
use fixtures::fixture;
use ukemi_engine::{
    Coordinates, Linearization, Model, State, Workspace, Wrt, qpos, qvel, set_minimal, step,
};

/// `model` with the options of the sessions that found these steps (`warm_start_widening`
/// 1e-3, and no widening relative to the weight: session 31's `warm_start_widening_weight`).
fn as_found(model: &Model) -> Model {
    model
        .with_options(ukemi_engine::Options {
            warm_start_widening: 1e-3,
            warm_start_widening_weight: 0.0,
            ..model.options.clone()
        })
        .unwrap()
}

/// The step's exact (`kappa_grad = None`) linearisation in maximal coordinates: its forward
/// pass takes the same decisions as `step` from the same start.
fn exact_linearization(
    model: &Model,
    start: &State,
    u: &[f64],
) -> ukemi_engine::Result<Linearization> {
    Linearization::new(model, start, u, Coordinates::Maximal, Wrt::STATE_CTRL, None)
}

/// `model` without the pyramid friction cones' last resort (`Options::pyramid_fallback`).
fn pyramid_off(model: &Model) -> Model {
    model
        .with_options(ukemi_engine::Options {
            pyramid_fallback: false,
            ..model.options.clone()
        })
        .unwrap()
}

/// `state` rebuilt from its minimal coordinates (what `rollout_vjp` and the JAX layer step
/// from).
fn rebuilt(model: &Model, state: &State) -> State {
    let mut out = state.clone();
    set_minimal(model, &mut out, &qpos(model, state), &qvel(model, state)).unwrap();
    out
}

/// Whether no contact of `state` sinks.
fn assert_no_penetration(model: &Model, state: &State) {
    let deepest = ukemi_engine::contact::signed_distances(model, state)
        .into_iter()
        .fold(f64::INFINITY, f64::min);
    assert!(deepest > -1e-8, "penetration {deepest:e} m");
}

/// Seed 2's step 143, taken from the state rebuilt from its minimal coordinates (what
/// `rollout_vjp` and the JAX layer step from): the left lower arm wedged between the waist
/// and the floor, the right one on the left shin, five contacts at gaps ~1e-12 m. Before the
/// all-active last resort, every attempt crawled at step lengths ~1e-3 (~1350 iterations) and
/// the step failed; with every candidate active from the start it converges in ~20 iterations.
#[test]
fn a_wedged_humanoid_step_converges() {
    let Some((model, state, u)) = fixture("humanoid_seed2_step143") else {
        return;
    };
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
    let mut rebuilt = rebuilt(&model, &state);
    let report = step(&model, &mut rebuilt, &mut Workspace::new(&model), &u).unwrap();
    assert!(report.status.is_success(), "{report:?}");
    assert_no_penetration(&model, &rebuilt);
}

/// Seed 13's step 127 from the exact state: the right knee at its limit, the foot folded
/// against the thigh. Its whole solve, sub-steps and long solves all failed (~1100
/// iterations) with the separated-friction holds of the first attempt. It converges from the
/// impulses of the step with pyramid friction cones (the last resort tried next), and, with
/// that off (`pyramid_fallback`), on the exact problem without the holds (~200 iterations).
/// Either way the gradients' forward pass decides the same way.
#[test]
fn a_folded_leg_step_converges() {
    let Some((model, start, u)) = fixture("humanoid_seed13_step127") else {
        return;
    };
    let off = pyramid_off(&model);
    for model in [model, off] {
        let mut lin = exact_linearization(&model, &start, &u).unwrap();
        let jac = lin.jacobians(&model).unwrap();
        assert!(jac.a.iter().chain(jac.b.iter()).all(|x| x.is_finite()));
        let mut state = start.clone();
        let report = step(&model, &mut state, &mut Workspace::new(&model), &u).unwrap();
        assert!(report.status.is_success(), "{report:?}");
        // the same root both ways
        let (p, q) = (lin.next_state().pose(1).pos, state.pose(1).pos);
        assert!((p - q).norm() < 1e-9, "{p:?} vs {q:?}");
        assert_no_penetration(&model, &state);
    }
}

/// Seed 97's step 53 from the exact state, with the warm-start widening it was found with
/// (1e-3; the default 1e-2 converges it at once): every attempt on every problem jams (a
/// residual ~5e-6 with the barrier parameter stuck at ~6e-6, step lengths ~1e-3; ~2800
/// iterations), while the same step from the state rebuilt from its minimal coordinates
/// converges. The step's last resort takes it from there, so it lands where a step from the
/// rebuilt state lands.
#[test]
fn a_jammed_exact_start_is_stepped_from_its_rebuilt_state() {
    let Some((model, mut state, u)) = fixture("humanoid_seed97_step53") else {
        return;
    };
    let model = as_found(&model);
    let mut rebuilt = rebuilt(&model, &state);
    let report = step(&model, &mut state, &mut Workspace::new(&model), &u).unwrap();
    assert!(report.status.is_success(), "{report:?}");
    assert_no_penetration(&model, &state);
    step(&model, &mut rebuilt, &mut Workspace::new(&model), &u).unwrap();
    for b in 1..model.nbody() {
        let (p, q) = (state.pose(b).pos, rebuilt.pose(b).pos);
        assert!((p - q).norm() < 1e-9, "body {b}: {p:?} vs {q:?}");
    }
}

/// Seed 2's step 143 from the exact state (the wedged limb above, before any rebuild): its
/// warm start widened by the default widening (1e-2 when this was found; 0.40 N·s, the
/// weight-relative one, since session 31) fails every attempt (~5600 iterations through the
/// last resorts), widened by the gentle 1e-3 it converges in 18 iterations. The first attempt
/// is retried so before anything else.
#[test]
fn a_wedged_limb_retries_its_first_attempt_widened_gently() {
    let Some((model, mut state, u)) = fixture("humanoid_seed2_step143") else {
        return;
    };
    let report = step(&model, &mut state, &mut Workspace::new(&model), &u).unwrap();
    assert!(report.status.is_success(), "{report:?}");
    assert!(report.iterations < 500, "{report:?}");
    assert_eq!(report.subdivisions, 1, "{report:?}");
    assert_no_penetration(&model, &state);
}

/// Steps of the humanoid under the default options (found in session 32; a solver change moves
/// a chaotic trajectory's later states) that jam the exact cones from the previous step's
/// impulses on every attempt, and converge with the exact cones warm-started from the impulses
/// of the step with pyramid friction cones: `step` reports them `Converged`, no contact sinks,
/// `step_jacobians` takes the same decisions and lands on the same root, and the exact cones
/// take the steps after it.
fn jammed_step_converges_from_the_pyramids_impulses(seed: u64, at: usize) {
    let Some((model, start, u)) = fixture(&format!("humanoid_seed{seed}_step{at}")) else {
        return;
    };
    use ukemi_engine::SolveStatus;
    // the jam: without the pyramid the step fails (should this start converging, the solver has
    // outgrown this state: find another with `step_bench humanoid.xml 1000 1 SEED` and keep
    // it with `snapshot_step`)
    let off = pyramid_off(&model);
    let mut failed = start.clone();
    let report = step(&off, &mut failed, &mut Workspace::new(&off), &u).unwrap();
    assert!(!report.status.is_success(), "{report:?}");
    let mut state = start.clone();
    let mut ws = Workspace::new(&model);
    let report = step(&model, &mut state, &mut ws, &u).unwrap();
    assert_eq!(report.status, SolveStatus::Converged, "{report:?}");
    assert_no_penetration(&model, &state);
    // the gradients' forward pass decides the same way
    let lin = exact_linearization(&model, &start, &u).unwrap();
    let (p, q) = (lin.next_state().pose(1).pos, state.pose(1).pos);
    assert!((p - q).norm() < 1e-9, "{p:?} vs {q:?}");
    // and the exact cones take the steps after it
    let mut controls = workload::Controls::with_seed(seed);
    let ctrls: Vec<Vec<f64>> = (0..at + 12).map(|_| controls.next(&model)).collect();
    for (k, u) in ctrls.iter().enumerate().skip(at + 1) {
        let r = step(&model, &mut state, &mut ws, u).unwrap();
        assert!(r.status.is_success(), "step {k}: {r:?}");
        assert_no_penetration(&model, &state);
    }
}

/// Seed 155's step 188: the legs crossed, the right shin pressed on the left thigh, the right
/// foot sliding. The exact cones jam (~3100 iterations: residual ~1e-6, complementarity ~2e-4,
/// step lengths ~1e-3); the pyramid converges (~20 iterations), and from its impulses the exact
/// cones (~10).
#[test]
fn a_jammed_step_converges_from_the_pyramids_impulses() {
    jammed_step_converges_from_the_pyramids_impulses(155, 188);
}

/// Seed 21's step 591 (found in session 34, when seed 253's step 845 of session 32 no longer
/// jammed: the coupling elimination order moved the trajectory): the pyramid jams too, and from
/// its last iterate's impulses the exact cones converge (2849 iterations in all).
#[test]
fn a_step_that_jams_the_pyramid_too_converges_from_its_last_iterate() {
    jammed_step_converges_from_the_pyramids_impulses(21, 591);
}

/// The shared Panda's seed-371 step 159 under the default options (found in session 32): both
/// fingers' pads on the floor (penetrations ~1e-12 m) and 0.55 mm from each other, ~300
/// candidates active. The exact cones fail every attempt, from the pyramid's impulses too,
/// while the pyramid converges (131 iterations taken whole): the step is the pyramid's, status
/// `PyramidFriction`: a valid state (no contact sinks, every impulse inside its exact cone, the
/// steps after it converge) without gradients (`step_jacobians` reports it unconverged).
#[test]
fn a_step_the_exact_cones_cannot_take_is_the_pyramids() {
    let Some((model, start, u)) = fixture("panda_seed371_step159") else {
        return;
    };
    use ukemi_engine::SolveStatus;
    let mut state = start.clone();
    let mut ws = Workspace::new(&model);
    let report = step(&model, &mut state, &mut ws, &u).unwrap();
    assert_eq!(report.status, SolveStatus::PyramidFriction, "{report:?}");
    assert!(report.status.is_success());
    assert_no_penetration(&model, &state);
    for (c, f) in state.contact_impulse(&model).chunks(3).enumerate() {
        let mu = model.contacts[c].friction;
        let tangential = (f[1] * f[1] + f[2] * f[2]).sqrt();
        assert!(
            f[0] >= 0.0 && tangential <= mu * f[0] * (1.0 + 1e-9),
            "candidate {c}: {f:?}"
        );
    }
    let lin = exact_linearization(&model, &start, &u);
    assert!(lin.is_err(), "no gradients through the pyramid's step");
    let mut controls = workload::Controls::with_seed(371);
    let ctrls: Vec<Vec<f64>> = (0..170).map(|_| controls.next(&model)).collect();
    for (k, u) in ctrls.iter().enumerate().skip(160) {
        let r = step(&model, &mut state, &mut ws, u).unwrap();
        assert!(r.status.is_success(), "step {k}: {r:?}");
        assert_no_penetration(&model, &state);
    }
}
