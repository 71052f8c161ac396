//! Foreground extraction: which depth pixels belong to the person.
//!
//! With a background frame (the empty scene), a pixel is foreground when it has a reading
//! and lies clearly in front of the background there; the tolerance grows with depth like
//! the sensor's quantisation step. Without one, pixels within a depth range are grouped.
//! Either way the candidates are split into depth-continuous connected components and
//! the nearest large one is kept as the body, together with nearby large pieces of it
//! (a hand cut off by a shadow). Speckles vanish; holes inside the body stay holes.

use super::DepthView;
use crate::error::{ensure, Error, Result};

/// Settings of [`foreground_mask`].
#[derive(Debug, Clone, Copy)]
pub struct ForegroundConfig {
    /// Depth range (metres) considered at all.
    pub min_depth: f32,
    pub max_depth: f32,
    /// Background subtraction: foreground is `depth < background − tol(background)` with
    /// tol(z) = `bg_tolerance` + `bg_tolerance_quadratic`·z² (metres).
    pub bg_tolerance: f32,
    pub bg_tolerance_quadratic: f32,
    /// Two 4-neighbours belong to the same object when their depths differ by at most
    /// this (metres).
    pub max_step: f32,
    /// Components smaller than this many pixels are speckles.
    pub min_component: usize,
    /// A component is "large" if it has at least this share of the largest's pixels; the
    /// nearest large component is the body.
    pub large_share: f32,
    /// Other large pieces are kept when their median depth is within this of the body's
    /// and their bounding box touches the body's (grown by 10%).
    pub attach_depth: f32,
}

impl Default for ForegroundConfig {
    fn default() -> Self {
        ForegroundConfig {
            min_depth: 0.3,
            max_depth: 8.0,
            bg_tolerance: 0.025,
            bg_tolerance_quadratic: 0.003,
            max_step: 0.25,
            min_component: 40,
            large_share: 0.3,
            attach_depth: 0.5,
        }
    }
}

impl ForegroundConfig {
    pub fn validate(&self) -> Result<()> {
        let c = self;
        ensure(
            c.min_depth.is_finite() && c.min_depth >= 0.0 && c.max_depth > c.min_depth,
            "min_depth/max_depth",
            || {
                format!(
                    "need 0 <= min_depth < max_depth, got {} and {}",
                    c.min_depth, c.max_depth
                )
            },
        )?;
        for (v, n) in [
            (c.bg_tolerance, "bg_tolerance"),
            (c.bg_tolerance_quadratic, "bg_tolerance_quadratic"),
            (c.max_step, "max_step"),
            (c.attach_depth, "attach_depth"),
        ] {
            ensure(v.is_finite() && v >= 0.0, n, || {
                format!("must be >= 0, got {v}")
            })?;
        }
        ensure(
            c.large_share > 0.0 && c.large_share <= 1.0,
            "large_share",
            || format!("must be in (0, 1], got {}", c.large_share),
        )
    }
}

/// The person's pixels (row-major, same size as `depth`).
///
/// Errors when the image holds no reading in range (`NoBody`) or the background does not
/// match the depth image's size.
pub fn foreground_mask(
    depth: &DepthView,
    background: Option<&DepthView>,
    config: &ForegroundConfig,
) -> Result<Vec<bool>> {
    config.validate()?;
    if let Some(bg) = background {
        ensure(
            bg.width == depth.width && bg.height == depth.height,
            "background",
            || {
                format!(
                    "is {}x{} but depth is {}x{}",
                    bg.height, bg.width, depth.height, depth.width
                )
            },
        )?;
    }
    let n = depth.data.len();
    let in_range = |z: f32| z > config.min_depth && z < config.max_depth;
    let candidate: Vec<bool> = (0..n)
        .map(|i| {
            let z = depth.data[i];
            if !in_range(z) {
                return false;
            }
            match background {
                Some(bg) => {
                    let b = bg.data[i];
                    b.is_nan()
                        || b <= 0.0
                        || z < b - (config.bg_tolerance + config.bg_tolerance_quadratic * b * b)
                }
                None => true,
            }
        })
        .collect();
    if !candidate.iter().any(|&c| c) {
        return Err(Error::NoBody(if depth.count_valid() == 0 {
            "depth: the image has no valid reading (all zero or NaN)".into()
        } else {
            "depth: no foreground pixel (nothing in range / in front of the background)".into()
        }));
    }
    let components = Components::label(depth, &candidate, config.max_step);
    let keep = components.select_body(config);
    if keep.is_empty() {
        return Err(Error::NoBody(format!(
            "depth: no foreground object of at least {} pixels",
            config.min_component
        )));
    }
    let mut keep_flag = vec![false; components.stats.len()];
    for k in keep {
        keep_flag[k] = true;
    }
    let mut mask: Vec<bool> = components
        .label
        .iter()
        .map(|&l| l >= 0 && keep_flag[l as usize])
        .collect();
    for _ in 0..DROPOUT_FILL_PASSES {
        fill_dropouts(depth, &mut mask);
    }
    Ok(mask)
}

/// Passes of [`fill_dropouts`]: enough for the 1–2 pixel dropouts of depth sensors.
const DROPOUT_FILL_PASSES: usize = 2;

/// Adds to the mask the pixels *without a reading* that the body surrounds: both
/// neighbours along a row or a column, or three of the four 4-neighbours, in the mask.
/// These are sensor dropouts on the body, part of its silhouette (they add no points).
/// A real hole in the body's outline shows the scene behind it, has a reading, and stays
/// a hole.
fn fill_dropouts(depth: &DepthView, mask: &mut [bool]) {
    let (w, h) = (depth.width, depth.height);
    let mut add = Vec::new();
    for row in 1..h.saturating_sub(1) {
        for col in 1..w.saturating_sub(1) {
            let i = row * w + col;
            if mask[i] || depth.data[i] > 0.0 {
                continue;
            }
            let (l, r, u, d) = (mask[i - 1], mask[i + 1], mask[i - w], mask[i + w]);
            let count = l as u8 + r as u8 + u as u8 + d as u8;
            if (l && r) || (u && d) || count >= 3 {
                add.push(i);
            }
        }
    }
    for i in add {
        mask[i] = true;
    }
}

/// Per-component statistics.
#[derive(Debug, Clone)]
struct ComponentStats {
    size: usize,
    median_depth: f32,
    bbox: [usize; 4], // row0, col0, row1, col1 (inclusive)
}

struct Components {
    label: Vec<i32>,
    stats: Vec<ComponentStats>,
}

impl Components {
    /// Connected components of `candidate` pixels under 4-connectivity, joining two
    /// neighbours only when their depths differ by at most `max_step`.
    fn label(depth: &DepthView, candidate: &[bool], max_step: f32) -> Self {
        let (w, h) = (depth.width, depth.height);
        let mut uf = UnionFind::new(w * h);
        for row in 0..h {
            for col in 0..w {
                let i = row * w + col;
                if !candidate[i] {
                    continue;
                }
                let z = depth.data[i];
                if col + 1 < w && candidate[i + 1] && (depth.data[i + 1] - z).abs() <= max_step {
                    uf.union(i, i + 1);
                }
                if row + 1 < h && candidate[i + w] && (depth.data[i + w] - z).abs() <= max_step {
                    uf.union(i, i + w);
                }
            }
        }
        let mut label = vec![-1i32; w * h];
        let mut root_label = vec![-1i32; w * h];
        let mut depths: Vec<Vec<f32>> = Vec::new();
        let mut bboxes: Vec<[usize; 4]> = Vec::new();
        for i in 0..w * h {
            if !candidate[i] {
                continue;
            }
            let r = uf.find(i);
            if root_label[r] < 0 {
                root_label[r] = depths.len() as i32;
                depths.push(Vec::new());
                bboxes.push([usize::MAX, usize::MAX, 0, 0]);
            }
            let l = root_label[r];
            label[i] = l;
            depths[l as usize].push(depth.data[i]);
            let (row, col) = (i / w, i % w);
            let b = &mut bboxes[l as usize];
            b[0] = b[0].min(row);
            b[1] = b[1].min(col);
            b[2] = b[2].max(row);
            b[3] = b[3].max(col);
        }
        let stats = depths
            .into_iter()
            .zip(bboxes)
            .map(|(mut d, bbox)| {
                let size = d.len();
                let mid = size / 2;
                let (_, m, _) = d.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
                ComponentStats {
                    size,
                    median_depth: *m,
                    bbox,
                }
            })
            .collect();
        Components { label, stats }
    }

    /// The body: the nearest component among the large ones, plus large pieces next to it.
    fn select_body(&self, config: &ForegroundConfig) -> Vec<usize> {
        let largest = self.stats.iter().map(|s| s.size).max().unwrap_or(0);
        if largest < config.min_component {
            return Vec::new();
        }
        let large = (config.large_share * largest as f32).ceil() as usize;
        let body = (0..self.stats.len())
            .filter(|&k| self.stats[k].size >= large.max(config.min_component))
            .min_by(|&a, &b| {
                self.stats[a]
                    .median_depth
                    .total_cmp(&self.stats[b].median_depth)
            })
            .expect("the largest component qualifies");
        let b = &self.stats[body];
        let grow_r = (b.bbox[2] - b.bbox[0]) / 10 + 1;
        let grow_c = (b.bbox[3] - b.bbox[1]) / 10 + 1;
        let outer = [
            b.bbox[0].saturating_sub(grow_r),
            b.bbox[1].saturating_sub(grow_c),
            b.bbox[2] + grow_r,
            b.bbox[3] + grow_c,
        ];
        let mut keep = vec![body];
        for (k, s) in self.stats.iter().enumerate() {
            if k == body || s.size < config.min_component {
                continue;
            }
            let overlaps = s.bbox[0] <= outer[2]
                && s.bbox[2] >= outer[0]
                && s.bbox[1] <= outer[3]
                && s.bbox[3] >= outer[1];
            if overlaps && (s.median_depth - b.median_depth).abs() <= config.attach_depth {
                keep.push(k);
            }
        }
        keep
    }
}

/// Disjoint sets with path halving and union by size.
struct UnionFind {
    parent: Vec<u32>,
    size: Vec<u32>,
}

impl UnionFind {
    fn new(n: usize) -> Self {
        UnionFind {
            parent: (0..n as u32).collect(),
            size: vec![1; n],
        }
    }

    fn find(&mut self, mut x: usize) -> usize {
        while self.parent[x] as usize != x {
            let p = self.parent[x] as usize;
            self.parent[x] = self.parent[p];
            x = self.parent[x] as usize;
        }
        x
    }

    fn union(&mut self, a: usize, b: usize) {
        let (mut a, mut b) = (self.find(a), self.find(b));
        if a == b {
            return;
        }
        if self.size[a] < self.size[b] {
            std::mem::swap(&mut a, &mut b);
        }
        self.parent[b] = a as u32;
        self.size[a] += self.size[b];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(h: usize, w: usize, f: impl Fn(usize, usize) -> f32) -> Vec<f32> {
        (0..h * w).map(|i| f(i / w, i % w)).collect()
    }

    #[test]
    fn background_subtraction_keeps_the_body_and_its_holes() {
        let (h, w) = (60, 80);
        let bg = img(h, w, |_, _| 4.0);
        let depth = img(h, w, |r, c| {
            if (10..50).contains(&r) && (30..50).contains(&c) {
                if r == 30 && c == 40 {
                    0.0 // a hole inside the body
                } else {
                    2.5
                }
            } else if r == 2 && c == 2 {
                1.0 // a speckle
            } else {
                4.0 + if (r + c) % 2 == 0 { 0.02 } else { -0.02 } // noise
            }
        });
        let d = DepthView::new(&depth, h, w, "depth").unwrap();
        let b = DepthView::new(&bg, h, w, "background").unwrap();
        let m = foreground_mask(&d, Some(&b), &ForegroundConfig::default()).unwrap();
        assert_eq!(m.iter().filter(|&&x| x).count(), 40 * 20 - 1);
        assert!(!m[30 * w + 40]);
        assert!(!m[2 * w + 2]);
    }

    #[test]
    fn nearest_large_body_wins() {
        let (h, w) = (60, 100);
        let depth = img(h, w, |r, c| {
            if (10..55).contains(&r) && (10..40).contains(&c) {
                3.0 // the far person, larger in pixels
            } else if (20..50).contains(&r) && (60..80).contains(&c) {
                2.0 // the near person
            } else if r < 3 && c < 3 {
                1.0 // a small near blob
            } else {
                0.0
            }
        });
        let d = DepthView::new(&depth, h, w, "depth").unwrap();
        let m = foreground_mask(&d, None, &ForegroundConfig::default()).unwrap();
        assert!(m[30 * w + 70] && !m[30 * w + 20] && !m[0]);
    }

    #[test]
    fn empty_input_is_no_body() {
        let depth = vec![0.0f32; 12];
        let d = DepthView::new(&depth, 3, 4, "depth").unwrap();
        let e = foreground_mask(&d, None, &ForegroundConfig::default()).unwrap_err();
        assert!(matches!(e, Error::NoBody(_)));
    }
}
