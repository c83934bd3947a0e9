//! Joint limits as inequality constraints: a pendulum swung into its limit holds it and releases
//! when pushed away.
#[path = "common/contact.rs"]
mod common;
use ukemi_engine::{
    ActuatorSpec, BodySpec, JointKind, JointSpec, Model, ModelBuilder, SolveStatus, State,
    Workspace, qpos, set_minimal, step,
};

#[test]
fn limit_holds_and_releases() {
    let model = limited_pendulum(-0.5, 0.5, |_| {});
    assert_eq!(model.variable_counts()[2], ("joint_limit", 4));
    let mut state = State::reference(&model);
    set_minimal(&model, &mut state, &[0.3], &[3.0]).unwrap();
    let mut ws = Workspace::new(&model);
    let (mut worst, mut max_it, mut max_angle) = (0.0f64, 0, f64::MIN);
    // push into the upper limit with a constant torque
    for _ in 0..300 {
        let r = step(&model, &mut state, &mut ws, &[5.0]).unwrap();
        assert_eq!(r.status, SolveStatus::Converged, "{r:?}");
        max_it = max_it.max(r.iterations);
        let q = qpos(&model, &state)[0];
        max_angle = max_angle.max(q);
        worst = worst.max(q - 0.5);
    }
    let q = qpos(&model, &state)[0];
    eprintln!("limit: angle {q:.10}, worst violation {worst:.2e}, max iterations {max_it}");
    assert!(worst < 1e-8, "limit violated by {worst:.3e}");
    assert!((q - 0.5).abs() < 1e-6, "should rest on the limit, at {q}");
    // push the other way: it leaves the limit
    for _ in 0..50 {
        step(&model, &mut state, &mut ws, &[-20.0]).unwrap();
    }
    assert!(qpos(&model, &state)[0] < 0.3, "released from the limit");
    assert!(max_it <= 30);
}

/// A pendulum with a motor on a hinge limited to `(lo, hi)`, bob 1 kg at 1 m.
fn limited_pendulum(lo: f64, hi: f64, options: impl FnOnce(&mut ukemi_engine::Options)) -> Model {
    let mut j = JointSpec::new("hinge", JointKind::Revolute, "world", "bob")
        .axis([0.0, 1.0, 0.0])
        .anchors([0.0; 3], [0.0, 0.0, 1.0]);
    j.range = Some(vec![(lo, hi)]);
    let model = ModelBuilder::new()
        .timestep(0.01)
        .body(BodySpec::new("bob", 1.0, [1e-3; 3]).pos([0.0, 0.0, -1.0]))
        .joint(j)
        .actuator(ActuatorSpec::motor("m", "hinge", 0, 1.0))
        .compile()
        .unwrap();
    let mut o = model.options.clone();
    options(&mut o);
    model.with_options(o).unwrap()
}

/// A limit out of the step's reach takes no part in it (no interior-point work, zero impulse),
/// and the trajectory is the one with every limit active, to the solver's tolerance.
#[test]
fn far_limits_take_no_part_and_do_not_change_the_trajectory() {
    let tight = |o: &mut ukemi_engine::Options| {
        o.rtol = 1e-12;
        o.kappa_tol = 1e-13;
    };
    let on = limited_pendulum(-0.8, 0.8, tight);
    let off = limited_pendulum(-0.8, 0.8, |o| {
        tight(o);
        o.activation_margin = f64::INFINITY;
    });
    let (mut s_on, mut s_off) = (State::reference(&on), State::reference(&off));
    let (mut ws_on, mut ws_off) = (Workspace::new(&on), Workspace::new(&off));
    let (mut inactive, mut active, mut worst) = (0, 0, 0.0f64);
    let mut touched = false;
    for k in 0..300 {
        // swings into both limits and back
        let u = [12.0 * (k as f64 * 0.04).sin()];
        let r_on = step(&on, &mut s_on, &mut ws_on, &u).unwrap();
        let r_off = step(&off, &mut s_off, &mut ws_off, &u).unwrap();
        assert_eq!(r_on.status, SolveStatus::Converged, "{r_on:?}");
        assert_eq!(r_off.status, SolveStatus::Converged, "{r_off:?}");
        assert_eq!(ws_off.active_limits(), 1);
        match ws_on.active_limits() {
            0 => {
                inactive += 1;
                // [γ_lo, s_lo, γ_hi, s_hi] (no contacts): no impulse
                assert_eq!([s_on.ineq_vars[0], s_on.ineq_vars[2]], [0.0; 2]);
            }
            _ => active += 1,
        }
        let (q_on, q_off) = (qpos(&on, &s_on)[0], qpos(&off, &s_off)[0]);
        touched |= q_on.abs() > 0.8 - 1e-6;
        worst = worst.max((q_on - q_off).abs());
    }
    eprintln!(
        "limit inactive in {inactive} steps, active in {active}; largest difference {worst:.2e}"
    );
    assert!(touched, "the swing must reach a limit");
    assert!(
        inactive > 50 && active > 20,
        "{inactive} inactive, {active} active"
    );
    assert!(worst < 1e-9, "trajectories differ by {worst:e}");
}

/// A limit the step's reach estimate leaves out is still enforced: at rest 0.15 rad from its
/// bound (beyond the 0.1 rad reach), a 3000 N·m torque closes the distance within one step;
/// the step is solved again with the limit active and ends on the bound.
#[test]
fn a_limit_the_estimate_misses_is_still_enforced() {
    let model = limited_pendulum(-0.5, 0.15, |o| o.gravity = nalgebra::Vector3::zeros());
    let mut state = State::reference(&model);
    let mut ws = Workspace::new(&model);
    let r = step(&model, &mut state, &mut ws, &[3000.0]).unwrap();
    assert_eq!(r.status, SolveStatus::Converged, "{r:?}");
    assert_eq!(
        ws.active_limits(),
        1,
        "the missed limit is re-solved active"
    );
    let q = qpos(&model, &state)[0];
    assert!((q - 0.15).abs() < 1e-8, "angle {q}, bound 0.15");
    assert!(state.ineq_vars[2] > 1.0, "γ_hi {}", state.ineq_vars[2]);
}
