//! `Camera` for Python.

use super::native;
use crate::camera::Camera;
use pyo3::prelude::*;

#[pyclass(name = "Camera", module = "depthpose._core", frozen, eq)]
#[derive(Clone, PartialEq)]
pub struct PyCamera {
    pub inner: Camera,
}

#[pymethods]
impl PyCamera {
    #[new]
    #[pyo3(signature = (fx, fy, cx, cy, width, height))]
    fn new(fx: f64, fy: f64, cx: f64, cy: f64, width: i128, height: i128) -> PyResult<Self> {
        let size = |v: i128, n: &str| super::arrays::count_at_least(v, 1, n);
        Ok(PyCamera {
            inner: Camera::new(
                fx,
                fy,
                cx,
                cy,
                size(width, "width")?,
                size(height, "height")?,
            )?,
        })
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
    fn from_intrinsics(intrinsics: Vec<f64>, shape: (i128, i128)) -> PyResult<Self> {
        if intrinsics.len() != 4 {
            return Err(crate::Error::invalid(
                "intrinsics",
                format!("need [fx, fy, cx, cy], got {} values", intrinsics.len()),
            )
            .into());
        }
        Self::new(
            intrinsics[0],
            intrinsics[1],
            intrinsics[2],
            intrinsics[3],
            shape.1,
            shape.0,
        )
    }

    /// The same camera for an image resampled by `factor`.
    fn scaled(&self, factor: f64) -> PyResult<Self> {
        Ok(PyCamera {
            inner: self.inner.scaled(factor)?,
        })
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

    /// Pixel coordinates (N, 2) [u, v] of camera-frame points (N, 3); NaN behind the camera.
    fn project<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, numpy::PyArrayDyn<f64>>> {
        let p = super::arrays::f64_array(points, "points", Some(2), true)?;
        if p.shape[1] != 3 {
            return Err(crate::Error::invalid(
                "points",
                format!("expected shape (N, 3), got {:?}", p.shape),
            )
            .into());
        }
        let cam = self.inner;
        let out: Vec<f64> = native(py, || {
            p.data
                .chunks_exact(3)
                .flat_map(
                    |q| match cam.project(&nalgebra::Vector3::new(q[0], q[1], q[2])) {
                        Some((u, v)) => [u, v],
                        None => [f64::NAN, f64::NAN],
                    },
                )
                .collect()
        });
        Ok(super::arrays::to_numpy(py, out, &[p.shape[0], 2]))
    }

    /// Camera-frame points (N, 3) of pixels (N, 2) [u, v] at depths (N,).
    fn back_project<'py>(
        &self,
        py: Python<'py>,
        pixels: &Bound<'py, PyAny>,
        depth: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, numpy::PyArrayDyn<f64>>> {
        let uv = super::arrays::f64_array(pixels, "pixels", Some(2), true)?;
        let z = super::arrays::f64_array(depth, "depth", Some(1), true)?;
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
        let out: Vec<f64> = native(py, || {
            uv.data
                .chunks_exact(2)
                .zip(&z.data)
                .flat_map(|(q, &d)| {
                    let p = cam.back_project(q[0], q[1], d);
                    [p.x, p.y, p.z]
                })
                .collect()
        });
        Ok(super::arrays::to_numpy(py, out, &[z.shape[0], 3]))
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
