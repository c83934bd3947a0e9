//! `ukemi._ukemi`: the Python extension. Registration only; see the sibling modules.
mod envs;
mod errors;
mod gradients;
mod mjcf;
mod model;
mod state;
mod step;
mod xla_ffi;

use pyo3::prelude::*;

/// The compiled core of ukemi.
#[pymodule(gil_used = false)]
fn _ukemi(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<model::PyModelBuilder>()?;
    m.add_class::<model::PyModel>()?;
    m.add_class::<state::PyState>()?;
    m.add_class::<step::PyStepInfo>()?;
    m.add_class::<envs::PyEnvStates>()?;
    m.add_function(wrap_pyfunction!(step::step, m)?)?;
    m.add_function(wrap_pyfunction!(step::solver_trace, m)?)?;
    m.add_function(wrap_pyfunction!(step::step_smoothed, m)?)?;
    m.add_function(wrap_pyfunction!(step::rollout, m)?)?;
    m.add_function(wrap_pyfunction!(step::signed_distances, m)?)?;
    m.add_function(wrap_pyfunction!(gradients::step_jacobians, m)?)?;
    m.add_function(wrap_pyfunction!(gradients::step_vjp, m)?)?;
    m.add_function(wrap_pyfunction!(gradients::step_jvp, m)?)?;
    m.add_function(wrap_pyfunction!(gradients::rollout_vjp_py, m)?)?;
    m.add_function(wrap_pyfunction!(gradients::rollout_jacobians_py, m)?)?;
    m.add_function(wrap_pyfunction!(gradients::kept_rollouts, m)?)?;
    m.add_function(wrap_pyfunction!(gradients::warm_hints, m)?)?;
    m.add_function(wrap_pyfunction!(gradients::set_flat_warm_start, m)?)?;
    m.add_function(wrap_pyfunction!(gradients::flat_step, m)?)?;
    m.add_function(wrap_pyfunction!(gradients::flat_step_vjp, m)?)?;
    m.add_function(wrap_pyfunction!(gradients::flat_rollout, m)?)?;
    m.add_function(wrap_pyfunction!(gradients::flat_rollout_vjp, m)?)?;
    m.add_function(wrap_pyfunction!(gradients::flat_step_jacobians, m)?)?;
    m.add_function(wrap_pyfunction!(gradients::set_num_threads, m)?)?;
    m.add_function(wrap_pyfunction!(gradients::get_num_threads, m)?)?;
    m.add_function(wrap_pyfunction!(xla_ffi::capsules, m)?)?;
    m.add_function(wrap_pyfunction!(xla_ffi::model_handle, m)?)?;
    m.add_function(wrap_pyfunction!(xla_ffi::release_model_handle, m)?)?;
    let kinds: Vec<&str> = ukemi_engine::JointKind::ALL
        .iter()
        .map(|k| k.name())
        .collect();
    m.add("JOINT_KINDS", kinds)?;
    let statuses: Vec<&str> = ukemi_engine::SolveStatus::ALL
        .iter()
        .map(|s| s.name())
        .collect();
    m.add("STATUS_NAMES", statuses)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
