//! `ukemi._ukemi`: the Python extension. Registration only; see the sibling modules.
mod errors;
mod mjcf;
mod model;
mod state;
mod step;

use pyo3::prelude::*;

/// The compiled core of ukemi.
#[pymodule(gil_used = false)]
fn _ukemi(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<model::PyModelBuilder>()?;
    m.add_class::<model::PyModel>()?;
    m.add_class::<state::PyState>()?;
    m.add_class::<step::PyStepInfo>()?;
    m.add_function(wrap_pyfunction!(step::step, m)?)?;
    m.add_function(wrap_pyfunction!(step::rollout, m)?)?;
    m.add_function(wrap_pyfunction!(step::signed_distances, m)?)?;
    let kinds: Vec<&str> = ukemi_engine::JointKind::ALL
        .iter()
        .map(|k| k.name())
        .collect();
    m.add("JOINT_KINDS", kinds)?;
    m.add(
        "STATUS_NAMES",
        [
            "converged",
            "max_iterations",
            "line_search_failed",
            "non_finite",
        ],
    )?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
