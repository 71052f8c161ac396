//! `BodyModel` for Python: kinematics, distances, Jacobians, rendering, meshes.

use super::arrays::{f32_array, f64_array, i64_array, to_numpy};
use super::camera::PyCamera;
use crate::body::superquadric::MeshConfig;
use crate::body::{
    pose_from_slice, pose_with_root_increment, BodyModel, BodyShape, Pose, JOINT_NAMES, NUM_JOINTS,
    NUM_PARAMS, NUM_SEGMENTS, PARAM_NAMES, PART_NAMES, SHAPE_PARAM_NAMES,
};
use crate::error::Error;
use numpy::PyArrayDyn;
use pyo3::prelude::*;

type F64Array<'py> = Bound<'py, PyArrayDyn<f64>>;
type F32Array<'py> = Bound<'py, PyArrayDyn<f32>>;
type I16Array<'py> = Bound<'py, PyArrayDyn<i16>>;
type I64Array<'py> = Bound<'py, PyArrayDyn<i64>>;

fn pose_arg(obj: &Bound<PyAny>, name: &str) -> PyResult<Pose> {
    let a = f64_array(obj, name, Some(1), true)?;
    Ok(pose_from_slice(&a.data, name)?)
}

fn points_arg(obj: &Bound<PyAny>) -> PyResult<Vec<[f32; 3]>> {
    let a = f32_array(obj, "points", Some(2), true)?;
    if a.shape[1] != 3 {
        return Err(Error::invalid(
            "points",
            format!("expected shape (N, 3), got {:?}", a.shape),
        )
        .into());
    }
    Ok(a.data.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// The articulated 16-segment, 22-parameter body model (see the Rust docs of
/// `depthpose::body` for frames, parameters and joint axes).
#[pyclass(name = "BodyModel", module = "depthpose._core")]
#[derive(Clone)]
pub struct PyBodyModel {
    pub inner: BodyModel,
}

#[pymethods]
impl PyBodyModel {
    /// A body `height` metres tall with reference proportions.
    #[new]
    #[pyo3(signature = (height=1.75))]
    fn new(height: f64) -> PyResult<Self> {
        Ok(PyBodyModel {
            inner: BodyModel::new(height)?,
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
    fn lower_bounds<'py>(&self, py: Python<'py>) -> F64Array<'py> {
        to_numpy(py, BodyModel::lower_bounds().to_vec(), &[NUM_PARAMS])
    }
    /// Upper bounds of the pose (22,), +inf for the free root.
    #[getter]
    fn upper_bounds<'py>(&self, py: Python<'py>) -> F64Array<'py> {
        to_numpy(py, BodyModel::upper_bounds().to_vec(), &[NUM_PARAMS])
    }
    /// The shape parameters (metres) in `shape_names` order.
    #[getter]
    fn get_shape<'py>(&self, py: Python<'py>) -> F64Array<'py> {
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
    fn neutral_pose<'py>(py: Python<'py>) -> F64Array<'py> {
        to_numpy(py, BodyModel::neutral_pose().to_vec(), &[NUM_PARAMS])
    }

    /// `pose` with its joint angles clamped into the limits.
    fn clamp_pose<'py>(
        &self,
        py: Python<'py>,
        pose: &Bound<'py, PyAny>,
    ) -> PyResult<F64Array<'py>> {
        let p = pose_arg(pose, "pose")?;
        Ok(to_numpy(
            py,
            BodyModel::clamp_pose(&p).to_vec(),
            &[NUM_PARAMS],
        ))
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
        let w = f64_array(omega, "omega", Some(1), true)?;
        if w.data.len() != 3 {
            return Err(
                Error::invalid("omega", format!("needs 3 values, got {}", w.data.len())).into(),
            );
        }
        let q =
            pose_with_root_increment(&p, &nalgebra::Vector3::new(w.data[0], w.data[1], w.data[2]));
        Ok(to_numpy(py, q.to_vec(), &[NUM_PARAMS]))
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
        Ok(to_numpy(py, out, &[NUM_SEGMENTS, 4, 4]))
    }

    /// The 15 joints (15, 3) in the camera frame, ITOP order.
    fn joints<'py>(&self, py: Python<'py>, pose: &Bound<'py, PyAny>) -> PyResult<F64Array<'py>> {
        let p = pose_arg(pose, "pose")?;
        let j = self.inner.joints(&p);
        let out: Vec<f64> = j.iter().flat_map(|v| [v.x, v.y, v.z]).collect();
        Ok(to_numpy(py, out, &[NUM_JOINTS, 3]))
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
        Ok(to_numpy(py, out.to_vec(), &[NUM_JOINTS, 3, NUM_PARAMS]))
    }

    /// Signed distances (N, 16) float32 of points (N, 3) to every segment ellipsoid
    /// (negative inside). With `cap`, values are exact below `cap` and only a lower
    /// bound (>= cap) above it, which is much faster.
    #[pyo3(signature = (points, pose, cap=None))]
    fn distances<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
        pose: &Bound<'py, PyAny>,
        cap: Option<f64>,
    ) -> PyResult<F32Array<'py>> {
        let pts = points_arg(points)?;
        let p = pose_arg(pose, "pose")?;
        let n = pts.len();
        let out = py.detach(|| -> crate::Result<Vec<f32>> {
            let mut out = vec![0.0f32; n * NUM_SEGMENTS];
            match cap {
                Some(c) => self.inner.distances_capped(&pts, &p, c, &mut out)?,
                None => self.inner.distances(&pts, &p, &mut out)?,
            }
            Ok(out)
        })?;
        Ok(to_numpy(py, out, &[n, NUM_SEGMENTS]))
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
            return Err(Error::invalid(
                "labels",
                format!("has {} entries for {} points", lab.data.len(), pts.len()),
            )
            .into());
        }
        let lab: Vec<i32> = lab
            .data
            .iter()
            .map(|&l| l.clamp(i32::MIN as i64, i32::MAX as i64) as i32)
            .collect();
        let p = pose_arg(pose, "pose")?;
        let n = pts.len();
        let (r, j) = py.detach(|| -> crate::Result<(Vec<f64>, Vec<f64>)> {
            let (mut r, mut j) = (vec![0.0; n], vec![0.0; n * NUM_PARAMS]);
            self.inner
                .residuals_and_jacobian(&pts, &lab, &p, &mut r, &mut j)?;
            Ok((r, j))
        })?;
        Ok((to_numpy(py, r, &[n]), to_numpy(py, j, &[n, NUM_PARAMS])))
    }

    /// Depth (H, W) float32 metres (0 = background) and part labels (H, W) int16
    /// (-1 = background) of the posed body seen by `camera`.
    fn render_depth<'py>(
        &self,
        py: Python<'py>,
        pose: &Bound<'py, PyAny>,
        camera: &PyCamera,
    ) -> PyResult<(F32Array<'py>, I16Array<'py>)> {
        let p = pose_arg(pose, "pose")?;
        let cam = camera.inner;
        let (d, l) = py.detach(|| self.inner.render_depth(&p, &cam));
        let shape = [cam.height, cam.width];
        Ok((to_numpy(py, d, &shape), to_numpy(py, l, &shape)))
    }

    /// Super-quadric surface meshes of the 16 segments, posed in the camera frame:
    /// a list of (vertices (V, 3) float64, faces (F, 3) int64), outward faces.
    #[pyo3(signature = (pose, rings=20, sectors=24))]
    fn superquadric_meshes<'py>(
        &self,
        py: Python<'py>,
        pose: &Bound<'py, PyAny>,
        rings: usize,
        sectors: usize,
    ) -> PyResult<Vec<(F64Array<'py>, I64Array<'py>)>> {
        let p = pose_arg(pose, "pose")?;
        if !(3..=1000).contains(&rings) || !(3..=1000).contains(&sectors) {
            return Err(Error::invalid(
                "rings/sectors",
                format!("must be within 3..=1000, got {rings} and {sectors}"),
            )
            .into());
        }
        let meshes = self
            .inner
            .superquadric_meshes(&p, &MeshConfig { rings, sectors })?;
        Ok(meshes
            .into_iter()
            .map(|m| {
                let nv = m.vertices.len();
                let nf = m.faces.len();
                let v: Vec<f64> = m.vertices.into_iter().flatten().collect();
                let f: Vec<i64> = m.faces.into_iter().flatten().map(|i| i as i64).collect();
                (to_numpy(py, v, &[nv, 3]), to_numpy(py, f, &[nf, 3]))
            })
            .collect())
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
            to_numpy(py, c, &[NUM_SEGMENTS, 3]),
            to_numpy(py, r, &[NUM_SEGMENTS, 3, 3]),
            to_numpy(py, e, &[NUM_SEGMENTS, 3]),
        ))
    }

    fn __repr__(&self) -> String {
        format!(
            "BodyModel(standing_height={:.3})",
            self.inner.shape.standing_height()
        )
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyBodyModel>()
}
