//! `PipelineConfig`: the estimator's and the tracker's settings, from keyword
//! arguments.

use super::super::convert::{fit_config, Int, Real};
use super::super::fit::PyFitConfig;
use crate::error::Error;
use crate::pipeline::PipelineConfig;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Settings of the estimator and the tracker (see the Rust docs of
/// `depthpose::pipeline::PipelineConfig`); keyword arguments, defaults from Rust.
#[pyclass(name = "PipelineConfig", module = "depthpose._core", frozen, eq)]
#[derive(Clone, PartialEq)]
pub struct PyPipelineConfig {
    pub inner: PipelineConfig,
}

fn int_field(value: &Bound<PyAny>, name: &str) -> PyResult<usize> {
    value.extract::<Int>()?.count(name)
}

fn bool_field(value: &Bound<PyAny>, name: &str) -> PyResult<bool> {
    if !value.is_instance_of::<pyo3::types::PyBool>() {
        return Err(Error::invalid(
            name,
            format!("expected True or False, got {}", short(value)),
        )
        .into());
    }
    value.extract()
}

fn real_field(value: &Bound<PyAny>, name: &str) -> PyResult<f64> {
    value.extract::<Real>()?.get(name)
}

/// A value for an error message, at most 60 characters.
fn short(value: &Bound<PyAny>) -> String {
    let s = value
        .repr()
        .map(|r| r.to_string())
        .unwrap_or_else(|_| "?".into());
    if s.chars().count() > 60 {
        format!("{}…", s.chars().take(57).collect::<String>())
    } else {
        s
    }
}

#[pymethods]
impl PyPipelineConfig {
    #[new]
    #[pyo3(signature = (**kwargs))]
    fn new(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let mut c = PipelineConfig::default();
        if let Some(kw) = kwargs {
            for (key, value) in kw.iter() {
                let name: String = key.extract()?;
                let n = name.as_str();
                match n {
                    "candidates" => c.candidates = int_field(&value, n)?,
                    "hypotheses" => c.hypotheses = int_field(&value, n)?,
                    "back_views" => c.back_views = bool_field(&value, n)?,
                    "any_roll" => c.any_roll = bool_field(&value, n)?,
                    "limb_poses" => c.limb_poses = bool_field(&value, n)?,
                    "candidate_iterations" => c.candidate_iterations = int_field(&value, n)?,
                    "finals" => c.finals = int_field(&value, n)?,
                    "final_iterations" => {
                        c.final_iterations = if value.is_none() {
                            None
                        } else {
                            Some(int_field(&value, n)?)
                        }
                    }
                    "candidate_stride" => c.candidate_stride = int_field(&value, n)?,
                    "final_stride" => c.final_stride = int_field(&value, n)?,
                    "prior_weight" => c.prior_weight = real_field(&value, n)?,
                    "track_iterations" => c.track_iterations = int_field(&value, n)?,
                    "track_stride" => c.track_stride = int_field(&value, n)?,
                    "velocity_damping" => c.velocity_damping = real_field(&value, n)?,
                    "min_inlier_share" => c.min_inlier_share = real_field(&value, n)?,
                    "lost_ratio" => c.lost_ratio = real_field(&value, n)?,
                    "lost_discrepancy" => c.lost_discrepancy = real_field(&value, n)?,
                    "recheck_every" => c.recheck_every = int_field(&value, n)?,
                    "recheck_hypotheses" => c.recheck_hypotheses = int_field(&value, n)?,
                    "lost_hypotheses" => c.lost_hypotheses = int_field(&value, n)?,
                    "switch_margin" => c.switch_margin = real_field(&value, n)?,
                    "pose_prior_weight" => c.pose_prior_weight = real_field(&value, n)?,
                    "penetration_weight" => c.penetration_weight = real_field(&value, n)?,
                    "size_range" => c.size_range = real_field(&value, n)?,
                    "size_step" => c.size_step = real_field(&value, n)?,
                    "calibration_frames" => c.calibration_frames = int_field(&value, n)?,
                    "calibration_every" => c.calibration_every = int_field(&value, n)?,
                    "calibration_prior_weight" => {
                        c.calibration_prior_weight = real_field(&value, n)?
                    }
                    "calibration_rounds" => c.calibration_rounds = int_field(&value, n)?,
                    "learn_background" => c.learn_background = bool_field(&value, n)?,
                    "working_focal" => c.working_focal = real_field(&value, n)?,
                    "fit" => c.fit = fit_config(Some(&value), "fit")?,
                    other => {
                        return Err(Error::invalid(
                            other,
                            "not a PipelineConfig setting (see help(depthpose.PipelineConfig))",
                        )
                        .into())
                    }
                }
            }
        }
        c.validate()?;
        Ok(PyPipelineConfig { inner: c })
    }

    /// This config with some settings changed (keyword arguments as for the
    /// constructor).
    #[pyo3(signature = (**kwargs))]
    fn replace(&self, py: Python<'_>, kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let all = self.as_dict(py)?;
        if let Some(kw) = kwargs {
            all.update(kw.as_mapping())?;
        }
        Self::new(Some(&all))
    }

    /// Every setting by name (`fit` as a FitConfig).
    fn as_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let c = &self.inner;
        let d = PyDict::new(py);
        d.set_item("candidates", c.candidates)?;
        d.set_item("hypotheses", c.hypotheses)?;
        d.set_item("back_views", c.back_views)?;
        d.set_item("any_roll", c.any_roll)?;
        d.set_item("limb_poses", c.limb_poses)?;
        d.set_item("candidate_iterations", c.candidate_iterations)?;
        d.set_item("finals", c.finals)?;
        d.set_item("final_iterations", c.final_iterations)?;
        d.set_item("candidate_stride", c.candidate_stride)?;
        d.set_item("final_stride", c.final_stride)?;
        d.set_item("prior_weight", c.prior_weight)?;
        d.set_item("track_iterations", c.track_iterations)?;
        d.set_item("track_stride", c.track_stride)?;
        d.set_item("velocity_damping", c.velocity_damping)?;
        d.set_item("min_inlier_share", c.min_inlier_share)?;
        d.set_item("lost_ratio", c.lost_ratio)?;
        d.set_item("lost_discrepancy", c.lost_discrepancy)?;
        d.set_item("recheck_every", c.recheck_every)?;
        d.set_item("recheck_hypotheses", c.recheck_hypotheses)?;
        d.set_item("lost_hypotheses", c.lost_hypotheses)?;
        d.set_item("switch_margin", c.switch_margin)?;
        d.set_item("pose_prior_weight", c.pose_prior_weight)?;
        d.set_item("penetration_weight", c.penetration_weight)?;
        d.set_item("size_range", c.size_range)?;
        d.set_item("size_step", c.size_step)?;
        d.set_item("calibration_frames", c.calibration_frames)?;
        d.set_item("calibration_every", c.calibration_every)?;
        d.set_item("calibration_prior_weight", c.calibration_prior_weight)?;
        d.set_item("calibration_rounds", c.calibration_rounds)?;
        d.set_item("learn_background", c.learn_background)?;
        d.set_item("working_focal", c.working_focal)?;
        d.set_item("fit", PyFitConfig::from_rust(&c.fit))?;
        Ok(d)
    }

    fn __getattr__(&self, py: Python<'_>, name: &str) -> PyResult<Py<PyAny>> {
        let d = self.as_dict(py)?;
        match d.get_item(name)? {
            Some(v) => Ok(v.unbind()),
            None => Err(pyo3::exceptions::PyAttributeError::new_err(format!(
                "PipelineConfig has no setting {name:?}"
            ))),
        }
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let d = self.as_dict(py)?;
        let mut parts = Vec::new();
        for (k, v) in d.iter() {
            parts.push(format!("{}={}", k, v.repr()?));
        }
        Ok(format!("PipelineConfig({})", parts.join(", ")))
    }
}
