//! Rolling contact: a ball on a rigid arm, hung from a ball joint above the floor and resting on
//! it, spun about the line from the joint to the contact point, rolls around the joint like a
//! cone on its tip. The line lies inside the friction cone (26.6° from the normal, μ ≥ 0.6), so
//! the contact sticks, nothing dissipates, and the motion is the analytic steady precession.
//!
//! Before the no-slip rows were made rolling-consistent (`engine/src/contact/slip.rs`) this
//! scene jammed: no step of it converged at dt 0.01, 663 of 1000 at dt 0.001 failed, the ball
//! sank 0.26 mm (random stress scene 701 was one such capsule).
#[path = "common/gradients.rs"]
mod grad_check;

use ukemi_engine::{Coordinates, State, Workspace, mjcf, set_minimal, step};

/// Anchor height, arm (anchor to ball centre, body frame), ball radius.
const ANCHOR: f64 = 0.3;
const ARM: [f64; 3] = [0.15, 0.0, -0.25];
const RADIUS: f64 = 0.05;

fn model(h: f64, mu: f64) -> ukemi_engine::Model {
    let xml = format!(
        r#"<mujoco><option timestep="{h}"/><worldbody>
        <geom type="plane" size="5 5 .1" friction="{mu}"/>
        <body pos="0 0 {ANCHOR}"><joint type="ball"/>
          <geom type="capsule" fromto="0 0 0 {} {} {}" size="{RADIUS}" mass="1" friction="{mu}"/>
        </body></worldbody></mujoco>"#,
        ARM[0], ARM[1], ARM[2]
    );
    mjcf::load_str(&xml, "<rolling>")
        .unwrap_or_else(|e| panic!("{e}"))
        .model
}

/// Spin about the anchor–contact line at `spin` rad/s for one second: the ball centre's
/// azimuth about the anchor's vertical (unwrapped), |ω| at the end, and the least signed distance.
fn roll(h: f64, mu: f64, spin: f64) -> (f64, f64, f64) {
    let model = model(h, mu);
    let mut state = State::reference(&model);
    // the contact point lies RADIUS below the ball centre, on the floor
    let line = nalgebra::Vector3::new(ARM[0], ARM[1], ARM[2] - RADIUS).normalize();
    let omega = spin * line;
    set_minimal(&model, &mut state, &[1.0, 0.0, 0.0, 0.0], omega.as_slice()).unwrap();
    let mut ws = Workspace::new(&model);
    let mut least = f64::INFINITY;
    let mut azimuth = Vec::new();
    for k in 0..(1.0 / h).round() as usize {
        let report = step(&model, &mut state, &mut ws, &[]).unwrap();
        assert!(
            report.status.is_success(),
            "dt {h} μ {mu} step {k}: {report:?}"
        );
        let distances = ukemi_engine::contact::signed_distances(&model, &state);
        least = distances.into_iter().fold(least, f64::min);
        // the centre of mass lies halfway along the arm, at the ball centre's azimuth
        let com = state.pose(1).pos;
        azimuth.push(com[1].atan2(com[0]));
    }
    // unwrap the azimuth
    let mut total = 0.0;
    for pair in azimuth.windows(2) {
        let mut d = pair[1] - pair[0];
        d -= (d / std::f64::consts::TAU).round() * std::f64::consts::TAU;
        total += d;
    }
    total += azimuth[0];
    let (_, w) = state.velocity(1);
    (total, w.norm(), least)
}

#[test]
fn a_ball_on_a_ball_joint_rolls_around_it_at_the_precession_rate() {
    // ω = s d along the anchor–contact line d: the ball centre c moves at s d × (c − a) =
    // s r d × z, so it circles the anchor's vertical (radius |ARM_xy|) at Ω = s r sinθ / |ARM_xy|,
    // θ the angle of d from the vertical, clockwise seen from above for d pointing along +x
    let spin = 5.0;
    let horizontal = ARM[0].hypot(ARM[1]);
    let sin_theta = horizontal / (horizontal.powi(2) + (ARM[2] - RADIUS).powi(2)).sqrt();
    let omega_precession = spin * RADIUS * sin_theta / horizontal;
    // (dt, tolerance on the azimuth after 1 s): the integrator's O(h²) (measured 1.7e-5 at
    // dt 0.01, 1.7e-7 at dt 0.001)
    for (h, tol) in [(0.01, 5e-5), (0.001, 5e-7)] {
        let (azimuth, w, least) = roll(h, 1.0, spin);
        eprintln!(
            "dt {h}: azimuth {azimuth:.9} (analytic {:.9}), |ω| {w:.9}, least φ {least:.2e}",
            -omega_precession
        );
        assert!(
            (azimuth + omega_precession).abs() < tol,
            "dt {h}: azimuth {azimuth} vs {}",
            -omega_precession
        );
        // rolling without slipping dissipates nothing: the spin keeps its speed
        assert!((w - spin).abs() < 1e-4 * spin, "dt {h}: |ω| {w}");
        assert!(least >= -1e-8, "dt {h}: penetration {least:.3e}");
    }
}

#[test]
fn a_sticking_roll_does_not_depend_on_the_friction_coefficient() {
    // the roll needs less friction than μ = 0.6 allows, so μ = 0.6 and μ = 2 move alike
    let (a, wa, _) = roll(0.01, 0.6, 5.0);
    let (b, wb, _) = roll(0.01, 2.0, 5.0);
    assert!((a - b).abs() < 1e-8, "azimuth {a} vs {b}");
    assert!((wa - wb).abs() < 1e-8, "|ω| {wa} vs {wb}");
}

#[test]
fn rolling_jacobians_match_the_smoothed_step() {
    // the slip rows are nonlinear in ω (the core's exact displacement): the implicit
    // Jacobians of a step of the roll, in both coordinates, against central differences of the
    // smoothed step at the same κ, and the VJP/JVP against the Jacobian products. At μ = 0.3
    // the line from the anchor to the contact lies outside the friction cone, so the contact
    // impulse is unique. (At μ ≥ 0.5 the capsule is wedged: any impulse along that line is
    // carried by the joint, the central-path point at κ is not found and the gradient raises;
    // README, Known limits.) Smaller κ: central differences of the smoothed step in the geom
    // offsets lose accuracy (the smoothed gap κ/γ is ~2e-5 m at κ = 1e-6).
    let model = grad_check::tight(model(0.01, 0.3));
    let mut state = State::reference(&model);
    let line = nalgebra::Vector3::new(ARM[0], ARM[1], ARM[2] - RADIUS).normalize();
    set_minimal(
        &model,
        &mut state,
        &[1.0, 0.0, 0.0, 0.0],
        (5.0 * line).as_slice(),
    )
    .unwrap();
    let mut ws = Workspace::new(&model);
    for _ in 0..10 {
        step(&model, &mut state, &mut ws, &[]).unwrap();
    }
    for coords in [Coordinates::Minimal, Coordinates::Maximal] {
        for kappa in [1e-4, 1e-5] {
            let e = grad_check::check(&model, &state, &[], coords, Some(kappa), 1e-5);
            eprintln!("{coords:?} κ {kappa:e}: max relative error {e:.1e}");
        }
    }
}
