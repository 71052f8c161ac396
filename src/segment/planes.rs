//! Support planes — floor, walls, ceiling — of a depth image, found by RANSAC with a
//! robust refit.
//!
//! A plane is `n·X = d` in the camera frame (`n` unit, `d > 0`: the camera is on the side
//! `n·X < d`). A pixel with depth `z` on the ray `r = ((u − cx)/fx, (v − cy)/fy, 1)` lies
//! on the plane when its depth is within the sensor's tolerance `tol(z)` of the plane's
//! depth along that ray, `d / (n·r)`. Measuring along the ray (as background subtraction
//! does) rather than perpendicular to the plane matters at grazing angles: a foot 5 cm
//! above the floor seen from 1 m up and 4 m away is 5 cm from the plane but 20 cm in
//! front of it along the ray, so it stays with the body.
//!
//! Hypotheses are drawn from a grid of sample pixels: the first point anywhere, the other
//! two near it in the image (a plane is locally coherent, so three nearby points lie on
//! one surface far more often than three random ones). The best hypothesis is refitted by
//! total least squares to its inliers over the whole image, twice, and kept when its
//! inliers cover at least [`PlaneConfig::min_area`] square metres — more than any body
//! part shows. Its pixels are removed and the search repeats.

use crate::camera::Camera;
use crate::cloud::DepthView;
use nalgebra::{Matrix3, SymmetricEigen, Vector3};

/// Settings of the support-plane search (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneConfig {
    /// Sample pixels the hypotheses are drawn from and scored on (a regular grid).
    pub samples: usize,
    /// RANSAC hypotheses per plane.
    pub iterations: usize,
    /// The second and third points of a hypothesis lie within this share of the image's
    /// larger side of the first.
    pub local_radius: f32,
    /// A plane is a support when its inliers cover at least this many square metres.
    pub min_area: f32,
    /// At most this many planes.
    pub max_planes: usize,
    /// A pixel is on a plane when its depth is within `tolerance + tolerance_quadratic·z²`
    /// metres of the plane's depth along its ray (the sensor's noise and quantisation
    /// grow with z²).
    pub tolerance: f32,
    pub tolerance_quadratic: f32,
    /// Seed of the hypotheses' random draws (the result is deterministic for a seed).
    pub seed: u64,
}

impl Default for PlaneConfig {
    fn default() -> Self {
        PlaneConfig {
            samples: 3000,
            iterations: 120,
            local_radius: 0.08,
            min_area: 1.0,
            max_planes: 4,
            tolerance: 0.03,
            tolerance_quadratic: 0.004,
            seed: 0x05ee_d0f9_1a9e,
        }
    }
}

impl PlaneConfig {
    /// The depth tolerance at depth `z`.
    #[inline]
    pub fn tolerance_at(&self, z: f32) -> f32 {
        self.tolerance + self.tolerance_quadratic * z * z
    }
}

/// A support plane `normal·X = offset` (camera frame, metres), `offset > 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    pub normal: [f64; 3],
    pub offset: f64,
    /// Pixels within the tolerance of the plane (of those it was detected on).
    pub inliers: usize,
    /// Area its inlier pixels cover on the plane, square metres.
    pub area: f64,
}

impl Plane {
    /// The plane through three points, oriented away from the camera; None when they
    /// are nearly collinear or the plane passes near the camera.
    fn through(a: Vector3<f64>, b: Vector3<f64>, c: Vector3<f64>) -> Option<Self> {
        let n = (b - a).cross(&(c - a));
        // Twice the triangle's area: below 2·(2 cm)² the normal is mostly noise.
        let norm = n.norm();
        if norm < 8e-4 {
            return None;
        }
        Self::from_normal(n / norm, a)
    }

    /// The plane with unit normal `n` through `p`, oriented so that the offset is positive.
    fn from_normal(n: Vector3<f64>, p: Vector3<f64>) -> Option<Self> {
        let d = n.dot(&p);
        if d.abs() < 0.05 {
            return None; // through the camera: seen edge-on, not a support
        }
        let s = d.signum();
        Some(Plane {
            normal: [s * n.x, s * n.y, s * n.z],
            offset: s * d,
            inliers: 0,
            area: 0.0,
        })
    }

    /// `n·r` for the ray `r = (x, y, 1)`; positive when the ray meets the plane in front
    /// of the camera.
    #[inline]
    pub fn facing(&self, rx: f32, ry: f32) -> f32 {
        (self.normal[0] as f32) * rx + (self.normal[1] as f32) * ry + self.normal[2] as f32
    }

    /// The plane's depth along the ray `(x, y, 1)`, or infinity where the ray does not
    /// meet it in front of the camera.
    #[inline]
    pub fn depth_along(&self, rx: f32, ry: f32) -> f32 {
        let f = self.facing(rx, ry);
        if f > 1e-6 {
            self.offset as f32 / f
        } else {
            f32::INFINITY
        }
    }

    /// Whether a pixel of depth `z` on the ray `(rx, ry, 1)` lies on the plane within
    /// `tol` metres of depth: `|z·(n·r) − d| ≤ tol·(n·r)`, no division.
    #[inline]
    pub fn holds(&self, rx: f32, ry: f32, z: f32, tol: f32) -> bool {
        let f = self.facing(rx, ry);
        f > 0.0 && (z * f - self.offset as f32).abs() <= tol * f
    }
}

/// Rays of the pixel grid: `x = (u − cx)/fx` per column and `y = (v − cy)/fy` per row.
pub(crate) struct Rays {
    pub x: Vec<f32>,
    pub y: Vec<f32>,
    /// Area of a pixel's footprint at depth 1 on a fronto-parallel plane: 1/(fx·fy).
    pub pixel_area: f32,
}

impl Rays {
    pub fn new(camera: &Camera, width: usize, height: usize) -> Self {
        Rays {
            x: (0..width)
                .map(|u| ((u as f64 - camera.cx) / camera.fx) as f32)
                .collect(),
            y: (0..height)
                .map(|v| ((v as f64 - camera.cy) / camera.fy) as f32)
                .collect(),
            pixel_area: (1.0 / (camera.fx * camera.fy)) as f32,
        }
    }
}

/// One sample pixel: its grid cell, ray and depth.
#[derive(Clone, Copy)]
struct Sample {
    cell: u32,
    rx: f32,
    ry: f32,
    z: f32,
}

impl Sample {
    fn point(&self) -> Vector3<f64> {
        let z = self.z as f64;
        Vector3::new(self.rx as f64 * z, self.ry as f64 * z, z)
    }
}

/// A small deterministic generator (xorshift64*): the hypotheses must not depend on
/// anything but the seed and the image.
struct Rng(u64);

impl Rng {
    fn new(seed: u64) -> Self {
        Rng(seed.max(1))
    }

    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    /// Uniform in `0..n` (n > 0).
    fn below(&mut self, n: usize) -> usize {
        ((self.next() >> 32) as usize * n) >> 32
    }
}

/// The support planes of `depth` (see the module docs), largest first, and for each
/// pixel whether it lies on one of them. `usable[i]` says which pixels may belong to a
/// plane at all (a reading in range). `previous` planes (a video's last frame) are tried
/// first: each is refitted and kept while it still covers `min_area`; the search for
/// new planes then runs on what they leave. Hypotheses, refits and areas use the sample
/// grid; one pass over every pixel then marks the planes' pixels. `rays`: the
/// camera's rays for this image ([`Rays::new`]).
pub(crate) fn detect_planes(
    depth: &DepthView,
    rays: &Rays,
    usable: &[bool],
    config: &PlaneConfig,
    previous: &[Plane],
) -> (Vec<Plane>, Vec<bool>) {
    let (w, h) = (depth.width, depth.height);
    let valid = usable.iter().filter(|&&u| u).count();
    let mut planes: Vec<Plane> = Vec::new();
    if valid < 3 || config.max_planes == 0 {
        return (planes, vec![false; w * h]);
    }
    // The sample grid: every `stride`-th pixel of every `stride`-th row.
    let stride = ((valid as f64 / config.samples.max(1) as f64).sqrt().floor() as usize).max(1);
    let (gw, gh) = (w.div_ceil(stride), h.div_ceil(stride));
    let mut grid: Vec<i32> = vec![-1; gw * gh];
    let mut samples: Vec<Sample> = Vec::with_capacity(gw * gh);
    for (gr, row) in (0..h).step_by(stride).enumerate() {
        for (gc, col) in (0..w).step_by(stride).enumerate() {
            let i = row * w + col;
            if usable[i] {
                grid[gr * gw + gc] = samples.len() as i32;
                samples.push(Sample {
                    cell: (gr * gw + gc) as u32,
                    rx: rays.x[col],
                    ry: rays.y[row],
                    z: depth.data[i],
                });
            }
        }
    }
    let sample_area = (stride * stride) as f64 * rays.pixel_area as f64;
    let mut alive = vec![true; samples.len()];
    let radius = ((config.local_radius * w.max(h) as f32 / stride as f32).round() as usize).max(2);
    let mut rng = Rng::new(config.seed);
    // The previous frame's planes first (a camera that does not move sees the same
    // ones), then new ones, largest first, until the best left is too small.
    let mut previous = previous.iter().take(config.max_planes);
    while planes.len() < config.max_planes {
        let from_previous = previous.len() > 0;
        let hypothesis = match previous.next() {
            Some(p) => Some(*p),
            None => best_hypothesis(&samples, &alive, &grid, (gw, gh), radius, config, &mut rng),
        };
        let Some(mut plane) = hypothesis else { break };
        for _ in 0..2 {
            match refit(&samples, &alive, &plane, config) {
                Some(p) => plane = p,
                None => break,
            }
        }
        let area = sample_area * footprint(&samples, &alive, &plane, config);
        if area < config.min_area as f64 {
            if from_previous {
                continue; // gone from view; the search below may find others
            }
            break;
        }
        plane.area = area;
        for (s, a) in samples.iter().zip(alive.iter_mut()) {
            *a &= !plane.holds(s.rx, s.ry, s.z, config.tolerance_at(s.z));
        }
        planes.push(plane);
    }
    let on_plane = mark_pixels(depth, rays, usable, &mut planes, config);
    (planes, on_plane)
}

/// Marks the usable pixels that lie on one of `planes` and counts each plane's.
fn mark_pixels(
    depth: &DepthView,
    rays: &Rays,
    usable: &[bool],
    planes: &mut [Plane],
    config: &PlaneConfig,
) -> Vec<bool> {
    let w = depth.width;
    let mut on_plane = vec![false; usable.len()];
    if planes.is_empty() {
        return on_plane;
    }
    for (row, &ry) in rays.y.iter().enumerate() {
        let (z_row, use_row) = (&depth.data[row * w..][..w], &usable[row * w..][..w]);
        let out = &mut on_plane[row * w..][..w];
        for plane in planes.iter_mut() {
            let mut count = 0;
            for (col, &rx) in rays.x.iter().enumerate() {
                let z = z_row[col];
                if use_row[col] && !out[col] && plane.holds(rx, ry, z, config.tolerance_at(z)) {
                    out[col] = true;
                    count += 1;
                }
            }
            plane.inliers += count;
        }
    }
    on_plane
}

/// The hypothesis with the most inlier samples among `config.iterations` draws, or None
/// when no draw gave a plane.
fn best_hypothesis(
    samples: &[Sample],
    alive: &[bool],
    grid: &[i32],
    (gw, gh): (usize, usize),
    radius: usize,
    config: &PlaneConfig,
    rng: &mut Rng,
) -> Option<Plane> {
    let live: Vec<u32> = (0..samples.len() as u32)
        .filter(|&k| alive[k as usize])
        .collect();
    if live.len() < 3 {
        return None;
    }
    let mut best: Option<(usize, Plane)> = None;
    for _ in 0..config.iterations {
        let first = live[rng.below(live.len())] as usize;
        let s0 = samples[first];
        let cell = s0.cell as usize;
        let (gr, gc) = (cell / gw, cell % gw);
        let mut near = || -> Option<Sample> {
            for _ in 0..8 {
                let r = gr as isize + rng.below(2 * radius + 1) as isize - radius as isize;
                let c = gc as isize + rng.below(2 * radius + 1) as isize - radius as isize;
                if r < 0 || c < 0 || r >= gh as isize || c >= gw as isize {
                    continue;
                }
                let g = grid[r as usize * gw + c as usize];
                if g >= 0 && g as usize != first && alive[g as usize] {
                    return Some(samples[g as usize]);
                }
            }
            None
        };
        let (Some(s1), Some(s2)) = (near(), near()) else {
            continue;
        };
        let Some(plane) = Plane::through(s0.point(), s1.point(), s2.point()) else {
            continue;
        };
        let score = samples
            .iter()
            .zip(alive)
            .filter(|(s, &a)| a && plane.holds(s.rx, s.ry, s.z, config.tolerance_at(s.z)))
            .count();
        if best.as_ref().is_none_or(|(b, _)| score > *b) {
            best = Some((score, plane));
        }
    }
    best.map(|(_, p)| p)
}

/// Total least squares refit of `plane` to its inlier samples among the live ones, each
/// weighted by 1/tol(z)² (far pixels are noisier). None when fewer than three hold.
fn refit(samples: &[Sample], alive: &[bool], plane: &Plane, config: &PlaneConfig) -> Option<Plane> {
    let (mut sw, mut s1, mut s2) = (0.0f64, Vector3::zeros(), Matrix3::zeros());
    let mut count = 0usize;
    for (s, _) in samples.iter().zip(alive).filter(|(_, &a)| a) {
        let tol = config.tolerance_at(s.z);
        if !plane.holds(s.rx, s.ry, s.z, tol) {
            continue;
        }
        let wt = 1.0 / (tol as f64 * tol as f64);
        let p = s.point();
        sw += wt;
        s1 += wt * p;
        s2 += wt * p * p.transpose();
        count += 1;
    }
    if count < 3 {
        return None;
    }
    let mean = s1 / sw;
    let cov = s2 / sw - mean * mean.transpose();
    let eig = SymmetricEigen::new(cov);
    let k = eig.eigenvalues.imin();
    let n: Vector3<f64> = eig.eigenvectors.column(k).into();
    Plane::from_normal(n.normalize(), mean)
}

/// The live samples' footprint on `plane` in units of a pixel's at depth 1: Σ z²/(n·r)
/// over the samples that lie on it (n·r bounded below: grazing pixels are unreliable).
fn footprint(samples: &[Sample], alive: &[bool], plane: &Plane, config: &PlaneConfig) -> f64 {
    samples
        .iter()
        .zip(alive)
        .filter(|(s, &a)| a && plane.holds(s.rx, s.ry, s.z, config.tolerance_at(s.z)))
        .map(|(s, _)| (s.z * s.z / plane.facing(s.rx, s.ry).max(0.1)) as f64)
        .sum()
}
