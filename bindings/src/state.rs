//! `State`: per-rollout data with numpy views computed on access.
use std::sync::Arc;

use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use ukemi_engine::{Model, State};

/// Simulation state of one model (positions, velocities, time, warm start).
#[pyclass(name = "State", module = "ukemi._ukemi")]
#[derive(Clone)]
pub struct PyState {
    pub model: Arc<Model>,
    pub inner: State,
}

fn array2<'py>(py: Python<'py>, v: Vec<f64>, cols: usize) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let rows = v.len() / cols;
    PyArray1::from_vec(py, v).reshape([rows, cols])
}

#[pymethods]
impl PyState {
    /// Simulation time (s).
    #[getter]
    fn time(&self) -> f64 {
        self.inner.time
    }
    /// Generalized positions, (nq,).
    #[getter]
    fn qpos<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, ukemi_engine::qpos(&self.model, &self.inner))
    }
    /// Generalized velocities, (nv,).
    #[getter]
    fn qvel<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, ukemi_engine::qvel(&self.model, &self.inner))
    }
    /// Body frame origins, world (m), (nbody, 3).
    #[getter]
    fn body_pos<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        array2(py, self.inner.body_pos(&self.model), 3)
    }
    /// Orientations (w, x, y, z), (nbody, 4).
    #[getter]
    fn body_quat<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        array2(py, self.inner.quat.clone(), 4)
    }
    /// Linear velocities of the body frame origins, world (m/s), (nbody, 3).
    #[getter]
    fn body_linvel<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        array2(py, self.inner.body_linvel(&self.model), 3)
    }
    /// Angular velocities, world frame (rad/s), (nbody, 3).
    #[getter]
    fn body_angvel<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        array2(py, self.inner.body_angvel(&self.model), 3)
    }
    /// Centre-of-mass positions, world (m), (nbody, 3).
    #[getter]
    fn com_pos<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        array2(py, self.inner.com_pos.clone(), 3)
    }
    /// Joint constraint impulses of the last step (N·s), (ncon,).
    #[getter]
    fn joint_impulse<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.joint_impulse)
    }
    /// Contact impulses of the last step per candidate, contact frame (normal, t1, t2) (N·s),
    /// (ncontact, 3). Divide by the time step for forces.
    #[getter]
    fn contact_impulse<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        array2(py, self.inner.contact_impulse(&self.model), 3)
    }
    /// Length `Σ coef qpos` of each tendon limit's tendon (m or rad), (n tendon limits,).
    #[getter]
    fn tendon_length<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.inner.tendon_length(&self.model))
    }
    /// Impulse `γ_lo - γ_hi` of each tendon limit in the last step (N·s or N·m·s per unit
    /// coef; positive pushes the length up), (n tendon limits,). Divide by the time step for
    /// forces.
    #[getter]
    fn tendon_impulse<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.inner.tendon_impulse(&self.model))
    }
    /// Dry-friction impulse of each joint dof with `frictionloss` in the last step (joints in
    /// model order, their dofs in order; N·s or N·m·s), positive resisting a positive rate:
    /// `±frictionloss · dt` while the dof slides, less while it sticks, (n friction dofs,).
    #[getter]
    fn joint_friction_impulse<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.inner.joint_friction_impulse(&self.model))
    }
    /// Dry-friction impulse of each passive tendon with `frictionloss` in the last step (per
    /// unit length; positive resists a lengthening tendon), (n tendons with friction,).
    #[getter]
    fn tendon_friction_impulse<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.inner.tendon_friction_impulse(&self.model))
    }
    /// Discrete linear momentum (kg·m/s), (3,).
    fn linear_momentum<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(
            py,
            ukemi_engine::mechanics::linear_momentum(&self.model, &self.inner).as_slice(),
        )
    }
    /// Discrete angular momentum about the origin (kg·m²/s), (3,).
    fn angular_momentum<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(
            py,
            ukemi_engine::mechanics::angular_momentum(&self.model, &self.inner).as_slice(),
        )
    }
    /// Discrete total energy: kinetic (bodies and joint armature) + gravity + joint springs (J).
    fn energy(&self) -> f64 {
        ukemi_engine::mechanics::total_energy(&self.model, &self.inner)
    }
    /// Every number of the state, warm start included, as one float64 array that
    /// `model.state_from_snapshot` turns back into this state bit for bit: a checkpoint from
    /// which a step repeats exactly what it would have done (`qpos`, `qvel` alone lose the
    /// solver's warm start).
    fn snapshot<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.inner.snapshot())
    }
    /// An independent copy.
    fn copy(&self) -> PyState {
        self.clone()
    }
    fn __copy__(&self) -> PyState {
        self.clone()
    }
    fn __deepcopy__(&self, _memo: &Bound<'_, PyAny>) -> PyState {
        self.clone()
    }
    fn __repr__(&self) -> String {
        format!(
            "ukemi.State(time={}, nbody={})",
            self.inner.time,
            self.model.nbody()
        )
    }
}
