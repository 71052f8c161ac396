//! Pose from rectified stereo pairs for Python: the native class that
//! `depthpose.StereoPoseEstimator` / `depthpose.StereoPoseTracker` wrap. Each `update`
//! (matching, depth, pose) is one native call with the GIL released.

use super::body::PyBodyModel;
use super::camera::PyCamera;
use super::convert::{bool_array, depth_array, invalid, to_numpy, Flag, Int, Real};
use super::native;
use super::pipeline::{EstimatorArgs, EstimatorParts, PyPipelineConfig, PyPoseResult};
use super::stereo::gray_image;
use crate::pipeline::{StereoDepth, StereoDepthConfig, StereoPipeline, StereoRig, Tracker};
use numpy::PyArrayDyn;
use pyo3::prelude::*;

/// A gray pair (H, W) each, checked against each other and the camera.
fn pair(
    camera: &crate::camera::Camera,
    left: &Bound<PyAny>,
    right: &Bound<PyAny>,
    names: [&str; 2],
) -> PyResult<(Vec<f32>, Vec<f32>)> {
    let l = gray_image(left, names[0])?;
    camera.check_image(names[0], l.shape[0], l.shape[1])?;
    let r = gray_image(right, names[1])?;
    if r.shape != l.shape {
        return Err(invalid(
            names[1],
            format!(
                "shape {:?} does not match {} {:?}",
                r.shape, names[0], l.shape
            ),
        ));
    }
    Ok((l.data, r.data))
}

/// The stereo stage's settings from the keyword arguments.
struct StereoArgs {
    max_disparity: Option<Int>,
    fattening: Flag,
    disparity_tolerance: Real,
    disparity_sigma: Real,
    weigh_points: Flag,
}

impl StereoArgs {
    fn config(&self) -> PyResult<StereoDepthConfig> {
        let mut c = StereoDepthConfig::default();
        c.matching.max_disparity = self
            .max_disparity
            .as_ref()
            .map(|v| v.count("max_disparity"))
            .transpose()?;
        if !self.fattening.get("fattening")? {
            c.fattening = None;
        }
        c.disparity_tolerance = self.disparity_tolerance.get_f32("disparity_tolerance")?;
        c.disparity_sigma = self.disparity_sigma.get_f32("disparity_sigma")?;
        c.weigh_points = self.weigh_points.get("weigh_points")?;
        Ok(c)
    }
}

/// Pose from rectified pairs, from scratch or tracked (see `depthpose.StereoPoseTracker`).
#[pyclass(name = "_StereoPose", module = "depthpose._core")]
pub struct PyStereoPose {
    inner: StereoPipeline,
}

#[pymethods]
impl PyStereoPose {
    #[new]
    #[pyo3(signature = (camera, templates, baseline, *, doffs=Real::new(0.0), model=None, config=None,
        background=None, background_depth=None, track=Flag::new(true), calibrate=None, max_disparity=None,
        fattening=Flag::new(true), disparity_tolerance=Real::new(1.0),
        disparity_sigma=Real::new(0.25), weigh_points=Flag::new(false)))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        camera: &Bound<'_, PyAny>,
        templates: &Bound<'_, PyAny>,
        baseline: Real,
        doffs: Real,
        model: Option<&Bound<'_, PyAny>>,
        config: Option<&Bound<'_, PyAny>>,
        background: Option<(Bound<'_, PyAny>, Bound<'_, PyAny>)>,
        background_depth: Option<&Bound<'_, PyAny>>,
        track: Flag,
        calibrate: Option<Flag>,
        max_disparity: Option<Int>,
        fattening: Flag,
        disparity_tolerance: Real,
        disparity_sigma: Real,
        weigh_points: Flag,
    ) -> PyResult<Self> {
        let track = track.get("track")?;
        let calibrate = match &calibrate {
            Some(c) => c.get("calibrate")?,
            None => model.is_none(),
        };
        let mut parts = EstimatorParts::of(&EstimatorArgs {
            camera,
            templates,
            model,
            config,
            background: None,
        })?;
        let rig = StereoRig {
            baseline: baseline.get("baseline")?,
            doffs: doffs.get("doffs")?,
        };
        let stereo_config = StereoArgs {
            max_disparity,
            fattening,
            disparity_tolerance,
            disparity_sigma,
            weigh_points,
        }
        .config()?;
        let mut stereo = StereoDepth::new(&parts.camera, rig, stereo_config)?;
        parts.config.segment = stereo.segment_config(&parts.config.segment);
        parts.config.fit = stereo.fit_config(&parts.config.fit);
        let bg = background
            .map(|(l, r)| pair(&parts.camera, &l, &r, ["background[0]", "background[1]"]))
            .transpose()?;
        let bg_depth = match (bg, background_depth) {
            (Some(_), Some(_)) => {
                return Err(invalid(
                    "background_depth",
                    "give either the empty scene's pair (background) or its depth, not both",
                ))
            }
            (Some((l, r)), None) => Some(native(py, || stereo.frame(&l, &r, false))?.depth),
            (None, Some(d)) => {
                let d = depth_array(d, "background_depth")?;
                parts
                    .camera
                    .check_image("background_depth", d.shape[0], d.shape[1])?;
                Some(d.data)
            }
            (None, None) => None,
        };
        let estimator = parts.estimator(bg_depth.as_deref())?;
        let inner = if track {
            StereoPipeline::tracking(stereo, Tracker::new(estimator, calibrate))
        } else {
            StereoPipeline::estimating(stereo, estimator)
        };
        Ok(PyStereoPose { inner })
    }

    #[pyo3(signature = (left, right, mask=None))]
    fn update(
        &mut self,
        py: Python<'_>,
        left: &Bound<'_, PyAny>,
        right: &Bound<'_, PyAny>,
        mask: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyPoseResult> {
        let camera = *self.inner.estimator().camera();
        let (l, r) = pair(&camera, left, right, ["left", "right"])?;
        let shape = [camera.height, camera.width];
        let mask = mask.map(|m| bool_array(m, "mask", &shape)).transpose()?;
        let pipeline = &mut self.inner;
        let out = native(py, || pipeline.update(&l, &r, mask.as_deref()))?;
        Ok(PyPoseResult {
            inner: out.result,
            shape,
        })
    }

    #[pyo3(signature = (shape=Flag::new(false)))]
    fn reset(&mut self, shape: Flag) -> PyResult<()> {
        self.inner.reset(shape.get("shape")?);
        Ok(())
    }

    /// The last pair's disparity (H, W), NaN unmatched; None before the first pair.
    #[getter]
    fn disparity<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArrayDyn<f32>>>> {
        let cam = self.inner.estimator().camera();
        self.inner
            .disparity()
            .map(|d| to_numpy(py, d.to_vec(), &[cam.height, cam.width]))
            .transpose()
    }
    #[getter]
    fn baseline(&self) -> f64 {
        self.inner.stereo().rig().baseline
    }
    #[getter]
    fn doffs(&self) -> f64 {
        self.inner.stereo().rig().doffs
    }
    #[getter]
    fn tracking(&self) -> bool {
        self.inner.tracker().is_some()
    }
    #[getter]
    fn model(&self) -> PyBodyModel {
        let model = match self.inner.tracker() {
            Some(t) => t.model(),
            None => self.inner.estimator().model(),
        };
        PyBodyModel {
            inner: model.clone(),
        }
    }
    #[getter]
    fn config(&self) -> PyPipelineConfig {
        PyPipelineConfig {
            inner: self.inner.estimator().config().clone(),
        }
    }
    #[getter]
    fn camera(&self) -> PyCamera {
        PyCamera {
            inner: *self.inner.estimator().camera(),
        }
    }
    /// The calibrated shape factors (12,) of a tracking pipeline, else None.
    #[getter]
    fn shape_factors<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArrayDyn<f64>>>> {
        self.inner
            .tracker()
            .and_then(|t| t.shape_factors())
            .map(|f| {
                let n = f.len();
                to_numpy(py, f.to_vec(), &[n])
            })
            .transpose()
    }
    #[getter]
    fn calibration_error(&self) -> Option<String> {
        self.inner
            .tracker()
            .and_then(|t| t.calibration().error.clone())
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyStereoPose>()?;
    Ok(())
}
