//! `step` and `rollout`: the only place that sequences the modules (validate, prepare, solve,
//! write back).
use crate::model::Model;
use crate::solver::newton;
pub use crate::solver::newton::AppliedForces;
use crate::state::{SolveStatus, State, StepReport, Workspace};
use crate::{Error, Result, ensure};

/// Check a step's inputs: sizes, finiteness, and that state and workspace belong to `model`.
pub fn validate_inputs(
    model: &Model,
    state: &State,
    ws: &Workspace,
    ctrl: &[f64],
    forces: &AppliedForces,
) -> Result<()> {
    state.check_model(model)?;
    ensure!(
        ws.topology_id == model.topology_id(),
        Error::ModelMismatch {
            detail: "workspace was built for another model".into()
        }
    );
    ensure!(
        ctrl.len() == model.nu(),
        Error::shape("ctrl", &[model.nu()], &[ctrl.len()])
    );
    if let Some(i) = ctrl.iter().position(|x| !x.is_finite()) {
        return Err(Error::input(
            format!("ctrl[{i}]"),
            ctrl[i],
            "must be finite",
        ));
    }
    if let Some(q) = forces.qfrc {
        ensure!(
            q.len() == model.nv,
            Error::shape("qfrc_applied", &[model.nv], &[q.len()])
        );
        ensure!(
            q.iter().all(|x| x.is_finite()),
            Error::input("qfrc_applied", q, "must be finite")
        );
    }
    if let Some(x) = forces.xfrc {
        ensure!(
            x.len() == 6 * model.nbody(),
            Error::shape("xfrc_applied", &[model.nbody(), 6], &[x.len()])
        );
        ensure!(
            x.iter().all(|v| v.is_finite()),
            Error::input("xfrc_applied", x, "must be finite")
        );
    }
    Ok(())
}

/// Advance `state` by one time step with controls `ctrl` (length `nu`).
///
/// Returns a report; a solve that did not converge still writes its last iterate into `state`
/// (so it can be inspected) and says so in [`StepReport::status`].
///
/// ```
/// use ukemi_engine::{BodySpec, JointKind, JointSpec, ModelBuilder, State, Workspace, step};
/// let model = ModelBuilder::new()
///     .body(BodySpec::new("ball", 1.0, [0.1, 0.1, 0.1]).pos([0.0, 0.0, 1.0]))
///     .joint(JointSpec::new("free", JointKind::Floating, "world", "ball"))
///     .compile()
///     .unwrap();
/// let mut state = State::reference(&model);
/// let mut ws = Workspace::new(&model);
/// let report = step(&model, &mut state, &mut ws, &[]).unwrap();
/// assert_eq!(report.status.name(), "converged");
/// // free fall: z = 1 - g h² after one step of the variational integrator
/// assert!((state.com_pos[5] - (1.0 - 9.81 * 0.01 * 0.01)).abs() < 1e-12);
/// ```
pub fn step(
    model: &Model,
    state: &mut State,
    ws: &mut Workspace,
    ctrl: &[f64],
) -> Result<StepReport> {
    step_with(model, state, ws, ctrl, &AppliedForces::default())
}

/// [`step`] with applied generalized forces and body wrenches.
pub fn step_with(
    model: &Model,
    state: &mut State,
    ws: &mut Workspace,
    ctrl: &[f64],
    forces: &AppliedForces,
) -> Result<StepReport> {
    validate_inputs(model, state, ws, ctrl, forces)?;
    newton::prepare(model, state, ws, ctrl, forces);
    let report = newton::solve(model, state, ws);
    let failed = (!report.status.is_success()).then(|| state.clone());
    newton::write_state(model, state, ws);
    match failed {
        Some(start) if model.options.max_subdivisions > 1 => {
            // keep the failed iterate (written above) unless a subdivision succeeds
            let mut s = start;
            let sub = subdivided(model, &mut s, ws, ctrl, forces)?;
            Ok(match sub {
                Ok(r) => {
                    *state = s;
                    StepReport {
                        iterations: r.iterations + report.iterations,
                        ..r
                    }
                }
                Err(iterations) => StepReport {
                    iterations: iterations + report.iterations,
                    ..report
                },
            })
        }
        _ => Ok(report),
    }
}

/// A step whose solve failed, taken again as `n` = 2, 4, … ≤ `max_subdivisions` equal
/// sub-steps from `state` under the same control and forces. On success `state` holds the end
/// of the last sub-step with the impulses summed over the sub-steps ([`State::add_impulses`])
/// and the report; otherwise `Err(iterations spent)` and `state` is untouched.
fn subdivided(
    model: &Model,
    state: &mut State,
    ws: &mut Workspace,
    ctrl: &[f64],
    forces: &AppliedForces,
) -> Result<std::result::Result<StepReport, usize>> {
    subdivided_with(model, state, ws, ctrl, forces, &mut |_, _, _, _, _| {})
}

/// [`subdivided`], calling `solved(n, i, start, ws, report)` after sub-step `i` of an attempt
/// with `n` sub-steps converged, with the sub-step's start state and its solution in `ws` (the gradients
/// keep them to linearise every sub-step; an attempt that fails later is abandoned, and the next
/// attempt starts again at `i = 0`).
pub(crate) fn subdivided_with(
    model: &Model,
    state: &mut State,
    ws: &mut Workspace,
    ctrl: &[f64],
    forces: &AppliedForces,
    solved: &mut dyn FnMut(u32, usize, &State, &Workspace, StepReport),
) -> Result<std::result::Result<StepReport, usize>> {
    let h = model.options.timestep;
    let mut iterations = 0;
    let mut n = 2;
    while n <= model.options.max_subdivisions {
        let sub = substep_model(model, n)?;
        let mut report = StepReport {
            status: SolveStatus::Converged,
            iterations: 0,
            residual: 0.0,
            complementarity: 0.0,
            subdivisions: n,
        };
        let mut ends: Vec<State> = Vec::with_capacity(n as usize);
        let mut s = state.clone();
        for i in 0..n as usize {
            newton::prepare(&sub, &s, ws, ctrl, forces);
            let r = newton::solve(&sub, &s, ws);
            iterations += r.iterations;
            if !r.status.is_success() {
                report.status = r.status;
                break;
            }
            solved(n, i, &s, ws, r);
            if r.status == SolveStatus::Acceptable {
                report.status = SolveStatus::Acceptable;
            }
            report.residual = report.residual.max(r.residual);
            report.complementarity = report.complementarity.max(r.complementarity);
            newton::write_state(&sub, &mut s, ws);
            ends.push(s.clone());
        }
        if report.status.is_success() {
            // the last sub-step's poses, velocities and slacks; the whole step's impulses
            for end in &ends[..ends.len() - 1] {
                s.add_impulses(model, end);
            }
            s.time = state.time + h;
            *state = s;
            report.iterations = iterations;
            return Ok(Ok(report));
        }
        n *= 2;
    }
    Ok(Err(iterations))
}

/// The model a step of `model` is subdivided into: the same with time step `h / n`.
pub(crate) fn substep_model(model: &Model, n: u32) -> Result<Model> {
    model.with_options(crate::Options {
        timestep: model.options.timestep / n as f64,
        ..model.options.clone()
    })
}

/// Step `nstep` times with controls `ctrls` (row-major `(nstep, nu)`), calling `record` after every
/// step with the new state and its report. Stops at the first step that fails to converge when
/// `stop_on_failure` is set (the failing step is still recorded).
pub fn rollout(
    model: &Model,
    state: &mut State,
    ws: &mut Workspace,
    ctrls: &[f64],
    nstep: usize,
    stop_on_failure: bool,
    mut record: impl FnMut(usize, &State, &StepReport),
) -> Result<()> {
    let nu = model.nu();
    ensure!(
        ctrls.len() == nstep * nu,
        Error::shape("ctrls", &[nstep, nu], &[ctrls.len() / nu.max(1), nu])
    );
    for k in 0..nstep {
        let report = step(model, state, ws, &ctrls[k * nu..(k + 1) * nu])?;
        record(k, state, &report);
        if stop_on_failure && !report.status.is_success() {
            break;
        }
    }
    Ok(())
}
