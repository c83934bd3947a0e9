//! Contact activation (`Options::activation_margin`): candidates out of the step's reach take no
//! part in the solve. The trajectory must not change, and no contact may be missed.
#[path = "common/contact.rs"]
mod common;
use common::*;
use nalgebra::Vector3;
use ukemi_engine::{
    AppliedForces, ContactModel, Model, ModelBuilder, Options, Shape, SolveStatus, State,
    Workspace, contact, step, step_with,
};

/// Tolerances 100× tighter than the defaults, so that what the solves leave unresolved does not
/// hide the effect of activation: all-active solves give far candidates impulses of order
/// `kappa / φ`, and each step's solution is only known to `rtol` (at the default tolerances the
/// two trajectories below differ by 1.5e-9 after 200 steps).
fn with_margin(model: &Model, margin: f64) -> Model {
    model
        .with_options(Options {
            activation_margin: margin,
            rtol: 1e-12,
            kappa_tol: 1e-13,
            ..model.options.clone()
        })
        .unwrap()
}

/// Six spheres dropped with sideways velocities at different heights: 6 floor candidates and
/// 15 sphere-sphere candidates, most of them far most of the time.
fn spheres() -> Model {
    let mut b = floor(ModelBuilder::new().timestep(0.01), 0.7);
    for i in 0..6 {
        let x = 1.5 * i as f64;
        b = free_body(
            b,
            &format!("s{i}"),
            1.0 + 0.3 * i as f64,
            Shape::Sphere { radius: 0.1 },
            [x, 0.2 * i as f64, 0.3 + 0.25 * i as f64],
            [1.0, 0.0, 0.0, 0.0],
            0.7,
            ContactModel::Nonlinear,
        );
    }
    b.compile().unwrap()
}

fn start(model: &Model) -> State {
    let mut state = State::reference(model);
    for b in 1..model.nbody() {
        let k = b as f64;
        state.set_velocity(
            b,
            &Vector3::new(0.5 * k.sin(), 0.3 * k.cos(), 0.2 * k),
            &Vector3::new(0.0, 3.0 * k.cos(), 1.0),
        );
    }
    state
}

#[test]
fn far_candidates_do_not_change_the_trajectory() {
    let base = spheres();
    let (on, off) = (with_margin(&base, 0.01), with_margin(&base, f64::INFINITY));
    let (mut s_on, mut s_off) = (start(&on), start(&off));
    let (mut ws_on, mut ws_off) = (Workspace::new(&on), Workspace::new(&off));
    let (mut least, mut most) = (usize::MAX, 0);
    let (mut it_on, mut it_off) = (0, 0);
    let mut worst: f64 = 0.0;
    for _ in 0..200 {
        let r_on = step(&on, &mut s_on, &mut ws_on, &[]).unwrap();
        let r_off = step(&off, &mut s_off, &mut ws_off, &[]).unwrap();
        assert_eq!(r_on.status, SolveStatus::Converged, "{r_on:?}");
        assert_eq!(r_off.status, SolveStatus::Converged, "{r_off:?}");
        it_on += r_on.iterations;
        it_off += r_off.iterations;
        assert_eq!(ws_off.active_contacts(), off.ncontact());
        least = least.min(ws_on.active_contacts());
        most = most.max(ws_on.active_contacts());
        for b in 1..on.nbody() {
            let d = (s_on.pose(b).pos - s_off.pose(b).pos).norm();
            let v = (s_on.velocity(b).0 - s_off.velocity(b).0).norm();
            worst = worst.max(d).max(v);
        }
        // inactive candidates report zero impulse
        let imp = s_on.contact_impulse(&on);
        for (c, &a) in ws_on.contact_active().iter().enumerate() {
            if !a {
                assert_eq!(&imp[3 * c..3 * c + 3], &[0.0; 3]);
            }
        }
    }
    eprintln!(
        "active candidates {least}..={most} of {}; iterations {it_on} vs {it_off} all active; \
         largest difference {worst:.2e}",
        on.ncontact()
    );
    assert!(worst < 1e-9, "trajectories differ by {worst:e}");
    assert!(least < on.ncontact() / 2, "activation left {least} active");
    assert!(
        most >= 6,
        "the landed spheres' floor contacts must be active"
    );
}

#[test]
fn a_fast_sphere_is_caught_by_the_floor() {
    let model = free_body(
        floor(ModelBuilder::new().timestep(0.01), 0.5),
        "ball",
        1.0,
        Shape::Sphere { radius: 0.05 },
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 0.0, 0.0],
        0.5,
        ContactModel::Nonlinear,
    )
    .compile()
    .unwrap();
    let model = with_margin(&model, 0.01);
    let mut state = State::reference(&model);
    state.set_velocity(1, &Vector3::new(3.0, 0.0, -40.0), &Vector3::zeros());
    let mut ws = Workspace::new(&model);
    let mut inactive_steps = 0;
    for _ in 0..60 {
        let r = step(&model, &mut state, &mut ws, &[]).unwrap();
        assert_eq!(r.status, SolveStatus::Converged, "{r:?}");
        inactive_steps += usize::from(ws.active_contacts() == 0);
        let phi = contact::signed_distances(&model, &state)[0];
        assert!(phi >= -1e-8, "t = {}: penetration {phi:e}", state.time);
    }
    assert!(inactive_steps > 0, "the far floor should start inactive");
}

#[test]
fn a_contact_the_estimate_misses_is_still_enforced() {
    // at rest 4 cm above the floor, no gravity: the activation estimate (zero speed) leaves the
    // floor inactive, then a 2000 N push closes the gap within one 10 ms step
    let model = free_body(
        floor(ModelBuilder::new().timestep(0.01).gravity([0.0; 3]), 0.5),
        "ball",
        1.0,
        Shape::Sphere { radius: 0.05 },
        [0.0, 0.0, 0.09],
        [1.0, 0.0, 0.0, 0.0],
        0.5,
        ContactModel::Nonlinear,
    )
    .compile()
    .unwrap();
    let model = with_margin(&model, 0.01);
    let mut state = State::reference(&model);
    let mut ws = Workspace::new(&model);
    let mut xfrc = vec![0.0; 6 * model.nbody()];
    xfrc[6 + 2] = -2000.0;
    let forces = AppliedForces {
        qfrc: None,
        xfrc: Some(&xfrc),
    };
    let r = step_with(&model, &mut state, &mut ws, &[], &forces).unwrap();
    assert_eq!(r.status, SolveStatus::Converged, "{r:?}");
    assert_eq!(
        ws.active_contacts(),
        1,
        "the missed floor contact is re-solved active"
    );
    let phi = contact::signed_distances(&model, &state)[0];
    assert!(phi.abs() < 1e-8, "penetration or gap {phi:e}");
    assert!(state.contact_impulse(&model)[0] > 1.0);
}

/// Two spheres 2 cm apart (beyond the 1 cm margin) in zero gravity, started with velocities
/// `(v_a, ω, v_b, ω)`; returns whether their candidate took part in the first step.
fn pair_active(v_a: [f64; 3], v_b: [f64; 3], omega: [f64; 3]) -> bool {
    let mut b = ModelBuilder::new().timestep(0.01).gravity([0.0; 3]);
    for (name, x) in [("a", 0.0), ("b", 0.22)] {
        b = free_body(
            b,
            name,
            1.0,
            Shape::Sphere { radius: 0.1 },
            [x, 0.0, 1.0],
            [1.0, 0.0, 0.0, 0.0],
            0.5,
            ContactModel::Nonlinear,
        );
    }
    let model = with_margin(&b.compile().unwrap(), 0.01);
    let mut state = State::reference(&model);
    let w = Vector3::from(omega);
    state.set_velocity(1, &Vector3::from(v_a), &w);
    state.set_velocity(2, &Vector3::from(v_b), &w);
    let mut ws = Workspace::new(&model);
    let r = step(&model, &mut state, &mut ws, &[]).unwrap();
    assert_eq!(r.status, SolveStatus::Converged, "{r:?}");
    ws.active_contacts() == 1
}

#[test]
fn only_an_approach_along_the_normal_activates_a_candidate() {
    // the activation reach looks at the rate at which the witness points close along the
    // normal: 5 m/s side by side, turning together about a's centre at 3 rad/s, sliding past
    // each other at 5 m/s, or spinning about their own centres leave the gap as it is
    assert!(!pair_active([5.0, 0.0, 0.0], [5.0, 0.0, 0.0], [0.0; 3]));
    let rigid_b = Vector3::new(0.0, 0.0, 3.0).cross(&Vector3::new(0.22, 0.0, 0.0));
    assert!(!pair_active([0.0; 3], rigid_b.into(), [0.0, 0.0, 3.0]));
    assert!(!pair_active([0.0, 5.0, 0.0], [0.0; 3], [0.0; 3]));
    assert!(!pair_active([0.0; 3], [0.0; 3], [0.0, 0.0, 5.0]));
    // closing at 1 m/s (either body) they take part: 0.01 + 2 h 1 m/s = 3 cm reach
    assert!(pair_active([1.0, 0.0, 0.0], [0.0; 3], [0.0; 3]));
    assert!(pair_active([0.0; 3], [-1.0, 0.0, 0.0], [0.0; 3]));
    // closing at 0.4 m/s: 1.8 cm reach, short of the 2 cm gap (and the step leaves it at
    // 1.6 cm, beyond a quarter margin: no re-solve)
    assert!(!pair_active([0.4, 0.0, 0.0], [0.0; 3], [0.0; 3]));
}

/// Two boxes of half extent `half` in zero gravity, face to face along x with a 7 mm gap (B
/// offset 1 mm sideways), B moving towards A at `speed`.
fn box_pair(half: f64, speed: f64, margin: f64) -> (Model, State) {
    let mut b = ModelBuilder::new().timestep(0.01).gravity([0.0; 3]);
    for (name, x, y) in [("a", 0.0, 0.0), ("b", 2.0 * half + 0.007, 0.001)] {
        b = free_body(
            b,
            name,
            1.0,
            Shape::Box {
                half_extents: Vector3::repeat(half),
            },
            [x, y, 1.0],
            [1.0, 0.0, 0.0, 0.0],
            0.5,
            ContactModel::Nonlinear,
        );
    }
    let model = with_margin(&b.compile().unwrap(), margin);
    let mut state = State::reference(&model);
    state.set_velocity(2, &Vector3::new(-speed, 0.0, 0.0), &Vector3::zeros());
    (model, state)
}

#[test]
fn small_geoms_are_activated_within_their_own_size() {
    // at rest 7 mm apart: within the 1 cm margin, but beyond the 5.2 mm bounding radius of
    // 3 mm boxes (fingertip pads), which caps their margin; 5 cm boxes keep the full margin
    for (half, active) in [(0.003, false), (0.05, true)] {
        let (model, mut state) = box_pair(half, 0.0, 0.01);
        let mut ws = Workspace::new(&model);
        let r = step(&model, &mut state, &mut ws, &[]).unwrap();
        assert_eq!(r.status, SolveStatus::Converged, "{r:?}");
        assert_eq!(ws.active_contacts() > 0, active, "half extent {half}");
    }
    // and the capped margin misses no contact: a 3 mm box thrown at another one follows the
    // all-active trajectory, without penetration and with momentum conserved
    let (on, mut s_on) = box_pair(0.003, 0.05, 0.01);
    let (off, mut s_off) = box_pair(0.003, 0.05, f64::INFINITY);
    let (mut ws_on, mut ws_off) = (Workspace::new(&on), Workspace::new(&off));
    let (mut inactive_steps, mut worst) = (0, 0.0_f64);
    for _ in 0..60 {
        for (m, s, ws) in [
            (&on, &mut s_on, &mut ws_on),
            (&off, &mut s_off, &mut ws_off),
        ] {
            let r = step(m, s, ws, &[]).unwrap();
            assert_eq!(r.status, SolveStatus::Converged, "{r:?}");
            let phi = contact::signed_distances(m, s);
            let least = phi.iter().copied().fold(f64::INFINITY, f64::min);
            assert!(least >= -1e-8, "t = {}: penetration {least:e}", s.time);
        }
        inactive_steps += usize::from(ws_on.active_contacts() == 0);
        for b in 1..on.nbody() {
            worst = worst.max((s_on.pose(b).pos - s_off.pose(b).pos).norm());
        }
    }
    let (va, vb) = (s_on.velocity(1).0, s_on.velocity(2).0);
    assert!(inactive_steps > 0, "the pair should start inactive");
    // (1e-8: the all-active run's far corners carry impulses of order kappa / phi, and the boxes
    // stay pressed together after the inelastic impact, so the difference grows; 2.7e-9 m)
    assert!(worst < 1e-8, "trajectories differ by {worst:e}");
    assert!(
        (va + vb - Vector3::new(-0.05, 0.0, 0.0)).norm() < 1e-9,
        "{va} {vb}"
    );
    assert!(va.x < -0.02, "the struck box must move: {va}");
}

/// A body of two boxes side by side whose bottoms lie 7 mm apart in height (more than half the
/// 1 cm margin, less than the margin), at rest on the floor on the lower box's bottom (its
/// centre of mass over that box): the
/// corners of both boxes are points of one rigid body, the lower box's touch first, and the
/// upper box's four bottom corners are left out (box by box they were active: each box's own
/// lowest corner is within the margin). Like the Skydio X2 upside down on its three box tops.
#[test]
fn a_bodys_boxes_share_their_lowest_corner() {
    use ukemi_engine::{BodySpec, GeomSpec, JointKind, JointSpec};
    let half = Vector3::new(0.05, 0.05, 0.02);
    let model = ModelBuilder::new()
        .timestep(0.01)
        .geom(GeomSpec::new("floor", "world", Shape::Plane).friction(0.8))
        .body(BodySpec::new("two", 1.0, [0.002, 0.003, 0.004]).pos([0.0, 0.0, 0.02]))
        .joint(JointSpec::new("free", JointKind::Floating, "world", "two"))
        .geom(GeomSpec::new("low", "two", Shape::Box { half_extents: half }).friction(0.8))
        .geom(
            GeomSpec::new("high", "two", Shape::Box { half_extents: half })
                .pos([0.12, 0.0, 0.007])
                .friction(0.8),
        )
        .compile()
        .unwrap();
    let mut state = State::reference(&model);
    let mut ws = Workspace::new(&model);
    let mut active = Vec::new();
    for _ in 0..50 {
        let r = step(&model, &mut state, &mut ws, &[]).unwrap();
        assert!(r.status.is_success(), "{r:?}");
        active.push(ws.active_contacts());
    }
    // the lower box's four bottom corners, and none of the upper box's
    assert!(active[10..].iter().all(|&n| n == 4), "{active:?}");
    // at rest on the lower box, which carries the body: no penetration, no creep
    let least = contact::signed_distances(&model, &state)
        .into_iter()
        .fold(f64::INFINITY, f64::min);
    assert!(least > -1e-9, "{least:e}");
    let (v, w) = state.velocity(1);
    assert!(v.norm() < 1e-6 && w.norm() < 1e-6, "{v:?} {w:?}");
    let pose = state.pose(1);
    assert!((pose.pos.z - 0.02).abs() < 1e-6, "{:?}", pose.pos);
    assert!(pose.quat.w.abs() > 1.0 - 1e-9, "tipped: {:?}", pose.quat);
}
