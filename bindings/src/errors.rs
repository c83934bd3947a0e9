//! Engine errors → Python exception classes (defined in `python/ukemi/errors.py`), and the
//! panic guard every entry point runs through.
use std::panic::{AssertUnwindSafe, catch_unwind};

use pyo3::prelude::*;
use ukemi_engine::Error;

pyo3::import_exception!(ukemi.errors, ModelError);
pyo3::import_exception!(ukemi.errors, ShapeError);
pyo3::import_exception!(ukemi.errors, InputError);
pyo3::import_exception!(ukemi.errors, ModelMismatchError);
pyo3::import_exception!(ukemi.errors, UnsupportedError);
pyo3::import_exception!(ukemi.errors, InternalError);
pyo3::import_exception!(ukemi.errors, MjcfError);
pyo3::import_exception!(ukemi.errors, UrdfError);
pyo3::import_exception!(ukemi.errors, ConvergenceError);

/// One exhaustive mapping: adding an engine variant does not compile until it is mapped here.
pub fn to_py(e: Error) -> PyErr {
    let msg = e.to_string();
    match e {
        Error::InvalidModel { .. } => ModelError::new_err(msg),
        Error::Shape { .. } => ShapeError::new_err(msg),
        Error::InvalidInput { .. } => InputError::new_err(msg),
        Error::ModelMismatch { .. } => ModelMismatchError::new_err(msg),
        Error::Unsupported(_) => UnsupportedError::new_err(msg),
        Error::Mjcf { .. } => MjcfError::new_err(msg),
        Error::Urdf { .. } => UrdfError::new_err(msg),
        Error::NotConverged { .. } => ConvergenceError::new_err(msg),
    }
}

/// Run `f`, turning a Rust panic into `ukemi.InternalError` (never pyo3's `PanicException`,
/// which is a `BaseException` and escapes `except Exception`).
pub fn guard<T>(f: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(payload) => {
            let what = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            Err(InternalError::new_err(format!(
                "internal error in the ukemi engine (please report): {what}"
            )))
        }
    }
}

/// `Result` → `PyResult` through [`to_py`].
pub trait IntoPy<T> {
    /// Map the engine error.
    fn py(self) -> PyResult<T>;
}

impl<T> IntoPy<T> for ukemi_engine::Result<T> {
    fn py(self) -> PyResult<T> {
        self.map_err(to_py)
    }
}
