//! Seeds and growing: the two stages of Growing Correspondence Seeds (Čech and Šára,
//! "Efficient sampling of disparity space for fast and accurate matching", 2007).
//!
//! A few seeds are matched by exhaustive search along their epipolar line; then a
//! priority queue ordered by correlation grows matches from them into the 4-neighbours
//! of the left image, testing only disparities d − 1, d, d + 1 of the match they grow
//! from. A popped candidate is accepted only when its left and its right pixel are both
//! still free (uniqueness), so the disparity space is sampled only around surfaces.

use super::correlation::Correlator;
use rayon::prelude::*;
use std::collections::BinaryHeap;

/// Value of the integer disparity map where a pixel has no match.
pub const UNMATCHED: i32 = -1;

/// A candidate in the queue: (ordered correlation bits, pixel index, disparity). The
/// heap pops the largest correlation first; ties break on the index, so runs are
/// deterministic.
type Candidate = (u32, u32, u32);

/// Offset that makes every correlation (≥ `NO_CORRELATION` = −2) a positive float, whose
/// IEEE bits then order like the values.
const KEY_OFFSET: f32 = 4.0;

#[inline]
fn key(c: f32) -> u32 {
    (c + KEY_OFFSET).to_bits()
}

#[inline]
fn value(k: u32) -> f32 {
    f32::from_bits(k) - KEY_OFFSET
}

/// A tiny deterministic generator (SplitMix64) for drawing seed pixels.
pub struct SplitMix64(u64);

impl SplitMix64 {
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in 0..n (n > 0); the modulo bias is negligible for image sizes.
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

/// The best disparity of left pixel (x, y) by exhaustive search over 0..=max_d, with
/// its correlation, if it is distinct: the best correlation outside d ± 1 must leave at
/// least `1 / distinctness` times more dissimilarity (1 − c) than the best.
pub fn search_line(
    corr: &Correlator,
    x: usize,
    y: usize,
    max_d: usize,
    distinctness: f32,
) -> Option<(usize, f32)> {
    let top = max_d.min(corr.max_disparity_at(x));
    let (mut best_d, mut best) = (0usize, f32::NEG_INFINITY);
    // Scores are kept only to find the runner-up away from the best; the line is short
    // and seeds are few, so a second pass is cheaper than storing them.
    for d in 0..=top {
        let c = corr.score(x, y, d);
        if c > best {
            best = c;
            best_d = d;
        }
    }
    if !best.is_finite() {
        return None;
    }
    let runner_up = (0..=top)
        .filter(|&d| d + 1 < best_d || d > best_d + 1)
        .map(|d| corr.score(x, y, d))
        .fold(f32::NEG_INFINITY, f32::max);
    let distinct = (1.0 - best) <= distinctness * (1.0 - runner_up);
    distinct.then_some((best_d, best))
}

/// Random seeds: `count` left pixels drawn with `rng` (textured, window inside), each
/// matched by [`search_line`]; returns (x, y, d, correlation) of those that pass
/// `threshold` and the distinctness test. Seeds are searched in parallel.
pub fn random_seeds(
    corr: &Correlator,
    count: usize,
    max_d: usize,
    threshold: f32,
    distinctness: f32,
    rng: &mut SplitMix64,
) -> Vec<(usize, usize, usize, f32)> {
    let (w, h, half) = (corr.width(), corr.height(), corr.half());
    if w <= 2 * half || h <= 2 * half {
        return Vec::new();
    }
    let pixels: Vec<(usize, usize)> = (0..count)
        .map(|_| {
            (
                half + rng.below(w - 2 * half),
                half + rng.below(h - 2 * half),
            )
        })
        .collect();
    pixels
        .par_iter()
        .filter(|&&(x, y)| corr.left_textured(x, y))
        .filter_map(|&(x, y)| {
            let (d, c) = search_line(corr, x, y, max_d, distinctness)?;
            (c >= threshold).then_some((x, y, d, c))
        })
        .collect()
}

/// Reusable state of the growing stage.
pub struct Grower {
    heap: BinaryHeap<Candidate>,
    right_used: Vec<bool>,
}

impl Grower {
    pub fn new() -> Self {
        Grower {
            heap: BinaryHeap::new(),
            right_used: Vec::new(),
        }
    }

    /// Grows matches from `seeds` (x, y, d); writes the integer disparity (or
    /// `UNMATCHED`) and the correlation of every left pixel into `disparity` and
    /// `confidence`. Only candidates with correlation ≥ `threshold` are accepted, and
    /// no disparity above `max_d`.
    pub fn grow(
        &mut self,
        corr: &Correlator,
        seeds: &[(usize, usize, usize)],
        max_d: usize,
        threshold: f32,
        disparity: &mut [i32],
        confidence: &mut [f32],
    ) {
        let w = corr.width();
        let n = w * corr.height();
        disparity.fill(UNMATCHED);
        confidence.fill(f32::NAN);
        self.right_used.clear();
        self.right_used.resize(n, false);
        self.heap.clear();

        for &(x, y, d) in seeds {
            if corr.inside(x, y) && d <= max_d.min(corr.max_disparity_at(x)) {
                let c = corr.score(x, y, d);
                if c >= threshold {
                    self.heap.push((key(c), (y * w + x) as u32, d as u32));
                }
            }
        }

        while let Some((k, idx, d)) = self.heap.pop() {
            let (idx, d) = (idx as usize, d as usize);
            if disparity[idx] != UNMATCHED || self.right_used[idx - d] {
                continue; // uniqueness: one of the two pixels is taken already
            }
            disparity[idx] = d as i32;
            confidence[idx] = value(k);
            self.right_used[idx - d] = true;
            let (x, y) = (idx % w, idx / w);
            let neighbours = [
                (x.wrapping_sub(1), y),
                (x + 1, y),
                (x, y.wrapping_sub(1)),
                (x, y + 1),
            ];
            for (nx, ny) in neighbours {
                if !corr.inside(nx, ny) {
                    continue;
                }
                let nidx = ny * w + nx;
                if disparity[nidx] != UNMATCHED {
                    continue;
                }
                let top = max_d.min(corr.max_disparity_at(nx));
                let (mut best_d, mut best) = (0usize, f32::NEG_INFINITY);
                for nd in d.saturating_sub(1)..=(d + 1).min(top) {
                    if self.right_used[nidx - nd] {
                        continue;
                    }
                    let c = corr.score(nx, ny, nd);
                    if c > best {
                        best = c;
                        best_d = nd;
                    }
                }
                if best >= threshold {
                    self.heap.push((key(best), nidx as u32, best_d as u32));
                }
            }
        }
    }
}

impl Default for Grower {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_order_like_correlations() {
        let vals = [-2.0f32, -1.0, -0.3, 0.0, 0.2, 0.7, 0.99, 1.0];
        for pair in vals.windows(2) {
            assert!(key(pair[0]) < key(pair[1]));
        }
        for v in vals {
            assert!((value(key(v)) - v).abs() < 1e-6);
        }
    }

    #[test]
    fn rng_is_deterministic_and_in_range() {
        let mut a = SplitMix64::new(7);
        let mut b = SplitMix64::new(7);
        for _ in 0..100 {
            let (p, q) = (a.below(13), b.below(13));
            assert_eq!(p, q);
            assert!(p < 13);
        }
    }
}
