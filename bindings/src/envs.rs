//! `EnvStates`: the full engine states of N environments, owned by Python and stepped in place
//! by one call (parallel in Rust, GIL released). The gymnasium envs keep one of these (a single
//! env: N = 1; the vector env: one row per sub-env).
use std::sync::Arc;

use numpy::{
    PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use ukemi_engine::batch::{EnvStep, env_step_rows};
use ukemi_engine::joints::coordinates::{qpos_into, qvel_into};
use ukemi_engine::{Model, State, Workspace};

use crate::errors::{InputError, IntoPy, ShapeError, guard};
use crate::model::PyModel;
use crate::state::PyState;

/// Full states (positions, midpoint velocities, solver warm start) of `len` environments of
/// one model, with one solver workspace each.
#[pyclass(name = "EnvStates", module = "ukemi._ukemi")]
pub struct PyEnvStates {
    model: Arc<Model>,
    states: Vec<State>,
    workspaces: Vec<Workspace>,
}

impl PyEnvStates {
    fn row(&self, row: usize) -> PyResult<usize> {
        if row >= self.states.len() {
            return Err(InputError::new_err(format!(
                "invalid input: `row` = {row}: must be < {} (the number of states)",
                self.states.len()
            )));
        }
        Ok(row)
    }

    fn flat(&self, row: usize, out: &mut [f64]) {
        let (q, v) = out.split_at_mut(self.model.nq);
        qpos_into(&self.model, &self.states[row], q);
        qvel_into(&self.model, &self.states[row], v);
    }
}

#[pymethods]
impl PyEnvStates {
    /// `num` states at the model's reference pose.
    #[new]
    fn new(model: &PyModel, num: usize) -> PyResult<Self> {
        guard(|| {
            let m = model.inner.clone();
            Ok(PyEnvStates {
                states: vec![State::reference(&m); num],
                workspaces: (0..num).map(|_| Workspace::new(&m)).collect(),
                model: m,
            })
        })
    }

    fn __len__(&self) -> usize {
        self.states.len()
    }

    /// Replace row `row` by a fresh state at `(qpos, qvel)` (as `model.make_state(qpos, qvel)`:
    /// reference warm start, time 0) and a fresh workspace.
    fn reset(
        &mut self,
        row: usize,
        qpos: PyReadonlyArray1<'_, f64>,
        qvel: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<()> {
        guard(|| {
            let row = self.row(row)?;
            let m = &self.model;
            let mut s = State::reference(m);
            ukemi_engine::set_minimal(m, &mut s, qpos.as_slice()?, qvel.as_slice()?).py()?;
            self.states[row] = s;
            self.workspaces[row] = Workspace::new(m);
            Ok(())
        })
    }

    /// A copy of row `row` as a `ukemi.State`.
    fn state(&self, row: usize) -> PyResult<PyState> {
        guard(|| {
            let row = self.row(row)?;
            Ok(PyState {
                model: self.model.clone(),
                inner: self.states[row].clone(),
            })
        })
    }

    /// Copy `state` (a `ukemi.State` of the same model) into row `row`.
    fn set_state(&mut self, row: usize, state: &PyState) -> PyResult<()> {
        guard(|| {
            let row = self.row(row)?;
            state.inner.check_model(&self.model).py()?;
            self.states[row] = state.inner.clone();
            Ok(())
        })
    }

    /// `[qpos, qvel]` of row `row`, (nq + nv,).
    fn qpos_qvel<'py>(&self, py: Python<'py>, row: usize) -> PyResult<Bound<'py, PyArray1<f64>>> {
        guard(|| {
            let row = self.row(row)?;
            let mut out = vec![0.0; self.model.nq + self.model.nv];
            self.flat(row, &mut out);
            Ok(PyArray1::from_vec(py, out))
        })
    }

    /// One environment step of the rows `rows` (R,): `nstep` engine steps each under its row of
    /// `ctrls` (R, nu), in parallel with the GIL released. Returns `(x (R, nq + nv), status
    /// codes (R,), contact forces (R, ncontact, 3), body contact wrenches (R, nbody, 6))`, the
    /// forces those of the last engine step. A row whose solve failed is left at its input
    /// state with zero forces and a failure code. Bad input changes no state.
    #[allow(clippy::type_complexity)]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        rows: PyReadonlyArray1<'py, i64>,
        ctrls: PyReadonlyArray2<'py, f64>,
        nstep: usize,
    ) -> PyResult<(
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray1<u8>>,
        Bound<'py, PyArray3<f64>>,
        Bound<'py, PyArray3<f64>>,
    )> {
        guard(|| {
            let m = self.model.clone();
            let (nx, nc, nb) = (m.nq + m.nv, m.ncontact(), m.nbody());
            let rows = rows
                .as_slice()?
                .iter()
                .enumerate()
                .map(|(k, &r)| {
                    usize::try_from(r).map_err(|_| {
                        InputError::new_err(format!(
                            "invalid input: `rows[{k}]` = {r}: must be >= 0"
                        ))
                    })
                })
                .collect::<PyResult<Vec<usize>>>()?;
            if ctrls.shape() != [rows.len(), m.nu()] {
                return Err(ShapeError::new_err(format!(
                    "shape of `ctrls`: expected [{}, {}], got {:?}",
                    rows.len(),
                    m.nu(),
                    ctrls.shape()
                )));
            }
            let ctrls = ctrls.as_slice()?;
            let (states, workspaces) = (&mut self.states, &mut self.workspaces);
            let out: Vec<EnvStep> = py
                .detach(|| env_step_rows(&m, states, workspaces, &rows, ctrls, nstep))
                .py()?;
            let mut x = vec![0.0; rows.len() * nx];
            for (k, &r) in rows.iter().enumerate() {
                let (q, v) = x[k * nx..(k + 1) * nx].split_at_mut(m.nq);
                qpos_into(&m, &self.states[r], q);
                qvel_into(&m, &self.states[r], v);
            }
            let status: Vec<u8> = out.iter().map(|o| o.status.code()).collect();
            let force: Vec<f64> = out
                .iter()
                .flat_map(|o| o.forces.force_c.iter().copied())
                .collect();
            let wrench: Vec<f64> = out
                .iter()
                .flat_map(|o| o.forces.body_wrench.iter().copied())
                .collect();
            let n = rows.len();
            Ok((
                PyArray1::from_vec(py, x).reshape([n, nx])?,
                PyArray1::from_vec(py, status),
                PyArray1::from_vec(py, force).reshape([n, nc, 3])?,
                PyArray1::from_vec(py, wrench).reshape([n, nb, 6])?,
            ))
        })
    }

    /// An independent copy (states cloned, fresh workspaces).
    fn __copy__(&self) -> PyEnvStates {
        PyEnvStates {
            model: self.model.clone(),
            states: self.states.clone(),
            workspaces: (0..self.states.len())
                .map(|_| Workspace::new(&self.model))
                .collect(),
        }
    }

    fn __deepcopy__(&self, _memo: &Bound<'_, PyAny>) -> PyEnvStates {
        self.__copy__()
    }

    fn __repr__(&self) -> String {
        format!(
            "ukemi.EnvStates(len={}, nbody={})",
            self.states.len(),
            self.model.nbody()
        )
    }
}
