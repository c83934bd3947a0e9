//! Shared contact scenes.
#![allow(dead_code)]
use nalgebra::Vector3;
use ukemi_engine::{
    BodySpec, ContactModel, GeomSpec, JointKind, JointSpec, Model, ModelBuilder, Shape,
    SolveStatus, State, Workspace, contact, step,
};

/// Floor plane through the origin (normal +z), friction `mu`.
pub fn floor(b: ModelBuilder, mu: f64) -> ModelBuilder {
    b.geom(GeomSpec::new("floor", "world", Shape::Plane).friction(mu))
}

/// A free body with one geom, COM at the body origin.
#[allow(clippy::too_many_arguments)]
pub fn free_body(
    b: ModelBuilder,
    name: &str,
    mass: f64,
    shape: Shape,
    pos: [f64; 3],
    quat: [f64; 4],
    mu: f64,
    model: ContactModel,
) -> ModelBuilder {
    let inertia = match &shape {
        Shape::Sphere { radius } => [0.4 * mass * radius * radius; 3],
        Shape::Box { half_extents: e } => {
            let (x, y, z) = (4.0 * e[0] * e[0], 4.0 * e[1] * e[1], 4.0 * e[2] * e[2]);
            [
                mass * (y + z) / 12.0,
                mass * (x + z) / 12.0,
                mass * (x + y) / 12.0,
            ]
        }
        Shape::Capsule {
            radius,
            half_length,
        } => {
            let (r, l) = (*radius, 2.0 * half_length);
            let side = mass * (3.0 * r * r + l * l) / 12.0 + mass * r * r * 0.25;
            [side, side, 0.5 * mass * r * r]
        }
        _ => [0.1 * mass; 3],
    };
    b.body(BodySpec::new(name, mass, inertia).pos(pos).quat(quat))
        .joint(JointSpec::new(
            &format!("{name}_free"),
            JointKind::Floating,
            "world",
            name,
        ))
        .geom(
            GeomSpec::new(&format!("{name}_geom"), name, shape)
                .friction(mu)
                .model(Some(model)),
        )
}

/// Summary of a run.
#[derive(Debug, Default)]
pub struct Run {
    pub min_distance: f64,
    /// Most iterations of one solve: a step taken as `n` sub-steps (a fast turn, a failed
    /// whole solve) counts its iterations over `n`.
    pub max_iterations: usize,
    pub mean_iterations: f64,
    pub final_speed: f64,
}

/// Step `n` times; every step must converge; track the least signed distance.
pub fn run(model: &Model, state: &mut State, n: usize) -> Run {
    let mut ws = Workspace::new(model);
    let mut out = Run {
        min_distance: f64::INFINITY,
        ..Default::default()
    };
    let mut total = 0;
    for _ in 0..n {
        let r = step(model, state, &mut ws, &vec![0.0; model.nu()]).unwrap();
        assert_eq!(
            r.status,
            SolveStatus::Converged,
            "t = {}: {r:?}",
            state.time
        );
        let per_solve = r.iterations.div_ceil(r.subdivisions as usize);
        out.max_iterations = out.max_iterations.max(per_solve);
        total += r.iterations;
        let d = contact::signed_distances(model, state);
        out.min_distance = d.iter().copied().fold(out.min_distance, f64::min);
    }
    out.mean_iterations = total as f64 / n as f64;
    out.final_speed = (1..model.nbody())
        .map(|b| {
            let (v, w) = state.velocity(b);
            v.norm().max(w.norm())
        })
        .fold(0.0, f64::max);
    out
}

/// Speed of body `b`'s COM.
pub fn speed(state: &State, b: usize) -> f64 {
    state.velocity(b).0.norm()
}

pub fn quat_about(axis: [f64; 3], angle: f64) -> [f64; 4] {
    let a = Vector3::from(axis).normalize();
    let (s, c) = (0.5 * angle).sin_cos();
    [c, s * a[0], s * a[1], s * a[2]]
}
