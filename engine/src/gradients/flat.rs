//! Flat minimal-state functions for array frameworks (JAX, PyTorch): the state is
//! `x = [qpos, qvel]` (length `nq + nv`, quaternions as 4 raw numbers), so an adjoint of `x` is
//! a plain array of the same shape. Batched versions run the batch in parallel (rayon).
//!
//! A flat state carries no solver warm start; each flat step hands the warm start of the state
//! it returns to the flat step that takes that state next ([`super::hints`]), and [`rollout`]
//! chains full states internally. The environments step full states instead ([`crate::batch`]).
use rayon::prelude::*;

use super::rollout::{advance, advance_stored, rollout_vjp_kept};
use super::tangent::{
    Coordinates, qpos_adjoint_from_tangent, qpos_raw_from_tangent, qpos_tangent_from_raw,
    tangent_adjoint_from_qpos,
};
use super::{Linearization, Wrt};
use crate::joints::coordinates::{qpos_into, qvel_into, set_minimal};
use crate::model::Model;
use crate::state::{Recycled, State, Workspace};
use crate::{Error, Result, ensure};

/// Length of a flat state.
pub fn nx(model: &Model) -> usize {
    model.nq + model.nv
}

/// The full state of a flat `x` (reference warm start).
pub fn state_of(model: &Model, x: &[f64]) -> Result<State> {
    ensure!(
        x.len() == nx(model),
        Error::shape("x", &[nx(model)], &[x.len()])
    );
    let mut s = State::reference(model);
    set_minimal(model, &mut s, &x[..model.nq], &x[model.nq..])?;
    Ok(s)
}

/// The full state of a flat `x`, with the warm start of the flat step that returned `x` if
/// one did ([`super::hints`]), else the reference one.
pub(crate) fn warm_state_of(model: &Model, x: &[f64]) -> Result<State> {
    let mut s = state_of(model, x)?;
    super::hints::recall(model, x, &mut s);
    Ok(s)
}

/// `[qpos, qvel]` of a state.
pub fn flat_of(model: &Model, state: &State, out: &mut [f64]) {
    let (q, v) = out.split_at_mut(model.nq);
    qpos_into(model, state, q);
    qvel_into(model, state, v);
}

/// One step of a flat state. Errors (including non-convergence) name the failure.
pub fn step(model: &Model, x: &[f64], u: &[f64]) -> Result<Vec<f64>> {
    step_kept(model, x, u, false)
}

/// [`step`]; with `keep`, the solved step is kept ([`super::kept`]) for the [`step_vjp`] with
/// the same model and inputs that differentiation calls next, which then does not solve it
/// again. The next state is the same bits either way.
pub fn step_kept(model: &Model, x: &[f64], u: &[f64], keep: bool) -> Result<Vec<f64>> {
    let s = warm_state_of(model, x)?;
    let mut ws = Recycled::new(Workspace::pooled(model));
    let mut out = vec![0.0; nx(model)];
    if keep {
        let (next, stored) = advance_stored(model, &s, u, Coordinates::Minimal, &mut ws)?;
        flat_of(model, &next, &mut out);
        super::hints::remember(model, &out, &next);
        let forward = super::kept::Forward {
            states: vec![s, next],
            solutions: vec![stored],
        };
        super::kept::keep(super::kept::Key::new(model, x, u), forward);
    } else {
        let next = advance(model, &s, u, Coordinates::Minimal, &mut ws)?;
        flat_of(model, &next, &mut out);
        super::hints::remember(model, &out, &next);
    }
    Ok(out)
}

/// One step that reports instead of failing: `(x⁺, status code)` with the codes of
/// [`crate::SolveStatus::code`] (0 = converged). A step that did not converge returns its last
/// iterate, flagged, so array programs (under `jit`) can mask it instead of aborting.
pub fn step_with_status(model: &Model, x: &[f64], u: &[f64]) -> Result<(Vec<f64>, u8)> {
    let mut s = warm_state_of(model, x)?;
    let mut ws = Recycled::new(Workspace::pooled(model));
    // subdivides a failed step, as `ukemi.step` does
    let report = crate::step::step(model, &mut s, &mut ws, u)?;
    let mut out = vec![0.0; nx(model)];
    flat_of(model, &s, &mut out);
    if report.status.code() == 0 {
        super::hints::remember(model, &out, &s);
    }
    Ok((out, report.status.code()))
}

/// The linearisation of the flat step from `x` (its state `s`) with `u`: of its stored
/// solution when a differentiated forward pass kept it ([`step_kept`]), else of a new solve.
fn linearise(
    model: &Model,
    s: &State,
    x: &[f64],
    u: &[f64],
    wrt: Wrt,
    kappa_grad: Option<f64>,
) -> Result<Linearization> {
    let c = Coordinates::Minimal;
    match super::kept::take(&super::kept::Key::new(model, x, u)) {
        Some(f) if f.solutions.len() == 1 => {
            let ws = Workspace::pooled(model);
            let stored = &f.solutions[0];
            Linearization::from_stored(model, &f.states[0], u, c, wrt, kappa_grad, stored, ws)
        }
        _ => Linearization::new(model, s, u, c, wrt, kappa_grad),
    }
}

/// Adjoints `(x, u, params)` of one flat step given the adjoint of its output.
pub fn step_vjp(
    model: &Model,
    x: &[f64],
    u: &[f64],
    adj_next: &[f64],
    kappa_grad: Option<f64>,
    with_params: bool,
) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>)> {
    let (nq, nv) = (model.nq, model.nv);
    ensure!(
        adj_next.len() == nq + nv,
        Error::shape("adjoint_next", &[nq + nv], &[adj_next.len()])
    );
    let s = warm_state_of(model, x)?;
    let wrt = Wrt {
        state: true,
        ctrl: true,
        params: with_params,
    };
    let mut lin = linearise(model, &s, x, u, wrt, kappa_grad)?;
    let mut qpos_next = vec![0.0; nq];
    qpos_into(model, lin.next_state(), &mut qpos_next);
    let mut adj_t = vec![0.0; 2 * nv];
    tangent_adjoint_from_qpos(model, &qpos_next, &adj_next[..nq], &mut adj_t[..nv]);
    adj_t[nv..].copy_from_slice(&adj_next[nq..]);
    let a = lin.vjp(model, &adj_t)?;
    let mut adj_x = vec![0.0; nq + nv];
    qpos_adjoint_from_tangent(model, &x[..nq], &a.state[..nv], &mut adj_x[..nq]);
    adj_x[nq..].copy_from_slice(&a.state[nv..]);
    Ok((adj_x, a.ctrl, a.params))
}

/// Jacobians of one flat step in raw flat coordinates: `(∂x⁺/∂x (nx × nx), ∂x⁺/∂u (nx × nu),
/// ∂x⁺/∂θ (nx × nparams, empty unless `with_params`))`, row-major. Built from the engine's
/// minimal-coordinate Jacobians and the exact maps between raw quaternions and tangents, so
/// the quaternion columns include the normalisation the step applies to its input.
pub fn step_jacobians(
    model: &Model,
    x: &[f64],
    u: &[f64],
    kappa_grad: Option<f64>,
    with_params: bool,
) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>)> {
    use nalgebra::DMatrix;
    let (nq, nv) = (model.nq, model.nv);
    let n = nq + nv;
    let s = warm_state_of(model, x)?;
    let wrt = Wrt {
        state: true,
        ctrl: true,
        params: with_params,
    };
    let mut lin = linearise(model, &s, x, u, wrt, kappa_grad)?;
    let jac = lin.jacobians(model)?;
    let mut qpos_next = vec![0.0; nq];
    qpos_into(model, lin.next_state(), &mut qpos_next);
    // raw input -> tangent (2nv × n) and tangent -> raw output (n × 2nv)
    let mut t_in = DMatrix::zeros(2 * nv, n);
    let mut t_out = DMatrix::zeros(n, 2 * nv);
    let (mut e, mut col) = (vec![0.0; n.max(2 * nv)], vec![0.0; n.max(2 * nv)]);
    for k in 0..nq {
        e.fill(0.0);
        e[k] = 1.0;
        qpos_tangent_from_raw(model, &x[..nq], &e[..nq], &mut col[..nv]);
        for (r, c) in col[..nv].iter().enumerate() {
            t_in[(r, k)] = *c;
        }
    }
    for k in 0..nv {
        t_in[(nv + k, nq + k)] = 1.0;
        e.fill(0.0);
        e[k] = 1.0;
        qpos_raw_from_tangent(model, &qpos_next, &e[..nv], &mut col[..nq]);
        for (r, c) in col[..nq].iter().enumerate() {
            t_out[(r, k)] = *c;
        }
        t_out[(nq + k, nv + k)] = 1.0;
    }
    let row_major = |m: DMatrix<f64>| m.transpose().as_slice().to_vec();
    let a = &t_out * &jac.a * &t_in;
    let b = &t_out * &jac.b;
    let c = &t_out * &jac.c;
    Ok((row_major(a), row_major(b), row_major(c)))
}

/// A rollout of `nstep` steps from flat `x0`: `(T+1, nq+nv)` row-major.
pub fn rollout(model: &Model, x0: &[f64], us: &[f64], nstep: usize) -> Result<Vec<f64>> {
    rollout_kept(model, x0, us, nstep, false)
}

/// [`rollout`]; with `keep`, its forward pass is kept ([`super::kept`]) for the
/// [`rollout_vjp`] with the same model and inputs that differentiation will call next, which
/// then solves no step again. The states are the same bits either way.
pub fn rollout_kept(
    model: &Model,
    x0: &[f64],
    us: &[f64],
    nstep: usize,
    keep: bool,
) -> Result<Vec<f64>> {
    let nu = model.nu();
    ensure!(
        us.len() == nstep * nu,
        Error::shape("us", &[nstep, nu], &[us.len() / nu.max(1), nu])
    );
    let n = nx(model);
    if keep {
        let s0 = warm_state_of(model, x0)?;
        let (states, solutions, _) =
            super::rollout::forward_stored(model, s0, us, nstep, Coordinates::Minimal)?;
        let mut out = vec![0.0; (nstep + 1) * n];
        for (s, o) in states.iter().zip(out.chunks_exact_mut(n)) {
            flat_of(model, s, o);
        }
        super::hints::remember(model, &out[nstep * n..], &states[nstep]);
        let key = super::kept::Key::new(model, x0, us);
        super::kept::keep(key, super::kept::Forward { states, solutions });
        return Ok(out);
    }
    let mut out = vec![0.0; (nstep + 1) * n];
    let mut s = warm_state_of(model, x0)?;
    let mut ws = Recycled::new(Workspace::pooled(model));
    flat_of(model, &s, &mut out[..n]);
    for k in 0..nstep {
        s = advance(
            model,
            &s,
            &us[k * nu..(k + 1) * nu],
            Coordinates::Minimal,
            &mut ws,
        )
        .map_err(|e| e.at(format!(" (step {k})")))?;
        flat_of(model, &s, &mut out[(k + 1) * n..(k + 2) * n]);
    }
    super::hints::remember(model, &out[nstep * n..], &s);
    Ok(out)
}

/// Adjoints `(x0, us, params)` of a flat rollout given `adj_xs` (`(T+1, nq+nv)` row-major).
pub fn rollout_vjp(
    model: &Model,
    x0: &[f64],
    us: &[f64],
    nstep: usize,
    adj_xs: &[f64],
    kappa_grad: Option<f64>,
    with_params: bool,
) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>)> {
    let (nq, nv, n) = (model.nq, model.nv, nx(model));
    ensure!(
        adj_xs.len() == (nstep + 1) * n,
        Error::shape("adjoint_xs", &[nstep + 1, n], &[adj_xs.len() / n, n])
    );
    let s0 = warm_state_of(model, x0)?;
    let kept = super::kept::take(&super::kept::Key::new(model, x0, us));
    let adjoint = |k: usize, s: &State, out: &mut [f64]| {
        let mut q = vec![0.0; nq];
        qpos_into(model, s, &mut q);
        let a = &adj_xs[k * n..(k + 1) * n];
        tangent_adjoint_from_qpos(model, &q, &a[..nq], &mut out[..nv]);
        out[nv..].copy_from_slice(&a[nq..]);
    };
    let (adj, _) = rollout_vjp_kept(
        model,
        &s0,
        us,
        nstep,
        Coordinates::Minimal,
        kappa_grad,
        with_params,
        &adjoint,
        kept,
    )?;
    let mut adj_x = vec![0.0; n];
    qpos_adjoint_from_tangent(model, &x0[..nq], &adj.state0[..nv], &mut adj_x[..nq]);
    adj_x[nq..].copy_from_slice(&adj.state0[nv..]);
    Ok((adj_x, adj.ctrls, adj.params))
}

static POOL: std::sync::RwLock<Option<std::sync::Arc<rayon::ThreadPool>>> =
    std::sync::RwLock::new(None);

/// Use `n` threads for batched calls (0: rayon's default, one per core).
pub fn set_num_threads(n: usize) -> Result<()> {
    let pool = if n == 0 {
        None
    } else {
        let p = rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .map_err(|e| Error::input("num_threads", n, e.to_string()))?;
        Some(std::sync::Arc::new(p))
    };
    match POOL.write() {
        Ok(mut g) => *g = pool,
        Err(poisoned) => *poisoned.into_inner() = pool,
    }
    Ok(())
}

/// Threads used by batched calls.
pub fn num_threads() -> usize {
    match POOL.read().ok().and_then(|g| g.clone()) {
        Some(p) => p.current_num_threads(),
        None => rayon::current_num_threads(),
    }
}

/// Run `f` (which may use rayon) in the pool of [`set_num_threads`], or rayon's global pool.
pub(crate) fn in_pool<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    match POOL.read().ok().and_then(|g| g.clone()) {
        Some(p) => p.install(f),
        None => f(),
    }
}

/// Apply `f` to each batch element in parallel; `models` has one model or one per element.
/// The first error wins (with its batch index).
pub fn batched<T: Send>(
    models: &[Model],
    batch: usize,
    f: impl Fn(&Model, usize) -> Result<T> + Sync,
) -> Result<Vec<T>> {
    ensure!(
        models.len() == 1 || models.len() == batch,
        Error::shape("params", &[batch], &[models.len()])
    );
    let pool = POOL.read().ok().and_then(|g| g.clone());
    let run = || {
        (0..batch)
            .into_par_iter()
            .map(|i| {
                let m = if models.len() == 1 {
                    &models[0]
                } else {
                    &models[i]
                };
                f(m, i).map_err(|e| e.at(format!(" (batch element {i})")))
            })
            .collect()
    };
    match pool {
        Some(p) => p.install(run),
        None => run(),
    }
}
