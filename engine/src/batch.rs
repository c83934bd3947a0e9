//! Batches of independent full states stepped in parallel (rayon), one [`Workspace`] per
//! state: the engine side of the gymnasium environments.
//!
//! An environment step holds one control for `nstep` engine steps (gymnasium's `frame_skip`).
//! The full [`State`] is kept between environment steps — the integrator's midpoint
//! velocities and the solver's warm start (joint impulses, interior-point variables) — so an
//! environment's trajectory is exactly [`crate::rollout`]'s under the same controls.
use rayon::prelude::*;

use crate::contact::wrench::{ContactForces, contact_forces};
use crate::model::Model;
use crate::state::{SolveStatus, State, Workspace};
use crate::step::{AppliedForces, step, validate_inputs};
use crate::{Error, Result, ensure};

/// What one environment step of one state reports.
#[derive(Clone, Debug)]
pub struct EnvStep {
    /// The first failure's status; if none failed, `Acceptable` when any step ended so, else
    /// `Converged`.
    pub status: SolveStatus,
    /// Contact forces of the last engine step; zero when a step failed.
    pub forces: ContactForces,
}

fn zero_forces(model: &Model) -> ContactForces {
    ContactForces {
        force_c: vec![0.0; 3 * model.ncontact()],
        body_wrench: vec![0.0; 6 * model.nbody()],
    }
}

/// `nstep` steps of `state` in place under the constant control `ctrl`.
///
/// A step that fails (or a non-finite state) restores `state` to its input and is reported
/// in [`EnvStep::status`], never as an error; errors are bad inputs only.
pub fn env_step(
    model: &Model,
    state: &mut State,
    ws: &mut Workspace,
    ctrl: &[f64],
    nstep: usize,
) -> Result<EnvStep> {
    validate_inputs(model, state, ws, ctrl, &AppliedForces::default())?;
    let start = state.clone();
    let mut prev = start.clone();
    let mut status = SolveStatus::Converged;
    for k in 0..nstep {
        if k + 1 == nstep && k > 0 {
            prev.clone_from(state);
        }
        let report = step(model, state, ws, ctrl)?;
        let finite = [
            &state.com_pos,
            &state.quat,
            &state.com_linvel,
            &state.angvel_b,
        ]
        .iter()
        .all(|a| a.iter().all(|x| x.is_finite()));
        if !report.status.is_success() || !finite {
            *state = start;
            let status = if report.status.is_success() {
                SolveStatus::NonFinite
            } else {
                report.status
            };
            return Ok(EnvStep {
                status,
                forces: zero_forces(model),
            });
        }
        if report.status == SolveStatus::Acceptable {
            status = SolveStatus::Acceptable;
        }
    }
    let forces = if nstep == 0 {
        zero_forces(model)
    } else {
        contact_forces(model, &prev, state)
    };
    Ok(EnvStep { status, forces })
}

/// One environment step of the rows `rows` of `states` (in parallel), row `rows[k]` under
/// control `ctrls[k * nu..(k + 1) * nu]`. Returns one [`EnvStep`] per entry of `rows`.
///
/// Every input is checked before any state moves, so an error leaves all states untouched.
pub fn env_step_rows(
    model: &Model,
    states: &mut [State],
    workspaces: &mut [Workspace],
    rows: &[usize],
    ctrls: &[f64],
    nstep: usize,
) -> Result<Vec<EnvStep>> {
    let (n, nu) = (states.len(), model.nu());
    ensure!(
        workspaces.len() == n,
        Error::shape("workspaces", &[n], &[workspaces.len()])
    );
    ensure!(
        ctrls.len() == rows.len() * nu,
        Error::shape("ctrls", &[rows.len(), nu], &[ctrls.len() / nu.max(1), nu])
    );
    // which control each state gets (None: not stepped)
    let mut ctrl_of: Vec<Option<usize>> = vec![None; n];
    for (k, &r) in rows.iter().enumerate() {
        ensure!(
            r < n,
            Error::input(format!("rows[{k}]"), r, format!("must be < {n}"))
        );
        ensure!(
            ctrl_of[r].is_none(),
            Error::input(format!("rows[{k}]"), r, "appears twice")
        );
        ctrl_of[r] = Some(k);
        let u = &ctrls[k * nu..(k + 1) * nu];
        validate_inputs(
            model,
            &states[r],
            &workspaces[r],
            u,
            &AppliedForces::default(),
        )
        .map_err(|e| e.at(format!(" (row {r})")))?;
    }
    let run = || {
        states
            .par_iter_mut()
            .zip(workspaces.par_iter_mut())
            .zip(ctrl_of.par_iter())
            .map(|((s, ws), k)| match k {
                Some(k) => env_step(model, s, ws, &ctrls[k * nu..(k + 1) * nu], nstep).map(Some),
                None => Ok(None),
            })
            .collect::<Result<Vec<Option<EnvStep>>>>()
    };
    let mut out = crate::gradients::flat::in_pool(run)?;
    Ok(rows.iter().filter_map(|&r| out[r].take()).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hopper_like() -> Model {
        let xml = r#"<mujoco><option timestep="0.005"/><worldbody>
            <geom type="plane" size="5 5 0.1"/>
            <body pos="0 0 0.3"><freejoint/><geom type="capsule" fromto="0 0 0 0.2 0 0" size="0.05"/>
              <body pos="0.2 0 0"><joint name="j" type="hinge" axis="0 1 0"/>
                <geom type="capsule" fromto="0 0 0 0 0 -0.2" size="0.04"/></body></body>
            </worldbody><actuator><motor joint="j" gear="1"/></actuator></mujoco>"#;
        crate::mjcf::load_str(xml, "<string>")
            .unwrap_or_else(|e| panic!("{e}"))
            .model
    }

    #[test]
    fn env_steps_equal_a_rollout_bit_for_bit() {
        let model = hopper_like();
        let (nstep, ctrls) = (3, [0.4, -0.7, 0.2, 0.9]);
        let mut states = vec![State::reference(&model); 2];
        let mut wss = vec![Workspace::new(&model), Workspace::new(&model)];
        let mut reference = State::reference(&model);
        let mut ws = Workspace::new(&model);
        for &u in &ctrls {
            let out = env_step_rows(&model, &mut states, &mut wss, &[1, 0], &[u, u], nstep)
                .unwrap_or_else(|e| panic!("{e}"));
            assert!(out.iter().all(|o| o.status.is_success()));
            for _ in 0..nstep {
                step(&model, &mut reference, &mut ws, &[u]).unwrap_or_else(|e| panic!("{e}"));
            }
            assert_eq!(states[0], reference);
            assert_eq!(states[1], reference);
        }
    }

    #[test]
    fn bad_rows_and_controls_leave_every_state_untouched() {
        let model = hopper_like();
        let mut states = vec![State::reference(&model); 2];
        let mut wss = vec![Workspace::new(&model), Workspace::new(&model)];
        let before = states.clone();
        for (rows, ctrls) in [
            (vec![0, 2], vec![0.0, 0.0]),
            (vec![0, 0], vec![0.0, 0.0]),
            (vec![0, 1], vec![0.0, f64::NAN]),
        ] {
            assert!(env_step_rows(&model, &mut states, &mut wss, &rows, &ctrls, 2).is_err());
            assert_eq!(states, before);
        }
    }
}
