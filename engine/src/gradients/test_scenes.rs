//! Scenes and comparisons shared by the unit tests (the gradients', the solver's, the step's).
use crate::{
    ActuatorSpec, BodySpec, GeomSpec, JointKind, JointSpec, Model, ModelBuilder, Shape, State,
    Workspace,
};

/// A 1 kg box (10 cm) settled on the floor (μ = 0.5), pushed along x by a motor on its free
/// joint: under [`push`] it sticks, slides and stops again.
pub(crate) fn pushed_box() -> (Model, State) {
    let half = nalgebra::Vector3::new(0.05, 0.05, 0.05);
    let m = ModelBuilder::new()
        .timestep(0.01)
        .geom(GeomSpec::new("floor", "world", Shape::Plane).friction(0.5))
        .body(BodySpec::new("box", 1.0, [1.0 / 600.0; 3]).pos([0.0, 0.0, 0.05]))
        .joint(JointSpec::new("free", JointKind::Floating, "world", "box"))
        .geom(GeomSpec::new("box", "box", Shape::Box { half_extents: half }).friction(0.5))
        .actuator(ActuatorSpec::motor("push", "free", 0, 1.0))
        .compile()
        .unwrap();
    let mut s = State::reference(&m);
    let mut ws = Workspace::new(&m);
    for _ in 0..20 {
        crate::step(&m, &mut s, &mut ws, &[0.0]).unwrap();
    }
    (m, s)
}

/// A 1 kg box of half-size 0.1 m resting on the floor, friction `mu` on both, time step `h`
/// (its candidates the default, exact friction cones).
pub(crate) fn box_on_floor(h: f64, mu: f64) -> Model {
    let half = nalgebra::Vector3::new(0.1, 0.1, 0.1);
    ModelBuilder::new()
        .timestep(h)
        .geom(GeomSpec::new("floor", "world", Shape::Plane).friction(mu))
        .body(BodySpec::new("box", 1.0, [0.1, 0.1, 0.1]).pos([0.0, 0.0, 0.1]))
        .joint(JointSpec::new("free", JointKind::Floating, "world", "box"))
        .geom(GeomSpec::new("box", "box", Shape::Box { half_extents: half }).friction(mu))
        .compile()
        .unwrap()
}

/// The push at step `k` (N).
pub(crate) fn push(k: usize) -> f64 {
    8.0 * (k as f64 * 0.3).sin()
}

/// `(max |a - b|, max(1, max |b|))`.
pub(crate) fn max_diff(a: &[f64], b: &[f64]) -> (f64, f64) {
    let scale = b.iter().fold(1.0f64, |m, v| m.max(v.abs()));
    let diff = a
        .iter()
        .zip(b)
        .fold(0.0f64, |m, (p, q)| m.max((p - q).abs()));
    (diff, scale)
}
