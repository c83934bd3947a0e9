//! Reverse-mode sweep over a whole trajectory: the gradient of a loss on every state with
//! respect to the initial state, every control and the parameters.
//!
//! The forward pass stores each step's solution. A step's linearisation at its stored solution
//! (factored Newton matrix, partials) depends on nothing the sweep computes, only its product
//! with the adjoint does; so with a second thread to run on ([`Sweep::Overlapped`]) each
//! solved step is handed to the pool and its Jacobians formed while the forward pass goes on,
//! and the reverse sweep is dense products with the adjoints. On one thread, or inside a
//! batch that fills the pool, each step is linearised when the sweep reaches it and applies
//! one transposed back-substitution ([`Sweep::Sequential`], the least work). When the forward
//! pass itself was kept by a differentiated JAX/torch rollout ([`super::kept`]), no step is
//! solved again: the sweep only linearises them (all at once on the pool).
use std::sync::OnceLock;

use nalgebra::{DMatrix, DVector};

use super::kept::Forward;
use super::tangent::{Coordinates, Point};
use super::{Adjoints, Jacobians, Linearization, StoredStep, Wrt, flat, substeps};
use crate::model::Model;
use crate::solver::newton;
use crate::state::{Recycled, State, Workspace};
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
pub(super) fn advance_stored(
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
/// tangent coordinates). The forward pass stores the states and each step's solution; each
/// step is linearised at its stored solution (no second solve; with `kappa_grad`, after the
/// move to the central path), on the thread pool during the forward pass when there is more
/// than one thread (see the module docs).
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
    rollout_vjp_kept(
        model,
        state,
        ctrls,
        nstep,
        coords,
        kappa_grad,
        with_params,
        &adjoint,
        None,
    )
    .map(|(adj, _)| adj)
}

/// Most bytes of Jacobians an overlapped sweep may hold (`T · ny · (ny + nu + nθ)` doubles:
/// 32 MB for 1000 steps of the humanoid without parameters); a longer rollout is swept
/// sequentially.
const OVERLAP_BUDGET: usize = 512 << 20;

/// How the reverse sweep gets each step's linearisation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Sweep {
    /// Linearise each step at its stored solution when the sweep reaches it, and apply one
    /// transposed back-substitution (the least work, all on the calling thread).
    Sequential,
    /// Linearise every step on the thread pool while the forward pass goes on, forming its
    /// Jacobians; the sweep multiplies them by the adjoints. About 15% more work (one
    /// back-substitution per output instead of one in all), but off the forward pass's thread:
    /// a rollout's time is then about its forward pass's.
    Overlapped,
}

impl Sweep {
    /// Overlapped when there is a second thread to run on, the call is not already on the pool
    /// (a batch of rollouts fills the threads by itself) and the Jacobians fit the budget.
    fn choose(nstep: usize, ny: usize, nz: usize) -> Sweep {
        let bytes = nstep
            .saturating_mul(ny)
            .saturating_mul(nz)
            .saturating_mul(8);
        if spare_thread() && bytes <= OVERLAP_BUDGET {
            Sweep::Overlapped
        } else {
            Sweep::Sequential
        }
    }
}

/// Whether there is a second thread to put work on: the pool ([`flat::num_threads`]) has
/// more than one, and the call is not already running on it (a batch fills the pool by
/// itself).
fn spare_thread() -> bool {
    rayon::current_thread_index().is_none() && flat::num_threads() > 1
}

/// The Jacobians of every step of a rollout (what [`Linearization::jacobians`] gives for each
/// step from the state the rollout reached), and the states `x_0..=x_T`.
#[derive(Clone, Debug)]
pub struct RolloutJacobians {
    /// `x_0..=x_T`: the given state, then each step's next state (in minimal coordinates
    /// every step rebuilds its start from `(qpos, qvel)` first, as [`rollout_vjp`] and
    /// [`Linearization::new`] do, so the rollout is `x_{k+1} = F(x_k, u_k)` exactly).
    pub states: Vec<State>,
    /// The Jacobians of step `k`, `∂x_{k+1}/∂(x_k, u_k, θ)`.
    pub steps: Vec<Jacobians>,
}

/// Roll out `nstep` steps from `state` with `ctrls` (row-major `(nstep, nu)`) and linearise
/// every step (the inputs `wrt`, gradients at `kappa_grad` as for [`Linearization::new`]):
/// what trajectory optimisers (iLQR, DDP) and Table V's workload need. With a second thread
/// the steps are linearised on the pool while the forward pass goes on (see the module docs),
/// with the same results bit for bit.
#[allow(clippy::too_many_arguments)]
pub fn rollout_jacobians(
    model: &Model,
    state: &State,
    ctrls: &[f64],
    nstep: usize,
    coords: Coordinates,
    wrt: Wrt,
    kappa_grad: Option<f64>,
) -> Result<RolloutJacobians> {
    rollout_jacobians_sweep(
        model,
        state,
        ctrls,
        nstep,
        coords,
        wrt,
        kappa_grad,
        spare_thread(),
    )
}

#[allow(clippy::too_many_arguments)]
fn rollout_jacobians_sweep(
    model: &Model,
    state: &State,
    ctrls: &[f64],
    nstep: usize,
    coords: Coordinates,
    wrt: Wrt,
    kappa_grad: Option<f64>,
    overlapped: bool,
) -> Result<RolloutJacobians> {
    let nu = model.nu();
    ensure!(
        ctrls.len() == nstep * nu,
        Error::shape("ctrls", &[nstep, nu], &[ctrls.len() / nu.max(1), nu])
    );
    state.check_model(model)?;
    super::check_kappa(kappa_grad)?;
    // (each step rebuilds its start in `coords` itself; see `rollout_vjp_sweep`)
    let state0 = state.clone();
    let (states, steps) = if overlapped {
        flat::in_pool(|| forward_overlapped(model, state0, ctrls, nstep, coords, wrt, kappa_grad))?
    } else {
        let (states, solutions, ws) = forward_stored(model, state0, ctrls, nstep, coords)?;
        let mut spare = Some(ws);
        let mut steps = Vec::with_capacity(nstep);
        for (k, stored) in solutions.iter().enumerate() {
            let u = &ctrls[k * nu..(k + 1) * nu];
            let ws = spare.take().unwrap_or_else(|| Workspace::pooled(model));
            let jac = Linearization::from_stored(
                model, &states[k], u, coords, wrt, kappa_grad, stored, ws,
            )
            .and_then(|mut lin| {
                let jac = lin.jacobians(model);
                spare = Some(lin.into_workspace());
                jac
            });
            steps.push(Some(jac));
        }
        (states, steps)
    };
    let steps = steps
        .into_iter()
        .enumerate()
        .map(|(k, jac)| {
            jac.ok_or_else(|| {
                // unreachable: the scope returns after every spawned step has set its slot
                Error::Unsupported(format!("rollout step {k}: its Jacobians were not formed"))
            })?
            .map_err(|e| e.at(format!(" (step {k})")))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(RolloutJacobians { states, steps })
}

/// [`rollout_vjp`] with the loss adjoint of each state supplied by `adjoint(k, x_k, out)`
/// (tangent coordinates), from a kept forward pass when there is one (its states and solutions
/// from the same inputs, see [`super::kept`]). Also returns the states `x_0..=x_T`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn rollout_vjp_kept(
    model: &Model,
    state: &State,
    ctrls: &[f64],
    nstep: usize,
    coords: Coordinates,
    kappa_grad: Option<f64>,
    with_params: bool,
    adjoint: &dyn Fn(usize, &State, &mut [f64]),
    kept: Option<Forward>,
) -> Result<(RolloutAdjoint, Vec<State>)> {
    let (nu, ny) = (model.nu(), coords.dim(model));
    let np = if with_params {
        model.param_layout().len()
    } else {
        0
    };
    let sweep = Sweep::choose(nstep, ny, ny + nu + np);
    rollout_vjp_sweep(
        model,
        state,
        ctrls,
        nstep,
        coords,
        kappa_grad,
        with_params,
        adjoint,
        sweep,
        kept,
    )
}

/// [`rollout_vjp_kept`] by the given sweep.
#[allow(clippy::too_many_arguments)]
pub(crate) fn rollout_vjp_sweep(
    model: &Model,
    state: &State,
    ctrls: &[f64],
    nstep: usize,
    coords: Coordinates,
    kappa_grad: Option<f64>,
    with_params: bool,
    adjoint: &dyn Fn(usize, &State, &mut [f64]),
    sweep: Sweep,
    kept: Option<Forward>,
) -> Result<(RolloutAdjoint, Vec<State>)> {
    let nu = model.nu();
    ensure!(
        ctrls.len() == nstep * nu,
        Error::shape("ctrls", &[nstep, nu], &[ctrls.len() / nu.max(1), nu])
    );
    state.check_model(model)?;
    let wrt = Wrt {
        state: true,
        ctrl: true,
        params: with_params,
    };
    let np = if with_params {
        model.param_layout().len()
    } else {
        0
    };
    if let Some(f) = kept {
        // the forward pass was kept ([`super::kept`]): only the linearisations are left
        ensure!(
            f.states.len() == nstep + 1 && f.solutions.len() == nstep,
            Error::shape("kept rollout", &[nstep], &[f.solutions.len()])
        );
        let reverse = match sweep {
            Sweep::Overlapped => Reverse::Jacobians(flat::in_pool(|| {
                linearise_all(model, &f, ctrls, coords, wrt, kappa_grad)
            })),
            Sweep::Sequential => Reverse::Stored(f.solutions, None),
        };
        let how = (wrt, kappa_grad);
        return reverse_sweep(model, ctrls, coords, how, np, adjoint, f.states, reverse);
    }
    // (each step rebuilds its start in `coords` itself, as `flat::rollout` does: rebuilding
    // here too would start the rollout from a state a rounding away from the forward pass's,
    // and a chaotic rollout then ends elsewhere)
    let state0 = state.clone();
    let (states, reverse) = match sweep {
        Sweep::Overlapped => {
            let (states, jacobians) = flat::in_pool(|| {
                forward_overlapped(model, state0, ctrls, nstep, coords, wrt, kappa_grad)
            })?;
            (states, Reverse::Jacobians(jacobians))
        }
        Sweep::Sequential => {
            let (states, solutions, ws) = forward_stored(model, state0, ctrls, nstep, coords)?;
            (states, Reverse::Stored(solutions, Some(Box::new(ws))))
        }
    };
    reverse_sweep(
        model,
        ctrls,
        coords,
        (wrt, kappa_grad),
        np,
        adjoint,
        states,
        reverse,
    )
}

/// Every step of a kept forward pass linearised on the thread pool, its Jacobians formed.
fn linearise_all(
    model: &Model,
    f: &Forward,
    ctrls: &[f64],
    coords: Coordinates,
    wrt: Wrt,
    kappa_grad: Option<f64>,
) -> Vec<StepJacobians> {
    use rayon::prelude::*;
    let nu = model.nu();
    (0..f.solutions.len())
        .into_par_iter()
        .map(|k| {
            let u = &ctrls[k * nu..(k + 1) * nu];
            let ws = Workspace::pooled(model);
            let x = &f.states[k];
            let stored = &f.solutions[k];
            Some(
                Linearization::from_stored(model, x, u, coords, wrt, kappa_grad, stored, ws)
                    .and_then(|mut lin| lin.jacobians(model)),
            )
        })
        .collect()
}

/// The reverse sweep over the states `x_0..=x_T` of a forward pass, each step's linearisation
/// given by `reverse`.
#[allow(clippy::too_many_arguments)]
fn reverse_sweep(
    model: &Model,
    ctrls: &[f64],
    coords: Coordinates,
    (wrt, kappa_grad): (Wrt, Option<f64>),
    np: usize,
    adjoint: &dyn Fn(usize, &State, &mut [f64]),
    states: Vec<State>,
    mut reverse: Reverse,
) -> Result<(RolloutAdjoint, Vec<State>)> {
    let (nu, ny, nstep) = (model.nu(), coords.dim(model), states.len() - 1);
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
        params: vec![0.0; np],
    };
    for k in (0..nstep).rev() {
        let u = &ctrls[k * nu..(k + 1) * nu];
        let a = match &mut reverse {
            Reverse::Stored(solutions, spare) => {
                let ws = spare
                    .take()
                    .map_or_else(|| Workspace::pooled(model), |ws| *ws);
                let stored = &solutions[k];
                let mut lin = Linearization::from_stored(
                    model, &states[k], u, coords, wrt, kappa_grad, stored, ws,
                )
                .map_err(|e| e.at(format!(" (step {k})")))?;
                let a = lin.vjp(model, &adj)?;
                *spare = Some(Box::new(lin.into_workspace()));
                a
            }
            Reverse::Jacobians(jacobians) => {
                let jac = jacobians[k].take().ok_or_else(|| {
                    // unreachable: the scope returns after every spawned step has set its slot
                    Error::Unsupported(format!("rollout step {k}: its Jacobians were not formed"))
                })?;
                let jac = jac.map_err(|e| e.at(format!(" (step {k})")))?;
                transposed_products(&jac, &adj)?
            }
        };
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

/// What the reverse sweep reads for each step.
enum Reverse {
    /// The stored solutions, each linearised when the sweep reaches it (in one workspace,
    /// reused: a robot's is megabytes, and allocating it per step cost as much as the step's
    /// back-substitution).
    Stored(Vec<StoredStep>, Option<Box<Workspace>>),
    /// Each step's Jacobians, formed while the forward pass went on.
    Jacobians(Vec<StepJacobians>),
}

/// A step's Jacobians as its task left them (`None` only if the task never ran).
type StepJacobians = Option<Result<Jacobians>>;

/// `(Aᵀ a, Bᵀ a, Cᵀ a)`: the adjoints of a step's inputs from its Jacobians, given the adjoint
/// `a` of its next state (checked as [`Linearization::vjp`] checks it).
fn transposed_products(jac: &Jacobians, adj_next: &[f64]) -> Result<Adjoints> {
    super::check_adjoint(jac.a.nrows(), adj_next)?;
    let a = DVector::from_column_slice(adj_next);
    let col = |m: &DMatrix<f64>| m.tr_mul(&a).as_slice().to_vec();
    Ok(Adjoints {
        state: col(&jac.a),
        ctrl: col(&jac.b),
        params: col(&jac.c),
    })
}

/// The forward pass alone: the states `x_0..=x_T`, each step's stored solution and the
/// workspace (for the reverse sweep to reuse).
pub(super) fn forward_stored(
    model: &Model,
    state0: State,
    ctrls: &[f64],
    nstep: usize,
    coords: Coordinates,
) -> Result<(Vec<State>, Vec<StoredStep>, Workspace)> {
    let nu = model.nu();
    let mut ws = Workspace::pooled(model);
    let mut states = Vec::with_capacity(nstep + 1);
    let mut solutions = Vec::with_capacity(nstep);
    states.push(state0);
    for k in 0..nstep {
        let u = &ctrls[k * nu..(k + 1) * nu];
        let (next, solution) = advance_stored(model, &states[k], u, coords, &mut ws)
            .map_err(|e| e.at(format!(" (step {k})")))?;
        states.push(next);
        solutions.push(solution);
    }
    Ok((states, solutions, ws))
}

/// The forward pass, handing each solved step to the thread pool to be linearised at its
/// stored solution and its Jacobians formed while the pass goes on: the steps' linearisations
/// are independent of each other and of the adjoints, so only the products with the adjoints
/// (dense and cheap) are left for the reverse sweep.
fn forward_overlapped(
    model: &Model,
    state0: State,
    ctrls: &[f64],
    nstep: usize,
    coords: Coordinates,
    wrt: Wrt,
    kappa_grad: Option<f64>,
) -> Result<(Vec<State>, Vec<StepJacobians>)> {
    let nu = model.nu();
    let slots: Vec<OnceLock<Result<Jacobians>>> = (0..nstep).map(|_| OnceLock::new()).collect();
    let states = rayon::scope(|scope| -> Result<Vec<State>> {
        let mut ws = Recycled::new(Workspace::pooled(model));
        let mut states = Vec::with_capacity(nstep + 1);
        states.push(state0);
        for k in 0..nstep {
            let u = &ctrls[k * nu..(k + 1) * nu];
            let (next, stored) = advance_stored(model, &states[k], u, coords, &mut ws)
                .map_err(|e| e.at(format!(" (step {k})")))?;
            let (x, slot) = (states[k].clone(), &slots[k]);
            scope.spawn(move |_| {
                let ws = Workspace::pooled(model);
                let jac =
                    Linearization::from_stored(model, &x, u, coords, wrt, kappa_grad, &stored, ws)
                        .and_then(|mut lin| lin.jacobians(model));
                let _ = slot.set(jac);
            });
            states.push(next);
        }
        Ok(states)
    })?;
    Ok((
        states,
        slots.into_iter().map(OnceLock::into_inner).collect(),
    ))
}

#[cfg(test)]
mod tests {
    use super::super::test_scenes::{max_diff, push, pushed_box};
    use super::*;

    fn sweep(
        m: &Model,
        s: &State,
        t: usize,
        kappa: Option<f64>,
        how: Sweep,
    ) -> Result<RolloutAdjoint> {
        let (ny, nu) = (Coordinates::Minimal.dim(m), m.nu());
        let ctrls: Vec<f64> = (0..t * nu).map(push).collect();
        let adj = |k: usize, _: &State, out: &mut [f64]| {
            for (i, o) in out.iter_mut().enumerate() {
                *o = ((k * ny + i) as f64 * 0.91).cos();
            }
        };
        let c = Coordinates::Minimal;
        rollout_vjp_sweep(m, s, &ctrls, t, c, kappa, true, &adj, how, None).map(|(r, _)| r)
    }

    /// Both sweeps give the same adjoints (the overlapped one multiplies each step's
    /// Jacobians by the adjoint, the sequential one back-substitutes the adjoint itself: they
    /// agree to the conditioning of the Newton matrix at the smoothed points).
    #[test]
    fn overlapped_and_sequential_sweeps_agree() {
        let (m, s) = pushed_box();
        for kappa in [Some(1e-4), Some(1e-6)] {
            let a = sweep(&m, &s, 25, kappa, Sweep::Sequential).unwrap();
            let b = sweep(&m, &s, 25, kappa, Sweep::Overlapped).unwrap();
            for (x, y) in [
                (&a.state0, &b.state0),
                (&a.ctrls, &b.ctrls),
                (&a.params, &b.params),
            ] {
                let (diff, scale) = max_diff(y, x);
                assert!(
                    diff < 1e-9 * scale,
                    "kappa {kappa:?}: {diff:e} of {scale:e}"
                );
            }
            assert!(a.ctrls.iter().any(|g| g.abs() > 1e-3), "{:?}", a.ctrls);
        }
    }

    /// The Jacobians along a rollout are those of each step linearised on its own from the
    /// state the rollout reached, and both ways of forming them give the same bits.
    #[test]
    fn rollout_jacobians_are_the_steps_jacobians() {
        let (m, s) = pushed_box();
        let (t, c) = (20, Coordinates::Minimal);
        let ctrls: Vec<f64> = (0..t).map(push).collect();
        for kappa in [None, Some(1e-4)] {
            let r = rollout_jacobians_sweep(&m, &s, &ctrls, t, c, Wrt::ALL, kappa, true).unwrap();
            let q = rollout_jacobians_sweep(&m, &s, &ctrls, t, c, Wrt::ALL, kappa, false).unwrap();
            assert_eq!((r.states.len(), r.steps.len()), (t + 1, t));
            for (k, (a, b)) in r.steps.iter().zip(&q.steps).enumerate() {
                for (x, y) in [(&a.a, &b.a), (&a.b, &b.b), (&a.c, &b.c)] {
                    let same = x
                        .iter()
                        .zip(y.iter())
                        .all(|(p, q)| p.to_bits() == q.to_bits());
                    assert!(same, "step {k}, kappa {kappa:?}");
                }
                let mut lin =
                    Linearization::new(&m, &r.states[k], &ctrls[k..=k], c, Wrt::ALL, kappa)
                        .unwrap();
                let j = lin.jacobians(&m).unwrap();
                for (x, y) in [(&a.a, &j.a), (&a.b, &j.b), (&a.c, &j.c)] {
                    let scale = y.amax().max(1.0);
                    assert!((x - y).amax() <= 1e-12 * scale, "step {k}, kappa {kappa:?}");
                }
                let next = Point::new(&m, lin.next_state(), c).unwrap().state;
                assert_eq!(crate::qpos(&m, &next), crate::qpos(&m, &r.states[k + 1]));
            }
        }
    }

    /// The box sticks and slides along the rollout (so the test above crosses both).
    #[test]
    fn the_box_sticks_and_slides() {
        let (m, mut s) = pushed_box();
        let mut ws = Workspace::new(&m);
        let (mut stuck, mut sliding) = (0, 0);
        for k in 0..25 {
            crate::step(&m, &mut s, &mut ws, &[push(k)]).unwrap();
            let vx = crate::qvel(&m, &s)[0].abs();
            stuck += usize::from(vx < 1e-6);
            sliding += usize::from(vx > 1e-2);
        }
        assert!(
            stuck > 3 && sliding > 3,
            "stuck {stuck}, sliding {sliding} of 25"
        );
    }

    /// A bad loss adjoint is reported at the same step by both sweeps.
    #[test]
    fn both_sweeps_report_a_non_finite_adjoint_at_its_step() {
        let (m, s) = pushed_box();
        let ctrls = vec![0.5; 10 * m.nu()];
        let bad = |k: usize, _: &State, out: &mut [f64]| {
            out.fill(if k == 4 { f64::NAN } else { 1.0 });
        };
        for how in [Sweep::Sequential, Sweep::Overlapped] {
            let c = Coordinates::Minimal;
            let err = rollout_vjp_sweep(&m, &s, &ctrls, 10, c, None, false, &bad, how, None)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(err.contains("adjoint_states[4]"), "{how:?}: {err}");
        }
    }
}
