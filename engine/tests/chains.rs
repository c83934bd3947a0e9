//! Double pendulum, 10-link chain and a four-bar linkage: every joint constraint holds to 1e-8
//! at every step, energy stays bounded, and the closed loop stays closed.
mod common;
use common::*;
use ukemi_engine::{
    BodySpec, JointKind, JointSpec, Model, ModelBuilder, State, Workspace, set_minimal,
};

/// Release a chain of `n` links with the top joint at 0.5 rad; returns the max constraint
/// violation and the max |energy error| (J) over `duration` seconds.
fn run_chain(n: usize, h: f64, duration: f64) -> (f64, f64) {
    let model = chain(n, h);
    let mut state = State::reference(&model);
    let q0: Vec<f64> = (0..n)
        .map(|i| if i == 0 { 0.5 } else { 0.1 * (i as f64).sin() })
        .collect();
    set_minimal(&model, &mut state, &q0, &vec![0.0; n]).unwrap();
    let mut ws = Workspace::new(&model);
    let e0 = energy(&model, &state);
    let (mut viol, mut band) = (0.0f64, 0.0f64);
    for _ in 0..(duration / h).round() as usize {
        step_ok(&model, &mut state, &mut ws, &[]);
        viol = viol.max(constraint_violation(&model, &state));
        band = band.max((energy(&model, &state) - e0).abs());
    }
    (viol, band)
}

#[test]
fn double_pendulum_keeps_constraints_and_energy() {
    let (viol, band) = run_chain(2, 0.005, 20.0);
    eprintln!("double pendulum: violation {viol:.2e}, energy band {band:.2e} J");
    assert!(viol <= 1e-8, "constraint violation {viol:.3e}");
    assert!(band < 1e-3, "energy band {band:.3e} J (drop energy ~1.5 J)");
}

#[test]
fn ten_link_chain_keeps_constraints_and_energy_error_is_second_order() {
    let (viol, band) = run_chain(10, 0.005, 10.0);
    let (_, band_half) = run_chain(10, 0.0025, 10.0);
    eprintln!(
        "10-link chain: violation {viol:.2e}, energy band {band:.2e} J, at h/2 {band_half:.2e} J"
    );
    assert!(viol <= 1e-8, "constraint violation {viol:.3e}");
    assert!(band < 1e-2, "energy band {band:.3e} J");
    // a variational integrator's energy error is O(h²) and bounded: halving h divides it by ~4
    let ratio = band / band_half;
    assert!(
        (3.0..5.0).contains(&ratio),
        "energy error ratio for h -> h/2 is {ratio:.2}, expected ~4"
    );
}

/// Planar four-bar in the x-z plane: ground pivots at x = 0 and x = 2, crank 1, coupler 2,
/// rocker 1 (a parallelogram when started square); hinge axes along y; the rocker is closed to
/// the ground by a loop joint.
fn fourbar(h: f64) -> Model {
    let rod = |len: f64| [len * len / 12.0, len * len / 12.0, 1e-3];
    ModelBuilder::new()
        .timestep(h)
        .body(BodySpec::new("crank", 1.0, rod(1.0)).pos([0.0, 0.0, 0.5]))
        .body(BodySpec::new("coupler", 1.0, [1e-3, 4.0 / 12.0, 4.0 / 12.0]).pos([1.0, 0.0, 1.0]))
        .body(BodySpec::new("rocker", 1.0, rod(1.0)).pos([2.0, 0.0, 0.5]))
        .joint(
            JointSpec::new("ground_crank", JointKind::Revolute, "world", "crank")
                .axis([0.0, 1.0, 0.0])
                .anchors([0.0; 3], [0.0, 0.0, -0.5]),
        )
        .joint(
            JointSpec::new("crank_coupler", JointKind::Revolute, "crank", "coupler")
                .axis([0.0, 1.0, 0.0])
                .anchors([0.0, 0.0, 0.5], [-1.0, 0.0, 0.0]),
        )
        .joint(
            JointSpec::new("coupler_rocker", JointKind::Revolute, "coupler", "rocker")
                .axis([0.0, 1.0, 0.0])
                .anchors([1.0, 0.0, 0.0], [0.0, 0.0, 0.5]),
        )
        .joint(
            JointSpec::new("rocker_ground", JointKind::Revolute, "rocker", "world")
                .axis([0.0, 1.0, 0.0])
                .anchors([0.0, 0.0, -0.5], [2.0, 0.0, 0.0])
                .closing_loop(),
        )
        .compile()
        .unwrap()
}

#[test]
fn four_bar_loop_stays_closed() {
    let model = fourbar(0.01);
    assert_eq!(model.nq, 3);
    let mut state = State::reference(&model);
    let mut ws = Workspace::new(&model);
    // push the crank sideways: the parallelogram swings under gravity
    set_minimal(&model, &mut state, &[0.0; 3], &[1.0, -1.0, 1.0]).unwrap();
    let e0 = energy(&model, &state);
    let (mut viol, mut band, mut swing) = (0.0f64, 0.0f64, 0.0f64);
    for _ in 0..3000 {
        step_ok(&model, &mut state, &mut ws, &[]);
        viol = viol.max(constraint_violation(&model, &state));
        band = band.max((energy(&model, &state) - e0).abs());
        swing = swing.max(ukemi_engine::qpos(&model, &state)[0].abs());
    }
    eprintln!("four-bar: violation {viol:.2e}, energy band {band:.2e}, max crank angle {swing:.3}");
    assert!(
        swing > 0.3,
        "the linkage should move (max crank angle {swing})"
    );
    assert!(viol <= 1e-8, "loop violation {viol:.3e}");
    assert!(band < 1e-2 * 9.81 * 3.0, "energy band {band:.3e}");
}
