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
/// `min_gap` pixels.
fn large_gaps(disparity: &[f32], height: usize, width: usize, min_gap: usize) -> Vec<bool> {
    let mut sets = UnionFind::default();
    let mut id = vec![u32::MAX; disparity.len()];
    for y in 0..height {
        for x in 0..width {
            let k = y * width + x;
            if !disparity[k].is_nan() {
                continue;
            }
            let left = (x > 0 && id[k - 1] != u32::MAX).then(|| id[k - 1] as usize);
            let up = (y > 0 && id[k - width] != u32::MAX).then(|| id[k - width] as usize);
            let set = match (left, up) {
                (Some(a), Some(b)) => {
                    sets.union(a, b);
                    a
                }
                (Some(a), None) | (None, Some(a)) => a,
                (None, None) => sets.push(),
            };
            id[k] = set as u32;
        }
    }
    let mut size = vec![0usize; sets.len()];
    let roots: Vec<usize> = id
        .iter()
        .map(|&s| {
            if s == u32::MAX {
                usize::MAX
            } else {
                let r = sets.find(s as usize);
                size[r] += 1;
                r
            }
        })
        .collect();
    roots
        .iter()
        .map(|&r| r != usize::MAX && size[r] >= min_gap)
        .collect()
}

/// In place: each value becomes the minimum over the (2·radius + 1)² square around it
/// (clipped at the image border), by a row pass and a column pass.
fn min_filter(values: &mut [f32], height: usize, width: usize, radius: usize) {
    let mut line = Vec::with_capacity(width.max(height));
    for row in values.chunks_exact_mut(width) {
        line.clear();
        line.extend_from_slice(row);
        min_line(&line, row, radius);
    }
    let mut column = vec![0.0; height];
    for x in 0..width {
        line.clear();
        line.extend((0..height).map(|y| values[y * width + x]));
        min_line(&line, &mut column, radius);
        for (y, v) in column.iter().enumerate() {
            values[y * width + x] = *v;
        }
    }
}

/// `out[i]` = min of `input[i − radius ..= i + radius]` (clipped). The radius is small,
/// so the direct loop beats a monotone deque.
fn min_line(input: &[f32], out: &mut [f32], radius: usize) {
    let n = input.len();
    for (i, o) in out.iter_mut().enumerate() {
        let (lo, hi) = (i.saturating_sub(radius), (i + radius + 1).min(n));
        *o = input[lo..hi].iter().copied().fold(f32::INFINITY, f32::min);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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

    fn same(a: &[f32], b: &[f32]) -> bool {
        a.iter()
            .zip(b)
            .all(|(x, y)| x == y || (x.is_nan() && y.is_nan()))
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

    #[test]
    fn rejects_a_wrong_size() {
        let mut d = vec![1.0f32; 10];
        assert!(remove_fattening(&mut d, 3, 4, &FatteningConfig::for_window(5)).is_err());
    }
}
