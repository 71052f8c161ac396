//! `PoseResult`: the pose of one frame, its joints, labels, mask and timings.

use super::super::body::PyBodyModel;
use super::super::convert::{joints_to_numpy, to_numpy};
use super::super::segment::{PyCluster, PyPlane};
use super::F64Array;
use crate::body::{BodyModel, JOINT_NAMES, NUM_JOINTS, NUM_PARAMS};
use crate::pipeline::PoseResult;
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// The pose of one frame.
#[pyclass(name = "PoseResult", module = "depthpose._core", frozen)]
pub struct PyPoseResult {
    pub(in crate::python) inner: PoseResult,
    pub(in crate::python) shape: [usize; 2],
}

#[pymethods]
impl PyPoseResult {
    /// The 22 pose parameters.
    #[getter]
    fn pose<'py>(&self, py: Python<'py>) -> PyResult<F64Array<'py>> {
        to_numpy(py, self.inner.pose.to_vec(), &[NUM_PARAMS])
    }
    /// The 15 joints (15, 3), camera frame, metres.
    #[getter]
    fn joints<'py>(&self, py: Python<'py>) -> PyResult<F64Array<'py>> {
        joints_to_numpy(py, &self.inner.joints, &[NUM_JOINTS, 3])
    }
    #[getter]
    fn joint_names(&self) -> Vec<&'static str> {
        JOINT_NAMES.to_vec()
    }
    /// The body model the pose was fitted with (its shape).
    #[getter]
    fn model(&self) -> PyBodyModel {
        PyBodyModel {
            inner: BodyModel::with_shape(self.inner.shape),
        }
    }
    /// The shape parameters of that model (`BodyModel.shape_names` order).
    #[getter]
    fn shape<'py>(&self, py: Python<'py>) -> PyResult<F64Array<'py>> {
        let v = self.inner.shape.to_vec().to_vec();
        let n = v.len();
        to_numpy(py, v, &[n])
    }
    #[getter]
    fn labels<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<i16>>> {
        to_numpy(py, self.inner.labels.clone(), &self.shape)
    }
    #[getter]
    fn mask<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<bool>>> {
        to_numpy(py, self.inner.mask.clone(), &self.shape)
    }
    #[getter]
    fn energy(&self) -> f64 {
        self.inner.energy
    }
    #[getter]
    fn iterations(&self) -> usize {
        self.inner.iterations
    }
    #[getter]
    fn converged(&self) -> bool {
        self.inner.converged
    }
    #[getter]
    fn confidence<'py>(&self, py: Python<'py>) -> PyResult<F64Array<'py>> {
        to_numpy(py, self.inner.confidence.to_vec(), &[NUM_JOINTS])
    }
    /// Milliseconds per stage, and `total` for the whole call.
    #[getter]
    fn timings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in &self.inner.timings.stages {
            d.set_item(k, v)?;
        }
        d.set_item("total", self.inner.timings.total)?;
        Ok(d)
    }
    #[getter]
    fn source(&self) -> &'static str {
        self.inner.source.name()
    }
    #[getter]
    fn discrepancy(&self) -> f64 {
        self.inner.discrepancy
    }
    /// How the person was found: "background", "planes", "learned" (a tracker's learned
    /// background), or None for a given mask.
    #[getter]
    fn segmentation_method(&self) -> Option<&'static str> {
        self.inner.segmentation.as_ref().map(|s| s.method.name())
    }
    /// The support planes removed to find the person.
    #[getter]
    fn planes(&self) -> Vec<PyPlane> {
        self.inner
            .segmentation
            .as_ref()
            .map(|s| s.planes.iter().map(|&p| PyPlane::from(p)).collect())
            .unwrap_or_default()
    }
    /// Other person-like objects seen.
    #[getter]
    fn others(&self) -> Vec<PyCluster> {
        self.inner
            .segmentation
            .as_ref()
            .map(|s| s.others.iter().map(|&c| PyCluster::from(c)).collect())
            .unwrap_or_default()
    }

    /// JSON-ready (labels and mask left out; they are images).
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let r = &self.inner;
        let d = PyDict::new(py);
        d.set_item("pose", r.pose.to_vec())?;
        let joints: Vec<[f64; 3]> = r.joints.iter().map(|j| [j.x, j.y, j.z]).collect();
        d.set_item("joints", joints)?;
        d.set_item("joint_names", JOINT_NAMES.to_vec())?;
        d.set_item("shape", r.shape.to_vec().to_vec())?;
        d.set_item("energy", r.energy)?;
        d.set_item("iterations", r.iterations)?;
        d.set_item("converged", r.converged)?;
        d.set_item("confidence", r.confidence.to_vec())?;
        d.set_item("timings", self.timings(py)?)?;
        d.set_item("source", r.source.name())?;
        d.set_item(
            "discrepancy",
            r.discrepancy.is_finite().then_some(r.discrepancy),
        )?;
        d.set_item("segmentation", self.segmentation_method())?;
        Ok(d)
    }

    /// `to_dict` as a JSON string.
    fn to_json(&self, py: Python<'_>) -> PyResult<String> {
        let json = py.import("json")?;
        json.call_method1("dumps", (self.to_dict(py)?,))?.extract()
    }

    fn __repr__(&self) -> String {
        format!(
            "PoseResult(source={:?}, discrepancy={:.3}, iterations={}, total={:.1} ms)",
            self.inner.source.name(),
            self.inner.discrepancy,
            self.inner.iterations,
            self.inner.timings.total
        )
    }
}
