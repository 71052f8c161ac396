//! The depth image seen as a cloud of 3-D points: validation, back-projection, surface
//! normals from the depth grid and the pixel-neighbourhood graph the CRF works on.
//! Foreground extraction lives in [`foreground`].

pub mod foreground;

use crate::camera::Camera;
use crate::error::{ensure, Error, Result};
use rayon::prelude::*;

pub use foreground::{foreground_mask, ForegroundConfig};

/// A borrowed depth image: row-major `height`×`width`, metres, 0 or NaN = no reading.
#[derive(Debug, Clone, Copy)]
pub struct DepthView<'a> {
    pub data: &'a [f32],
    pub width: usize,
    pub height: usize,
}

/// Index of the first negative or infinite value. Serial on purpose (a frame takes tens
/// of microseconds, less than waking the thread pool) and in branch-free chunks, so
/// that the scan vectorises; only a chunk with a bad value is searched.
fn first_bad_depth(data: &[f32]) -> Option<usize> {
    const CHUNK: usize = 512;
    let bad = |z: f32| z.is_infinite() | (z < 0.0);
    data.chunks(CHUNK).enumerate().find_map(|(c, chunk)| {
        if chunk.iter().fold(false, |acc, &z| acc | bad(z)) {
            chunk.iter().position(|&z| bad(z)).map(|k| c * CHUNK + k)
        } else {
            None
        }
    })
}

impl<'a> DepthView<'a> {
    /// Wraps a slice after checking its size and values: negative or infinite depth is
    /// an error (NaN and 0 mean "no reading").
    pub fn new(data: &'a [f32], height: usize, width: usize, name: &str) -> Result<Self> {
        ensure(height > 0 && width > 0, name, || {
            format!("depth image is empty ({height}x{width})")
        })?;
        ensure(data.len() == height * width, name, || {
            format!(
                "has {} values but {height}x{width} needs {}",
                data.len(),
                height * width
            )
        })?;
        if let Some(bad) = first_bad_depth(data) {
            return Err(Error::invalid(
                name,
                format!(
                    "depth must be >= 0 (0 or NaN = no reading); pixel (row {}, col {}) holds {}",
                    bad / width,
                    bad % width,
                    data[bad]
                ),
            ));
        }
        Ok(DepthView {
            data,
            width,
            height,
        })
    }

    /// The depth at (row, col) if it is a reading, else None.
    #[inline]
    pub fn at(&self, row: usize, col: usize) -> Option<f32> {
        let z = self.data[row * self.width + col];
        (z > 0.0).then_some(z) // NaN > 0 is false
    }

    /// Number of pixels with a reading.
    pub fn count_valid(&self) -> usize {
        self.data.iter().filter(|&&z| z > 0.0).count()
    }
}

/// Valid (foreground) depth pixels as 3-D points, in pixel (row-major) order.
#[derive(Debug, Clone, Default)]
pub struct Cloud {
    pub width: usize,
    pub height: usize,
    /// Camera-frame points, metres.
    pub points: Vec<[f32; 3]>,
    /// Linear pixel index (row·width + col) of each point.
    pub pixels: Vec<u32>,
    /// For each pixel, the index of its point or -1.
    pub point_of_pixel: Vec<i32>,
    /// Index of the first point of each row (`height + 1` entries): the points of row r
    /// are `row_start[r]..row_start[r + 1]`.
    pub row_start: Vec<u32>,
}

impl Cloud {
    /// Back-projects every pixel that has a reading and, if given, is in `mask`.
    pub fn from_depth(depth: &DepthView, camera: &Camera, mask: Option<&[bool]>) -> Result<Self> {
        let mut cloud = Cloud::default();
        cloud.fill_from_depth(depth, camera, mask)?;
        Ok(cloud)
    }

    /// Mean of the points (camera frame, metres), or None for an empty cloud.
    pub fn centroid(&self) -> Option<nalgebra::Vector3<f64>> {
        if self.points.is_empty() {
            return None;
        }
        let mut sum = nalgebra::Vector3::zeros();
        for p in &self.points {
            sum += nalgebra::Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
        }
        Some(sum / self.points.len() as f64)
    }

    /// [`Cloud::from_depth`] into this cloud, reusing its storage: a tracker that keeps
    /// one `Cloud` allocates nothing per frame once the buffers have grown.
    pub fn fill_from_depth(
        &mut self,
        depth: &DepthView,
        camera: &Camera,
        mask: Option<&[bool]>,
    ) -> Result<()> {
        camera.check_image("depth", depth.height, depth.width)?;
        if let Some(m) = mask {
            ensure(m.len() == depth.data.len(), "mask", || {
                format!(
                    "has {} pixels but the depth image has {}",
                    m.len(),
                    depth.data.len()
                )
            })?;
        }
        let (w, h) = (depth.width, depth.height);
        // Pass 1: points per row, then their offsets.
        self.row_start.clear();
        self.row_start.resize(h + 1, 0);
        self.row_start[1..]
            .par_iter_mut()
            .with_min_len(ROWS_PER_TASK)
            .enumerate()
            .for_each(|(row, n)| {
                let z = &depth.data[row * w..(row + 1) * w];
                *n = match mask {
                    None => z.iter().map(|&z| (z > 0.0) as u32).sum(),
                    Some(m) => z
                        .iter()
                        .zip(&m[row * w..(row + 1) * w])
                        .map(|(&z, &m)| (z > 0.0 && m) as u32)
                        .sum(),
                };
            });
        for row in 0..h {
            self.row_start[row + 1] += self.row_start[row];
        }
        let n = self.row_start[h] as usize;
        self.width = w;
        self.height = h;
        set_len(&mut self.points, n, [0.0; 3]);
        set_len(&mut self.pixels, n, 0);
        set_len(&mut self.point_of_pixel, w * h, 0); // every entry written below

        // Pass 2: every row writes its own slices, in parallel.
        let (fx, fy, cx, cy) = (
            camera.fx as f32,
            camera.fy as f32,
            camera.cx as f32,
            camera.cy as f32,
        );
        let row_start = &self.row_start;
        let rows = split_rows(&mut self.points, row_start)
            .into_iter()
            .zip(split_rows(&mut self.pixels, row_start))
            .collect::<Vec<_>>();
        rows.into_par_iter()
            .zip(self.point_of_pixel.par_chunks_mut(w))
            .with_min_len(ROWS_PER_TASK)
            .enumerate()
            .for_each(|(row, ((points, pixels), lookup))| {
                let z = &depth.data[row * w..(row + 1) * w];
                let fill = FillRow {
                    y: (row as f32 - cy) / fy,
                    cx,
                    fx,
                    first_pixel: (row * w) as u32,
                    first_point: row_start[row] as i32,
                };
                let mask = mask.map(|m| &m[row * w..(row + 1) * w]);
                fill.run(z, mask, points, pixels, lookup);
            });
        Ok(())
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// (row, col) of point `k`.
    #[inline]
    pub fn pixel(&self, k: usize) -> (usize, usize) {
        let i = self.pixels[k] as usize;
        (i / self.width, i % self.width)
    }
}

/// Makes `v` hold `n` elements whose values the caller overwrites. A buffer that must
/// grow is replaced by a zeroed allocation (`vec!` of a zero value gets pages the kernel
/// has already zeroed) instead of being filled element by element on one thread: for a
/// fresh 640×480 frame that serial first touch of ~30 MB cost more than the work itself.
fn set_len<T: Clone>(v: &mut Vec<T>, n: usize, zero: T) {
    if v.capacity() < n {
        *v = vec![zero; n];
    } else {
        v.resize(n, zero);
    }
}

/// Rows a parallel task takes at least: rows are short (a few µs of work), and with few
/// cores a task per row costs more in scheduling than it gains.
const ROWS_PER_TASK: usize = 8;

/// Back-projection of one image row into its slice of the cloud.
struct FillRow {
    /// (row − cy) / fy.
    y: f32,
    cx: f32,
    fx: f32,
    /// Linear index of the row's first pixel and of its first point.
    first_pixel: u32,
    first_point: i32,
}

impl FillRow {
    /// Writes the points of the row's pixels with a reading (and in `mask`, if given:
    /// `points`/`pixels` hold exactly that many) and the row of the pixel→point lookup.
    #[inline(always)]
    fn run(
        &self,
        depth: &[f32],
        mask: Option<&[bool]>,
        points: &mut [[f32; 3]],
        pixels: &mut [u32],
        lookup: &mut [i32],
    ) {
        lookup.fill(-1);
        let lookup = &mut lookup[..depth.len()];
        let mut k = 0;
        // Which pixels of a chunk to keep as bits, computed without branches; then one
        // step per kept pixel, none per skipped one.
        const CHUNK: usize = 32;
        for (c, z) in depth.chunks(CHUNK).enumerate() {
            let c0 = c * CHUNK;
            let mut bits = match mask {
                None => keep_bits(z, |_| true),
                Some(m) => {
                    let m = &m[c0..c0 + z.len()];
                    keep_bits(z, |j| m[j])
                }
            };
            if bits == u32::MAX {
                // A full chunk (the common case without a mask): a plain loop.
                let n = CHUNK;
                for (j, ((&z, point), pixel)) in z
                    .iter()
                    .zip(&mut points[k..k + n])
                    .zip(&mut pixels[k..k + n])
                    .enumerate()
                {
                    let col = c0 + j;
                    *point = [(col as f32 - self.cx) * z / self.fx, self.y * z, z];
                    *pixel = self.first_pixel + col as u32;
                }
                for (j, slot) in lookup[c0..c0 + n].iter_mut().enumerate() {
                    *slot = self.first_point + (k + j) as i32;
                }
                k += n;
                continue;
            }
            while bits != 0 {
                let j = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let (col, z) = (c0 + j, z[j]);
                // Same expression (and rounding) as ever: (col − cx)·z / fx.
                points[k] = [(col as f32 - self.cx) * z / self.fx, self.y * z, z];
                pixels[k] = self.first_pixel + col as u32;
                lookup[col] = self.first_point + k as i32;
                k += 1;
            }
        }
    }
}

/// Bit j set when `z[j]` is a reading and `keep(j)` (at most 32 pixels).
#[inline(always)]
fn keep_bits(z: &[f32], keep: impl Fn(usize) -> bool) -> u32 {
    z.iter().enumerate().fold(0u32, |bits, (j, &z)| {
        bits | (((z > 0.0) & keep(j)) as u32) << j
    })
}

/// Splits a per-point (or per-edge) array into the per-row pieces given by `offsets`
/// (`rows + 1` increasing entries, the last one the array's length).
fn split_rows<'a, T>(mut a: &'a mut [T], offsets: &[u32]) -> Vec<&'a mut [T]> {
    let mut out = Vec::with_capacity(offsets.len().saturating_sub(1));
    for pair in offsets.windows(2) {
        let (row, rest) = std::mem::take(&mut a).split_at_mut((pair[1] - pair[0]) as usize);
        out.push(row);
        a = rest;
    }
    out
}

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
struct NormalRow<'a> {
    /// Depth rows `radius` above, at and `radius` below the row (no reading outside the
    /// image).
    up: &'a [f32],
    here: &'a [f32],
    down: &'a [f32],
    /// (col − cx) of every column.
    x_of_col: &'a [f32],
    /// (row − cy) of the three rows, and (row − cy)/fy for the points themselves.
    y_up: f32,
    y_here: f32,
    y_down: f32,
    y_point: f32,
    fx: f32,
    inv_fx: f32,
    inv_fy: f32,
    r: usize,
    jump_scale: f32,
}

/// Normals of a span of columns, component by component, and whether each is valid
/// (false: the point gets the normal facing the camera).
#[derive(Default)]
struct DenseNormals {
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
    ok: Vec<bool>,
}

impl NormalRow<'_> {
    /// The normal of point `p` at column `col`, with every neighbour looked up through
    /// bounds checks.
    fn one(&self, p: [f32; 3], col: usize) -> [f32; 3] {
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
    fn dense(&self, lo: usize, hi: usize, out: &mut DenseNormals) {
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
fn facing_normal(c: [f32; 3], p: [f32; 3]) -> Option<[f32; 3]> {
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
fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline]
fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline]
fn normalize(a: [f32; 3]) -> [f32; 3] {
    let l = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    if l > 0.0 {
        [a[0] / l, a[1] / l, a[2] / l]
    } else {
        [0.0, 0.0, -1.0]
    }
}

/// Pixel connectivity of the neighbourhood graph.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Connectivity {
    Four,
    Eight,
}

impl Connectivity {
    pub fn from_int(n: u32) -> Result<Self> {
        match n {
            4 => Ok(Connectivity::Four),
            8 => Ok(Connectivity::Eight),
            _ => Err(Error::invalid(
                "connectivity",
                format!("must be 4 or 8, got {n}"),
            )),
        }
    }

    /// The number of neighbours of a pixel: 4 or 8 (the inverse of [`Connectivity::from_int`]).
    pub fn neighbours(self) -> u32 {
        match self {
            Connectivity::Four => 4,
            Connectivity::Eight => 8,
        }
    }
}

/// The undirected graph between neighbouring points of a cloud.
#[derive(Debug, Clone, Default)]
pub struct PixelGraph {
    /// Point indices (i, j), i < j in pixel order, each edge once.
    pub edges: Vec<[u32; 2]>,
    /// 3-D distance between the two points (metres).
    pub distance: Vec<f32>,
    /// Depth difference z_j − z_i (metres).
    pub depth_diff: Vec<f32>,
}

impl PixelGraph {
    pub fn len(&self) -> usize {
        self.edges.len()
    }

    pub fn is_empty(&self) -> bool {
        self.edges.is_empty()
    }
}

/// Number of forward edges starting in `row` (those of [`fill_row_edges`]), counted
/// over the columns from the row's first to its last point with sums the compiler
/// vectorises: two look-up entries a, b are both points exactly when `a | b >= 0`.
#[inline(always)]
fn row_edge_count<const EIGHT: bool>(cloud: &Cloud, row: usize) -> u32 {
    let (w, h) = (cloud.width, cloud.height);
    let (first, end) = (
        cloud.row_start[row] as usize,
        cloud.row_start[row + 1] as usize,
    );
    if first == end {
        return 0;
    }
    let col_of = |k: usize| cloud.pixels[k] as usize - row * w;
    let (c0, c1) = (col_of(first), col_of(end - 1) + 1);
    let here = &cloud.point_of_pixel[row * w..(row + 1) * w];
    let pairs = |a: &[i32], b: &[i32]| -> u32 {
        a.iter().zip(b).map(|(&a, &b)| ((a | b) >= 0) as u32).sum()
    };
    let mut count = pairs(&here[c0..c1 - 1], &here[c0 + 1..c1]); // right
    if row + 1 < h {
        let below = &cloud.point_of_pixel[(row + 1) * w..(row + 2) * w];
        count += pairs(&here[c0..c1], &below[c0..c1]); // down
        if EIGHT {
            let l0 = c0.max(1);
            count += pairs(&here[l0..c1], &below[l0 - 1..c1 - 1]); // down-left
            let r1 = c1.min(w - 1);
            if c0 < r1 {
                count += pairs(&here[c0..r1], &below[c0 + 1..r1 + 1]); // down-right
            }
        }
    }
    count
}

/// Fills the edges starting in `row` (their exact number) with their attributes, in
/// pixel order: for each point of the row (a), its neighbours (b > a) right, down-left,
/// down and down-right (8-connectivity; right and down only for 4).
#[inline(always)]
fn fill_row_edges<const EIGHT: bool>(
    cloud: &Cloud,
    row: usize,
    edges: &mut [[u32; 2]],
    distance: &mut [f32],
    depth_diff: &mut [f32],
) {
    let (w, h) = (cloud.width, cloud.height);
    let (first, end) = (
        cloud.row_start[row] as usize,
        cloud.row_start[row + 1] as usize,
    );
    let first_pixel = (row * w) as u32;
    let here = &cloud.point_of_pixel[row * w..(row + 1) * w];
    let below = if row + 1 < h {
        &cloud.point_of_pixel[(row + 1) * w..(row + 2) * w]
    } else {
        &[][..]
    };
    let point = |lookup: &[i32], col: usize| lookup.get(col).copied().unwrap_or(-1);
    let points = &cloud.points[..];
    let mut k = 0;
    // The edge a→b (b ≥ 0); the squared distance for now, the square roots are taken
    // below, all at once.
    let mut emit = |a: u32, p: [f32; 3], b: i32| {
        if b >= 0 {
            let d = sub(points[b as usize], p);
            edges[k] = [a, b as u32];
            distance[k] = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
            depth_diff[k] = d[2];
            k += 1;
        }
    };
    for ((a, &pixel), &p) in (first as u32..)
        .zip(&cloud.pixels[first..end])
        .zip(&points[first..end])
    {
        let col = (pixel - first_pixel) as usize;
        emit(a, p, point(here, col + 1));
        if EIGHT {
            emit(a, p, point(below, col.wrapping_sub(1)));
        }
        emit(a, p, point(below, col));
        if EIGHT {
            emit(a, p, point(below, col + 1));
        }
    }
    for d in distance.iter_mut() {
        *d = d.sqrt();
    }
}

/// Edges between points of `cloud` whose pixels are 4- or 8-neighbours.
pub fn neighbour_graph(cloud: &Cloud, connectivity: Connectivity) -> PixelGraph {
    let mut graph = PixelGraph::default();
    neighbour_graph_into(cloud, connectivity, &mut graph);
    graph
}

/// [`neighbour_graph`] into `graph`, reusing its storage.
pub fn neighbour_graph_into(cloud: &Cloud, connectivity: Connectivity, graph: &mut PixelGraph) {
    match connectivity {
        Connectivity::Four => graph_into::<false>(cloud, graph),
        Connectivity::Eight => graph_into::<true>(cloud, graph),
    }
}

fn graph_into<const EIGHT: bool>(cloud: &Cloud, graph: &mut PixelGraph) {
    let h = cloud.height;
    // Pass 1: edges per row and their offsets; pass 2: rows fill their own slices, so the
    // edges come out in pixel order whatever the threads do.
    let mut edge_start = vec![0u32; h + 1];
    edge_start[1..]
        .par_iter_mut()
        .with_min_len(ROWS_PER_TASK)
        .enumerate()
        .for_each(|(row, n)| *n = row_edge_count::<EIGHT>(cloud, row));
    for row in 0..h {
        edge_start[row + 1] += edge_start[row];
    }
    let m = edge_start[h] as usize;
    set_len(&mut graph.edges, m, [0, 0]);
    set_len(&mut graph.distance, m, 0.0);
    set_len(&mut graph.depth_diff, m, 0.0);
    let rows = split_rows(&mut graph.edges, &edge_start)
        .into_iter()
        .zip(split_rows(&mut graph.distance, &edge_start))
        .zip(split_rows(&mut graph.depth_diff, &edge_start))
        .collect::<Vec<_>>();
    rows.into_par_iter()
        .with_min_len(ROWS_PER_TASK)
        .enumerate()
        .for_each(|(row, ((edges, distance), depth_diff))| {
            fill_row_edges::<EIGHT>(cloud, row, edges, distance, depth_diff)
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_bad_depth_finds_the_first_bad_value_across_chunks() {
        let n = 3 * 512 + 7;
        let clean: Vec<f32> = (0..n).map(|k| (k % 5) as f32 * 0.5).collect();
        assert_eq!(first_bad_depth(&clean), None);
        let mut with_nan = clean.clone();
        with_nan[3] = f32::NAN; // NaN means "no reading", not an error
        assert_eq!(first_bad_depth(&with_nan), None);
        for &first in &[0, 1, 511, 512, 513, 1024, n - 1] {
            for bad in [-0.001f32, f32::INFINITY, f32::NEG_INFINITY] {
                let mut d = clean.clone();
                d[first] = bad;
                if first + 600 < n {
                    d[first + 600] = -1.0; // a later bad value does not win
                }
                assert_eq!(first_bad_depth(&d), Some(first), "bad {bad} at {first}");
            }
        }
    }

    fn cam() -> Camera {
        Camera::new(300.0, 300.0, 79.5, 59.5, 160, 120).unwrap()
    }

    /// Depth image of the plane n·p = d (camera frame).
    fn plane_depth(cam: &Camera, n: [f64; 3], d: f64) -> Vec<f32> {
        let mut out = vec![0.0f32; cam.width * cam.height];
        for row in 0..cam.height {
            for col in 0..cam.width {
                let r = cam.back_project(col as f64, row as f64, 1.0);
                let t = d / (n[0] * r.x + n[1] * r.y + n[2] * r.z);
                out[row * cam.width + col] = t as f32; // r.z = 1 so t is the depth
            }
        }
        out
    }

    /// Depth image of a sphere (centre c, radius rad); 0 off the sphere.
    fn sphere_depth(cam: &Camera, c: [f64; 3], rad: f64) -> Vec<f32> {
        let mut out = vec![0.0f32; cam.width * cam.height];
        for row in 0..cam.height {
            for col in 0..cam.width {
                let r = cam.back_project(col as f64, row as f64, 1.0);
                // |t r - c|² = rad²  →  t²|r|² − 2t r·c + |c|² − rad² = 0
                let a = r.norm_squared();
                let b = r.x * c[0] + r.y * c[1] + r.z * c[2];
                let cc = c[0] * c[0] + c[1] * c[1] + c[2] * c[2] - rad * rad;
                let disc = b * b - a * cc;
                if disc >= 0.0 {
                    out[row * cam.width + col] = ((b - disc.sqrt()) / a) as f32;
                }
            }
        }
        out
    }

    #[test]
    fn back_projection_lies_on_plane_and_normals_match() {
        let cam = cam();
        let n = nalgebra::Vector3::new(0.2, -0.3, -1.0).normalize();
        let d = -2.0; // n·p = d with n pointing to the camera
        let depth = plane_depth(&cam, [n.x, n.y, n.z], d);
        let view = DepthView::new(&depth, cam.height, cam.width, "depth").unwrap();
        let cloud = Cloud::from_depth(&view, &cam, None).unwrap();
        assert_eq!(cloud.len(), cam.width * cam.height);
        let normals = normals_from_depth(&view, &cam, &cloud, &NormalConfig::default());
        for (p, m) in cloud.points.iter().zip(&normals) {
            let on = n.x * p[0] as f64 + n.y * p[1] as f64 + n.z * p[2] as f64;
            assert!((on - d).abs() < 1e-5, "point off the plane by {}", on - d);
            let dot = n.x * m[0] as f64 + n.y * m[1] as f64 + n.z * m[2] as f64;
            assert!(
                dot > 0.9999,
                "normal off by {} deg",
                dot.acos().to_degrees()
            );
        }
    }

    #[test]
    fn sphere_normals_are_radial_even_at_the_silhouette() {
        let cam = cam();
        let c = [0.05, -0.02, 1.5];
        let rad = 0.2;
        let depth = sphere_depth(&cam, c, rad);
        let view = DepthView::new(&depth, cam.height, cam.width, "depth").unwrap();
        let cloud = Cloud::from_depth(&view, &cam, None).unwrap();
        assert!(cloud.len() > 1000);
        let normals = normals_from_depth(&view, &cam, &cloud, &NormalConfig::default());
        let mut worst_inner = 0.0f64;
        for (p, m) in cloud.points.iter().zip(&normals) {
            let radial =
                nalgebra::Vector3::new(p[0] as f64 - c[0], p[1] as f64 - c[1], p[2] as f64 - c[2]);
            assert!((radial.norm() - rad).abs() < 1e-4);
            let radial = radial.normalize();
            let dot = radial.x * m[0] as f64 + radial.y * m[1] as f64 + radial.z * m[2] as f64;
            // Facing the camera always; accurate where the surface is not grazing.
            assert!(dot > 0.0);
            let facing =
                -(radial.x * p[0] as f64 + radial.y * p[1] as f64 + radial.z * p[2] as f64)
                    / (p[0] as f64).hypot(p[1] as f64).hypot(p[2] as f64);
            if facing > 0.5 {
                worst_inner = worst_inner.max(dot.clamp(-1.0, 1.0).acos().to_degrees());
            }
        }
        assert!(worst_inner < 2.0, "worst normal error {worst_inner} deg");
    }

    #[test]
    fn graph_edges_and_attributes() {
        let cam = Camera::new(100.0, 100.0, 2.0, 1.5, 5, 4).unwrap();
        let mut depth = vec![1.0f32; 20];
        depth[7] = 0.0; // a hole
        depth[12] = 1.5; // a step
        let view = DepthView::new(&depth, 4, 5, "depth").unwrap();
        let cloud = Cloud::from_depth(&view, &cam, None).unwrap();
        assert_eq!(cloud.len(), 19);
        let g4 = neighbour_graph(&cloud, Connectivity::Four);
        // A full 5x4 grid has 4·4 + 5·3 = 31 4-edges; the hole removes its 4.
        assert_eq!(g4.len(), 27);
        let g8 = neighbour_graph(&cloud, Connectivity::Eight);
        // plus 2·4·3 = 24 diagonals, minus the hole's 4.
        assert_eq!(g8.len(), 27 + 20);
        for (k, &[a, b]) in g8.edges.iter().enumerate() {
            let (p, q) = (cloud.points[a as usize], cloud.points[b as usize]);
            assert!((g8.depth_diff[k] - (q[2] - p[2])).abs() < 1e-7);
            let d = ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) + (q[2] - p[2]).powi(2)).sqrt();
            assert!((g8.distance[k] - d).abs() < 1e-6);
        }
        assert!(g4.depth_diff.iter().any(|&d| (d - 0.5).abs() < 1e-6));
    }

    #[test]
    fn reused_buffers_give_the_same_cloud_and_graph_as_fresh_ones() {
        let cam = cam();
        let sphere = sphere_depth(&cam, [0.05, -0.02, 1.5], 0.2);
        let plane = plane_depth(&cam, [0.2, -0.3, -1.0], -2.0);
        let mut cloud = Cloud::default();
        let mut graph = PixelGraph::default();
        let mut normals = Vec::new();
        // The full plane first (large buffers), then the smaller sphere with a mask.
        for (depth, masked) in [(&plane, false), (&sphere, true), (&plane, false)] {
            let view = DepthView::new(depth, cam.height, cam.width, "depth").unwrap();
            let mask: Vec<bool> = (0..depth.len()).map(|i| i % 7 != 0).collect();
            let mask = masked.then_some(mask.as_slice());
            let fresh = Cloud::from_depth(&view, &cam, mask).unwrap();
            cloud.fill_from_depth(&view, &cam, mask).unwrap();
            assert_eq!(cloud.points, fresh.points);
            assert_eq!(cloud.pixels, fresh.pixels);
            assert_eq!(cloud.point_of_pixel, fresh.point_of_pixel);
            assert_eq!(cloud.row_start, fresh.row_start);
            for (k, &i) in fresh.pixels.iter().enumerate() {
                assert_eq!(fresh.point_of_pixel[i as usize], k as i32);
            }
            let cfg = NormalConfig::default();
            normals.resize(cloud.len(), [0.0; 3]);
            normals_into(&view, &cam, &cloud, &cfg, &mut normals);
            assert_eq!(normals, normals_from_depth(&view, &cam, &fresh, &cfg));
            neighbour_graph_into(&cloud, Connectivity::Eight, &mut graph);
            let g = neighbour_graph(&fresh, Connectivity::Eight);
            assert_eq!(graph.edges, g.edges);
            assert_eq!(graph.distance, g.distance);
            assert!(
                graph.edges.windows(2).all(|e| e[0] < e[1]),
                "edges in pixel order"
            );
        }
    }

    /// The cloud, normals and graph computed the plain way: one pixel at a time, on one
    /// thread, with every neighbour looked up through bounds checks. The fast paths must
    /// give exactly this (same values, same order).
    mod reference {
        use super::super::*;

        pub fn cloud(depth: &DepthView, cam: &Camera, mask: Option<&[bool]>) -> Cloud {
            let (w, h) = (depth.width, depth.height);
            let (fx, fy, cx, cy) = (cam.fx as f32, cam.fy as f32, cam.cx as f32, cam.cy as f32);
            let mut c = Cloud {
                width: w,
                height: h,
                point_of_pixel: vec![-1; w * h],
                row_start: vec![0],
                ..Default::default()
            };
            for row in 0..h {
                for col in 0..w {
                    let i = row * w + col;
                    let z = depth.data[i];
                    if z > 0.0 && mask.is_none_or(|m| m[i]) {
                        c.point_of_pixel[i] = c.points.len() as i32;
                        c.points
                            .push([(col as f32 - cx) * z / fx, (row as f32 - cy) / fy * z, z]);
                        c.pixels.push(i as u32);
                    }
                }
                c.row_start.push(c.points.len() as u32);
            }
            c
        }

        pub fn normals(
            depth: &DepthView,
            cam: &Camera,
            cloud: &Cloud,
            config: &NormalConfig,
        ) -> Vec<[f32; 3]> {
            let r = config.radius.max(1) as isize;
            let (w, h) = (depth.width as isize, depth.height as isize);
            let (inv_fx, inv_fy) = (1.0 / cam.fx as f32, 1.0 / cam.fy as f32);
            let (cx, cy) = (cam.cx as f32, cam.cy as f32);
            let point_at = |row: isize, col: isize| -> Option<[f32; 3]> {
                if row < 0 || col < 0 || row >= h || col >= w {
                    return None;
                }
                let z = depth.data[(row * w + col) as usize];
                (z > 0.0).then_some([
                    (col as f32 - cx) * z * inv_fx,
                    (row as f32 - cy) * z * inv_fy,
                    z,
                ])
            };
            (0..cloud.len())
                .map(|k| {
                    let p = cloud.points[k];
                    let (row, col) = cloud.pixel(k);
                    let (row, col) = (row as isize, col as isize);
                    let jump = surface_jump(p[2]) * config.jump_scale * r as f32;
                    let near = |q: Option<[f32; 3]>| q.filter(|q| (q[2] - p[2]).abs() <= jump);
                    let tangent = |a, b| match (near(a), near(b)) {
                        (Some(a), Some(b)) => Some(sub(b, a)),
                        (Some(a), None) => Some(sub(p, a)),
                        (None, Some(b)) => Some(sub(b, p)),
                        (None, None) => None,
                    };
                    let tu = tangent(point_at(row, col - r), point_at(row, col + r));
                    let tv = tangent(point_at(row - r, col), point_at(row + r, col));
                    match (tu, tv) {
                        (Some(tu), Some(tv)) => facing_normal(cross(tu, tv), p),
                        _ => None,
                    }
                    .unwrap_or_else(|| normalize([-p[0], -p[1], -p[2]]))
                })
                .collect()
        }

        pub fn graph(cloud: &Cloud, connectivity: Connectivity) -> PixelGraph {
            let offsets: &[(usize, isize)] = match connectivity {
                Connectivity::Four => &[(0, 1), (1, 0)],
                Connectivity::Eight => &[(0, 1), (1, -1), (1, 0), (1, 1)],
            };
            let (w, h) = (cloud.width, cloud.height);
            let mut g = PixelGraph::default();
            for row in 0..h {
                for col in 0..w {
                    let a = cloud.point_of_pixel[row * w + col];
                    if a < 0 {
                        continue;
                    }
                    for &(dr, dc) in offsets {
                        let (r2, c2) = (row + dr, col as isize + dc);
                        if r2 >= h || c2 < 0 || c2 >= w as isize {
                            continue;
                        }
                        let b = cloud.point_of_pixel[r2 * w + c2 as usize];
                        if b >= 0 {
                            let (p, q) = (cloud.points[a as usize], cloud.points[b as usize]);
                            let d = sub(q, p);
                            g.edges.push([a as u32, b as u32]);
                            g.distance
                                .push((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt());
                            g.depth_diff.push(d[2]);
                        }
                    }
                }
            }
            g
        }
    }

    /// Bit patterns, so that the comparison is exact (and NaN-safe).
    fn bits<const N: usize>(v: &[[f32; N]]) -> Vec<[u32; N]> {
        v.iter().map(|a| a.map(f32::to_bits)).collect()
    }

    fn scalar_bits(v: &[f32]) -> Vec<u32> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    /// A depth image of a few slanted planes at different depths with holes (0 and NaN),
    /// so that it has silhouette edges, depth steps and missing neighbours everywhere.
    fn random_depth(h: usize, w: usize, seed: u64, holes: f64) -> (Vec<f32>, Vec<bool>) {
        let mut state = seed | 1;
        let mut next = move || {
            // xorshift64*
            state ^= state >> 12;
            state ^= state << 25;
            state ^= state >> 27;
            (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
        };
        let (a, b, split) = (next() - 0.5, next() - 0.5, next());
        let mut depth = Vec::with_capacity(h * w);
        let mut mask = Vec::with_capacity(h * w);
        for row in 0..h {
            for col in 0..w {
                let (u, v) = (col as f64 / w as f64, row as f64 / h as f64);
                let base = if u + 0.3 * v < split { 1.2 } else { 3.5 };
                let mut z = base + a * u + b * v + 0.01 * next();
                let roll = next();
                if roll < holes * 0.5 {
                    z = 0.0;
                } else if roll < holes {
                    z = f64::NAN;
                } else if roll > 0.995 {
                    z = 0.05 * next(); // a stray reading very close to the camera
                }
                depth.push(z as f32);
                mask.push(next() < 0.8 || base < 2.0);
            }
        }
        (depth, mask)
    }

    fn check_against_reference(h: usize, w: usize, seed: u64, holes: f64, radius: usize) {
        let cam = Camera::new(
            500.0 + w as f64,
            480.0 + h as f64,
            w as f64 / 2.0 - 0.5,
            h as f64 / 2.0 + 0.25,
            w,
            h,
        )
        .unwrap();
        let (depth, mask) = random_depth(h, w, seed, holes);
        let view = DepthView::new(&depth, h, w, "depth").unwrap();
        let cfg = NormalConfig {
            radius,
            jump_scale: 1.3,
        };
        // Reused buffers, grown on a larger image first, as a tracker keeps them.
        let mut cloud = Cloud::default();
        let mut graph = PixelGraph::default();
        let mut normals = vec![[9.0f32; 3]; 4 * h * w];
        let big = vec![2.0f32; 4 * h * w];
        let big_view = DepthView::new(&big, 2 * h, 2 * w, "depth").unwrap();
        let big_cam = Camera::new(500.0, 500.0, w as f64, h as f64, 2 * w, 2 * h).unwrap();
        cloud.fill_from_depth(&big_view, &big_cam, None).unwrap();
        neighbour_graph_into(&cloud, Connectivity::Eight, &mut graph);
        for m in [None, Some(mask.as_slice())] {
            let want = reference::cloud(&view, &cam, m);
            cloud.fill_from_depth(&view, &cam, m).unwrap();
            let fresh = Cloud::from_depth(&view, &cam, m).unwrap();
            for got in [&cloud, &fresh] {
                assert_eq!((got.width, got.height), (w, h));
                assert_eq!(bits(&got.points), bits(&want.points));
                assert_eq!(got.pixels, want.pixels);
                assert_eq!(got.point_of_pixel, want.point_of_pixel);
                assert_eq!(got.row_start, want.row_start);
            }
            let want_normals = reference::normals(&view, &cam, &want, &cfg);
            normals.resize(cloud.len(), [9.0; 3]);
            normals_into(&view, &cam, &cloud, &cfg, &mut normals);
            assert_eq!(bits(&normals), bits(&want_normals));
            let fresh_normals = normals_from_depth(&view, &cam, &fresh, &cfg);
            assert_eq!(bits(&fresh_normals), bits(&want_normals));
            for connectivity in [Connectivity::Four, Connectivity::Eight] {
                let want = reference::graph(&want, connectivity);
                neighbour_graph_into(&cloud, connectivity, &mut graph);
                for got in [&graph, &neighbour_graph(&fresh, connectivity)] {
                    assert_eq!(got.edges, want.edges);
                    assert_eq!(scalar_bits(&got.distance), scalar_bits(&want.distance));
                    assert_eq!(scalar_bits(&got.depth_diff), scalar_bits(&want.depth_diff));
                }
            }
        }
    }

    #[test]
    fn fast_paths_match_the_serial_reference_on_a_vga_frame() {
        check_against_reference(480, 640, 7, 0.1, 2);
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(48))]

        #[test]
        fn fast_paths_match_the_serial_reference(
            h in 1usize..40,
            w in 1usize..40,
            seed in proptest::prelude::any::<u64>(),
            holes in 0.0f64..0.9,
            radius in 0usize..4,
        ) {
            check_against_reference(h, w, seed, holes, radius);
        }
    }

    #[test]
    fn bad_depth_is_rejected_with_its_pixel() {
        let mut d = vec![1.0f32; 6];
        d[4] = -1.0;
        let e = DepthView::new(&d, 2, 3, "depth").unwrap_err().to_string();
        assert!(e.contains("depth") && e.contains("row 1, col 1"), "{e}");
        d[4] = f32::INFINITY;
        assert!(DepthView::new(&d, 2, 3, "depth").is_err());
        d[4] = f32::NAN;
        assert_eq!(DepthView::new(&d, 2, 3, "depth").unwrap().count_valid(), 5);
        assert!(DepthView::new(&d, 3, 3, "depth").is_err());
        assert!(DepthView::new(&[], 0, 3, "depth").is_err());
    }
}
