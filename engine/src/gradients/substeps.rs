//! Gradients through a subdivided step.
//!
//! When the solve of a whole step fails, [`crate::step`] takes it as `n` equal sub-steps of
//! `h / n` under the same control (`Options::max_subdivisions`). The step map is then the
//! composition `x⁺ = F_n ∘ … ∘ F_1 (x)` of sub-step maps of the model with time step `h / n`,
//! and its derivatives are the chain rule over the sub-steps, each linearised at its own
//! solution exactly as a whole step is (`SolveLinearization`, with its own move to the central
//! path at `kappa_grad`):
//!
//! ```text
//! A = J_out A_n ⋯ A_1 J_in      B = J_out Σ_i A_n ⋯ A_{i+1} B_i      C likewise with C_i S
//! ```
//!
//! The sub-steps are chained in maximal coordinates, since a subdivided step never passes
//! through minimal coordinates between its sub-steps. In minimal coordinates `J_in` (maximal
//! tangent of the start ← minimal tangent) and `J_out` (minimal tangent of the end ← maximal
//! tangent) are derivatives of forward kinematics and of `qpos`/`qvel`, smooth explicit maps,
//! taken by central differences like the other partials. `S` scales the time-step parameter by
//! `1 / n`: a sub-step's time step is `h / n`.
//!
//! Accuracy: maximal Jacobians carry large entries in the directions that break a joint (the
//! next step pulls the joint back within one step, ~1/h), which cancel in minimal coordinates;
//! the partials' central differences (~1e-7 relative) then show up amplified. Measured on a
//! hinge spun at 300 rad/s in 4 sub-steps: maximal A within 8e-8 of finite differences relative
//! to its largest entry (1.2e3), minimal A within 1.5e-6 (largest entry 1.4).
use nalgebra::{DMatrix, DVector};

use super::tangent::{Coordinates, Point};
use super::{
    Adjoints, FD_STEP, Jacobians, PartialsMethod, PhaseTimes, SolveLinearization, StoredSolution,
    StoredStep, Wrt, check_adjoint, check_tangents, not_converged,
};
use crate::model::Model;
use crate::model::params::Param;
use crate::solver::newton;
use crate::state::{State, StepReport, Workspace};
use crate::step::{
    AppliedForces, energy_ceiling, long_solve, pyramid_step, rotation_substeps, subdivided_with,
    substep_model, suspect, warm_started_from, whole_step,
};
use crate::{Result, ensure};

/// What a forward pass keeps of a subdivided step: each sub-step's start and solution.
#[derive(Clone, Debug)]
pub(crate) struct StoredSubsteps {
    n: u32,
    starts: Vec<State>,
    solutions: Vec<StoredSolution>,
    next: State,
    report: StepReport,
}

impl StoredSubsteps {
    /// Bytes of its arrays.
    pub(crate) fn heap_bytes(&self) -> usize {
        let starts: usize = self.starts.iter().map(State::heap_bytes).sum();
        let sols: usize = self.solutions.iter().map(StoredSolution::heap_bytes).sum();
        starts + sols + self.next.heap_bytes()
    }

    /// The state the step ends in (what [`crate::step`] returns).
    pub(crate) fn next(&self) -> &State {
        &self.next
    }
}

/// What [`crate::step`] makes of a whole-step solve from `state` (solution in `ws`, report
/// `whole`): kept when it converged and is not [`suspect`] (gained energy, or turned a body
/// further than `max_step_rotation`), else taken as
/// sub-steps when `max_subdivisions` allows and a subdivision succeeds, else kept if it
/// converged, else all of that from the impulses of the step with pyramid friction cones
/// (`Options::pyramid_fallback`), else (with `drop_redundant_friction`) all of that again on
/// the exact problem, else an error. A kept whole step's solution is in `ws` (as after its
/// solve) and in the returned [`StoredSolution`].
pub(crate) fn retry(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    ctrl: &[f64],
    whole: StepReport,
) -> Result<StoredStep> {
    let error = match attempts(model, state, ws, ctrl, whole) {
        Err(e) => e,
        kept => return kept,
    };
    // as `crate::step` does after that: the exact cones warm-started from the impulses of the
    // step with pyramid cones (the warm start changes where the solve begins, not the problem:
    // linearised as any step)
    let none = AppliedForces::default();
    let pyramid = pyramid_step(model, state, ctrl, &none)?;
    if let Some(warm) = pyramid.and_then(|(p, _)| warm_started_from(state, &p)) {
        // (the whole step only, as `crate::step` takes it)
        if let (report, Some(_)) = whole_step(model, &warm, ws, ctrl, &none) {
            return Ok(StoredStep::Whole(StoredSolution::of(ws, report)));
        }
    }
    // then the exact problem, without the friction that `drop_redundant_friction` holds (its
    // solution then holds none of it, and is linearised as such)
    if model.options.drop_redundant_friction {
        let exact = model.with_options(crate::Options {
            drop_redundant_friction: false,
            ..model.options.clone()
        })?;
        newton::prepare(&exact, state, ws, ctrl, &none);
        let report = newton::solve(&exact, state, ws);
        if let Ok(kept) = attempts(&exact, state, ws, ctrl, report) {
            return Ok(kept);
        }
    }
    Err(error)
}

/// [`retry`] with the options of `model` only.
fn attempts(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    ctrl: &[f64],
    whole: StepReport,
) -> Result<StoredStep> {
    let solution = StoredSolution::of(ws, whole);
    let converged = whole.status.is_success();
    let (mut first, mut ceiling) = (2, None);
    if converged {
        let mut next = state.clone();
        newton::write_state(model, &mut next, ws);
        if !suspect(model, state, &next, ws) {
            return Ok(StoredStep::Whole(solution));
        }
        first = rotation_substeps(model, &next);
        ceiling = Some(energy_ceiling(model, state, &next));
    }
    if model.options.max_subdivisions == 1 {
        ensure!(converged, not_converged("step", whole));
        return Ok(StoredStep::Whole(solution));
    }
    match solve(model, state, ws, ctrl, whole, first, ceiling) {
        Ok(sub) => Ok(StoredStep::Substeps(sub)),
        Err(e) if !converged => {
            match long_solve(model, state, ws, ctrl, &Default::default(), false)? {
                Ok((_, report)) => Ok(StoredStep::Whole(StoredSolution::of(ws, report))),
                Err(_) => Err(e),
            }
        }
        Err(_) => {
            // the sub-steps overwrote `ws`: back to the whole step's solution
            newton::prepare(model, state, ws, ctrl, &AppliedForces::default());
            ws.w.copy_from_slice(&solution.w);
            ws.active.copy_from_slice(&solution.active);
            ws.saturated.copy_from_slice(&solution.saturated);
            // and the features it ended with (`activation::refreeze_disks` may have moved one)
            let features = solution.frozen.iter().copied();
            crate::solver::activation::prepare_candidates_holding(model, state, ws, features);
            newton::evaluate(model, state, ws, false, 0.0);
            Ok(StoredStep::Whole(solution))
        }
    }
}

/// Take the step from `state`, whose whole solve failed (or gained energy) with `failed`, as
/// sub-steps, the way [`crate::step`] does, keeping every sub-step's start and solution.
pub(crate) fn solve(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    ctrl: &[f64],
    failed: StepReport,
    first: u32,
    ceiling: Option<f64>,
) -> Result<StoredSubsteps> {
    let (mut starts, mut solutions) = (Vec::new(), Vec::new());
    let mut next = state.clone();
    let outcome = subdivided_with(
        model,
        &mut next,
        ws,
        ctrl,
        &AppliedForces::default(),
        failed.status.is_success(),
        first,
        ceiling,
        true,
        &mut |_, i, start, ws, report| {
            if i == 0 {
                starts.clear();
                solutions.clear();
            }
            starts.push(start.clone());
            solutions.push(StoredSolution::of(ws, report));
        },
    )?;
    match outcome {
        Ok(report) => Ok(StoredSubsteps {
            n: report.subdivisions,
            starts,
            solutions,
            next,
            report: StepReport {
                iterations: report.iterations + failed.iterations,
                ..report
            },
        }),
        Err(iterations) => Err(not_converged(
            &format!(
                "step (also as up to {} sub-steps)",
                model.options.max_subdivisions
            ),
            StepReport {
                iterations: iterations + failed.iterations,
                ..failed
            },
        )),
    }
}

/// A subdivided step linearised sub-step by sub-step (see the module docs).
pub(crate) struct Substeps {
    coords: Coordinates,
    /// The model with time step `h / n`.
    sub: Model,
    n: usize,
    steps: Vec<SolveLinearization>,
    /// Maximal tangent of the start ← minimal tangent (`None` in maximal coordinates).
    j_in: Option<DMatrix<f64>>,
    /// Minimal tangent of the end ← maximal tangent (`None` in maximal coordinates).
    j_out: Option<DMatrix<f64>>,
    next: State,
    report: StepReport,
    wrt: Wrt,
    /// Column of the time step among the selected parameters.
    timestep: Option<usize>,
}

impl Substeps {
    /// Linearise every sub-step of `stored` (taken from `point.state`) in maximal coordinates,
    /// the first in `ws`.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        model: &Model,
        point: Point,
        ctrl: &[f64],
        wrt: Wrt,
        kappa_grad: Option<f64>,
        stored: &StoredSubsteps,
        ws: Workspace,
        method: PartialsMethod,
    ) -> Result<Substeps> {
        let sub = substep_model(model, stored.n)?;
        // later sub-steps need their state Jacobians to chain whatever the caller selected
        let inner = Wrt { state: true, ..wrt };
        let mut spare = Some(ws);
        let mut steps = Vec::with_capacity(stored.starts.len());
        for (i, (start, sol)) in stored.starts.iter().zip(&stored.solutions).enumerate() {
            let ws = spare.take().unwrap_or_else(|| Workspace::new(&sub));
            let lin = SolveLinearization::from_stored(
                &sub,
                start,
                ctrl,
                Coordinates::Maximal,
                inner,
                kappa_grad,
                sol,
                ws,
                method,
            )
            .map_err(|e| e.at(format!(" (sub-step {i} of {})", stored.n)))?;
            steps.push(lin);
        }
        let (j_in, j_out) = match point.coords {
            Coordinates::Maximal => (None, None),
            Coordinates::Minimal => (
                Some(minimal_to_maximal(model, &point)),
                Some(maximal_to_minimal(model, &stored.next)?),
            ),
        };
        let timestep = wrt
            .params
            .then(|| {
                model
                    .param_layout()
                    .iter()
                    .position(|p| *p == Param::Timestep)
            })
            .flatten();
        Ok(Substeps {
            coords: point.coords,
            sub,
            n: stored.n as usize,
            steps,
            j_in,
            j_out,
            next: stored.next.clone(),
            report: stored.report,
            wrt,
            timestep,
        })
    }

    pub(crate) fn steps(&self) -> &[SolveLinearization] {
        &self.steps
    }
    pub(crate) fn into_workspace(self) -> Workspace {
        self.steps
            .into_iter()
            .next()
            .map(SolveLinearization::into_workspace)
            .unwrap_or_else(|| Workspace::new(&self.sub))
    }
    pub(crate) fn next_state(&self) -> &State {
        &self.next
    }
    pub(crate) fn report(&self) -> StepReport {
        self.report
    }
    pub(crate) fn coordinates(&self) -> Coordinates {
        self.coords
    }
    /// The sub-steps' central-path reports, iterations summed (the last one's status and
    /// residuals: every one converged, or the linearisation would have failed).
    pub(crate) fn central_report(&self) -> Option<StepReport> {
        let reports: Vec<StepReport> = self
            .steps
            .iter()
            .filter_map(|s| s.central_report())
            .collect();
        let last = *reports.last()?;
        Some(StepReport {
            iterations: reports.iter().map(|r| r.iterations).sum(),
            ..last
        })
    }
    pub(crate) fn phase_times(&self) -> PhaseTimes {
        let mut t = PhaseTimes::default();
        for s in &self.steps {
            let p = s.phase_times();
            t.solve += p.solve;
            t.central += p.central;
            t.factor += p.factor;
            t.partials += p.partials;
            t.backsub += p.backsub;
        }
        t
    }

    /// Sizes of the selected inputs `(state, ctrl, params)` and of the output tangent.
    fn sizes(&self, model: &Model) -> (usize, usize, usize, usize) {
        let ny = self.coords.dim(model);
        let nx = if self.wrt.state { ny } else { 0 };
        let nu = if self.wrt.ctrl { model.nu() } else { 0 };
        let np = if self.wrt.params {
            model.param_layout().len()
        } else {
            0
        };
        (nx, nu, np, ny)
    }

    /// A sub-step's parameter tangent or adjoint from the step's: the time step's entry / n.
    fn scale_timestep(&self, v: &mut [f64]) {
        if let Some(t) = self.timestep {
            v[t] /= self.n as f64;
        }
    }

    pub(crate) fn jacobians(&mut self, model: &Model) -> Result<Jacobians> {
        let (nx, nu, np, ny) = self.sizes(model);
        let dim = Coordinates::Maximal.dim(model);
        // Jacobians of the maximal state after each sub-step with respect to (x, u, θ)
        let mut a = match &self.j_in {
            Some(j) => j.clone(),
            None => DMatrix::identity(dim, dim),
        };
        let (mut b, mut c) = (DMatrix::zeros(dim, nu), DMatrix::zeros(dim, np));
        for step in &mut self.steps {
            let j = step.jacobians(&self.sub)?;
            a = &j.a * &a;
            b = &j.a * &b + &j.b;
            let mut ci = j.c;
            if let Some(t) = self.timestep {
                ci.column_mut(t).scale_mut(1.0 / self.n as f64);
            }
            c = &j.a * &c + ci;
        }
        let out = |m: DMatrix<f64>| match &self.j_out {
            Some(j) => j * m,
            None => m,
        };
        Ok(Jacobians {
            a: if nx > 0 {
                out(a)
            } else {
                DMatrix::zeros(ny, 0)
            },
            b: out(b),
            c: out(c),
        })
    }

    pub(crate) fn vjp(&mut self, model: &Model, adj_next: &[f64]) -> Result<Adjoints> {
        let (nx, nu, np, ny) = self.sizes(model);
        check_adjoint(ny, adj_next)?;
        let mut adj: Vec<f64> = match &self.j_out {
            Some(j) => j
                .tr_mul(&DVector::from_column_slice(adj_next))
                .as_slice()
                .to_vec(),
            None => adj_next.to_vec(),
        };
        let (mut ctrl, mut params) = (vec![0.0; nu], vec![0.0; np]);
        for step in self.steps.iter_mut().rev() {
            let a = step.vjp(&self.sub, &adj)?;
            for (x, g) in ctrl.iter_mut().zip(&a.ctrl) {
                *x += g;
            }
            for (x, g) in params.iter_mut().zip(&a.params) {
                *x += g;
            }
            adj = a.state;
        }
        self.scale_timestep(&mut params);
        let state = match (&self.j_in, nx) {
            (_, 0) => vec![],
            (Some(j), _) => j.tr_mul(&DVector::from_vec(adj)).as_slice().to_vec(),
            (None, _) => adj,
        };
        Ok(Adjoints {
            state,
            ctrl,
            params,
        })
    }

    pub(crate) fn jvp(
        &mut self,
        model: &Model,
        dx: &[f64],
        du: &[f64],
        dtheta: &[f64],
    ) -> Result<Vec<f64>> {
        let (nx, nu, np, _) = self.sizes(model);
        check_tangents([(dx, nx), (du, nu), (dtheta, np)])?;
        let dim = Coordinates::Maximal.dim(model);
        let mut t: Vec<f64> = match (&self.j_in, nx) {
            (_, 0) => vec![0.0; dim],
            (Some(j), _) => (j * DVector::from_column_slice(dx)).as_slice().to_vec(),
            (None, _) => dx.to_vec(),
        };
        let mut dtheta_sub = dtheta.to_vec();
        self.scale_timestep(&mut dtheta_sub);
        for step in &mut self.steps {
            t = step.jvp(&self.sub, &t, du, &dtheta_sub)?;
        }
        Ok(match &self.j_out {
            Some(j) => (j * DVector::from_vec(t)).as_slice().to_vec(),
            None => t,
        })
    }
}

/// `∂ maximal(x ⊕ δ) / ∂δ` at the minimal point `point` (maximal tangent, `12 (nbody - 1) × 2 nv`),
/// by central differences of forward kinematics.
fn minimal_to_maximal(model: &Model, point: &Point) -> DMatrix<f64> {
    let mut base = point.clone();
    base.coords = Coordinates::Maximal;
    let (n_in, n_out) = (
        Coordinates::Minimal.dim(model),
        Coordinates::Maximal.dim(model),
    );
    let mut scratch = vec![0.0; Point::scratch_len(model)];
    let (mut plus, mut minus) = (point.state.clone(), point.state.clone());
    let (mut yp, mut ym) = (vec![0.0; n_out], vec![0.0; n_out]);
    let mut dir = vec![0.0; n_in];
    let mut j = DMatrix::zeros(n_out, n_in);
    for k in 0..n_in {
        dir.fill(0.0);
        dir[k] = 1.0;
        plus.clone_from(&point.state);
        minus.clone_from(&point.state);
        point.perturbed(model, &dir, FD_STEP, &mut plus, &mut scratch);
        point.perturbed(model, &dir, -FD_STEP, &mut minus, &mut scratch);
        base.difference(model, &plus, &mut yp, &mut scratch);
        base.difference(model, &minus, &mut ym, &mut scratch);
        for r in 0..n_out {
            j[(r, k)] = (yp[r] - ym[r]) / (2.0 * FD_STEP);
        }
    }
    j
}

/// `∂ minimal(s ⊕ δ) / ∂δ` at the maximal state `end` (`2 nv × 12 (nbody - 1)`), by central
/// differences of `qpos` and `qvel`.
fn maximal_to_minimal(model: &Model, end: &State) -> Result<DMatrix<f64>> {
    let at = Point::new(model, end, Coordinates::Maximal)?;
    let mut minimal = at.clone();
    minimal.coords = Coordinates::Minimal;
    let (n_in, n_out) = (
        Coordinates::Maximal.dim(model),
        Coordinates::Minimal.dim(model),
    );
    let mut scratch = vec![0.0; Point::scratch_len(model)];
    let (mut plus, mut minus) = (end.clone(), end.clone());
    let (mut yp, mut ym) = (vec![0.0; n_out], vec![0.0; n_out]);
    let mut dir = vec![0.0; n_in];
    let mut j = DMatrix::zeros(n_out, n_in);
    for k in 0..n_in {
        dir.fill(0.0);
        dir[k] = 1.0;
        // a maximal perturbation writes only the bodies it moves
        plus.clone_from(end);
        minus.clone_from(end);
        at.perturbed(model, &dir, FD_STEP, &mut plus, &mut scratch);
        at.perturbed(model, &dir, -FD_STEP, &mut minus, &mut scratch);
        minimal.difference(model, &plus, &mut yp, &mut scratch);
        minimal.difference(model, &minus, &mut ym, &mut scratch);
        for r in 0..n_out {
            j[(r, k)] = (yp[r] - ym[r]) / (2.0 * FD_STEP);
        }
    }
    Ok(j)
}
