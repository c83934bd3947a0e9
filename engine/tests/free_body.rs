//! Free rigid body with a non-diagonal inertia, no gravity: discrete linear and angular momentum
//! are conserved to round-off, energy oscillates without drift, and a spin about the intermediate
//! principal axis flips (the Dzhanibekov effect).
mod common;
use common::*;
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use ukemi_engine::{BodySpec, JointKind, JointSpec, ModelBuilder, State, Workspace, mechanics};

/// Principal moments (1, 2, 3) rotated into a body frame where the inertia is full.
fn tumbling_body(h: f64) -> (ukemi_engine::Model, Matrix3<f64>) {
    let rot = UnitQuaternion::from_euler_angles(0.3, -0.7, 1.1)
        .to_rotation_matrix()
        .into_inner();
    let inertia = rot * Matrix3::from_diagonal(&Vector3::new(1.0, 2.0, 3.0)) * rot.transpose();
    let mut opts_builder = ModelBuilder::new().timestep(h).gravity([0.0; 3]);
    opts_builder.options.rtol = 1e-14;
    let model = opts_builder
        .body(
            BodySpec::new("box", 2.0, [1.0, 1.0, 1.0])
                .inertia_matrix(inertia)
                .pos([0.1, 0.2, 0.3]),
        )
        .joint(JointSpec::new("free", JointKind::Floating, "world", "box"))
        .compile()
        .unwrap();
    (model, rot)
}

#[test]
fn momentum_conserved_energy_bounded_and_intermediate_axis_flips() {
    let h = 0.005;
    let (model, rot) = tumbling_body(h);
    let intermediate = rot.column(1).into_owned(); // principal axis of moment 2, body frame
    let mut state = State::reference(&model);
    let spin = intermediate * 2.0 + rot.column(0) * 1e-3 + rot.column(2) * 1e-3;
    state.set_velocity(1, &Vector3::new(0.3, -0.2, 0.1), &spin);
    let mut ws = Workspace::new(&model);
    let (p0, l0, e0) = (
        mechanics::linear_momentum(&model, &state),
        mechanics::angular_momentum(&model, &state),
        energy(&model, &state),
    );
    let (mut dp, mut dl, mut de) = (0.0f64, 0.0f64, 0.0f64);
    let mut signs = Vec::new();
    for _ in 0..10_000 {
        step_ok(&model, &mut state, &mut ws, &[]);
        dp = dp.max((mechanics::linear_momentum(&model, &state) - p0).norm() / p0.norm());
        dl = dl.max((mechanics::angular_momentum(&model, &state) - l0).norm() / l0.norm());
        de = de.max((energy(&model, &state) - e0).abs() / e0);
        signs.push(state.velocity(1).1.dot(&intermediate).signum());
    }
    eprintln!("momentum drift linear {dp:.2e} angular {dl:.2e}, energy band {de:.2e}");
    assert!(dp < 1e-10, "linear momentum drift {dp:.3e}");
    assert!(dl < 1e-10, "angular momentum drift {dl:.3e}");
    assert!(de < 1e-6, "energy oscillation {de:.3e}");
    let flips = signs.windows(2).filter(|w| w[0] != w[1]).count();
    assert!(
        flips >= 2,
        "intermediate-axis spin never flipped ({flips} sign changes)"
    );
}

#[test]
fn major_axis_spin_is_stable() {
    // the same body spun about its largest principal axis does not flip
    let (model, rot) = tumbling_body(0.005);
    let major = rot.column(2).into_owned();
    let mut state = State::reference(&model);
    state.set_velocity(1, &Vector3::zeros(), &(major * 2.0 + rot.column(1) * 1e-3));
    let mut ws = Workspace::new(&model);
    for _ in 0..4000 {
        step_ok(&model, &mut state, &mut ws, &[]);
        assert!(state.velocity(1).1.dot(&major) > 1.9);
    }
}
