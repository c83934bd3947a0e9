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
//! at κ: starting from the hard solution (solved to `kappa_tol`), Newton's method on
//! `R(w; κ) = 0` with every complementarity pair held at `b ∘ c = κ e`
//! ([`crate::solver::ipm`]'s `solve_central`). The derivatives are those of that smoothed step
//! map (contact forces act at a distance ~κ/γ, friction is smoothed), while the returned next
//! state is still the hard one. `None` differentiates the hard solution itself (exact but
//! discontinuous through contact changes, and ill-conditioned at grazing contact).
//!
//! **Partials.** `∂R/∂z` and `∂Y/∂z, ∂Y/∂w` are derivatives of smooth, explicit functions at a
//! fixed `w`; they are taken by central differences of the engine's own residual and output
//! map (step 1e-6 in state units; relative error ~1e-9), so every physical term of the residual
//! is differentiated consistently. Only the non-smooth part, the solution map `w(z)`, needs the
//! implicit function theorem. Replacing the partials with analytic ones is a speed upgrade that
//! the tests in this module pin down.
pub mod flat;
mod rollout;
pub mod tangent;

use nalgebra::{DMatrix, DVector};

use crate::math::quat;
use crate::model::Model;
use crate::model::params::Param;
use crate::model::topology_body_node as body_node;
use crate::solver::{ipm, newton};
use crate::state::{SolveStatus, State, StepReport, Workspace};
use crate::step::{AppliedForces, validate_inputs};
use crate::{Error, Result, ensure};
pub use rollout::{RolloutAdjoint, rollout_vjp};
pub use tangent::Coordinates;
use tangent::Point;

/// Central-difference step for state, control and velocity inputs.
const FD_STEP: f64 = 1e-6;

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

/// One input direction of the step.
#[derive(Clone, Copy, Debug)]
enum Input {
    State(usize),
    Ctrl(usize),
    Param(Param),
}

/// A solved step, linearised at its gradient point: the factored Newton matrix and the
/// partial derivatives of the residual and the output map.
pub struct Linearization {
    coords: Coordinates,
    wrt: Wrt,
    point: Point,
    next: State,
    report: StepReport,
    central: Option<StepReport>,
    ws: Workspace,
    /// Gradient point (the solution, or its central-path point at `kappa_grad`).
    w: Vec<f64>,
    /// `∂R/∂z`, `nw × nz` with `z = [state | ctrl | params]` as selected by `wrt`.
    r_z: DMatrix<f64>,
    /// `∂Y/∂z`, `ny × nz`.
    y_z: DMatrix<f64>,
    /// `∂Y/∂w`, `ny × nw` (only body-velocity columns are non-zero).
    y_w: DMatrix<f64>,
    nx: usize,
    nu: usize,
    np: usize,
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
    out.time = state.time + h;
}

/// Solve one step from `state` and, when `kappa` is given and the model has inequality
/// constraints, move the solution onto the central path at `kappa`. Returns the hard next
/// state, the reports, and the workspace holding the gradient point in `ws.w`.
fn solve_for_gradient(
    model: &Model,
    state: &State,
    ctrl: &[f64],
    kappa: Option<f64>,
) -> Result<(State, StepReport, Option<StepReport>, Workspace)> {
    let mut ws = Workspace::new(model);
    validate_inputs(model, state, &ws, ctrl, &AppliedForces::default())?;
    newton::prepare(model, state, &mut ws, ctrl, &AppliedForces::default());
    let report = newton::solve(model, state, &mut ws);
    ensure!(report.status.is_success(), not_converged("step", report));
    let mut next = state.clone();
    newton::write_state(model, &mut next, &ws);
    let central = match kappa {
        Some(k) if model.topology.has_cones => {
            let c = ipm::solve_central(model, state, &mut ws, k);
            ensure!(
                c.status.is_success(),
                not_converged(&format!("central-path point at kappa_grad = {k:e}"), c)
            );
            Some(c)
        }
        _ => None,
    };
    Ok((next, report, central, ws))
}

/// [`crate::step`] followed by the move to the central path at `kappa`: the smoothed step map
/// whose derivatives `kappa_grad = Some(kappa)` returns. Writes the smoothed next state.
pub fn step_smoothed(
    model: &Model,
    state: &mut State,
    ctrl: &[f64],
    kappa: f64,
) -> Result<StepReport> {
    let (_, _, central, ws) = solve_for_gradient(model, state, ctrl, Some(kappa))?;
    let w = ws.w.clone();
    let prev = state.clone();
    next_state_into(model, &prev, &w, state);
    Ok(central.unwrap_or(StepReport {
        status: SolveStatus::Converged,
        iterations: 0,
        residual: 0.0,
        complementarity: 0.0,
    }))
}

/// Scratch for evaluating the residual and output map at perturbed inputs.
struct Probe {
    model: Model,
    state: State,
    next: State,
    ctrl: Vec<f64>,
    ws: Workspace,
    residual: Vec<f64>,
    y: Vec<f64>,
    scratch: Vec<f64>,
}

impl Probe {
    fn new(lin: &Linearization, model: &Model, ctrl: &[f64]) -> Probe {
        let n = model.topology.pattern.total_dim();
        // the residual map is linearised with the solve's contact activation frozen
        let mut ws = Workspace::new(model);
        ws.active.clone_from(&lin.ws.active);
        Probe {
            model: model.clone(),
            state: lin.point.state.clone(),
            next: lin.point.state.clone(),
            ctrl: ctrl.to_vec(),
            ws,
            residual: vec![0.0; n],
            y: vec![0.0; lin.coords.dim(model)],
            scratch: vec![0.0; Point::scratch_len(model)],
        }
    }

    /// Residual and output at the gradient point with the probe's (perturbed) inputs.
    fn eval(&mut self, w: &[f64], out_base: &Point) {
        newton::prepare_forces(
            &self.model,
            &self.state,
            &mut self.ws,
            &self.ctrl,
            &AppliedForces::default(),
        );
        newton::evaluate_in(
            &self.model,
            &self.state,
            &mut self.ws,
            w,
            &mut self.residual,
            0.0,
        );
        next_state_into(&self.model, &self.state, w, &mut self.next);
        out_base.difference(&self.model, &self.next, &mut self.y, &mut self.scratch);
    }
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
        if let Some(k) = kappa_grad {
            ensure!(
                k.is_finite() && k > 0.0,
                Error::input("kappa_grad", k, "must be finite and > 0 (or None)")
            );
        }
        state.check_model(model)?;
        let point = Point::new(model, state, coords)?;
        let (next, report, central, mut ws) =
            solve_for_gradient(model, &point.state, ctrl, kappa_grad)?;
        let kappa = if central.is_some() {
            kappa_grad.unwrap_or(0.0)
        } else {
            0.0
        };
        // Newton matrix at the gradient point, factored once for every input direction
        newton::evaluate(model, &point.state, &mut ws, false, kappa);
        newton::assemble(model, &mut ws);
        if ws.matrix.factor(&model.topology.pattern).is_err() {
            return Err(not_converged(
                "factorisation of the Newton matrix at the gradient point",
                StepReport {
                    status: SolveStatus::NonFinite,
                    ..report
                },
            ));
        }
        let w = ws.w.clone();
        let nx = if wrt.state { coords.dim(model) } else { 0 };
        let nu = if wrt.ctrl { model.nu() } else { 0 };
        let np = if wrt.params {
            model.param_layout().len()
        } else {
            0
        };
        let (nw, ny) = (w.len(), coords.dim(model));
        let mut lin = Linearization {
            coords,
            wrt,
            point,
            next,
            report,
            central,
            ws,
            w,
            r_z: DMatrix::zeros(nw, nx + nu + np),
            y_z: DMatrix::zeros(ny, nx + nu + np),
            y_w: DMatrix::zeros(ny, nw),
            nx,
            nu,
            np,
        };
        lin.partials(model, ctrl);
        Ok(lin)
    }

    /// Central differences of the residual and output map at the gradient point.
    fn partials(&mut self, model: &Model, ctrl: &[f64]) {
        let mut probe = Probe::new(self, model, ctrl);
        // base of the output tangent: the smoothed next state
        let mut base_next = self.point.state.clone();
        next_state_into(model, &self.point.state, &self.w, &mut base_next);
        let out_base = match Point::new(model, &base_next, Coordinates::Maximal) {
            Ok(mut p) => {
                p.coords = self.coords;
                p.state = base_next;
                p
            }
            Err(_) => return,
        };
        let mut inputs = Vec::new();
        inputs.extend((0..self.nx).map(Input::State));
        inputs.extend((0..self.nu).map(Input::Ctrl));
        if self.wrt.params {
            inputs.extend(model.param_layout().into_iter().map(Input::Param));
        }
        let ny = self.coords.dim(model);
        let mut dir = vec![0.0; ny];
        let (mut r_plus, mut y_plus) = (vec![0.0; self.w.len()], vec![0.0; ny]);
        for (col, input) in inputs.into_iter().enumerate() {
            let eps = match input {
                Input::Param(p) => 1e-6 * model.param(p).abs().max(1.0),
                _ => FD_STEP,
            };
            for sign in [1.0, -1.0] {
                match input {
                    Input::State(i) => {
                        dir.fill(0.0);
                        dir[i] = 1.0;
                        self.point.perturbed(
                            model,
                            &dir,
                            sign * eps,
                            &mut probe.state,
                            &mut probe.scratch,
                        );
                    }
                    Input::Ctrl(i) => probe.ctrl[i] = ctrl[i] + sign * eps,
                    Input::Param(p) => probe.model.set_param(p, model.param(p) + sign * eps),
                }
                probe.eval(&self.w, &out_base);
                if sign > 0.0 {
                    r_plus.copy_from_slice(&probe.residual);
                    y_plus.copy_from_slice(&probe.y);
                }
            }
            let inv = 1.0 / (2.0 * eps);
            for (i, (p, m)) in r_plus.iter().zip(&probe.residual).enumerate() {
                self.r_z[(i, col)] = (p - m) * inv;
            }
            for (i, (p, m)) in y_plus.iter().zip(&probe.y).enumerate() {
                self.y_z[(i, col)] = (p - m) * inv;
            }
            // restore
            match input {
                Input::State(_) => probe.state.clone_from(&self.point.state),
                Input::Ctrl(i) => probe.ctrl[i] = ctrl[i],
                Input::Param(p) => probe.model.set_param(p, model.param(p)),
            }
        }
        // ∂Y/∂w: only the body velocities enter the output map
        let mut w = self.w.clone();
        for b in 1..model.nbody() {
            let o = body_node(b).map_or(0, |n| model.topology.pattern.offset(n));
            for k in o..o + 6 {
                let mut col = [vec![0.0; ny], vec![0.0; ny]];
                for (s, sign) in [1.0, -1.0].into_iter().enumerate() {
                    w[k] = self.w[k] + sign * FD_STEP;
                    next_state_into(model, &self.point.state, &w, &mut probe.next);
                    out_base.difference(model, &probe.next, &mut col[s], &mut probe.scratch);
                }
                w[k] = self.w[k];
                for (i, (p, m)) in col[0].iter().zip(&col[1]).enumerate() {
                    self.y_w[(i, k)] = (p - m) / (2.0 * FD_STEP);
                }
            }
        }
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
        self.central
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

    /// `R_w⁻¹ x` with the factorisation of the gradient point.
    fn solve(&mut self, model: &Model, x: &mut [f64]) {
        self.ws.matrix.solve(&model.topology.pattern, x);
    }

    /// Full Jacobians (`A`, `B`, `C`; a block has no columns when its input was not selected).
    pub fn jacobians(&mut self, model: &Model) -> Result<Jacobians> {
        self.check(model)?;
        let nz = self.nx + self.nu + self.np;
        let nw = self.w.len();
        let mut x = DMatrix::zeros(nw, nz);
        let mut col = vec![0.0; nw];
        for j in 0..nz {
            col.copy_from_slice(self.r_z.column(j).as_slice());
            self.solve(model, &mut col);
            x.column_mut(j).copy_from_slice(&col);
        }
        let full = &self.y_z - &self.y_w * x;
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
        ensure!(
            adj_next.len() == ny,
            Error::shape("adjoint_next", &[ny], &[adj_next.len()])
        );
        ensure!(
            adj_next.iter().all(|x| x.is_finite()),
            Error::input("adjoint_next", adj_next, "must be finite")
        );
        let a = DVector::from_column_slice(adj_next);
        let mut lam: Vec<f64> = (self.y_w.transpose() * &a).iter().copied().collect();
        self.ws
            .matrix
            .solve_transpose(&model.topology.pattern, &mut lam);
        let lam = DVector::from_vec(lam);
        let adj = self.y_z.transpose() * &a - self.r_z.transpose() * lam;
        let s = adj.as_slice();
        Ok(Adjoints {
            state: s[..self.nx].to_vec(),
            ctrl: s[self.nx..self.nx + self.nu].to_vec(),
            params: s[self.nx + self.nu..].to_vec(),
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
        for (name, v, n) in [
            ("dx", dx, self.nx),
            ("du", du, self.nu),
            ("dtheta", dtheta, self.np),
        ] {
            ensure!(v.len() == n, Error::shape(name, &[n], &[v.len()]));
            ensure!(
                v.iter().all(|x| x.is_finite()),
                Error::input(name, v, "must be finite")
            );
        }
        let t = DVector::from_iterator(
            self.nx + self.nu + self.np,
            dx.iter().chain(du).chain(dtheta).copied(),
        );
        let mut dw: Vec<f64> = (&self.r_z * &t).iter().copied().collect();
        self.solve(model, &mut dw);
        let out = &self.y_z * &t - &self.y_w * DVector::from_vec(dw);
        Ok(out.iter().copied().collect())
    }
}
