//! A gripper's finger pads pressed together: bodies that can only slide along the contact
//! normal relative to each other, whose friction the solver holds at zero
//! (`Options::drop_redundant_friction`, `contact::slide_pair`).
#[path = "common/gradients.rs"]
mod grad_check;

use ukemi_engine::{
    BodySpec, ContactModel, Coordinates, GeomSpec, JointKind, JointSpec, Model, ModelBuilder,
    Shape, State, Workspace, mechanics, set_minimal, step,
};

/// A hand turning about the vertical on a hinge, one finger welded to it and one sliding on it
/// along y, pulled against the fixed one by a spring; a 2 cm box pad on the fixed finger, a
/// 1 × 2 × 1 cm one on the sliding finger (its corners well inside the other's face: pads of
/// one size put the corners on the face's edges, where the feature switches).
fn gripper(drop: bool) -> Model {
    gripper_limited(drop, None)
}

/// [`gripper`] with its slide limited to `range` (m; the pads' gap is `0.03 + q`).
fn gripper_limited(drop: bool, range: Option<(f64, f64)>) -> Model {
    let pad = |name: &str, body: &str, half: [f64; 3]| {
        GeomSpec::new(
            name,
            body,
            Shape::Box {
                half_extents: half.into(),
            },
        )
        .friction(1.0)
        .model(Some(ContactModel::Nonlinear))
    };
    let m = ModelBuilder::new()
        .timestep(0.01)
        .body(BodySpec::new("hand", 1.0, [0.01, 0.01, 0.02]))
        .body(BodySpec::new("fixed", 0.1, [1e-5; 3]))
        .body(BodySpec::new("sliding", 0.1, [1e-5; 3]))
        .joint(JointSpec::new(
            "wrist",
            JointKind::Revolute,
            "world",
            "hand",
        ))
        .joint(JointSpec::new("weld", JointKind::Fixed, "hand", "fixed"))
        .joint(JointSpec {
            range: range.map(|r| vec![r]),
            ..JointSpec::new("slide", JointKind::Prismatic, "hand", "sliding")
                .axis([0.0, 1.0, 0.0])
                .anchors([0.0, 0.05, 0.0], [0.0; 3])
                .stiffness(100.0)
                .spring_ref(vec![-0.05])
        })
        .geom(pad("pad_fixed", "fixed", [0.01; 3]))
        .geom(pad("pad_sliding", "sliding", [0.005, 0.01, 0.005]))
        .compile()
        .unwrap();
    let mut o = m.options.clone();
    o.drop_redundant_friction = drop;
    m.with_options(o).unwrap()
}

/// The gripper turning at 2 rad/s with its sliding pad 3 cm from the other.
fn start(m: &Model) -> State {
    let mut s = State::reference(m);
    set_minimal(m, &mut s, &[0.0, 0.0], &[2.0, 0.0]).unwrap();
    s
}

#[test]
fn pressed_pads_hold_no_friction_and_conserve_angular_momentum() {
    // nothing acts on the turning gripper about its wrist's (vertical) axis: the pads' impact
    // and pressure are internal, so its angular momentum about that axis is conserved. With
    // the pads' friction held at zero it is, to the solver's tolerance; with the friction kept, the impact
    // step's friction (the pads' gap closing within the step while turning reads as slip along
    // the discrete slip measure) acts as a couple across the gap and changes it
    let (held, free) = (gripper(true), gripper(false));
    let (mut a, mut b) = (start(&held), start(&free));
    let (mut wa, mut wb) = (Workspace::new(&held), Workspace::new(&free));
    let l0 = mechanics::angular_momentum(&held, &a)[2];
    let (mut drift_held, mut drift_free, mut pressed) = (0.0f64, 0.0f64, 0);
    for k in 0..150 {
        for (m, s, ws) in [(&held, &mut a, &mut wa), (&free, &mut b, &mut wb)] {
            assert!(step(m, s, ws, &[]).unwrap().status.is_success(), "step {k}");
        }
        assert_eq!(wb.frictionless_contacts(), 0);
        pressed += usize::from(wa.frictionless_contacts() > 0);
        drift_held = drift_held.max((mechanics::angular_momentum(&held, &a)[2] - l0).abs() / l0);
        drift_free = drift_free.max((mechanics::angular_momentum(&free, &b)[2] - l0).abs() / l0);
    }
    eprintln!("angular momentum drift: friction held {drift_held:e}, kept {drift_free:e}");
    assert!(drift_held < 1e-7, "held: {drift_held:e}");
    // (the solver's tolerances: ~7e-9 in 150 steps; with the friction kept, 6e-3)
    // the spring closes the 3 cm within a few steps, then the pads stay pressed: the sliding
    // pad's four corners on the other's face cannot slip, one of them takes part, frictionless,
    // and implies the other three (the same gap up to a constant)
    assert!(pressed > 140, "{pressed} steps with held contacts");
    assert_eq!(wa.frictionless_contacts(), 1);
    assert_eq!(wa.shadowed_contacts(), 3);
    // pressed, pads touching 3 cm in from the start; the fixed pad holds the spring's 2 N pull
    // less the centrifugal force of the turning finger (< 0.01 N), all of it on the one corner
    let q = ukemi_engine::qpos(&held, &a);
    assert!((q[1] - (-0.03)).abs() < 1e-6, "slide at {}", q[1]);
    let imp: f64 = a.contact_impulse(&held).chunks(3).map(|f| f[0]).sum();
    let expected = 100.0 * 0.02 * 0.01;
    assert!(
        (imp - expected).abs() < 0.05 * expected,
        "normal impulse {imp} vs {expected}"
    );
}

#[test]
fn jacobians_with_pads_held_frictionless_match_finite_differences() {
    let m = gripper(true);
    let mut s = State::reference(&m);
    set_minimal(&m, &mut s, &[0.0, -0.025], &[0.5, -0.1]).unwrap();
    let mut ws = Workspace::new(&m);
    for _ in 0..3 {
        step(&m, &mut s, &mut ws, &[]).unwrap();
    }
    assert_eq!((ws.frictionless_contacts(), ws.shadowed_contacts()), (1, 3));
    // (the parameters' central differences are good to ~2e-5 here, with the friction held or
    // kept alike; the hard step's maximal-coordinate products agree with the Jacobians to
    // ~1e-6 relative only, the transposed and forward solves of its contact rows, γ/s ~ 1e9,
    // as for the box sliding at the limit in `saturation.rs`)
    for (coords, kappa, tol) in [
        (Coordinates::Minimal, Some(1e-4), 5e-5),
        (Coordinates::Maximal, Some(1e-4), 5e-5),
        (Coordinates::Minimal, None, 5e-5),
    ] {
        let err = grad_check::check(&m, &s, &[], coords, kappa, tol);
        eprintln!("{coords:?} kappa {kappa:?}: max rel err {err:e}");
    }
}

/// A finger slammed shut at 2 m/s with its pad 3 cm from the other: the step's approach term
/// (`2 h u` = 4 cm) reaches the pads, but a slide limit 5 mm ahead stops the finger 2.5 cm
/// short (its spring then holds it there), and the pads' candidates stay out of the step
/// (`activation::slide_room`). With the limit 4 cm ahead they take part, and the pads meet
/// without sinking into each other.
#[test]
fn a_finger_limit_keeps_unreachable_pads_out_of_the_step() {
    for (lower, reachable) in [(-0.005, false), (-0.04, true)] {
        let m = gripper_limited(true, Some((lower, 0.1)));
        let mut s = State::reference(&m);
        set_minimal(&m, &mut s, &[0.0, 0.0], &[0.0, -2.0]).unwrap();
        let mut ws = Workspace::new(&m);
        let r = step(&m, &mut s, &mut ws, &[]).unwrap();
        assert!(r.status.is_success(), "{r:?}");
        assert_eq!(ws.active_contacts() > 0, reachable, "lower limit {lower}");
        // the rest of the closing: every step converges and the pads never sink
        for k in 0..30 {
            let r = step(&m, &mut s, &mut ws, &[]).unwrap();
            assert!(r.status.is_success(), "step {k}: {r:?}");
            let gap = ukemi_engine::contact::signed_distances(&m, &s)
                .into_iter()
                .fold(f64::INFINITY, f64::min);
            assert!(gap > -1e-8, "step {k}: gap {gap:e}");
            if !reachable {
                assert!(
                    gap > 0.02,
                    "step {k}: the limit stops the pads 2.5 cm apart, {gap}"
                );
            }
        }
    }
}
