//! Numpy array arguments: checked (type, dimensions, size limits, layout) before
//! anything is copied, then read into flat row-major `Vec`s; and results back as numpy
//! arrays.

use super::{
    check_image_pixels, invalid, too_large, type_name, wrong_type, MAX_ARRAY_ELEMENTS,
    MAX_IMAGE_PIXELS,
};
use crate::python::InvalidTypeError;
use numpy::ndarray::{ArrayD, IxDyn};
use numpy::{
    Element, IntoPyArray, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::{PyList, PyTuple};

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

/// Why a dtype of numpy kind `kind` cannot hold numbers, or None if it can.
pub fn not_numeric(kind: u8) -> Option<&'static str> {
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

/// Joints (any number of 3-vectors, e.g. the 15 of a pose or those of several frames
/// one after the other) as a numpy array of `shape`, x, y, z per joint.
pub fn joints_to_numpy<'a, 'py>(
    py: Python<'py>,
    joints: impl IntoIterator<Item = &'a nalgebra::Vector3<f64>>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let v = joints.into_iter().flat_map(|j| [j.x, j.y, j.z]).collect();
    to_numpy(py, v, shape)
}
