//! Depth and part-label rendering of the posed ellipsoid body by analytic ray casting.
//!
//! The ray through pixel (u, v) is p(λ) = λ·d with d = ((u − cx)/fx, (v − cy)/fy, 1),
//! so λ is the depth z directly. For an ellipsoid (p − c)ᵀ M (p − c) = 1 with
//! M = R diag(1/e²) Rᵀ the hits solve A λ² − 2 B λ + C = 0 with A = dᵀMd, B = dᵀMc,
//! C = cᵀMc − 1; the nearest is λ = (B − √(B² − AC)) / A. Along an image row A, B and
//! the discriminant D = B² − AC are polynomials in x = (u − cx)/fx, so each ellipsoid's
//! exact silhouette span on the row comes from one quadratic (D(x) ≥ 0) and only the
//! pixels inside it are visited.

use crate::body::ellipsoid::PlacedEllipsoid;
use crate::body::{BodyModel, Kinematics, Pose};
use crate::camera::Camera;
use crate::error::{Error, Result};
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

/// Label of pixels that hit no segment.
pub const BACKGROUND_LABEL: i16 = -1;
/// Rows per rayon task.
const ROWS_PER_TASK: usize = 4;

/// An ellipsoid's quadric in the camera frame, ready for ray casting.
#[derive(Debug, Clone, Copy)]
struct RayQuadric {
    m: Matrix3<f64>,
    mc: Vector3<f64>,
    c: f64,
    label: i16,
}

impl RayQuadric {
    /// None when the camera is inside the ellipsoid (nothing sensible to render).
    fn new(e: &PlacedEllipsoid, label: i16) -> Option<Self> {
        let r = e.prepared.radii();
        let inv = Matrix3::from_diagonal(&Vector3::new(
            1.0 / (r.x * r.x),
            1.0 / (r.y * r.y),
            1.0 / (r.z * r.z),
        ));
        let m = e.rotation * inv * e.rotation.transpose();
        let mc = m * e.centre;
        let c = e.centre.dot(&mc) - 1.0;
        (c > 0.0).then_some(RayQuadric { m, mc, c, label })
    }
}

/// The ellipsoids as ray-casting quadrics, `labels_of[k]` the label of ellipsoid k
/// (those the camera is inside are left out).
fn ray_quadrics(ellipsoids: &[PlacedEllipsoid], labels_of: &[i16]) -> Vec<RayQuadric> {
    ellipsoids
        .iter()
        .zip(labels_of)
        .filter_map(|(e, &l)| RayQuadric::new(e, l))
        .collect()
}

/// Renders the ellipsoids into caller buffers (`depth` H×W metres, 0 = no hit; `labels`
/// H×W, [`BACKGROUND_LABEL`] = no hit). `labels_of[k]` is the label written for
/// ellipsoid k.
pub fn render_ellipsoids_into(
    ellipsoids: &[PlacedEllipsoid],
    labels_of: &[i16],
    camera: &Camera,
    depth: &mut [f32],
    labels: &mut [i16],
) -> Result<()> {
    let (w, h) = (camera.width, camera.height);
    if depth.len() != w * h {
        return Err(Error::invalid(
            "depth",
            format!(
                "buffer has {} values, the camera needs {h}x{w}",
                depth.len()
            ),
        ));
    }
    if labels.len() != w * h {
        return Err(Error::invalid(
            "labels",
            format!(
                "buffer has {} values, the camera needs {h}x{w}",
                labels.len()
            ),
        ));
    }
    if labels_of.len() != ellipsoids.len() {
        return Err(Error::invalid(
            "labels_of",
            "needs one label per ellipsoid".to_string(),
        ));
    }
    let quadrics = ray_quadrics(ellipsoids, labels_of);
    let cam = *camera;
    depth
        .par_chunks_mut(w * ROWS_PER_TASK)
        .zip(labels.par_chunks_mut(w * ROWS_PER_TASK))
        .enumerate()
        .for_each(|(task, (drows, lrows))| {
            for (r, (drow, lrow)) in drows.chunks_mut(w).zip(lrows.chunks_mut(w)).enumerate() {
                let v = (task * ROWS_PER_TASK + r) as f64;
                render_row(&quadrics, &cam, v, drow, lrow);
            }
        });
    Ok(())
}

/// One image row: every quadric's silhouette span, then the nearest hit per pixel.
fn render_row(
    quadrics: &[RayQuadric],
    cam: &Camera,
    v: f64,
    depth: &mut [f32],
    labels: &mut [i16],
) {
    depth.fill(0.0);
    labels.fill(BACKGROUND_LABEL);
    render_row_spans(quadrics, cam, v, depth, labels);
}

/// [`render_row`] without clearing the row first: only the pixels inside a silhouette
/// are written. Returns the column range they cover (`None`: no silhouette meets the
/// row).
fn render_row_spans(
    quadrics: &[RayQuadric],
    cam: &Camera,
    v: f64,
    depth: &mut [f32],
    labels: &mut [i16],
) -> Option<(usize, usize)> {
    let y = (v - cam.cy) / cam.fy;
    let w = depth.len();
    let mut covered: Option<(usize, usize)> = None;
    for q in quadrics {
        let m = &q.m;
        // A(x) = αx² + βx + γ, B(x) = b1·x + b0, D(x) = B² − A·C = P x² + Q x + R.
        let alpha = m[(0, 0)];
        let beta = 2.0 * (m[(0, 1)] * y + m[(0, 2)]);
        let gamma = m[(1, 1)] * y * y + 2.0 * m[(1, 2)] * y + m[(2, 2)];
        let b1 = q.mc.x;
        let b0 = q.mc.y * y + q.mc.z;
        let p = b1 * b1 - q.c * alpha;
        let qq = 2.0 * b1 * b0 - q.c * beta;
        let rr = b0 * b0 - q.c * gamma;
        let (u_lo, u_hi) = if p < 0.0 {
            let disc = qq * qq - 4.0 * p * rr;
            if disc < 0.0 {
                continue;
            }
            let s = disc.sqrt();
            // p < 0: the roots ordered (−qq + s)/(2p) ≤ (−qq − s)/(2p).
            let (x1, x2) = ((-qq + s) / (2.0 * p), (-qq - s) / (2.0 * p));
            (cam.fx * x1 + cam.cx, cam.fx * x2 + cam.cx)
        } else {
            // Unbounded silhouette (ellipsoid reaching behind the camera): scan the row.
            (0.0, (w - 1) as f64)
        };
        let first = u_lo.ceil().max(0.0);
        let last = u_hi.floor().min((w - 1) as f64);
        if first > last {
            continue;
        }
        let (first_col, last_col) = (first as usize, last as usize);
        covered = Some(match covered {
            None => (first_col, last_col),
            Some((lo, hi)) => (lo.min(first_col), hi.max(last_col)),
        });
        for col in first_col..=last_col {
            let x = (col as f64 - cam.cx) / cam.fx;
            let a = (alpha * x + beta) * x + gamma;
            let b = b1 * x + b0;
            let d = b * b - a * q.c;
            if d < 0.0 {
                continue;
            }
            let z = (b - d.sqrt()) / a;
            if z > 0.0 {
                let cur = depth[col];
                let zf = z as f32;
                if cur == 0.0 || zf < cur {
                    depth[col] = zf;
                    labels[col] = q.label;
                }
            }
        }
    }
    covered
}

/// The smallest column range holding both (None when both are).
fn union(a: Option<(usize, usize)>, b: Option<(usize, usize)>) -> Option<(usize, usize)> {
    match (a, b) {
        (Some((a0, a1)), Some((b0, b1))) => Some((a0.min(b0), a1.max(b1))),
        (a, None) => a,
        (None, b) => b,
    }
}

/// Label of each segment's pixels: its index.
const SEGMENT_LABELS: [i16; crate::body::NUM_SEGMENTS] = {
    let mut ids = [0i16; crate::body::NUM_SEGMENTS];
    let mut k = 0;
    while k < ids.len() {
        ids[k] = k as i16;
        k += 1;
    }
    ids
};

impl BodyModel {
    /// Renders the posed body into caller buffers (H×W row-major): depth z in metres
    /// (0 = background) and the segment label of each pixel (−1 = background).
    pub fn render_depth_into(
        &self,
        pose: &Pose,
        camera: &Camera,
        depth: &mut [f32],
        labels: &mut [i16],
    ) -> Result<()> {
        let placed = self.placed_ellipsoids(&Kinematics::new(self, pose));
        render_ellipsoids_into(&placed, &SEGMENT_LABELS, camera, depth, labels)
    }

    /// Renders the posed body: (depth H×W metres, labels H×W).
    pub fn render_depth(&self, pose: &Pose, camera: &Camera) -> (Vec<f32>, Vec<i16>) {
        let n = camera.width * camera.height;
        let (mut depth, mut labels) = (vec![0.0; n], vec![BACKGROUND_LABEL; n]);
        self.render_depth_into(pose, camera, &mut depth, &mut labels)
            .expect("buffers sized from the camera");
        (depth, labels)
    }
}

/// How badly a rendered body explains an observed one, from depth alone (see
/// [`BodyModel::depth_discrepancies`]): where both have depth the cost is the depth
/// difference capped at `cap` metres; an observed pixel with nothing rendered, or a
/// rendered pixel outside `mask`, costs `cap`. The sum over `cap` × the observed pixel
/// count (observed = in `mask` with a finite depth > 0); infinite when none is.
pub fn depth_discrepancy(rendered: &[f32], depth: &[f32], mask: &[bool], cap: f64) -> f64 {
    let (mut sum, mut n_observed) = (Mismatch::default(), 0);
    for ((&r, &d), &m) in rendered.iter().zip(depth).zip(mask) {
        sum.add(r, d, m, cap);
        n_observed += observed(d, m) as usize;
    }
    sum.score(cap, n_observed)
}

/// An observed pixel: in the mask, with a finite depth > 0. Branch-free (NaN fails
/// both comparisons, +∞ the second), so a loop counting observed pixels vectorises.
#[inline]
fn observed(depth: f32, in_mask: bool) -> bool {
    in_mask & (depth > 0.0) & (depth < f32::INFINITY)
}

/// The running sums of [`depth_discrepancy`].
#[derive(Debug, Default, Clone, Copy)]
struct Mismatch {
    /// Σ capped depth differences where both have depth.
    diff: f64,
    /// Pixels costing `cap`.
    penalties: usize,
}

impl Mismatch {
    /// Adds pixel (rendered `r`, observed `d`, in the mask `m`).
    #[inline]
    fn add(&mut self, r: f32, d: f32, m: bool, cap: f64) {
        let obs = observed(d, m);
        let ren = r.is_finite() && r > 0.0;
        if obs && ren {
            self.diff += ((r - d).abs() as f64).min(cap);
        } else if obs || (ren && !m) {
            // Observed but not rendered, or rendered outside the foreground (a hole
            // inside the mask is neither).
            self.penalties += 1;
        }
    }

    /// The discrepancy for `observed` observed pixels (infinite when none is).
    fn score(&self, cap: f64, observed: usize) -> f64 {
        if observed == 0 {
            return f64::INFINITY;
        }
        (self.diff + cap * self.penalties as f64) / (cap * observed as f64)
    }
}

impl BodyModel {
    /// [`depth_discrepancy`] of each of `poses` rendered by `camera` against `depth`
    /// and `mask` (H×W), the poses in parallel.
    pub fn depth_discrepancies(
        &self,
        poses: &[Pose],
        camera: &Camera,
        depth: &[f32],
        mask: &[bool],
        cap: f64,
    ) -> Result<Vec<f64>> {
        let n = camera.width * camera.height;
        if depth.len() != n || mask.len() != n {
            return Err(Error::invalid(
                "depth",
                format!(
                    "depth has {} and mask {} pixels, the camera {}×{} = {n}",
                    depth.len(),
                    mask.len(),
                    camera.width,
                    camera.height
                ),
            ));
        }
        if !(cap.is_finite() && cap > 0.0) {
            return Err(Error::invalid(
                "cap",
                format!("must be finite and > 0, got {cap}"),
            ));
        }
        // Per row, the columns of the observed pixels; outside them and outside the
        // rendered silhouettes a pixel adds nothing, so each pose visits only those
        // columns (same sums, in the same order, as `depth_discrepancy` on a full
        // rendering). One counting pass per row (branch-free, so it vectorises) finds
        // the rows with observed pixels; only those are searched for their ends.
        let w = camera.width;
        let mut n_observed = 0usize;
        let observed_cols: Vec<Option<(usize, usize)>> = depth
            .chunks(w)
            .zip(mask.chunks(w))
            .map(|(d, m)| {
                let count: u32 = d.iter().zip(m).map(|(&z, &m)| observed(z, m) as u32).sum();
                n_observed += count as usize;
                if count == 0 {
                    return None;
                }
                let obs = |c: &usize| observed(d[*c], m[*c]);
                let lo = (0..w).find(obs)?;
                Some((lo, (0..w).rfind(obs).unwrap_or(lo)))
            })
            .collect();
        if n_observed == 0 {
            return Ok(vec![f64::INFINITY; poses.len()]);
        }
        poses
            .par_iter()
            .map_init(
                || (vec![0.0f32; w], vec![BACKGROUND_LABEL; w]),
                |(rendered, labels), pose| {
                    let placed = self.placed_ellipsoids(&Kinematics::new(self, pose));
                    let quadrics = ray_quadrics(&placed, &SEGMENT_LABELS);
                    let mut sum = Mismatch::default();
                    for (v, &observed_cols) in observed_cols.iter().enumerate() {
                        let drawn = render_row_spans(&quadrics, camera, v as f64, rendered, labels);
                        let Some((lo, hi)) = union(drawn, observed_cols) else {
                            continue;
                        };
                        let row = v * w;
                        for col in lo..=hi {
                            sum.add(rendered[col], depth[row + col], mask[row + col], cap);
                        }
                        if let Some((lo, hi)) = drawn {
                            rendered[lo..=hi].fill(0.0);
                        }
                    }
                    Ok(sum.score(cap, n_observed))
                },
            )
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::NUM_SEGMENTS;

    #[test]
    fn sphere_depth_is_exact() {
        let cam = Camera::new(200.0, 200.0, 31.5, 23.5, 64, 48).unwrap();
        let e = PlacedEllipsoid {
            centre: Vector3::new(0.05, -0.02, 2.0),
            rotation: Matrix3::identity(),
            prepared: crate::body::ellipsoid::Prepared::new(&Vector3::new(0.2, 0.2, 0.2)),
        };
        let (mut d, mut l) = (vec![0.0; 64 * 48], vec![0i16; 64 * 48]);
        render_ellipsoids_into(&[e], &[7], &cam, &mut d, &mut l).unwrap();
        let mut hits = 0;
        for row in 0..48 {
            for col in 0..64 {
                let ray = Vector3::new(
                    (col as f64 - 31.5) / 200.0,
                    (row as f64 - 23.5) / 200.0,
                    1.0,
                );
                // Brute force: march along the ray, then bisect on the sphere boundary.
                let inside = |z: f64| (ray * z - e.centre).norm() < 0.2;
                let mut hit = None;
                let mut z = 1.5;
                while z < 2.5 {
                    if inside(z) {
                        let (mut a, mut b) = (z - 1e-3, z);
                        for _ in 0..60 {
                            let m = 0.5 * (a + b);
                            if inside(m) {
                                b = m
                            } else {
                                a = m
                            }
                        }
                        hit = Some(b);
                        break;
                    }
                    z += 1e-3;
                }
                let k = row * 64 + col;
                match hit {
                    Some(z) => {
                        hits += 1;
                        assert_eq!(l[k], 7);
                        assert!((d[k] as f64 - z).abs() < 1e-5, "{} vs {z}", d[k]);
                    }
                    None => assert!(l[k] == BACKGROUND_LABEL && d[k] == 0.0 || l[k] == 7),
                }
            }
        }
        assert!(hits > 100);
    }

    #[test]
    fn body_renders_where_it_stands() {
        let model = BodyModel::default();
        let cam = Camera::itop();
        let pose = BodyModel::neutral_pose();
        let (d, l) = model.render_depth(&pose, &cam);
        let fg: Vec<usize> = (0..d.len()).filter(|&i| d[i] > 0.0).collect();
        assert!(fg.len() > 3000);
        assert!(fg
            .iter()
            .all(|&i| l[i] >= 0 && (l[i] as usize) < NUM_SEGMENTS));
        assert!(fg.iter().all(|&i| d[i] > 2.6 && d[i] < 3.3));
        // Every segment is visible in the neutral front view and the subject's right
        // hand is on the image left.
        let mut seen = [false; NUM_SEGMENTS];
        let mut hand_cols = (0usize, 0usize, 0usize, 0usize);
        for &i in &fg {
            seen[l[i] as usize] = true;
            if l[i] as usize == crate::body::seg::R_HAND {
                hand_cols.0 += i % cam.width;
                hand_cols.1 += 1;
            }
            if l[i] as usize == crate::body::seg::L_HAND {
                hand_cols.2 += i % cam.width;
                hand_cols.3 += 1;
            }
        }
        assert!(seen.iter().all(|s| *s), "{seen:?}");
        assert!(hand_cols.0 / hand_cols.1 < 150 && hand_cols.2 / hand_cols.3 > 170);
        // Head at the top.
        let head_row = fg
            .iter()
            .filter(|&&i| l[i] == 0)
            .map(|&i| i / cam.width)
            .min()
            .unwrap();
        assert!(head_row < 60);
        let (mut small, mut small_labels) = ([0.0f32; 10], [0i16; 10]);
        assert!(model
            .render_depth_into(&pose, &cam, &mut small, &mut small_labels)
            .is_err());
    }

    /// The row-range discrepancies equal `depth_discrepancy` of full renderings, bit
    /// for bit: poses in and partly out of the frame, a mask with extra and missing
    /// pixels, holes and NaN in the depth; infinite with nothing observed.
    #[test]
    fn discrepancies_equal_full_renderings() {
        use crate::body::kinematics::tests::pose_for_tests;
        let model = BodyModel::default();
        let cam = Camera::itop();
        let (observed, _) = model.render_depth(&pose_for_tests(1), &cam);
        let (w, h) = (cam.width, cam.height);
        let mut depth = observed.clone();
        let mut mask: Vec<bool> = observed.iter().map(|&d| d > 0.0).collect();
        for v in 0..h {
            for u in 0..w {
                let i = v * w + u;
                match (u * 7 + v * 13) % 29 {
                    0 => depth[i] = f32::NAN,
                    1 => depth[i] = 0.0,
                    2 => mask[i] = false,
                    _ => {}
                }
                if (100..140).contains(&u) && (20..60).contains(&v) {
                    mask[i] = true; // foreground the body does not explain
                    depth[i] = 2.5;
                }
            }
        }
        let mut shifted = pose_for_tests(3);
        shifted[0] += 1.2; // partly out of the frame on the right
        let poses = [
            BodyModel::neutral_pose(),
            pose_for_tests(1),
            pose_for_tests(2),
            shifted,
        ];
        let got = model
            .depth_discrepancies(&poses, &cam, &depth, &mask, 0.1)
            .unwrap();
        for (pose, g) in poses.iter().zip(&got) {
            let (rendered, _) = model.render_depth(pose, &cam);
            let want = depth_discrepancy(&rendered, &depth, &mask, 0.1);
            assert!(want.is_finite() && want > 0.0);
            assert_eq!(g.to_bits(), want.to_bits(), "{g} vs {want}");
        }
        let none = vec![false; w * h];
        let got = model
            .depth_discrepancies(&poses, &cam, &depth, &none, 0.1)
            .unwrap();
        assert!(got.iter().all(|d| d.is_infinite()));
    }
}
