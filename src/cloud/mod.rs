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
        if let Some(bad) = data
            .par_iter()
            .position_any(|&z| z.is_infinite() || z < 0.0)
        {
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
        self.data.par_iter().filter(|&&z| z > 0.0).count()
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
        let keep = |i: usize| depth.data[i] > 0.0 && mask.is_none_or(|m| m[i]);
        // Pass 1: points per row, then their offsets.
        self.row_start.clear();
        self.row_start.resize(h + 1, 0);
        self.row_start[1..]
            .par_iter_mut()
            .enumerate()
            .for_each(|(row, n)| *n = (row * w..(row + 1) * w).filter(|&i| keep(i)).count() as u32);
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
            .enumerate()
            .for_each(|(row, ((points, pixels), lookup))| {
                let y = (row as f32 - cy) / fy;
                let mut k = 0;
                for (col, slot) in lookup.iter_mut().enumerate() {
                    let i = row * w + col;
                    if keep(i) {
                        let z = depth.data[i];
                        points[k] = [(col as f32 - cx) * z / fx, y * z, z];
                        pixels[k] = i as u32;
                        *slot = row_start[row] as i32 + k as i32;
                        k += 1;
                    } else {
                        *slot = -1;
                    }
                }
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
    let r = config.radius.max(1) as isize;
    let (w, h) = (depth.width as isize, depth.height as isize);
    let (inv_fx, inv_fy, cx, cy) = (
        1.0 / camera.fx as f32,
        1.0 / camera.fy as f32,
        camera.cx as f32,
        camera.cy as f32,
    );
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
    // Rows in parallel; the points of a row are contiguous.
    split_rows(out, &cloud.row_start)
        .into_par_iter()
        .enumerate()
        .for_each(|(row, normals)| {
            let first = cloud.row_start[row] as usize;
            let row = row as isize;
            for (k, n) in normals.iter_mut().enumerate() {
                let p = cloud.points[first + k];
                let col = (cloud.pixels[first + k] as usize % depth.width) as isize;
                let jump = surface_jump(p[2]) * config.jump_scale * r as f32;
                let near = |q: Option<[f32; 3]>| q.filter(|q| (q[2] - p[2]).abs() <= jump);
                let tangent = |a: Option<[f32; 3]>, b: Option<[f32; 3]>| match (near(a), near(b)) {
                    (Some(a), Some(b)) => Some(sub(b, a)),
                    (Some(a), None) => Some(sub(p, a)),
                    (None, Some(b)) => Some(sub(b, p)),
                    (None, None) => None,
                };
                let tu = tangent(point_at(row, col - r), point_at(row, col + r));
                let tv = tangent(point_at(row - r, col), point_at(row + r, col));
                *n = match (tu, tv) {
                    (Some(tu), Some(tv)) => facing_normal(cross(tu, tv), p),
                    _ => None,
                }
                .unwrap_or_else(|| normalize([-p[0], -p[1], -p[2]]));
            }
        });
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

    /// Forward neighbour offsets (d_row, d_col), each undirected edge listed once.
    fn offsets(self) -> &'static [(usize, isize)] {
        match self {
            Connectivity::Four => &[(0, 1), (1, 0)],
            Connectivity::Eight => &[(0, 1), (1, -1), (1, 0), (1, 1)],
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

/// Calls `f(a, b)` for each forward edge (point indices) starting in `row`, in pixel
/// order.
#[inline]
fn row_edges(cloud: &Cloud, offsets: &[(usize, isize)], row: usize, mut f: impl FnMut(u32, u32)) {
    let (w, h) = (cloud.width, cloud.height);
    let lookup = &cloud.point_of_pixel;
    for col in 0..w {
        let a = lookup[row * w + col];
        if a < 0 {
            continue;
        }
        for &(dr, dc) in offsets {
            let (r2, c2) = (row + dr, col as isize + dc);
            if r2 >= h || c2 < 0 || c2 >= w as isize {
                continue;
            }
            let b = lookup[r2 * w + c2 as usize];
            if b >= 0 {
                f(a as u32, b as u32);
            }
        }
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
    let h = cloud.height;
    let offsets = connectivity.offsets();
    // Pass 1: edges per row and their offsets; pass 2: rows fill their own slices.
    let mut edge_start = vec![0u32; h + 1];
    edge_start[1..]
        .par_iter_mut()
        .enumerate()
        .for_each(|(row, n)| {
            let mut count = 0u32;
            row_edges(cloud, offsets, row, |_, _| count += 1);
            *n = count;
        });
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
        .enumerate()
        .for_each(|(row, ((edges, distance), depth_diff))| {
            let mut k = 0;
            row_edges(cloud, offsets, row, |a, b| {
                let (p, q) = (cloud.points[a as usize], cloud.points[b as usize]);
                let d = sub(q, p);
                edges[k] = [a, b];
                distance[k] = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                depth_diff[k] = d[2];
                k += 1;
            });
        });
}

#[cfg(test)]
mod tests {
    use super::*;

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
