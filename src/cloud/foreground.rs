//! Foreground extraction: which depth pixels belong to the person.
//!
//! With a background frame (the empty scene), a pixel is foreground when it has a reading
//! and lies clearly in front of the background there; the tolerance grows with depth like
//! the sensor's quantisation step. Without one, pixels within a depth range are grouped.
//! Either way the candidates are split into depth-continuous connected components and
//! the nearest large one is kept as the body, together with nearby large pieces of it
//! (a hand cut off by a shadow) and, with a background frame, the large pieces that
//! meet it across a dropout seam (a side view's far leg behind the near one). Speckles
//! vanish; holes inside the body stay holes.

use super::DepthView;
use crate::error::{ensure, Error, Result};
use crate::union_find::UnionFind;

/// Settings of [`foreground_mask`].
#[derive(Debug, Clone, Copy, PartialEq)]
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
    /// With a background frame, pieces that meet the body across a dropout seam are
    /// kept from this many pixels. 0 keeps every one: a depth sensor's dropouts break a
    /// thin far limb into small pieces. A stereo rig's mismatches leave small islands
    /// beside the body (on the floor around the feet), so its segmentation keeps only
    /// pieces of `min_component` pixels.
    pub min_joined_piece: usize,
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
            min_joined_piece: 0,
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
    // Branch-free per pixel (the loops vectorise); the background test only with one.
    let mut candidate = vec![false; n];
    match background {
        Some(bg) => {
            for ((c, &z), &b) in candidate.iter_mut().zip(depth.data).zip(bg.data) {
                *c = in_range(z) & (b.is_nan() | (b <= 0.0) | in_front_of_background(z, b, config));
            }
        }
        None => {
            for (c, &z) in candidate.iter_mut().zip(depth.data) {
                *c = in_range(z);
            }
        }
    }
    if !candidate.iter().any(|&c| c) {
        return Err(Error::NoBody(if depth.count_valid() == 0 {
            "depth: the image has no valid reading (all zero or NaN)".into()
        } else {
            "depth: no foreground pixel (nothing in range / in front of the background)".into()
        }));
    }
    let components = Components::label(depth, &candidate, config.max_step, config.min_component);
    // With a background frame every candidate lies in front of the empty scene, so a
    // piece that meets the body across a sensor's dropout seam with a small depth step
    // (a side view's far leg behind the near one) is part of it, however far its median
    // lies behind the body's. Without one, the seam may separate the body from a wall.
    let groups = background.is_some().then(|| {
        components
            .bridge_gaps(depth, MAX_GAP, config.attach_depth)
            .0
    });
    let keep = components.select_body(config, groups.as_deref());
    if keep.is_empty() {
        return Err(Error::NoBody(format!(
            "depth: no foreground object of at least {} pixels",
            config.min_component
        )));
    }
    let mut keep_flag = vec![false; components.stats.len()];
    // Dropouts can only be filled inside the kept components' bounding box.
    let mut bbox = [usize::MAX, usize::MAX, 0, 0];
    for k in keep {
        keep_flag[k] = true;
        bbox = union_box(bbox, components.stats[k].bbox);
    }
    let mut mask = vec![false; n];
    for &i in &components.pixels {
        mask[i as usize] = keep_flag[components.label[i as usize] as usize];
    }
    fill_silhouette(depth, &mut mask, bbox);
    Ok(mask)
}

/// Adds to `mask` (whose bounding box is `bbox`) the pixels without a reading that
/// belong to the silhouette: the dropouts the body surrounds ([`fill_dropouts`]), then
/// those biting into its edge ([`fill_majority`]).
pub(crate) fn fill_silhouette(depth: &DepthView, mask: &mut [bool], bbox: [usize; 4]) {
    let mut added = Vec::new();
    for _ in 0..DROPOUT_FILL_PASSES {
        fill_dropouts(depth, mask, bbox, &mut added);
    }
    let mut bbox = bbox;
    for _ in 0..MAJORITY_FILL_PASSES {
        match fill_majority(depth, mask, bbox, &mut added) {
            Some(grown) => bbox = grown,
            None => break,
        }
    }
}

/// Whether depth `z` lies clearly in front of the background depth `b` (a reading):
/// `z < b − tol(b)` with tol(b) = `bg_tolerance` + `bg_tolerance_quadratic`·b².
#[inline]
pub(crate) fn in_front_of_background(z: f32, b: f32, config: &ForegroundConfig) -> bool {
    z < b - (config.bg_tolerance + config.bg_tolerance_quadratic * b * b)
}

/// Passes of [`fill_dropouts`]: enough for the 1–2 pixel dropouts of depth sensors.
pub(crate) const DROPOUT_FILL_PASSES: usize = 2;

/// Pixels without a reading that may separate two parts of one object (dropouts along
/// depth edges are 1–2 pixels wide, a projector's shadow a few more).
pub(crate) const MAX_GAP: usize = 3;

/// Adds to the mask the pixels *without a reading* that the body surrounds: both
/// neighbours along a row or a column, or three of the four 4-neighbours, in the mask.
/// These are sensor dropouts on the body, part of its silhouette (they add no points).
/// A real hole in the body's outline shows the scene behind it, has a reading, and stays
/// a hole. Only pixels inside `bbox` (row0, col0, row1, col1; the mask's bounding box)
/// can qualify: outside it at most one neighbour is in the mask. `add` is scratch.
pub(crate) fn fill_dropouts(
    depth: &DepthView,
    mask: &mut [bool],
    bbox: [usize; 4],
    add: &mut Vec<usize>,
) {
    let (w, h) = (depth.width, depth.height);
    let rows = bbox[0].max(1)..(bbox[2] + 1).min(h.saturating_sub(1));
    let cols = bbox[1].max(1)..(bbox[3] + 1).min(w.saturating_sub(1));
    fill_where(depth, mask, rows, cols, add, |m, i| {
        let (l, r, u, d) = (m[i - 1], m[i + 1], m[i - w], m[i + w]);
        (l && r) || (u && d) || l as u8 + r as u8 + u as u8 + d as u8 >= 3
    });
}

/// Adds to the mask the pixels without a reading in `rows` × `cols` that `rule` (the
/// mask, the pixel) accepts, every pixel judged on the mask as it was before: one pass
/// of a fill. The ranges leave a pixel's 8 neighbours inside the image. `add` is
/// scratch, left holding the pixels added.
fn fill_where(
    depth: &DepthView,
    mask: &mut [bool],
    rows: std::ops::Range<usize>,
    cols: std::ops::Range<usize>,
    add: &mut Vec<usize>,
    rule: impl Fn(&[bool], usize) -> bool,
) {
    let w = depth.width;
    add.clear();
    for row in rows {
        for col in cols.clone() {
            let i = row * w + col;
            // A reading (NaN is none) is never filled.
            if mask[i] || depth.data[i] > 0.0 {
                continue;
            }
            if rule(mask, i) {
                add.push(i);
            }
        }
    }
    for &i in add.iter() {
        mask[i] = true;
    }
}

/// Passes of [`fill_majority`]: the ragged edge of a noisy sensor's silhouette is a few
/// pixels deep.
pub(crate) const MAJORITY_FILL_PASSES: usize = 3;

/// Adds to the mask the pixels without a reading of which at least 5 of the 8
/// neighbours are in it: dropouts that bite into the silhouette's edge (a smooth edge
/// gives an outside pixel at most 3 neighbours inside, a projector's shadow band along
/// it too). Only pixels within one pixel of `bbox` (row0, col0, row1, col1; the mask's
/// bounding box) can qualify. Returns the bounding box of the mask after the pass, or
/// None when no pixel was added. `add` is scratch.
pub(crate) fn fill_majority(
    depth: &DepthView,
    mask: &mut [bool],
    bbox: [usize; 4],
    add: &mut Vec<usize>,
) -> Option<[usize; 4]> {
    let (w, h) = (depth.width, depth.height);
    if w < 3 || h < 3 || bbox[0] > bbox[2] {
        add.clear();
        return None;
    }
    let rows = bbox[0].max(2) - 1..(bbox[2] + 2).min(h - 1);
    let cols = bbox[1].max(2) - 1..(bbox[3] + 2).min(w - 1);
    fill_where(depth, mask, rows, cols, add, |m, i| {
        let n = m[i - w - 1] as u8
            + m[i - w] as u8
            + m[i - w + 1] as u8
            + m[i - 1] as u8
            + m[i + 1] as u8
            + m[i + w - 1] as u8
            + m[i + w] as u8
            + m[i + w + 1] as u8;
        n >= 5
    });
    let grown = add
        .iter()
        .fold(bbox, |b, &i| union_box(b, [i / w, i % w, i / w, i % w]));
    (!add.is_empty()).then_some(grown)
}

/// The smallest box (row0, col0, row1, col1, inclusive) holding boxes `a` and `b`; the
/// empty box is `[usize::MAX, usize::MAX, 0, 0]`.
pub(crate) fn union_box(a: [usize; 4], b: [usize; 4]) -> [usize; 4] {
    [
        a[0].min(b[0]),
        a[1].min(b[1]),
        a[2].max(b[2]),
        a[3].max(b[3]),
    ]
}

/// Per-component statistics.
#[derive(Debug, Clone)]
pub(crate) struct ComponentStats {
    pub size: usize,
    pub median_depth: f32,
    pub bbox: [usize; 4], // row0, col0, row1, col1 (inclusive)
}

pub(crate) struct Components {
    /// Component of each pixel, −1 for non-candidates.
    pub label: Vec<i32>,
    /// The candidate pixels, in raster order.
    pub pixels: Vec<u32>,
    pub stats: Vec<ComponentStats>,
}

impl Components {
    /// Connected components of `candidate` pixels under 4-connectivity, joining two
    /// neighbours only when their depths differ by at most `max_step`, numbered in the
    /// raster order of their first pixel. Two passes: provisional labels from the left
    /// and upper neighbours with their equivalences in a union–find over the labels
    /// (not the pixels), then the final numbering and the statistics. The median depth
    /// is computed only for components of at least `min_size` pixels (the only ones
    /// [`Components::select_body`] looks at); smaller ones get NaN.
    pub(crate) fn label(
        depth: &DepthView,
        candidate: &[bool],
        max_step: f32,
        min_size: usize,
    ) -> Self {
        let (w, h) = (depth.width, depth.height);
        let z = depth.data;
        let mut label = vec![-1i32; w * h];
        let mut pixels = Vec::new();
        let mut uf = UnionFind::default();
        // Most of a frame is background: runs without a candidate are skipped 16 at once.
        const RUN: usize = 16;
        for row in 0..h {
            let mut next = 0; // the next column to look at
            while next < w {
                let col = next;
                let i = row * w + col;
                next += 1;
                if !candidate[i] {
                    // Skip the following RUN columns too when none of them is a candidate.
                    if next + RUN <= w && !candidate[i + 1..i + 1 + RUN].iter().any(|&c| c) {
                        next += RUN;
                    }
                    continue;
                }
                pixels.push(i as u32);
                let joins = |j: usize| candidate[j] && (z[j] - z[i]).abs() <= max_step;
                let left = (col > 0 && joins(i - 1)).then(|| label[i - 1] as usize);
                let up = (row > 0 && joins(i - w)).then(|| label[i - w] as usize);
                label[i] = match (left, up) {
                    (Some(a), Some(b)) => {
                        if a != b {
                            uf.union(a, b);
                        }
                        a as i32
                    }
                    (Some(a), None) | (None, Some(a)) => a as i32,
                    (None, None) => uf.push() as i32,
                };
            }
        }
        // Final numbering: first pixel in raster order first.
        let mut final_id = vec![-1i32; uf.len()];
        let mut stats: Vec<ComponentStats> = Vec::new();
        let mut row = 0;
        for &i in &pixels {
            let i = i as usize;
            // Raster order: the row only grows (no division per pixel).
            while i >= (row + 1) * w {
                row += 1;
            }
            let col = i - row * w;
            let l = &mut label[i];
            let root = uf.find(*l as usize);
            if final_id[root] < 0 {
                final_id[root] = stats.len() as i32;
                stats.push(ComponentStats {
                    size: 0,
                    median_depth: f32::NAN,
                    bbox: [usize::MAX, usize::MAX, 0, 0],
                });
            }
            *l = final_id[root];
            let s = &mut stats[*l as usize];
            s.size += 1;
            s.bbox = union_box(s.bbox, [row, col, row, col]);
        }
        // Medians of the components large enough to matter.
        let mut slot = vec![usize::MAX; stats.len()];
        let mut depths: Vec<Vec<f32>> = Vec::new();
        for (k, s) in stats.iter().enumerate() {
            if s.size >= min_size {
                slot[k] = depths.len();
                depths.push(Vec::with_capacity(s.size));
            }
        }
        if !depths.is_empty() {
            for &i in &pixels {
                let k = slot[label[i as usize] as usize];
                if k != usize::MAX {
                    depths[k].push(z[i as usize]);
                }
            }
            for (k, s) in stats.iter_mut().enumerate() {
                if slot[k] != usize::MAX {
                    let d = &mut depths[slot[k]];
                    let mid = d.len() / 2;
                    s.median_depth = *d.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1;
                }
            }
        }
        Components {
            label,
            pixels,
            stats,
        }
    }

    /// Groups of components into objects: two components whose pixels are neighbours, or
    /// face each other across a run of at most `max_gap` pixels without a reading (a sensor
    /// dropout along a depth edge, a projector shadow), along a row or a column, with depths
    /// within `max_step`, are one object. (The components join neighbours within a smaller
    /// step: a body's far leg is a component of its own, and joins the body here.) Returns
    /// the group of each component, groups numbered from 0, and their count.
    pub(crate) fn bridge_gaps(
        &self,
        depth: &DepthView,
        max_gap: usize,
        max_step: f32,
    ) -> (Vec<usize>, usize) {
        let (w, h) = (depth.width, depth.height);
        let mut uf = UnionFind::singletons(self.stats.len());
        if max_gap > 0 {
            let z = depth.data;
            let label = &self.label;
            // From each labelled pixel, the first labelled pixel to its right and the first
            // below, across at most `max_gap` pixels without a reading; a reading of
            // something else between them (a plane) separates them. Only the candidate
            // pixels are visited, so a frame of background subtraction costs its person.
            for &p in &self.pixels {
                let i = p as usize;
                let (row, col) = (i / w, i % w);
                for (step, room) in [(1, w - 1 - col), (w, h - 1 - row)] {
                    for s in 1..=room.min(max_gap + 1) {
                        let j = i + s * step;
                        if label[j] >= 0 {
                            let (a, b) = (label[i] as usize, label[j] as usize);
                            if a != b && (z[i] - z[j]).abs() <= max_step {
                                uf.union(a, b);
                            }
                            break;
                        }
                        if z[j] > 0.0 {
                            break;
                        }
                    }
                }
            }
        }
        uf.numbered_sets()
    }

    /// The body: the nearest component among the large ones, plus the large pieces next
    /// to it (their boxes touch and their medians lie within `attach_depth`) and, with
    /// `groups` ([`Self::bridge_gaps`]), the pieces in the body's group of at least
    /// `min_joined_piece` pixels.
    fn select_body(&self, config: &ForegroundConfig, groups: Option<&[usize]>) -> Vec<usize> {
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
            if k == body {
                continue;
            }
            let joined =
                s.size >= config.min_joined_piece && groups.is_some_and(|g| g[k] == g[body]);
            let overlaps = s.bbox[0] <= outer[2]
                && s.bbox[2] >= outer[0]
                && s.bbox[1] <= outer[3]
                && s.bbox[3] >= outer[1];
            let near = s.size >= config.min_component
                && overlaps
                && (s.median_depth - b.median_depth).abs() <= config.attach_depth;
            if near || joined {
                keep.push(k);
            }
        }
        keep
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Components by breadth-first flood fill from each unlabelled candidate in raster
    /// order, with every median computed (a reference for the two-pass labelling).
    fn flood_components(depth: &DepthView, candidate: &[bool], max_step: f32) -> Components {
        let (w, h) = (depth.width, depth.height);
        let mut label = vec![-1i32; w * h];
        let mut stats = Vec::new();
        for start in 0..w * h {
            if !candidate[start] || label[start] >= 0 {
                continue;
            }
            let id = stats.len() as i32;
            let mut queue = std::collections::VecDeque::from([start]);
            label[start] = id;
            let (mut depths, mut bbox) = (Vec::new(), [usize::MAX, usize::MAX, 0, 0]);
            while let Some(i) = queue.pop_front() {
                let (row, col) = (i / w, i % w);
                depths.push(depth.data[i]);
                bbox = union_box(bbox, [row, col, row, col]);
                let mut near = Vec::new();
                if col > 0 {
                    near.push(i - 1);
                }
                if col + 1 < w {
                    near.push(i + 1);
                }
                if row > 0 {
                    near.push(i - w);
                }
                if row + 1 < h {
                    near.push(i + w);
                }
                for j in near {
                    if candidate[j]
                        && label[j] < 0
                        && (depth.data[j] - depth.data[i]).abs() <= max_step
                    {
                        label[j] = id;
                        queue.push_back(j);
                    }
                }
            }
            depths.sort_by(|a, b| a.total_cmp(b));
            stats.push(ComponentStats {
                size: depths.len(),
                median_depth: depths[depths.len() / 2],
                bbox,
            });
        }
        let pixels = (0..w * h)
            .filter(|&i| candidate[i])
            .map(|i| i as u32)
            .collect();
        Components {
            label,
            pixels,
            stats,
        }
    }

    /// [`Components::bridge_gaps`] by walking every row and every column of the image,
    /// remembering the last labelled pixel and the pixels without a reading since it.
    fn walked_groups(
        comp: &Components,
        depth: &DepthView,
        max_gap: usize,
        max_step: f32,
    ) -> Vec<usize> {
        let (w, h) = (depth.width, depth.height);
        let mut uf = UnionFind::singletons(comp.stats.len());
        if max_gap > 0 {
            let (z, label) = (depth.data, &comp.label);
            let mut walk = |start: usize, step: usize, len: usize| {
                let (mut last, mut gap): (Option<usize>, usize) = (None, 0);
                for k in 0..len {
                    let i = start + k * step;
                    if label[i] >= 0 {
                        if let Some(j) = last {
                            let (a, b) = (label[j] as usize, label[i] as usize);
                            if a != b && (z[i] - z[j]).abs() <= max_step {
                                uf.union(a, b);
                            }
                        }
                        (last, gap) = (Some(i), 0);
                    } else if z[i] > 0.0 {
                        last = None;
                    } else {
                        gap += 1;
                        if gap > max_gap {
                            last = None;
                        }
                    }
                }
            };
            for row in 0..h {
                walk(row * w, 1, w);
            }
            for col in 0..w {
                walk(col, w, h);
            }
        }
        uf.numbered_sets().0
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// Bridging from the candidate pixels groups the components exactly as walking
        /// every row and column does.
        #[test]
        fn bridging_matches_a_walk_over_every_line(
            h in 1usize..14,
            w in 1usize..41,
            levels in proptest::collection::vec(0u8..6, 14 * 40),
            max_gap in 0usize..5,
            max_step in prop_oneof![Just(0.2f32), Just(0.5f32)],
        ) {
            // No reading (0 and NaN), three candidate depths, a reading that is not one.
            let values = [0.0f32, f32::NAN, 1.0, 1.1, 1.6, 3.0];
            let depth: Vec<f32> = levels[..h * w].iter().map(|&k| values[k as usize]).collect();
            let view = DepthView::new(&depth, h, w, "depth").unwrap();
            let candidate: Vec<bool> = depth.iter().map(|&z| z > 0.3 && z < 2.5).collect();
            let comp = Components::label(&view, &candidate, 0.05, usize::MAX);
            let (group, count) = comp.bridge_gaps(&view, max_gap, max_step);
            let want = walked_groups(&comp, &view, max_gap, max_step);
            prop_assert_eq!(count, want.iter().max().map_or(0, |&g| g + 1));
            prop_assert_eq!(group, want);
        }

        /// The two-pass labelling finds the flood fill's components with the same
        /// numbering, sizes, boxes and (for large enough ones) medians; the mask fills
        /// the same dropouts, inside and biting into the edge, as a scan of the whole
        /// image would.
        #[test]
        fn components_match_a_flood_fill(
            h in 1usize..14,
            w in 1usize..41,
            levels in proptest::collection::vec(0u8..6, 14 * 40),
            step in prop_oneof![Just(0.05f32), Just(0.25f32)],
            min_size in 0usize..6,
        ) {
            let values = [0.0f32, 1.0, 1.1, 1.2, 2.0, 3.0];
            let depth: Vec<f32> = levels[..h * w].iter().map(|&k| values[k as usize]).collect();
            let view = DepthView::new(&depth, h, w, "depth").unwrap();
            let candidate: Vec<bool> = depth.iter().map(|&z| z > 0.3 && z < 2.5).collect();
            let got = Components::label(&view, &candidate, step, min_size);
            let want = flood_components(&view, &candidate, step);
            prop_assert_eq!(&got.label, &want.label);
            prop_assert_eq!(got.stats.len(), want.stats.len());
            for (g, e) in got.stats.iter().zip(&want.stats) {
                prop_assert_eq!(g.size, e.size);
                prop_assert_eq!(g.bbox, e.bbox);
                if g.size >= min_size {
                    prop_assert_eq!(g.median_depth, e.median_depth);
                } else {
                    prop_assert!(g.median_depth.is_nan());
                }
            }
            // The same candidates as above: readings in (0.3, 2.5) m.
            let config = ForegroundConfig { min_depth: 0.3, max_depth: 2.5, min_component: min_size, max_step: step, ..Default::default() };
            if let Ok(mask) = foreground_mask(&view, None, &config) {
                // The same selection on the reference components, then dropouts filled
                // by scanning every pixel.
                let keep = want.select_body(&config, None);
                let mut full: Vec<bool> = want.label.iter().map(|&l| l >= 0 && keep.contains(&(l as usize))).collect();
                // `passes` times, every interior pixel without a reading that `rule`
                // accepts (given the mask and the pixel) joins the mask.
                let mut fill = |passes: usize, rule: &dyn Fn(&[bool], usize) -> bool| {
                    for _ in 0..passes {
                        let add: Vec<usize> = (0..h * w)
                            .filter(|&i| {
                                let (row, col) = (i / w, i % w);
                                if row == 0 || col == 0 || row + 1 >= h || col + 1 >= w || full[i] || depth[i] > 0.0 {
                                    return false;
                                }
                                rule(&full, i)
                            })
                            .collect();
                        for i in add {
                            full[i] = true;
                        }
                    }
                };
                // Surrounded along a row or a column, or by three of the four neighbours.
                fill(DROPOUT_FILL_PASSES, &|m, i| {
                    let (l, r, u, d) = (m[i - 1], m[i + 1], m[i - w], m[i + w]);
                    (l && r) || (u && d) || (l as u8 + r as u8 + u as u8 + d as u8) >= 3
                });
                // Then at least 5 of the 8 neighbours in.
                fill(MAJORITY_FILL_PASSES, &|m, i| {
                    [i - w - 1, i - w, i - w + 1, i - 1, i + 1, i + w - 1, i + w, i + w + 1].iter().filter(|&&j| m[j]).count() >= 5
                });
                prop_assert_eq!(mask, full);
            }
        }
    }

    /// `n` rows × `w` columns of depth from a per-column profile.
    fn columns(h: usize, profile: &[f32]) -> Vec<f32> {
        (0..h).flat_map(|_| profile.iter().copied()).collect()
    }

    #[test]
    fn gaps_without_readings_join_objects_and_readings_separate_them() {
        let groups = |profile: &[f32]| {
            let depth = columns(4, profile);
            let view = DepthView::new(&depth, 4, profile.len(), "depth").unwrap();
            let candidate: Vec<bool> = depth.iter().map(|&z| z > 0.0 && z < 4.0).collect();
            let comp = Components::label(&view, &candidate, 0.05, usize::MAX);
            let (group, n) = comp.bridge_gaps(&view, 3, 0.5);
            (comp.stats.len(), n, group)
        };
        // Two parts 0.2 m apart in depth, across two pixels without a reading: one object.
        assert_eq!(groups(&[2.0, 2.0, 0.0, 0.0, 2.2, 2.2]).1, 1);
        // Directly adjacent with a step the components do not join (0.3 m): one object.
        assert_eq!(groups(&[2.0, 2.0, 2.3, 2.3]).1, 1);
        // Four pixels without a reading are too wide a gap.
        assert_eq!(groups(&[2.0, 0.0, 0.0, 0.0, 0.0, 2.0]).1, 2);
        // A reading of something else between them (4.5 m, not a candidate) separates.
        assert_eq!(groups(&[2.0, 2.0, 4.5, 2.0, 2.0]).1, 2);
        // Too far apart in depth (0.8 m).
        let (components, n, _) = groups(&[2.0, 0.0, 2.8]);
        assert_eq!((components, n), (2, 2));
    }

    #[test]
    fn the_majority_fill_closes_bites_but_not_a_shadow_band() {
        let (h, w) = (12, 12);
        // A body block (rows 2..10, cols 3..9) with dropouts in it and a notch at its right
        // edge,
        // and a one-pixel band without readings along its left edge (a shadow).
        let mut depth = vec![4.0f32; h * w];
        let mut mask = vec![false; h * w];
        for r in 2..10 {
            for c in 3..9 {
                depth[r * w + c] = 2.0;
                mask[r * w + c] = true;
            }
            depth[r * w + 2] = 0.0;
        }
        for (r, c) in [(5, 8), (7, 6), (7, 7)] {
            depth[r * w + c] = 0.0;
            mask[r * w + c] = false;
        }
        let view = DepthView::new(&depth, h, w, "depth").unwrap();
        let mut add = Vec::new();
        let mut bbox = Some([2, 3, 9, 8]);
        while let Some(b) = bbox {
            bbox = fill_majority(&view, &mut mask, b, &mut add);
        }
        for (r, c) in [(5, 8), (7, 6), (7, 7)] {
            assert!(mask[r * w + c], "bite pixel ({r}, {c}) filled");
        }
        for r in 0..h {
            assert!(!mask[r * w + 2], "shadow pixel ({r}, 2) left out");
        }
    }

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
                    0.0 // a sensor dropout on the body: part of the silhouette
                } else if (20..24).contains(&r) && (35..38).contains(&c) {
                    4.0 // a real hole: the wall seen through the body
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
        assert_eq!(m.iter().filter(|&&x| x).count(), 40 * 20 - 4 * 3);
        assert!(m[30 * w + 40], "dropout filled");
        assert!(!m[21 * w + 36], "hole kept");
        assert!(!m[2 * w + 2], "speckle dropped");
    }

    #[test]
    fn with_a_background_a_far_leg_across_a_dropout_seam_is_kept_and_an_object_behind_is_not() {
        // A side view: the body (3.0 m) and, behind a one-pixel dropout seam, its far leg
        // going back from 3.4 m to 3.78 m (median 0.59 m behind the body's: beyond
        // `attach_depth`), with its foot (12 pixels, below `min_component`) cut off by a
        // row of dropouts.
        let (h, w) = (60, 80);
        let bg = img(h, w, |_, _| 5.0);
        let scene = |seam: f32| {
            img(h, w, |r, c| match (r, c) {
                (10..50, 30..45) => 3.0,
                (30..50, 45) => seam,
                (30..50, 46..50) => 3.4 + 0.02 * (r - 30) as f32,
                (50, 46..50) => 0.0,
                (51..54, 46..50) => 3.8,
                _ => 5.0,
            })
        };
        let b = DepthView::new(&bg, h, w, "background").unwrap();
        let config = ForegroundConfig::default();
        let depth = scene(0.0);
        let d = DepthView::new(&depth, h, w, "depth").unwrap();
        let m = foreground_mask(&d, Some(&b), &config).unwrap();
        assert!(m[20 * w + 35], "the body");
        assert!(m[40 * w + 47], "the far leg");
        assert!(m[52 * w + 47], "its foot");
        assert!(m[40 * w + 45], "the seam between them");
        // The same shapes with the empty scene's reading in the seam: an object standing
        // behind the person, beside it in the image. It stays out.
        let depth = scene(5.0);
        let d = DepthView::new(&depth, h, w, "depth").unwrap();
        let m = foreground_mask(&d, Some(&b), &config).unwrap();
        assert!(m[20 * w + 35] && !m[40 * w + 47] && !m[52 * w + 47]);
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
