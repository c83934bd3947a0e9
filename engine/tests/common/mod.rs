//! Small mechanisms shared by the scenario tests.
#![allow(dead_code)]
use ukemi_engine::joints::geometry::{JointFrame, Pose};
use ukemi_engine::{
    BodySpec, JointKind, JointSpec, Model, ModelBuilder, State, Workspace, mechanics, step,
};

/// A point-like bob of mass 1 on a massless rod of length `len`, hinge about y at the origin.
pub fn pendulum(len: f64, h: f64) -> Model {
    ModelBuilder::new()
        .timestep(h)
        .body(BodySpec::new("bob", 1.0, [1e-6, 1e-6, 1e-6]).pos([0.0, 0.0, -len]))
        .joint(
            JointSpec::new("hinge", JointKind::Revolute, "world", "bob")
                .axis([0.0, 1.0, 0.0])
                .anchors([0.0; 3], [0.0, 0.0, len]),
        )
        .compile()
        .unwrap()
}

/// `n` uniform rods (mass 1, length 1) hanging in a chain along -z, hinges about y.
pub fn chain(n: usize, h: f64) -> Model {
    let mut b = ModelBuilder::new().timestep(h);
    let rod = 1.0 / 12.0;
    for i in 0..n {
        let name = format!("link{i}");
        b = b.body(BodySpec::new(&name, 1.0, [rod, rod, 1e-3]).pos([0.0, 0.0, -(i as f64) - 0.5]));
        let parent = if i == 0 {
            "world".to_string()
        } else {
            format!("link{}", i - 1)
        };
        let pa = if i == 0 { [0.0; 3] } else { [0.0, 0.0, -0.5] };
        b = b.joint(
            JointSpec::new(&format!("j{i}"), JointKind::Revolute, &parent, &name)
                .axis([0.0, 1.0, 0.0])
                .anchors(pa, [0.0, 0.0, 0.5]),
        );
    }
    b.compile().unwrap()
}

/// Max |constraint| over all joints of `state`.
pub fn constraint_violation(model: &Model, state: &State) -> f64 {
    let pose = |b: usize| if b == 0 { Pose::world() } else { state.pose(b) };
    let mut worst = 0.0f64;
    for j in &model.joints {
        let mut k = vec![0.0; j.ncon()];
        JointFrame::new(j, &pose(j.parent), &pose(j.child)).constraint(j, &mut k);
        worst = k.iter().fold(worst, |m, x| m.max(x.abs()));
    }
    worst
}

/// Total mechanical energy (kinetic of the midpoint velocities + gravity).
pub fn energy(model: &Model, state: &State) -> f64 {
    mechanics::total_energy(model, state)
}

/// Step once and insist on convergence.
pub fn step_ok(model: &Model, state: &mut State, ws: &mut Workspace, ctrl: &[f64]) {
    let r = step(model, state, ws, ctrl).unwrap();
    assert_eq!(
        r.status,
        ukemi_engine::SolveStatus::Converged,
        "step at t = {}: {r:?}",
        state.time
    );
}

/// Times at which `x` crosses zero upwards, linearly interpolated.
pub fn upward_crossings(t: &[f64], x: &[f64]) -> Vec<f64> {
    let mut out = Vec::new();
    for i in 1..x.len() {
        if x[i - 1] < 0.0 && x[i] >= 0.0 {
            out.push(t[i - 1] + (t[i] - t[i - 1]) * (-x[i - 1]) / (x[i] - x[i - 1]));
        }
    }
    out
}
