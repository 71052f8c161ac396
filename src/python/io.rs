//! Image reading and writing for Python (`depthpose.io` wraps these).

use super::convert::{depth_array, rgb_u8, to_numpy, Arr, PathArg, Real, Text};
use super::native;
use crate::io;
use numpy::PyArrayDyn;
use pyo3::prelude::*;

type F32Array<'py> = Bound<'py, PyArrayDyn<f32>>;

fn image_out<'py>(py: Python<'py>, img: io::Image) -> PyResult<F32Array<'py>> {
    to_numpy(py, img.data, &[img.height, img.width])
}

/// A 16-bit PNG/TIFF depth image (units of `scale` metres) or float TIFF, as float32 metres.
#[pyfunction]
#[pyo3(signature = (path, scale=Real::new(0.001)), text_signature = "(path, scale=0.001)")]
fn read_depth_image(py: Python<'_>, path: PathArg, scale: Real) -> PyResult<F32Array<'_>> {
    let (path, scale) = (path.get("path")?, scale.get("scale")?);
    let img = native(py, || io::read_depth(&path, scale))?;
    image_out(py, img)
}

/// Any PNG/TIFF/JPEG as gray float32 (integer types scaled to [0, 1]).
#[pyfunction]
fn read_gray_image(py: Python<'_>, path: PathArg) -> PyResult<F32Array<'_>> {
    let path = path.get("path")?;
    let img = native(py, || io::read_gray(&path))?;
    image_out(py, img)
}

/// A float TIFF (first channel) as stored.
#[pyfunction]
fn read_float_image(py: Python<'_>, path: PathArg) -> PyResult<F32Array<'_>> {
    let path = path.get("path")?;
    let img = native(py, || io::read_float(&path))?;
    image_out(py, img)
}

/// Writes depth (H, W) metres (or uint16 millimetres) as a 16-bit PNG in units of
/// `scale` metres; refuses a depth the PNG cannot store.
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
    m.add_function(wrap_pyfunction!(read_depth_image, m)?)?;
    m.add_function(wrap_pyfunction!(read_gray_image, m)?)?;
    m.add_function(wrap_pyfunction!(read_float_image, m)?)?;
    m.add_function(wrap_pyfunction!(write_depth_png, m)?)?;
    m.add_function(wrap_pyfunction!(write_rgb_png, m)?)?;
    m.add_function(wrap_pyfunction!(depth_metres, m)?)?;
    m.add("MIN_DEPTH_SCALE", io::MIN_DEPTH_SCALE)?;
    m.add("MAX_DEPTH_SCALE", io::MAX_DEPTH_SCALE)?;
    Ok(())
}
