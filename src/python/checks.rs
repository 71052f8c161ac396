//! The argument checks of the Python layer (`depthpose._validate` re-exports them):
//! the converters of [`super::convert`] as functions, so that a Python module checks
//! an argument by the rules and with the messages of the native functions.

use super::convert::{
    array_like, bool_array, check_image_pixels, f64_array, invalid, not_numeric, to_numpy,
    too_large, type_name, wrong_type, Int, Real, Text, MAX_ARRAY_ELEMENTS, MAX_IMAGE_PIXELS,
};
use super::InvalidTypeError;
use crate::error::brief;
use numpy::{PyArrayDescr, PyArrayDescrMethods, PyArrayDyn, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;

/// The name argument of a check ("value" when it is not a string).
fn name_of(name: &Text) -> String {
    name.get("name").unwrap_or("value").to_string()
}

/// A Python or numpy integer (not a bool) within [`low`, `high`] (either may be
/// open), as a Python int.
#[pyfunction]
#[pyo3(signature = (value, name, *, low=None, high=None))]
fn _check_integer<'py>(
    value: &Bound<'py, PyAny>,
    name: Text,
    low: Option<i128>,
    high: Option<i128>,
) -> PyResult<Bound<'py, PyAny>> {
    integer(value, &name_of(&name), low, high)
}

/// [`_check_integer`] for Rust callers: `value` within [`low`, `high`] as a Python int.
pub(crate) fn integer<'py>(
    value: &Bound<'py, PyAny>,
    name: &str,
    low: Option<i128>,
    high: Option<i128>,
) -> PyResult<Bound<'py, PyAny>> {
    let range = || {
        let end = |b: Option<i128>| b.map(|v| v.to_string()).unwrap_or_default();
        format!("must be an integer in {}..{}", end(low), end(high))
    };
    let int: Int = value.extract()?;
    match int.get(name) {
        Ok(v) if low.is_some_and(|l| v < l) || high.is_some_and(|h| v > h) => {
            Err(invalid(name, format!("{}, got {v}", range())))
        }
        Ok(_) => value.call_method0("__index__"),
        Err(e) if e.is_instance_of::<InvalidTypeError>(value.py()) => Err(e),
        Err(_) => {
            // An integer beyond 128 bits: fine beyond an open end of the range.
            let v = value.call_method0("__index__")?;
            let positive = v.gt(0)?;
            if positive && high.is_none() || !positive && low.is_none() {
                Ok(v)
            } else {
                Err(invalid(
                    name,
                    format!("{}, got an integer far outside it", range()),
                ))
            }
        }
    }
}

/// A finite Python or numpy real number (not a bool) within [`low`, `high`]
/// (`low_open`: above `low`).
#[pyfunction]
#[pyo3(signature = (value, name, *, low=None, high=None, low_open=false))]
fn _check_number(
    value: Real,
    name: Text,
    low: Option<f64>,
    high: Option<f64>,
    low_open: bool,
) -> PyResult<f64> {
    number(value, &name_of(&name), (low, high), low_open)
}

/// [`_check_number`] for Rust callers: `value` within `(low, high)` (`None`: open).
pub(crate) fn number(
    value: Real,
    name: &str,
    (low, high): (Option<f64>, Option<f64>),
    low_open: bool,
) -> PyResult<f64> {
    let v = value.get(name)?;
    let (lo, hi) = (
        low.unwrap_or(f64::NEG_INFINITY),
        high.unwrap_or(f64::INFINITY),
    );
    let above = if low_open { v > lo } else { v >= lo };
    if v.is_finite() && above && v <= hi {
        return Ok(v);
    }
    Err(invalid(
        name,
        format!(
            "must be a finite number in {}{}, {}], got {}",
            if low_open { "(" } else { "[" },
            brief(lo),
            brief(hi),
            brief(v)
        ),
    ))
}

/// `value` itself if it is a numpy array within its size limit (not copied): an image
/// (`image` > 0: H × W at most `MAX_IMAGE_PIXELS`, `image` values a pixel) or any
/// other array (`MAX_ARRAY_ELEMENTS`).
#[pyfunction]
#[pyo3(signature = (value, name, *, image=0))]
fn _check_array<'py>(
    value: &Bound<'py, PyAny>,
    name: Text,
    image: usize,
) -> PyResult<Bound<'py, PyAny>> {
    check_array(value, &name_of(&name), image)?;
    Ok(value.clone())
}

/// [`_check_array`]'s checks, returning the array.
fn check_array<'a, 'py>(
    value: &'a Bound<'py, PyAny>,
    name: &str,
    image: usize,
) -> PyResult<&'a Bound<'py, PyUntypedArray>> {
    let a = value
        .cast::<PyUntypedArray>()
        .map_err(|_| wrong_type(name, "a numpy array", &type_name(value)))?;
    let shape = a.shape();
    if image > 0 && shape.len() >= 2 {
        check_image_pixels(shape[0], shape[1], name)?;
    }
    let (limit, value) = if image > 0 {
        ("MAX_IMAGE_PIXELS", MAX_IMAGE_PIXELS)
    } else {
        ("MAX_ARRAY_ELEMENTS", MAX_ARRAY_ELEMENTS)
    };
    if a.len() > value.saturating_mul(image.max(1)) {
        let shown = crate::io::npy::shape_text(shape);
        return Err(too_large(
            name,
            format!(
                "{} elements (shape {shown}) exceed the limit {limit} = {value}",
                a.len()
            ),
        ));
    }
    Ok(a)
}

/// A mask of exactly `shape` as a C-contiguous bool array: bool, or an integer dtype
/// holding only 0 and 1, of any memory layout.
#[pyfunction]
#[pyo3(signature = (value, shape, name=None))]
fn _check_mask<'py>(
    py: Python<'py>,
    value: &Bound<'py, PyAny>,
    shape: Vec<usize>,
    name: Option<Text>,
) -> PyResult<Bound<'py, PyArrayDyn<bool>>> {
    let name = name.as_ref().map_or_else(|| "mask".to_string(), name_of);
    let contiguous = if check_array(value, &name, 1)?.is_c_contiguous() {
        value.clone()
    } else {
        py.import("numpy")?
            .call_method1("ascontiguousarray", (value,))?
    };
    let m = bool_array(&contiguous, &name, &shape)?;
    to_numpy(py, m, &shape)
}

/// A numeric array (a list or tuple of numbers too, any layout) as float64, without
/// NaN or inf.
#[pyfunction]
#[pyo3(signature = (value, name, *, ndim=None))]
fn _check_numbers<'py>(
    py: Python<'py>,
    value: &Bound<'py, PyAny>,
    name: Text,
    ndim: Option<usize>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let name = name_of(&name);
    let a = f64_array(&array_like(value, &name)?, &name, ndim, true)?;
    to_numpy(py, a.data, &a.shape)
}

/// Why `dtype` cannot hold numbers (None if it can), in the words of the native
/// converters' errors.
#[pyfunction]
fn _not_numbers(dtype: &Bound<'_, PyArrayDescr>) -> Option<&'static str> {
    not_numeric(dtype.kind())
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(_not_numbers, m)?)?;
    m.add_function(wrap_pyfunction!(_check_integer, m)?)?;
    m.add_function(wrap_pyfunction!(_check_number, m)?)?;
    m.add_function(wrap_pyfunction!(_check_array, m)?)?;
    m.add_function(wrap_pyfunction!(_check_mask, m)?)?;
    m.add_function(wrap_pyfunction!(_check_numbers, m)?)
}
