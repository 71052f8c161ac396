//! PyO3 bindings: the private native module `depthpose._core`.
//!
//! Bindings only convert and validate; algorithms live in the stage modules. Every
//! argument goes through the converters of [`convert`] (numbers, flags, strings, paths,
//! arrays, native objects): dtype, shape, memory layout, size limits and finiteness
//! are checked there, before anything is allocated, and every error names the
//! argument. The real work runs in [`native`] (the GIL released, on a worker of
//! rayon's pool), and results return as owned arrays. One file per stage.

mod body;
mod camera;
mod checks;
mod cloud;
mod convert;
mod export;
mod fit;
mod graphcut;
mod io;
mod keywords;
mod pipeline;
mod segment;
mod sequence;
mod stereo;
mod stereo_pose;
mod synth;
mod templates;

use crate::error::Error;
use pyo3::create_exception;
use pyo3::exceptions::{PyFileNotFoundError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyDict, PyTuple, PyType};
use pyo3::{ffi, PyTypeInfo};

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
    "A file is unreadable, corrupt or not in the expected format (a missing file is \
     the subclass MissingFileError)."
);
create_exception!(
    _core,
    NoBodyError,
    DepthPoseError,
    "The input holds no usable body (no valid depth, empty foreground)."
);
create_exception!(
    _core,
    ResourceLimitError,
    DepthPoseError,
    "An input, or the result it asks for, exceeds one of depthpose's size limits \
     (MAX_IMAGE_PIXELS, MAX_ARRAY_ELEMENTS, MAX_RESULT_BYTES, MAX_FIT_POINTS, \
     MAX_LABELS); the message names it."
);

/// An exception class with two bases, made once per interpreter by calling `type`.
fn two_base_exception(
    py: Python<'_>,
    name: &str,
    bases: (Bound<'_, PyType>, Bound<'_, PyType>),
    doc: &str,
) -> PyResult<Py<PyType>> {
    let dict = PyDict::new(py);
    dict.set_item("__module__", "depthpose._core")?;
    dict.set_item("__doc__", doc)?;
    let bases = PyTuple::new(py, [bases.0, bases.1])?;
    let ty = py.get_type::<PyType>().call1((name, bases, dict))?;
    Ok(ty.cast_into::<PyType>()?.unbind())
}

/// Declares an exception class with two bases (as `create_exception!` does with one).
macro_rules! two_base_exception {
    ($name:ident, $first:ty, $second:ty, $doc:expr) => {
        #[doc = $doc]
        pub struct $name;

        // SAFETY: the pointer is that of a type object kept alive by the static.
        unsafe impl PyTypeInfo for $name {
            fn type_object_raw(py: Python<'_>) -> *mut ffi::PyTypeObject {
                static TYPE_OBJECT: PyOnceLock<Py<PyType>> = PyOnceLock::new();
                TYPE_OBJECT
                    .get_or_init(py, || {
                        two_base_exception(
                            py,
                            stringify!($name),
                            (py.get_type::<$first>(), py.get_type::<$second>()),
                            $doc,
                        )
                        .expect("an exception class with two bases")
                    })
                    .as_ptr()
                    .cast()
            }
        }
    };
}

two_base_exception!(
    InvalidTypeError,
    InvalidInputError,
    PyTypeError,
    "An argument of the wrong Python type (a TypeError, and an InvalidInputError)."
);
two_base_exception!(
    MissingFileError,
    PyFileNotFoundError,
    FileFormatError,
    "A file or folder that does not exist (a FileNotFoundError, and a FileFormatError)."
);

/// `errno` of a missing file.
const ENOENT: i32 = 2;

impl From<Error> for PyErr {
    fn from(e: Error) -> PyErr {
        // Numbers printed in full (1e300 has 301 digits) are shortened wherever the
        // message was made; a file's path is kept as it is.
        let brief = |m: &str| crate::error::brief_numbers(m).into_owned();
        match e {
            Error::InvalidArgument { name, message } => {
                InvalidInputError::new_err(format!("{name}: {}", brief(&message)))
            }
            Error::File { path, message } => {
                FileFormatError::new_err(format!("{path}: {}", brief(&message)))
            }
            Error::NotFound { path } => {
                PyErr::new::<MissingFileError, _>((ENOENT, "no such file".to_string(), path))
            }
            Error::NoBody(message) => NoBodyError::new_err(brief(&message)),
            Error::ResourceLimit { name, message } => {
                ResourceLimitError::new_err(format!("{name}: {}", brief(&message)))
            }
        }
    }
}

/// Releases the GIL and runs `f` on a worker of rayon's pool
/// ([`crate::pool::on_worker`]): the parallel loops inside then share their work with
/// the other workers directly instead of waking this thread after each one. An error
/// of `f` becomes the matching Python exception; a panic (a bug) becomes a
/// `RuntimeError` saying so instead of unwinding into Python.
pub(crate) fn native<T: Send, E: Into<PyErr> + Send>(
    py: Python<'_>,
    f: impl FnOnce() -> Result<T, E> + Send,
) -> PyResult<T> {
    native_ok(py, f)?.map_err(Into::into)
}

/// [`native`] for work that cannot fail (but for a bug).
pub(crate) fn native_ok<T: Send>(py: Python<'_>, f: impl FnOnce() -> T + Send) -> PyResult<T> {
    py.detach(|| {
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| crate::pool::on_worker(f)))
    })
    .map_err(|panic| {
        let what = panic
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        pyo3::exceptions::PyRuntimeError::new_err(format!(
            "depthpose internal error (a bug; please report it): {what}"
        ))
    })
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("DepthPoseError", py.get_type::<DepthPoseError>())?;
    m.add("InvalidInputError", py.get_type::<InvalidInputError>())?;
    m.add("FileFormatError", py.get_type::<FileFormatError>())?;
    m.add("NoBodyError", py.get_type::<NoBodyError>())?;
    m.add("ResourceLimitError", py.get_type::<ResourceLimitError>())?;
    m.add("InvalidTypeError", py.get_type::<InvalidTypeError>())?;
    m.add("MissingFileError", py.get_type::<MissingFileError>())?;
    m.add("MAX_IMAGE_PIXELS", convert::MAX_IMAGE_PIXELS)?;
    m.add("MAX_ARRAY_ELEMENTS", convert::MAX_ARRAY_ELEMENTS)?;
    m.add("MAX_RESULT_BYTES", convert::MAX_RESULT_BYTES)?;
    m.add("MAX_FIT_POINTS", convert::MAX_FIT_POINTS)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    camera::register(m)?;
    checks::register(m)?;
    body::register(m)?;
    cloud::register(m)?;
    export::register(m)?;
    fit::register(m)?;
    graphcut::register(m)?;
    io::register(m)?;
    segment::register(m)?;
    sequence::register(m)?;
    pipeline::register(m)?;
    stereo::register(m)?;
    stereo_pose::register(m)?;
    synth::register(m)?;
    templates::register(m)?;
    Ok(())
}
