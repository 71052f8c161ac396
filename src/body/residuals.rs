//! Point-to-ellipsoid distances of a cloud to the posed body, and the residuals and
//! Jacobian of the model fit.

use super::ellipsoid::{PlacedEllipsoid, Prepared, SortedPlacement};
use super::kinematics::{Kinematics, SEGMENT_DOFS};
use super::{param, BodyModel, Pose, NUM_PARAMS, NUM_SEGMENTS};
use crate::error::{Error, Result};
use rayon::prelude::*;

/// Points per rayon task: large enough to amortise scheduling.
const CHUNK_POINTS: usize = 256;
/// At most this many parameters move one segment (root 6 + shoulder/hip 3 + elbow/knee 1).
pub const MAX_SEGMENT_DOFS: usize = 10;

/// Everything the per-point hot loops need at one pose, computed once per pose: the
/// segment ellipsoids with their axis sort folded into the rotation, and for each
/// segment the parameters that move it with the data of their Jacobian entries.
///
/// Moving the surface with velocity v at p changes the signed distance by −n·v. For a
/// rotation about unit axis a through pivot c, v = a × (p − c), so
/// −n·v = n·(a × c) − a·(p × n): with m = p × n computed once per point, each entry is
/// two dot products. For a translation along a, −n·v = −n·a. Both are n·w − a'·m with
/// (a', w) = (a, a × c) or (0, −a), precomputed per parameter.
#[derive(Debug, Clone)]
pub struct PoseGeometry {
    pub kinematics: Kinematics,
    pub segments: [SortedPlacement; NUM_SEGMENTS],
    /// Per segment: its parameters (ascending) and how many there are.
    dofs: [([usize; MAX_SEGMENT_DOFS], usize); NUM_SEGMENTS],
    /// Per parameter: a' and w (see above).
    axis: [[f64; 3]; NUM_PARAMS],
    moment: [[f64; 3]; NUM_PARAMS],
}

/// The first `pts.len()` entries of `buf` set to `pts` in f64 (`pts.len()` ≤ buf's).
#[inline]
pub fn to_f64<'a>(pts: &[[f32; 3]], buf: &'a mut [[f64; 3]]) -> &'a [[f64; 3]] {
    for (b, p) in buf.iter_mut().zip(pts) {
        *b = [p[0] as f64, p[1] as f64, p[2] as f64];
    }
    &buf[..pts.len()]
}

/// [`BodyModel::distances`] (`cap` None) or [`BodyModel::distances_capped`] of one
/// chunk of at most [`CHUNK_POINTS`] points, `out` its N×[`NUM_SEGMENTS`] rows.
fn distances_chunk(geo: &PoseGeometry, pts: &[[f32; 3]], cap: Option<f64>, out: &mut [f32]) {
    let n = pts.len();
    let mut soa = [[0.0f32; CHUNK_POINTS]; 3];
    for (i, p) in pts.iter().enumerate() {
        for (c, &v) in soa.iter_mut().zip(p) {
            c[i] = v;
        }
    }
    let [px, py, pz] = &soa;
    let mut dist = [0.0f32; CHUNK_POINTS];
    for (k, e) in geo.segments.iter().enumerate() {
        e.signed_distances_camera_soa_f32([px, py, pz], cap, &mut dist[..n]);
        for (i, &d) in dist[..n].iter().enumerate() {
            out[i * NUM_SEGMENTS + k] = d;
        }
    }
}

/// Counting sort by segment: the indices of the points whose label is a segment
/// (labels outside 0..[`NUM_SEGMENTS`] are skipped) grouped by segment, ascending within
/// each, written to the front of `order` (which must hold `labels.len()` entries).
/// Returns where each segment's run starts: segment k's points are
/// `order[start[k]..start[k + 1]]`.
pub fn group_by_segment(labels: &[i32], order: &mut [u32]) -> [usize; NUM_SEGMENTS + 1] {
    let segment = |l: i32| (l >= 0 && (l as usize) < NUM_SEGMENTS).then_some(l as usize);
    let mut start = [0usize; NUM_SEGMENTS + 1];
    for k in labels.iter().filter_map(|&l| segment(l)) {
        start[k + 1] += 1;
    }
    for k in 0..NUM_SEGMENTS {
        start[k + 1] += start[k];
    }
    let mut next = start;
    for (i, k) in labels
        .iter()
        .enumerate()
        .filter_map(|(i, &l)| Some((i, segment(l)?)))
    {
        order[next[k]] = i as u32;
        next[k] += 1;
    }
    start
}

#[inline]
fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// a × b.
#[inline]
pub fn cross(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

impl PoseGeometry {
    pub fn new(model: &BodyModel, pose: &Pose) -> Self {
        let kinematics = Kinematics::new(model, pose);
        let placed = model.placed_ellipsoids(&kinematics);
        let segments = std::array::from_fn(|k| SortedPlacement::new(&placed[k]));
        let dofs = std::array::from_fn(|k| {
            let mut idx = [0usize; MAX_SEGMENT_DOFS];
            let mut n = 0;
            for dof in (0..NUM_PARAMS).filter(|d| SEGMENT_DOFS[k] & (1 << d) != 0) {
                idx[n] = dof;
                n += 1;
            }
            (idx, n)
        });
        let mut axis = [[0.0; 3]; NUM_PARAMS];
        let mut moment = [[0.0; 3]; NUM_PARAMS];
        for dof in 0..NUM_PARAMS {
            let a = kinematics.dof_axis[dof];
            let a = [a.x, a.y, a.z];
            if dof < param::ROOT_R {
                moment[dof] = [-a[0], -a[1], -a[2]];
            } else {
                let c = kinematics.dof_pivot[dof];
                moment[dof] = cross(&a, &[c.x, c.y, c.z]);
                axis[dof] = a;
            }
        }
        PoseGeometry {
            kinematics,
            segments,
            dofs,
            axis,
            moment,
        }
    }

    /// The parameters that move segment `k` (ascending).
    #[inline]
    pub fn segment_dofs(&self, k: usize) -> &[usize] {
        let (idx, n) = &self.dofs[k];
        &idx[..*n]
    }

    /// The 6-vector b of parameter `dof` such that d(signed distance)/d(dof) = q·b for
    /// q = (n, p × n) (see the type's comment): b = (w, −a'). So the Jacobian of a
    /// segment's points is Q·B (Q: one row q per point, B: one column b per parameter)
    /// and JᵀJ = Bᵀ(QᵀQ)B: the points need only the 6×6 QᵀQ.
    #[inline]
    pub fn dof_basis(&self, dof: usize) -> [f64; 6] {
        let (w, a) = (&self.moment[dof], &self.axis[dof]);
        [w[0], w[1], w[2], -a[0], -a[1], -a[2]]
    }

    /// d(signed distance)/d(parameter) of a point `p` on segment `k` whose closest-point
    /// normal is `n`, for the parameters of [`Self::segment_dofs`] in that order
    /// (written to the first entries of `out`; returns how many).
    #[inline]
    pub fn jacobian_row(
        &self,
        k: usize,
        p: &[f64; 3],
        n: &[f64; 3],
        out: &mut [f64; MAX_SEGMENT_DOFS],
    ) -> usize {
        let m = cross(p, n);
        let (idx, count) = &self.dofs[k];
        for (o, &dof) in out.iter_mut().zip(&idx[..*count]) {
            *o = dot(n, &self.moment[dof]) - dot(&self.axis[dof], &m);
        }
        *count
    }
}

impl BodyModel {
    /// The segment ellipsoids placed in the camera frame for the frames of `kin`.
    pub fn placed_ellipsoids(&self, kin: &Kinematics) -> [PlacedEllipsoid; NUM_SEGMENTS] {
        let ell = self.shape.ellipsoids();
        std::array::from_fn(|k| {
            let f = &kin.frames[k];
            PlacedEllipsoid {
                centre: f.transform_point(&ell[k].centre.into()).coords,
                rotation: *f.rotation.to_rotation_matrix().matrix(),
                prepared: Prepared::new(&ell[k].radii),
            }
        })
    }

    /// Signed distances (negative inside) of every point to every segment ellipsoid:
    /// `out` is N×[`NUM_SEGMENTS`] row-major. The points and results are f32, and so
    /// is the solve where the CPU has AVX-512 or AVX2 (within ~3e-7 × max(1 m, |d|) of
    /// the f64 solve, see [`SortedPlacement::signed_distances_camera_soa_f32`]); the fit
    /// uses the f64 solver.
    pub fn distances(&self, points: &[[f32; 3]], pose: &Pose, out: &mut [f32]) -> Result<()> {
        if out.len() != points.len() * NUM_SEGMENTS {
            return Err(Error::invalid(
                "out",
                format!(
                    "needs {} values for {} points, got {}",
                    points.len() * NUM_SEGMENTS,
                    points.len(),
                    out.len()
                ),
            ));
        }
        let geo = PoseGeometry::new(self, pose);
        out.par_chunks_mut(CHUNK_POINTS * NUM_SEGMENTS)
            .zip(points.par_chunks(CHUNK_POINTS))
            .for_each(|(o, pts)| distances_chunk(&geo, pts, None, o));
        Ok(())
    }

    /// Like [`BodyModel::distances`], but exact only where it matters for truncated
    /// costs: when a cheap lower bound (the larger of the bounding-sphere bound and the
    /// scaled-radii bound, see [`SortedPlacement::distance_lower_bound`]) already
    /// reaches `cap`, that bound is written instead of the exact distance. So
    /// every value below `cap` is exact (the value [`BodyModel::distances`] gives) and
    /// every value ≥ `cap` means "at least `cap`". Faster when most points are far
    /// from most segments.
    pub fn distances_capped(
        &self,
        points: &[[f32; 3]],
        pose: &Pose,
        cap: f64,
        out: &mut [f32],
    ) -> Result<()> {
        if cap.is_nan() || cap <= 0.0 {
            return Err(Error::invalid(
                "cap",
                format!("must be positive, got {cap}"),
            ));
        }
        if out.len() != points.len() * NUM_SEGMENTS {
            return Err(Error::invalid(
                "out",
                format!(
                    "needs {} values for {} points, got {}",
                    points.len() * NUM_SEGMENTS,
                    points.len(),
                    out.len()
                ),
            ));
        }
        let geo = PoseGeometry::new(self, pose);
        out.par_chunks_mut(CHUNK_POINTS * NUM_SEGMENTS)
            .zip(points.par_chunks(CHUNK_POINTS))
            .for_each(|(o, pts)| distances_chunk(&geo, pts, Some(cap), o));
        Ok(())
    }

    /// Residuals and Jacobian of the fit: for a point with label k ≥ 0 the residual is
    /// its signed distance to segment k's ellipsoid and its Jacobian row is
    /// d(residual)/d(pose) (22 columns; root rotation columns with respect to the
    /// body-frame increment ω, R ← R·exp(\[ω\]×)). Points with label −1 get a zero
    /// residual and a zero row. `jacobian_out` is N×22 row-major.
    pub fn residuals_and_jacobian(
        &self,
        points: &[[f32; 3]],
        labels: &[i32],
        pose: &Pose,
        residuals_out: &mut [f64],
        jacobian_out: &mut [f64],
    ) -> Result<()> {
        let n = points.len();
        if labels.len() != n {
            return Err(Error::invalid(
                "labels",
                format!("has {} entries for {n} points", labels.len()),
            ));
        }
        if let Some(bad) = labels.iter().find(|&&l| l < -1 || l >= NUM_SEGMENTS as i32) {
            return Err(Error::invalid(
                "labels",
                format!("must be -1 (skip) or a segment 0..{NUM_SEGMENTS}, got {bad}"),
            ));
        }
        if residuals_out.len() != n {
            return Err(Error::invalid(
                "residuals_out",
                format!("needs {n} values, got {}", residuals_out.len()),
            ));
        }
        if jacobian_out.len() != n * NUM_PARAMS {
            return Err(Error::invalid(
                "jacobian_out",
                format!(
                    "needs {} values, got {}",
                    n * NUM_PARAMS,
                    jacobian_out.len()
                ),
            ));
        }
        let geo = PoseGeometry::new(self, pose);
        residuals_out
            .par_chunks_mut(CHUNK_POINTS)
            .zip(jacobian_out.par_chunks_mut(CHUNK_POINTS * NUM_PARAMS))
            .zip(
                points
                    .par_chunks(CHUNK_POINTS)
                    .zip(labels.par_chunks(CHUNK_POINTS)),
            )
            .for_each(|((res, jac), (pts, labs))| {
                res.fill(0.0);
                jac.fill(0.0);
                // The chunk's labelled points grouped by segment, so each segment's
                // distances go through the lockstep root-finder.
                let mut order = [0u32; CHUNK_POINTS];
                let start = group_by_segment(labs, &mut order);
                let vec3 = |i: usize| [pts[i][0] as f64, pts[i][1] as f64, pts[i][2] as f64];
                for (k, e) in geo.segments.iter().enumerate() {
                    let run = &order[start[k]..start[k + 1]];
                    let items = run
                        .iter()
                        .map(|&i| (i as usize, e.local(&vec3(i as usize))));
                    e.distances_and_normals_batched(items, |i, d, normal| {
                        res[i] = d;
                        let mut j = [0.0; MAX_SEGMENT_DOFS];
                        let count = geo.jacobian_row(k, &vec3(i), &normal, &mut j);
                        let row = &mut jac[i * NUM_PARAMS..(i + 1) * NUM_PARAMS];
                        for (&dof, v) in geo.segment_dofs(k).iter().zip(&j[..count]) {
                            row[dof] = *v;
                        }
                    });
                }
            });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::kinematics::tests::pose_for_tests;
    use super::super::*;
    use nalgebra::Vector3;

    fn cloud_around(model: &BodyModel, pose: &Pose, n: usize, seed: u64) -> Vec<[f32; 3]> {
        // Points scattered around the joints (inside and outside the ellipsoids).
        let joints = model.joints(pose);
        let mut state = seed | 1;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state % 10_000) as f64 / 10_000.0 - 0.5
        };
        (0..n)
            .map(|i| {
                let j = joints[i % NUM_JOINTS];
                [
                    (j.x + 0.3 * next()) as f32,
                    (j.y + 0.3 * next()) as f32,
                    (j.z + 0.3 * next()) as f32,
                ]
            })
            .collect()
    }

    #[test]
    fn distances_match_single_queries() {
        let m = BodyModel::default();
        let pose = pose_for_tests(7);
        let pts = cloud_around(&m, &pose, 500, 3);
        let mut out = vec![0.0f32; pts.len() * NUM_SEGMENTS];
        m.distances(&pts, &pose, &mut out).unwrap();
        let frames = m.segment_transforms(&pose);
        let ell = m.shape.ellipsoids();
        for (i, p) in pts.iter().enumerate() {
            for k in 0..NUM_SEGMENTS {
                let pc = nalgebra::Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                let local = frames[k].inverse_transform_point(&pc).coords - ell[k].centre;
                let d = signed_distance_to_ellipsoid(&ell[k].radii, &local);
                assert!((out[i * NUM_SEGMENTS + k] as f64 - d).abs() < 1e-5);
            }
        }
        assert!(m.distances(&pts, &pose, &mut out[1..]).is_err());
        // Capped: exact below the cap, a valid lower bound at or above it.
        let mut capped = vec![0.0f32; out.len()];
        m.distances_capped(&pts, &pose, 0.1, &mut capped).unwrap();
        let mut n_capped = 0;
        for (c, e) in capped.iter().zip(&out) {
            if *c < 0.1 {
                assert_eq!(c, e);
            } else {
                n_capped += (c != e) as usize;
                assert!(*c >= 0.1 && *c <= *e + 1e-6);
            }
        }
        assert!(n_capped > 0);
        assert!(m.distances_capped(&pts, &pose, 0.0, &mut capped).is_err());
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let m = BodyModel::default();
        for seed in 0..4 {
            let pose = pose_for_tests(seed + 11);
            let pts = cloud_around(&m, &pose, 64, seed + 5);
            let labels: Vec<i32> = (0..pts.len())
                .map(|i| {
                    if i % 9 == 8 {
                        -1
                    } else {
                        (i % NUM_SEGMENTS) as i32
                    }
                })
                .collect();
            let n = pts.len();
            let (mut r, mut jac) = (vec![0.0; n], vec![0.0; n * NUM_PARAMS]);
            m.residuals_and_jacobian(&pts, &labels, &pose, &mut r, &mut jac)
                .unwrap();
            let h = 1e-6;
            let (mut rp, mut rm, mut scratch) =
                (vec![0.0; n], vec![0.0; n], vec![0.0; n * NUM_PARAMS]);
            for dof in 0..NUM_PARAMS {
                let (plus, minus) = if (3..6).contains(&dof) {
                    let mut w = Vector3::zeros();
                    w[dof - 3] = h;
                    (
                        pose_with_root_increment(&pose, &w),
                        pose_with_root_increment(&pose, &-w),
                    )
                } else {
                    let (mut a, mut b) = (pose, pose);
                    a[dof] += h;
                    b[dof] -= h;
                    (a, b)
                };
                m.residuals_and_jacobian(&pts, &labels, &plus, &mut rp, &mut scratch)
                    .unwrap();
                m.residuals_and_jacobian(&pts, &labels, &minus, &mut rm, &mut scratch)
                    .unwrap();
                for i in 0..n {
                    let fd = (rp[i] - rm[i]) / (2.0 * h);
                    let an = jac[i * NUM_PARAMS + dof];
                    assert!(
                        (an - fd).abs() <= 1e-4 * an.abs().max(fd.abs()).max(1e-3),
                        "point {i} label {} dof {dof}: analytic {an} vs fd {fd}",
                        labels[i]
                    );
                }
            }
            for (i, &l) in labels.iter().enumerate() {
                if l < 0 {
                    assert_eq!(r[i], 0.0);
                    assert!(jac[i * NUM_PARAMS..(i + 1) * NUM_PARAMS]
                        .iter()
                        .all(|v| *v == 0.0));
                }
            }
        }
    }

    /// Residuals and Jacobian rows over many chunks (the segments' points through the
    /// lockstep root-finder) equal the one-point queries bit for bit.
    #[test]
    fn batched_residuals_equal_single_queries() {
        use super::{PoseGeometry, MAX_SEGMENT_DOFS};
        let m = BodyModel::default();
        let pose = pose_for_tests(7);
        let pts = cloud_around(&m, &pose, 3000, 3);
        let labels: Vec<i32> = (0..pts.len())
            .map(|i| {
                if i % 11 == 10 {
                    -1
                } else {
                    ((i * 7) % NUM_SEGMENTS) as i32
                }
            })
            .collect();
        let n = pts.len();
        let (mut r, mut jac) = (vec![0.0; n], vec![0.0; n * NUM_PARAMS]);
        m.residuals_and_jacobian(&pts, &labels, &pose, &mut r, &mut jac)
            .unwrap();
        let geo = PoseGeometry::new(&m, &pose);
        for (i, &l) in labels.iter().enumerate().filter(|(_, &l)| l >= 0) {
            let k = l as usize;
            let p = [pts[i][0] as f64, pts[i][1] as f64, pts[i][2] as f64];
            let (d, normal) = geo.segments[k].distance_and_normal(&p);
            assert_eq!(r[i].to_bits(), d.to_bits(), "point {i}");
            let mut j = [0.0; MAX_SEGMENT_DOFS];
            let count = geo.jacobian_row(k, &p, &normal, &mut j);
            let mut row = [0.0; NUM_PARAMS];
            for (&dof, v) in geo.segment_dofs(k).iter().zip(&j[..count]) {
                row[dof] = *v;
            }
            assert_eq!(
                &jac[i * NUM_PARAMS..(i + 1) * NUM_PARAMS],
                &row[..],
                "point {i}"
            );
        }
    }

    #[test]
    fn rejects_bad_labels() {
        let m = BodyModel::default();
        let pose = BodyModel::neutral_pose();
        let pts = [[0.0f32, 0.0, 3.0]; 2];
        let (mut r, mut j) = (vec![0.0; 2], vec![0.0; 2 * NUM_PARAMS]);
        let e = m
            .residuals_and_jacobian(&pts, &[0, 16], &pose, &mut r, &mut j)
            .unwrap_err();
        assert!(e.to_string().starts_with("labels"));
        assert!(m
            .residuals_and_jacobian(&pts, &[0], &pose, &mut r, &mut j)
            .is_err());
    }
}
