//! `BodyModel` for Python: kinematics, distances, Jacobians, rendering, meshes, and
//! `ShapeFitResult`, the outcome of its shape fit.

use super::convert::{
    bool_array, camera as camera_arg, check_fit_points, check_image_pixels, check_result_bytes,
    depth_array, f32_array, f64_array, fit_config, i64_array, invalid, joints_to_numpy, to_numpy,
    Int, Real,
};
use super::keywords::keywords;
use super::{native, native_ok};
use crate::body::rotation;
use crate::body::superquadric::MeshConfig;
use crate::body::{
    pose_from_slice, pose_with_root_increment, BodyModel, BodyShape, Pose, JOINT_NAMES, NUM_JOINTS,
    NUM_PARAMS, NUM_SEGMENTS, NUM_SHAPE_FACTORS, PARAM_NAMES, PART_NAMES, SHAPE_FACTOR_NAMES,
    SHAPE_PARAM_NAMES,
};
use crate::error::Error;
use crate::fit::{self, ShapeConfig, ShapeFrame};
use numpy::{PyArrayDyn, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::collections::HashMap;

type F64Array<'py> = Bound<'py, PyArrayDyn<f64>>;
type F32Array<'py> = Bound<'py, PyArrayDyn<f32>>;
type I16Array<'py> = Bound<'py, PyArrayDyn<i16>>;
type I64Array<'py> = Bound<'py, PyArrayDyn<i64>>;

/// One pose from a (22,) array; a non-finite value is named by its parameter.
pub(super) fn pose_arg(obj: &Bound<PyAny>, name: &str) -> PyResult<Pose> {
    let a = f64_array(obj, name, Some(1), false)?;
    Ok(pose_from_slice(&a.data, name)?)
}

/// K poses from a (K, 22) array; a bad row is named `name[k]`.
pub(super) fn poses_arg(obj: &Bound<PyAny>, name: &str) -> PyResult<Vec<Pose>> {
    let a = f64_array(obj, name, Some(2), false)?;
    if a.shape[1] != NUM_PARAMS {
        return Err(invalid(
            name,
            format!("expected shape (K, {NUM_PARAMS}), got {:?}", a.shape),
        ));
    }
    Ok(a.data
        .chunks(NUM_PARAMS)
        .enumerate()
        .map(|(k, row)| pose_from_slice(row, &format!("{name}[{k}]")))
        .collect::<crate::Result<Vec<_>>>()?)
}

fn points_arg(obj: &Bound<PyAny>) -> PyResult<Vec<[f32; 3]>> {
    let a = f32_array(obj, "points", Some(2), true)?;
    if a.shape[1] != 3 {
        return Err(invalid(
            "points",
            format!("expected shape (N, 3), got {:?}", a.shape),
        ));
    }
    Ok(a.data.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// Most frames one shape calibration takes.
const MAX_FRAMES: usize = 1024;
/// Most rounds (and LM iterations per round) of a shape calibration.
const MAX_ROUNDS: i128 = 100_000;

/// The items of a per-frame argument: a list/tuple of arrays or an array whose first
/// axis is the frame (`ndim` = dimensions of the stacked array).
fn frame_items<'py>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    ndim: usize,
) -> PyResult<Vec<Bound<'py, PyAny>>> {
    let items: Vec<Bound<'py, PyAny>> = if let Ok(arr) = obj.cast::<PyUntypedArray>() {
        if arr.ndim() != ndim {
            return Err(invalid(
                name,
                format!(
                    "expected a list of frames or a {ndim}-D array, got shape {:?}",
                    arr.shape()
                ),
            ));
        }
        if arr.shape()[0] > MAX_FRAMES {
            return Err(super::convert::too_large(
                name,
                format!("more than {MAX_FRAMES} frames"),
            ));
        }
        (0..arr.shape()[0])
            .map(|i| obj.get_item(i))
            .collect::<PyResult<_>>()?
    } else if obj.is_instance_of::<pyo3::types::PyList>()
        || obj.is_instance_of::<pyo3::types::PyTuple>()
    {
        if obj.len()? > MAX_FRAMES {
            return Err(super::convert::too_large(
                name,
                format!("more than {MAX_FRAMES} frames"),
            ));
        }
        obj.try_iter()?.collect::<PyResult<_>>()?
    } else {
        let ty = obj
            .get_type()
            .name()
            .map(|n| n.to_string())
            .unwrap_or_else(|_| "?".into());
        return Err(super::convert::wrong_type(
            name,
            "a list of arrays or a numpy array",
            &ty,
        ));
    };
    if items.is_empty() {
        return Err(invalid(name, "needs at least one frame"));
    }
    Ok(items)
}

/// The articulated 16-segment, 22-parameter body model (see the Rust docs of
/// `depthpose::body` for frames, parameters and joint axes).
#[pyclass(name = "BodyModel", module = "depthpose._core")]
#[derive(Clone)]
pub struct PyBodyModel {
    pub inner: BodyModel,
}

keywords! {
    /// The keyword arguments of `BodyModel.fit_shape`.
    struct ShapeKeywords<'py> {
        masks: Option<Bound<'py, PyAny>> = None,
        iterations: Int = Int::new(3),
        config: Option<Bound<'py, PyAny>> = None,
        lm_iterations: Int = Int::new(20),
        prior_weight: Real = Real::new(1e5),
        bounds: Option<Bound<'py, PyAny>> = None,
    }
}

#[pymethods]
impl PyBodyModel {
    /// A body `height` metres tall with reference proportions.
    #[new]
    #[pyo3(signature = (height=Real::new(1.75)), text_signature = "(height=1.75)")]
    fn new(height: Real) -> PyResult<Self> {
        Ok(PyBodyModel {
            inner: BodyModel::new(height.get("height")?)?,
        })
    }

    /// Pose parameter names (22).
    #[getter]
    fn param_names(&self) -> Vec<&'static str> {
        PARAM_NAMES.to_vec()
    }
    /// Output joint names (15, ITOP order).
    #[getter]
    fn joint_names(&self) -> Vec<&'static str> {
        JOINT_NAMES.to_vec()
    }
    /// Segment (part label) names (16).
    #[getter]
    fn part_names(&self) -> Vec<&'static str> {
        PART_NAMES.to_vec()
    }
    /// Shape parameter names, the order of `shape`.
    #[getter]
    fn shape_names(&self) -> Vec<&'static str> {
        SHAPE_PARAM_NAMES.to_vec()
    }
    /// Lower bounds of the pose (22,), -inf for the free root.
    #[getter]
    fn lower_bounds<'py>(&self, py: Python<'py>) -> PyResult<F64Array<'py>> {
        to_numpy(py, BodyModel::lower_bounds().to_vec(), &[NUM_PARAMS])
    }
    /// Upper bounds of the pose (22,), +inf for the free root.
    #[getter]
    fn upper_bounds<'py>(&self, py: Python<'py>) -> PyResult<F64Array<'py>> {
        to_numpy(py, BodyModel::upper_bounds().to_vec(), &[NUM_PARAMS])
    }
    /// The shape parameters (metres) in `shape_names` order.
    #[getter]
    fn get_shape<'py>(&self, py: Python<'py>) -> PyResult<F64Array<'py>> {
        let v = self.inner.shape.to_vec();
        to_numpy(py, v.to_vec(), &[v.len()])
    }
    #[setter]
    fn set_shape(&mut self, shape: &Bound<PyAny>) -> PyResult<()> {
        let a = f64_array(shape, "shape", Some(1), true)?;
        self.inner.shape = BodyShape::from_vec(&a.data)?;
        Ok(())
    }
    /// The shape as a {name: value} dict.
    fn shape_dict(&self) -> Vec<(&'static str, f64)> {
        SHAPE_PARAM_NAMES
            .iter()
            .copied()
            .zip(self.inner.shape.to_vec())
            .collect()
    }

    /// Upright, facing the camera, arms down, hip centre 3 m ahead (22,).
    #[staticmethod]
    fn neutral_pose<'py>(py: Python<'py>) -> PyResult<F64Array<'py>> {
        to_numpy(py, BodyModel::neutral_pose().to_vec(), &[NUM_PARAMS])
    }

    /// `pose` with its joint angles clamped into the limits.
    fn clamp_pose<'py>(
        &self,
        py: Python<'py>,
        pose: &Bound<'py, PyAny>,
    ) -> PyResult<F64Array<'py>> {
        let p = pose_arg(pose, "pose")?;
        to_numpy(py, BodyModel::clamp_pose(&p).to_vec(), &[NUM_PARAMS])
    }

    /// `pose` with its root rotation R replaced by R·exp([omega]x) (body-frame increment,
    /// the meaning of the Jacobian columns 3..6).
    #[staticmethod]
    fn pose_with_root_increment<'py>(
        py: Python<'py>,
        pose: &Bound<'py, PyAny>,
        omega: &Bound<'py, PyAny>,
    ) -> PyResult<F64Array<'py>> {
        let p = pose_arg(pose, "pose")?;
        let q = pose_with_root_increment(&p, &vector_arg(omega, "omega")?);
        to_numpy(py, q.to_vec(), &[NUM_PARAMS])
    }

    /// Segment frame → camera transforms (16, 4, 4).
    fn segment_transforms<'py>(
        &self,
        py: Python<'py>,
        pose: &Bound<'py, PyAny>,
    ) -> PyResult<F64Array<'py>> {
        let p = pose_arg(pose, "pose")?;
        let frames = self.inner.segment_transforms(&p);
        let mut out = Vec::with_capacity(NUM_SEGMENTS * 16);
        for f in &frames {
            let m = f.to_homogeneous();
            for r in 0..4 {
                for c in 0..4 {
                    out.push(m[(r, c)]);
                }
            }
        }
        to_numpy(py, out, &[NUM_SEGMENTS, 4, 4])
    }

    /// The 15 joints (15, 3) in the camera frame, ITOP order.
    fn joints<'py>(&self, py: Python<'py>, pose: &Bound<'py, PyAny>) -> PyResult<F64Array<'py>> {
        let p = pose_arg(pose, "pose")?;
        let j = self.inner.joints(&p);
        let out: Vec<f64> = j.iter().flat_map(|v| [v.x, v.y, v.z]).collect();
        to_numpy(py, out, &[NUM_JOINTS, 3])
    }

    /// d(joints)/d(pose) as (15, 3, 22); root rotation columns are body-frame increments.
    fn joints_jacobian<'py>(
        &self,
        py: Python<'py>,
        pose: &Bound<'py, PyAny>,
    ) -> PyResult<F64Array<'py>> {
        let p = pose_arg(pose, "pose")?;
        let mut out = [0.0; NUM_JOINTS * 3 * NUM_PARAMS];
        self.inner.joints_jacobian(&p, &mut out);
        to_numpy(py, out.to_vec(), &[NUM_JOINTS, 3, NUM_PARAMS])
    }

    /// Signed distances (N, 16) float32 of points (N, 3) to every segment ellipsoid
    /// (negative inside), solved in single precision where the CPU has AVX-512 or AVX2
    /// (within ~3e-7 × max(1 m, |d|) of a double-precision solve). With `cap`, values
    /// are exact below `cap` and only a lower bound (>= cap) above it, which is faster.
    #[pyo3(signature = (points, pose, cap=None))]
    fn distances<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
        pose: &Bound<'py, PyAny>,
        cap: Option<Real>,
    ) -> PyResult<F32Array<'py>> {
        let cap = cap.map(|c| c.get("cap")).transpose()?;
        let pts = points_arg(points)?;
        let p = pose_arg(pose, "pose")?;
        let n = pts.len();
        check_result_bytes(
            n.checked_mul(NUM_SEGMENTS * 4),
            "points",
            "the distances (N, 16)",
        )?;
        let out = native(py, || -> crate::Result<Vec<f32>> {
            let mut out = vec![0.0f32; n * NUM_SEGMENTS];
            match cap {
                Some(c) => self.inner.distances_capped(&pts, &p, c, &mut out)?,
                None => self.inner.distances(&pts, &p, &mut out)?,
            }
            Ok(out)
        })?;
        to_numpy(py, out, &[n, NUM_SEGMENTS])
    }

    /// Residuals (N,) = signed distance of each point to its labelled segment (label -1:
    /// residual 0) and the Jacobian (N, 22).
    fn residuals_and_jacobian<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
        labels: &Bound<'py, PyAny>,
        pose: &Bound<'py, PyAny>,
    ) -> PyResult<(F64Array<'py>, F64Array<'py>)> {
        let pts = points_arg(points)?;
        let lab = i64_array(labels, "labels", Some(1))?;
        if lab.data.len() != pts.len() {
            return Err(invalid(
                "labels",
                format!("has {} entries for {} points", lab.data.len(), pts.len()),
            ));
        }
        check_result_bytes(
            pts.len().checked_mul((NUM_PARAMS + 1) * 8),
            "points",
            "the residuals and Jacobian (N, 22)",
        )?;
        let lab: Vec<i32> = lab
            .data
            .iter()
            .map(|&l| l.clamp(i32::MIN as i64, i32::MAX as i64) as i32)
            .collect();
        let p = pose_arg(pose, "pose")?;
        let n = pts.len();
        let (r, j) = native(py, || -> crate::Result<(Vec<f64>, Vec<f64>)> {
            let (mut r, mut j) = (vec![0.0; n], vec![0.0; n * NUM_PARAMS]);
            self.inner
                .residuals_and_jacobian(&pts, &lab, &p, &mut r, &mut j)?;
            Ok((r, j))
        })?;
        Ok((to_numpy(py, r, &[n])?, to_numpy(py, j, &[n, NUM_PARAMS])?))
    }

    /// How badly each of `poses` (K, 22) explains the observed body in `depth` (H, W;
    /// metres, or uint16 millimetres) within `mask` (H, W bool): rendered and compared
    /// pixel by pixel (depth difference capped at `cap` metres; a foreground pixel with
    /// nothing rendered or a rendered pixel outside the mask costs `cap`), divided by
    /// `cap` × the foreground pixel count. (K,) float64, the poses rendered in parallel.
    #[pyo3(signature = (poses, depth, mask, camera, cap=Real::new(0.1)),
           text_signature = "($self, poses, depth, mask, camera, cap=0.1)")]
    fn depth_discrepancies<'py>(
        &self,
        py: Python<'py>,
        poses: &Bound<'py, PyAny>,
        depth: &Bound<'py, PyAny>,
        mask: &Bound<'py, PyAny>,
        camera: &Bound<'py, PyAny>,
        cap: Real,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let cam = camera_arg(camera, "camera")?;
        let cap = cap.get("cap")?;
        let d = depth_array(depth, "depth")?;
        let (h, w) = (d.shape[0], d.shape[1]);
        cam.check_image("depth", h, w)?;
        let m = bool_array(mask, "mask", &[h, w])?;
        let poses = poses_arg(poses, "poses")?;
        let out = native(py, || {
            self.inner
                .depth_discrepancies(&poses, &cam, &d.data, &m, cap)
        })?;
        let k = out.len();
        to_numpy(py, out, &[k])
    }

    /// Depth (H, W) float32 metres (0 = background) and part labels (H, W) int16
    /// (-1 = background) of the posed body seen by `camera`.
    fn render_depth<'py>(
        &self,
        py: Python<'py>,
        pose: &Bound<'py, PyAny>,
        camera: &Bound<'py, PyAny>,
    ) -> PyResult<(F32Array<'py>, I16Array<'py>)> {
        let cam = camera_arg(camera, "camera")?;
        check_image_pixels(cam.height, cam.width, "camera")?;
        let p = pose_arg(pose, "pose")?;
        let (d, l) = native_ok(py, || self.inner.render_depth(&p, &cam))?;
        let shape = [cam.height, cam.width];
        Ok((to_numpy(py, d, &shape)?, to_numpy(py, l, &shape)?))
    }

    /// Super-quadric surface meshes of the 16 segments, posed in the camera frame:
    /// a list of (vertices (V, 3) float64, faces (F, 3) int64), outward faces.
    #[pyo3(signature = (pose, rings=Int::new(20), sectors=Int::new(24)),
           text_signature = "($self, pose, rings=20, sectors=24)")]
    fn superquadric_meshes<'py>(
        &self,
        py: Python<'py>,
        pose: &Bound<'py, PyAny>,
        rings: Int,
        sectors: Int,
    ) -> PyResult<Vec<(F64Array<'py>, I64Array<'py>)>> {
        let (rings, sectors) = (rings.count("rings")?, sectors.count("sectors")?);
        check_mesh_bytes(rings, sectors, NUM_SEGMENTS)?;
        let p = pose_arg(pose, "pose")?;
        let meshes = native(py, || {
            self.inner
                .superquadric_meshes(&p, &MeshConfig { rings, sectors })
        })?;
        meshes
            .into_iter()
            .map(|m| {
                let nv = m.vertices.len();
                let nf = m.faces.len();
                let v: Vec<f64> = m.vertices.into_iter().flatten().collect();
                let f: Vec<i64> = m.faces.into_iter().flatten().map(|i| i as i64).collect();
                Ok((to_numpy(py, v, &[nv, 3])?, to_numpy(py, f, &[nf, 3])?))
            })
            .collect()
    }

    /// Ellipsoids of the posed body: centres (16, 3), rotations (16, 3, 3) (ellipsoid →
    /// camera) and half-axes (16, 3).
    fn ellipsoids<'py>(
        &self,
        py: Python<'py>,
        pose: &Bound<'py, PyAny>,
    ) -> PyResult<(F64Array<'py>, F64Array<'py>, F64Array<'py>)> {
        let p = pose_arg(pose, "pose")?;
        let kin = crate::body::Kinematics::new(&self.inner, &p);
        let placed = self.inner.placed_ellipsoids(&kin);
        let mut c = Vec::new();
        let mut r = Vec::new();
        let mut e = Vec::new();
        for pe in &placed {
            c.extend(pe.centre.iter());
            for i in 0..3 {
                for j in 0..3 {
                    r.push(pe.rotation[(i, j)]);
                }
            }
            e.extend(pe.prepared.radii().iter());
        }
        Ok((
            to_numpy(py, c, &[NUM_SEGMENTS, 3])?,
            to_numpy(py, r, &[NUM_SEGMENTS, 3, 3])?,
            to_numpy(py, e, &[NUM_SEGMENTS, 3])?,
        ))
    }

    /// Names of the shape factors of `with_shape_factors` and `fit_shape`.
    #[getter]
    fn shape_factor_names(&self) -> Vec<&'static str> {
        SHAPE_FACTOR_NAMES.to_vec()
    }

    /// A model whose shape is this one's with each factor group scaled (12 factors,
    /// `shape_factor_names` order, 1 = unchanged).
    fn with_shape_factors(&self, factors: &Bound<PyAny>) -> PyResult<Self> {
        let a = f64_array(factors, "factors", Some(1), true)?;
        Ok(PyBodyModel {
            inner: self.inner.with_shape_factors(&a.data)?,
        })
    }

    /// Calibrates the body shape on one or several frames: `depths` (list of (H, W) or
    /// (F, H, W); float metres or uint16 mm), `poses` (F, 22) initial poses, `masks`
    /// optional person masks. Alternates per-frame pose/label fits (hard EM) with a
    /// joint Levenberg-Marquardt over the shape factors and all poses for `iterations`
    /// rounds at most. Returns a `ShapeFitResult` (`model`, `factors`, `poses`, ...).
    #[pyo3(signature = (depths, camera, poses, **options),
           text_signature = "($self, depths, camera, poses, *, masks=None, iterations=3, \
                             config=None, lm_iterations=20, prior_weight=100000.0, \
                             bounds=None)")]
    fn fit_shape<'py>(
        &self,
        depths: &Bound<'py, PyAny>,
        camera: &Bound<'py, PyAny>,
        poses: &Bound<'py, PyAny>,
        options: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<PyShapeFitResult> {
        let ShapeKeywords {
            masks,
            iterations,
            config,
            lm_iterations,
            prior_weight,
            bounds,
        } = ShapeKeywords::parse("BodyModel.fit_shape", options)?;
        let cam = camera_arg(camera, "camera")?;
        let bounds = match &bounds {
            None => (0.7, 1.4),
            Some(b) => {
                let v = super::convert::reals(b, "bounds", Some(2))?;
                (v[0], v[1])
            }
        };
        let (h, w) = (cam.height, cam.width);
        let depth_items = frame_items(depths, "depths", 3)?;
        let mut ds = Vec::with_capacity(depth_items.len());
        for (i, d) in depth_items.iter().enumerate() {
            let name = format!("depths[{i}]");
            let a = depth_array(d, &name)?;
            cam.check_image(&name, a.shape[0], a.shape[1])?;
            ds.push(a.data);
        }
        let pose_items = frame_items(poses, "poses", 2)?;
        if pose_items.len() != ds.len() {
            return Err(invalid(
                "poses",
                format!(
                    "has {} poses for {} depth frames",
                    pose_items.len(),
                    ds.len()
                ),
            ));
        }
        let mut ps: Vec<Pose> = Vec::with_capacity(ds.len());
        for (i, p) in pose_items.iter().enumerate() {
            ps.push(pose_arg(p, &format!("poses[{i}]"))?);
        }
        let ms: Option<Vec<Vec<bool>>> = match &masks {
            None => None,
            Some(m) => {
                let items = frame_items(m, "masks", 3)?;
                if items.len() != ds.len() {
                    return Err(invalid(
                        "masks",
                        format!("has {} masks for {} depth frames", items.len(), ds.len()),
                    ));
                }
                Some(
                    items
                        .iter()
                        .enumerate()
                        .map(|(i, m)| bool_array(m, &format!("masks[{i}]"), &[h, w]))
                        .collect::<PyResult<_>>()?,
                )
            }
        };
        let mut points = 0;
        for (i, d) in ds.iter().enumerate() {
            let m = ms.as_ref().map(|m| m[i].as_slice());
            points = check_fit_points(d, m, points, "depths")?;
        }
        let cfg = ShapeConfig {
            fit: fit_config(config.as_ref(), "config")?,
            rounds: iterations.in_range(1, MAX_ROUNDS, "iterations")? as usize,
            lm_iterations: lm_iterations.in_range(1, MAX_ROUNDS, "lm_iterations")? as usize,
            lower: bounds.0,
            upper: bounds.1,
            prior_weight: prior_weight.get("prior_weight")?,
            ..ShapeConfig::default()
        };
        cfg.validate().map_err(|e| match e {
            Error::InvalidArgument { name, message } if name == "lower" || name == "upper" => {
                Error::invalid("bounds", format!("{name} {message}"))
            }
            other => other,
        })?;
        let base = self.inner.clone();
        let result = native(depths.py(), || {
            let frames: Vec<ShapeFrame> = ds
                .iter()
                .enumerate()
                .map(|(i, d)| ShapeFrame {
                    depth: d,
                    mask: ms.as_ref().map(|m| m[i].as_slice()),
                })
                .collect();
            fit::fit_shape(&frames, &cam, &base, &ps, &cfg)
        })?;
        Ok(PyShapeFitResult {
            result,
            height: h,
            width: w,
        })
    }

    fn __repr__(&self) -> String {
        format!(
            "BodyModel(standing_height={:.3})",
            self.inner.shape.standing_height()
        )
    }
}

/// Refuses meshes of `rings` × `sectors` divisions for `segments` segments whose
/// vertices and faces (with the copies made for Python) pass [`MAX_RESULT_BYTES`].
///
/// [`MAX_RESULT_BYTES`]: super::convert::MAX_RESULT_BYTES
pub(super) fn check_mesh_bytes(rings: usize, sectors: usize, segments: usize) -> PyResult<()> {
    // Per division a vertex (3 float64) and two faces (6 int64), each also copied once.
    let bytes = rings
        .checked_mul(sectors)
        .and_then(|d| d.checked_add(2 * rings + 2))
        .and_then(|d| d.checked_mul(segments))
        .and_then(|d| d.checked_mul(2 * (24 + 48)));
    check_result_bytes(bytes, "rings/sectors", "the meshes")
}

/// A (3, 3) rotation matrix argument, finite.
fn matrix_arg(value: &Bound<'_, PyAny>, name: &str) -> PyResult<nalgebra::Matrix3<f64>> {
    let a = f64_array(value, name, Some(2), true)?;
    if a.shape != [3, 3] {
        return Err(invalid(
            name,
            format!("expected a (3, 3) matrix, got shape {:?}", a.shape),
        ));
    }
    Ok(nalgebra::Matrix3::from_row_slice(&a.data))
}

/// A (3,) vector argument, finite.
fn vector_arg(value: &Bound<'_, PyAny>, name: &str) -> PyResult<nalgebra::Vector3<f64>> {
    let a = f64_array(value, name, Some(1), true)?;
    if a.data.len() != 3 {
        return Err(invalid(
            name,
            format!("needs 3 values, got {}", a.data.len()),
        ));
    }
    Ok(nalgebra::Vector3::new(a.data[0], a.data[1], a.data[2]))
}

/// The Euler angles (z, x, y) in degrees of a (3, 3) rotation matrix, R = Rz·Rx·Ry.
#[pyfunction]
fn _euler_zxy(matrix: &Bound<'_, PyAny>) -> PyResult<(f64, f64, f64)> {
    let [z, x, y] = rotation::euler_zxy_from_matrix(&matrix_arg(matrix, "matrix")?);
    Ok((z.to_degrees(), x.to_degrees(), y.to_degrees()))
}

/// Outcome of `BodyModel.fit_shape`: the calibrated model, its shape factors and the
/// fitted poses of the calibration frames.
#[pyclass(name = "ShapeFitResult", module = "depthpose._core")]
pub struct PyShapeFitResult {
    pub(crate) result: fit::ShapeResult,
    pub(crate) height: usize,
    pub(crate) width: usize,
}

#[pymethods]
impl PyShapeFitResult {
    /// The base model with the fitted shape.
    #[getter]
    fn model(&self) -> PyBodyModel {
        PyBodyModel {
            inner: self.result.model.clone(),
        }
    }
    /// The shape factors (12,) relative to the base model, `factor_names` order.
    #[getter]
    fn factors<'py>(&self, py: Python<'py>) -> PyResult<F64Array<'py>> {
        to_numpy(py, self.result.factors.to_vec(), &[NUM_SHAPE_FACTORS])
    }
    /// Names of the shape factors.
    #[getter]
    fn factor_names(&self) -> Vec<&'static str> {
        SHAPE_FACTOR_NAMES.to_vec()
    }
    /// The factors as a {name: value} dict.
    fn factors_dict(&self) -> HashMap<&'static str, f64> {
        SHAPE_FACTOR_NAMES
            .iter()
            .copied()
            .zip(self.result.factors)
            .collect()
    }
    /// The fitted pose of every frame (F, 22).
    #[getter]
    fn poses<'py>(&self, py: Python<'py>) -> PyResult<F64Array<'py>> {
        let n = self.result.poses.len();
        let v = self.result.poses.iter().flatten().copied().collect();
        to_numpy(py, v, &[n, NUM_PARAMS])
    }
    /// The joints of every frame (F, 15, 3) with the fitted model, camera frame.
    #[getter]
    fn joints<'py>(&self, py: Python<'py>) -> PyResult<F64Array<'py>> {
        let n = self.result.joints.len();
        joints_to_numpy(py, self.result.joints.iter().flatten(), &[n, NUM_JOINTS, 3])
    }
    /// Part labels of every frame (F, H, W) int16: segment 0..15, −1 = background or
    /// outlier.
    #[getter]
    fn labels<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<i16>>> {
        let n = self.result.labels.len();
        let v = self.result.labels.iter().flatten().copied().collect();
        to_numpy(py, v, &[n, self.height, self.width])
    }
    /// The final energy (sum over the frames plus the shape prior).
    #[getter]
    fn energy(&self) -> f64 {
        self.result.energy
    }
    /// The energy after every pose/label step and every shape step (non-increasing).
    #[getter]
    fn energy_trace<'py>(&self, py: Python<'py>) -> PyResult<F64Array<'py>> {
        let n = self.result.energy_trace.len();
        to_numpy(py, self.result.energy_trace.clone(), &[n])
    }
    /// Rounds of pose/label step + shape step run.
    #[getter]
    fn rounds(&self) -> usize {
        self.result.rounds
    }
    fn __repr__(&self) -> String {
        let f: Vec<String> = SHAPE_FACTOR_NAMES
            .iter()
            .zip(self.result.factors)
            .map(|(n, v)| format!("{n}={v:.3}"))
            .collect();
        format!(
            "ShapeFitResult(frames={}, energy={:.4}, rounds={}, {})",
            self.result.poses.len(),
            self.result.energy,
            self.result.rounds,
            f.join(", ")
        )
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyBodyModel>()?;
    m.add_class::<PyShapeFitResult>()?;
    m.add_function(wrap_pyfunction!(_euler_zxy, m)?)
}
