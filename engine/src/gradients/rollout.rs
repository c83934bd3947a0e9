//! Reverse-mode sweep over a whole trajectory: the gradient of a loss on every state with
//! respect to the initial state, every control and the parameters.
use super::tangent::{Coordinates, Point};
use super::{Linearization, StoredStep, Wrt, substeps};
use crate::model::Model;
use crate::solver::newton;
use crate::state::{State, Workspace};
use crate::step::AppliedForces;
use crate::{Error, Result, ensure};

/// Adjoints of a rollout's inputs.
#[derive(Clone, Debug)]
pub struct RolloutAdjoint {
    /// Adjoint of the initial state (tangent coordinates).
    pub state0: Vec<f64>,
    /// Adjoints of the controls, row-major `(nstep, nu)`.
    pub ctrls: Vec<f64>,
    /// Adjoint of the parameters (summed over steps).
    pub params: Vec<f64>,
}

/// One step of the chain the gradients differentiate: in minimal coordinates the state is
/// rebuilt from `(qpos, qvel)` first, so the rollout is `x_{k+1} = F(x_k, u_k)` exactly.
pub(crate) fn advance(
    model: &Model,
    state: &State,
    ctrl: &[f64],
    coords: Coordinates,
    ws: &mut Workspace,
) -> Result<State> {
    advance_stored(model, state, ctrl, coords, ws).map(|(s, _)| s)
}

/// [`advance`], also returning what the reverse sweep needs to linearise the step without
/// solving it again. A step whose whole solve fails is subdivided as [`crate::step`] does.
fn advance_stored(
    model: &Model,
    state: &State,
    ctrl: &[f64],
    coords: Coordinates,
    ws: &mut Workspace,
) -> Result<(State, StoredStep)> {
    let mut s = Point::new(model, state, coords)?.state;
    crate::step::validate_inputs(model, &s, ws, ctrl, &AppliedForces::default())?;
    newton::prepare(model, &s, ws, ctrl, &AppliedForces::default());
    let report = newton::solve(model, &s, ws);
    match substeps::retry(model, &s, ws, ctrl, report)
        .map_err(|e| e.at(" (rollout step)".to_string()))?
    {
        StoredStep::Whole(whole) => {
            newton::write_state(model, &mut s, ws);
            Ok((s, StoredStep::Whole(whole)))
        }
        StoredStep::Substeps(sub) => Ok((sub.next().clone(), StoredStep::Substeps(sub))),
    }
}

/// Gradient of `L(x_0, …, x_T)` through the rollout from `state` with `ctrls` (row-major
/// `(nstep, nu)`), given `adjoint_states` = `∂L/∂x_k` for k = 0..=T (row-major `(T+1, ny)`,
/// tangent coordinates). The forward pass stores the states and each step's solution; the
/// reverse pass linearises each step at its stored solution (no second solve; with
/// `kappa_grad`, after the move to the central path) and applies one transposed
/// back-substitution per step.
#[allow(clippy::too_many_arguments)]
pub fn rollout_vjp(
    model: &Model,
    state: &State,
    ctrls: &[f64],
    nstep: usize,
    adjoint_states: &[f64],
    coords: Coordinates,
    kappa_grad: Option<f64>,
    with_params: bool,
) -> Result<RolloutAdjoint> {
    let ny = coords.dim(model);
    ensure!(
        adjoint_states.len() == (nstep + 1) * ny,
        Error::shape(
            "adjoint_states",
            &[nstep + 1, ny],
            &[adjoint_states.len() / ny.max(1), ny]
        )
    );
    let adjoint = |k: usize, _: &State, out: &mut [f64]| {
        out.copy_from_slice(&adjoint_states[k * ny..(k + 1) * ny]);
    };
    rollout_vjp_with(
        model,
        state,
        ctrls,
        nstep,
        coords,
        kappa_grad,
        with_params,
        &adjoint,
    )
    .map(|(adj, _)| adj)
}

/// [`rollout_vjp`] with the loss adjoint of each state supplied by `adjoint(k, x_k, out)`
/// (tangent coordinates). Also returns the states `x_0..=x_T`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn rollout_vjp_with(
    model: &Model,
    state: &State,
    ctrls: &[f64],
    nstep: usize,
    coords: Coordinates,
    kappa_grad: Option<f64>,
    with_params: bool,
    adjoint: &dyn Fn(usize, &State, &mut [f64]),
) -> Result<(RolloutAdjoint, Vec<State>)> {
    let (nu, ny) = (model.nu(), coords.dim(model));
    ensure!(
        ctrls.len() == nstep * nu,
        Error::shape("ctrls", &[nstep, nu], &[ctrls.len() / nu.max(1), nu])
    );
    state.check_model(model)?;
    let mut ws = Workspace::pooled(model);
    let mut states = Vec::with_capacity(nstep + 1);
    let mut solutions = Vec::with_capacity(nstep);
    states.push(Point::new(model, state, coords)?.state);
    for k in 0..nstep {
        let (next, solution) = advance_stored(
            model,
            &states[k],
            &ctrls[k * nu..(k + 1) * nu],
            coords,
            &mut ws,
        )
        .map_err(|e| e.at(format!(" (step {k})")))?;
        states.push(next);
        solutions.push(solution);
    }
    let wrt = Wrt {
        state: true,
        ctrl: true,
        params: with_params,
    };
    let mut adj = vec![0.0; ny];
    let mut loss_adj = vec![0.0; ny];
    adjoint(nstep, &states[nstep], &mut adj);
    ensure!(
        adj.iter().all(|x| x.is_finite()),
        Error::input(format!("adjoint_states[{nstep}]"), &adj, "must be finite")
    );
    let mut out = RolloutAdjoint {
        state0: vec![],
        ctrls: vec![0.0; nstep * nu],
        params: vec![
            0.0;
            if with_params {
                model.param_layout().len()
            } else {
                0
            }
        ],
    };
    // one workspace for the whole sweep (a robot's is megabytes: allocating it per step cost
    // as much as the step's back-substitution)
    let mut spare = Some(ws);
    for k in (0..nstep).rev() {
        let u = &ctrls[k * nu..(k + 1) * nu];
        let stored = &solutions[k];
        let ws = spare.take().unwrap_or_else(|| Workspace::pooled(model));
        let mut lin =
            Linearization::from_stored(model, &states[k], u, coords, wrt, kappa_grad, stored, ws)
                .map_err(|e| e.at(format!(" (step {k})")))?;
        let a = lin.vjp(model, &adj)?;
        spare = Some(lin.into_workspace());
        out.ctrls[k * nu..(k + 1) * nu].copy_from_slice(&a.ctrl);
        for (p, g) in out.params.iter_mut().zip(&a.params) {
            *p += g;
        }
        adjoint(k, &states[k], &mut loss_adj);
        ensure!(
            loss_adj.iter().all(|x| x.is_finite()),
            Error::input(format!("adjoint_states[{k}]"), &loss_adj, "must be finite")
        );
        adj = a.state;
        for (x, g) in adj.iter_mut().zip(&loss_adj) {
            *x += g;
        }
    }
    out.state0 = adj;
    Ok((out, states))
}
