//! Point-to-ellipsoid distances of a cloud to the posed body, and the residuals and
//! Jacobian of the model fit.

use super::ellipsoid::{PlacedEllipsoid, Prepared};
use super::kinematics::{Kinematics, SEGMENT_DOFS};
use super::{BodyModel, Pose, NUM_PARAMS, NUM_SEGMENTS};
use crate::error::{Error, Result};
use nalgebra::Vector3;
use rayon::prelude::*;

/// Points per rayon task: large enough to amortise scheduling.
const CHUNK_POINTS: usize = 256;

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

    fn placed(&self, pose: &Pose) -> (Kinematics, [PlacedEllipsoid; NUM_SEGMENTS]) {
        let kin = Kinematics::new(self, pose);
        let placed = self.placed_ellipsoids(&kin);
        (kin, placed)
    }

    /// Signed distances (negative inside) of every point to every segment ellipsoid:
    /// `out` is N×[`NUM_SEGMENTS`] row-major.
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
        let (_, placed) = self.placed(pose);
        out.par_chunks_mut(CHUNK_POINTS * NUM_SEGMENTS)
            .zip(points.par_chunks(CHUNK_POINTS))
            .for_each(|(o, pts)| {
                for (row, p) in o.chunks_exact_mut(NUM_SEGMENTS).zip(pts) {
                    let p = Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                    for (d, e) in row.iter_mut().zip(&placed) {
                        *d = e.signed_distance(&p) as f32;
                    }
                }
            });
        Ok(())
    }

    /// Like [`BodyModel::distances`], but exact only where it matters for truncated
    /// costs: when a cheap lower bound (distance to the ellipsoid's bounding sphere)
    /// already reaches `cap`, that bound is written instead of the exact distance. So
    /// every value below `cap` is exact and every value ≥ `cap` means "at least `cap`".
    /// Much faster when most points are far from most segments.
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
        let (_, placed) = self.placed(pose);
        let bound: [f64; NUM_SEGMENTS] = std::array::from_fn(|k| placed[k].prepared.radii().max());
        out.par_chunks_mut(CHUNK_POINTS * NUM_SEGMENTS)
            .zip(points.par_chunks(CHUNK_POINTS))
            .for_each(|(o, pts)| {
                for (row, p) in o.chunks_exact_mut(NUM_SEGMENTS).zip(pts) {
                    let p = Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                    for ((d, e), r) in row.iter_mut().zip(&placed).zip(&bound) {
                        let lower = (p - e.centre).norm() - r;
                        *d = if lower >= cap {
                            lower as f32
                        } else {
                            e.signed_distance(&p) as f32
                        };
                    }
                }
            });
        Ok(())
    }

    /// Residuals and Jacobian of the fit: for a point with label k ≥ 0 the residual is
    /// its signed distance to segment k's ellipsoid and its Jacobian row is
    /// d(residual)/d(pose) (22 columns; root rotation columns with respect to the
    /// body-frame increment ω, R ← R·exp([ω]×)). Points with label −1 get a zero
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
        let (kin, placed) = self.placed(pose);
        residuals_out
            .par_chunks_mut(CHUNK_POINTS)
            .zip(jacobian_out.par_chunks_mut(CHUNK_POINTS * NUM_PARAMS))
            .zip(
                points
                    .par_chunks(CHUNK_POINTS)
                    .zip(labels.par_chunks(CHUNK_POINTS)),
            )
            .for_each(|((res, jac), (pts, labs))| {
                for (i, (p, &label)) in pts.iter().zip(labs).enumerate() {
                    let row = &mut jac[i * NUM_PARAMS..(i + 1) * NUM_PARAMS];
                    row.fill(0.0);
                    if label < 0 {
                        res[i] = 0.0;
                        continue;
                    }
                    let k = label as usize;
                    let p = Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                    let q = placed[k].query(&p);
                    res[i] = q.distance;
                    // Moving the segment with velocity v at p changes the distance by −n·v.
                    let mask = SEGMENT_DOFS[k];
                    for (dof, out) in row.iter_mut().enumerate() {
                        if mask & (1 << dof) != 0 {
                            *out = -q.normal.dot(&kin.point_velocity(dof, &p));
                        }
                    }
                }
            });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::kinematics::tests::pose_for_tests;
    use super::super::*;
    use super::*;

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
