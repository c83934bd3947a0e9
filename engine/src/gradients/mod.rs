//! Implicit gradients of a step (Dojo §III-B, §IV-C, eq. 11).
//!
//! A step solves `R(w; x, u, θ) = 0` for the unknowns `w` (next midpoint velocities, joint
//! impulses, contact and limit variables) and maps the solution to the next state
//! `x⁺ = Y(w; x, θ)` (`p⁺ = p + h v⁺`, `q⁺ = q ⊗ f(ω⁺)`). By the implicit function theorem
//!
//! ```text
//! dx⁺/dz = ∂Y/∂z - ∂Y/∂w · R_w⁻¹ · ∂R/∂z          z ∈ {state x, control u, parameters θ}
//! ```
//!
//! `R_w` is the solver's own Newton matrix, assembled at the gradient point and factored once
//! on the mechanism graph (no dense re-solve): a Jacobian costs one back-substitution per input,
//! a vector-Jacobian product one transposed back-substitution in all.
//!
//! **κ-smoothing.** With `kappa_grad = Some(κ)` the gradient point is the *central-path point*
//! at κ, the solution of `R(w; κ) = 0` with every complementarity pair of the contact
//! candidates within reach and of the limits the step activated held at `b ∘ c = κ w e`, `w` a
//! smooth taper of the gap (a limit side's slack) and its rate at the step's start
//! (`solver::taper`: 1 touching, at its floor before the activation's reach) whose slope the
//! partials carry; the others keep no impulse (every one at `κ e` with
//! `Options::smooth_every_candidate`; see `solver::central::solve`):
//! after the hard solve (to `kappa_tol`), `solver::central::solve` moves every complementarity
//! pair of the hard solution to product κ and runs Newton's method at κ from there (a few
//! iterations); if that fails, it restarts the inequality variables at the neutral point and
//! runs the predictor-corrector with centring floored at κ, with an iteration budget of at
//! least `CENTRAL_MAX_ITER` = 200 (`Options::central_warm_start = false`: that path alone,
//! as before). The derivatives are those
//! of that smoothed step map (contact forces act at a distance ~κ/γ, friction is smoothed),
//! while the returned next state is still the hard one. `None` differentiates the hard solution itself (exact but
//! discontinuous through contact changes, and ill-conditioned at grazing contact).
//!
//! **Partials.** `∂R/∂z` and `∂Y/∂z, ∂Y/∂w` are derivatives of smooth, explicit functions at a
//! fixed `w`; they are taken by central differences of the engine's own residual and output
//! map (`partials.rs`), so every physical term of the residual is differentiated consistently.
//! Columns whose residual rows do not overlap share one evaluation (a colouring of the
//! body–joint–contact graph, `sparsity.rs`), and each evaluation refreshes only the contact
//! candidates the perturbation moves. Only the non-smooth part, the solution map `w(z)`, needs
//! the implicit function theorem.
//!
//! **Back-substitution.** `∂Y/∂w` reads only the body velocities, and each column of `∂R/∂z`
//! is non-zero only on its support, so a Jacobian is formed from `min(ny, nz)` solves (transposed
//! when there are fewer outputs than inputs) and sparse products.
pub mod flat;
pub mod hints;
pub mod kept;
mod light;
mod partials;
mod plan;
mod rollout;
mod sparsity;
mod substeps;
pub mod tangent;
#[cfg(test)]
pub(crate) mod test_scenes;

use std::time::Instant;

use nalgebra::{DMatrix, DVector};

use crate::contact::Frozen;
use crate::math::quat;
use crate::model::Model;
use crate::model::topology_body_node as body_node;
use crate::solver::{activation, central, newton};
use crate::state::{Recycled, SolveStatus, State, StepReport, Workspace};
use crate::step::{AppliedForces, validate_inputs};
use crate::{Error, Result, ensure};
pub use partials::PartialsMethod;
use partials::{Input, Partials};
pub use rollout::{RolloutAdjoint, RolloutJacobians, rollout_jacobians, rollout_vjp};
use substeps::{StoredSubsteps, Substeps};
pub use tangent::Coordinates;
use tangent::Point;

/// Central-difference step for state, control and velocity inputs.
const FD_STEP: f64 = 1e-6;

/// Least iteration budget of the central-path solve at `kappa_grad` (see [`move_to_central`]).
const CENTRAL_MAX_ITER: usize = 200;

/// Which inputs to differentiate with respect to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Wrt {
    /// The state (tangent coordinates).
    pub state: bool,
    /// The controls.
    pub ctrl: bool,
    /// The model parameters ([`Model::params`]).
    pub params: bool,
}

impl Wrt {
    /// Everything.
    pub const ALL: Wrt = Wrt {
        state: true,
        ctrl: true,
        params: true,
    };
    /// State and controls.
    pub const STATE_CTRL: Wrt = Wrt {
        state: true,
        ctrl: true,
        params: false,
    };
}

/// Jacobians of one step in the chosen coordinates (`ny` = state tangent size).
#[derive(Clone, Debug)]
pub struct Jacobians {
    /// `dx⁺/dx`, `ny × ny` (empty when not requested).
    pub a: DMatrix<f64>,
    /// `dx⁺/du`, `ny × nu`.
    pub b: DMatrix<f64>,
    /// `dx⁺/dθ`, `ny × nparams`.
    pub c: DMatrix<f64>,
}

/// Adjoints of a step's inputs given the adjoint of its output.
#[derive(Clone, Debug)]
pub struct Adjoints {
    /// Adjoint of the state (tangent coordinates).
    pub state: Vec<f64>,
    /// Adjoint of the controls.
    pub ctrl: Vec<f64>,
    /// Adjoint of the parameters.
    pub params: Vec<f64>,
}

/// Wall-clock seconds spent in each phase of a linearisation (for profiling; see
/// `engine/examples/gradient_phases.rs`).
#[derive(Clone, Copy, Debug, Default)]
pub struct PhaseTimes {
    /// The hard solve of the step.
    pub solve: f64,
    /// The move to the central path at `kappa_grad`.
    pub central: f64,
    /// Assembly and factorisation of the Newton matrix at the gradient point.
    pub factor: f64,
    /// Partial derivatives `∂R/∂z`, `∂Y/∂z`, `∂Y/∂w`.
    pub partials: f64,
    /// Back-substitutions and products of [`Linearization::jacobians`] / `vjp` / `jvp`.
    pub backsub: f64,
}

/// One solve linearised at its gradient point: the factored Newton matrix and the partial
/// derivatives of the residual and the output map. A step is one of these, or several when it
/// was subdivided ([`Linearization`]).
pub(crate) struct SolveLinearization {
    coords: Coordinates,
    next: State,
    report: StepReport,
    central: Option<Central>,
    /// The solve's workspace (its factored matrix), back to the thread's spares when dropped.
    ws: Recycled,
    /// Gradient point (the solution, or its central-path point at `kappa_grad`).
    w: Vec<f64>,
    /// `∂R/∂z`, `∂Y/∂z`, `∂Y/∂w` with `z = [state | ctrl | params]` as selected by `wrt`.
    parts: Partials,
    nx: usize,
    nu: usize,
    np: usize,
    times: PhaseTimes,
}

fn not_converged(what: &str, report: StepReport) -> Error {
    Error::NotConverged {
        context: what.to_string(),
        status: report.status.name().to_string(),
        iterations: report.iterations,
        residual: report.residual,
        complementarity: report.complementarity,
    }
}

/// Write the next state implied by the unknowns `w` (next midpoint velocities) from `state`.
fn next_state_into(model: &Model, state: &State, w: &[f64], out: &mut State) {
    let h = model.options.timestep;
    for b in 1..model.nbody() {
        let o = body_node(b).map_or(0, |n| model.topology.pattern.offset(n));
        let v = nalgebra::Vector3::new(w[o], w[o + 1], w[o + 2]);
        let om = nalgebra::Vector3::new(w[o + 3], w[o + 4], w[o + 5]);
        let p = state.pose(b);
        let next = crate::joints::geometry::Pose {
            pos: p.pos + v * h,
            quat: (p.quat * quat::step_map(&om, h)).normalize(),
        };
        out.set_pose(b, &next);
        out.set_velocity(b, &v, &om);
    }
    for (ji, joint) in model.joints.iter().enumerate() {
        if let Some(k) = model.topology.winding_adr[ji] {
            let pose = |b: usize| {
                if b == 0 {
                    crate::joints::geometry::Pose::world()
                } else {
                    out.pose(b)
                }
            };
            let (p, c) = (pose(joint.parent), pose(joint.child));
            out.winding[k] = crate::joints::coordinates::turns_after(model, state, ji, &p, &c);
        }
    }
    out.time = state.time + h;
}

/// The least slack of an orthant pair (a contact's gap, a limit's distance) relative to its
/// impulse in the gradients' Newton matrix, `s ≥ SLACK_FLOOR · γ` (the matrix only: the point
/// and its residual are the solve's). Why: a pair pressed hard at the solution (the gymnasium
/// ant's hip on its limit with γ = 54 N·m·s and s = 1.8e-14) gave the leaf-first elimination
/// a pivot of `s` and Schur updates of `γ / s` ≈ 3e15 into its bodies, whose blocks then came
/// out singular: 2 of the ant's first 20 Table V states had no exact Jacobians. With the floor
/// they factor, and their `B` matches central differences of the hard step to 1e-7 relative
/// (`∂v⁺/∂u`, floors 1e-8 / 1e-9 / 1e-10 / 1e-11: 1e-6, 1.5e-7, 1.4e-6, 1.6e-5: the floor
/// against round-off in `γ / s`); states without such a pair are unchanged.
pub(crate) const SLACK_FLOOR: f64 = 1e-9;

/// The hard solve of one step from `state` in a fresh workspace; the report says whether it
/// converged.
fn solve_hard(model: &Model, state: &State, ctrl: &[f64]) -> Result<(Workspace, StepReport)> {
    let mut ws = Workspace::pooled(model);
    validate_inputs(model, state, &ws, ctrl, &AppliedForces::default())?;
    newton::prepare(model, state, &mut ws, ctrl, &AppliedForces::default());
    let report = newton::solve(model, state, &mut ws);
    Ok((ws, report))
}

/// Solve one step from `state` and, when `kappa` is given and the model has inequality
/// constraints, move the solution onto the central path at `kappa`. Returns the hard next
/// state, the reports, and the workspace holding the gradient point in `ws.w`.
fn solve_for_gradient(
    model: &Model,
    state: &State,
    ctrl: &[f64],
    kappa: Option<f64>,
    times: &mut PhaseTimes,
) -> Result<(State, StepReport, Option<Central>, Workspace)> {
    let t0 = Instant::now();
    let (ws, report) = solve_hard(model, state, ctrl)?;
    ensure!(report.status.is_success(), not_converged("step", report));
    finish_solve(model, state, ws, report, kappa, times, t0)
}

/// The next state of a converged solve in `ws` and its move to the central path at `kappa`.
fn finish_solve(
    model: &Model,
    state: &State,
    mut ws: Workspace,
    report: StepReport,
    kappa: Option<f64>,
    times: &mut PhaseTimes,
    t0: Instant,
) -> Result<(State, StepReport, Option<Central>, Workspace)> {
    let mut next = state.clone();
    newton::write_state(model, &mut next, &ws);
    let t1 = Instant::now();
    times.solve = (t1 - t0).as_secs_f64();
    let central = move_to_central(model, state, &mut ws, kappa)?;
    times.central = t1.elapsed().as_secs_f64();
    Ok((next, report, central, ws))
}

/// [`crate::step()`] followed by the move to the central path at `kappa`: the smoothed step map
/// whose derivatives `kappa_grad = Some(kappa)` returns. Writes the smoothed next state. A step
/// whose whole solve fails is reported as not converged (its sub-steps' smoothed maps are
/// chained along the hard sub-steps, which no single smoothed map of the step reproduces).
pub fn step_smoothed(
    model: &Model,
    state: &mut State,
    ctrl: &[f64],
    kappa: f64,
) -> Result<StepReport> {
    let mut times = PhaseTimes::default();
    let (_, _, central, ws) = solve_for_gradient(model, state, ctrl, Some(kappa), &mut times)?;
    let w = ws.w.clone();
    let prev = state.clone();
    next_state_into(model, &prev, &w, state);
    Ok(central.map_or(
        StepReport {
            status: SolveStatus::Converged,
            iterations: 0,
            residual: 0.0,
            complementarity: 0.0,
            subdivisions: 1,
        },
        |c| c.report,
    ))
}

/// A solved step: the hard next state, the solver reports and the workspace holding the
/// gradient point in `ws.w`.
struct Solved {
    next: State,
    report: StepReport,
    central: Option<Central>,
    ws: Workspace,
    /// Whether `ws` holds the evaluation of `ws.w` at κ = 0 (what the Newton matrix at the
    /// gradient point is assembled from), so that it need not be evaluated again.
    evaluated: bool,
}

/// What a forward pass keeps of a solved step so that it can be linearised without solving it
/// again: the solution, the contact activation it was solved with and the friction cones it
/// holds saturated.
#[derive(Clone, Debug)]
pub(crate) struct StoredSolution {
    w: Vec<f64>,
    active: Vec<bool>,
    saturated: Vec<Option<crate::solver::saturation::Hold>>,
    /// The features the active candidates held for the step (`Workspace::frozen`), which a
    /// re-freeze after the solve may have moved from those the state's prediction chooses.
    frozen: Vec<(usize, Option<Frozen>)>,
    report: StepReport,
}

impl StoredSolution {
    /// The solution held by `ws` after a successful solve.
    pub(crate) fn of(ws: &Workspace, report: StepReport) -> StoredSolution {
        StoredSolution {
            w: ws.w.clone(),
            active: ws.active.clone(),
            saturated: ws.saturated.clone(),
            frozen: active_frozen(ws),
            report,
        }
    }
}

/// The frozen features of the active contact candidates of `ws`.
fn active_frozen(ws: &Workspace) -> Vec<(usize, Option<Frozen>)> {
    crate::solver::inequality::active_candidates(ws.contact_active())
        .map(|c| (c, ws.frozen[c]))
        .collect()
}

impl StoredSolution {
    /// Bytes of its arrays.
    pub(crate) fn heap_bytes(&self) -> usize {
        let frozen = std::mem::size_of::<(usize, Option<Frozen>)>() * self.frozen.len();
        8 * self.w.len() + self.active.len() + 24 * self.saturated.len() + frozen
    }
}

/// What a forward pass keeps of a step: its solution, or each sub-step's when it was subdivided.
#[derive(Clone, Debug)]
pub(crate) enum StoredStep {
    Whole(StoredSolution),
    Substeps(StoredSubsteps),
}

impl StoredStep {
    /// Bytes of its arrays.
    pub(crate) fn heap_bytes(&self) -> usize {
        match self {
            StoredStep::Whole(s) => s.heap_bytes(),
            StoredStep::Substeps(s) => s.heap_bytes(),
        }
    }
}

fn check_kappa(kappa_grad: Option<f64>) -> Result<()> {
    if let Some(k) = kappa_grad {
        ensure!(
            k.is_finite() && k > 0.0,
            Error::input("kappa_grad", k, "must be finite and > 0 (or None)")
        );
    }
    Ok(())
}

/// The move of a solved workspace to the central path: the solver report (iterations of every
/// attempt) and whether the neutral-start fallback ran.
#[derive(Clone, Copy, Debug)]
struct Central {
    report: StepReport,
    fallback: bool,
}

/// Move a solved workspace onto the central path at `kappa` (when given and the model has
/// inequality constraints).
fn move_to_central(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    kappa: Option<f64>,
) -> Result<Option<Central>> {
    match kappa {
        Some(k) if model.topology.has_cones => {
            let warm = model
                .options
                .central_warm_start
                .then_some(model.options.max_iter);
            let c = solve_central(model, state, ws, k, warm)?;
            ensure!(
                c.report.status.is_success(),
                not_converged(
                    &format!("central-path point at kappa_grad = {k:e}"),
                    c.report
                )
            );
            Ok(Some(c))
        }
        _ => Ok(None),
    }
}

/// The central-path solve at `k` of the solved step in `ws`: with `warm_budget = Some(n)` first
/// from the hard solution moved onto the central path (`central::Start::Hard`, at most `n`
/// iterations), then, if that fails, from the neutral point and the hard velocities.
///
/// NOTE: from the neutral point (γ = s = 1 on every candidate, far from the step's impulse
/// scale) the solve needs more iterations than a warm-started hard step (panda, 835
/// candidates: 36-56), so the fallback gets a budget of at least `CENTRAL_MAX_ITER`.
fn solve_central(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    k: f64,
    warm_budget: Option<usize>,
) -> Result<Central> {
    let mut iterations = 0;
    if let Some(budget) = warm_budget {
        let hard = ws.w.clone();
        let c = solve_central_from(model, state, ws, k, central::Start::Hard, budget)?;
        if c.status.is_success() {
            return Ok(Central {
                report: c,
                fallback: false,
            });
        }
        iterations = c.iterations;
        ws.w.copy_from_slice(&hard);
    }
    let budget = model.options.max_iter.max(CENTRAL_MAX_ITER);
    let mut c = solve_central_from(model, state, ws, k, central::Start::Neutral, budget)?;
    c.iterations += iterations;
    Ok(Central {
        report: c,
        fallback: warm_budget.is_some(),
    })
}

/// One central-path solve from `start` with an iteration budget of `max_iter`.
fn solve_central_from(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    k: f64,
    start: central::Start,
    max_iter: usize,
) -> Result<StepReport> {
    let budgeted;
    let m = if max_iter == model.options.max_iter {
        model
    } else {
        let mut opts = model.options.clone();
        opts.max_iter = max_iter;
        budgeted = model.with_options(opts)?;
        &budgeted
    };
    let mut c = central::solve(m, state, ws, k, start);
    // the solve checks convergence before each iteration: a last iterate that meets the
    // tolerance is converged
    if c.status == SolveStatus::MaxIterations && c.residual < model.options.rtol {
        c.status = SolveStatus::Converged;
    }
    Ok(c)
}

impl SolveLinearization {
    /// Linearise a step that a forward pass already solved from `state` (which must be the
    /// state that solve started from, rebuilt in `coords`), in the workspace `ws` (any
    /// workspace of `model`: everything read is reinitialised).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn from_stored(
        model: &Model,
        state: &State,
        ctrl: &[f64],
        coords: Coordinates,
        wrt: Wrt,
        kappa_grad: Option<f64>,
        stored: &StoredSolution,
        mut ws: Workspace,
        method: PartialsMethod,
    ) -> Result<SolveLinearization> {
        let point = Point::new(model, state, coords)?;
        let mut times = PhaseTimes::default();
        let t0 = Instant::now();
        validate_inputs(model, &point.state, &ws, ctrl, &AppliedForces::default())?;
        let forces = AppliedForces::default();
        if kappa_grad.is_some() && model.options.smooth_every_candidate {
            // the central-path solve takes every candidate: prepare them all
            newton::prepare(model, &point.state, &mut ws, ctrl, &forces);
        } else {
            // the stored solve fixed the contact activation (the central-path solve keeps it
            // too): only the forces and the active candidates' geometry are read (`evaluate`
            // prepares those), not a new solve's activation search over every candidate (a
            // tenth of a Panda's reverse step)
            ws.prepared.fill(false);
            newton::prepare_smooth_forces(model, &point.state, &mut ws, ctrl, &forces);
        }
        ws.w.copy_from_slice(&stored.w);
        ws.active.copy_from_slice(&stored.active);
        // (a recycled workspace's shadowed candidates are another step's: the smoothed step
        // would pool them, `saturation::hold_frictionless`)
        ws.shadowed.fill(false);
        if kappa_grad.is_some() && !model.options.smooth_every_candidate {
            // the smoothed step joins the candidates above the taper's floor that the stored
            // activation left out (`central::join_weighted`): their gaps and rates at the start
            activation::prepare(model, &point.state, &mut ws);
        }
        // the limits' slacks and rates at the start, which the activation records (the κ
        // taper and the inactive limits' variables read them)
        for (j, joint) in model.joints.iter().enumerate() {
            activation::record_limit_start(&point.state, &mut ws, j, joint);
        }
        for k in 0..model.tendon_limits.len() {
            activation::record_tendon_start(model, &point.state, &mut ws, k);
        }
        ws.saturated.copy_from_slice(&stored.saturated);
        // the features the solve ended with (`evaluate` prepares no candidate prepared here)
        let candidates = stored.frozen.iter().copied();
        activation::prepare_candidates_holding(model, &point.state, &mut ws, candidates);
        newton::evaluate(model, &point.state, &mut ws, false, 0.0);
        let mut next = point.state.clone();
        newton::write_state(model, &mut next, &ws);
        let t1 = Instant::now();
        times.solve = (t1 - t0).as_secs_f64();
        let central = move_to_central(model, &point.state, &mut ws, kappa_grad)?;
        times.central = t1.elapsed().as_secs_f64();
        let solved = Solved {
            next,
            report: stored.report,
            evaluated: central.is_none(),
            central,
            ws,
        };
        Self::at_solution(model, point, ctrl, wrt, kappa_grad, solved, times, method)
    }

    /// Factor the Newton matrix at the gradient point and take the partials.
    #[allow(clippy::too_many_arguments)]
    fn at_solution(
        model: &Model,
        point: Point,
        ctrl: &[f64],
        wrt: Wrt,
        kappa_grad: Option<f64>,
        solved: Solved,
        mut times: PhaseTimes,
        method: PartialsMethod,
    ) -> Result<SolveLinearization> {
        let Solved {
            next,
            report,
            central,
            mut ws,
            evaluated,
        } = solved;
        let t0 = Instant::now();
        let kappa = match central {
            Some(_) => kappa_grad.unwrap_or(0.0),
            None => 0.0,
        };
        // Newton matrix at the gradient point, factored once for every input direction
        if !(evaluated && kappa == 0.0) {
            newton::evaluate(model, &point.state, &mut ws, false, kappa);
        }
        ws.slack_floor = SLACK_FLOOR;
        newton::assemble(model, &mut ws);
        ws.slack_floor = 0.0;
        if let Err(n) = ws.matrix.factor(&model.topology.pattern) {
            let what = format!(
                "factorisation of the Newton matrix at the gradient point (singular at {})",
                model.node_name(n)
            );
            return Err(not_converged(
                &what,
                StepReport {
                    status: SolveStatus::NonFinite,
                    ..report
                },
            ));
        }
        times.factor = t0.elapsed().as_secs_f64();
        let coords = point.coords;
        let mut inputs = Vec::new();
        if wrt.state {
            inputs.extend((0..coords.dim(model)).map(Input::State));
        }
        if wrt.ctrl {
            inputs.extend((0..model.nu()).map(Input::Ctrl));
        }
        if wrt.params {
            inputs.extend(model.param_layout().into_iter().map(Input::Param));
        }
        let nx = if wrt.state { coords.dim(model) } else { 0 };
        let nu = if wrt.ctrl { model.nu() } else { 0 };
        let np = inputs.len() - nx - nu;
        let w = ws.w.clone();
        let t0 = Instant::now();
        let held = (&ws.active[..], &active_frozen(&ws)[..]);
        let taper = (ws.kappa_taper && kappa > 0.0).then(|| partials::Taper {
            kappa,
            phi_now: &ws.contact_phi_now,
            rate_now: &ws.contact_rate_now,
            saturated: &ws.saturated,
            rate_rows: (0..model.ncontact())
                .map(|c| ws.active[c].then(|| ws.contact_step[c].normal_row()))
                .collect(),
            limit_slack: &ws.limit_slack_now,
            limit_rate: &ws.limit_rate_now,
            limit_adr: &ws.limit_adr,
        });
        let parts = partials::partials(model, &point, ctrl, &w, held, &inputs, method, taper)?;
        times.partials = t0.elapsed().as_secs_f64();
        Ok(SolveLinearization {
            coords,
            next,
            report,
            central,
            ws: Recycled::new(ws),
            w,
            parts,
            nx,
            nu,
            np,
            times,
        })
    }

    /// Residual evaluations spent on the partial derivatives.
    pub fn residual_evaluations(&self) -> usize {
        self.parts.evaluations
    }
    /// The workspace the linearisation was computed in, for reuse.
    pub(crate) fn into_workspace(self) -> Workspace {
        self.ws.into_inner()
    }

    /// The hard next state (what [`crate::step`] returns).
    pub fn next_state(&self) -> &State {
        &self.next
    }
    /// The step's solver report.
    pub fn report(&self) -> StepReport {
        self.report
    }
    /// The report of the move to the central path (`None` without `kappa_grad` or without
    /// inequality constraints).
    pub fn central_report(&self) -> Option<StepReport> {
        self.central.map(|c| c.report)
    }
    /// Whether the move to the central path fell back to the neutral start (the start from the
    /// hard solution, `Options::central_warm_start`, failed); false without a central solve.
    pub fn central_fallback(&self) -> bool {
        self.central.is_some_and(|c| c.fallback)
    }
    /// Seconds spent in each phase so far.
    pub fn phase_times(&self) -> PhaseTimes {
        self.times
    }
    /// Coordinates of the state tangent.
    pub fn coordinates(&self) -> Coordinates {
        self.coords
    }

    fn check(&self, model: &Model) -> Result<()> {
        ensure!(
            model.topology_id() == self.ws.topology_id,
            Error::ModelMismatch {
                detail: "linearization was made for another model".into()
            }
        );
        Ok(())
    }

    /// Full Jacobians (`A`, `B`, `C`; a block has no columns when its input was not selected).
    /// `dx⁺/dz = ∂Y/∂z - Λᵀ ∂R/∂z` with `R_wᵀ Λ = ∂Y/∂wᵀ` (one transposed solve per output)
    /// when there are fewer outputs than inputs, else `∂Y/∂w (R_w⁻¹ ∂R/∂z)` (one solve per input).
    pub fn jacobians(&mut self, model: &Model) -> Result<Jacobians> {
        self.check(model)?;
        let t0 = Instant::now();
        let p = &model.topology.pattern;
        let parts = &self.parts;
        let (ny, nz, nw) = (parts.y_z.nrows(), parts.y_z.ncols(), self.w.len());
        let mut full = parts.y_z.clone();
        if ny <= nz {
            // every output at once: row r of `xs` holds row r of R_w⁻ᵀ ∂Y/∂wᵀ (the buffer is
            // zero between uses, so only the live rows are written and cleared)
            let mut xs = std::mem::take(&mut self.ws.jacobian_rhs);
            xs.resize(nw * ny, 0.0);
            for (kk, &k) in parts.w_cols.iter().enumerate() {
                for i in 0..ny {
                    xs[k * ny + i] = parts.y_w[(i, kk)];
                }
            }
            self.ws.matrix.solve_transpose_many(p, &mut xs, ny);
            let (mut part, mut dots) = (vec![0.0; ny], vec![0.0; ny]);
            for c in 0..nz {
                parts.col_dot_many(c, &xs, ny, &mut part, &mut dots);
                for (i, d) in dots.iter().enumerate() {
                    full[(i, c)] -= d;
                }
            }
            for r in self.ws.matrix.live_rows() {
                xs[r.start * ny..r.end * ny].fill(0.0);
            }
            for &k in &parts.w_cols {
                xs[k * ny..(k + 1) * ny].fill(0.0);
            }
            self.ws.jacobian_rhs = xs;
        } else {
            let mut x = vec![0.0; nw];
            for c in 0..nz {
                x.fill(0.0);
                parts.col_add_to(c, 1.0, &mut x);
                self.ws.matrix.solve(p, &mut x);
                for i in 0..ny {
                    full[(i, c)] -= parts
                        .w_cols
                        .iter()
                        .enumerate()
                        .map(|(kk, &k)| parts.y_w[(i, kk)] * x[k])
                        .sum::<f64>();
                }
            }
        }
        self.times.backsub += t0.elapsed().as_secs_f64();
        Ok(Jacobians {
            a: full.columns(0, self.nx).into_owned(),
            b: full.columns(self.nx, self.nu).into_owned(),
            c: full.columns(self.nx + self.nu, self.np).into_owned(),
        })
    }

    /// Vector-Jacobian product: the adjoints of state, control and parameters given the adjoint
    /// `adj_next` of the next state (tangent coordinates). One transposed back-substitution.
    pub fn vjp(&mut self, model: &Model, adj_next: &[f64]) -> Result<Adjoints> {
        self.check(model)?;
        let ny = self.coords.dim(model);
        check_adjoint(ny, adj_next)?;
        let t0 = Instant::now();
        let parts = &self.parts;
        // λ = R_w⁻ᵀ ∂Y/∂wᵀ a;  adj = ∂Y/∂zᵀ a - ∂R/∂zᵀ λ
        let mut lam = vec![0.0; self.w.len()];
        for (kk, &k) in parts.w_cols.iter().enumerate() {
            lam[k] = (0..ny).map(|i| parts.y_w[(i, kk)] * adj_next[i]).sum();
        }
        self.ws
            .matrix
            .solve_transpose(&model.topology.pattern, &mut lam);
        let adj: Vec<f64> = (0..parts.y_z.ncols())
            .map(|c| {
                let y: f64 = (0..ny).map(|i| parts.y_z[(i, c)] * adj_next[i]).sum();
                y - parts.col_dot(c, &lam)
            })
            .collect();
        self.times.backsub += t0.elapsed().as_secs_f64();
        Ok(Adjoints {
            state: adj[..self.nx].to_vec(),
            ctrl: adj[self.nx..self.nx + self.nu].to_vec(),
            params: adj[self.nx + self.nu..].to_vec(),
        })
    }

    /// Jacobian-vector product: the tangent of the next state for input tangents `dx` (state),
    /// `du` (controls) and `dtheta` (parameters); each must match the selected inputs (empty
    /// when not selected).
    pub fn jvp(
        &mut self,
        model: &Model,
        dx: &[f64],
        du: &[f64],
        dtheta: &[f64],
    ) -> Result<Vec<f64>> {
        self.check(model)?;
        check_tangents([(dx, self.nx), (du, self.nu), (dtheta, self.np)])?;
        let t = DVector::from_iterator(
            self.nx + self.nu + self.np,
            dx.iter().chain(du).chain(dtheta).copied(),
        );
        let parts = &self.parts;
        let mut dw = vec![0.0; self.w.len()];
        for (c, tc) in t.iter().enumerate() {
            parts.col_add_to(c, *tc, &mut dw);
        }
        self.ws.matrix.solve(&model.topology.pattern, &mut dw);
        let mut out = &parts.y_z * &t;
        for (kk, &k) in parts.w_cols.iter().enumerate() {
            for i in 0..out.len() {
                out[i] -= parts.y_w[(i, kk)] * dw[k];
            }
        }
        Ok(out.iter().copied().collect())
    }
}

/// The adjoint of a next state: `ny` finite numbers.
fn check_adjoint(ny: usize, adj_next: &[f64]) -> Result<()> {
    ensure!(
        adj_next.len() == ny,
        Error::shape("adjoint_next", &[ny], &[adj_next.len()])
    );
    ensure!(
        adj_next.iter().all(|x| x.is_finite()),
        Error::input("adjoint_next", adj_next, "must be finite")
    );
    Ok(())
}

/// Input tangents `dx`, `du`, `dtheta` of a JVP with their expected lengths.
fn check_tangents(tangents: [(&[f64], usize); 3]) -> Result<()> {
    for (name, (v, n)) in ["dx", "du", "dtheta"].into_iter().zip(tangents) {
        ensure!(v.len() == n, Error::shape(name, &[n], &[v.len()]));
        ensure!(
            v.iter().all(|x| x.is_finite()),
            Error::input(name, v, "must be finite")
        );
    }
    Ok(())
}

/// A solved step linearised at its gradient point (see the module docs). A step whose whole
/// solve failed and that [`crate::step()`] took as `n` sub-steps (`Options::max_subdivisions`)
/// is linearised sub-step by sub-step and chained (`substeps.rs`), so its gradients are those
/// of the step the simulation actually took.
pub struct Linearization(Kind);

// both variants hold a workspace inline (~1.4 KB); one linearisation lives at a time
#[allow(clippy::large_enum_variant)]
enum Kind {
    Whole(SolveLinearization),
    Substeps(Substeps),
}

impl Linearization {
    /// Solve the step from `state` with `ctrl` and linearise it (see the module docs).
    pub fn new(
        model: &Model,
        state: &State,
        ctrl: &[f64],
        coords: Coordinates,
        wrt: Wrt,
        kappa_grad: Option<f64>,
    ) -> Result<Linearization> {
        Self::with_method(
            model,
            state,
            ctrl,
            coords,
            wrt,
            kappa_grad,
            PartialsMethod::default(),
        )
    }

    /// [`Linearization::new`] with the partial derivatives taken by `method`.
    pub fn with_method(
        model: &Model,
        state: &State,
        ctrl: &[f64],
        coords: Coordinates,
        wrt: Wrt,
        kappa_grad: Option<f64>,
        method: PartialsMethod,
    ) -> Result<Linearization> {
        check_kappa(kappa_grad)?;
        state.check_model(model)?;
        let point = Point::new(model, state, coords)?;
        let mut times = PhaseTimes::default();
        let t0 = Instant::now();
        let (mut ws, report) = solve_hard(model, &point.state, ctrl)?;
        // the same decisions as `crate::step`: a failed or energy-gaining solve is subdivided
        // (or, failing that, solved with a longer budget: its report is the stored one)
        let report = match substeps::retry(model, &point.state, &mut ws, ctrl, report)? {
            StoredStep::Substeps(stored) => {
                let lin = Substeps::new(model, point, ctrl, wrt, kappa_grad, &stored, ws, method)?;
                return Ok(Linearization(Kind::Substeps(lin)));
            }
            StoredStep::Whole(solution) => solution.report,
        };
        let (next, report, central, ws) =
            finish_solve(model, &point.state, ws, report, kappa_grad, &mut times, t0)?;
        let solved = Solved {
            next,
            report,
            central,
            ws,
            evaluated: false,
        };
        SolveLinearization::at_solution(model, point, ctrl, wrt, kappa_grad, solved, times, method)
            .map(|l| Linearization(Kind::Whole(l)))
    }

    /// Linearise a step that a forward pass already solved from `state` (which must be the
    /// state that solve started from, rebuilt in `coords`), in the workspace `ws` (any
    /// workspace of `model`: everything read is reinitialised).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn from_stored(
        model: &Model,
        state: &State,
        ctrl: &[f64],
        coords: Coordinates,
        wrt: Wrt,
        kappa_grad: Option<f64>,
        stored: &StoredStep,
        ws: Workspace,
    ) -> Result<Linearization> {
        check_kappa(kappa_grad)?;
        let method = PartialsMethod::default();
        Ok(Linearization(match stored {
            StoredStep::Whole(sol) => Kind::Whole(SolveLinearization::from_stored(
                model, state, ctrl, coords, wrt, kappa_grad, sol, ws, method,
            )?),
            StoredStep::Substeps(sub) => {
                let point = Point::new(model, state, coords)?;
                Kind::Substeps(Substeps::new(
                    model, point, ctrl, wrt, kappa_grad, sub, ws, method,
                )?)
            }
        }))
    }

    /// Residual evaluations spent on the partial derivatives.
    pub fn residual_evaluations(&self) -> usize {
        match &self.0 {
            Kind::Whole(l) => l.residual_evaluations(),
            Kind::Substeps(l) => l.steps().iter().map(|s| s.residual_evaluations()).sum(),
        }
    }
    /// The workspace the linearisation was computed in, for reuse.
    pub(crate) fn into_workspace(self) -> Workspace {
        match self.0 {
            Kind::Whole(l) => l.into_workspace(),
            Kind::Substeps(l) => l.into_workspace(),
        }
    }
    /// The hard next state (what [`crate::step()`] returns).
    pub fn next_state(&self) -> &State {
        match &self.0 {
            Kind::Whole(l) => l.next_state(),
            Kind::Substeps(l) => l.next_state(),
        }
    }
    /// The step's solver report (`subdivisions > 1` for a subdivided step; its iterations
    /// include the failed whole-step solve).
    pub fn report(&self) -> StepReport {
        match &self.0 {
            Kind::Whole(l) => l.report(),
            Kind::Substeps(l) => l.report(),
        }
    }
    /// The report of the move to the central path (`None` without `kappa_grad` or without
    /// inequality constraints; for a subdivided step the sub-steps' iterations summed).
    pub fn central_report(&self) -> Option<StepReport> {
        match &self.0 {
            Kind::Whole(l) => l.central_report(),
            Kind::Substeps(l) => l.central_report(),
        }
    }
    /// Whether the move to the central path fell back to the neutral start (the start from the
    /// hard solution, `Options::central_warm_start`, failed) in any solve; false without a
    /// central solve.
    pub fn central_fallback(&self) -> bool {
        match &self.0 {
            Kind::Whole(l) => l.central_fallback(),
            Kind::Substeps(l) => l.steps().iter().any(|s| s.central_fallback()),
        }
    }
    /// Seconds spent in each phase so far (summed over sub-steps).
    pub fn phase_times(&self) -> PhaseTimes {
        match &self.0 {
            Kind::Whole(l) => l.phase_times(),
            Kind::Substeps(l) => l.phase_times(),
        }
    }
    /// Coordinates of the state tangent.
    pub fn coordinates(&self) -> Coordinates {
        match &self.0 {
            Kind::Whole(l) => l.coordinates(),
            Kind::Substeps(l) => l.coordinates(),
        }
    }
    /// Full Jacobians (`A`, `B`, `C`; a block has no columns when its input was not selected).
    pub fn jacobians(&mut self, model: &Model) -> Result<Jacobians> {
        match &mut self.0 {
            Kind::Whole(l) => l.jacobians(model),
            Kind::Substeps(l) => l.jacobians(model),
        }
    }
    /// Vector-Jacobian product: the adjoints of state, control and parameters given the adjoint
    /// `adj_next` of the next state (tangent coordinates). One transposed back-substitution per
    /// solve.
    pub fn vjp(&mut self, model: &Model, adj_next: &[f64]) -> Result<Adjoints> {
        match &mut self.0 {
            Kind::Whole(l) => l.vjp(model, adj_next),
            Kind::Substeps(l) => l.vjp(model, adj_next),
        }
    }
    /// Jacobian-vector product: the tangent of the next state for input tangents `dx` (state),
    /// `du` (controls) and `dtheta` (parameters); each must match the selected inputs (empty
    /// when not selected).
    pub fn jvp(
        &mut self,
        model: &Model,
        dx: &[f64],
        du: &[f64],
        dtheta: &[f64],
    ) -> Result<Vec<f64>> {
        match &mut self.0 {
            Kind::Whole(l) => l.jvp(model, dx, du, dtheta),
            Kind::Substeps(l) => l.jvp(model, dx, du, dtheta),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{BodySpec, GeomSpec, JointKind, JointSpec, ModelBuilder, Shape};

    /// A 1 kg box (10 cm) sliding at 1 m/s on a floor with μ = 0.5, settled onto it.
    fn sliding_box() -> (Model, State) {
        let half = nalgebra::Vector3::new(0.05, 0.05, 0.05);
        let m = ModelBuilder::new()
            .timestep(0.01)
            .geom(GeomSpec::new("floor", "world", Shape::Plane).friction(0.5))
            .body(BodySpec::new("box", 1.0, [1.0 / 600.0; 3]).pos([0.0, 0.0, 0.05]))
            .joint(JointSpec::new("free", JointKind::Floating, "world", "box"))
            .geom(GeomSpec::new("box", "box", Shape::Box { half_extents: half }).friction(0.5))
            .compile()
            .unwrap();
        let mut s = State::reference(&m);
        let mut ws = Workspace::new(&m);
        for _ in 0..20 {
            crate::step(&m, &mut s, &mut ws, &[]).unwrap();
        }
        let q = crate::qpos(&m, &s);
        crate::set_minimal(&m, &mut s, &q, &[1.0, 0.0, 0.0, 0.0, 0.0, 0.0]).unwrap();
        (m, s)
    }

    #[test]
    fn a_failed_central_solve_from_the_hard_solution_falls_back_to_the_neutral_start() {
        let (m, s) = sliding_box();
        let kappa = 1e-4;
        let mut ws = Workspace::new(&m);
        newton::prepare(&m, &s, &mut ws, &[], &AppliedForces::default());
        assert!(newton::solve(&m, &s, &mut ws).status.is_success());
        let (hard_w, hard_active) = (ws.w.clone(), ws.active.clone());
        let from_hard = |ws: &mut Workspace, warm_budget| {
            ws.w.copy_from_slice(&hard_w);
            ws.active.copy_from_slice(&hard_active);
            let c = solve_central(&m, &s, ws, kappa, warm_budget).unwrap();
            assert_eq!(c.report.status, SolveStatus::Converged, "{c:?}");
            (c, ws.w.clone())
        };
        // the start from the hard solution converges on its own in a few iterations
        let (warm, w_warm) = from_hard(&mut ws, Some(m.options.max_iter));
        assert!(
            !warm.fallback && (2..=10).contains(&warm.report.iterations),
            "{warm:?}"
        );
        // the former path: the neutral start only
        let (neutral, w_neutral) = from_hard(&mut ws, None);
        assert!(neutral.report.iterations > warm.report.iterations);
        // one iteration cannot reach the κ path: the warm solve fails and the neutral start
        // runs from the hard velocities, exactly the former path
        let (forced, w_forced) = from_hard(&mut ws, Some(1));
        assert!(forced.fallback);
        assert_eq!(forced.report.iterations, 1 + neutral.report.iterations);
        assert_eq!(w_forced, w_neutral);
        // one central-path point, whichever start found it (on the rows that take part: an
        // inactive candidate's variables are whatever each start left there)
        let mut live = vec![true; w_warm.len()];
        let t = &m.topology;
        for (c, &n) in t.contact_node.iter().enumerate() {
            if !hard_active[c] {
                let o = t.pattern.offset(n);
                live[o..o + t.pattern.dim(n)].fill(false);
            }
        }
        assert!(
            live.contains(&false),
            "every candidate active: the test tests less"
        );
        let scale = w_warm.iter().fold(1.0f64, |m, x| m.max(x.abs()));
        let diff = (w_warm.iter().zip(&w_forced).zip(&live))
            .filter(|(_, l)| **l)
            .fold(0.0f64, |m, ((a, b), _)| m.max((a - b).abs()));
        assert!(diff < 1e-8 * scale, "solutions differ by {diff:e}");
    }
}
