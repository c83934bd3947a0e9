//! Dry joint friction (`frictionloss`) against Coulomb's law on one slide joint and one hinge:
//! a load below the friction holds the joint exactly still, a load above it accelerates the
//! joint by the difference, and a moving joint decelerates at `f / m` and stops without
//! reversing or creeping.
mod common;
use common::*;
use ukemi_engine::{
    AppliedForces, BodySpec, JointKind, JointSpec, ModelBuilder, State, Workspace, qpos, qvel,
    set_minimal, step_with,
};

const H: f64 = 0.01;
/// The solver's default `kappa_tol`, the complementarity products it converges to (an upper
/// bound: its last iterates' products are smaller).
const KAPPA_TOL: f64 = 1e-11;

/// A 2 kg block on a slide joint along x (or a 0.5 kg·m² wheel on a hinge about z) with
/// friction `f`, no gravity.
fn joint(kind: JointKind, f: f64) -> ukemi_engine::Model {
    ModelBuilder::new()
        .timestep(H)
        .gravity([0.0; 3])
        .body(BodySpec::new("m", 2.0, [0.5, 0.5, 0.5]))
        .joint(
            JointSpec::new("j", kind, "world", "m")
                .axis([1.0, 0.0, 0.0])
                .frictionloss(f),
        )
        .compile()
        .unwrap()
}

/// Steps under a constant generalized force `load`: the rates after each step.
fn rates(model: &ukemi_engine::Model, v0: f64, load: f64, steps: usize) -> Vec<f64> {
    let mut state = State::reference(model);
    set_minimal(model, &mut state, &[0.0], &[v0]).unwrap();
    let mut ws = Workspace::new(model);
    let q = [load];
    let forces = AppliedForces {
        qfrc: Some(&q),
        xfrc: None,
    };
    (0..steps)
        .map(|_| {
            let report = step_with(model, &mut state, &mut ws, &[], &forces).unwrap();
            assert!(report.status.is_success(), "{report:?}");
            // the friction holds what the load and the momentum change leave
            let (v, tau) = (
                qvel(model, &state)[0],
                state.joint_friction_impulse(model)[0],
            );
            let f = model.joints[0].frictionloss[0];
            assert!(tau.abs() <= f * H * (1.0 + 1e-9), "{tau} beyond {f} h");
            // sliding, the room `s = κ / (h |v|)` left to the bound is the interior point's
            if v.abs() > 1e-4 {
                let room = KAPPA_TOL / (H * v.abs());
                assert!(
                    (tau - f * H * v.signum()).abs() < room,
                    "sliding at {v}: {tau}"
                );
            }
            v
        })
        .collect()
}

#[test]
fn a_load_below_the_friction_holds_the_joint_exactly() {
    // what is left is the interior point's: a displacement `κ / (f h - |τ|)` a step, with
    // `kappa_tol` 1e-11 and 1e-3 N·s of room to the bound at most 1e-8 m (1e-6 m/s)
    for kind in [JointKind::Prismatic, JointKind::Revolute] {
        let model = joint(kind, 3.0);
        let v = rates(&model, 0.0, 2.9, 100);
        let worst = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let travel: f64 = v.iter().sum::<f64>() * H;
        eprintln!("{kind:?} under 2.9 against friction 3: rate {worst:.1e}, travel {travel:.1e}");
        let bound = KAPPA_TOL / (3.0 * H - 2.9 * H) / H;
        assert!(
            worst < bound,
            "{kind:?} creeps at {worst:e} (bound {bound:e})"
        );
        assert!(
            travel.abs() < 100.0 * bound * H,
            "{kind:?} creeps {travel:e}"
        );
    }
}

#[test]
fn a_load_above_the_friction_accelerates_by_the_difference() {
    for (kind, inertia) in [(JointKind::Prismatic, 2.0), (JointKind::Revolute, 0.5)] {
        let model = joint(kind, 3.0);
        for load in [5.0, -5.0] {
            let v = rates(&model, 0.0, load, 50);
            for (k, &vk) in v.iter().enumerate() {
                // (a hinge's discrete momentum `I ω √(1 - (hω/2)²)` bends this by (hω/2)², and
                // the friction impulse is within `κ / (h |v|)` of its bound)
                let want = (load - 3.0 * load.signum()) / inertia * H * (k + 1) as f64;
                let room = KAPPA_TOL / (H * want.abs()) / inertia;
                let tol = room + 1e-12 + (H * want / 2.0).powi(2) * want.abs();
                assert!((vk - want).abs() < tol, "{kind:?} step {k}: {vk} vs {want}");
            }
        }
    }
}

#[test]
fn a_sliding_joint_decelerates_at_f_over_m_and_stops_for_good() {
    let (f, m, v0) = (3.0, 2.0, 1.0);
    let model = joint(JointKind::Prismatic, f);
    let v = rates(&model, v0, 0.0, 120);
    // v₀ m / f = 0.667 s: 66 whole steps of deceleration f h / m, then rest
    let stop = (v0 * m / (f * H)).floor() as usize;
    for (k, &vk) in v.iter().enumerate() {
        let want = (v0 - f / m * H * (k + 1) as f64).max(0.0);
        // each step's impulse within `κ / (h v)` of its bound, the slowest step's the largest
        let tol = (k + 1) as f64 * KAPPA_TOL / (H * want.max(0.01)) / m;
        assert!((vk - want).abs() < tol, "step {k}: {vk} vs {want}");
    }
    // at rest with no load the room is f h on both sides: κ / (f h) a step at most
    let rest = KAPPA_TOL / (f * H) / H;
    assert!(
        v[stop + 1..].iter().all(|x| x.abs() < rest),
        "{:?}",
        &v[stop..]
    );
}

#[test]
fn dry_friction_dissipates_and_a_frictionless_joint_does_not_pay_for_it() {
    let counts = joint(JointKind::Revolute, 0.0).variable_counts();
    assert!(counts.contains(&("joint_friction", 0)), "{counts:?}");
    let counts = joint(JointKind::Revolute, 1.0).variable_counts();
    assert!(counts.contains(&("joint_friction", 4)), "{counts:?}");
    // kinetic energy falls by exactly the friction impulse's work while the block slides
    let model = joint(JointKind::Prismatic, 2.0);
    let mut state = State::reference(&model);
    set_minimal(&model, &mut state, &[0.0], &[0.503]).unwrap();
    let mut ws = Workspace::new(&model);
    let energy = |s: &State| 0.5 * 2.0 * qvel(&model, s)[0].powi(2);
    let mut slid = 0;
    for _ in 0..100 {
        let (e0, v0) = (energy(&state), qvel(&model, &state)[0]);
        step_ok(&model, &mut state, &mut ws, &[]);
        let (e1, v1) = (energy(&state), qvel(&model, &state)[0]);
        if v1 > 1e-6 {
            // m (v₁ - v₀) = -f h, so ΔE = -f h (v₀ + v₁) / 2
            let room = KAPPA_TOL / (H * v1) * (v0 + v1) / 2.0;
            assert!(
                (e0 - e1 - 2.0 * H * (v0 + v1) / 2.0).abs() < room,
                "{e0} {e1}"
            );
            slid += 1;
        } else {
            assert!(v1.abs() < 1e-6 && e1 <= e0 + 1e-12, "{v1} {e0} {e1}");
        }
    }
    assert!(slid > 10 && slid < 100, "{slid}");
    let _ = qpos(&model, &state);
}
