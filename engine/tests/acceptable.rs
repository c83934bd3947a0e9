//! The "acceptable" status: a solve that stalls on round-off before the tight tolerances ends
//! as `Acceptable` (a success) only within `acceptable_rtol` / `acceptable_kappa_tol`, reports
//! its residual honestly, and is a failure when acceptance is turned off.
#[path = "common/contact.rs"]
mod common;
use common::*;
use ukemi_engine::{ContactModel, Model, ModelBuilder, Shape, SolveStatus, State, Workspace, step};

/// A 1 kg box dropped flat on the floor (four corner contacts: statically indeterminate).
fn box_model() -> Model {
    let b = floor(ModelBuilder::new().timestep(0.01), 0.8);
    free_body(
        b,
        "box",
        1.0,
        Shape::Box {
            half_extents: [0.1, 0.1, 0.1].into(),
        },
        [0.0, 0.0, 0.15],
        [1.0, 0.0, 0.0, 0.0],
        0.8,
        ContactModel::Nonlinear,
    )
    .compile()
    .unwrap()
}

/// Statuses and final state of 100 steps.
fn statuses(model: &Model) -> (Vec<(SolveStatus, f64, f64)>, State) {
    let mut state = State::reference(model);
    let mut ws = Workspace::new(model);
    let reports = (0..100)
        .map(|_| {
            let r = step(model, &mut state, &mut ws, &[]).unwrap();
            (r.status, r.residual, r.complementarity)
        })
        .collect();
    (reports, state)
}

#[test]
fn unreachable_tolerance_ends_acceptable_within_the_acceptable_bounds() {
    let base = box_model();
    let mut o = base.options.clone();
    // below the round-off of the momentum rows (m g h ≈ 0.1 N·s): never reachable
    o.rtol = 1e-20;
    let (reports, state) = statuses(&base.with_options(o.clone()).unwrap());
    let acceptable = reports
        .iter()
        .filter(|r| r.0 == SolveStatus::Acceptable)
        .count();
    assert!(acceptable > 50, "{acceptable} acceptable steps");
    for &(status, residual, complementarity) in &reports {
        assert!(status.is_success(), "{status:?}");
        if status == SolveStatus::Acceptable {
            assert!(residual < o.acceptable_rtol && complementarity < o.acceptable_kappa_tol);
            assert!(
                residual >= o.rtol,
                "an acceptable step reports its true residual"
            );
        }
    }
    // the acceptable trajectory is the converged one to the acceptable tolerance
    let (_, reference) = statuses(&base);
    let dz = (state.pose(1).pos - reference.pose(1).pos).norm();
    assert!(dz < 1e-8, "acceptable trajectory differs by {dz:e} m");

    // with acceptance off the same stalls are failures (the first steps are free fall, whose
    // residual can be exactly zero; the stalls come with contact)
    o.acceptable_rtol = 0.0;
    let (reports, _) = statuses(&base.with_options(o).unwrap());
    let failed = reports.iter().filter(|r| !r.0.is_success()).count();
    assert!(failed > 0, "no step failed with acceptance off");
}
