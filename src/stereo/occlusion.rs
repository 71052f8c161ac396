//! Removal of the matches that a nearer surface spreads into the half-occluded band on
//! its left.
//!
//! In the left image, the background just left of a nearer surface's left edge is not
//! seen by the right camera: a band as wide as the disparity step has no true match. A
//! correlation window there straddles the edge, is dominated by the nearer surface's
//! texture, and takes its disparity; uniqueness then leaves the background pixels
//! whose right pixels the band took unmatched. The filter drops every match that has,
//! within `reach` pixels to its left, a match farther by more than `jump` pixels; an
//! unmatched pixel counts as the nearest match left of it (the surface the gap belongs
//! to). Right edges have no half-occlusion in the left image and are left alone.

use super::OCCLUSION_JUMP;
use rayon::prelude::*;

/// [`remove_half_occluded`] with the matcher's settings for a correlation window of
/// side `window`: a window reaches half its side across an edge, and a match is
/// dropped beside one more than [`OCCLUSION_JUMP`] pixels farther.
pub fn remove_half_occluded_for_window(
    disparity: &mut [f32],
    confidence: &mut [f32],
    width: usize,
    window: usize,
) -> usize {
    remove_half_occluded(disparity, confidence, width, window / 2, OCCLUSION_JUMP)
}

/// Sets to NaN every match of `disparity` (row-major, rows of `width`, NaN unmatched)
/// in the half-occluded band of a nearer surface (module docs), and the same pixels of
/// `confidence`. Returns the number of matches removed.
pub fn remove_half_occluded(
    disparity: &mut [f32],
    confidence: &mut [f32],
    width: usize,
    reach: usize,
    jump: f32,
) -> usize {
    if width == 0 || reach == 0 {
        return 0;
    }
    disparity
        .par_chunks_mut(width)
        .zip(confidence.par_chunks_mut(width))
        .map_init(Vec::new, |seen, (row, conf)| {
            // What each pixel shows its right-hand neighbours: its match, or, unmatched,
            // the nearest match on its left (+∞, nothing, before the first).
            seen.clear();
            let mut last = f32::INFINITY;
            seen.extend(row.iter().map(|&d| {
                if !d.is_nan() {
                    last = d;
                }
                last
            }));
            let mut removed = 0;
            for x in 0..row.len() {
                let d = row[x];
                if d.is_nan() {
                    continue;
                }
                let farthest = seen[x.saturating_sub(reach)..x]
                    .iter()
                    .copied()
                    .fold(f32::INFINITY, f32::min);
                if farthest < d - jump {
                    row[x] = f32::NAN;
                    conf[x] = f32::NAN;
                    removed += 1;
                }
            }
            removed
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stereo::testing::{random_disparities, same};

    /// Brute force: walks left from each match to find, for each of the `reach`
    /// pixels on its left, the disparity of the nearest match at or left of it.
    fn brute(d: &[f32], width: usize, reach: usize, jump: f32) -> Vec<f32> {
        let mut out = d.to_vec();
        for (r, row) in d.chunks(width).enumerate() {
            for x in 0..row.len() {
                if row[x].is_nan() {
                    continue;
                }
                let mut occluded = false;
                for j in 1..=reach.min(x) {
                    let seen = (0..=x - j).rev().map(|k| row[k]).find(|v| !v.is_nan());
                    occluded |= seen.is_some_and(|v| v < row[x] - jump);
                }
                if occluded {
                    out[r * width + x] = f32::NAN;
                }
            }
        }
        out
    }

    #[test]
    fn drops_the_band_left_of_a_nearer_surface_only() {
        // A wall at 10 px, a gap the band's uniqueness left, the band at the nearer
        // surface's 20 px, then the surface itself and the wall again on its right.
        let n = f32::NAN;
        let row = [10.0, 10.0, n, n, 20.0, 20.0, 20.0, 20.0, 20.0, 10.0, 10.0];
        let mut d = row.to_vec();
        let mut c = vec![0.9; row.len()];
        let removed = remove_half_occluded(&mut d, &mut c, row.len(), 2, 2.0);
        // The surface's first two pixels go (the wall is 2 px to their left across
        // the gap); the right edge and the wall stay.
        assert_eq!(removed, 2);
        let want = [10.0, 10.0, n, n, n, n, 20.0, 20.0, 20.0, 10.0, 10.0];
        assert!(same(&d, &want), "{d:?}");
        assert!(c[4].is_nan() && c[5].is_nan() && c[6] == 0.9);
    }

    #[test]
    fn a_gentle_slope_and_a_small_step_stay() {
        let slope: Vec<f32> = (0..40).map(|x| 5.0 + 0.5 * x as f32).collect();
        let mut d = slope.clone();
        let mut c = vec![1.0; 40];
        assert_eq!(remove_half_occluded(&mut d, &mut c, 40, 2, 2.0), 0);
        let mut step = vec![10.0f32; 20];
        step[10..].fill(12.0); // 2 px: not more than the jump
        let mut c = vec![1.0; 20];
        assert_eq!(remove_half_occluded(&mut step, &mut c, 20, 2, 2.0), 0);
    }

    #[test]
    fn matches_brute_force_on_random_rows() {
        let (h, w) = (30, 53);
        for (seed, holes) in [(7, 0.1), (8, 0.4), (9, 0.8)] {
            let d = random_disparities(h * w, holes, 30.0, seed);
            for (reach, jump) in [(1, 0.5), (2, 2.0), (4, 5.0), (60, 1.0)] {
                let want = brute(&d, w, reach, jump);
                let mut got = d.clone();
                let mut c = vec![0.5; h * w];
                let removed = remove_half_occluded(&mut got, &mut c, w, reach, jump);
                assert!(
                    same(&got, &want),
                    "holes {holes}, reach {reach}, jump {jump}"
                );
                let gone: Vec<bool> = d
                    .iter()
                    .zip(&got)
                    .map(|(a, b)| !a.is_nan() && b.is_nan())
                    .collect();
                assert_eq!(removed, gone.iter().filter(|&&g| g).count());
                assert!(gone.iter().zip(&c).all(|(&g, c)| g == c.is_nan()));
            }
        }
    }
}
