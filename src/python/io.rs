//! File reading and writing for Python: depth images in every format, gray images,
//! PFM, and numpy's `.npz` archives (`depthpose.io` re-exports these; `_core.pyi`
//! documents them). Paths and arrays are checked here; the files are read and written
//! by [`crate::io`] with the GIL released.

use super::convert::{
    check_image_pixels, depth_array, f32_array, invalid, rgb_u8, to_numpy, type_name, wrong_type,
    Arr, Flag, Int, PathArg, Real, Text,
};
use super::native;
use crate::io::{self, npy, npz, Image};
use numpy::{PyArray1, PyArrayDyn, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};
use std::path::PathBuf;

type F32Array<'py> = Bound<'py, PyArrayDyn<f32>>;

fn image_out<'py>(py: Python<'py>, img: Image) -> PyResult<F32Array<'py>> {
    to_numpy(py, img.data, &[img.height, img.width])
}

/// A path argument that is not empty.
fn path(arg: &PathArg, name: &str) -> PyResult<PathBuf> {
    let p = arg.get(name)?;
    if p.as_os_str().is_empty() {
        return Err(invalid(name, "empty path"));
    }
    Ok(p)
}

/// The (height, width) of a raw frame: a tuple or list of two positive integers.
fn raw_shape(obj: &Bound<'_, PyAny>) -> PyResult<(usize, usize)> {
    let pair = obj.is_instance_of::<PyTuple>() || obj.is_instance_of::<PyList>();
    if !pair || obj.len()? != 2 {
        return Err(invalid(
            "shape",
            format!("expected (height, width), got {}", obj.repr()?),
        ));
    }
    let h: Int = obj.get_item(0)?.extract()?;
    let w: Int = obj.get_item(1)?.extract()?;
    Ok((h.at_least(1, "shape")?, w.at_least(1, "shape")?))
}

#[pyfunction]
#[pyo3(signature = (path, scale=Real::new(0.001), shape=None),
       text_signature = "(path, scale=0.001, shape=None)")]
fn read_depth<'py>(
    py: Python<'py>,
    path: PathArg,
    scale: Real,
    shape: Option<Bound<'py, PyAny>>,
) -> PyResult<F32Array<'py>> {
    let scale = scale.get("scale")?;
    io::check_depth_scale(scale)?;
    let path = self::path(&path, "path")?;
    // The shape of a raw frame only, checked once the file is known to exist (a
    // missing file is reported as such whatever the shape).
    let shape = match shape {
        Some(s) if io::is_raw(&path) && path.is_file() => Some(raw_shape(&s)?),
        _ => None,
    };
    let img = native(py, || io::read_depth(&path, scale, shape))?;
    image_out(py, img)
}

/// A depth argument of any memory layout: a float or uint16 view that is not
/// C-contiguous is copied (after its size is checked), then read as every depth
/// argument is.
fn depth_any_layout(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Arr<f32>> {
    if let Ok(a) = obj.cast::<PyUntypedArray>() {
        let kind = numpy::PyArrayDescrMethods::kind(&a.dtype());
        if a.ndim() == 2 && !a.is_c_contiguous() && matches!(kind, b'f' | b'u') {
            check_image_pixels(a.shape()[0], a.shape()[1], name)?;
            let copy = obj
                .py()
                .import("numpy")?
                .call_method1("ascontiguousarray", (obj,))?;
            return depth_array(&copy, name);
        }
    }
    depth_array(obj, name)
}

#[pyfunction]
#[pyo3(signature = (path, depth, scale=Real::new(0.001)),
       text_signature = "(path, depth, scale=0.001)")]
fn write_depth(
    py: Python<'_>,
    path: PathArg,
    depth: &Bound<'_, PyAny>,
    scale: Real,
) -> PyResult<()> {
    let path = self::path(&path, "path")?;
    io::check_depth_suffix(&path)?;
    let scale = scale.get("scale")?;
    io::check_depth_scale(scale)?;
    let d = depth_any_layout(depth, "depth")?;
    let img = Image {
        height: d.shape[0],
        width: d.shape[1],
        data: d.data,
    };
    native(py, || io::write_depth(&path, &img, scale))
}

#[pyfunction]
fn read_image(py: Python<'_>, path: PathArg) -> PyResult<F32Array<'_>> {
    let path = self::path(&path, "path")?;
    let img = native(py, || io::read_gray(&path))?;
    image_out(py, img)
}

#[pyfunction]
fn read_float_image(py: Python<'_>, path: PathArg) -> PyResult<F32Array<'_>> {
    let path = self::path(&path, "path")?;
    let img = native(py, || io::read_float(&path))?;
    image_out(py, img)
}

#[pyfunction]
fn read_pfm(py: Python<'_>, path: PathArg) -> PyResult<F32Array<'_>> {
    let path = self::path(&path, "path")?;
    let img = native(py, || io::pfm::read(&path))?;
    image_out(py, img)
}

#[pyfunction]
#[pyo3(signature = (path, image, *, nan_as_inf=Flag::new(false)),
       text_signature = "(path, image, *, nan_as_inf=False)")]
fn write_pfm(
    py: Python<'_>,
    path: PathArg,
    image: &Bound<'_, PyAny>,
    nan_as_inf: Flag,
) -> PyResult<()> {
    let path = self::path(&path, "path")?;
    let nan_as_inf = nan_as_inf.get("nan_as_inf")?;
    if let Ok(a) = image.cast::<PyUntypedArray>() {
        if a.ndim() >= 2 {
            check_image_pixels(a.shape()[0], a.shape()[1], "image")?;
        }
    }
    let a = f32_array(image, "image", Some(2), false)?;
    let mut img = Image {
        height: a.shape[0],
        width: a.shape[1],
        data: a.data,
    };
    if nan_as_inf {
        img.data
            .iter_mut()
            .filter(|v| v.is_nan())
            .for_each(|v| *v = f32::INFINITY);
    }
    native(py, || io::pfm::write(&path, &img))
}

/// An array read from a `.npy` as a numpy array of its dtype, shape and order (the
/// bytes are handed over, not copied).
pub(crate) fn npy_to_numpy<'py>(py: Python<'py>, a: npy::Array) -> PyResult<Bound<'py, PyAny>> {
    let bytes = PyArray1::from_vec(py, a.data);
    let flat = bytes.call_method1("view", (a.dtype.descr(),))?;
    let kwargs = PyDict::new(py);
    kwargs.set_item("order", if a.fortran { "F" } else { "C" })?;
    flat.call_method("reshape", (PyTuple::new(py, &a.shape)?,), Some(&kwargs))
}

/// The arrays of a `.npz` file, by key, as numpy arrays.
pub(crate) fn read_npz_dict<'py>(
    py: Python<'py>,
    path: PathBuf,
    what: &str,
    keys: Option<Vec<String>>,
) -> PyResult<Bound<'py, PyDict>> {
    let arrays = native(py, || npz::read(&path, what, keys.as_deref()))?;
    let out = PyDict::new(py);
    for (key, a) in arrays {
        out.set_item(key, npy_to_numpy(py, a)?)?;
    }
    Ok(out)
}

#[pyfunction]
#[pyo3(signature = (path, what=None, keys=None),
       text_signature = "(path, what='a .npz archive', keys=None)")]
fn read_npz<'py>(
    py: Python<'py>,
    path: PathArg,
    what: Option<Text>,
    keys: Option<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let path = self::path(&path, "path")?;
    let what = match &what {
        Some(w) => w.get("what")?,
        None => "a .npz archive",
    };
    let keys = match keys {
        None => None,
        Some(k) => Some(
            k.extract::<Vec<String>>()
                .map_err(|_| wrong_type("keys", "a list of strings", &type_name(&k)))?,
        ),
    };
    read_npz_dict(py, path, what, keys)
}

/// An array argument as a `.npy` holds it: its dtype (a plain one), shape and bytes
/// in C order.
fn numpy_to_npy(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<npy::Array> {
    let np = obj.py().import("numpy")?;
    // asarray, not ascontiguousarray, which turns a 0-d array into a 1-d one.
    let kwargs = PyDict::new(obj.py());
    kwargs.set_item("order", "C")?;
    let a = np
        .call_method("asarray", (obj,), Some(&kwargs))
        .map_err(|_| invalid(name, "not a rectangular array"))?;
    let descr: String = a.getattr("dtype")?.getattr("str")?.extract()?;
    let dtype = npy::Dtype::parse(&descr).map_err(|m| invalid(name, m))?;
    if dtype.kind == npy::Kind::Object {
        return Err(wrong_type(
            name,
            "an array of plain values",
            "an object array",
        ));
    }
    let shape: Vec<usize> = a.getattr("shape")?.extract()?;
    let data: Vec<u8> = a.call_method0("tobytes")?.extract()?;
    Ok(npy::Array {
        dtype,
        shape,
        fortran: false,
        data,
    })
}

#[pyfunction]
#[pyo3(signature = (path, **arrays))]
fn write_npz(py: Python<'_>, path: PathArg, arrays: Option<&Bound<'_, PyDict>>) -> PyResult<()> {
    let path = self::path(&path, "path")?;
    let mut entries = Vec::new();
    for (key, value) in arrays.into_iter().flatten() {
        let key: String = key.extract()?;
        let a = numpy_to_npy(&value, &key)?;
        entries.push((key, a));
    }
    let refs: Vec<(&str, &npy::Array)> = entries.iter().map(|(k, a)| (k.as_str(), a)).collect();
    native(py, || npz::write(&path, &refs))
}

#[pyfunction]
#[pyo3(signature = (path, depth, scale=Real::new(0.001)),
       text_signature = "(path, depth, scale=0.001)")]
fn write_depth_png(
    py: Python<'_>,
    path: PathArg,
    depth: &Bound<'_, PyAny>,
    scale: Real,
) -> PyResult<()> {
    let (path, scale) = (path.get("path")?, scale.get("scale")?);
    io::check_depth_scale(scale)?;
    let d: Arr<f32> = depth_array(depth, "depth")?;
    native(py, || {
        io::write_depth_png(&path, &d.data, d.shape[0], d.shape[1], scale)
    })
}

/// A depth argument checked and converted as every depthpose function takes it:
/// (H, W) float32 metres (uint16 millimetres converted).
#[pyfunction]
#[pyo3(signature = (depth, name=None))]
fn depth_metres<'py>(
    py: Python<'py>,
    depth: &Bound<'py, PyAny>,
    name: Option<Text>,
) -> PyResult<F32Array<'py>> {
    let name = match &name {
        Some(n) => n.get("name")?,
        None => "depth",
    };
    let d = depth_array(depth, name)?;
    to_numpy(py, d.data, &d.shape)
}

/// Writes an (H, W, 3) picture (integers in 0..=255) as PNG.
#[pyfunction]
fn write_rgb_png(py: Python<'_>, path: PathArg, rgb: &Bound<'_, PyAny>) -> PyResult<()> {
    let path = path.get("path")?;
    let a = rgb_u8(rgb, "rgb")?;
    native(py, || {
        io::write_rgb_png(&path, &a.data, a.shape[0], a.shape[1])
    })
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(read_depth, m)?)?;
    m.add_function(wrap_pyfunction!(write_depth, m)?)?;
    m.add_function(wrap_pyfunction!(read_image, m)?)?;
    m.add_function(wrap_pyfunction!(read_float_image, m)?)?;
    m.add_function(wrap_pyfunction!(read_pfm, m)?)?;
    m.add_function(wrap_pyfunction!(write_pfm, m)?)?;
    m.add_function(wrap_pyfunction!(read_npz, m)?)?;
    m.add_function(wrap_pyfunction!(write_npz, m)?)?;
    m.add_function(wrap_pyfunction!(write_depth_png, m)?)?;
    m.add_function(wrap_pyfunction!(write_rgb_png, m)?)?;
    m.add_function(wrap_pyfunction!(depth_metres, m)?)?;
    m.add("MIN_DEPTH_SCALE", io::MIN_DEPTH_SCALE)?;
    m.add("MAX_DEPTH_SCALE", io::MAX_DEPTH_SCALE)?;
    m.add("KINECT_SHAPE", io::raw::KINECT_SHAPE)?;
    Ok(())
}
