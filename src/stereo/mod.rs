//! Stereo matching by Growing Correspondence Seeds (Čech and Šára, "Efficient sampling
//! of disparity space for fast and accurate matching", CVPR BenCOS workshop 2007), and
//! disparity → depth.
//!
//! Convention: the images are rectified; left pixel (x, y) matches right pixel
//! (x − d, y) with d ≥ 0. Unmatched pixels get NaN.
//!
//! Stages: (1) window moments of both images from box filters, (2) random seeds
//! matched by exhaustive search along the epipolar line (plus user seeds), (3) growing
//! from the seeds with a priority queue and the uniqueness constraint, testing only
//! d − 1, d, d + 1 for each 4-neighbour, (4) optional left–right check, (5) subpixel
//! refinement by a parabola through the correlations at d − 1, d, d + 1, (6) optional
//! removal of small disparity segments, (7) optional removal of the matches a nearer
//! surface spreads into the half-occluded band on its left ([`occlusion`]). Memory is
//! O(W·H), never O(W·H·D). [`fattening`] removes the band of background pixels a nearer
//! surface's disparity spreads to against an unmatched background.

mod correlation;
pub mod fattening;
mod grow;
pub mod occlusion;

pub use correlation::Similarity;

use crate::error::{ensure, Error, Result};
use crate::union_find::UnionFind;
use correlation::{Correlator, NO_CORRELATION};
use grow::{random_seeds, Grower, SplitMix64, DISPARITY_LIMIT, UNMATCHED};
use rayon::prelude::*;

/// Largest accepted window side (pixels): beyond it the matcher is needlessly slow.
pub const MAX_WINDOW: usize = 31;

/// Rows per band: bands grow independently and in parallel (uniqueness couples only
/// pixels of one row, so a band is a self-contained problem; a surface split by a band
/// border is grown from the seeds on each side). Fixed, so results do not depend on
/// the number of threads.
pub const BAND_ROWS: usize = 96;

/// Largest disparity difference (px) between a left match and the right match it
/// points to for the left–right check to keep it.
pub const LR_TOLERANCE: f32 = 1.0;

/// Largest disparity step (px) between 4-neighbours of one segment in the small-segment
/// filter.
pub const SEGMENT_STEP: i32 = 1;

/// A match is in a nearer surface's half-occluded band ([`occlusion`]) when a match
/// within half a window to its left is farther by more than this (px): the error the
/// band's matches would have.
pub const OCCLUSION_JUMP: f32 = 2.0;

/// Settings of [`match_stereo`].
#[derive(Debug, Clone, PartialEq)]
pub struct StereoConfig {
    /// Side of the square correlation window in pixels (odd, ≥ 3).
    pub window: usize,
    /// Acceptance threshold τ on the correlation: weaker matches are never accepted.
    pub threshold: f32,
    /// Number of random seed pixels matched by exhaustive search.
    pub num_seeds: usize,
    /// Largest disparity considered; `None` for the whole epipolar line (at most
    /// 32767 px either way).
    pub max_disparity: Option<usize>,
    /// Seed distinctness ρ in (0, 1]: a seed is kept only if the best match outside
    /// d ± 1 leaves at least 1/ρ times its dissimilarity (1 − c). 1 disables the test.
    pub seed_distinctness: f32,
    /// Smallest window standard deviation, in units of the image's global standard
    /// deviation, that is matched at all (untextured windows stay unmatched).
    pub min_texture: f32,
    /// The window similarity.
    pub similarity: Similarity,
    /// Keep only matches confirmed by matching the right image against the left.
    /// Uniqueness already makes matches one-to-one, so this costs twice the time for
    /// a modest gain.
    pub lr_check: bool,
    /// Subpixel refinement by a parabola through the correlations at d − 1, d, d + 1.
    pub subpixel: bool,
    /// Fill one-pixel gaps between two horizontal neighbours whose disparities differ
    /// by at most 1, with whichever of their disparities correlates better (if ≥ the
    /// threshold). On a surface slanted in depth, n left pixels see fewer than n right
    /// pixels, so integer uniqueness leaves such gaps; the filled pixel shares its right
    /// pixel with a neighbour.
    pub fill_gaps: bool,
    /// Matched segments (4-connected, disparity steps ≤ 1) smaller than this many
    /// pixels are removed; 0 keeps everything.
    pub min_segment: usize,
    /// Remove the matches a nearer surface's windows spread into the half-occluded band
    /// left of it, which has no true match ([`occlusion`], [`OCCLUSION_JUMP`]).
    pub half_occlusion: bool,
    /// Seed of the random generator that draws seed pixels (runs are deterministic).
    pub rng_seed: u64,
}

impl Default for StereoConfig {
    fn default() -> Self {
        StereoConfig {
            window: 5,
            threshold: 0.47,
            num_seeds: 2000,
            max_disparity: None,
            seed_distinctness: 0.8,
            min_texture: 0.005,
            similarity: Similarity::Mncc,
            lr_check: false,
            subpixel: true,
            fill_gaps: true,
            min_segment: 200,
            half_occlusion: true,
            rng_seed: 0,
        }
    }
}

impl StereoConfig {
    /// Checks every field; errors name it.
    pub fn validate(&self) -> Result<()> {
        ensure(
            self.window >= 3 && self.window % 2 == 1 && self.window <= MAX_WINDOW,
            "window",
            || format!("must be odd and in 3..={MAX_WINDOW}, got {}", self.window),
        )?;
        ensure(
            self.threshold.is_finite() && self.threshold > -1.0 && self.threshold <= 1.0,
            "threshold",
            || format!("must be a correlation in (-1, 1], got {}", self.threshold),
        )?;
        ensure(
            self.seed_distinctness.is_finite()
                && self.seed_distinctness > 0.0
                && self.seed_distinctness <= 1.0,
            "seed_distinctness",
            || format!("must be in (0, 1], got {}", self.seed_distinctness),
        )?;
        ensure(
            self.min_texture.is_finite() && self.min_texture >= 0.0,
            "min_texture",
            || format!("must be finite and ≥ 0, got {}", self.min_texture),
        )?;
        Ok(())
    }
}

/// A user-given seed: left pixel (x, y) matches right pixel (x − d, y).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Seed {
    pub x: usize,
    pub y: usize,
    pub d: usize,
}

/// The output of [`match_stereo`], row-major H×W.
#[derive(Debug, Clone)]
pub struct StereoResult {
    /// Disparity in pixels (left x matches right x − d), NaN where unmatched.
    pub disparity: Vec<f32>,
    /// Correlation of the accepted match, NaN where unmatched.
    pub confidence: Vec<f32>,
    pub height: usize,
    pub width: usize,
    /// Seeds that started the growing (random seeds that passed, plus user seeds).
    pub seeds_used: usize,
}

impl StereoResult {
    fn empty(height: usize, width: usize) -> Self {
        StereoResult {
            disparity: vec![f32::NAN; height * width],
            confidence: vec![f32::NAN; height * width],
            height,
            width,
            seeds_used: 0,
        }
    }

    /// Number of matched pixels.
    pub fn matched(&self) -> usize {
        self.disparity.iter().filter(|d| !d.is_nan()).count()
    }
}

fn check_image(img: &[f32], height: usize, width: usize, name: &str) -> Result<()> {
    ensure(img.len() == height * width, name, || {
        format!(
            "has {} pixels, expected {height}×{width} = {}",
            img.len(),
            height * width
        )
    })?;
    // A branch-free test per block (it vectorises), the position only on failure.
    let all_finite = img
        .chunks(256)
        .all(|block| block.iter().fold(true, |ok, v| ok & v.is_finite()));
    if all_finite {
        return Ok(());
    }
    let i = img.iter().position(|v| !v.is_finite()).unwrap_or(0);
    Err(Error::invalid(
        name,
        format!("holds a non-finite value ({}) at pixel {i}", img[i]),
    ))
}

/// Gray from interleaved RGB (H·W·3), by the Rec. 601 luma weights.
pub fn gray_from_rgb(rgb: &[f32]) -> Vec<f32> {
    rgb.chunks_exact(3)
        .map(|p| 0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2])
        .collect()
}

/// Matches a rectified gray pair (row-major `height`×`width`, any intensity scale) by
/// Growing Correspondence Seeds from `config.num_seeds` random seeds.
pub fn match_stereo(
    left: &[f32],
    right: &[f32],
    height: usize,
    width: usize,
    config: &StereoConfig,
) -> Result<StereoResult> {
    match_stereo_seeded(left, right, height, width, config, &[])
}

/// Like [`match_stereo`], growing also from the user's `seeds` (each must lie inside
/// the image with x − d ≥ 0; seeds whose correlation is below the threshold are
/// dropped like any other candidate).
pub fn match_stereo_seeded(
    left: &[f32],
    right: &[f32],
    height: usize,
    width: usize,
    config: &StereoConfig,
    seeds: &[Seed],
) -> Result<StereoResult> {
    config.validate()?;
    ensure(height > 0 && width > 0, "left", || {
        format!("image is empty ({height}×{width})")
    })?;
    check_image(left, height, width, "left")?;
    check_image(right, height, width, "right")?;
    let max_d = config.max_disparity.unwrap_or(width - 1);
    ensure(max_d < width, "max_disparity", || {
        format!("must be below the image width {width}, got {max_d}")
    })?;
    let max_d = max_d.min(DISPARITY_LIMIT);
    for (i, s) in seeds.iter().enumerate() {
        ensure(s.x < width && s.y < height && s.d <= s.x, "seeds", || {
            format!(
                "seed {i} ({}, {}, d={}) is outside the {height}×{width} image or points left of it",
                s.x, s.y, s.d
            )
        })?;
    }
    ensure(
        config.num_seeds > 0 || !seeds.is_empty(),
        "num_seeds",
        || "is 0 and no seeds were given: nothing to grow from".to_string(),
    )?;
    // Each random seed is a line search from a random pixel: more than the pixels only
    // repeat them (and a huge count would be a failed allocation, not a result). The
    // default count is allowed on any image, however small.
    let most_seeds = (width * height).max(StereoConfig::default().num_seeds);
    ensure(config.num_seeds <= most_seeds, "num_seeds", || {
        format!(
            "must be at most {most_seeds} (the pixels of the image), got {}",
            config.num_seeds
        )
    })?;
    let half = config.window / 2;
    if height < config.window || width < config.window {
        return Ok(StereoResult::empty(height, width));
    }
    // Rows are padded by reflection (the same rows in both images, since the pair is
    // rectified), so windows of the top and bottom `half` rows stay correct and those
    // rows are matched too; the result is cropped back.
    let left = pad_rows(left, width, height, half);
    let right = pad_rows(right, width, height, half);
    let padded: Vec<Seed> = seeds
        .iter()
        .map(|s| Seed {
            y: s.y + half,
            ..*s
        })
        .collect();
    match_padded(
        left,
        right,
        height + 2 * half,
        width,
        config,
        max_d,
        &padded,
    )
}

/// `img` (row-major `height`×`width`) with `pad` rows above and below, reflected about
/// the first and the last row (row −k is row k). Needs `pad` < `height`.
fn pad_rows(img: &[f32], width: usize, height: usize, pad: usize) -> Vec<f32> {
    let mut out = Vec::with_capacity(width * (height + 2 * pad));
    for k in (1..=pad).rev() {
        out.extend_from_slice(&img[k * width..(k + 1) * width]);
    }
    out.extend_from_slice(img);
    for k in 1..=pad {
        let r = height - 1 - k;
        out.extend_from_slice(&img[r * width..(r + 1) * width]);
    }
    out
}

/// [`match_stereo_seeded`] on validated images padded with `config.window / 2` rows
/// above and below; the result leaves the padding rows out.
fn match_padded(
    left: Vec<f32>,
    right: Vec<f32>,
    height: usize,
    width: usize,
    config: &StereoConfig,
    max_d: usize,
    seeds: &[Seed],
) -> Result<StereoResult> {
    let half = config.window / 2;
    let flip = |img: &[f32]| -> Vec<f32> {
        img.chunks_exact(width)
            .flat_map(|row| row.iter().rev().copied())
            .collect()
    };
    // The right image, mirrored, is a left image for the mirrored left image.
    let mirrored = config.lr_check.then(|| (flip(&right), flip(&left)));
    let Some(corr) = Correlator::new(
        left,
        right,
        width,
        height,
        half,
        config.min_texture,
        config.similarity,
    ) else {
        // A uniform image: no texture.
        return Ok(StereoResult::empty(height - 2 * half, width));
    };
    let user: Vec<(usize, usize, usize)> = seeds.iter().map(|s| (s.x, s.y, s.d)).collect();
    let (mut disp_int, seeds_used, growers) = grow_pass(&corr, config, max_d, &user);

    if let Some((left_back, right_back)) = mirrored {
        let back = Correlator::new(
            left_back,
            right_back,
            width,
            height,
            half,
            config.min_texture,
            config.similarity,
        )
        .expect("both images have texture: the forward pass built its correlator");
        let (disp_back, _, back_growers) = grow_pass(&back, config, max_d, &[]);
        Grower::recycle(back_growers);
        left_right_check(&mut disp_int, &disp_back, width);
    }
    if config.fill_gaps {
        fill_gaps(&mut disp_int, &corr, max_d, config.threshold);
    }
    if config.min_segment > 0 {
        remove_small_segments(&mut disp_int, width, height, config.min_segment);
    }

    // Confidence = correlation at d; subpixel offset from d − 1, d, d + 1 (cached).
    // Only the rows between the padding are written out.
    let out_height = height - 2 * half;
    let mut disparity = vec![f32::NAN; width * out_height];
    let mut confidence = vec![f32::NAN; width * out_height];
    disparity
        .par_chunks_mut(width)
        .zip(confidence.par_chunks_mut(width))
        .zip(disp_int[half * width..].par_chunks(width))
        .enumerate()
        .for_each(|(row, ((drow, crow), irow))| {
            let y = row + half;
            for (x, ((dv, cv), &d)) in drow.iter_mut().zip(crow).zip(irow).enumerate() {
                if d == UNMATCHED {
                    continue;
                }
                let d = d as usize;
                let top = max_d.min(corr.max_disparity_at(x));
                let scores = growers[y / BAND_ROWS].scores_around(&corr, x, y, d, top);
                *cv = scores[1];
                let offset = if config.subpixel {
                    subpixel_offset(scores)
                } else {
                    0.0
                };
                *dv = d as f32 + offset;
            }
        });
    Grower::recycle(growers);
    if config.half_occlusion {
        occlusion::remove_half_occluded_for_window(
            &mut disparity,
            &mut confidence,
            width,
            config.window,
        );
    }
    Ok(StereoResult {
        disparity,
        confidence,
        height: out_height,
        width,
        seeds_used,
    })
}

/// Seeds + growing on one correlator, in bands of `BAND_ROWS` rows grown in parallel:
/// integer disparities, seeds used, and the growers of the bands (their correlation
/// caches serve the subpixel step).
fn grow_pass(
    corr: &Correlator,
    config: &StereoConfig,
    max_d: usize,
    user: &[(usize, usize, usize)],
) -> (Vec<i32>, usize, Vec<Grower>) {
    let mut rng = SplitMix64::new(config.rng_seed);
    let found = random_seeds(
        corr,
        config.num_seeds,
        max_d,
        config.threshold,
        config.seed_distinctness,
        &mut rng,
    );
    let mut all: Vec<(usize, usize, usize)> = user.to_vec();
    all.extend(found.iter().map(|&(x, y, d, _)| (x, y, d)));
    let height = corr.height();
    let growers: Vec<Grower> = (0..height.div_ceil(BAND_ROWS))
        .into_par_iter()
        .map(|band| {
            let rows = band * BAND_ROWS..((band + 1) * BAND_ROWS).min(height);
            let mut grower = Grower::pooled();
            grower.grow(corr, &all, max_d, config.threshold, rows);
            grower
        })
        .collect();
    let mut disparity = Vec::with_capacity(corr.width() * height);
    for g in &growers {
        g.disparity(&mut disparity);
    }
    (disparity, all.len(), growers)
}

/// Unmatches left pixels whose match is not confirmed by the mirrored (right-to-left)
/// pass `back`, stored in mirrored right coordinates.
fn left_right_check(disp: &mut [i32], back: &[i32], width: usize) {
    disp.par_chunks_mut(width)
        .zip(back.par_chunks(width))
        .for_each(|(row, brow)| {
            for (x, d) in row.iter_mut().enumerate() {
                if *d == UNMATCHED {
                    continue;
                }
                let db = brow[width - 1 - (x - *d as usize)];
                if db == UNMATCHED || ((db - *d).abs() as f32) > LR_TOLERANCE {
                    *d = UNMATCHED;
                }
            }
        });
}

/// Fills one-pixel horizontal gaps (see [`StereoConfig::fill_gaps`]).
fn fill_gaps(disp: &mut [i32], corr: &Correlator, max_d: usize, threshold: f32) {
    let width = corr.width();
    disp.par_chunks_mut(width).enumerate().for_each(|(y, row)| {
        for x in 1..width.saturating_sub(1) {
            let (dl, dr) = (row[x - 1], row[x + 1]);
            // No chains: filling x needs x + 1 matched, so a filled pixel never
            // borders another gap.
            if row[x] != UNMATCHED || dl == UNMATCHED || dr == UNMATCHED {
                continue;
            }
            if (dl - dr).abs() > 1 || !corr.inside(x, y) {
                continue;
            }
            let top = max_d.min(corr.max_disparity_at(x)) as i32;
            let mut best = (UNMATCHED, threshold);
            for d in [dl, dr] {
                if d <= top {
                    let c = corr.score(x, y, d as usize);
                    if c >= best.1 {
                        best = (d, c);
                    }
                }
            }
            row[x] = best.0;
        }
    });
}

/// Unmatches 4-connected segments (neighbour disparities within `SEGMENT_STEP`) of
/// fewer than `min_size` pixels.
///
/// By runs rather than by a flood fill: each row is cut into runs of matched pixels
/// joined left to right, runs of consecutive rows are merged (union–find) where any
/// column they share joins them vertically, and the runs of small segments are cleared.
/// Every pass reads the map in order, where a flood fill's stack and its per-pixel
/// labels jump between rows.
fn remove_small_segments(disp: &mut [i32], width: usize, height: usize, min_size: usize) {
    let joined = |a: i32, b: i32| a != UNMATCHED && b != UNMATCHED && (a - b).abs() <= SEGMENT_STEP;
    // Runs as [start, end) pixel indices, row by row; `row_runs[y]..row_runs[y + 1]`
    // are row y's.
    let mut runs: Vec<(usize, usize)> = Vec::new();
    let mut row_runs = Vec::with_capacity(height + 1);
    // One set per run, merged below where runs of consecutive rows join.
    let mut sets = UnionFind::default();
    for y in 0..height {
        row_runs.push(runs.len());
        let row = &disp[y * width..][..width];
        let mut x = 0;
        while x < width {
            if row[x] == UNMATCHED {
                x += 1;
                continue;
            }
            let start = x;
            x += 1;
            while x < width && joined(row[x - 1], row[x]) {
                x += 1;
            }
            runs.push((y * width + start, y * width + x));
            sets.push();
        }
    }
    row_runs.push(runs.len());

    for y in 1..height {
        // Sweep the runs of rows y − 1 and y together, by column.
        let (mut a, a_end) = (row_runs[y - 1], row_runs[y]);
        let (mut b, b_end) = (row_runs[y], row_runs[y + 1]);
        while a < a_end && b < b_end {
            let (a_start, a_stop) = (runs[a].0 - (y - 1) * width, runs[a].1 - (y - 1) * width);
            let (b_start, b_stop) = (runs[b].0 - y * width, runs[b].1 - y * width);
            let (lo, hi) = (a_start.max(b_start), a_stop.min(b_stop));
            if lo < hi
                && sets.find(a) != sets.find(b)
                && (lo..hi).any(|x| joined(disp[(y - 1) * width + x], disp[y * width + x]))
            {
                sets.union(a, b);
            }
            if a_stop <= b_stop {
                a += 1;
            } else {
                b += 1;
            }
        }
    }
    let mut size = vec![0usize; runs.len()];
    for (r, &(start, end)) in runs.iter().enumerate() {
        size[sets.find(r)] += end - start;
    }
    for (r, &(start, end)) in runs.iter().enumerate() {
        if size[sets.find(r)] < min_size {
            disp[start..end].fill(UNMATCHED);
        }
    }
}

/// Vertex offset in [−0.5, 0.5] of the parabola through the correlations at d − 1, d,
/// d + 1; 0 at the ends of the range (`NO_CORRELATION` there) or where the three do not
/// peak at d.
fn subpixel_offset([cm, c0, cp]: [f32; 3]) -> f32 {
    if cm == NO_CORRELATION || cp == NO_CORRELATION {
        return 0.0;
    }
    let curvature = cm - 2.0 * c0 + cp;
    if curvature.is_nan() || curvature >= 0.0 {
        return 0.0;
    }
    (0.5 * (cm - cp) / curvature).clamp(-0.5, 0.5)
}

/// Depth in metres from disparity in pixels: Z = baseline · focal / (d + doffs); 0
/// where the disparity is NaN or d + doffs ≤ 0.
pub fn depth_from_disparity(
    disparity: &[f32],
    focal: f64,
    baseline: f64,
    doffs: f64,
) -> Result<Vec<f32>> {
    crate::error::ensure_positive(focal, "focal")?;
    crate::error::ensure_positive(baseline, "baseline")?;
    ensure(doffs.is_finite(), "doffs", || {
        format!("must be finite, got {doffs}")
    })?;
    let bf = baseline * focal;
    Ok(disparity
        .iter()
        .map(|&d| {
            let denom = d as f64 + doffs;
            if d.is_finite() && denom > 0.0 {
                (bf / denom) as f32
            } else {
                0.0
            }
        })
        .collect())
}

#[cfg(test)]
mod testing;
#[cfg(test)]
mod tests;
