//! Synthetic depth sequences, for Python (`depthpose.synth`).

use super::camera::PyCamera;
use super::convert::{check_result_bytes, object, to_numpy, Int, Real, Text};
use super::keywords::keywords;
use super::native;
use crate::body::{JOINT_NAMES, NUM_JOINTS, NUM_PARAMS};
use crate::camera::Camera;
use crate::synth::{make_sequence as render_sequence, Motion, SequenceConfig};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

keywords! {
    /// The keyword-only settings of `make_sequence`.
    struct SequenceKeywords {
        distance: Real = Real::new(3.0),
        view_deg: Real = Real::new(0.0),
        noise: Real = Real::new(1.0),
        seed: Int = Int::new(0),
        height: Real = Real::new(1.75),
        fps: Real = Real::new(30.0),
        cycles: Real = Real::new(1.0),
        camera_height: Real = Real::new(1.2),
        tilt_deg: Real = Real::new(5.0),
        wall_distance: Option<Real> = None,
    }
}

/// The joint angles (22,) of `motion` at phase `t` (modulo 1); the root parts are zero.
#[pyfunction]
fn motion_pose<'py>(
    py: Python<'py>,
    motion: Text,
    t: Real,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let pose = Motion::from_name(motion.get("motion")?)?.pose(t.get("t")?);
    to_numpy(py, pose.to_vec(), &[NUM_PARAMS])
}

/// A sequence of `motion` as a dict of the shared synthetic data's arrays.
#[pyfunction]
#[pyo3(signature = (motion=None, frames=Int::new(30), camera=None, **settings),
       text_signature = "(motion='wave', frames=30, camera=None, *, distance=3.0, \
                         view_deg=0.0, noise=1.0, seed=0, height=1.75, fps=30.0, cycles=1.0, \
                         camera_height=1.2, tilt_deg=5.0, wall_distance=None)")]
fn make_sequence<'py>(
    py: Python<'py>,
    motion: Option<Text>,
    frames: Int,
    camera: Option<&Bound<'py, PyAny>>,
    settings: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    let k = SequenceKeywords::parse("make_sequence", settings)?;
    let motion = match &motion {
        None => Motion::Wave,
        Some(m) => Motion::from_name(m.get("motion")?)?,
    };
    let config = SequenceConfig {
        motion,
        frames: frames.in_range(1, 10_000, "frames")? as usize,
        distance: k.distance.get("distance")?,
        view_deg: k.view_deg.get("view_deg")?,
        noise: k.noise.get("noise")?,
        seed: k.seed.seed("seed")?,
        height: k.height.get("height")?,
        cycles: k.cycles.get("cycles")?,
        camera_height: k.camera_height.get("camera_height")?,
        tilt_deg: k.tilt_deg.get("tilt_deg")?,
        fps: k.fps.get("fps")?,
        wall_distance: k
            .wall_distance
            .map(|w| w.get("wall_distance"))
            .transpose()?,
    };
    let camera: Camera = match camera.filter(|c| !c.is_none()) {
        None => Camera::itop(),
        Some(c) => object::<PyCamera>(c, "camera", "a depthpose.Camera or None")?.inner,
    };
    let (h, w) = (camera.height, camera.width);
    // depth, mask and labels: 5 bytes a pixel a frame.
    let bytes = config
        .frames
        .checked_mul(h * w)
        .and_then(|n| n.checked_mul(5));
    check_result_bytes(bytes, "frames", "the sequence")?;
    let seq = native(py, || render_sequence(&camera, &config))?;
    let t = config.frames;
    let numpy = py.import("numpy")?;
    let meta = PyDict::new(py);
    meta.set_item("generator", "depthpose.synth")?;
    meta.set_item("motion", motion.name())?;
    meta.set_item("frames", t)?;
    meta.set_item("cycles", config.cycles)?;
    meta.set_item("subject_height", config.height)?;
    meta.set_item("view_deg", config.view_deg)?;
    meta.set_item("distance", config.distance)?;
    meta.set_item("camera_height", config.camera_height)?;
    meta.set_item("tilt_deg", config.tilt_deg)?;
    meta.set_item("wall_distance", seq.wall_distance)?;
    meta.set_item("noise", config.noise)?;
    meta.set_item("seed", config.seed)?;
    meta.set_item(
        "joints",
        "anatomical: Head = head centre, Neck = base of neck, Hand = wrist, Foot = ankle, \
         Torso = mid-spine",
    )?;
    let meta = py.import("json")?.call_method1("dumps", (meta,))?;
    let out = PyDict::new(py);
    out.set_item("depth", to_numpy(py, seq.depth, &[t, h, w])?)?;
    out.set_item("background", to_numpy(py, seq.background, &[h, w])?)?;
    out.set_item("mask", to_numpy(py, seq.mask, &[t, h, w])?)?;
    out.set_item("joints", to_numpy(py, seq.joints, &[t, NUM_JOINTS, 3])?)?;
    let intrinsics = vec![camera.fx, camera.fy, camera.cx, camera.cy];
    out.set_item("intrinsics", to_numpy(py, intrinsics, &[4])?)?;
    let names = PyTuple::new(py, JOINT_NAMES)?;
    out.set_item("joint_names", numpy.call_method1("array", (names,))?)?;
    out.set_item("fps", numpy.call_method1("array", (config.fps,))?)?;
    out.set_item("meta", numpy.call_method1("array", (meta,))?)?;
    out.set_item("poses", to_numpy(py, seq.poses, &[t, NUM_PARAMS])?)?;
    out.set_item("labels", to_numpy(py, seq.labels, &[t, h, w])?)?;
    Ok(out)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let names: Vec<&str> = Motion::ALL.iter().map(|m| m.name()).collect();
    m.add("MOTIONS", PyTuple::new(m.py(), names)?)?;
    m.add_function(wrap_pyfunction!(motion_pose, m)?)?;
    m.add_function(wrap_pyfunction!(make_sequence, m)?)
}
