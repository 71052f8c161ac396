//! `PoseEstimator`: the pose of a depth frame from scratch, one native call per frame
//! with the GIL released.

use super::super::body::PyBodyModel;
use super::super::camera::PyCamera;
use super::super::convert::{invalid, to_numpy};
use super::super::native;
use super::args::{estimator_of, pose_rows, EstimatorArgs, FrameArgs};
use super::config::PyPipelineConfig;
use super::result::PyPoseResult;
use super::F64Array;
use crate::body::Pose;
use crate::pipeline::Estimator;
use numpy::PyArrayDyn;
use pyo3::prelude::*;

/// Pose from scratch, one depth frame at a time.
#[pyclass(name = "PoseEstimator", module = "depthpose._core", frozen)]
pub struct PyPoseEstimator {
    inner: Estimator,
}

impl PyPoseEstimator {
    /// The depth discrepancy of each of `poses` on a frame.
    fn discrepancies_of(
        &self,
        py: Python<'_>,
        poses: &[Pose],
        depth: &Bound<'_, PyAny>,
        mask: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Vec<f64>> {
        let a = FrameArgs::of(self.inner.camera(), depth, mask)?;
        native(py, || -> crate::Result<Vec<f64>> {
            let frame = self.inner.prepare(&a.depth, a.mask.as_deref(), None)?;
            self.inner.discrepancies(&frame, poses)
        })
    }
}

#[pymethods]
impl PyPoseEstimator {
    #[new]
    #[pyo3(signature = (camera, *, model=None, templates=None, config=None, background=None))]
    fn new(
        camera: &Bound<'_, PyAny>,
        model: Option<&Bound<'_, PyAny>>,
        templates: Option<&Bound<'_, PyAny>>,
        config: Option<&Bound<'_, PyAny>>,
        background: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let args = EstimatorArgs {
            camera,
            model,
            templates,
            config,
        };
        Ok(PyPoseEstimator {
            inner: estimator_of(&args, background)?,
        })
    }

    #[pyo3(signature = (depth, mask=None))]
    fn estimate(
        &self,
        py: Python<'_>,
        depth: &Bound<'_, PyAny>,
        mask: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyPoseResult> {
        let a = FrameArgs::of(self.inner.camera(), depth, mask)?;
        let r = native(py, || self.inner.estimate(&a.depth, a.mask.as_deref()))?;
        Ok(PyPoseResult {
            inner: r,
            shape: a.shape,
        })
    }

    fn person_mask<'py>(
        &self,
        py: Python<'py>,
        depth: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArrayDyn<bool>>> {
        let a = FrameArgs::of(self.inner.camera(), depth, None)?;
        let m = native(py, || -> crate::Result<Vec<bool>> {
            let frame = self.inner.prepare(&a.depth, None, None)?;
            Ok(self.inner.resolution().upsample(&frame.mask, false))
        })?;
        to_numpy(py, m, &a.shape)
    }

    #[pyo3(signature = (poses, depth, mask=None))]
    fn discrepancies<'py>(
        &self,
        py: Python<'py>,
        poses: &Bound<'py, PyAny>,
        depth: &Bound<'py, PyAny>,
        mask: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<F64Array<'py>> {
        let poses = pose_rows(poses, "poses")?;
        let v = self.discrepancies_of(py, &poses, depth, mask)?;
        let n = v.len();
        to_numpy(py, v, &[n])
    }

    #[pyo3(signature = (pose, depth, mask=None))]
    fn discrepancy(
        &self,
        py: Python<'_>,
        pose: &Bound<'_, PyAny>,
        depth: &Bound<'_, PyAny>,
        mask: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<f64> {
        let poses = pose_rows(pose, "pose")?;
        if poses.len() != 1 {
            return Err(invalid(
                "pose",
                format!("expected one pose (22 values), got {}", poses.len()),
            ));
        }
        Ok(self.discrepancies_of(py, &poses, depth, mask)?[0])
    }

    fn penalty<'py>(&self, py: Python<'py>, poses: &Bound<'py, PyAny>) -> PyResult<F64Array<'py>> {
        let poses = pose_rows(poses, "poses")?;
        let v: Vec<f64> = poses.iter().map(|p| self.inner.penalty(p)).collect();
        let n = v.len();
        to_numpy(py, v, &[n])
    }

    #[getter]
    fn camera(&self) -> PyCamera {
        PyCamera {
            inner: *self.inner.camera(),
        }
    }
    #[getter]
    fn working_camera(&self) -> PyCamera {
        PyCamera {
            inner: self.inner.resolution().working,
        }
    }
    #[getter]
    fn model(&self) -> PyBodyModel {
        PyBodyModel {
            inner: self.inner.model().clone(),
        }
    }
    #[getter]
    fn config(&self) -> PyPipelineConfig {
        PyPipelineConfig {
            inner: self.inner.config().clone(),
        }
    }
}
