//! `PoseTracker`: the pose through a depth video, one native call per frame with the
//! GIL released.

use super::super::body::PyShapeFitResult;
use super::super::body::{pose_arg, PyBodyModel};
use super::super::camera::PyCamera;
use super::super::convert::{to_numpy, Flag};
use super::super::native;
use super::args::{calibrate_arg, estimator_of, EstimatorArgs, FrameArgs};
use super::config::PyPipelineConfig;
use super::result::PyPoseResult;
use super::F64Array;
use crate::pipeline::Tracker;
use pyo3::prelude::*;

/// Pose through a depth video: each update starts from the previous pose.
#[pyclass(name = "PoseTracker", module = "depthpose._core")]
pub struct PyPoseTracker {
    inner: Tracker,
}

#[pymethods]
impl PyPoseTracker {
    #[new]
    #[pyo3(signature = (camera, *, model=None, templates=None, config=None, background=None,
        calibrate=None))]
    fn new(
        camera: &Bound<'_, PyAny>,
        model: Option<&Bound<'_, PyAny>>,
        templates: Option<&Bound<'_, PyAny>>,
        config: Option<&Bound<'_, PyAny>>,
        background: Option<&Bound<'_, PyAny>>,
        calibrate: Option<Flag>,
    ) -> PyResult<Self> {
        let calibrate = calibrate_arg(calibrate.as_ref(), model)?;
        let args = EstimatorArgs {
            camera,
            model,
            templates,
            config,
        };
        Ok(PyPoseTracker {
            inner: Tracker::new(estimator_of(&args, background)?, calibrate),
        })
    }

    #[pyo3(signature = (depth, mask=None))]
    fn update(
        &mut self,
        py: Python<'_>,
        depth: &Bound<'_, PyAny>,
        mask: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyPoseResult> {
        let a = FrameArgs::of(self.inner.estimator().camera(), depth, mask)?;
        let tracker = &mut self.inner;
        let r = native(py, || tracker.update(&a.depth, a.mask.as_deref()))?;
        Ok(PyPoseResult {
            inner: r,
            shape: a.shape,
        })
    }

    #[pyo3(signature = (shape=Flag::new(false)), text_signature = "($self, shape=False)")]
    fn reset(&mut self, shape: Flag) -> PyResult<()> {
        self.inner.reset(shape.get("shape")?);
        Ok(())
    }

    fn start_from(&mut self, pose: &Bound<'_, PyAny>) -> PyResult<()> {
        let p = pose_arg(pose, "pose")?;
        Ok(self.inner.start_from(&p)?)
    }

    #[getter]
    fn camera(&self) -> PyCamera {
        PyCamera {
            inner: *self.inner.estimator().camera(),
        }
    }
    #[getter]
    fn model(&self) -> PyBodyModel {
        PyBodyModel {
            inner: self.inner.model().clone(),
        }
    }
    #[getter]
    fn base_model(&self) -> PyBodyModel {
        PyBodyModel {
            inner: self.inner.base_model().clone(),
        }
    }
    #[getter]
    fn config(&self) -> PyPipelineConfig {
        PyPipelineConfig {
            inner: self.inner.estimator().config().clone(),
        }
    }
    #[getter]
    fn lost_frames(&self) -> usize {
        self.inner.lost_frames
    }
    #[getter]
    fn switches(&self) -> usize {
        self.inner.switches
    }
    #[getter]
    fn calibrating(&self) -> bool {
        self.inner.calibrating()
    }
    #[getter]
    fn calibrated(&self) -> bool {
        self.inner.calibration().result.is_some()
    }
    #[getter]
    fn shape_factors<'py>(&self, py: Python<'py>) -> PyResult<Option<F64Array<'py>>> {
        self.inner
            .shape_factors()
            .map(|f| {
                let n = f.len();
                to_numpy(py, f.to_vec(), &[n])
            })
            .transpose()
    }
    #[getter]
    fn calibration(&self) -> Option<PyShapeFitResult> {
        let cam = self.inner.estimator().resolution().working;
        self.inner
            .calibration()
            .result
            .clone()
            .map(|result| PyShapeFitResult {
                result,
                height: cam.height,
                width: cam.width,
            })
    }
    #[getter]
    fn calibration_error(&self) -> Option<String> {
        self.inner.calibration().error.clone()
    }
    #[getter]
    fn calibration_frame(&self) -> Option<usize> {
        self.inner.calibration().frame
    }
}
