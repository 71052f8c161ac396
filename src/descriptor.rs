//! Surface-context descriptors (paper Section II-C, eqs. 2–4; after the shape context of
//! Belongie, Malik and Puzicha).
//!
//! 1. The silhouette's pixels are summarised on a grid scaled to the silhouette (cell
//!    side `sqrt(area / (samples · cells_per_sample))`, origin at the silhouette's
//!    bounding box, jittered by the seed): each cell keeps its pixel count, mean pixel
//!    position and the sum of its surface normals.
//! 2. Sample points: a coarser grid of the same kind with about `samples` occupied
//!    cells; in each, the pixel nearest the cell centre.
//! 3. Around each sample, log-polar bins in the image plane (`radial_bins` log-spaced
//!    rings from `inner_radius` to `outer_radius` times the mean pairwise distance of
//!    the samples, `angular_bins` sectors); a bin holds the sum of the normals of the
//!    pixels falling in it divided by the silhouette's pixel count. The descriptor is
//!    those sums concatenated (3 values per bin).
//!
//! Because both grids and the radii scale with the silhouette, the descriptors do not
//! change (up to pixel quantisation) when the body moves in the image or comes closer;
//! every sum is order-independent, so neither does shuffling the input points. Normals
//! are first rotated so the line of sight to the body's centroid becomes +z, so a body
//! off the optical axis is described as if seen straight on.

use crate::camera::Camera;
use crate::cloud::{normals_from_depth, Cloud, DepthView, NormalConfig};
use crate::error::{ensure, Error, Result};
use nalgebra::{Rotation3, Vector3};
use rayon::prelude::*;

/// Settings of the surface-context descriptors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DescriptorConfig {
    /// Target number of sample points (the actual count is within a few of it).
    pub samples: usize,
    /// Log-spaced rings.
    pub radial_bins: usize,
    /// Sectors.
    pub angular_bins: usize,
    /// Inner and outer ring radius, in units of the mean pairwise sample distance;
    /// points closer than `inner_radius` fall in the first ring, farther than
    /// `outer_radius` in none.
    pub inner_radius: f64,
    pub outer_radius: f64,
    /// Summary cells per sample cell (the normal grid is this many times finer).
    pub cells_per_sample: f64,
    /// Seed of the grid jitter; equal seeds give identical descriptors.
    pub seed: u64,
    /// Normal estimation.
    pub normal_radius: usize,
    /// Weight of the optional fourth value per bin, the body's relief: the depth of
    /// each point relative to the body's centre, in units of the body's RMS radius
    /// across the line of sight (so it is scale-invariant like the rest), summed per
    /// bin like the normals. 0 (the default): off, the paper's normals-only
    /// descriptor. The normals alone cannot tell an arm held toward the camera from
    /// one hanging down in front of the body; the relief can (docs/templates.md).
    pub depth_weight: f64,
}

impl Default for DescriptorConfig {
    fn default() -> Self {
        DescriptorConfig {
            samples: 100,
            radial_bins: 5,
            angular_bins: 12,
            inner_radius: 0.125,
            outer_radius: 2.0,
            cells_per_sample: 4.0,
            seed: 0,
            normal_radius: 2,
            depth_weight: 0.0,
        }
    }
}

/// Fewest sample points / silhouette pixels we describe.
pub const MIN_SAMPLES: usize = 4;
pub const MIN_POINTS: usize = 20;
/// Silhouette points farther than this from the median depth (m) are not the body: a
/// body with an arm stretched toward the camera spans well under it.
pub const MAX_DEPTH_FROM_MEDIAN: f32 = 1.0;
/// Refinements of the sample-grid step toward the target sample count.
const GRID_REFINEMENTS: usize = 3;

impl DescriptorConfig {
    pub fn validate(&self) -> Result<()> {
        ensure(
            (MIN_SAMPLES..=10_000).contains(&self.samples),
            "samples",
            || format!("must be in {MIN_SAMPLES}..=10000, got {}", self.samples),
        )?;
        ensure((1..=32).contains(&self.radial_bins), "radial_bins", || {
            format!("must be in 1..=32, got {}", self.radial_bins)
        })?;
        ensure(
            (1..=64).contains(&self.angular_bins),
            "angular_bins",
            || format!("must be in 1..=64, got {}", self.angular_bins),
        )?;
        ensure(
            self.inner_radius.is_finite()
                && self.inner_radius > 0.0
                && self.outer_radius.is_finite()
                && self.outer_radius > self.inner_radius,
            "inner_radius/outer_radius",
            || {
                format!(
                    "need 0 < inner < outer, got {} and {}",
                    self.inner_radius, self.outer_radius
                )
            },
        )?;
        ensure(
            self.cells_per_sample.is_finite() && (1.0..=100.0).contains(&self.cells_per_sample),
            "cells_per_sample",
            || format!("must be in 1..=100, got {}", self.cells_per_sample),
        )?;
        ensure(
            (1..=32).contains(&self.normal_radius),
            "normal_radius",
            || format!("must be in 1..=32, got {}", self.normal_radius),
        )?;
        ensure(
            self.depth_weight.is_finite() && (0.0..=100.0).contains(&self.depth_weight),
            "depth_weight",
            || format!("must be in 0..=100, got {}", self.depth_weight),
        )
    }

    /// Values per bin: the normal sum, and the relief sum when `depth_weight` > 0.
    pub fn values_per_bin(&self) -> usize {
        if self.depth_weight > 0.0 {
            4
        } else {
            3
        }
    }

    /// Values per descriptor.
    pub fn dim(&self) -> usize {
        self.values_per_bin() * self.radial_bins * self.angular_bins
    }
}

/// The descriptors of one silhouette.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SurfaceContext {
    /// Values per descriptor.
    pub dim: usize,
    /// Sample positions in pixels (u, v).
    pub pixels: Vec<[f32; 2]>,
    /// Sample positions relative to the silhouette centroid, in units of `scale`.
    pub positions: Vec<[f32; 2]>,
    /// Descriptors, samples × `dim`, row-major.
    pub descriptors: Vec<f32>,
    /// Mean pairwise distance of the samples (pixels): the unit of the log-polar radii.
    pub scale: f64,
    /// Silhouette centroid (pixels).
    pub centroid: [f64; 2],
    /// Number of silhouette pixels described.
    pub points: usize,
}

impl SurfaceContext {
    pub fn len(&self) -> usize {
        self.pixels.len()
    }

    pub fn is_empty(&self) -> bool {
        self.pixels.is_empty()
    }

    /// Descriptor of sample `i`.
    #[inline]
    pub fn descriptor(&self, i: usize) -> &[f32] {
        &self.descriptors[i * self.dim..(i + 1) * self.dim]
    }
}

/// splitmix64: a tiny deterministic generator for the grid jitter.
fn splitmix(state: &mut u64) -> f64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

/// A grid over the silhouette's bounding box.
struct Grid {
    origin: [f64; 2],
    step: f64,
    cols: usize,
    rows: usize,
}

impl Grid {
    fn new(lo: [f64; 2], hi: [f64; 2], step: f64, jitter: [f64; 2]) -> Self {
        let origin = [lo[0] - jitter[0] * step, lo[1] - jitter[1] * step];
        let cols = ((hi[0] - origin[0]) / step).floor() as usize + 1;
        let rows = ((hi[1] - origin[1]) / step).floor() as usize + 1;
        Grid {
            origin,
            step,
            cols,
            rows,
        }
    }

    #[inline]
    fn cell(&self, p: [f32; 2]) -> usize {
        let c = ((p[0] as f64 - self.origin[0]) / self.step) as usize;
        let r = ((p[1] as f64 - self.origin[1]) / self.step) as usize;
        r.min(self.rows - 1) * self.cols + c.min(self.cols - 1)
    }

    fn centre(&self, cell: usize) -> [f64; 2] {
        let (r, c) = (cell / self.cols, cell % self.cols);
        [
            self.origin[0] + (c as f64 + 0.5) * self.step,
            self.origin[1] + (r as f64 + 0.5) * self.step,
        ]
    }

    fn occupied(&self, pixels: &[[f32; 2]], seen: &mut Vec<bool>) -> usize {
        seen.clear();
        seen.resize(self.rows * self.cols, false);
        let mut n = 0;
        for p in pixels {
            let c = self.cell(*p);
            if !seen[c] {
                seen[c] = true;
                n += 1;
            }
        }
        n
    }
}

/// Surface-context descriptors of a silhouette given as pixel positions (u, v) — one
/// point per pixel, in any order — and the unit normal of each.
pub fn surface_context_from_points(
    pixels: &[[f32; 2]],
    normals: &[[f32; 3]],
    config: &DescriptorConfig,
) -> Result<SurfaceContext> {
    surface_context_with_relief(pixels, normals, None, config)
}

/// [`surface_context_from_points`] with each point's relief (see
/// [`DescriptorConfig::depth_weight`], before the weight), needed when the weight is
/// not 0 and ignored when it is.
pub fn surface_context_with_relief(
    pixels: &[[f32; 2]],
    normals: &[[f32; 3]],
    relief: Option<&[f32]>,
    config: &DescriptorConfig,
) -> Result<SurfaceContext> {
    config.validate()?;
    ensure(pixels.len() == normals.len(), "normals", || {
        format!("has {} normals for {} points", normals.len(), pixels.len())
    })?;
    let per = config.values_per_bin();
    let relief = if per == 4 {
        let r = relief.ok_or_else(|| {
            Error::invalid(
                "depth_weight",
                "the relief channel needs depth: describe a depth image, not bare normals",
            )
        })?;
        ensure(r.len() == pixels.len(), "relief", || {
            format!("has {} values for {} points", r.len(), pixels.len())
        })?;
        ensure(r.iter().all(|v| v.is_finite()), "relief", || {
            "must be finite".to_string()
        })?;
        Some(r)
    } else {
        None
    };
    if pixels.len() < MIN_POINTS {
        return Err(Error::NoBody(format!(
            "the silhouette has {} pixels; at least {MIN_POINTS} are needed to describe it",
            pixels.len()
        )));
    }
    ensure(
        pixels.iter().flatten().all(|v| v.is_finite())
            && normals.iter().flatten().all(|v| v.is_finite()),
        "points",
        || "pixel positions and normals must be finite".to_string(),
    )?;
    let m = pixels.len();
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    let mut centroid = [0.0f64; 2];
    for p in pixels {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k] as f64);
            hi[k] = hi[k].max(p[k] as f64);
            centroid[k] += p[k] as f64;
        }
    }
    centroid = [centroid[0] / m as f64, centroid[1] / m as f64];
    let mut rng = config.seed;
    let jitter = [splitmix(&mut rng), splitmix(&mut rng)];

    // Sample grid: step refined until about `samples` cells are occupied (occupancy
    // ∝ 1/step² away from the boundary).
    let mut seen = Vec::new();
    let mut step = (m as f64 / config.samples as f64).sqrt();
    for _ in 0..GRID_REFINEMENTS {
        let n = Grid::new(lo, hi, step, jitter).occupied(pixels, &mut seen);
        step *= (n as f64 / config.samples as f64).sqrt();
    }
    let grid = Grid::new(lo, hi, step, jitter);
    // Per cell the pixel nearest its centre; ties broken by (v, u) so input order
    // does not matter.
    let mut best: Vec<(f64, [f32; 2])> = vec![(f64::INFINITY, [0.0; 2]); grid.rows * grid.cols];
    for p in pixels {
        let c = grid.cell(*p);
        let centre = grid.centre(c);
        let d = (p[0] as f64 - centre[0]).powi(2) + (p[1] as f64 - centre[1]).powi(2);
        let b = &mut best[c];
        if d < b.0 || (d == b.0 && (p[1], p[0]) < (b.1[1], b.1[0])) {
            *b = (d, *p);
        }
    }
    let samples: Vec<[f32; 2]> = best
        .iter()
        .filter(|b| b.0.is_finite())
        .map(|b| b.1)
        .collect();
    let n = samples.len();
    ensure(n >= 2, "points", || {
        "the silhouette is too small to sample".to_string()
    })?;

    // Summary cells: count, mean position, normal sum and relief sum (f64:
    // order-independent up to rounding).
    let fine = Grid::new(lo, hi, step / config.cells_per_sample.sqrt(), jitter);
    let mut acc = vec![[0.0f64; 7]; fine.rows * fine.cols];
    for (k, (p, nrm)) in pixels.iter().zip(normals).enumerate() {
        let a = &mut acc[fine.cell(*p)];
        if let Some(r) = relief {
            a[6] += config.depth_weight * r[k] as f64;
        }
        a[0] += 1.0;
        a[1] += p[0] as f64;
        a[2] += p[1] as f64;
        a[3] += nrm[0] as f64;
        a[4] += nrm[1] as f64;
        a[5] += nrm[2] as f64;
    }
    let inv_m = 1.0 / m as f64;
    let cells: Vec<[f32; 6]> = acc
        .iter()
        .filter(|a| a[0] > 0.0)
        .map(|a| {
            [
                (a[1] / a[0]) as f32,
                (a[2] / a[0]) as f32,
                (a[3] * inv_m) as f32,
                (a[4] * inv_m) as f32,
                (a[5] * inv_m) as f32,
                (a[6] * inv_m) as f32,
            ]
        })
        .collect();

    let mut total = 0.0f64;
    for i in 0..n {
        for j in i + 1..n {
            let d = [
                (samples[i][0] - samples[j][0]) as f64,
                (samples[i][1] - samples[j][1]) as f64,
            ];
            total += d[0].hypot(d[1]);
        }
    }
    let scale = total / (n * (n - 1) / 2) as f64;
    ensure(scale > 0.0, "points", || {
        "the samples coincide; the silhouette has no extent".to_string()
    })?;

    let dim = config.dim();
    let mut descriptors = vec![0.0f32; n * dim];
    let bins = LogPolarBins::new(config, scale);
    let outer2 = bins.outer2;
    let na = config.angular_bins;
    descriptors
        .par_chunks_mut(dim)
        .zip(samples.par_iter())
        .for_each(|(desc, s)| {
            for c in &cells {
                let (du, dv) = (c[0] - s[0], c[1] - s[1]);
                let r2 = du * du + dv * dv;
                if r2 >= outer2 {
                    continue;
                }
                let k = per * (bins.ring(r2) * na + bins.sector(du, dv));
                desc[k] += c[2];
                desc[k + 1] += c[3];
                desc[k + 2] += c[4];
                if per == 4 {
                    desc[k + 3] += c[5];
                }
            }
        });
    let positions = samples
        .iter()
        .map(|s| {
            [
                ((s[0] as f64 - centroid[0]) / scale) as f32,
                ((s[1] as f64 - centroid[1]) / scale) as f32,
            ]
        })
        .collect();
    Ok(SurfaceContext {
        dim,
        pixels: samples,
        positions,
        descriptors,
        scale,
        centroid,
        points: m,
    })
}

/// The log-polar bins around a sample, found by comparisons instead of a logarithm
/// and an arc tangent per pixel cell (those were a quarter of a frame's descriptor
/// time).
///
/// Ring r holds the offsets of length in [inner·q^r, inner·q^(r+1)), q = (outer /
/// inner)^(1/rings), the first ring also everything nearer, the last everything
/// farther (up to `outer`, beyond which nothing counts): the ring is the number of
/// inner edges at or below the squared length. Sector a holds the directions whose
/// angle atan2(dv, du) lies in [−π + aΔ, −π + (a+1)Δ), Δ = 2π / sectors, angle π
/// (and the zero offset's 0) included as atan2 gives them: the sector is the number of
/// sector edges (inside (−π, π)) at or below the angle, counted with cross products
/// against the edges' unit vectors in the offset's half plane, where they order like
/// the angles. Up to rounding at the edges, the same bins as the formulas
/// `⌊(ln r − ln inner)·rings / ln(outer / inner)⌋` and `⌊(atan2 + π) / Δ⌋`
/// (`log_polar_bins_equal_the_formulas`).
struct LogPolarBins {
    /// Squared inner edges of rings 1..rings, ascending.
    ring_edges2: Vec<f32>,
    /// Squared outer radius.
    outer2: f32,
    /// Unit vectors of the sector edges with angle in (−π, 0] and in (0, π), ascending.
    lower_edges: Vec<[f32; 2]>,
    upper_edges: Vec<[f32; 2]>,
}

impl LogPolarBins {
    fn new(config: &DescriptorConfig, scale: f64) -> Self {
        let (nr, na) = (config.radial_bins, config.angular_bins);
        let (inner, outer) = (config.inner_radius * scale, config.outer_radius * scale);
        let ring_edges2 = (1..nr)
            .map(|r| {
                let edge = inner * (outer / inner).powf(r as f64 / nr as f64);
                (edge * edge) as f32
            })
            .collect();
        let (mut lower_edges, mut upper_edges) = (Vec::new(), Vec::new());
        for a in 1..na {
            let angle = -std::f64::consts::PI + a as f64 * std::f64::consts::TAU / na as f64;
            let unit = [angle.cos() as f32, angle.sin() as f32];
            if angle <= 0.0 {
                lower_edges.push(unit);
            } else {
                upper_edges.push(unit);
            }
        }
        let outer = outer as f32;
        LogPolarBins {
            ring_edges2,
            outer2: outer * outer,
            lower_edges,
            upper_edges,
        }
    }

    /// Ring of an offset of squared length `r2` (< `outer2`).
    #[inline]
    fn ring(&self, r2: f32) -> usize {
        self.ring_edges2.iter().filter(|&&e| r2 >= e).count()
    }

    /// Sector of the offset (du, dv).
    #[inline]
    fn sector(&self, du: f32, dv: f32) -> usize {
        // At or below the edge's angle ⇔ the edge turns counter-clockwise onto the offset.
        let at_or_after = |e: &&[f32; 2]| e[0] * dv - e[1] * du >= 0.0;
        if dv > 0.0 {
            self.lower_edges.len() + self.upper_edges.iter().filter(at_or_after).count()
        } else if dv == 0.0 && du < 0.0 {
            0 // angle ±π: the first sector, as ⌊2π / Δ⌋ mod sectors gives
        } else {
            self.lower_edges.iter().filter(at_or_after).count()
        }
    }
}

/// The rotation taking the unit line of sight `dir` to +z (the shortest arc).
pub fn line_of_sight_alignment(dir: &Vector3<f64>) -> Rotation3<f64> {
    Rotation3::rotation_between(dir, &Vector3::z()).unwrap_or_else(Rotation3::identity)
}

/// A silhouette ready to describe: its cloud, normals (aligned to the line of sight)
/// and 3-D centroid.
#[derive(Debug, Clone)]
pub struct Silhouette {
    pub cloud: Cloud,
    /// Unit normals, rotated by `alignment`.
    pub normals: Vec<[f32; 3]>,
    /// Mean of the 3-D points (camera frame).
    pub centroid: Vector3<f64>,
    /// Rotation taking the line of sight to the centroid onto +z.
    pub alignment: Rotation3<f64>,
}

impl Silhouette {
    /// Back-projects the masked depth pixels and estimates their normals.
    pub fn from_depth(
        depth: &DepthView,
        camera: &Camera,
        mask: Option<&[bool]>,
        normal_radius: usize,
    ) -> Result<Self> {
        let mut cloud = Cloud::from_depth(depth, camera, mask)?;
        // Masks from background subtraction or ground truth can hold a few pixels of
        // the floor or wall behind the body: drop points far from the median depth.
        if !cloud.is_empty() {
            let mut z: Vec<f32> = cloud.points.iter().map(|p| p[2]).collect();
            let mid = z.len() / 2;
            let median = *z.select_nth_unstable_by(mid, f32::total_cmp).1;
            let far = |p: &[f32; 3]| (p[2] - median).abs() > MAX_DEPTH_FROM_MEDIAN;
            if cloud.points.iter().any(far) {
                let mut keep = vec![false; depth.data.len()];
                for (p, &i) in cloud.points.iter().zip(&cloud.pixels) {
                    keep[i as usize] = !far(p);
                }
                cloud = Cloud::from_depth(depth, camera, Some(&keep))?;
            }
        }
        let centroid = match cloud.centroid() {
            Some(c) if cloud.len() >= MIN_POINTS => c,
            _ => {
                return Err(Error::NoBody(format!(
                    "only {} foreground pixels with depth; at least {MIN_POINTS} are needed",
                    cloud.len()
                )))
            }
        };
        let mut normals = normals_from_depth(
            depth,
            camera,
            &cloud,
            &NormalConfig {
                radius: normal_radius,
                ..Default::default()
            },
        );
        let alignment = line_of_sight_alignment(&centroid.normalize());
        let r = alignment.matrix().cast::<f32>();
        for n in normals.iter_mut() {
            let v = r * Vector3::from(*n);
            *n = [v.x, v.y, v.z];
        }
        Ok(Silhouette {
            cloud,
            normals,
            centroid,
            alignment,
        })
    }

    /// Pixel positions (u, v) of the points.
    pub fn pixels(&self) -> Vec<[f32; 2]> {
        (0..self.cloud.len())
            .map(|k| {
                let (r, c) = self.cloud.pixel(k);
                [c as f32, r as f32]
            })
            .collect()
    }

    /// Each point's relief: its depth relative to the centroid along the line of sight,
    /// in units of the RMS distance of the points from the centroid across it (see
    /// [`DescriptorConfig::depth_weight`]).
    pub fn relief(&self) -> Vec<f32> {
        let r = self.alignment.matrix();
        let local: Vec<Vector3<f64>> = self
            .cloud
            .points
            .iter()
            .map(|p| r * (Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64) - self.centroid))
            .collect();
        let across = local.iter().map(|v| v.x * v.x + v.y * v.y).sum::<f64>();
        let rms = (across / local.len().max(1) as f64).sqrt().max(1e-9);
        local.iter().map(|v| (v.z / rms) as f32).collect()
    }

    /// Its surface-context descriptors.
    pub fn surface_context(&self, config: &DescriptorConfig) -> Result<SurfaceContext> {
        let relief = (config.depth_weight > 0.0).then(|| self.relief());
        surface_context_with_relief(&self.pixels(), &self.normals, relief.as_deref(), config)
    }
}

/// Surface-context descriptors of the (masked) body in a depth image (metres, H×W).
pub fn surface_context_from_depth(
    depth: &DepthView,
    camera: &Camera,
    mask: Option<&[bool]>,
    config: &DescriptorConfig,
) -> Result<SurfaceContext> {
    config.validate()?;
    Silhouette::from_depth(depth, camera, mask, config.normal_radius)?.surface_context(config)
}

/// L2 distance between two descriptors.
#[inline]
pub fn descriptor_distance(a: &[f32], b: &[f32]) -> f32 {
    squared_distance(a, b).sqrt()
}

/// Lanes of the distance accumulator: independent partial sums let the compiler
/// vectorise (a single running f32 sum must stay sequential).
const LANES: usize = 8;

/// Squared L2 distance (the inner loop of matching).
#[inline]
pub fn squared_distance(a: &[f32], b: &[f32]) -> f32 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0f32; LANES];
    let mut ca = a.chunks_exact(LANES);
    let mut cb = b.chunks_exact(LANES);
    for (x, y) in (&mut ca).zip(&mut cb) {
        for k in 0..LANES {
            let d = x[k] - y[k];
            acc[k] += d * d;
        }
    }
    let mut total: f32 = acc.iter().sum();
    for (x, y) in ca.remainder().iter().zip(cb.remainder()) {
        total += (x - y) * (x - y);
    }
    total
}

/// [`squared_distance`] of `a` to four descriptors at once, each bit for bit the same
/// value (same lane sums in the same order).
///
/// Each distance is one dependent chain of adds, so computing one at a time waits on
/// the adder's latency; four independent chains keep it busy and load each chunk of
/// `a` once for four. With AVX2 (detected at run time) the chains are written with
/// intrinsics: left to itself, the compiler vectorised across the four distances
/// instead of along the lanes.
#[inline]
pub fn squared_distances_x4(a: &[f32], b: [&[f32]; 4]) -> [f32; 4] {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && b.iter().all(|b| b.len() == a.len()) {
        // SAFETY: the CPU supports AVX2 (checked just above); lengths checked too.
        return unsafe { squared_distances_x4_avx2(a, b) };
    }
    b.map(|b| squared_distance(a, b))
}

/// [`squared_distances_x4`] with AVX2; every `b[k]` as long as `a`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn squared_distances_x4_avx2(a: &[f32], b: [&[f32]; 4]) -> [f32; 4] {
    use std::arch::x86_64::*;
    let full = a.len() / LANES * LANES;
    let mut acc = [_mm256_setzero_ps(); 4];
    for c in (0..full).step_by(LANES) {
        // SAFETY: c + LANES <= full <= the length of `a` and of every `b[k]`.
        let x = _mm256_loadu_ps(a.as_ptr().add(c));
        for (acc, b) in acc.iter_mut().zip(&b) {
            let d = _mm256_sub_ps(x, _mm256_loadu_ps(b.as_ptr().add(c)));
            *acc = _mm256_add_ps(*acc, _mm256_mul_ps(d, d));
        }
    }
    std::array::from_fn(|k| {
        let mut lanes = [0.0f32; LANES];
        _mm256_storeu_ps(lanes.as_mut_ptr(), acc[k]);
        let mut total: f32 = lanes.iter().sum();
        for (x, y) in a[full..].iter().zip(&b[k][full..]) {
            total += (x - y) * (x - y);
        }
        total
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::BodyModel;

    fn render(pose: &crate::body::Pose, cam: &Camera) -> Vec<f32> {
        BodyModel::default().render_depth(pose, cam).0
    }

    fn context(depth: &[f32], cam: &Camera, cfg: &DescriptorConfig) -> SurfaceContext {
        let view = DepthView::new(depth, cam.height, cam.width, "depth").unwrap();
        surface_context_from_depth(&view, cam, None, cfg).unwrap()
    }

    /// Mean over samples of the distance to the nearest-position sample of `b`.
    fn mean_nearest(a: &SurfaceContext, b: &SurfaceContext) -> f32 {
        let mut total = 0.0;
        for i in 0..a.len() {
            let pa = a.positions[i];
            let j = (0..b.len())
                .min_by(|&x, &y| {
                    let dx = (b.positions[x][0] - pa[0]).hypot(b.positions[x][1] - pa[1]);
                    let dy = (b.positions[y][0] - pa[0]).hypot(b.positions[y][1] - pa[1]);
                    dx.total_cmp(&dy)
                })
                .unwrap();
            total += descriptor_distance(a.descriptor(i), b.descriptor(j));
        }
        total / a.len() as f32
    }

    fn arm_raised() -> crate::body::Pose {
        let mut p = BodyModel::neutral_pose();
        p[crate::body::param::R_SHOULDER + 1] = 1.5;
        p[crate::body::param::L_SHOULDER] = 1.4;
        p
    }

    #[test]
    fn shape_and_count() {
        let cam = Camera::itop();
        let cfg = DescriptorConfig::default();
        let sc = context(&render(&BodyModel::neutral_pose(), &cam), &cam, &cfg);
        assert_eq!(sc.dim, 180);
        assert_eq!(sc.descriptors.len(), sc.len() * 180);
        assert!((90..=110).contains(&sc.len()), "{}", sc.len());
        // The normal sums over all bins never exceed the share of points (≤ 1).
        for i in 0..sc.len() {
            let mag: f32 = sc
                .descriptor(i)
                .chunks(3)
                .map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt())
                .sum();
            assert!(mag <= 1.0 + 1e-4 && mag > 0.05, "{mag}");
        }
        // Positions are normalised: their mean pairwise distance is ≈ 1.
        let n = sc.len();
        let mut t = 0.0;
        for i in 0..n {
            for j in i + 1..n {
                t += (sc.positions[i][0] - sc.positions[j][0])
                    .hypot(sc.positions[i][1] - sc.positions[j][1]);
            }
        }
        assert!((t / (n * (n - 1) / 2) as f32 - 1.0).abs() < 1e-3);
    }

    #[test]
    fn deterministic_for_a_seed_and_varies_with_it() {
        let cam = Camera::itop();
        let d = render(&arm_raised(), &cam);
        let cfg = DescriptorConfig::default();
        assert_eq!(context(&d, &cam, &cfg), context(&d, &cam, &cfg));
        let other = context(&d, &cam, &DescriptorConfig { seed: 7, ..cfg });
        assert_ne!(other.pixels, context(&d, &cam, &cfg).pixels);
    }

    #[test]
    fn invariant_to_point_order() {
        let cam = Camera::itop();
        let d = render(&arm_raised(), &cam);
        let view = DepthView::new(&d, cam.height, cam.width, "depth").unwrap();
        let sil = Silhouette::from_depth(&view, &cam, None, 2).unwrap();
        let (px, nm) = (sil.pixels(), sil.normals.clone());
        let cfg = DescriptorConfig::default();
        let a = surface_context_from_points(&px, &nm, &cfg).unwrap();
        // A fixed pseudo-random permutation.
        let mut idx: Vec<usize> = (0..px.len()).collect();
        let mut s = 99u64;
        for i in (1..idx.len()).rev() {
            let j = (splitmix(&mut s) * (i + 1) as f64) as usize;
            idx.swap(i, j);
        }
        let px2: Vec<_> = idx.iter().map(|&i| px[i]).collect();
        let nm2: Vec<_> = idx.iter().map(|&i| nm[i]).collect();
        let b = surface_context_from_points(&px2, &nm2, &cfg).unwrap();
        assert_eq!(a.pixels, b.pixels);
        for (x, y) in a.descriptors.iter().zip(&b.descriptors) {
            assert!((x - y).abs() < 1e-6);
        }
    }

    #[test]
    fn invariant_to_translation_and_scale() {
        // The paper's normals-only descriptor, and with the relief channel.
        for depth_weight in [0.0, 3.0] {
            let cfg = DescriptorConfig {
                depth_weight,
                ..Default::default()
            };
            invariances_hold(&cfg);
        }
    }

    fn invariances_hold(cfg: &DescriptorConfig) {
        let cfg = *cfg;
        let cam = Camera::itop();
        let pose = arm_raised();
        let base = context(&render(&pose, &cam), &cam, &cfg);
        assert_eq!(base.dim, cfg.dim());
        assert_eq!(base.descriptors.len(), base.len() * cfg.dim());
        // Shifted in the image by an exact number of pixels: principal point moved.
        let shifted_cam = Camera::new(
            cam.fx,
            cam.fy,
            cam.cx + 23.0,
            cam.cy - 11.0,
            cam.width,
            cam.height,
        )
        .unwrap();
        let shifted = context(&render(&pose, &shifted_cam), &shifted_cam, &cfg);
        assert_eq!(shifted.points, base.points);
        for (a, b) in shifted.positions.iter().zip(&base.positions) {
            assert!((a[0] - b[0]).abs() < 1e-4 && (a[1] - b[1]).abs() < 1e-4);
        }
        for (a, b) in shifted.descriptors.iter().zip(&base.descriptors) {
            assert!((a - b).abs() < 1e-5);
        }
        // The same body farther away (fewer pixels) and a different pose.
        let mut far = pose;
        far[2] = 4.2;
        let far = context(&render(&far, &cam), &cam, &cfg);
        assert!(far.points < base.points * 6 / 10);
        let other = context(&render(&BodyModel::neutral_pose(), &cam), &cam, &cfg);
        let same = mean_nearest(&base, &far);
        let diff = mean_nearest(&base, &other);
        let typical: f32 = (0..base.len())
            .map(|i| base.descriptor(i).iter().map(|v| v * v).sum::<f32>().sqrt())
            .sum::<f32>()
            / base.len() as f32;
        assert!(
            same < 0.25 * typical,
            "scale change moved descriptors by {same} of {typical} ({cfg:?})"
        );
        assert!(diff > 1.5 * same, "same {same} other pose {diff} ({cfg:?})");
    }

    #[test]
    fn squared_distance_is_exact() {
        for n in [0usize, 3, 8, 13, 180] {
            let a: Vec<f32> = (0..n).map(|i| (i as f32 * 0.37).sin()).collect();
            let b: Vec<f32> = (0..n).map(|i| (i as f32 * 0.11).cos()).collect();
            let want: f64 = a
                .iter()
                .zip(&b)
                .map(|(x, y)| ((x - y) as f64).powi(2))
                .sum();
            assert!((squared_distance(&a, &b) as f64 - want).abs() < 1e-4 * (1.0 + want));
        }
    }

    /// The comparison bins against the logarithm and arc-tangent formulas, on offsets
    /// spread over the disc (and on the axes and the zero offset): equal wherever the
    /// offset is not within rounding of a bin edge.
    #[test]
    fn log_polar_bins_equal_the_formulas() {
        let config = DescriptorConfig::default();
        let scale = 37.5;
        let bins = LogPolarBins::new(&config, scale);
        let (nr, na) = (config.radial_bins, config.angular_bins);
        let inner = (config.inner_radius * scale) as f32;
        let outer = (config.outer_radius * scale) as f32;
        let mut s = 3u64;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        };
        let mut offsets: Vec<(f32, f32)> = (0..20_000)
            .map(|_| (outer * next(), outer * next()))
            .collect();
        offsets.extend([
            (0.0, 0.0),
            (3.0, 0.0),
            (-3.0, 0.0),
            (0.0, 3.0),
            (0.0, -3.0),
            (-3.0, -0.0),
        ]);
        let (mut checked, mut near_edge) = (0, 0);
        for (du, dv) in offsets {
            let r2 = du * du + dv * dv;
            if r2 >= bins.outer2 {
                continue;
            }
            let ring = (((0.5 * r2.ln() - inner.ln()) * nr as f32 / (outer / inner).ln()).max(0.0)
                as usize)
                .min(nr - 1);
            let theta = dv.atan2(du) + std::f32::consts::PI;
            let sector = ((theta * na as f32 / std::f32::consts::TAU) as usize) % na;
            // Within rounding of an edge, either bin is right.
            let ring_pos = (0.5 * r2.ln() - inner.ln()) * nr as f32 / (outer / inner).ln();
            let sector_pos = theta * na as f32 / std::f32::consts::TAU;
            let near = |x: f32| (x - x.round()).abs() < 1e-4;
            if (near(ring_pos) && ring_pos > 0.5) || (near(sector_pos) && r2 > 0.0) {
                near_edge += 1;
                continue;
            }
            assert_eq!(bins.ring(r2), ring, "ring of ({du}, {dv})");
            assert_eq!(bins.sector(du, dv), sector, "sector of ({du}, {dv})");
            checked += 1;
        }
        assert!(
            checked > 10_000 && near_edge < 50,
            "{checked} checked, {near_edge} near an edge"
        );
    }

    #[test]
    fn four_distances_equal_single_ones() {
        let mut s = 99u64;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        };
        for len in [0usize, 3, 8, 13, 180] {
            let a: Vec<f32> = (0..len).map(|_| next()).collect();
            let b: Vec<Vec<f32>> = (0..4).map(|_| (0..len).map(|_| next()).collect()).collect();
            let four = squared_distances_x4(&a, std::array::from_fn(|k| &b[k][..]));
            for k in 0..4 {
                assert_eq!(four[k].to_bits(), squared_distance(&a, &b[k]).to_bits());
            }
        }
    }

    #[test]
    fn bad_input_is_rejected() {
        let cfg = DescriptorConfig::default();
        let px = vec![[1.0f32, 2.0]; 50];
        let nm = vec![[0.0f32, 0.0, -1.0]; 49];
        assert!(matches!(
            surface_context_from_points(&px, &nm, &cfg),
            Err(Error::InvalidArgument { .. })
        ));
        assert!(matches!(
            surface_context_from_points(&px[..5], &nm[..5], &cfg),
            Err(Error::NoBody(_))
        ));
        let bad = DescriptorConfig {
            radial_bins: 0,
            ..cfg
        };
        assert!(bad.validate().is_err());
        let bad = DescriptorConfig {
            inner_radius: 3.0,
            ..cfg
        };
        assert!(bad.validate().is_err());
        for w in [-1.0, f64::NAN, 1e3] {
            let bad = DescriptorConfig {
                depth_weight: w,
                ..cfg
            };
            assert!(bad.validate().is_err(), "depth_weight {w}");
        }
        // The relief channel needs depth: bare pixels and normals cannot give it.
        let relief = DescriptorConfig {
            depth_weight: 1.0,
            ..cfg
        };
        let nm50 = vec![[0.0f32, 0.0, -1.0]; 50];
        assert!(matches!(
            surface_context_from_points(&px, &nm50, &relief),
            Err(Error::InvalidArgument { .. })
        ));
        assert!(matches!(
            surface_context_with_relief(&px, &nm50, Some(&[0.0; 49]), &relief),
            Err(Error::InvalidArgument { .. })
        ));
        let cam = Camera::itop();
        let empty = vec![0.0f32; cam.width * cam.height];
        let view = DepthView::new(&empty, cam.height, cam.width, "depth").unwrap();
        assert!(matches!(
            surface_context_from_depth(&view, &cam, None, &cfg),
            Err(Error::NoBody(_))
        ));
        let mask = vec![false; 3];
        let d = render(&BodyModel::neutral_pose(), &cam);
        let view = DepthView::new(&d, cam.height, cam.width, "depth").unwrap();
        assert!(surface_context_from_depth(&view, &cam, Some(&mask), &cfg).is_err());
    }
}
