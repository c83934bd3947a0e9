//! MJCF and URDF loading: `Model.from_xml_path` / `Model.from_xml_string` /
//! `Model.from_urdf_path` / `Model.from_urdf_string`. Warnings about ignored features are issued
//! as Python `UserWarning`s.
use std::path::Path;

use pyo3::prelude::*;
use ukemi_engine::mjcf::{self, MjcfModel};
use ukemi_engine::urdf::{self, UrdfModel};

use crate::errors::{IntoPy, guard};
use crate::model::PyModel;

fn finish(py: Python<'_>, loaded: ukemi_engine::Result<MjcfModel>) -> PyResult<PyModel> {
    let loaded = loaded.py()?;
    warn_all(py, &loaded.warnings)?;
    Ok(PyModel::new(loaded.model))
}

fn warn_all(py: Python<'_>, warnings: &[String]) -> PyResult<()> {
    let category = py.get_type::<pyo3::exceptions::PyUserWarning>();
    for w in warnings {
        let msg = std::ffi::CString::new(w.replace('\0', " "))
            .unwrap_or_else(|_| c"ukemi MJCF warning".to_owned());
        PyErr::warn(py, &category, &msg, 2)?;
    }
    Ok(())
}

/// Load an MJCF file.
pub fn from_path(py: Python<'_>, path: &str) -> PyResult<PyModel> {
    guard(|| {
        let loaded = py.detach(|| mjcf::load_path(Path::new(path)));
        finish(py, loaded)
    })
}

/// Load MJCF text.
pub fn from_string(py: Python<'_>, xml: &str) -> PyResult<PyModel> {
    guard(|| {
        let loaded = py.detach(|| mjcf::load_str(xml, "<string>"));
        finish(py, loaded)
    })
}

fn finish_urdf(py: Python<'_>, loaded: ukemi_engine::Result<UrdfModel>) -> PyResult<PyModel> {
    let loaded = loaded.py()?;
    warn_all(py, &loaded.warnings)?;
    Ok(PyModel::new(loaded.model))
}

/// Load a URDF file with a floating or fixed base.
pub fn from_urdf_path(py: Python<'_>, path: &str, floating: bool) -> PyResult<PyModel> {
    guard(|| {
        let loaded = py.detach(|| urdf::load_path(Path::new(path), floating));
        finish_urdf(py, loaded)
    })
}

/// Load URDF text with a floating or fixed base.
pub fn from_urdf_string(py: Python<'_>, xml: &str, floating: bool) -> PyResult<PyModel> {
    guard(|| {
        let loaded = py.detach(|| urdf::load_str(xml, "<string>", floating));
        finish_urdf(py, loaded)
    })
}

/// The MJCF document a URDF translates to (for inspection).
pub fn urdf_to_mjcf(py: Python<'_>, xml: &str, floating: bool) -> PyResult<String> {
    guard(|| {
        let loaded = py
            .detach(|| urdf::load_str(xml, "<string>", floating))
            .py()?;
        Ok(loaded.mjcf)
    })
}
