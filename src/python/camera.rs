//! `Camera` for Python.

use super::convert::{f64_array, ints, invalid, reals, to_numpy, Int, Real, Text};
use super::native_ok;
use crate::camera::{Camera, PRESETS};
use crate::error::brief;
use pyo3::prelude::*;

/// Smallest focal length accepted, in pixels (a camera with a focal length of a
/// thousandth of a pixel would see all of space in one pixel).
const MIN_FOCAL: f64 = 1e-3;
/// Largest focal length accepted, in pixels.
const MAX_FOCAL: f64 = 1e7;

/// Refuses a focal length outside [`MIN_FOCAL`, `MAX_FOCAL`] (denormal or absurd
/// intrinsics that would turn every back-projection into garbage).
fn check_focal(camera: &Camera) -> PyResult<()> {
    for (name, f) in [("fx", camera.fx), ("fy", camera.fy)] {
        if !(MIN_FOCAL..=MAX_FOCAL).contains(&f) {
            return Err(invalid(
                name,
                format!(
                    "focal length must be in [{}, {}] pixels, got {}",
                    brief(MIN_FOCAL),
                    brief(MAX_FOCAL),
                    brief(f)
                ),
            ));
        }
    }
    Ok(())
}

#[pyclass(name = "Camera", module = "depthpose._core", frozen, eq)]
#[derive(Clone, PartialEq)]
pub struct PyCamera {
    pub inner: Camera,
}

impl PyCamera {
    /// A camera from [fx, fy, cx, cy] and the image shape (height, width), checked as
    /// `Camera.from_intrinsics` checks it.
    pub(crate) fn from_values(k: [f64; 4], (height, width): (usize, usize)) -> PyResult<Self> {
        Self::new(
            Real::new(k[0]),
            Real::new(k[1]),
            Real::new(k[2]),
            Real::new(k[3]),
            Int::new(width as i128),
            Int::new(height as i128),
        )
    }
}

#[pymethods]
impl PyCamera {
    #[new]
    #[pyo3(signature = (fx, fy, cx, cy, width, height))]
    fn new(fx: Real, fy: Real, cx: Real, cy: Real, width: Int, height: Int) -> PyResult<Self> {
        let inner = Camera::new(
            fx.get("fx")?,
            fy.get("fy")?,
            cx.get("cx")?,
            cy.get("cy")?,
            width.at_least(1, "width")?,
            height.at_least(1, "height")?,
        )?;
        check_focal(&inner)?;
        Ok(PyCamera { inner })
    }

    /// The camera of a common depth sensor by name (see `presets()`).
    #[staticmethod]
    fn preset(name: Text) -> PyResult<Self> {
        Ok(PyCamera {
            inner: Camera::preset(name.get("name")?)?,
        })
    }

    /// The names `preset` knows.
    #[staticmethod]
    fn presets() -> Vec<&'static str> {
        PRESETS.to_vec()
    }

    /// Kinect v1 depth camera, 640×480.
    #[staticmethod]
    fn kinect_v1() -> Self {
        PyCamera {
            inner: Camera::kinect_v1(),
        }
    }

    /// Kinect v1 depth camera downsampled to 320×240.
    #[staticmethod]
    fn kinect_v1_qvga() -> Self {
        PyCamera {
            inner: Camera::kinect_v1_qvga(),
        }
    }

    /// The ITOP camera (320×240, f = 285.71), also that of the shared synthetic data.
    #[staticmethod]
    fn itop() -> Self {
        PyCamera {
            inner: Camera::itop(),
        }
    }

    /// A camera from [fx, fy, cx, cy] and an image shape (height, width).
    #[staticmethod]
    fn from_intrinsics(intrinsics: &Bound<PyAny>, shape: &Bound<PyAny>) -> PyResult<Self> {
        let k = reals(intrinsics, "intrinsics", Some(4))?;
        let [h, w] = ints::<2>(shape, "shape", "(height, width)")?;
        let (h, w) = (h.at_least(1, "shape")?, w.at_least(1, "shape")?);
        Self::new(
            Real::new(k[0]),
            Real::new(k[1]),
            Real::new(k[2]),
            Real::new(k[3]),
            Int::new(w as i128),
            Int::new(h as i128),
        )
    }

    /// The same camera for an image resampled by `factor`.
    fn scaled(&self, factor: Real) -> PyResult<Self> {
        let factor = factor.get("factor")?;
        let inner = self.inner.scaled(factor)?;
        if check_focal(&inner).is_err() {
            return Err(invalid(
                "factor",
                format!(
                    "{} scales the focal lengths to {} and {}, outside [{}, {}] pixels",
                    brief(factor),
                    brief(inner.fx),
                    brief(inner.fy),
                    brief(MIN_FOCAL),
                    brief(MAX_FOCAL)
                ),
            ));
        }
        Ok(PyCamera { inner })
    }

    #[getter]
    fn fx(&self) -> f64 {
        self.inner.fx
    }
    #[getter]
    fn fy(&self) -> f64 {
        self.inner.fy
    }
    #[getter]
    fn cx(&self) -> f64 {
        self.inner.cx
    }
    #[getter]
    fn cy(&self) -> f64 {
        self.inner.cy
    }
    #[getter]
    fn width(&self) -> usize {
        self.inner.width
    }
    #[getter]
    fn height(&self) -> usize {
        self.inner.height
    }
    /// (height, width), the shape of this camera's images.
    #[getter]
    fn shape(&self) -> (usize, usize) {
        (self.inner.height, self.inner.width)
    }
    /// [fx, fy, cx, cy].
    #[getter]
    fn intrinsics(&self) -> [f64; 4] {
        [self.inner.fx, self.inner.fy, self.inner.cx, self.inner.cy]
    }

    /// Pixel coordinates (N, 2) [u, v] of camera-frame points (N, 3); NaN behind the
    /// camera (or too near its plane to project within the float range).
    fn project<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, numpy::PyArrayDyn<f64>>> {
        let p = f64_array(points, "points", Some(2), true)?;
        if p.shape[1] != 3 {
            return Err(crate::Error::invalid(
                "points",
                format!("expected shape (N, 3), got {:?}", p.shape),
            )
            .into());
        }
        let cam = self.inner;
        let out: Vec<f64> = native_ok(py, || {
            p.data
                .chunks_exact(3)
                .flat_map(
                    |q| match cam.project(&nalgebra::Vector3::new(q[0], q[1], q[2])) {
                        // A point so near the camera plane that it projects beyond the
                        // float range is in no image either.
                        Some((u, v)) if u.is_finite() && v.is_finite() => [u, v],
                        _ => [f64::NAN, f64::NAN],
                    },
                )
                .collect()
        })?;
        to_numpy(py, out, &[p.shape[0], 2])
    }

    /// Camera-frame points (N, 3) of pixels (N, 2) [u, v] at depths (N,).
    fn back_project<'py>(
        &self,
        py: Python<'py>,
        pixels: &Bound<'py, PyAny>,
        depth: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, numpy::PyArrayDyn<f64>>> {
        let uv = f64_array(pixels, "pixels", Some(2), true)?;
        let z = f64_array(depth, "depth", Some(1), true)?;
        if uv.shape[1] != 2 || uv.shape[0] != z.shape[0] {
            return Err(crate::Error::invalid(
                "pixels",
                format!(
                    "expected shape (N, 2) with N = len(depth) = {}, got {:?}",
                    z.shape[0], uv.shape
                ),
            )
            .into());
        }
        let cam = self.inner;
        let out: Vec<f64> = native_ok(py, || {
            uv.data
                .chunks_exact(2)
                .zip(&z.data)
                .flat_map(|(q, &d)| {
                    let p = cam.back_project(q[0], q[1], d);
                    [p.x, p.y, p.z]
                })
                .collect()
        })?;
        if let Some(k) = out.iter().position(|v| !v.is_finite()) {
            return Err(invalid(
                "depth",
                format!(
                    "the point of pixel {} at depth {} is beyond the float64 range",
                    k / 3,
                    brief(z.data[k / 3])
                ),
            ));
        }
        to_numpy(py, out, &[z.shape[0], 3])
    }

    fn __repr__(&self) -> String {
        let c = &self.inner;
        format!(
            "Camera(fx={}, fy={}, cx={}, cy={}, width={}, height={})",
            c.fx, c.fy, c.cx, c.cy, c.width, c.height
        )
    }

    fn __getnewargs__(&self) -> (f64, f64, f64, f64, usize, usize) {
        let c = &self.inner;
        (c.fx, c.fy, c.cx, c.cy, c.width, c.height)
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyCamera>()
}
