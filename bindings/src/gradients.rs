//! Gradients: step Jacobians, VJP/JVP, rollout VJP, and the batched flat-state functions the JAX
//! and torch layers call. Validate under the GIL, compute with it released.
use numpy::{
    PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2,
    PyReadonlyArray3, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use ukemi_engine::gradients::{flat, rollout_jacobians, rollout_vjp};
use ukemi_engine::{Coordinates, Linearization, Model, Wrt};

use crate::errors::{InputError, IntoPy, ModelMismatchError, guard};
use crate::model::PyModel;
use crate::state::PyState;
use crate::step::PyStepInfo;

fn coords(name: &str) -> PyResult<Coordinates> {
    Coordinates::from_name(name).ok_or_else(|| {
        InputError::new_err(format!(
            "invalid input: `coordinates` = {name:?}: must be \"minimal\" or \"maximal\""
        ))
    })
}

fn same_model(model: &PyModel, state: &PyState) -> PyResult<()> {
    if state.model.topology_id() != model.inner.topology_id() {
        return Err(ModelMismatchError::new_err(
            "state was built for a different model (make it with model.make_state())",
        ));
    }
    Ok(())
}

fn matrix<'py>(py: Python<'py>, m: &nalgebra::DMatrix<f64>) -> PyResult<Bound<'py, PyArray2<f64>>> {
    // nalgebra is column-major: the transpose's storage is the row-major data
    let (r, c) = m.shape();
    PyArray1::from_vec(py, m.transpose().as_slice().to_vec()).reshape([r, c])
}

/// Linearise one step and return `(A, B, C, next_state, info, central_info)`.
#[pyfunction]
#[pyo3(name = "_step_jacobians")]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub fn step_jacobians<'py>(
    py: Python<'py>,
    model: &PyModel,
    state: &PyState,
    ctrl: PyReadonlyArray1<'py, f64>,
    kappa_grad: Option<f64>,
    coordinates: &str,
    wrt_state: bool,
    wrt_ctrl: bool,
    wrt_params: bool,
) -> PyResult<(
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    PyState,
    PyStepInfo,
    Option<PyStepInfo>,
)> {
    guard(|| {
        same_model(model, state)?;
        let c = coords(coordinates)?;
        let ctrl = ctrl.as_slice()?.to_vec();
        let m = model.inner.clone();
        let s = state.inner.clone();
        let wrt = Wrt {
            state: wrt_state,
            ctrl: wrt_ctrl,
            params: wrt_params,
        };
        let out = py.detach(|| {
            let mut lin = Linearization::new(&m, &s, &ctrl, c, wrt, kappa_grad)?;
            let jac = lin.jacobians(&m)?;
            Ok::<_, ukemi_engine::Error>((
                jac,
                lin.next_state().clone(),
                lin.report(),
                lin.central_report(),
            ))
        });
        let (jac, next, report, central) = out.py()?;
        Ok((
            matrix(py, &jac.a)?,
            matrix(py, &jac.b)?,
            matrix(py, &jac.c)?,
            PyState {
                model: model.inner.clone(),
                inner: next,
            },
            report.into(),
            central.map(Into::into),
        ))
    })
}

/// `(adj_state, adj_ctrl, adj_params)` of one step given the adjoint of the next state.
#[pyfunction]
#[pyo3(name = "_step_vjp")]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub fn step_vjp<'py>(
    py: Python<'py>,
    model: &PyModel,
    state: &PyState,
    ctrl: PyReadonlyArray1<'py, f64>,
    adjoint_next: PyReadonlyArray1<'py, f64>,
    kappa_grad: Option<f64>,
    coordinates: &str,
    wrt_params: bool,
) -> PyResult<(
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
)> {
    guard(|| {
        same_model(model, state)?;
        let c = coords(coordinates)?;
        let (ctrl, adj) = (ctrl.as_slice()?.to_vec(), adjoint_next.as_slice()?.to_vec());
        let m = model.inner.clone();
        let s = state.inner.clone();
        let wrt = Wrt {
            state: true,
            ctrl: true,
            params: wrt_params,
        };
        let a = py
            .detach(|| Linearization::new(&m, &s, &ctrl, c, wrt, kappa_grad)?.vjp(&m, &adj))
            .py()?;
        Ok((
            PyArray1::from_vec(py, a.state),
            PyArray1::from_vec(py, a.ctrl),
            PyArray1::from_vec(py, a.params),
        ))
    })
}

/// Tangent of the next state for input tangents `(dstate, dctrl, dparams)`.
#[pyfunction]
#[pyo3(name = "_step_jvp")]
#[allow(clippy::too_many_arguments)]
pub fn step_jvp<'py>(
    py: Python<'py>,
    model: &PyModel,
    state: &PyState,
    ctrl: PyReadonlyArray1<'py, f64>,
    dstate: PyReadonlyArray1<'py, f64>,
    dctrl: PyReadonlyArray1<'py, f64>,
    dparams: Option<PyReadonlyArray1<'py, f64>>,
    kappa_grad: Option<f64>,
    coordinates: &str,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    guard(|| {
        same_model(model, state)?;
        let c = coords(coordinates)?;
        let ctrl = ctrl.as_slice()?.to_vec();
        let (dx, du) = (dstate.as_slice()?.to_vec(), dctrl.as_slice()?.to_vec());
        let dp = dparams
            .map(|a| a.as_slice().map(|s| s.to_vec()))
            .transpose()?;
        let m = model.inner.clone();
        let s = state.inner.clone();
        let wrt = Wrt {
            state: true,
            ctrl: true,
            params: dp.is_some(),
        };
        let out = py
            .detach(|| {
                Linearization::new(&m, &s, &ctrl, c, wrt, kappa_grad)?.jvp(
                    &m,
                    &dx,
                    &du,
                    dp.as_deref().unwrap_or(&[]),
                )
            })
            .py()?;
        Ok(PyArray1::from_vec(py, out))
    })
}

/// Reverse sweep over a rollout: `(adj_state0, adj_ctrls (T, nu), adj_params)`.
#[pyfunction]
#[pyo3(name = "_rollout_vjp")]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub fn rollout_vjp_py<'py>(
    py: Python<'py>,
    model: &PyModel,
    state: &PyState,
    ctrls: PyReadonlyArray2<'py, f64>,
    adjoint_states: PyReadonlyArray2<'py, f64>,
    kappa_grad: Option<f64>,
    coordinates: &str,
    wrt_params: bool,
) -> PyResult<(
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
)> {
    guard(|| {
        same_model(model, state)?;
        let c = coords(coordinates)?;
        let nstep = ctrls.shape()[0];
        let nu = model.inner.nu();
        let (ctrls, adj) = (
            ctrls.as_slice()?.to_vec(),
            adjoint_states.as_slice()?.to_vec(),
        );
        let m = model.inner.clone();
        let s = state.inner.clone();
        let r = py
            .detach(|| rollout_vjp(&m, &s, &ctrls, nstep, &adj, c, kappa_grad, wrt_params))
            .py()?;
        Ok((
            PyArray1::from_vec(py, r.state0),
            PyArray1::from_vec(py, r.ctrls).reshape([nstep, nu])?,
            PyArray1::from_vec(py, r.params),
        ))
    })
}

/// `(hits, misses, rollouts kept, bytes kept)` of the forward rollouts kept for their VJPs.
#[pyfunction]
#[pyo3(name = "_kept_rollouts")]
pub fn kept_rollouts() -> (usize, usize, usize, usize) {
    ukemi_engine::gradients::kept::stats()
}

/// `(hits, misses, hints held, bytes held)` of the warm starts flat steps hand on.
#[pyfunction]
#[pyo3(name = "_warm_hints")]
pub fn warm_hints() -> (usize, usize, usize, usize) {
    ukemi_engine::gradients::hints::stats()
}

/// Whether flat steps (`ukemi.jax.step`, `ukemi.torch.step`, flat rollouts) hand the solver's
/// warm start of the state they return to the flat step that takes it next; returns the
/// previous setting. Off, every flat step starts cold.
#[pyfunction]
pub fn set_flat_warm_start(enabled: bool) -> bool {
    ukemi_engine::gradients::hints::set_enabled(enabled)
}

/// `(T, r, c)` row-major from `T` matrices of shape `(r, c)`.
fn stacked<'py>(
    py: Python<'py>,
    ms: &[&nalgebra::DMatrix<f64>],
    (r, c): (usize, usize),
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let mut data = Vec::with_capacity(ms.len() * r * c);
    for m in ms {
        data.extend_from_slice(m.transpose().as_slice());
    }
    PyArray1::from_vec(py, data).reshape([ms.len(), r, c])
}

/// Jacobians of every step of a rollout: `(A (T, ny, ny), B (T, ny, nu), C (T, ny, np),
/// states x_0..=x_T)`; a block has no columns when its input was not selected.
#[pyfunction]
#[pyo3(name = "_rollout_jacobians")]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub fn rollout_jacobians_py<'py>(
    py: Python<'py>,
    model: &PyModel,
    state: &PyState,
    ctrls: PyReadonlyArray2<'py, f64>,
    kappa_grad: Option<f64>,
    coordinates: &str,
    wrt_state: bool,
    wrt_ctrl: bool,
    wrt_params: bool,
) -> PyResult<(
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray3<f64>>,
    Vec<PyState>,
)> {
    guard(|| {
        same_model(model, state)?;
        let c = coords(coordinates)?;
        let nstep = ctrls.shape()[0];
        let ctrls = ctrls.as_slice()?.to_vec();
        let m = model.inner.clone();
        let s = state.inner.clone();
        let wrt = Wrt {
            state: wrt_state,
            ctrl: wrt_ctrl,
            params: wrt_params,
        };
        let r = py
            .detach(|| rollout_jacobians(&m, &s, &ctrls, nstep, c, wrt, kappa_grad))
            .py()?;
        let ny = c.dim(&m);
        let cols = |f: fn(&ukemi_engine::Jacobians) -> &nalgebra::DMatrix<f64>, n: usize| {
            let ms: Vec<_> = r.steps.iter().map(f).collect();
            stacked(py, &ms, (ny, n))
        };
        let nx = if wrt_state { ny } else { 0 };
        let nu = if wrt_ctrl { m.nu() } else { 0 };
        let np = if wrt_params { m.params().len() } else { 0 };
        let states = r
            .states
            .into_iter()
            .map(|inner| PyState {
                model: model.inner.clone(),
                inner,
            })
            .collect();
        Ok((
            cols(|j| &j.a, nx)?,
            cols(|j| &j.b, nu)?,
            cols(|j| &j.c, np)?,
            states,
        ))
    })
}

/// One model, or one per batch element when `params` (B, nparams) is given.
pub(crate) fn models_for(
    model: &Model,
    params: Option<&[f64]>,
    batch: usize,
) -> ukemi_engine::Result<Vec<Model>> {
    match params {
        None => Ok(vec![model.clone()]),
        Some(p) => {
            let np = model.params().len();
            ukemi_engine::ensure!(
                p.len() == batch * np,
                ukemi_engine::Error::shape("params", &[batch, np], &[p.len() / np.max(1), np])
            );
            (0..batch)
                .map(|i| model.with_params(&p[i * np..(i + 1) * np]))
                .collect()
        }
    }
}

/// Run `f(model_i, i)` for every batch element `i` on the thread pool with the GIL released:
/// one model, or one per element when `params` (B, nparams) is given.
fn batched_off_gil<T: Send>(
    py: Python<'_>,
    model: &PyModel,
    params: Option<&[f64]>,
    batch: usize,
    f: impl Fn(&Model, usize) -> ukemi_engine::Result<T> + Sync,
) -> PyResult<Vec<T>> {
    let (m, f) = (model.inner.clone(), &f);
    py.detach(|| {
        let models = models_for(&m, params, batch)?;
        flat::batched(&models, batch, f)
    })
    .py()
}

/// Concatenate per-element triples of outputs into three flat buffers (batch-major).
fn concat3(parts: Vec<(Vec<f64>, Vec<f64>, Vec<f64>)>) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let (mut a, mut b, mut c) = (vec![], vec![], vec![]);
    for (x, y, z) in parts {
        a.extend(x);
        b.extend(y);
        c.extend(z);
    }
    (a, b, c)
}

/// Batched arguments must share the leading batch size (the Python layer broadcasts first).
fn same_batch(name: &str, want: usize, got: usize) -> PyResult<()> {
    if want != got {
        return Err(crate::errors::ShapeError::new_err(format!(
            "shape of `{name}`: batch size {got} differs from the states' {want}"
        )));
    }
    Ok(())
}

fn slice2<'a>(a: &'a Option<PyReadonlyArray2<'_, f64>>) -> PyResult<Option<&'a [f64]>> {
    a.as_ref()
        .map(|x| x.as_slice())
        .transpose()
        .map_err(Into::into)
}

/// Batched flat steps: `xs (B, nq+nv)`, `us (B, nu)`, optional `params (B, nparams)`.
#[pyfunction]
#[pyo3(name = "_flat_step", signature = (model, xs, us, params=None, keep=false))]
pub fn flat_step<'py>(
    py: Python<'py>,
    model: &PyModel,
    xs: PyReadonlyArray2<'py, f64>,
    us: PyReadonlyArray2<'py, f64>,
    params: Option<PyReadonlyArray2<'py, f64>>,
    keep: bool,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    guard(|| {
        let (b, n, nu) = (xs.shape()[0], xs.shape()[1], us.shape()[1]);
        same_batch("us", b, us.shape()[0])?;
        let (xs, us) = (xs.as_slice()?, us.as_slice()?);
        let p = slice2(&params)?;
        let out = batched_off_gil(py, model, p, b, |mm, i| {
            let (x, u) = (&xs[i * n..(i + 1) * n], &us[i * nu..(i + 1) * nu]);
            flat::step_kept(mm, x, u, keep)
        })?;
        PyArray1::from_vec(py, out.concat()).reshape([b, n])
    })
}

/// Batched flat step VJPs: `(adj_x (B, nx), adj_u (B, nu), adj_params (B, nparams))`.
#[pyfunction]
#[pyo3(name = "_flat_step_vjp", signature = (model, xs, us, adj, kappa_grad, params=None, wrt_params=false))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub fn flat_step_vjp<'py>(
    py: Python<'py>,
    model: &PyModel,
    xs: PyReadonlyArray2<'py, f64>,
    us: PyReadonlyArray2<'py, f64>,
    adj: PyReadonlyArray2<'py, f64>,
    kappa_grad: Option<f64>,
    params: Option<PyReadonlyArray2<'py, f64>>,
    wrt_params: bool,
) -> PyResult<(
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
)> {
    guard(|| {
        let (b, n, nu) = (xs.shape()[0], xs.shape()[1], us.shape()[1]);
        same_batch("us", b, us.shape()[0])?;
        same_batch("adj", b, adj.shape()[0])?;
        let (xs, us, adj) = (xs.as_slice()?, us.as_slice()?, adj.as_slice()?);
        let p = slice2(&params)?;
        let np = if wrt_params {
            model.inner.params().len()
        } else {
            0
        };
        let out = batched_off_gil(py, model, p, b, |mm, i| {
            flat::step_vjp(
                mm,
                &xs[i * n..(i + 1) * n],
                &us[i * nu..(i + 1) * nu],
                &adj[i * n..(i + 1) * n],
                kappa_grad,
                wrt_params,
            )
        })?;
        let (gx, gu, gp) = concat3(out);
        Ok((
            PyArray1::from_vec(py, gx).reshape([b, n])?,
            PyArray1::from_vec(py, gu).reshape([b, nu])?,
            PyArray1::from_vec(py, gp).reshape([b, np])?,
        ))
    })
}

/// Batched flat rollouts: `x0s (B, nx)`, `us (B, T, nu)` → `(B, T+1, nx)`.
#[pyfunction]
#[pyo3(name = "_flat_rollout", signature = (model, x0s, us, params=None, keep=false))]
pub fn flat_rollout<'py>(
    py: Python<'py>,
    model: &PyModel,
    x0s: PyReadonlyArray2<'py, f64>,
    us: PyReadonlyArray3<'py, f64>,
    params: Option<PyReadonlyArray2<'py, f64>>,
    keep: bool,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    guard(|| {
        let (b, n) = (x0s.shape()[0], x0s.shape()[1]);
        let (t, nu) = (us.shape()[1], us.shape()[2]);
        same_batch("us", b, us.shape()[0])?;
        let (x0s, us) = (x0s.as_slice()?, us.as_slice()?);
        let p = slice2(&params)?;
        let out = batched_off_gil(py, model, p, b, |mm, i| {
            flat::rollout_kept(
                mm,
                &x0s[i * n..(i + 1) * n],
                &us[i * t * nu..(i + 1) * t * nu],
                t,
                keep,
            )
        })?;
        PyArray1::from_vec(py, out.concat()).reshape([b, t + 1, n])
    })
}

/// Batched flat rollout VJPs: `(adj_x0 (B, nx), adj_us (B, T, nu), adj_params (B, nparams))`.
#[pyfunction]
#[pyo3(name = "_flat_rollout_vjp", signature = (model, x0s, us, adj, kappa_grad, params=None, wrt_params=false))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub fn flat_rollout_vjp<'py>(
    py: Python<'py>,
    model: &PyModel,
    x0s: PyReadonlyArray2<'py, f64>,
    us: PyReadonlyArray3<'py, f64>,
    adj: PyReadonlyArray3<'py, f64>,
    kappa_grad: Option<f64>,
    params: Option<PyReadonlyArray2<'py, f64>>,
    wrt_params: bool,
) -> PyResult<(
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray2<f64>>,
)> {
    guard(|| {
        let (b, n) = (x0s.shape()[0], x0s.shape()[1]);
        let (t, nu) = (us.shape()[1], us.shape()[2]);
        same_batch("us", b, us.shape()[0])?;
        same_batch("adj", b, adj.shape()[0])?;
        if adj.shape()[1] != t + 1 {
            return Err(crate::errors::ShapeError::new_err(format!(
                "shape of `adj`: {} states, expected T + 1 = {}",
                adj.shape()[1],
                t + 1
            )));
        }
        let (x0s, us, adj) = (x0s.as_slice()?, us.as_slice()?, adj.as_slice()?);
        let p = slice2(&params)?;
        let np = if wrt_params {
            model.inner.params().len()
        } else {
            0
        };
        let out = batched_off_gil(py, model, p, b, |mm, i| {
            flat::rollout_vjp(
                mm,
                &x0s[i * n..(i + 1) * n],
                &us[i * t * nu..(i + 1) * t * nu],
                t,
                &adj[i * (t + 1) * n..(i + 1) * (t + 1) * n],
                kappa_grad,
                wrt_params,
            )
        })?;
        let (gx, gu, gp) = concat3(out);
        Ok((
            PyArray1::from_vec(py, gx).reshape([b, n])?,
            PyArray1::from_vec(py, gu).reshape([b, t, nu])?,
            PyArray1::from_vec(py, gp).reshape([b, np])?,
        ))
    })
}

/// Threads used by batched calls (0 restores one per core).
#[pyfunction]
pub fn set_num_threads(n: usize) -> PyResult<()> {
    guard(|| flat::set_num_threads(n).py())
}

/// Threads used by batched calls.
#[pyfunction]
pub fn get_num_threads() -> usize {
    flat::num_threads()
}

/// Batched raw flat-state Jacobians: `(A (B, nx, nx), B (B, nx, nu), C (B, nx, nparams))`.
#[pyfunction]
#[pyo3(name = "_flat_step_jacobians", signature = (model, xs, us, kappa_grad, params=None, wrt_params=false))]
#[allow(clippy::type_complexity)]
pub fn flat_step_jacobians<'py>(
    py: Python<'py>,
    model: &PyModel,
    xs: PyReadonlyArray2<'py, f64>,
    us: PyReadonlyArray2<'py, f64>,
    kappa_grad: Option<f64>,
    params: Option<PyReadonlyArray2<'py, f64>>,
    wrt_params: bool,
) -> PyResult<(
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray3<f64>>,
)> {
    guard(|| {
        let (b, n, nu) = (xs.shape()[0], xs.shape()[1], us.shape()[1]);
        same_batch("us", b, us.shape()[0])?;
        let (xs, us) = (xs.as_slice()?, us.as_slice()?);
        let p = slice2(&params)?;
        let np = if wrt_params {
            model.inner.params().len()
        } else {
            0
        };
        let out = batched_off_gil(py, model, p, b, |mm, i| {
            flat::step_jacobians(
                mm,
                &xs[i * n..(i + 1) * n],
                &us[i * nu..(i + 1) * nu],
                kappa_grad,
                wrt_params,
            )
        })?;
        let (ga, gb, gc) = concat3(out);
        Ok((
            PyArray1::from_vec(py, ga).reshape([b, n, n])?,
            PyArray1::from_vec(py, gb).reshape([b, n, nu])?,
            PyArray1::from_vec(py, gc).reshape([b, n, np])?,
        ))
    })
}
