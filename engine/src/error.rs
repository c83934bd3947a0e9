//! The engine's one error type. Every message names the field and the bad value.

/// Errors raised by the engine. Solver non-convergence is *not* an error: it is reported in
/// [`crate::StepReport::status`]. Deliberately not `#[non_exhaustive]`: the bindings map every
/// variant to a Python class in one exhaustive `match`, so a new variant fails to compile there.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A model field has an invalid value (found when compiling).
    #[error("invalid model: `{field}` = {value}: {reason}")]
    InvalidModel {
        /// Dotted path of the field, e.g. `body[link].mass`.
        field: String,
        /// The offending value, formatted.
        value: String,
        /// Why it is invalid.
        reason: String,
    },
    /// An array has the wrong shape.
    #[error("shape of `{name}`: expected {expected:?}, got {got:?}")]
    Shape {
        /// Argument name.
        name: String,
        /// Expected shape.
        expected: Vec<usize>,
        /// Shape received.
        got: Vec<usize>,
    },
    /// An input value is invalid (non-finite, out of range, unknown name...).
    #[error("invalid input: `{field}` = {value}: {reason}")]
    InvalidInput {
        /// Argument or field name.
        field: String,
        /// The offending value, formatted.
        value: String,
        /// Why it is invalid.
        reason: String,
    },
    /// A state was built for a different model.
    #[error("state was built for a different model ({detail})")]
    ModelMismatch {
        /// What differs.
        detail: String,
    },
    /// A feature is not supported.
    #[error("unsupported: {0}")]
    Unsupported(String),
    /// An MJCF document is malformed or has an invalid value.
    #[error("MJCF {source_name}:{line}: {msg}")]
    Mjcf {
        /// File path or `<string>`.
        source_name: String,
        /// 1-based line of the offending element (0 when unknown).
        line: usize,
        /// What is wrong: element, attribute and bad value.
        msg: String,
    },
    /// A URDF document is malformed or has an invalid value.
    #[error("URDF {source_name}:{line}: {msg}")]
    Urdf {
        /// File path or `<string>`.
        source_name: String,
        /// 1-based line of the offending element (0 when unknown).
        line: usize,
        /// What is wrong: element, attribute and bad value.
        msg: String,
    },
    /// A solve that a result depends on (a gradient's step or its central-path point) did not
    /// converge, so no valid result exists.
    #[error(
        "{context} did not converge: {status} after {iterations} iterations \
         (residual {residual:e}, complementarity {complementarity:e})"
    )]
    NotConverged {
        /// What was being solved.
        context: String,
        /// Solver status name.
        status: String,
        /// Iterations used.
        iterations: usize,
        /// Final residual ∞-norm.
        residual: f64,
        /// Final complementarity violation.
        complementarity: f64,
    },
}

/// Result alias of the engine.
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    /// Shorthand for [`Error::InvalidModel`].
    pub fn model(
        field: impl Into<String>,
        value: impl std::fmt::Debug,
        reason: impl Into<String>,
    ) -> Self {
        Error::InvalidModel {
            field: field.into(),
            value: format!("{value:?}"),
            reason: reason.into(),
        }
    }
    /// Shorthand for [`Error::InvalidInput`].
    pub fn input(
        field: impl Into<String>,
        value: impl std::fmt::Debug,
        reason: impl Into<String>,
    ) -> Self {
        Error::InvalidInput {
            field: field.into(),
            value: format!("{value:?}"),
            reason: reason.into(),
        }
    }
    /// [`Error::NotConverged`] with `where_` appended to its context (e.g. `" (step 7)"`);
    /// other errors unchanged.
    pub fn at(self, where_: impl std::fmt::Display) -> Self {
        match self {
            Error::NotConverged {
                context,
                status,
                iterations,
                residual,
                complementarity,
            } => Error::NotConverged {
                context: format!("{context}{where_}"),
                status,
                iterations,
                residual,
                complementarity,
            },
            other => other,
        }
    }
    /// Shorthand for [`Error::Shape`].
    pub fn shape(name: impl Into<String>, expected: &[usize], got: &[usize]) -> Self {
        Error::Shape {
            name: name.into(),
            expected: expected.to_vec(),
            got: got.to_vec(),
        }
    }

    /// `Ok` if every entry of `values` is finite, else the input error naming the first bad
    /// entry (`name[i]`) and its value.
    pub fn check_finite(name: &str, values: &[f64]) -> Result<()> {
        match values.iter().position(|x| !x.is_finite()) {
            Some(i) => Err(Error::input(
                format!("{name}[{i}]"),
                values[i],
                "must be finite",
            )),
            None => Ok(()),
        }
    }
}

/// `ensure!(cond, err)`: return `Err(err)` unless `cond` holds (one-line checks, as `polars_ensure!`).
#[macro_export]
macro_rules! ensure {
    ($cond:expr, $err:expr) => {
        if $cond {
        } else {
            return Err($err);
        }
    };
}
