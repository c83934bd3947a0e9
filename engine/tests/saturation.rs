//! Friction at the stick/slip boundary: a flat box on a floor whose gravity is tilted by 45°
//! (an incline) at μ = tan 45° = 1, where holding the box needs the whole friction cone.
//!
//! Interior-point solutions slip by O(√κ) there, and a saturated contact has no friction left to
//! stop that slip, so the box crept (1.3e-5 m in 1 s) until saturated cones were polished to the
//! exact sliding branch (`solver::saturation`).
mod common;
#[path = "common/contact.rs"]
mod contact_scenes;
#[path = "common/gradients.rs"]
mod grad_check;

use ukemi_engine::{
    ContactModel, Coordinates, Linearization, Model, ModelBuilder, Shape, SolveStatus, State,
    Workspace, Wrt, step,
};

const G: f64 = 9.81;
const HALF: [f64; 3] = [0.2, 0.2, 0.05];

/// The flat box resting on the floor under gravity tilted by 45° towards +x, friction `mu`.
fn incline(mu: f64) -> Model {
    let a = std::f64::consts::FRAC_PI_4;
    let b = ModelBuilder::new()
        .timestep(0.01)
        .gravity([G * a.sin(), 0.0, -G * a.cos()]);
    let b = contact_scenes::floor(b, mu);
    let b = contact_scenes::free_body(
        b,
        "box",
        1.0,
        Shape::Box {
            half_extents: HALF.into(),
        },
        [0.0, 0.0, HALF[2]],
        [1.0, 0.0, 0.0, 0.0],
        mu,
        ContactModel::Nonlinear,
    );
    b.compile().unwrap()
}

/// Run `n` steps from `s`; every step must converge. Returns the box's x positions.
fn slide(m: &Model, s: &mut State, n: usize) -> Vec<f64> {
    let mut ws = Workspace::new(m);
    let mut x = vec![s.com_pos[3]];
    for k in 0..n {
        let r = step(m, s, &mut ws, &[]).unwrap();
        assert!(r.status.is_success(), "step {k}: {r:?}");
        x.push(s.com_pos[3]);
    }
    x
}

#[test]
fn a_box_at_mu_tan_theta_sticks() {
    let m = incline(1.0);
    let x = slide(&m, &mut State::reference(&m), 500);
    // 5 s: before the polish 1.3e-5 m in the first second alone, accelerating
    let creep = (x[500] - x[0]).abs();
    assert!(creep < 1e-9, "crept {creep:e} m in 5 s");
    // gradients there are one-sided (friction held along the slope); the reverse sweep must
    // linearise the stored solutions with the same held rows as a step's Jacobians
    let mut s = State::reference(&m);
    let mut ws = Workspace::new(&m);
    for _ in 0..3 {
        step(&m, &mut s, &mut ws, &[]).unwrap();
    }
    assert_eq!(ws.saturated_contacts(), 4);
    grad_check::check_rollout_vjp_in(&m, &s, 3, None, Coordinates::Minimal, 1e-6);
}

#[test]
fn a_box_at_mu_tan_theta_keeps_sliding_at_its_speed() {
    // friction balances gravity exactly along the slope: a sliding box neither speeds up nor
    // stops (the interior-point solution alone left it accelerating)
    let m = incline(1.0);
    let v0 = 1e-4;
    let mut s = State::reference(&m);
    ukemi_engine::set_minimal(
        &m,
        &mut s,
        &[0.0, 0.0, HALF[2], 1.0, 0.0, 0.0, 0.0],
        &[v0, 0.0, 0.0, 0.0, 0.0, 0.0],
    )
    .unwrap();
    let x = slide(&m, &mut s, 200);
    let v_end = (x[200] - x[199]) / 0.01;
    assert!((v_end - v0).abs() < 1e-9, "v {v_end:e} m/s after 2 s");
}

#[test]
fn a_box_below_tan_theta_slides_with_coulomb_deceleration() {
    // μ = 0.9 < tan 45°: the polish must not hold a box that slides (a = g (sin θ - μ cos θ))
    let m = incline(0.9);
    let x = slide(&m, &mut State::reference(&m), 100);
    let a = std::f64::consts::FRAC_PI_4;
    let expected = G * (a.sin() - 0.9 * a.cos());
    for k in 10..99 {
        let acc = (x[k + 1] - 2.0 * x[k] + x[k - 1]) / 1e-4;
        assert!(
            (acc - expected).abs() < 1e-6 * expected,
            "step {k}: {acc} vs {expected}"
        );
    }
}

#[test]
fn jacobians_at_a_saturated_sliding_contact_match_finite_differences() {
    // a box sliding slowly at the limit, its four corners held saturated by the polish: the
    // exact (kappa_grad = None) Jacobians, taken at the interior-point solution, against central
    // differences of the polished step, every input and parameter (lateral slip is resisted by
    // friction turning with it, which the fixed-direction rows of the polish do not carry)
    let mut m = incline(1.0);
    let mut o = m.options.clone();
    o.rtol = 1e-14;
    o.max_iter = 100;
    m = m.with_options(o).unwrap();
    let mut s = State::reference(&m);
    let mut ws = Workspace::new(&m);
    ukemi_engine::set_minimal(
        &m,
        &mut s,
        &[0.0, 0.0, HALF[2], 1.0, 0.0, 0.0, 0.0],
        &[1e-4, 0.0, 0.0, 0.0, 0.0, 0.0],
    )
    .unwrap();
    for _ in 0..5 {
        step(&m, &mut s, &mut ws, &[]).unwrap();
    }
    assert!(
        ws.saturated_contacts() == 4,
        "the four corners are held: {}",
        ws.saturated_contacts()
    );
    let err = grad_check::check(&m, &s, &[], Coordinates::Maximal, None, 1e-6);
    eprintln!("saturated slide: max rel err {err:e}");
    let lin = Linearization::new(&m, &s, &[], Coordinates::Minimal, Wrt::ALL, None).unwrap();
    assert_eq!(lin.report().status, SolveStatus::Converged);
    // the reverse sweep linearises the stored (polished) solutions the same way; to 1e-6, not
    // 1e-10: hard gradients of a box on four corners are ill-conditioned (the corners' normal
    // impulses are indeterminate), and transposed and forward solves differ by ~5e-7 relative
    // for a box sliding fast without any polish too
    grad_check::check_rollout_vjp_in(&m, &s, 10, None, Coordinates::Minimal, 1e-6);
}
