//! Initial conditions from instantaneous velocities: the discrete Legendre transform.
//!
//! A state holds the *midpoint* velocities `v_{k-1/2}` of the step that led to it. A user who
//! knows the velocity at the state's time `t` (MuJoCo's `qvel`, an analytic initial condition)
//! needs the midpoint velocity whose trajectory passes `t` at that velocity. For the trapezoidal
//! discrete Lagrangian the momentum at `t` is `p = m v_{-1/2} + h/2 F = m v_{1/2} - h/2 F` (every
//! impulse of the step, constraint and contact ones included, split evenly), so the velocity at
//! `t` is the mean of the two midpoint velocities around it. Setting `v_{-1/2} = v₀` instead
//! starts the trajectory half a step late: a box launched at 2 m/s on a floor with μ = 0.5
//! stops `v₀ h / 2` short (2.4% at h = 0.01), a body thrown upwards lags its parabola by
//! `g h² / 2` after every step count.
//!
//! [`set_instant_velocity`] solves `(q̇(v_{-1/2}) + q̇(v_{1/2})) / 2 = q̇₀` in minimal coordinates
//! by fixed-point iteration on `v_{-1/2}`, each iteration one step of the model: exact after one
//! iteration when the step's impulses do not depend on the velocity (free flight, Coulomb
//! sliding), a few more otherwise.
use crate::joints::coordinates::{qvel, set_minimal};
use crate::model::Model;
use crate::state::{State, Workspace};
use crate::step::step;
use crate::{Error, Result, ensure};

/// Largest number of fixed-point iterations (steps) spent.
const MAX_ITER: usize = 50;

/// Set the velocities of `state` (at its configuration) so that its velocity at `state.time`,
/// the mean of the midpoint velocities before and after it, is `qvel0` (MuJoCo's `qvel`
/// convention) under controls `ctrl`. Returns the number of steps taken to find them; an error
/// if a step fails or the iteration does not reach round-off (`state` is then untouched). The
/// steps are solved to the default tolerances or the model's, whichever are tighter.
pub fn set_instant_velocity(
    model: &Model,
    state: &mut State,
    qvel0: &[f64],
    ctrl: &[f64],
) -> Result<usize> {
    ensure!(
        qvel0.len() == model.nv,
        Error::shape("qvel", &[model.nv], &[qvel0.len()])
    );
    Error::check_finite("qvel", qvel0)?;
    // the steps are solved at least as tightly as the defaults: at a loose tolerance (1e-2) the
    // solution jitters with the start velocity and the iteration cannot settle
    let defaults = crate::Options::default();
    let model = &model.with_options(crate::Options {
        rtol: model.options.rtol.min(defaults.rtol),
        kappa_tol: model.options.kappa_tol.min(defaults.kappa_tol),
        ..model.options.clone()
    })?;
    let qpos = crate::joints::coordinates::qpos(model, state);
    let scale = 1.0 + qvel0.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let mut ws = Workspace::new(model);
    let mut before = qvel0.to_vec();
    let mut trial = state.clone();
    let mut worst = f64::INFINITY;
    for iterations in 1..=MAX_ITER {
        trial.clone_from(state);
        set_minimal(model, &mut trial, &qpos, &before)?;
        let report = step(model, &mut trial, &mut ws, ctrl)?;
        ensure!(
            report.status.is_success(),
            Error::input(
                "qvel",
                qvel0,
                format!(
                    "the step that sets its instantaneous velocity did not converge ({})",
                    report.status.name()
                ),
            )
        );
        let after = qvel(model, &trial);
        worst = 0.0;
        for i in 0..model.nv {
            let miss = qvel0[i] - 0.5 * (before[i] + after[i]);
            worst = worst.max(miss.abs());
            before[i] += miss;
        }
        if worst <= 1e-12 * scale {
            set_minimal(model, state, &qpos, &before)?;
            return Ok(iterations);
        }
    }
    Err(Error::input(
        "qvel",
        qvel0,
        format!(
            "no midpoint velocity has this instantaneous velocity \
             ({MAX_ITER} iterations, last miss {worst:e})"
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{BodySpec, JointKind, JointSpec, ModelBuilder};

    #[test]
    fn a_thrown_body_follows_its_parabola_exactly() {
        // constant force: the variational trajectory from the instantaneous velocity is the
        // exact parabola at every step (from the midpoint convention it lags by g h²/2 · k)
        let h = 0.01;
        let m = ModelBuilder::new()
            .timestep(h)
            .body(BodySpec::new("ball", 1.0, [0.1, 0.1, 0.1]).pos([0.0, 0.0, 1.0]))
            .joint(JointSpec::new("free", JointKind::Floating, "world", "ball"))
            .compile()
            .unwrap();
        let v0 = [1.5, -0.5, 3.0, 0.0, 0.0, 0.0];
        let mut s = State::reference(&m);
        let iterations = set_instant_velocity(&m, &mut s, &v0, &[]).unwrap();
        assert!(iterations <= 2, "{iterations}");
        let g = m.options.gravity.z;
        let mut ws = Workspace::new(&m);
        for k in 1..=100 {
            step(&m, &mut s, &mut ws, &[]).unwrap();
            let t = k as f64 * h;
            let z = 1.0 + v0[2] * t + 0.5 * g * t * t;
            assert!(
                (s.com_pos[5] - z).abs() < 1e-12,
                "step {k}: {} vs {z}",
                s.com_pos[5]
            );
            assert!((s.com_pos[3] - v0[0] * t).abs() < 1e-12);
        }
    }

    #[test]
    fn bad_velocities_are_rejected_and_leave_the_state() {
        let m = ModelBuilder::new()
            .body(BodySpec::new("ball", 1.0, [0.1, 0.1, 0.1]).pos([0.0, 0.0, 1.0]))
            .joint(JointSpec::new("free", JointKind::Floating, "world", "ball"))
            .compile()
            .unwrap();
        let mut s = State::reference(&m);
        let before = s.clone();
        assert!(set_instant_velocity(&m, &mut s, &[0.0; 5], &[]).is_err());
        let nan = [0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0];
        let e = set_instant_velocity(&m, &mut s, &nan, &[]).unwrap_err();
        assert!(e.to_string().contains("qvel[1]"), "{e}");
        assert_eq!(s.com_pos, before.com_pos);
        assert_eq!(s.com_linvel, before.com_linvel);
    }
}
