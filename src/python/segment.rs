//! Person segmentation for Python: `segment_person` and its `Segmentation` result.

use super::convert::{camera as camera_arg, depth_array, object, to_numpy};
use super::native;
use crate::cloud::DepthView;
use crate::segment::{
    segment_person as segment, Cluster, Plane, SegmentConfig, SegmentHint, Segmentation,
};
use numpy::PyArrayDyn;
use pyo3::prelude::*;

/// A support plane `normal · X = offset` (camera frame, metres).
#[pyclass(name = "Plane", module = "depthpose._core", frozen)]
#[derive(Clone)]
pub struct PyPlane {
    inner: Plane,
}

#[pymethods]
impl PyPlane {
    #[getter]
    fn normal(&self) -> [f64; 3] {
        self.inner.normal
    }
    #[getter]
    fn offset(&self) -> f64 {
        self.inner.offset
    }
    #[getter]
    fn inliers(&self) -> usize {
        self.inner.inliers
    }
    #[getter]
    fn area(&self) -> f64 {
        self.inner.area
    }
    fn __repr__(&self) -> String {
        let n = self.inner.normal;
        format!(
            "Plane(normal=({:.3}, {:.3}, {:.3}), offset={:.3}, area={:.2})",
            n[0], n[1], n[2], self.inner.offset, self.inner.area
        )
    }
}

impl From<Plane> for PyPlane {
    fn from(inner: Plane) -> Self {
        PyPlane { inner }
    }
}

/// A depth-continuous cluster of pixels, measured in metres.
#[pyclass(name = "Cluster", module = "depthpose._core", frozen)]
#[derive(Clone)]
pub struct PyCluster {
    inner: Cluster,
}

#[pymethods]
impl PyCluster {
    #[getter]
    fn pixels(&self) -> usize {
        self.inner.pixels
    }
    #[getter]
    fn area(&self) -> f32 {
        self.inner.area
    }
    #[getter]
    fn height(&self) -> f32 {
        self.inner.height
    }
    #[getter]
    fn width(&self) -> f32 {
        self.inner.width
    }
    #[getter]
    fn centroid(&self) -> [f32; 3] {
        self.inner.centroid
    }
    #[getter]
    fn median_depth(&self) -> f32 {
        self.inner.median_depth
    }
    #[getter]
    fn bbox(&self) -> [usize; 4] {
        self.inner.bbox
    }
    #[getter]
    fn person_like(&self) -> bool {
        self.inner.person_like
    }
    #[getter]
    fn score(&self) -> f32 {
        self.inner.score
    }
    fn __repr__(&self) -> String {
        let c = &self.inner;
        format!(
            "Cluster(pixels={}, area={:.2}, height={:.2}, width={:.2}, depth={:.2})",
            c.pixels, c.area, c.height, c.width, c.median_depth
        )
    }
}

impl From<Cluster> for PyCluster {
    fn from(inner: Cluster) -> Self {
        PyCluster { inner }
    }
}

/// The person's pixels and how they were found.
#[pyclass(name = "Segmentation", module = "depthpose._core", frozen)]
pub struct PySegmentation {
    pub inner: Segmentation,
    shape: [usize; 2],
}

#[pymethods]
impl PySegmentation {
    #[getter]
    fn mask<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<bool>>> {
        to_numpy(py, self.inner.mask.clone(), &self.shape)
    }
    #[getter]
    fn method(&self) -> &'static str {
        self.inner.method.name()
    }
    #[getter]
    fn planes(&self) -> Vec<PyPlane> {
        self.inner
            .planes
            .iter()
            .map(|&inner| PyPlane { inner })
            .collect()
    }
    #[getter]
    fn person(&self) -> PyCluster {
        PyCluster {
            inner: self.inner.person,
        }
    }
    #[getter]
    fn others(&self) -> Vec<PyCluster> {
        self.inner
            .others
            .iter()
            .map(|&inner| PyCluster { inner })
            .collect()
    }
    fn __repr__(&self) -> String {
        format!(
            "Segmentation(method={:?}, person={} pixels, planes={}, others={})",
            self.inner.method.name(),
            self.inner.person.pixels,
            self.inner.planes.len(),
            self.inner.others.len()
        )
    }
}

/// The person's pixels of a depth image. See `depthpose.segment_person`.
#[pyfunction]
#[pyo3(signature = (depth, camera, background=None, *, previous=None))]
fn segment_person<'py>(
    py: Python<'py>,
    depth: &Bound<'py, PyAny>,
    camera: &Bound<'py, PyAny>,
    background: Option<&Bound<'py, PyAny>>,
    previous: Option<&Bound<'py, PyAny>>,
) -> PyResult<PySegmentation> {
    let camera = camera_arg(camera, "camera")?;
    let hint: Option<SegmentHint> = match previous {
        Some(p) => Some(
            object::<PySegmentation>(p, "previous", "a Segmentation or None")?
                .inner
                .hint(),
        ),
        None => None,
    };
    let d = depth_array(depth, "depth")?;
    let bg = background
        .map(|b| depth_array(b, "background"))
        .transpose()?;
    let seg = native(py, || -> PyResult<Segmentation> {
        let view = DepthView::new(&d.data, d.shape[0], d.shape[1], "depth")?;
        let bgv = match &bg {
            Some(b) => Some(DepthView::new(
                &b.data,
                b.shape[0],
                b.shape[1],
                "background",
            )?),
            None => None,
        };
        Ok(segment(
            &view,
            &camera,
            bgv.as_ref(),
            &SegmentConfig::default(),
            hint.as_ref(),
        )?)
    })?;
    Ok(PySegmentation {
        inner: seg,
        shape: [d.shape[0], d.shape[1]],
    })
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyPlane>()?;
    m.add_class::<PyCluster>()?;
    m.add_class::<PySegmentation>()?;
    m.add_function(wrap_pyfunction!(segment_person, m)?)?;
    Ok(())
}
