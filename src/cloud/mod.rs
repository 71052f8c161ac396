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

/// Valid (foreground) depth pixels as 3-D points.
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
}

impl Cloud {
    /// Back-projects every pixel that has a reading and, if given, is in `mask`.
    pub fn from_depth(depth: &DepthView, camera: &Camera, mask: Option<&[bool]>) -> Result<Self> {
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
        let mut point_of_pixel = vec![-1i32; w * h];
        let mut pixels = Vec::with_capacity(w * h / 4);
        for (i, &z) in depth.data.iter().enumerate() {
            if z > 0.0 && mask.is_none_or(|m| m[i]) {
                point_of_pixel[i] = pixels.len() as i32;
                pixels.push(i as u32);
            }
        }
        let (fx, fy, cx, cy) = (
            camera.fx as f32,
            camera.fy as f32,
            camera.cx as f32,
            camera.cy as f32,
        );
        let points = pixels
            .par_iter()
            .map(|&i| {
                let i = i as usize;
                let (u, v) = ((i % w) as f32, (i / w) as f32);
                let z = depth.data[i];
                [(u - cx) * z / fx, (v - cy) * z / fy, z]
            })
            .collect();
        Ok(Cloud {
            width: w,
            height: h,
            points,
            pixels,
            point_of_pixel,
        })
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
    let (fx, fy, cx, cy) = (
        camera.fx as f32,
        camera.fy as f32,
        camera.cx as f32,
        camera.cy as f32,
    );
    let point_at = |row: isize, col: isize| -> Option<[f32; 3]> {
        if row < 0 || col < 0 || row >= h || col >= w {
            return None;
        }
        let z = depth.data[(row * w + col) as usize];
        (z > 0.0).then(|| [(col as f32 - cx) * z / fx, (row as f32 - cy) * z / fy, z])
    };
    out.par_iter_mut().enumerate().for_each(|(k, n)| {
        let p = cloud.points[k];
        let (row, col) = cloud.pixel(k);
        let (row, col) = (row as isize, col as isize);
        let jump = surface_jump(p[2]) * config.jump_scale * r as f32;
        let near = |q: Option<[f32; 3]>| q.filter(|q| (q[2] - p[2]).abs() <= jump);
        let tangent = |a: Option<[f32; 3]>, b: Option<[f32; 3]>| -> Option<[f32; 3]> {
            match (near(a), near(b)) {
                (Some(a), Some(b)) => Some(sub(b, a)),
                (Some(a), None) => Some(sub(p, a)),
                (None, Some(b)) => Some(sub(b, p)),
                (None, None) => None,
            }
        };
        let tu = tangent(point_at(row, col - r), point_at(row, col + r));
        let tv = tangent(point_at(row - r, col), point_at(row + r, col));
        let view = normalize([-p[0], -p[1], -p[2]]);
        *n = match (tu, tv) {
            (Some(tu), Some(tv)) => {
                let c = cross(tu, tv);
                let len = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
                if len > 0.0 && len.is_finite() {
                    let c = [c[0] / len, c[1] / len, c[2] / len];
                    // Face the camera: the normal points back toward the origin.
                    if c[0] * p[0] + c[1] * p[1] + c[2] * p[2] > 0.0 {
                        [-c[0], -c[1], -c[2]]
                    } else {
                        c
                    }
                } else {
                    view
                }
            }
            _ => view,
        };
    });
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

/// Edges between points of `cloud` whose pixels are 4- or 8-neighbours.
pub fn neighbour_graph(cloud: &Cloud, connectivity: Connectivity) -> PixelGraph {
    let (w, h) = (cloud.width, cloud.height);
    let offsets = connectivity.offsets();
    // Rows in parallel, each producing its own edge list, then concatenated in order.
    let per_row: Vec<Vec<[u32; 2]>> = (0..h)
        .into_par_iter()
        .map(|row| {
            let mut edges = Vec::new();
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
                        edges.push([a as u32, b as u32]);
                    }
                }
            }
            edges
        })
        .collect();
    let edges: Vec<[u32; 2]> = per_row.concat();
    let (distance, depth_diff): (Vec<f32>, Vec<f32>) = edges
        .par_iter()
        .map(|&[a, b]| {
            let (p, q) = (cloud.points[a as usize], cloud.points[b as usize]);
            let d = sub(q, p);
            ((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt(), d[2])
        })
        .unzip();
    PixelGraph {
        edges,
        distance,
        depth_diff,
    }
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
