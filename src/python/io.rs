//! Image reading and writing for Python (`depthpose.io` wraps these).

use super::arrays::{depth_array, to_numpy, Arr};
use super::native;
use crate::io;
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use std::path::PathBuf;

type F32Array<'py> = Bound<'py, PyArrayDyn<f32>>;

fn image_out<'py>(py: Python<'py>, img: io::Image) -> F32Array<'py> {
    to_numpy(py, img.data, &[img.height, img.width])
}

/// A 16-bit PNG/TIFF depth image (units of `scale` metres) or float TIFF, as float32 metres.
#[pyfunction]
#[pyo3(signature = (path, scale=0.001))]
fn read_depth_image(py: Python<'_>, path: PathBuf, scale: f64) -> PyResult<F32Array<'_>> {
    let img = native(py, || io::read_depth(&path, scale))?;
    Ok(image_out(py, img))
}

/// Any PNG/TIFF/JPEG as gray float32 (integer types scaled to [0, 1]).
#[pyfunction]
fn read_gray_image(py: Python<'_>, path: PathBuf) -> PyResult<F32Array<'_>> {
    let img = native(py, || io::read_gray(&path))?;
    Ok(image_out(py, img))
}

/// A float TIFF (first channel) as stored.
#[pyfunction]
fn read_float_image(py: Python<'_>, path: PathBuf) -> PyResult<F32Array<'_>> {
    let img = native(py, || io::read_float(&path))?;
    Ok(image_out(py, img))
}

/// Writes depth (H, W) metres as a 16-bit PNG in units of `scale` metres.
#[pyfunction]
#[pyo3(signature = (path, depth, scale=0.001))]
fn write_depth_png(
    py: Python<'_>,
    path: PathBuf,
    depth: &Bound<'_, PyAny>,
    scale: f64,
) -> PyResult<()> {
    let d: Arr<f32> = depth_array(depth, "depth")?;
    native(py, || {
        io::write_depth_png(&path, &d.data, d.shape[0], d.shape[1], scale)
    })?;
    Ok(())
}

/// Writes an (H, W, 3) uint8 picture as PNG.
#[pyfunction]
fn write_rgb_png(py: Python<'_>, path: PathBuf, rgb: &Bound<'_, PyAny>) -> PyResult<()> {
    let a = super::arrays::i64_array(rgb, "rgb", Some(3))?;
    if a.shape[2] != 3 || a.data.iter().any(|&v| !(0..=255).contains(&v)) {
        return Err(crate::Error::invalid(
            "rgb",
            format!(
                "expected (H, W, 3) values in 0..=255, got shape {:?}",
                a.shape
            ),
        )
        .into());
    }
    let bytes: Vec<u8> = a.data.iter().map(|&v| v as u8).collect();
    native(py, || {
        io::write_rgb_png(&path, &bytes, a.shape[0], a.shape[1])
    })?;
    Ok(())
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(read_depth_image, m)?)?;
    m.add_function(wrap_pyfunction!(read_gray_image, m)?)?;
    m.add_function(wrap_pyfunction!(read_float_image, m)?)?;
    m.add_function(wrap_pyfunction!(write_depth_png, m)?)?;
    m.add_function(wrap_pyfunction!(write_rgb_png, m)?)?;
    Ok(())
}
