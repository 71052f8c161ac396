//! The one error type of the crate. The Python bindings map each variant to a
//! `depthpose.DepthPoseError` subclass (all of them `ValueError`s).

use thiserror::Error;

/// Everything that can go wrong in depthpose.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum Error {
    /// An argument has the wrong shape, type, range or content. `name` is the argument.
    #[error("{name}: {message}")]
    InvalidArgument { name: String, message: String },
    /// A file is missing, unreadable or not in the expected format.
    #[error("{path}: {message}")]
    File { path: String, message: String },
    /// The input holds no usable body (no valid depth, empty foreground, ...).
    #[error("{0}")]
    NoBody(String),
}

/// Shorthand used across the crate.
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    /// An invalid argument, naming it.
    pub fn invalid(name: impl Into<String>, message: impl Into<String>) -> Self {
        Error::InvalidArgument {
            name: name.into(),
            message: message.into(),
        }
    }

    /// A problem with a file.
    pub fn file(path: impl Into<String>, message: impl Into<String>) -> Self {
        Error::File {
            path: path.into(),
            message: message.into(),
        }
    }
}

/// Fails with an `InvalidArgument` naming `name` unless `ok` holds.
pub fn ensure(ok: bool, name: &str, message: impl FnOnce() -> String) -> Result<()> {
    if ok {
        Ok(())
    } else {
        Err(Error::invalid(name, message()))
    }
}

/// Fails unless `value` is finite and strictly positive.
pub fn ensure_positive(value: f64, name: &str) -> Result<()> {
    ensure(value.is_finite() && value > 0.0, name, || {
        format!("must be a finite positive number, got {value}")
    })
}
