//! Winding hinges: an unlimited hinge's `qpos` winds on past ±π as MuJoCo's does, its spring
//! sees the wound angle, and its Jacobians hold across the wrap of the measured angle.
mod common;
#[path = "common/gradients.rs"]
mod grad_check;

use common::*;
use std::f64::consts::{PI, TAU};
use ukemi_engine::{
    BodySpec, Coordinates, JointKind, JointSpec, ModelBuilder, State, Workspace, qpos, qvel,
    set_minimal,
};

/// A wheel on a hinge about y (inertia 0.2 about its axis) with an optional torsion spring.
fn wheel(stiffness: f64) -> ukemi_engine::Model {
    ModelBuilder::new()
        .timestep(0.01)
        .gravity([0.0; 3])
        .body(BodySpec::new("wheel", 1.0, [0.1, 0.2, 0.1]))
        .joint(
            JointSpec::new("axle", JointKind::Revolute, "world", "wheel")
                .axis([0.0, 1.0, 0.0])
                .stiffness(stiffness),
        )
        .compile()
        .unwrap()
}

#[test]
fn a_spinning_wheel_winds_on() {
    let m = wheel(0.0);
    let mut s = State::reference(&m);
    set_minimal(&m, &mut s, &[0.0], &[5.0]).unwrap();
    let mut ws = Workspace::new(&m);
    // free spin: the step map turns the wheel by 2 asin(h ω / 2) a step (ω the constant
    // midpoint velocity)
    let per_step = 2.0 * (0.01 * 5.0 / 2.0_f64).asin();
    for k in 1..=600 {
        step_ok(&m, &mut s, &mut ws, &[]);
        let want = per_step * k as f64;
        assert!(
            (qpos(&m, &s)[0] - want).abs() < 1e-9,
            "step {k}: {:?}",
            qpos(&m, &s)
        );
    }
    assert!(qpos(&m, &s)[0] > 4.0 * PI);
    // backwards too, from a wound start
    set_minimal(&m, &mut s, &[7.0], &[-5.0]).unwrap();
    assert!((qpos(&m, &s)[0] - 7.0).abs() < 1e-12);
    for _ in 0..300 {
        step_ok(&m, &mut s, &mut ws, &[]);
    }
    let want = 7.0 - 300.0 * per_step;
    assert!(
        (qpos(&m, &s)[0] - want).abs() < 1e-9,
        "{:?} vs {want}",
        qpos(&m, &s)
    );
    // the turns travel with the state's snapshot
    let back = State::from_snapshot(&m, &s.snapshot()).unwrap();
    assert_eq!(qpos(&m, &back), qpos(&m, &s));
}

#[test]
fn set_minimal_keeps_the_turns_of_an_angle_at_the_wrap() {
    let m = wheel(0.0);
    let mut s = State::reference(&m);
    for angle in [PI, -PI, 3.0 * PI, TAU, -TAU, 1e3] {
        set_minimal(&m, &mut s, &[angle], &[0.0]).unwrap();
        let q = qpos(&m, &s)[0];
        assert!(
            (q - angle).abs() < 1e-9 * angle.abs().max(1.0),
            "{angle}: {q}"
        );
    }
}

#[test]
fn a_wound_spring_unwinds_through_its_turns() {
    // wound one and a half turns: it swings between ±3π (energy ½ k (3π)², conserved by the
    // variational integrator up to its O(h²) oscillation); unwound it would swing ±π
    let (k, inertia) = (2.0, 0.2);
    let m = wheel(k);
    let mut s = State::reference(&m);
    set_minimal(&m, &mut s, &[3.0 * PI], &[0.0]).unwrap();
    let mut ws = Workspace::new(&m);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let period = TAU * (inertia / k).sqrt();
    for _ in 0..(1.5 * period / 0.01) as usize {
        step_ok(&m, &mut s, &mut ws, &[]);
        let q = qpos(&m, &s)[0];
        (lo, hi) = (lo.min(q), hi.max(q));
    }
    eprintln!("swing {lo:.4} .. {hi:.4} (±{:.4})", 3.0 * PI);
    assert!(
        (lo + 3.0 * PI).abs() < 1e-2 && (hi - 3.0 * PI).abs() < 1e-2,
        "{lo} {hi}"
    );
    let v = qvel(&m, &s)[0];
    assert!(v.is_finite());
}

#[test]
fn jacobians_hold_across_the_wrap_and_on_wound_angles() {
    let m = wheel(0.5);
    for (angle, rate) in [(PI - 0.01, 2.0), (-PI + 0.005, -1.0), (7.0, 3.0)] {
        let mut s = State::reference(&m);
        set_minimal(&m, &mut s, &[angle], &[rate]).unwrap();
        for coords in [Coordinates::Minimal, Coordinates::Maximal] {
            let e = grad_check::check(&m, &s, &[], coords, None, 1e-6);
            eprintln!("angle {angle} rate {rate} {coords:?}: max rel err {e:e}");
        }
        grad_check::check_rollout_vjp(&m, &s, 5, None);
    }
}

#[test]
fn a_tendon_over_a_winding_hinge_has_no_jump_and_meets_its_limit() {
    // L = θ limited to [-1, 8] rad: a wheel spun at 5 rad/s passes ±π with L going on (it used
    // to jump by -2π there) and stops at L = 8, 2.5 rad past the wrap
    use ukemi_engine::model::TendonLimitSpec;
    let mut b = ModelBuilder::new().timestep(0.01).gravity([0.0; 3]);
    b.add_body(BodySpec::new("wheel", 1.0, [0.1, 0.2, 0.1]));
    b.add_joint(
        JointSpec::new("axle", JointKind::Revolute, "world", "wheel").axis([0.0, 1.0, 0.0]),
    );
    b.add_tendon_limit(TendonLimitSpec {
        name: "t".into(),
        terms: vec![("axle".into(), 0, 1.0)],
        range: (-1.0, 8.0),
    });
    let m = b.compile().unwrap();
    let mut s = State::reference(&m);
    set_minimal(&m, &mut s, &[0.0], &[5.0]).unwrap();
    let mut ws = Workspace::new(&m);
    let mut last = 0.0;
    for _ in 0..300 {
        step_ok(&m, &mut s, &mut ws, &[]);
        let len = s.tendon_length(&m)[0];
        // (after the stop the wheel rests against the limit with no load: it leaves it only
        // by the interior point's degenerate complementarity, ~1e-6 rad a step)
        assert!(
            (len - last).abs() < 0.06 && len <= 8.0 + 1e-9,
            "{last} -> {len}"
        );
        last = len;
    }
    assert!((last - 8.0).abs() < 1e-3, "{last}");
    assert!(qvel(&m, &s)[0].abs() < 1e-3);
}
