//! `step` and `rollout`: validate under the GIL, compute with it released, return numpy arrays.
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use ukemi_engine::{AppliedForces, StepReport, Workspace};

use crate::errors::{IntoPy, ModelMismatchError, guard};
use crate::model::PyModel;
use crate::state::PyState;

/// What one step reports.
#[pyclass(name = "StepInfo", module = "ukemi._ukemi", frozen, get_all)]
#[derive(Clone)]
pub struct PyStepInfo {
    /// "converged" | "acceptable" | "max_iterations" | "line_search_failed" | "non_finite" |
    /// "pyramid_friction".
    pub status: &'static str,
    /// Newton iterations.
    pub iterations: usize,
    /// Final residual ∞-norm.
    pub residual: f64,
    /// Final complementarity violation.
    pub complementarity: f64,
    /// Equal sub-steps the step took: 1, or n > 1 when the whole step's solve failed and n
    /// sub-steps of timestep / n succeeded (option `max_subdivisions`).
    pub subdivisions: u32,
}

#[pymethods]
impl PyStepInfo {
    /// Whether the state is valid: the solve converged, reached the acceptable tolerances
    /// (status "acceptable"), or converged with pyramid friction cones after the exact cones
    /// failed (status "pyramid_friction", option `pyramid_fallback`).
    #[getter]
    fn converged(&self) -> bool {
        matches!(self.status, "converged" | "acceptable" | "pyramid_friction")
    }
    fn __repr__(&self) -> String {
        format!(
            "StepInfo(status={:?}, iterations={}, residual={:.3e}, subdivisions={})",
            self.status, self.iterations, self.residual, self.subdivisions
        )
    }
}

impl From<StepReport> for PyStepInfo {
    fn from(r: StepReport) -> Self {
        PyStepInfo {
            status: r.status.name(),
            iterations: r.iterations,
            residual: r.residual,
            complementarity: r.complementarity,
            subdivisions: r.subdivisions,
        }
    }
}

/// A Python state of `model` wrapping `inner`.
fn next_state(model: &PyModel, inner: ukemi_engine::State) -> PyState {
    PyState {
        model: model.inner.clone(),
        inner,
    }
}

fn same_model(model: &PyModel, state: &PyState) -> PyResult<()> {
    if state.model.topology_id() != model.inner.topology_id() {
        return Err(ModelMismatchError::new_err(
            "state was built for a different model (make it with model.make_state())",
        ));
    }
    Ok(())
}

/// One step; returns a new state (the input state is not modified).
#[pyfunction]
#[pyo3(name = "_step", signature = (model, state, ctrl, qfrc_applied=None, xfrc_applied=None))]
pub fn step(
    py: Python<'_>,
    model: &PyModel,
    state: &PyState,
    ctrl: PyReadonlyArray1<'_, f64>,
    qfrc_applied: Option<PyReadonlyArray1<'_, f64>>,
    xfrc_applied: Option<PyReadonlyArray2<'_, f64>>,
) -> PyResult<(PyState, PyStepInfo)> {
    guard(|| {
        same_model(model, state)?;
        let ctrl = ctrl.as_slice()?.to_vec();
        let qfrc = qfrc_applied
            .map(|a| a.as_slice().map(|s| s.to_vec()))
            .transpose()?;
        let xfrc = xfrc_applied
            .map(|a| a.as_slice().map(|s| s.to_vec()))
            .transpose()?;
        let m = model.inner.clone();
        let mut next = state.inner.clone();
        let report = py.detach(|| {
            let mut ws = model.take_workspace();
            let forces = AppliedForces {
                qfrc: qfrc.as_deref(),
                xfrc: xfrc.as_deref(),
            };
            let report = ukemi_engine::step_with(&m, &mut next, &mut ws, &ctrl, &forces);
            model.give_workspace(ws);
            report
        });
        let report = report.py()?;
        Ok((next_state(model, next), report.into()))
    })
}

/// Signed distance of every contact candidate (m, negative = penetration), (ncontact,).
#[pyfunction]
pub fn signed_distances<'py>(
    py: Python<'py>,
    model: &PyModel,
    state: &PyState,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    guard(|| {
        same_model(model, state)?;
        Ok(PyArray1::from_vec(
            py,
            ukemi_engine::contact::signed_distances(&model.inner, &state.inner),
        ))
    })
}

/// Roll out `ctrls` (nstep, nu) in Rust with the GIL released. Returns a dict of arrays and the
/// final state; stops after the first failed step when `stop_on_failure`.
#[pyfunction]
#[pyo3(name = "_rollout")]
pub fn rollout<'py>(
    py: Python<'py>,
    model: &PyModel,
    state: &PyState,
    ctrls: PyReadonlyArray2<'py, f64>,
    stop_on_failure: bool,
) -> PyResult<(Bound<'py, PyDict>, PyState)> {
    guard(|| {
        same_model(model, state)?;
        let m = model.inner.clone();
        let nstep = ctrls.shape()[0];
        let ctrls = ctrls.as_slice()?.to_vec();
        let (nq, nv, nb) = (m.nq, m.nv, m.nbody());
        let mut s = state.inner.clone();
        let mut out = Recorder::new(nstep, nq, nv, nb);
        out.record_state(&m, &s);
        let result = py.detach(|| {
            let mut ws = model.take_workspace();
            let result = ukemi_engine::rollout(
                &m,
                &mut s,
                &mut ws,
                &ctrls,
                nstep,
                stop_on_failure,
                |_, st, r| {
                    out.record_state(&m, st);
                    out.record_report(r);
                },
            );
            model.give_workspace(ws);
            result
        });
        result.py()?;
        let d = out.into_dict(py, nq, nv, nb)?;
        Ok((d, next_state(model, s)))
    })
}

/// Flat buffers filled during a rollout.
struct Recorder {
    qpos: Vec<f64>,
    qvel: Vec<f64>,
    time: Vec<f64>,
    body_pos: Vec<f64>,
    body_quat: Vec<f64>,
    min_distance: Vec<f64>,
    energy: Vec<f64>,
    status: Vec<u8>,
    iterations: Vec<i64>,
    residual: Vec<f64>,
    subdivisions: Vec<i64>,
}

impl Recorder {
    fn new(nstep: usize, nq: usize, nv: usize, nb: usize) -> Self {
        let n = nstep + 1;
        Recorder {
            qpos: Vec::with_capacity(n * nq),
            qvel: Vec::with_capacity(n * nv),
            time: Vec::with_capacity(n),
            body_pos: Vec::with_capacity(n * nb * 3),
            body_quat: Vec::with_capacity(n * nb * 4),
            min_distance: Vec::with_capacity(n),
            energy: Vec::with_capacity(n),
            status: Vec::with_capacity(nstep),
            iterations: Vec::with_capacity(nstep),
            residual: Vec::with_capacity(nstep),
            subdivisions: Vec::with_capacity(nstep),
        }
    }
    fn record_state(&mut self, m: &ukemi_engine::Model, s: &ukemi_engine::State) {
        let (a, b) = (self.qpos.len(), self.qvel.len());
        self.qpos.resize(a + m.nq, 0.0);
        self.qvel.resize(b + m.nv, 0.0);
        ukemi_engine::joints::coordinates::qpos_into(m, s, &mut self.qpos[a..]);
        ukemi_engine::joints::coordinates::qvel_into(m, s, &mut self.qvel[b..]);
        self.time.push(s.time);
        self.body_pos.extend(s.body_pos(m));
        self.body_quat.extend_from_slice(&s.quat);
        let d = ukemi_engine::contact::signed_distances(m, s);
        self.min_distance
            .push(d.iter().copied().fold(f64::INFINITY, f64::min));
        // of the simulated state itself: rebuilding a state from qpos/qvel drops the velocity
        // components the joints' motion subspaces do not span (O(h), see Trajectory.energy)
        self.energy
            .push(ukemi_engine::mechanics::total_energy(m, s));
    }
    fn record_report(&mut self, r: &StepReport) {
        self.status.push(r.status.code());
        self.iterations.push(r.iterations as i64);
        self.residual.push(r.residual);
        self.subdivisions.push(r.subdivisions as i64);
    }
    fn into_dict<'py>(
        self,
        py: Python<'py>,
        nq: usize,
        nv: usize,
        nb: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let n = self.time.len();
        let d = PyDict::new(py);
        d.set_item("qpos", PyArray1::from_vec(py, self.qpos).reshape([n, nq])?)?;
        d.set_item("qvel", PyArray1::from_vec(py, self.qvel).reshape([n, nv])?)?;
        d.set_item("time", PyArray1::from_vec(py, self.time))?;
        d.set_item(
            "body_pos",
            PyArray1::from_vec(py, self.body_pos).reshape([n, nb, 3])?,
        )?;
        d.set_item(
            "body_quat",
            PyArray1::from_vec(py, self.body_quat).reshape([n, nb, 4])?,
        )?;
        d.set_item("min_distance", PyArray1::from_vec(py, self.min_distance))?;
        d.set_item("energy", PyArray1::from_vec(py, self.energy))?;
        d.set_item("status", PyArray1::from_vec(py, self.status))?;
        d.set_item("iterations", PyArray1::from_vec(py, self.iterations))?;
        d.set_item("residual", PyArray1::from_vec(py, self.residual))?;
        d.set_item("subdivisions", PyArray1::from_vec(py, self.subdivisions))?;
        Ok(d)
    }
}

/// One step with every interior-point iteration recorded: `(next_state, info, trace)`, trace a
/// dict of per-iteration arrays (see `ukemi_engine::IterationRecord`).
#[pyfunction]
#[pyo3(name = "_solver_trace")]
pub fn solver_trace<'py>(
    py: Python<'py>,
    model: &PyModel,
    state: &PyState,
    ctrl: PyReadonlyArray1<'_, f64>,
    condition: bool,
) -> PyResult<(PyState, PyStepInfo, Bound<'py, PyDict>)> {
    guard(|| {
        same_model(model, state)?;
        let ctrl = ctrl.as_slice()?.to_vec();
        let m = model.inner.clone();
        let mut next = state.inner.clone();
        let (report, records) = py.detach(|| {
            let mut ws = Workspace::new(&m);
            ws.set_trace(true, condition);
            let report = ukemi_engine::step(&m, &mut next, &mut ws, &ctrl);
            (report, ws.trace().to_vec())
        });
        let report = report.py()?;
        let out = PyDict::new(py);
        let column = |f: fn(&ukemi_engine::IterationRecord) -> f64| -> Vec<f64> {
            records.iter().map(f).collect()
        };
        out.set_item(
            "attempt",
            PyArray1::from_vec(py, records.iter().map(|r| r.attempt as i64).collect()),
        )?;
        out.set_item("residual", PyArray1::from_vec(py, column(|r| r.residual)))?;
        out.set_item(
            "complementarity",
            PyArray1::from_vec(py, column(|r| r.complementarity)),
        )?;
        out.set_item("mu", PyArray1::from_vec(py, column(|r| r.mu)))?;
        out.set_item("kappa", PyArray1::from_vec(py, column(|r| r.kappa)))?;
        out.set_item("alpha_aff", PyArray1::from_vec(py, column(|r| r.alpha_aff)))?;
        out.set_item("alpha", PyArray1::from_vec(py, column(|r| r.alpha)))?;
        out.set_item(
            "corrector",
            PyArray1::from_vec(py, records.iter().map(|r| r.corrector).collect()),
        )?;
        out.set_item("condition", PyArray1::from_vec(py, column(|r| r.condition)))?;
        Ok((next_state(model, next), report.into(), out))
    })
}

/// The smoothed step: the hard step moved to the central path at `kappa` (the map whose
/// derivatives `kappa_grad = kappa` gives). Returns `(next_state, info)`; `info` reports the
/// central-path solve.
#[pyfunction]
#[pyo3(name = "_step_smoothed")]
pub fn step_smoothed(
    py: Python<'_>,
    model: &PyModel,
    state: &PyState,
    ctrl: PyReadonlyArray1<'_, f64>,
    kappa: f64,
) -> PyResult<(PyState, PyStepInfo)> {
    guard(|| {
        same_model(model, state)?;
        let ctrl = ctrl.as_slice()?.to_vec();
        let m = model.inner.clone();
        let mut next = state.inner.clone();
        let report = py.detach(|| ukemi_engine::step_smoothed(&m, &mut next, &ctrl, kappa));
        let report = report.py()?;
        Ok((next_state(model, next), report.into()))
    })
}
