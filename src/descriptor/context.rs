//! The descriptors of a silhouette: the pixel grid, the sample points and their
//! log-polar bins.

use super::config::{DescriptorConfig, GRID_REFINEMENTS, MIN_POINTS};
use crate::error::{ensure, Error, Result};
use rayon::prelude::*;

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
pub(super) fn splitmix(state: &mut u64) -> f64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

/// A grid over the silhouette's bounding box.
pub(super) struct Grid {
    pub(super) origin: [f64; 2],
    pub(super) step: f64,
    pub(super) cols: usize,
    pub(super) rows: usize,
}

impl Grid {
    pub(super) fn new(lo: [f64; 2], hi: [f64; 2], step: f64, jitter: [f64; 2]) -> Self {
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
    pub(super) fn cell(&self, p: [f32; 2]) -> usize {
        let c = ((p[0] as f64 - self.origin[0]) / self.step) as usize;
        let r = ((p[1] as f64 - self.origin[1]) / self.step) as usize;
        r.min(self.rows - 1) * self.cols + c.min(self.cols - 1)
    }

    pub(super) fn centre(&self, cell: usize) -> [f64; 2] {
        let (r, c) = (cell / self.cols, cell % self.cols);
        [
            self.origin[0] + (c as f64 + 0.5) * self.step,
            self.origin[1] + (r as f64 + 0.5) * self.step,
        ]
    }

    pub(super) fn occupied(&self, pixels: &[[f32; 2]], seen: &mut Vec<bool>) -> usize {
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
pub(super) struct LogPolarBins {
    /// Squared inner edges of rings 1..rings, ascending.
    pub(super) ring_edges2: Vec<f32>,
    /// Squared outer radius.
    pub(super) outer2: f32,
    /// Unit vectors of the sector edges with angle in (−π, 0] and in (0, π), ascending.
    pub(super) lower_edges: Vec<[f32; 2]>,
    pub(super) upper_edges: Vec<[f32; 2]>,
}

impl LogPolarBins {
    pub(super) fn new(config: &DescriptorConfig, scale: f64) -> Self {
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
    pub(super) fn ring(&self, r2: f32) -> usize {
        self.ring_edges2.iter().filter(|&&e| r2 >= e).count()
    }

    /// Sector of the offset (du, dv).
    #[inline]
    pub(super) fn sector(&self, du: f32, dv: f32) -> usize {
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
