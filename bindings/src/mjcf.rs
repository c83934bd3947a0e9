//! MJCF loading: `Model.from_xml_path` / `Model.from_xml_string`. Warnings about ignored
//! features are issued as Python `UserWarning`s.
use std::path::Path;
use std::sync::Arc;

use pyo3::prelude::*;
use ukemi_engine::mjcf::{self, MjcfModel};

use crate::errors::{IntoPy, guard};
use crate::model::PyModel;

fn finish(py: Python<'_>, loaded: ukemi_engine::Result<MjcfModel>) -> PyResult<PyModel> {
    let loaded = loaded.py()?;
    let category = py.get_type::<pyo3::exceptions::PyUserWarning>();
    for w in &loaded.warnings {
        let msg = std::ffi::CString::new(w.replace('\0', " "))
            .unwrap_or_else(|_| c"ukemi MJCF warning".to_owned());
        PyErr::warn(py, &category, &msg, 2)?;
    }
    Ok(PyModel {
        inner: Arc::new(loaded.model),
    })
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
