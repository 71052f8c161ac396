//! Converting and checking every argument that crosses from Python into Rust.
//!
//! Every error names the argument. Wrong Python types raise `InvalidTypeError` (a
//! `TypeError` and an `InvalidInputError`), wrong values `InvalidInputError`, and
//! inputs beyond a size limit `ResourceLimitError` naming the limit, checked before
//! anything is allocated or copied.
//!
//! # Numbers, flags, strings, paths
//!
//! [`Int`], [`Real`], [`Flag`], [`Text`] and [`PathArg`] take any Python object and
//! check it when asked for the value ([`Int::count`], [`Real::get`], ...), so that
//! the error names the argument. Integers are Python `int`s or numpy integers (any
//! size: one beyond the range asked for is a clear error, not an `OverflowError`);
//! real numbers are those or Python/numpy floats. `bool` is not a number here.
//!
//! # Arrays
//!
//! | kind | dtypes | read as | layout |
//! |---|---|---|---|
//! | numbers (points, poses, costs, seeds, ...) | floating, signed or unsigned integer | f64 or f32 | any |
//! | indices (edges, labels, node ids) | signed or unsigned integer | i64 | any |
//! | depth images | float32/float64 metres, uint16 millimetres | f32 metres | C-contiguous |
//! | masks | bool, or an integer type holding only 0 and 1 | bool | C-contiguous |
//!
//! "Any" layout: C or Fortran order, negative strides, strided or broadcast views are
//! read in logical (row-major) order. Depth images and masks are the pixel arrays of
//! a live loop and must be C-contiguous (`numpy.ascontiguousarray`); others are
//! refused with a clear error. Non-native byte order, unaligned data, float16 and
//! long double are converted by numpy (after the size check). Bool, complex, object,
//! string, datetime and structured arrays are refused where numbers are expected.

use super::body::PyBodyModel;
use super::camera::PyCamera;
use super::fit::PyFitConfig;
use super::{InvalidInputError, InvalidTypeError, ResourceLimitError};
use crate::camera::Camera;
use crate::error::{brief, brief_numbers};
use numpy::ndarray::{ArrayD, IxDyn};
use numpy::{
    Element, IntoPyArray, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyOverflowError, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyList, PyMapping, PyString, PyTuple};
use pyo3::{PyClass, PyTypeInfo};
use std::convert::Infallible;
use std::path::PathBuf;

/// Largest depth image, mask or picture (height × width): 2^23 pixels, e.g.
/// 4096 × 2048. Also the largest image a camera may render.
pub const MAX_IMAGE_PIXELS: usize = crate::io::MAX_IMAGE_PIXELS;
/// Most depth readings (in the mask) one body fit or template match takes: 2^20. A fit
/// holds some 900 bytes per point (costs per segment, the neighbour graph, labels).
pub const MAX_FIT_POINTS: usize = 1 << 20;
/// Largest number of elements of any other array argument: 2^26 (512 MiB as float64).
pub const MAX_ARRAY_ELEMENTS: usize = 1 << 26;
/// Largest result one call may allocate (an output array, a rendered image, a graph
/// built for it): 2^30 bytes.
pub const MAX_RESULT_BYTES: usize = 1 << 30;

/// An argument as an error shows it: the name of its type.
pub fn type_name(obj: &Bound<PyAny>) -> String {
    obj.get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "?".into())
}

/// `InvalidInputError` naming `name`.
pub fn invalid(name: &str, msg: impl std::fmt::Display) -> PyErr {
    InvalidInputError::new_err(format!("{name}: {}", brief_numbers(&msg.to_string())))
}

/// `InvalidTypeError` (a `TypeError`) naming `name`: expected `what`, got `obj`'s type.
pub fn wrong_type(name: &str, what: &str, got: &str) -> PyErr {
    PyErr::new::<InvalidTypeError, _>(format!("{name}: expected {what}, got {got}"))
}

/// `ResourceLimitError` naming `name` and the limit.
pub fn too_large(name: &str, msg: impl std::fmt::Display) -> PyErr {
    ResourceLimitError::new_err(format!("{name}: {msg}"))
}

/// Fails unless a result of `bytes` bytes (computed without overflow by the caller,
/// `None` when it overflowed) fits [`MAX_RESULT_BYTES`].
pub fn check_result_bytes(bytes: Option<usize>, name: &str, what: &str) -> PyResult<()> {
    match bytes {
        Some(b) if b <= MAX_RESULT_BYTES => Ok(()),
        _ => Err(too_large(
            name,
            format!(
                "{what} would need {} bytes, more than the limit MAX_RESULT_BYTES = {MAX_RESULT_BYTES}",
                bytes.map_or_else(|| "over 2**64".to_string(), |b| b.to_string())
            ),
        )),
    }
}

/// Fails unless an image of `height` × `width` pixels fits [`MAX_IMAGE_PIXELS`].
pub fn check_image_pixels(height: usize, width: usize, name: &str) -> PyResult<()> {
    match height.checked_mul(width) {
        Some(p) if p <= MAX_IMAGE_PIXELS => Ok(()),
        _ => Err(too_large(
            name,
            format!(
                "an image of {height}x{width} pixels exceeds the limit MAX_IMAGE_PIXELS = \
                 {MAX_IMAGE_PIXELS}"
            ),
        )),
    }
}

/// Fails unless the depth readings of `depth` (positive, finite, in `mask`) number at
/// most [`MAX_FIT_POINTS`] (`already`: readings counted in other frames).
pub fn check_fit_points(
    depth: &[f32],
    mask: Option<&[bool]>,
    already: usize,
    name: &str,
) -> PyResult<usize> {
    let valid = |z: f32| z.is_finite() && z > 0.0;
    let n = already
        + match mask {
            Some(m) => depth
                .iter()
                .zip(m)
                .filter(|(&z, &on)| on && valid(z))
                .count(),
            None => depth.iter().filter(|&&z| valid(z)).count(),
        };
    if n > MAX_FIT_POINTS {
        return Err(too_large(
            name,
            format!(
                "{n} depth readings to fit exceed the limit MAX_FIT_POINTS = {MAX_FIT_POINTS}; \
                 pass a mask of the person or a smaller image"
            ),
        ));
    }
    Ok(n)
}

// ---- numbers, flags, strings, paths --------------------------------------------------

/// What a scalar argument turned out to be.
#[derive(Clone, Debug)]
enum Scalar {
    Int(i128),
    /// An integer beyond i128 (its sign).
    HugeInt {
        negative: bool,
    },
    Float(f64),
    /// Not a number: the type's name.
    Other(String),
}

fn is_bool(obj: &Bound<PyAny>) -> bool {
    obj.is_instance_of::<PyBool>() || type_name(obj) == "bool" || type_name(obj) == "bool_"
}

fn scalar(obj: &Bound<PyAny>) -> Scalar {
    if is_bool(obj) {
        return Scalar::Other("bool".into());
    }
    // SAFETY: a valid object pointer; PyIndex_Check only reads its type.
    let index = unsafe { pyo3::ffi::PyIndex_Check(obj.as_ptr()) } != 0;
    if index {
        match obj.extract::<i128>() {
            Ok(v) => return Scalar::Int(v),
            Err(e) if e.is_instance_of::<PyOverflowError>(obj.py()) => {
                return Scalar::HugeInt {
                    negative: obj.lt(0).unwrap_or(false),
                }
            }
            Err(_) => {} // e.g. a 0-d float array: read as a float below
        }
    }
    if obj.is_instance_of::<PyFloat>() || obj.hasattr("__float__").unwrap_or(false) {
        if let Ok(v) = obj.extract::<f64>() {
            return Scalar::Float(v);
        }
    }
    Scalar::Other(type_name(obj))
}

fn huge(negative: bool) -> &'static str {
    if negative {
        "an integer below -2**127"
    } else {
        "an integer of 2**127 or more"
    }
}

/// An integer argument (Python `int`, numpy integer) of any size; see the methods for
/// the ranges.
#[derive(Clone, Debug)]
pub struct Int(Scalar);

impl Int {
    /// A default value.
    pub const fn new(v: i128) -> Self {
        Int(Scalar::Int(v))
    }

    /// The integer, or an error naming `name`.
    pub fn get(&self, name: &str) -> PyResult<i128> {
        match &self.0 {
            Scalar::Int(v) => Ok(*v),
            Scalar::HugeInt { negative } => Err(invalid(
                name,
                format!("got {}, far outside the range allowed", huge(*negative)),
            )),
            Scalar::Float(v) => Err(wrong_type(
                name,
                "an integer",
                &format!("float {}", brief(*v)),
            )),
            Scalar::Other(t) => Err(wrong_type(name, "an integer", t)),
        }
    }

    /// A value in `lo..=hi`.
    pub fn in_range(&self, lo: i128, hi: i128, name: &str) -> PyResult<i128> {
        match &self.0 {
            Scalar::HugeInt { negative } => Err(invalid(
                name,
                format!("must be an integer in {lo}..={hi}, got {}", huge(*negative)),
            )),
            _ => {
                let v = self.get(name)?;
                if (lo..=hi).contains(&v) {
                    Ok(v)
                } else {
                    Err(invalid(
                        name,
                        format!("must be an integer in {lo}..={hi}, got {v}"),
                    ))
                }
            }
        }
    }

    /// A non-negative integer (a count, a size, an index).
    pub fn count(&self, name: &str) -> PyResult<usize> {
        self.at_least(0, name)
    }

    /// An integer of at least `min`.
    pub fn at_least(&self, min: usize, name: &str) -> PyResult<usize> {
        let what = || format!("must be an integer >= {min}");
        match &self.0 {
            Scalar::HugeInt { negative } => Err(invalid(
                name,
                format!("{}, got {}", what(), huge(*negative)),
            )),
            _ => {
                let v = self.get(name)?;
                usize::try_from(v)
                    .ok()
                    .filter(|&u| u >= min)
                    .ok_or_else(|| invalid(name, format!("{}, got {v}", what())))
            }
        }
    }

    /// An RNG seed: an integer in 0..2**64.
    pub fn seed(&self, name: &str) -> PyResult<u64> {
        Ok(self.in_range(0, i128::from(u64::MAX), name)? as u64)
    }
}

/// A real-number argument (Python/numpy floats and integers).
#[derive(Clone, Debug)]
pub struct Real(Scalar);

impl Real {
    /// A default value.
    pub const fn new(v: f64) -> Self {
        Real(Scalar::Float(v))
    }

    /// The number as given (NaN and ±inf included: the callee checks its range).
    pub fn get(&self, name: &str) -> PyResult<f64> {
        match &self.0 {
            Scalar::Float(v) => Ok(*v),
            Scalar::Int(v) => Ok(*v as f64),
            Scalar::HugeInt { negative } => Err(invalid(
                name,
                format!("got {}, beyond any sensible value", huge(*negative)),
            )),
            Scalar::Other(t) => Err(wrong_type(name, "a number", t)),
        }
    }

    /// The number in single precision (as given: the callee checks its range; a value
    /// beyond the float32 range becomes ±inf).
    pub fn get_f32(&self, name: &str) -> PyResult<f32> {
        Ok(self.get(name)? as f32)
    }
}

/// A `bool` argument (Python or numpy bool; integers are refused).
#[derive(Clone, Debug)]
pub struct Flag(Result<bool, String>);

impl Flag {
    /// A default value.
    pub const fn new(v: bool) -> Self {
        Flag(Ok(v))
    }

    /// The flag, or an error naming `name`.
    pub fn get(&self, name: &str) -> PyResult<bool> {
        self.0
            .clone()
            .map_err(|t| wrong_type(name, "True or False", &t))
    }

    /// An optional flag (None: `None`), or an error naming `name`.
    pub fn optional(flag: Option<&Flag>, name: &str) -> PyResult<Option<bool>> {
        flag.map(|f| {
            f.0.clone()
                .map_err(|t| wrong_type(name, "True, False or None", &t))
        })
        .transpose()
    }
}

/// A `str` argument.
#[derive(Clone, Debug)]
pub struct Text(Result<String, String>);

impl Text {
    /// The string, or an error naming `name`.
    pub fn get(&self, name: &str) -> PyResult<&str> {
        match &self.0 {
            Ok(s) => Ok(s),
            Err(t) => Err(wrong_type(name, "a string", t)),
        }
    }
}

/// A file path argument (`str` or `os.PathLike`).
#[derive(Clone, Debug)]
pub struct PathArg(Result<PathBuf, String>);

impl PathArg {
    /// The path, or an error naming `name`.
    pub fn get(&self, name: &str) -> PyResult<PathBuf> {
        self.0
            .clone()
            .map_err(|t| wrong_type(name, "a path (str or os.PathLike)", &t))
    }
}

macro_rules! lazy_argument {
    ($ty:ident, |$obj:ident| $body:expr) => {
        impl<'a, 'py> FromPyObject<'a, 'py> for $ty {
            type Error = Infallible;
            fn extract(obj: pyo3::Borrowed<'a, 'py, PyAny>) -> Result<Self, Infallible> {
                let $obj: &Bound<'py, PyAny> = &obj;
                Ok($body)
            }
        }
    };
}

lazy_argument!(Int, |obj| Int(scalar(obj)));
lazy_argument!(Real, |obj| Real(scalar(obj)));
lazy_argument!(Flag, |obj| Flag(if is_bool(obj) {
    obj.is_truthy().map_err(|_| type_name(obj))
} else {
    Err(type_name(obj))
}));
lazy_argument!(Text, |obj| Text(
    obj.extract::<String>().map_err(|_| type_name(obj))
));
lazy_argument!(PathArg, |obj| PathArg(
    obj.extract::<PathBuf>().map_err(|_| type_name(obj))
));

/// A list of real numbers (any sequence of numbers, or a 1-D array).
pub fn reals(obj: &Bound<PyAny>, name: &str, len: Option<usize>) -> PyResult<Vec<f64>> {
    let values: Vec<f64> = if obj.cast::<PyUntypedArray>().is_ok() {
        f64_array(obj, name, Some(1), false)?.data
    } else {
        let Ok(seq) = obj.try_iter() else {
            return Err(wrong_type(name, "a sequence of numbers", &type_name(obj)));
        };
        let mut out = Vec::new();
        for (i, item) in seq.enumerate() {
            if i >= MAX_ARRAY_ELEMENTS {
                return Err(too_large(name, "too many values (MAX_ARRAY_ELEMENTS)"));
            }
            let item = item?;
            out.push(Real(scalar(&item)).get(&format!("{name}[{i}]"))?);
        }
        out
    };
    if let Some(n) = len {
        if values.len() != n {
            return Err(invalid(
                name,
                format!("needs {n} values, got {}", values.len()),
            ));
        }
    }
    Ok(values)
}

/// Exactly `N` integers from a tuple, list or other sequence (`what` describes it).
pub fn ints<const N: usize>(obj: &Bound<PyAny>, name: &str, what: &str) -> PyResult<[Int; N]> {
    let items: Vec<Int> = match obj.try_iter() {
        Ok(seq) if obj.cast::<pyo3::types::PyString>().is_err() => seq
            .take(N + 1)
            .map(|item| item.map(|i| Int(scalar(&i))))
            .collect::<PyResult<_>>()?,
        _ => return Err(wrong_type(name, what, &type_name(obj))),
    };
    let n = items.len();
    items.try_into().map_err(|_| {
        invalid(
            name,
            format!(
                "expected {what}, got {}",
                if n > N {
                    "more values".to_string()
                } else {
                    format!("{n} values")
                }
            ),
        )
    })
}

/// A list of non-negative integers (any sequence of integers, or a 1-D array).
pub fn counts(obj: &Bound<PyAny>, name: &str) -> PyResult<Vec<usize>> {
    if obj.cast::<PyUntypedArray>().is_ok() {
        let a = i64_array(obj, name, Some(1))?;
        return a
            .data
            .iter()
            .enumerate()
            .map(|(i, &v)| {
                usize::try_from(v).map_err(|_| {
                    invalid(
                        name,
                        format!("must hold non-negative integers, got {v} at {i}"),
                    )
                })
            })
            .collect();
    }
    let Ok(seq) = obj.try_iter() else {
        return Err(wrong_type(name, "a sequence of integers", &type_name(obj)));
    };
    let mut out = Vec::new();
    for (i, item) in seq.enumerate() {
        if i >= MAX_ARRAY_ELEMENTS {
            return Err(too_large(name, "too many values (MAX_ARRAY_ELEMENTS)"));
        }
        out.push(Int(scalar(&item?)).count(&format!("{name}[{i}]"))?);
    }
    Ok(out)
}

/// A pixel connectivity argument: 4 or 8.
pub fn connectivity(value: &Int) -> PyResult<crate::cloud::Connectivity> {
    let n = value.get("connectivity")?;
    u32::try_from(n)
        .ok()
        .and_then(|n| crate::cloud::Connectivity::from_int(n).ok())
        .ok_or_else(|| invalid("connectivity", format!("must be 4 or 8, got {n}")))
}

// ---- native objects ----------------------------------------------------------------

/// `obj` as the native class `T` (`what` describes it in the error).
pub fn object<'py, T: PyClass + PyTypeInfo>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    what: &str,
) -> PyResult<PyRef<'py, T>> {
    let bound = obj
        .cast::<T>()
        .map_err(|_| wrong_type(name, what, &type_name(obj)))?;
    bound
        .try_borrow()
        .map_err(|_| invalid(name, "is being changed by another call"))
}

/// A `depthpose.Camera` argument.
pub fn camera(obj: &Bound<PyAny>, name: &str) -> PyResult<Camera> {
    Ok(object::<PyCamera>(obj, name, "a depthpose.Camera")?.inner)
}

/// An optional `depthpose.BodyModel` argument (None: the default model).
pub fn body_model(obj: Option<&Bound<PyAny>>, name: &str) -> PyResult<crate::body::BodyModel> {
    match obj {
        None => Ok(crate::body::BodyModel::default()),
        Some(m) => Ok(
            object::<PyBodyModel>(m, name, "a depthpose.BodyModel or None")?
                .inner
                .clone(),
        ),
    }
}

/// An optional `depthpose.FitConfig` argument: a FitConfig, a mapping of its keyword
/// arguments, or None (the defaults).
pub fn fit_config(obj: Option<&Bound<PyAny>>, name: &str) -> PyResult<crate::fit::FitConfig> {
    let Some(obj) = obj.filter(|c| !c.is_none()) else {
        return Ok(crate::fit::FitConfig::default());
    };
    if obj.is_instance_of::<PyFitConfig>() {
        return Ok(object::<PyFitConfig>(obj, name, "a FitConfig")?.to_rust()?);
    }
    let Ok(mapping) = obj.cast::<PyMapping>() else {
        return Err(wrong_type(
            name,
            "a FitConfig, a dict or None",
            &type_name(obj),
        ));
    };
    let py = obj.py();
    let settings = PyDict::new(py);
    settings.update(mapping)?;
    if let Some(key) = settings
        .keys()
        .iter()
        .find(|k| !k.is_instance_of::<PyString>())
    {
        return Err(PyErr::new::<InvalidTypeError, _>(format!(
            "{name}: keys must be setting names, got {}",
            key.repr()?
        )));
    }
    let config = py
        .get_type::<PyFitConfig>()
        .call((), Some(&settings))
        .map_err(|e| {
            if e.is_instance_of::<PyTypeError>(py) && !e.is_instance_of::<InvalidTypeError>(py) {
                PyErr::new::<InvalidTypeError, _>(format!("{name}: {}", e.value(py)))
            } else {
                e
            }
        })?;
    Ok(object::<PyFitConfig>(&config, name, "a FitConfig")?.to_rust()?)
}

/// A list or tuple as `numpy.asarray` reads it (a ragged one is refused, naming
/// `name`); anything else as it is, for the array readers to check.
pub fn array_like<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<Bound<'py, PyAny>> {
    if !(obj.is_instance_of::<PyList>() || obj.is_instance_of::<PyTuple>()) {
        return Ok(obj.clone());
    }
    obj.py()
        .import("numpy")?
        .call_method1("asarray", (obj,))
        .map_err(|_| invalid(name, "not a rectangular array of numbers"))
}

// ---- arrays ------------------------------------------------------------------------

/// A numpy argument copied into a flat row-major `Vec` with its shape.
pub struct Arr<T> {
    pub data: Vec<T>,
    pub shape: Vec<usize>,
}

/// How an array argument is checked before it is read.
struct Check<'a> {
    name: &'a str,
    ndim: Option<usize>,
    /// Must be C-contiguous (images and masks).
    contiguous: bool,
    /// Largest number of elements (of pixels for images: see `image`).
    max_elements: usize,
    /// The first two axes are an image's height and width (limited by
    /// [`MAX_IMAGE_PIXELS`]).
    image: bool,
}

/// The array behind `obj` with the checks every argument gets, in this order: a numpy
/// array, `ndim` dimensions, non-empty, within its size limit, C-contiguous if asked.
fn untyped<'a, 'py>(
    obj: &'a Bound<'py, PyAny>,
    c: &Check,
) -> PyResult<&'a Bound<'py, PyUntypedArray>> {
    let name = c.name;
    let arr = obj
        .cast::<PyUntypedArray>()
        .map_err(|_| wrong_type(name, "a numpy array", &type_name(obj)))?;
    if let Some(n) = c.ndim {
        if arr.ndim() != n {
            return Err(invalid(
                name,
                format!("expected a {n}-D array, got shape {:?}", arr.shape()),
            ));
        }
    }
    if arr.len() == 0 {
        return Err(invalid(
            name,
            format!("array is empty (shape {:?})", arr.shape()),
        ));
    }
    if c.image && arr.ndim() >= 2 {
        let s = arr.shape();
        check_image_pixels(s[0], s[1], name)?;
    }
    if arr.len() > c.max_elements {
        return Err(too_large(
            name,
            format!(
                "{} elements (shape {:?}) exceed the limit {} = {}",
                arr.len(),
                arr.shape(),
                if c.image {
                    "MAX_IMAGE_PIXELS"
                } else {
                    "MAX_ARRAY_ELEMENTS"
                },
                c.max_elements
            ),
        ));
    }
    if c.contiguous && !arr.is_c_contiguous() {
        return Err(invalid(
            name,
            "array is not C-contiguous (a strided view or Fortran order); pass \
             numpy.ascontiguousarray(...)",
        ));
    }
    Ok(arr)
}

/// Why the dtype `dt` cannot hold numbers, or None if it can.
fn not_numeric(kind: u8) -> Option<&'static str> {
    match kind {
        b'f' | b'i' | b'u' => None,
        b'b' => Some("a bool array where numbers are expected"),
        b'c' => Some("complex numbers are not supported"),
        b'O' => Some("an object array; convert it with numpy.asarray(x, dtype=float)"),
        b'U' | b'S' => Some("a string array where numbers are expected"),
        b'M' | b'm' => Some("a date/time array where numbers are expected"),
        _ => Some("not a numeric array"),
    }
}

/// `arr` converted by numpy to a dtype the typed readers take (native byte order,
/// aligned, float32/64 for other float sizes), or None when it already is one. Called
/// only after the size checks.
fn normalised<'py>(arr: &Bound<'py, PyUntypedArray>) -> PyResult<Option<Bound<'py, PyAny>>> {
    let dt = arr.dtype();
    let kind = dt.kind();
    let size = dt.itemsize();
    let native = dt.is_native_byteorder().unwrap_or(true);
    let plain_size = match kind {
        b'f' => size == 4 || size == 8,
        b'i' | b'u' => matches!(size, 1 | 2 | 4 | 8),
        _ => true,
    };
    if native && plain_size && arr.is_aligned() && !dt.has_fields() && !dt.has_subarray() {
        return Ok(None);
    }
    let target = match kind {
        b'f' if size < 4 => "float32".to_string(),
        b'f' if size > 8 => "float64".to_string(),
        b'f' | b'i' | b'u' | b'b' => format!("={}{}", kind as char, size),
        _ => return Ok(None),
    };
    Ok(Some(arr.call_method1("astype", (target,))?))
}

/// The values of a `T` array in row-major order, each converted by `f`.
fn read_typed<T: Element + Copy, O>(
    arr: &Bound<PyUntypedArray>,
    name: &str,
    f: impl Fn(T) -> O,
) -> PyResult<Vec<O>> {
    let a = arr.cast::<PyArrayDyn<T>>()?;
    let ro = a
        .try_readonly()
        .map_err(|_| invalid(name, "is being written by another call"))?;
    // C-contiguous input (the usual case) converts as a slice: the n-D element iterator
    // costs about 10 ns per element. (A Fortran-order array is contiguous too, but not
    // in row-major order.)
    Ok(match ro.as_slice() {
        Ok(v) if a.is_c_contiguous() => v.iter().map(|&v| f(v)).collect(),
        _ => ro.as_array().iter().map(|&v| f(v)).collect(),
    })
}

/// Returns the values of `$arr` as `$out` if its dtype is one of the types listed.
macro_rules! read_as {
    ($arr:expr, $name:expr, $out:ty, [$($t:ty),*]) => {{
        let dt = $arr.dtype();
        let py = $arr.py();
        $(
            if dt.is_equiv_to(&numpy::dtype::<$t>(py)) {
                return read_typed::<$t, $out>($arr, $name, |v| v as $out);
            }
        )*
    }};
}

/// The values of a numeric array as `f64`.
fn read_f64(arr: &Bound<PyUntypedArray>, name: &str) -> PyResult<Vec<f64>> {
    if let Some(a) = normalised(arr)? {
        return read_f64(a.cast::<PyUntypedArray>()?, name);
    }
    read_as!(
        arr,
        name,
        f64,
        [f64, f32, u8, u16, u32, u64, i8, i16, i32, i64]
    );
    Err(dtype_error(arr, name, "numbers"))
}

/// The values of a numeric array as `f32`.
fn read_f32(arr: &Bound<PyUntypedArray>, name: &str) -> PyResult<Vec<f32>> {
    if let Some(a) = normalised(arr)? {
        return read_f32(a.cast::<PyUntypedArray>()?, name);
    }
    read_as!(
        arr,
        name,
        f32,
        [f32, f64, u8, u16, u32, u64, i8, i16, i32, i64]
    );
    Err(dtype_error(arr, name, "numbers"))
}

/// The values of an integer array as `i64` (uint64 values beyond int64 refused).
fn read_i64(arr: &Bound<PyUntypedArray>, name: &str) -> PyResult<Vec<i64>> {
    if let Some(a) = normalised(arr)? {
        return read_i64(a.cast::<PyUntypedArray>()?, name);
    }
    if arr.dtype().is_equiv_to(&numpy::dtype::<u64>(arr.py())) {
        let v = read_typed::<u64, u64>(arr, name, |v| v)?;
        return v
            .iter()
            .enumerate()
            .map(|(i, &x)| {
                i64::try_from(x).map_err(|_| {
                    invalid(name, format!("value {x} at flat index {i} is beyond int64"))
                })
            })
            .collect();
    }
    read_as!(arr, name, i64, [i64, i32, u32, u16, u8, i16, i8]);
    Err(dtype_error(arr, name, "integers"))
}

fn dtype_error(arr: &Bound<PyUntypedArray>, name: &str, what: &str) -> PyErr {
    let dt = arr.dtype();
    let why = not_numeric(dt.kind()).unwrap_or(match what {
        "integers" => "floats where integers are expected (indices must be exact)",
        _ => "not a supported numeric type",
    });
    let e = format!("dtype {dt}: {why}");
    if matches!(dt.kind(), b'O' | b'U' | b'S' | b'M' | b'm' | b'V' | b'c') {
        wrong_type_array(name, &e)
    } else {
        invalid(name, e)
    }
}

/// An array of a dtype that holds no numbers: a `TypeError` too.
fn wrong_type_array(name: &str, msg: &str) -> PyErr {
    PyErr::new::<InvalidTypeError, _>(format!("{name}: {msg}"))
}

fn general(name: &str, ndim: Option<usize>) -> Check<'_> {
    Check {
        name,
        ndim,
        contiguous: false,
        max_elements: MAX_ARRAY_ELEMENTS,
        image: false,
    }
}

fn first_non_finite<T: Copy + Into<f64>>(data: &[T], name: &str) -> PyResult<()> {
    if let Some(i) = data.iter().position(|&v| !v.into().is_finite()) {
        return Err(invalid(
            name,
            format!(
                "holds a non-finite value ({}) at flat index {i}",
                data[i].into()
            ),
        ));
    }
    Ok(())
}

/// A numeric array of any layout as `f64`. `finite` refuses NaN and ±inf.
pub fn f64_array(
    obj: &Bound<PyAny>,
    name: &str,
    ndim: Option<usize>,
    finite: bool,
) -> PyResult<Arr<f64>> {
    let arr = untyped(obj, &general(name, ndim))?;
    let shape = arr.shape().to_vec();
    let data = read_f64(arr, name)?;
    if finite {
        first_non_finite(&data, name)?;
    }
    Ok(Arr { data, shape })
}

/// Like [`f64_array`] in single precision (values beyond its range become ±inf,
/// which `finite` refuses).
pub fn f32_array(
    obj: &Bound<PyAny>,
    name: &str,
    ndim: Option<usize>,
    finite: bool,
) -> PyResult<Arr<f32>> {
    let arr = untyped(obj, &general(name, ndim))?;
    let shape = arr.shape().to_vec();
    let data = read_f32(arr, name)?;
    if finite {
        first_non_finite(&data, name)?;
    }
    Ok(Arr { data, shape })
}

/// An integer array of any layout (floats are refused so that indices stay exact).
pub fn i64_array(obj: &Bound<PyAny>, name: &str, ndim: Option<usize>) -> PyResult<Arr<i64>> {
    let arr = untyped(obj, &general(name, ndim))?;
    let shape = arr.shape().to_vec();
    let data = read_i64(arr, name)?;
    Ok(Arr { data, shape })
}

/// An RGB picture (H, W, 3) of an integer dtype with values in 0..=255, any layout.
pub fn rgb_u8(obj: &Bound<PyAny>, name: &str) -> PyResult<Arr<u8>> {
    let arr = untyped(
        obj,
        &Check {
            name,
            ndim: Some(3),
            contiguous: false,
            max_elements: 3 * MAX_IMAGE_PIXELS,
            image: true,
        },
    )?;
    let shape = arr.shape().to_vec();
    if shape[2] != 3 {
        return Err(invalid(
            name,
            format!("expected an (H, W, 3) picture, got shape {shape:?}"),
        ));
    }
    let values = read_i64(arr, name)?;
    if let Some(i) = values.iter().position(|v| !(0..=255).contains(v)) {
        return Err(invalid(
            name,
            format!(
                "values must be in 0..=255 (uint8), got {} at flat index {i}",
                values[i]
            ),
        ));
    }
    Ok(Arr {
        data: values.into_iter().map(|v| v as u8).collect(),
        shape,
    })
}

/// A numeric image (H, W) or (H, W, C) of any layout as f32, finite.
pub fn image_f32(obj: &Bound<PyAny>, name: &str) -> PyResult<Arr<f32>> {
    let arr = untyped(
        obj,
        &Check {
            name,
            ndim: None,
            contiguous: false,
            max_elements: 4 * MAX_IMAGE_PIXELS,
            image: true,
        },
    )?;
    if !(arr.ndim() == 2 || arr.ndim() == 3) {
        return Err(invalid(
            name,
            format!(
                "expected an image (H, W) or (H, W, C), got shape {:?}",
                arr.shape()
            ),
        ));
    }
    let shape = arr.shape().to_vec();
    let data = read_f32(arr, name)?;
    first_non_finite(&data, name)?;
    Ok(Arr { data, shape })
}

/// A boolean mask of exactly `shape` (H, W): bool, or an integer type holding only 0
/// and 1; C-contiguous.
pub fn bool_array(obj: &Bound<PyAny>, name: &str, shape: &[usize]) -> PyResult<Vec<bool>> {
    let arr = untyped(
        obj,
        &Check {
            name,
            ndim: Some(shape.len()),
            contiguous: true,
            max_elements: MAX_IMAGE_PIXELS,
            image: true,
        },
    )?;
    if arr.shape() != shape {
        return Err(invalid(
            name,
            format!("shape {:?} does not match {:?}", arr.shape(), shape),
        ));
    }
    let dt = arr.dtype();
    if dt.is_equiv_to(&numpy::dtype::<bool>(arr.py())) {
        let a = arr.cast::<PyArrayDyn<bool>>()?;
        let ro = a
            .try_readonly()
            .map_err(|_| invalid(name, "is being written by another call"))?;
        return Ok(match ro.as_slice() {
            Ok(v) => v.to_vec(),
            Err(_) => ro.as_array().iter().copied().collect(),
        });
    }
    if !matches!(dt.kind(), b'i' | b'u') {
        let msg = format!(
            "a mask must be a bool array (or integers 0 and 1), got dtype {dt}; use mask \
             != 0 or mask.astype(bool) if that is what you mean"
        );
        return Err(if matches!(dt.kind(), b'O' | b'U' | b'S' | b'V') {
            wrong_type_array(name, &msg)
        } else {
            invalid(name, msg)
        });
    }
    let values = read_i64(arr, name)?;
    if let Some(i) = values.iter().position(|&v| v != 0 && v != 1) {
        return Err(invalid(
            name,
            format!(
                "an integer mask must hold only 0 and 1, got {} at flat index {i}",
                values[i]
            ),
        ));
    }
    Ok(values.into_iter().map(|v| v == 1).collect())
}

/// A depth image (H, W) in metres: float32/float64 as metres, uint16 as millimetres;
/// C-contiguous. NaN and 0 mean "no reading"; negative or infinite values are errors.
pub fn depth_array(obj: &Bound<PyAny>, name: &str) -> PyResult<Arr<f32>> {
    let arr = untyped(
        obj,
        &Check {
            name,
            ndim: Some(2),
            contiguous: true,
            max_elements: MAX_IMAGE_PIXELS,
            image: true,
        },
    )?;
    let shape = arr.shape().to_vec();
    let dt = arr.dtype();
    let is_u16 = dt.kind() == b'u' && dt.itemsize() == 2;
    let is_float = dt.kind() == b'f';
    if !is_u16 && !is_float {
        let msg =
            format!("depth must be float32/float64 metres or uint16 millimetres, got dtype {dt}");
        return Err(if not_numeric(dt.kind()).is_some() && dt.kind() != b'b' {
            wrong_type_array(name, &msg)
        } else {
            invalid(name, msg)
        });
    }
    let mut data = read_f32(arr, name)?;
    if is_u16 {
        data.iter_mut().for_each(|v| *v *= 0.001);
    }
    crate::cloud::DepthView::new(&data, shape[0], shape[1], name)?;
    Ok(Arr { data, shape })
}

/// An owned `Vec` as a numpy array of `shape` (no copy).
pub fn to_numpy<'py, T: Element>(
    py: Python<'py>,
    data: Vec<T>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyArrayDyn<T>>> {
    let n = data.len();
    ArrayD::from_shape_vec(IxDyn(shape), data)
        .map(|a| a.into_pyarray(py))
        .map_err(|_| {
            PyErr::new::<pyo3::exceptions::PyRuntimeError, _>(format!(
                "internal error: {n} values do not make shape {shape:?} (please report)"
            ))
        })
}
