//! Joint limits as inequality constraints: a pendulum swung into its limit holds it and releases
//! when pushed away.
#[path = "common/contact.rs"]
mod common;
use ukemi_engine::{
    ActuatorSpec, BodySpec, JointKind, JointSpec, ModelBuilder, SolveStatus, State, Workspace,
    qpos, set_minimal, step,
};

#[test]
fn limit_holds_and_releases() {
    let mut j = JointSpec::new("hinge", JointKind::Revolute, "world", "bob")
        .axis([0.0, 1.0, 0.0])
        .anchors([0.0; 3], [0.0, 0.0, 1.0]);
    j.range = Some(vec![(-0.5, 0.5)]);
    let model = ModelBuilder::new()
        .timestep(0.01)
        .body(BodySpec::new("bob", 1.0, [1e-3; 3]).pos([0.0, 0.0, -1.0]))
        .joint(j)
        .actuator(ActuatorSpec::motor("m", "hinge", 0, 1.0))
        .compile()
        .unwrap();
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
