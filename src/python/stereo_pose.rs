//! Pose from rectified stereo pairs for Python: `StereoPoseTracker` and its subclass
//! `StereoPoseEstimator` (documented in `python/depthpose/_core.pyi`). Each `update`
//! (matching, depth, pose) is one native call with the GIL released.

use super::body::PyBodyModel;
use super::camera::PyCamera;
use super::convert::{
    bool_array, depth_array, invalid, to_numpy, type_name, wrong_type, Flag, Int, Real,
};
use super::keywords::keywords;
use super::native;
use super::pipeline::{
    calibrate_arg, EstimatorArgs, EstimatorParts, PyPipelineConfig, PyPoseResult,
};
use super::stereo::gray_image;
use crate::error::brief;
use crate::pipeline::{StereoDepth, StereoDepthConfig, StereoPipeline, StereoRig, Tracker};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};

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

/// The empty scene's pair `(left, right)`: a tuple or list of two images.
fn background_pair<'py>(
    obj: &Bound<'py, PyAny>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let sequence = obj.is_instance_of::<PyTuple>() || obj.is_instance_of::<PyList>();
    if !sequence || obj.len()? != 2 {
        return Err(wrong_type(
            "background",
            "the empty scene's pair (left, right)",
            &type_name(obj),
        ));
    }
    Ok((obj.get_item(0)?, obj.get_item(1)?))
}

/// The distance between the camera centres: finite and positive.
fn baseline_arg(baseline: &Real) -> PyResult<f64> {
    let b = baseline.get("baseline")?;
    if !(b.is_finite() && b > 0.0) {
        return Err(invalid(
            "baseline",
            format!("must be a finite number in (0, inf], got {}", brief(b)),
        ));
    }
    Ok(b)
}

keywords! {
    /// The keyword arguments of `StereoPoseTracker` and `StereoPoseEstimator`.
    struct StereoKeywords<'py> {
        doffs: Real = Real::new(0.0),
        model: Option<Bound<'py, PyAny>> = None,
        templates: Option<Bound<'py, PyAny>> = None,
        config: Option<Bound<'py, PyAny>> = None,
        background: Option<Bound<'py, PyAny>> = None,
        background_depth: Option<Bound<'py, PyAny>> = None,
        calibrate: Option<Flag> = None,
        max_disparity: Option<Int> = None,
        fattening: Flag = Flag::new(true),
        disparity_tolerance: Real = Real::new(1.0),
        disparity_sigma: Real = Real::new(0.25),
        weigh_points: Flag = Flag::new(false),
    }
}

impl StereoKeywords<'_> {
    /// The stereo stage's settings.
    fn stereo_config(&self) -> PyResult<StereoDepthConfig> {
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

/// Pose through a video of rectified stereo pairs.
#[pyclass(name = "StereoPoseTracker", module = "depthpose._core", subclass)]
pub struct PyStereoPoseTracker {
    inner: StereoPipeline,
}

impl PyStereoPoseTracker {
    /// The pipeline of `camera`, `baseline` and the keyword arguments: tracking, or
    /// estimating each pair from scratch.
    fn build(
        camera: &Bound<'_, PyAny>,
        baseline: &Real,
        options: &StereoKeywords<'_>,
        track: bool,
    ) -> PyResult<Self> {
        let calibrate = calibrate_arg(options.calibrate.as_ref(), options.model.as_ref())?;
        let mut parts = EstimatorParts::of(&EstimatorArgs {
            camera,
            model: options.model.as_ref(),
            templates: options.templates.as_ref(),
            config: options.config.as_ref(),
        })?;
        let baseline = baseline_arg(baseline)?;
        let background = options
            .background
            .as_ref()
            .map(background_pair)
            .transpose()?;
        let rig = StereoRig {
            baseline,
            doffs: options.doffs.get("doffs")?,
        };
        let mut stereo = StereoDepth::new(&parts.camera, rig, options.stereo_config()?)?;
        parts.config.segment = stereo.segment_config(&parts.config.segment);
        parts.config.fit = stereo.fit_config(&parts.config.fit);
        let bg = background
            .map(|(l, r)| pair(&parts.camera, &l, &r, ["background[0]", "background[1]"]))
            .transpose()?;
        let bg_depth = match (bg, &options.background_depth) {
            (Some(_), Some(_)) => {
                return Err(invalid(
                    "background_depth",
                    "give either the empty scene's pair (background) or its depth, not both",
                ))
            }
            (Some((l, r)), None) => {
                Some(native(camera.py(), || stereo.frame(&l, &r, false))?.depth)
            }
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
        Ok(PyStereoPoseTracker { inner })
    }
}

#[pymethods]
impl PyStereoPoseTracker {
    // The signature of both stereo classes.
    #[new]
    #[pyo3(signature = (camera, baseline, **options),
           text_signature = "(camera, baseline, *, doffs=0.0, model=None, templates=None, \
                             config=None, background=None, background_depth=None, \
                             calibrate=None, max_disparity=None, fattening=True, \
                             disparity_tolerance=1.0, disparity_sigma=0.25, weigh_points=False)")]
    fn new(
        camera: &Bound<'_, PyAny>,
        baseline: Real,
        options: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let options = StereoKeywords::parse("StereoPoseTracker.__new__", options)?;
        Self::build(camera, &baseline, &options, true)
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

    #[pyo3(signature = (shape=Flag::new(false)), text_signature = "($self, shape=False)")]
    fn reset(&mut self, shape: Flag) -> PyResult<()> {
        self.inner.reset(shape.get("shape")?);
        Ok(())
    }

    #[getter]
    fn disparity<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArrayDyn<f32>>>> {
        let cam = self.inner.estimator().camera();
        self.inner
            .disparity()
            .map(|d| to_numpy(py, d.to_vec(), &[cam.height, cam.width]))
            .transpose()
    }
    #[getter]
    fn camera(&self) -> PyCamera {
        PyCamera {
            inner: *self.inner.estimator().camera(),
        }
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

/// Pose of each rectified stereo pair from scratch.
#[pyclass(name = "StereoPoseEstimator", module = "depthpose._core", extends = PyStereoPoseTracker)]
pub struct PyStereoPoseEstimator;

#[pymethods]
impl PyStereoPoseEstimator {
    // The signature of both stereo classes.
    #[new]
    #[pyo3(signature = (camera, baseline, **options),
           text_signature = "(camera, baseline, *, doffs=0.0, model=None, templates=None, \
                             config=None, background=None, background_depth=None, \
                             calibrate=None, max_disparity=None, fattening=True, \
                             disparity_tolerance=1.0, disparity_sigma=0.25, weigh_points=False)")]
    fn new(
        camera: &Bound<'_, PyAny>,
        baseline: Real,
        options: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<PyClassInitializer<Self>> {
        let options = StereoKeywords::parse("StereoPoseEstimator.__new__", options)?;
        let base = PyStereoPoseTracker::build(camera, &baseline, &options, false)?;
        Ok(PyClassInitializer::from(base).add_subclass(PyStereoPoseEstimator))
    }

    #[pyo3(signature = (left, right, mask=None))]
    fn estimate(
        mut slf: PyRefMut<'_, Self>,
        py: Python<'_>,
        left: &Bound<'_, PyAny>,
        right: &Bound<'_, PyAny>,
        mask: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyPoseResult> {
        slf.as_super().update(py, left, right, mask)
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyStereoPoseTracker>()?;
    m.add_class::<PyStereoPoseEstimator>()?;
    Ok(())
}
