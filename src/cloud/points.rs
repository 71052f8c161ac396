//! The cloud: valid depth pixels back-projected to 3-D points.

use super::depth::DepthView;
use crate::camera::Camera;
use crate::error::{ensure, Result};
use rayon::prelude::*;

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
/// fresh 640×480 frame that serial first touch of ~30 MB costs more than the work itself.
pub(super) fn set_len<T: Clone>(v: &mut Vec<T>, n: usize, zero: T) {
    if v.capacity() < n {
        *v = vec![zero; n];
    } else {
        v.resize(n, zero);
    }
}

/// Rows a parallel task takes at least: rows are short (a few µs of work), and with few
/// cores a task per row costs more in scheduling than it gains.
pub(super) const ROWS_PER_TASK: usize = 8;

/// Back-projection of one image row into its slice of the cloud.
pub(super) struct FillRow {
    /// (row − cy) / fy.
    pub(super) y: f32,
    pub(super) cx: f32,
    pub(super) fx: f32,
    /// Linear index of the row's first pixel and of its first point.
    pub(super) first_pixel: u32,
    pub(super) first_point: i32,
}

impl FillRow {
    /// Writes the points of the row's pixels with a reading (and in `mask`, if given:
    /// `points`/`pixels` hold exactly that many) and the row of the pixel→point lookup.
    #[inline(always)]
    pub(super) fn run(
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
pub(super) fn keep_bits(z: &[f32], keep: impl Fn(usize) -> bool) -> u32 {
    z.iter().enumerate().fold(0u32, |bits, (j, &z)| {
        bits | (((z > 0.0) & keep(j)) as u32) << j
    })
}

/// Splits a per-point (or per-edge) array into the per-row pieces given by `offsets`
/// (`rows + 1` increasing entries, the last one the array's length).
pub(super) fn split_rows<'a, T>(mut a: &'a mut [T], offsets: &[u32]) -> Vec<&'a mut [T]> {
    let mut out = Vec::with_capacity(offsets.len().saturating_sub(1));
    for pair in offsets.windows(2) {
        let (row, rest) = std::mem::take(&mut a).split_at_mut((pair[1] - pair[0]) as usize);
        out.push(row);
        a = rest;
    }
    out
}
