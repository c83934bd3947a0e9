//! Coulomb friction with the exact cone: a box launched at 30° to the axes slides in a straight
//! line and stops at v0²/(2μg); the pyramid drifts (size documented); on an incline the box
//! slides with g(sin θ - μ cos θ) above the friction angle and sticks below it.
#[path = "common/contact.rs"]
mod common;
use common::*;
use nalgebra::Vector3;
use ukemi_engine::{ContactModel, GeomSpec, ModelBuilder, Shape, State};

fn slide(model_kind: ContactModel, h: f64) -> (f64, f64, f64) {
    let (mu, v0) = (0.5, 1.0);
    let b = ModelBuilder::new().timestep(h).geom(
        GeomSpec::new("floor", "world", Shape::Plane)
            .friction(mu)
            .model(Some(model_kind)),
    );
    let half = Vector3::new(0.1, 0.1, 0.05);
    let model = free_body(
        b,
        "box",
        1.0,
        Shape::Box { half_extents: half },
        [0.0, 0.0, 0.05],
        [1.0, 0.0, 0.0, 0.0],
        mu,
        model_kind,
    )
    .compile()
    .unwrap();
    let mut state = State::reference(&model);
    let dir = Vector3::new(30f64.to_radians().cos(), 30f64.to_radians().sin(), 0.0);
    state.set_velocity(1, &(dir * v0), &Vector3::zeros());
    let start = state.pose(1).pos;
    let r = run(&model, &mut state, (0.5 / h) as usize);
    let d = state.pose(1).pos - start;
    let along = d.dot(&dir);
    let lateral = (d - dir * along).xy().norm();
    eprintln!(
        "{model_kind:?} h {h}: distance {along:.6} (analytic {:.6}), lateral {lateral:.2e} m, iterations mean {:.1} max {}",
        v0 * v0 / (2.0 * mu * 9.81),
        r.mean_iterations,
        r.max_iterations
    );
    (along, lateral, v0 * v0 / (2.0 * mu * 9.81))
}

#[test]
fn nonlinear_cone_slides_straight_and_stops_at_v0_squared_over_2_mu_g() {
    let (along, lateral, analytic) = slide(ContactModel::Nonlinear, 0.001);
    assert!(lateral < 1e-6, "lateral deviation {lateral:.3e} m");
    assert!(
        (along - analytic).abs() / analytic < 0.01,
        "stopping distance {along} vs {analytic}"
    );
}

#[test]
fn linearized_cone_drifts_sideways() {
    // The 4-sided pyramid's friction is not opposite the velocity except along its edges or
    // faces: launched at 30° the box curves towards the nearest pyramid direction.
    let (_, lateral_linear, _) = slide(ContactModel::Linear, 0.001);
    let (_, lateral_exact, _) = slide(ContactModel::Nonlinear, 0.001);
    eprintln!("lateral drift: pyramid {lateral_linear:.3e} m, exact cone {lateral_exact:.3e} m");
    assert!(
        lateral_linear > 1e-3,
        "the pyramid should drift by millimetres, got {lateral_linear:.3e}"
    );
    assert!(lateral_linear > 1e3 * lateral_exact.max(1e-12));
}

fn incline(theta_deg: f64, mu: f64, h: f64, steps: usize) -> (f64, f64) {
    let theta = theta_deg.to_radians();
    let q = quat_about([1.0, 0.0, 0.0], theta); // plane normal tilted about x: slope along -y
    let b = ModelBuilder::new()
        .timestep(h)
        .gravity([0.0, 0.0, -9.81])
        .geom(
            GeomSpec::new("ramp", "world", Shape::Plane)
                .quat(q)
                .friction(mu),
        );
    let half = Vector3::new(0.1, 0.1, 0.05);
    let n = Vector3::new(0.0, -theta.sin(), theta.cos());
    let pos = n * 0.05;
    let model = free_body(
        b,
        "box",
        1.0,
        Shape::Box { half_extents: half },
        pos.into(),
        q,
        mu,
        ContactModel::Nonlinear,
    )
    .compile()
    .unwrap();
    let mut state = State::reference(&model);
    // settle onto the ramp for a few steps, then measure
    let _ = run(&model, &mut state, 5);
    let (p0, t0) = (state.pose(1).pos, state.time);
    let v0 = state.velocity(1).0;
    let r = run(&model, &mut state, steps);
    let t = state.time - t0;
    let down = Vector3::new(0.0, -theta.cos(), -theta.sin());
    let s = (state.pose(1).pos - p0).dot(&down);
    // s = v0·t + a t²/2  → a
    let a = 2.0 * (s - v0.dot(&down) * t) / (t * t);
    eprintln!(
        "incline {theta_deg}° μ {mu}: displacement {s:.3e} m, acceleration {a:.5}, iterations max {}",
        r.max_iterations
    );
    (a, s)
}

#[test]
fn box_slides_down_a_steep_incline_with_analytic_acceleration() {
    let (theta, mu) = (30.0f64, 0.3);
    let (a, _) = incline(theta, mu, 0.001, 1000);
    let expected = 9.81 * (theta.to_radians().sin() - mu * theta.to_radians().cos());
    assert!(
        (a - expected).abs() / expected < 0.01,
        "acceleration {a} vs {expected}"
    );
}

#[test]
fn box_sticks_below_the_friction_angle() {
    let (_, s) = incline(30.0, 0.8, 0.01, 1000);
    assert!(s.abs() < 1e-9, "moved {s:.3e} m over 1000 steps");
}
