//! Candidates apart: an active contact candidate at least 1 mm from touching has its friction
//! held at zero while its gap stays open, and released as soon as the gap closes
//! (`Options::drop_redundant_friction`, `solver::saturation::hold_separated`).
#[path = "common/gradients.rs"]
mod grad_check;

use nalgebra::Vector3;
use ukemi_engine::{
    BodySpec, ContactModel, Coordinates, GeomSpec, JointKind, JointSpec, Model, ModelBuilder,
    Shape, State, Workspace, step,
};

/// A 10 cm ball over a floor (μ = 0.8), `drop` switching the hold.
fn ball(drop: bool) -> Model {
    let m = ModelBuilder::new()
        .timestep(0.01)
        .geom(
            GeomSpec::new("floor", "world", Shape::Plane)
                .friction(0.8)
                .model(Some(ContactModel::Nonlinear)),
        )
        .body(BodySpec::new("ball", 1.0, [0.004; 3]))
        .joint(JointSpec::new("free", JointKind::Floating, "world", "ball"))
        .geom(GeomSpec::new("ball", "ball", Shape::Sphere { radius: 0.1 }).friction(0.8))
        .compile()
        .unwrap();
    let mut o = m.options.clone();
    o.drop_redundant_friction = drop;
    m.with_options(o).unwrap()
}

/// The ball `gap` above the floor with velocity `v` and spin `w`.
fn at(m: &Model, gap: f64, v: [f64; 3], w: [f64; 3]) -> State {
    let mut s = State::reference(m);
    let mut pose = s.pose(1);
    pose.pos = Vector3::new(0.0, 0.0, 0.1 + gap);
    s.set_pose(1, &pose);
    s.set_velocity(1, &Vector3::from(v), &Vector3::from(w));
    s
}

/// One step from `s` with and without the hold: the two next states and the held count.
fn both(gap: f64, v: [f64; 3], w: [f64; 3]) -> (State, State, usize, [f64; 3]) {
    let mut out = Vec::new();
    let mut held = 0;
    let mut impulse = [0.0; 3];
    for drop in [true, false] {
        let m = ball(drop);
        let mut s = at(&m, gap, v, w);
        let mut ws = Workspace::new(&m);
        let r = step(&m, &mut s, &mut ws, &[]).unwrap();
        assert_eq!(r.status.name(), "converged", "{r:?}");
        assert_eq!(ws.active_contacts(), 1, "the candidate takes part");
        if drop {
            held = ws.separated_contacts();
            let f = s.contact_impulse(&m);
            impulse = [f[0], f[1], f[2]];
        } else {
            assert_eq!(ws.separated_contacts(), 0);
        }
        out.push(s);
    }
    let b = out.pop().unwrap();
    (out.pop().unwrap(), b, held, impulse)
}

fn max_difference(a: &State, b: &State) -> f64 {
    let (pa, pb) = (a.pose(1), b.pose(1));
    let ((va, wa), (vb, wb)) = (a.velocity(1), b.velocity(1));
    [
        (pa.pos - pb.pos).amax(),
        (va - vb).amax(),
        (wa - wb).amax(),
        (pa.quat.coords - pb.quat.coords).amax(),
    ]
    .into_iter()
    .fold(0.0, f64::max)
}

#[test]
fn a_ball_that_stays_apart_is_held_and_steps_as_without_the_hold() {
    // 5 mm up, falling 1 mm in the step while sliding and spinning: apart throughout
    let (held, kept, count, impulse) = both(5e-3, [1.0, 0.5, 0.0], [0.0, 0.0, 3.0]);
    assert_eq!(count, 1, "the candidate apart is held");
    assert!(impulse.iter().all(|f| f.abs() < 1e-8), "{impulse:?}");
    // the kept friction's impulse is O(κ/gap) on the central path (γ ≈ κ_tol / gap): the two
    // steps differ by that, the held one keeps its sliding velocity exactly
    let d = max_difference(&held, &kept);
    assert!(d < 2e-8, "next states differ by {d:e}");
    let (v, _) = held.velocity(1);
    assert!(
        (v.x - 1.0).abs() < 1e-12 && (v.y - 0.5).abs() < 1e-12,
        "{v:?}"
    );
    // free fall, sliding on: z drops by g h² exactly (the variational integrator's ballistic
    // step), x by v h
    let z = held.pose(1).pos.z;
    assert!((z - (0.105 - 9.81 * 1e-4)).abs() < 1e-9, "z {z}");
}

#[test]
fn a_ball_that_lands_in_the_step_is_released_and_has_its_friction() {
    // 3 mm up, falling at 1 m/s while sliding at 2 m/s: it lands within the step, so the hold
    // is released when its gap closes and the friction acts (spinning the ball up towards
    // rolling)
    let (held, kept, count, impulse) = both(3e-3, [2.0, 0.0, -1.0], [0.0; 3]);
    assert_eq!(count, 0, "the landing candidate is released");
    let d = max_difference(&held, &kept);
    assert!(d < 1e-8, "next states differ by {d:e}");
    let (normal, friction) = (impulse[0], impulse[1].hypot(impulse[2]));
    assert!(normal > 0.1, "normal impulse {normal}");
    assert!(
        friction > 0.5 * normal && friction <= 0.8 * normal * (1.0 + 1e-9),
        "friction {friction}, normal {normal}"
    );
}

#[test]
fn jacobians_of_a_held_step_match_finite_differences() {
    // hard and smoothed: the held pair's rows are equalities (no friction), whose derivative is
    // the unheld one's to O(κ / gap)
    let m = grad_check::tight(ball(true));
    let s = at(&m, 5e-3, [1.0, 0.5, 0.0], [0.0, 0.0, 3.0]);
    for (coords, kappa) in [
        (Coordinates::Minimal, None),
        (Coordinates::Maximal, None),
        (Coordinates::Minimal, Some(1e-4)),
    ] {
        let err = grad_check::check(&m, &s, &[], coords, kappa, 1e-6);
        eprintln!("{coords:?} kappa {kappa:?}: max rel err {err:e}");
    }
}
