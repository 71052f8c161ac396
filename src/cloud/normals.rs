//! Surface normals from the depth grid.

use super::depth::DepthView;
use super::points::{split_rows, Cloud, ROWS_PER_TASK};
use crate::camera::Camera;
use rayon::prelude::*;

/// Largest depth step (metres) still treated as the same surface at depth `z`: a few
/// times the sensor's quantisation step, which grows with z².
#[inline]
pub fn surface_jump(z: f32) -> f32 {
    0.03 + 0.02 * z * z
}

/// Settings of [`normals_from_depth`].
#[derive(Debug, Clone, Copy)]
pub struct NormalConfig {
    /// Pixel distance of the finite-difference stencil; larger smooths sensor noise.
    pub radius: usize,
    /// Depth steps larger than `surface_jump(z)·jump_scale` are edges, not surface.
    pub jump_scale: f32,
}

impl Default for NormalConfig {
    fn default() -> Self {
        NormalConfig {
            radius: 2,
            jump_scale: 1.0,
        }
    }
}

/// Unit surface normals (facing the camera) of the cloud's points, from the depth grid.
///
/// For each point the tangent along rows and along columns is a central difference over
/// `radius` pixels; a side whose neighbour is missing or across a depth step (a
/// silhouette or self-occlusion edge) is dropped and the other side used alone, so that
/// normals at edges and holes describe the surface the point is on. A point with no
/// usable neighbour in one direction gets the normal facing the camera.
pub fn normals_from_depth(
    depth: &DepthView,
    camera: &Camera,
    cloud: &Cloud,
    config: &NormalConfig,
) -> Vec<[f32; 3]> {
    let mut out = vec![[0.0f32; 3]; cloud.len()];
    normals_into(depth, camera, cloud, config, &mut out);
    out
}

/// [`normals_from_depth`] into a caller-provided buffer of `cloud.len()` normals.
pub fn normals_into(
    depth: &DepthView,
    camera: &Camera,
    cloud: &Cloud,
    config: &NormalConfig,
    out: &mut [[f32; 3]],
) {
    assert_eq!(out.len(), cloud.len());
    let r = config.radius.max(1);
    let (w, h) = (depth.width, depth.height);
    let (fx, fy, cx, cy) = (
        camera.fx as f32,
        camera.fy as f32,
        camera.cx as f32,
        camera.cy as f32,
    );
    // (col − cx) of every column, exactly as the back-projection computes it.
    let x_of_col: Vec<f32> = (0..w).map(|col| col as f32 - cx).collect();
    // Stands in for the stencil rows above and below the image: no reading anywhere.
    let no_row = vec![0.0f32; w];
    let depth_row = |rr: usize| match rr < h {
        true => &depth.data[rr * w..(rr + 1) * w],
        false => &no_row[..],
    };
    // Rows in parallel; the points of a row are contiguous.
    split_rows(out, &cloud.row_start)
        .into_par_iter()
        .with_min_len(ROWS_PER_TASK)
        .enumerate()
        .for_each_init(DenseNormals::default, |dense, (row, normals)| {
            if normals.is_empty() {
                return;
            }
            let first = cloud.row_start[row] as usize;
            let points = &cloud.points[first..first + normals.len()];
            let pixels = &cloud.pixels[first..first + normals.len()];
            let stencil = NormalRow {
                up: row.checked_sub(r).map_or(&no_row[..], depth_row),
                here: depth_row(row),
                down: depth_row(row + r),
                x_of_col: &x_of_col,
                y_up: (row as isize - r as isize) as f32 - cy,
                y_here: row as f32 - cy,
                y_down: (row + r) as f32 - cy,
                y_point: (row as f32 - cy) / fy,
                fx,
                inv_fx: 1.0 / fx,
                inv_fy: 1.0 / fy,
                r,
                jump_scale: config.jump_scale,
            };
            // The columns from the row's first to its last point whose whole stencil is
            // in the image go through the branch-free kernel, the others one by one.
            let first_pixel = (row * w) as u32;
            let col_of = |pixel: u32| (pixel - first_pixel) as usize;
            let lo = col_of(pixels[0]).max(r);
            let hi = (col_of(pixels[pixels.len() - 1]) + 1).min(w.saturating_sub(r));
            if lo < hi {
                stencil.dense(lo, hi, dense);
            }
            for ((n, &p), &pixel) in normals.iter_mut().zip(points).zip(pixels) {
                let col = col_of(pixel);
                *n = if (lo..hi).contains(&col) {
                    let i = col - lo;
                    match dense.ok[i] {
                        true => [dense.x[i], dense.y[i], dense.z[i]],
                        false => normalize([-p[0], -p[1], -p[2]]),
                    }
                } else {
                    stencil.one(p, col)
                };
            }
        });
}

/// The depth rows and constants of the normals of one image row.
pub(super) struct NormalRow<'a> {
    /// Depth rows `radius` above, at and `radius` below the row (no reading outside the
    /// image).
    pub(super) up: &'a [f32],
    pub(super) here: &'a [f32],
    pub(super) down: &'a [f32],
    /// (col − cx) of every column.
    pub(super) x_of_col: &'a [f32],
    /// (row − cy) of the three rows, and (row − cy)/fy for the points themselves.
    pub(super) y_up: f32,
    pub(super) y_here: f32,
    pub(super) y_down: f32,
    pub(super) y_point: f32,
    pub(super) fx: f32,
    pub(super) inv_fx: f32,
    pub(super) inv_fy: f32,
    pub(super) r: usize,
    pub(super) jump_scale: f32,
}

/// Normals of a span of columns, component by component, and whether each is valid
/// (false: the point gets the normal facing the camera).
#[derive(Default)]
pub(super) struct DenseNormals {
    pub(super) x: Vec<f32>,
    pub(super) y: Vec<f32>,
    pub(super) z: Vec<f32>,
    pub(super) ok: Vec<bool>,
}

impl NormalRow<'_> {
    /// The normal of point `p` at column `col`, with every neighbour looked up through
    /// bounds checks.
    pub(super) fn one(&self, p: [f32; 3], col: usize) -> [f32; 3] {
        let jump = surface_jump(p[2]) * self.jump_scale * self.r as f32;
        // The neighbour's point at (y, column x) if it is a reading on the same surface
        // as p, else p itself: a tangent from a missing side then runs from (or to) p,
        // and with both sides missing it is zero, which makes the cross product zero
        // and the normal the fallback below.
        let near = |y: f32, x: usize, z: Option<&f32>| -> [f32; 3] {
            match z {
                Some(&z) if z > 0.0 && (z - p[2]).abs() <= jump => {
                    [self.x_of_col[x] * z * self.inv_fx, y * z * self.inv_fy, z]
                }
                _ => p,
            }
        };
        let (left, right) = (col.wrapping_sub(self.r), col + self.r); // wraps when off-image
        let tu = sub(
            near(self.y_here, right, self.here.get(right)),
            near(self.y_here, left, self.here.get(left)),
        );
        let tv = sub(
            near(self.y_down, col, self.down.get(col)),
            near(self.y_up, col, self.up.get(col)),
        );
        facing_normal(cross(tu, tv), p).unwrap_or_else(|| normalize([-p[0], -p[1], -p[2]]))
    }

    /// [`NormalRow::one`] for every column in `lo..hi` (`r <= lo`, `hi + r <= width`),
    /// without branches so that the compiler can vectorise it; the fallback normal is
    /// left to the caller (`ok` false). Pixels without a reading get garbage.
    pub(super) fn dense(&self, lo: usize, hi: usize, out: &mut DenseNormals) {
        let (n, r) = (hi - lo, self.r);
        for v in [&mut out.x, &mut out.y, &mut out.z] {
            v.resize(n, 0.0);
        }
        out.ok.resize(n, false);
        let (ox, oy, oz, ok) = (
            &mut out.x[..n],
            &mut out.y[..n],
            &mut out.z[..n],
            &mut out.ok[..n],
        );
        let (z_here, z_left, z_right) = (
            &self.here[lo..hi],
            &self.here[lo - r..hi - r],
            &self.here[lo + r..hi + r],
        );
        let (z_up, z_down) = (&self.up[lo..hi], &self.down[lo..hi]);
        let (x_here, x_left, x_right) = (
            &self.x_of_col[lo..hi],
            &self.x_of_col[lo - r..hi - r],
            &self.x_of_col[lo + r..hi + r],
        );
        let (jump_scale, rf) = (self.jump_scale, r as f32);
        for i in 0..n {
            let z = z_here[i];
            let p = [x_here[i] * z / self.fx, self.y_point * z, z];
            let jump = surface_jump(z) * jump_scale * rf;
            let pick = |x: f32, y: f32, zn: f32| -> [f32; 3] {
                let near = (zn > 0.0) & ((zn - z).abs() <= jump);
                let q = [x * zn * self.inv_fx, y * zn * self.inv_fy, zn];
                [
                    if near { q[0] } else { p[0] },
                    if near { q[1] } else { p[1] },
                    if near { q[2] } else { p[2] },
                ]
            };
            let tu = sub(
                pick(x_right[i], self.y_here, z_right[i]),
                pick(x_left[i], self.y_here, z_left[i]),
            );
            let tv = sub(
                pick(x_here[i], self.y_down, z_down[i]),
                pick(x_here[i], self.y_up, z_up[i]),
            );
            // facing_normal without its branches; −1/len is exactly −(1/len).
            let c = cross(tu, tv);
            let len = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
            let inv = 1.0 / len;
            let s = if c[0] * p[0] + c[1] * p[1] + c[2] * p[2] > 0.0 {
                -inv
            } else {
                inv
            };
            ox[i] = c[0] * s;
            oy[i] = c[1] * s;
            oz[i] = c[2] * s;
            ok[i] = (len > 0.0) & (len < f32::INFINITY);
        }
    }
}

/// The unit normal along `c`, flipped to face the camera at the origin from `p`; None if
/// `c` is degenerate.
#[inline]
pub(super) fn facing_normal(c: [f32; 3], p: [f32; 3]) -> Option<[f32; 3]> {
    let len = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
    if !(len > 0.0 && len.is_finite()) {
        return None;
    }
    let s = if c[0] * p[0] + c[1] * p[1] + c[2] * p[2] > 0.0 {
        -1.0 / len
    } else {
        1.0 / len
    };
    Some([c[0] * s, c[1] * s, c[2] * s])
}

#[inline]
pub(super) fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline]
pub(super) fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline]
pub(super) fn normalize(a: [f32; 3]) -> [f32; 3] {
    let l = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    if l > 0.0 {
        [a[0] / l, a[1] / l, a[2] / l]
    } else {
        [0.0, 0.0, -1.0]
    }
}
