//! Removal of foreground fattening: the band of background pixels that window matching
//! gives the disparity of a nearer surface.
//!
//! A correlation window that straddles a depth edge is dominated by whichever side has
//! more texture, and near a person in front of a plain wall that is the person: the
//! wall's pixels within about half a window of the silhouette match at the person's
//! disparity, so the person looks a few pixels fatter than it is, and its outline
//! carries points that belong to nothing. The filter drops every match that has, within
//! `radius` pixels, a clearly farther match (disparity smaller by more than `jump`) or a
//! large unmatched region (the plain wall behind). A small unmatched hole inside a
//! surface is not an edge and is ignored. On a continuous surface nothing is removed; at
//! an edge the nearer side loses the fattened band and at most a pixel or two of its own.

use crate::error::{ensure, Result};
use crate::union_find::UnionFind;

/// Settings of [`remove_fattening`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FatteningConfig {
    /// Pixels around an edge whose nearer side is removed: half the correlation window
    /// (how far fattening reaches).
    pub radius: usize,
    /// A neighbour is across an edge when its disparity is smaller by more than this
    /// (pixels); a slanted surface changes by much less over `radius` pixels.
    pub jump: f32,
    /// Unmatched regions of at least this many pixels are treated as a far surface
    /// (an untextured wall); smaller ones are holes in a surface and ignored.
    pub min_gap: usize,
}

impl FatteningConfig {
    /// The settings for a correlation window of side `window`.
    pub fn for_window(window: usize) -> Self {
        FatteningConfig {
            radius: window / 2,
            jump: f32::INFINITY,
            min_gap: 64,
        }
    }

    pub fn validate(&self) -> Result<()> {
        ensure(self.radius <= 64, "fattening.radius", || {
            format!("must be <= 64, got {}", self.radius)
        })?;
        ensure(
            !self.jump.is_nan() && self.jump >= 0.0,
            "fattening.jump",
            || format!("must be >= 0, got {}", self.jump),
        )
    }
}

/// Sets to NaN (unmatched) every match of `disparity` (row-major `height`×`width`, NaN
/// unmatched) that lies within `config.radius` pixels of a farther surface (module
/// docs). Returns the number of matches removed.
pub fn remove_fattening(
    disparity: &mut [f32],
    height: usize,
    width: usize,
    config: &FatteningConfig,
) -> Result<usize> {
    config.validate()?;
    ensure(disparity.len() == height * width, "disparity", || {
        format!(
            "has {} values for a {height}×{width} image",
            disparity.len()
        )
    })?;
    if config.radius == 0 || disparity.is_empty() {
        return Ok(0);
    }
    // What each pixel tells its neighbours: a match its disparity, a large gap −∞ (the
    // farthest surface), a small hole +∞ (nothing).
    let gaps = large_gaps(disparity, height, width, config.min_gap);
    let mut far: Vec<f32> = disparity
        .iter()
        .zip(&gaps)
        .map(|(&d, &gap)| match (d.is_nan(), gap) {
            (false, _) => d,
            (true, true) => f32::NEG_INFINITY,
            (true, false) => f32::INFINITY,
        })
        .collect();
    min_filter(&mut far, height, width, config.radius);
    let mut removed = 0;
    for (d, &m) in disparity.iter_mut().zip(&far) {
        if !d.is_nan() && (m == f32::NEG_INFINITY || m < *d - config.jump) {
            *d = f32::NAN;
            removed += 1;
        }
    }
    Ok(removed)
}

/// Whether each pixel is unmatched and in a 4-connected unmatched region of at least
/// `min_gap` pixels. The regions are unions of the rows' unmatched runs (a run joins
/// those of the row above that share a column), so the work grows with the runs, not
/// the pixels.
fn large_gaps(disparity: &[f32], height: usize, width: usize, min_gap: usize) -> Vec<bool> {
    // The unmatched runs [x0, x1) row by row; row y's are runs[row_start[y]..row_start[y + 1]].
    let mut runs: Vec<(usize, usize)> = Vec::new();
    let mut row_start = Vec::with_capacity(height + 1);
    let mut sets = UnionFind::default();
    for row in disparity.chunks_exact(width) {
        row_start.push(runs.len());
        let mut x = 0;
        while x < width {
            if !row[x].is_nan() {
                x += 1;
                continue;
            }
            let x0 = x;
            while x < width && row[x].is_nan() {
                x += 1;
            }
            runs.push((x0, x));
            sets.push();
        }
    }
    row_start.push(runs.len());
    for y in 1..height {
        let (mut i, mut j) = (row_start[y - 1], row_start[y]);
        while i < row_start[y] && j < row_start[y + 1] {
            let ((a0, a1), (b0, b1)) = (runs[i], runs[j]);
            if a0 < b1 && b0 < a1 {
                sets.union(i, j);
            }
            if a1 < b1 {
                i += 1;
            } else {
                j += 1;
            }
        }
    }
    let roots: Vec<usize> = (0..runs.len()).map(|k| sets.find(k)).collect();
    let mut size = vec![0usize; runs.len()];
    for (&r, &(x0, x1)) in roots.iter().zip(&runs) {
        size[r] += x1 - x0;
    }
    let mut gaps = vec![false; disparity.len()];
    for y in 0..height {
        for k in row_start[y]..row_start[y + 1] {
            if size[roots[k]] >= min_gap {
                let (x0, x1) = runs[k];
                gaps[y * width + x0..y * width + x1].fill(true);
            }
        }
    }
    gaps
}

/// In place: each value becomes the minimum over the (2·radius + 1)² square around it
/// (clipped at the image border), by a pass along the rows and one across them; both
/// work on whole contiguous rows, so they vectorise.
fn min_filter(values: &mut [f32], height: usize, width: usize, radius: usize) {
    let mut rows = vec![0.0; values.len()];
    for (src, dst) in values.chunks_exact(width).zip(rows.chunks_exact_mut(width)) {
        min_line(src, dst, radius);
    }
    for y in 0..height {
        let (lo, hi) = (y.saturating_sub(radius), (y + radius + 1).min(height));
        let out = &mut values[y * width..(y + 1) * width];
        out.copy_from_slice(&rows[lo * width..(lo + 1) * width]);
        for r in lo + 1..hi {
            for (o, v) in out.iter_mut().zip(&rows[r * width..(r + 1) * width]) {
                *o = o.min(*v);
            }
        }
    }
}

/// `out[i]` = min of `input[i − radius ..= i + radius]` (clipped), as the minimum of
/// the input shifted by each offset up to `radius` either way.
fn min_line(input: &[f32], out: &mut [f32], radius: usize) {
    let n = input.len();
    out.copy_from_slice(input);
    for s in 1..=radius.min(n.saturating_sub(1)) {
        for (o, v) in out[..n - s].iter_mut().zip(&input[s..]) {
            *o = o.min(*v);
        }
        for (o, v) in out[s..].iter_mut().zip(&input[..n - s]) {
            *o = o.min(*v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stereo::testing::{random_disparities, same};

    /// A person-like block of disparity 20 in front of a wall of disparity 10, with the
    /// wall's pixels next to the block given the block's disparity (fattening).
    fn scene(fat: usize) -> (Vec<f32>, usize, usize) {
        let (h, w) = (40, 60);
        let mut d = vec![10.0f32; h * w];
        for y in 10..30 {
            for x in (20 - fat)..(40 + fat) {
                d[y * w + x] = 20.0;
            }
        }
        (d, h, w)
    }

    /// Brute force: a match is removed iff a farther match or large-gap pixel lies in
    /// its square neighbourhood.
    fn brute(d: &[f32], h: usize, w: usize, c: &FatteningConfig) -> Vec<f32> {
        let gaps = large_gaps(d, h, w, c.min_gap);
        let r = c.radius as isize;
        let mut out = d.to_vec();
        for y in 0..h as isize {
            for x in 0..w as isize {
                let v = d[(y * w as isize + x) as usize];
                if v.is_nan() {
                    continue;
                }
                let mut edge = false;
                for dy in -r..=r {
                    for dx in -r..=r {
                        let (yy, xx) = (y + dy, x + dx);
                        if yy < 0 || xx < 0 || yy >= h as isize || xx >= w as isize {
                            continue;
                        }
                        let k = (yy * w as isize + xx) as usize;
                        edge |= (d[k].is_nan() && gaps[k]) || d[k] < v - c.jump;
                    }
                }
                if edge {
                    out[(y * w as isize + x) as usize] = f32::NAN;
                }
            }
        }
        out
    }

    #[test]
    fn removes_the_fattened_band_and_keeps_the_wall() {
        let (mut d, h, w) = scene(2);
        let c = FatteningConfig {
            jump: 1.0,
            ..FatteningConfig::for_window(5)
        };
        let removed = remove_fattening(&mut d, h, w, &c).unwrap();
        // The block's columns 18..42 lose radius 2 on each side; the wall is untouched.
        assert_eq!(removed, 2 * 2 * 20 + 2 * 2 * (24 - 4));
        for y in 0..h {
            for x in 0..w {
                let v = d[y * w + x];
                let inside = (12..28).contains(&y) && (20..40).contains(&x);
                let block = (10..30).contains(&y) && (18..42).contains(&x);
                if inside {
                    assert_eq!(v, 20.0, "({y}, {x})");
                } else if block {
                    assert!(v.is_nan(), "({y}, {x})");
                } else {
                    assert_eq!(v, 10.0, "({y}, {x})");
                }
            }
        }
    }

    #[test]
    fn by_default_only_an_unmatched_background_marks_an_edge() {
        // Against a matched wall nothing counts as an edge by default.
        let (mut d, h, w) = scene(2);
        let c = FatteningConfig::for_window(5);
        assert_eq!(remove_fattening(&mut d, h, w, &c).unwrap(), 0);
        // Against an unmatched (textureless) wall the band next to it goes.
        let (mut d, h, w) = scene(2);
        for v in d.iter_mut().filter(|v| **v == 10.0) {
            *v = f32::NAN;
        }
        let removed = remove_fattening(&mut d, h, w, &c).unwrap();
        assert_eq!(removed, 2 * 2 * 20 + 2 * 2 * (24 - 4));
        assert!(d[20 * w + 30] == 20.0 && d[20 * w + 19].is_nan());
    }

    #[test]
    fn matches_brute_force_with_holes_and_gaps() {
        let (mut d, h, w) = scene(1);
        // A large unmatched region (a plain wall) and single-pixel holes.
        for y in 0..h {
            for x in 45..w {
                d[y * w + x] = f32::NAN;
            }
        }
        for k in [15 * w + 25, 22 * w + 33, 5 * w + 5] {
            d[k] = f32::NAN;
        }
        // A gentle slope: 0.1 px per row never counts as an edge.
        for y in 0..h {
            for x in 0..10 {
                d[y * w + x] = 8.0 + 0.1 * y as f32;
            }
        }
        for c in [
            FatteningConfig::for_window(5),
            FatteningConfig::for_window(9),
            FatteningConfig {
                radius: 1,
                jump: 0.5,
                min_gap: 1,
            },
        ] {
            let want = brute(&d, h, w, &c);
            let mut got = d.clone();
            remove_fattening(&mut got, h, w, &c).unwrap();
            assert!(same(&got, &want), "{c:?}");
        }
    }

    #[test]
    fn a_continuous_surface_loses_nothing() {
        let (h, w) = (30, 30);
        let mut d: Vec<f32> = (0..h * w).map(|k| 5.0 + 0.2 * (k / w) as f32).collect();
        d[10 * w + 10] = f32::NAN; // a hole
        let before = d.clone();
        let removed = remove_fattening(&mut d, h, w, &FatteningConfig::for_window(5)).unwrap();
        assert_eq!(removed, 0);
        assert!(same(&d, &before));
    }

    /// Brute force of [`large_gaps`]: a flood fill from every unmatched pixel.
    fn gaps_by_flood_fill(d: &[f32], h: usize, w: usize, min_gap: usize) -> Vec<bool> {
        let mut region = vec![usize::MAX; d.len()];
        let mut sizes = Vec::new();
        for start in 0..d.len() {
            if !d[start].is_nan() || region[start] != usize::MAX {
                continue;
            }
            let (id, mut stack, mut n) = (sizes.len(), vec![start], 0);
            region[start] = id;
            while let Some(k) = stack.pop() {
                n += 1;
                let (y, x) = (k / w, k % w);
                let next = [
                    (x > 0).then(|| k - 1),
                    (x + 1 < w).then(|| k + 1),
                    (y > 0).then(|| k - w),
                    (y + 1 < h).then(|| k + w),
                ];
                for j in next.into_iter().flatten() {
                    if d[j].is_nan() && region[j] == usize::MAX {
                        region[j] = id;
                        stack.push(j);
                    }
                }
            }
            sizes.push(n);
        }
        region
            .iter()
            .map(|&r| r != usize::MAX && sizes[r] >= min_gap)
            .collect()
    }

    #[test]
    fn large_gaps_match_a_flood_fill() {
        for (seed, holes) in [(1, 0.3), (2, 0.5), (3, 0.6), (4, 0.9)] {
            for (h, w) in [(1, 17), (23, 1), (31, 47)] {
                let d = random_disparities(h * w, holes, 40.0, seed);
                for min_gap in [1, 2, 5, 20, 200] {
                    assert_eq!(
                        large_gaps(&d, h, w, min_gap),
                        gaps_by_flood_fill(&d, h, w, min_gap),
                        "seed {seed}, {h}×{w}, min_gap {min_gap}"
                    );
                }
            }
        }
    }

    #[test]
    fn random_scenes_match_brute_force() {
        for (seed, holes) in [(5, 0.2), (6, 0.5), (7, 0.7)] {
            let (h, w) = (29, 41);
            let d = random_disparities(h * w, holes, 40.0, seed);
            for c in [
                FatteningConfig::for_window(5),
                FatteningConfig {
                    radius: 3,
                    jump: 4.0,
                    min_gap: 3,
                },
                FatteningConfig {
                    radius: 60,
                    jump: 1.0,
                    min_gap: 1,
                },
            ] {
                let want = brute(&d, h, w, &c);
                let mut got = d.clone();
                remove_fattening(&mut got, h, w, &c).unwrap();
                assert!(same(&got, &want), "seed {seed}, {c:?}");
            }
        }
    }

    #[test]
    fn rejects_a_wrong_size() {
        let mut d = vec![1.0f32; 10];
        assert!(remove_fattening(&mut d, 3, 4, &FatteningConfig::for_window(5)).is_err());
    }
}
