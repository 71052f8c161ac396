//! PyO3 bindings: the private native module `depthpose._core`.
//!
//! Bindings only convert and validate; algorithms live in the stage modules. Every
//! function takes numpy arrays as `&Bound<PyAny>`, checks dtype / shape / contiguity /
//! finiteness with the helpers below (errors name the argument), releases the GIL with
//! [`native`] (the GIL released, the work on a worker of rayon's pool) around the real
//! work and returns owned arrays. One file per stage.

mod arrays;
mod body;
mod camera;
mod cloud;
mod fit;
mod graphcut;
mod io;
mod pipeline;
mod segment;
mod stereo;
mod templates;

use crate::error::Error;
use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

create_exception!(
    _core,
    DepthPoseError,
    PyValueError,
    "Base class of every depthpose error (a ValueError)."
);
create_exception!(
    _core,
    InvalidInputError,
    DepthPoseError,
    "An argument has the wrong type, shape, range or content."
);
create_exception!(
    _core,
    FileFormatError,
    DepthPoseError,
    "A file is missing, unreadable, corrupt or not in the expected format."
);
create_exception!(
    _core,
    NoBodyError,
    DepthPoseError,
    "The input holds no usable body (no valid depth, empty foreground)."
);

impl From<Error> for PyErr {
    fn from(e: Error) -> PyErr {
        let msg = e.to_string();
        match e {
            Error::InvalidArgument { .. } => InvalidInputError::new_err(msg),
            Error::File { .. } => FileFormatError::new_err(msg),
            Error::NoBody(_) => NoBodyError::new_err(msg),
        }
    }
}

/// Releases the GIL and runs `f` on a worker of rayon's pool
/// ([`crate::pool::on_worker`]): the parallel loops inside then share their work with
/// the other workers directly instead of waking this thread after each one.
pub(crate) fn native<T: Send>(py: Python<'_>, f: impl FnOnce() -> T + Send) -> T {
    py.detach(|| crate::pool::on_worker(f))
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("DepthPoseError", py.get_type::<DepthPoseError>())?;
    m.add("InvalidInputError", py.get_type::<InvalidInputError>())?;
    m.add("FileFormatError", py.get_type::<FileFormatError>())?;
    m.add("NoBodyError", py.get_type::<NoBodyError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    camera::register(m)?;
    body::register(m)?;
    cloud::register(m)?;
    fit::register(m)?;
    graphcut::register(m)?;
    io::register(m)?;
    segment::register(m)?;
    pipeline::register(m)?;
    stereo::register(m)?;
    templates::register(m)?;
    Ok(())
}
