//! The pipeline for Python: `PipelineConfig`, `PoseResult`, `PoseEstimator` and
//! `PoseTracker` (documented in `python/depthpose/_core.pyi`), and the pose helpers
//! `swap_limbs`, `mirror_view` and `rest_pose_penalty`. Each `estimate` and `update`
//! is one native call with the GIL released.

mod args;
mod config;
mod estimator;
mod result;
mod tracker;

pub(super) use args::{calibrate_arg, EstimatorArgs, EstimatorParts};
pub(super) use config::PyPipelineConfig;
pub(super) use result::PyPoseResult;

use super::body::pose_arg;
use super::convert::{f64_array, to_numpy, Real};
use crate::body::{pose_from_slice, Pose, JOINT_NAMES, NUM_PARAMS};
use crate::error::Error;
use crate::pipeline::{mirror_view as mirror, rest_pose_penalty as penalty, swap_limbs as swap};
use numpy::PyArrayDyn;
use pyo3::prelude::*;

type F64Array<'py> = Bound<'py, PyArrayDyn<f64>>;

/// The left/right-swapped pose (see `depthpose.swap_limbs`).
#[pyfunction]
fn swap_limbs<'py>(py: Python<'py>, pose: &Bound<'py, PyAny>) -> PyResult<F64Array<'py>> {
    let p = pose_arg(pose, "pose")?;
    to_numpy(py, swap(&p).to_vec(), &[NUM_PARAMS])
}

/// The mirror image of the pose in the camera's vertical plane through the hip centre.
#[pyfunction]
fn mirror_view<'py>(py: Python<'py>, pose: &Bound<'py, PyAny>) -> PyResult<F64Array<'py>> {
    let p = pose_arg(pose, "pose")?;
    to_numpy(py, mirror(&p).to_vec(), &[NUM_PARAMS])
}

/// `weight` × Σ θ² over the 14 limb angles of each pose: (N, 22) → (N,), (22,) → (1,).
#[pyfunction]
fn rest_pose_penalty<'py>(
    py: Python<'py>,
    poses: &Bound<'py, PyAny>,
    weight: Real,
) -> PyResult<F64Array<'py>> {
    let weight = weight.get("weight")?;
    if !(weight.is_finite() && weight >= 0.0) {
        return Err(
            Error::invalid("weight", format!("must be finite and >= 0, got {weight}")).into(),
        );
    }
    let a = f64_array(poses, "poses", None, false)?;
    let rows = match a.shape.as_slice() {
        [NUM_PARAMS] => 1,
        [n, NUM_PARAMS] => *n,
        other => {
            return Err(Error::invalid(
                "poses",
                format!("expected shape ({NUM_PARAMS},) or (N, {NUM_PARAMS}), got {other:?}"),
            )
            .into())
        }
    };
    let poses: Vec<Pose> = (0..rows)
        .map(|k| pose_from_slice(&a.data[k * NUM_PARAMS..][..NUM_PARAMS], "poses"))
        .collect::<crate::Result<_>>()?;
    let v: Vec<f64> = poses.iter().map(|p| penalty(p, weight)).collect();
    let n = v.len();
    to_numpy(py, v, &[n])
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyPipelineConfig>()?;
    m.add_class::<PyPoseResult>()?;
    m.add_class::<estimator::PyPoseEstimator>()?;
    m.add_class::<tracker::PyPoseTracker>()?;
    m.add_function(wrap_pyfunction!(swap_limbs, m)?)?;
    m.add_function(wrap_pyfunction!(mirror_view, m)?)?;
    m.add_function(wrap_pyfunction!(rest_pose_penalty, m)?)?;
    m.add("JOINT_NAMES", JOINT_NAMES.to_vec())?;
    Ok(())
}
