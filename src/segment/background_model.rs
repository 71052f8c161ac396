//! An online model of a video's static background: the depth of the empty scene, learned
//! per pixel from the frames of a recording while a person moves through it.
//!
//! Each pixel keeps a running estimate of its farthest stable depth. A reading that
//! agrees with the pixel's current mode (within a tolerance that grows with depth like
//! the sensor's noise, `tolerance + tolerance_quadratic·z²`) adds to the mode's count and
//! refines its mean; one that does not feeds a second, challenging mode. A challenger that
//! becomes stable replaces the mode when it lies farther (what covered the pixel has
//! gone) or when the mode itself was never stable (a passing reading). A mode seen in
//! `frames` agreeing frames is learned as the pixel's background depth, and a learned
//! depth only gives way to a farther stable one, or is refined by readings within the
//! tolerance of it: something that stands in front of the background for a long time is
//! never taken for it.
//!
//! The pixels of the person — the current mask, grown by `margin` pixels to cover the
//! silhouette's mixed-depth edge — are not learned at all, so a person who stands still
//! stays unknown and a pixel the person covers is learned once the person has moved
//! away. Pixels without a reading are not learned either and stay unknown (depth 0).
//!
//! Once `min_learned_share` of the pixels that have had a reading are learned, the model
//! gives the segmentation its background ([`BackgroundModel::learned`]): the person is
//! what lies clearly in front of it, and the automatic support-plane test decides the
//! pixels that are still unknown ([`super::segment_person`]).

use crate::error::{ensure, Result};
use std::sync::Arc;

/// Settings of [`BackgroundModel`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BackgroundModelConfig {
    /// Two depths of a pixel agree when they differ by at most `tolerance +
    /// tolerance_quadratic·z²` metres (`z` the pixel's mode).
    pub tolerance: f32,
    pub tolerance_quadratic: f32,
    /// A pixel's depth is learned after this many agreeing frames.
    pub frames: usize,
    /// The model is used once this share of the pixels that have had a reading is
    /// learned.
    pub min_learned_share: f32,
    /// Pixels within this many pixels (chessboard distance) of the person's mask are not
    /// learned.
    pub margin: usize,
}

impl Default for BackgroundModelConfig {
    fn default() -> Self {
        BackgroundModelConfig {
            tolerance: 0.03,
            tolerance_quadratic: 0.004,
            frames: 8,
            min_learned_share: 0.5,
            margin: 4,
        }
    }
}

/// The largest [`BackgroundModelConfig::frames`].
pub const MAX_FRAMES: usize = 10_000;
/// The largest [`BackgroundModelConfig::margin`].
pub const MAX_MARGIN: usize = 64;
/// A mode's mean follows its readings with at most this many frames of memory (a slow
/// drift of the sensor is followed).
const MEAN_WINDOW: u16 = 32;
/// `1/n` for the running mean of `n` readings, `n` in 1..=[`MEAN_WINDOW`].
const WEIGHTS: [f32; MEAN_WINDOW as usize + 1] = {
    let mut w = [0.0; MEAN_WINDOW as usize + 1];
    let mut n = 1;
    while n <= MEAN_WINDOW as usize {
        w[n] = 1.0 / n as f32;
        n += 1;
    }
    w
};

impl BackgroundModelConfig {
    /// Checks every field; the error names the first nonsensical one (prefixed
    /// `background_model.`).
    pub fn validate(&self) -> Result<()> {
        for (v, n) in [
            (self.tolerance, "background_model.tolerance"),
            (
                self.tolerance_quadratic,
                "background_model.tolerance_quadratic",
            ),
        ] {
            ensure(v.is_finite() && v >= 0.0, n, || {
                format!("must be a finite number >= 0, got {v}")
            })?;
        }
        ensure(
            (1..=MAX_FRAMES).contains(&self.frames),
            "background_model.frames",
            || format!("expected 1..{MAX_FRAMES}, got {}", self.frames),
        )?;
        let s = self.min_learned_share;
        ensure(
            s.is_finite() && (0.0..=1.0).contains(&s),
            "background_model.min_learned_share",
            || format!("expected a number in [0, 1], got {s}"),
        )?;
        ensure(self.margin <= MAX_MARGIN, "background_model.margin", || {
            format!("expected 0..{MAX_MARGIN}, got {}", self.margin)
        })
    }

    /// The agreement tolerance at depth `z`.
    #[inline]
    pub fn tolerance_at(&self, z: f32) -> f32 {
        self.tolerance + self.tolerance_quadratic * z * z
    }
}

/// One depth hypothesis of a pixel: its mean and how many frames agreed with it (0: none).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Mode {
    depth: f32,
    count: u16,
}

impl Mode {
    /// Whether `z` agrees with this mode.
    #[inline]
    fn agrees(&self, z: f32, config: &BackgroundModelConfig) -> bool {
        self.count > 0 && (z - self.depth).abs() <= config.tolerance_at(self.depth)
    }

    /// Adds an agreeing reading.
    #[inline]
    fn add(&mut self, z: f32) {
        self.count = self.count.saturating_add(1);
        self.depth += (z - self.depth) * WEIGHTS[self.count.min(MEAN_WINDOW) as usize];
    }
}

/// The learned background of a video (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct BackgroundModel {
    width: usize,
    height: usize,
    config: BackgroundModelConfig,
    /// Per pixel: its mode and the challenging mode.
    modes: Vec<[Mode; 2]>,
    /// Learned depth per pixel, 0 where unknown; shared with the segmentations that use
    /// it (copied on write only while one still holds it).
    background: Arc<Vec<f32>>,
    /// Whether the pixel has had a reading.
    seen: Vec<bool>,
    seen_pixels: usize,
    learned_pixels: usize,
    frames: usize,
    /// Scratch: the person's mask grown by the margin.
    grown: Vec<bool>,
}

impl BackgroundModel {
    /// An empty model for `width`×`height` images.
    pub fn new(width: usize, height: usize, config: BackgroundModelConfig) -> Result<Self> {
        config.validate()?;
        let n = width * height;
        Ok(BackgroundModel {
            width,
            height,
            config,
            modes: vec![[Mode::default(); 2]; n],
            background: Arc::new(vec![0.0; n]),
            seen: vec![false; n],
            seen_pixels: 0,
            learned_pixels: 0,
            frames: 0,
            grown: vec![false; n],
        })
    }

    pub fn config(&self) -> &BackgroundModelConfig {
        &self.config
    }

    /// Frames learned from.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// The learned depth per pixel (row-major, metres), 0 where unknown.
    pub fn background(&self) -> &[f32] {
        &self.background
    }

    /// The share of the pixels that have had a reading whose depth is learned (0 before
    /// any reading).
    pub fn learned_share(&self) -> f64 {
        if self.seen_pixels == 0 {
            0.0
        } else {
            self.learned_pixels as f64 / self.seen_pixels as f64
        }
    }

    /// Whether enough is learned for the model to be used.
    pub fn ready(&self) -> bool {
        self.learned_pixels > 0 && self.learned_share() >= self.config.min_learned_share as f64
    }

    /// The learned background for the segmentation (0 where unknown) once [`Self::ready`].
    pub fn learned(&self) -> Option<Arc<Vec<f32>>> {
        self.ready().then(|| Arc::clone(&self.background))
    }

    /// Learns from one frame: `depth` in metres (0 or NaN: no reading), `person` the
    /// person's pixels (not learned, nor those within the margin), both row-major of the
    /// model's size. Errors when a size differs.
    pub fn update(&mut self, depth: &[f32], person: Option<&[bool]>) -> Result<()> {
        let n = self.width * self.height;
        ensure(depth.len() == n, "depth", || {
            format!(
                "has {} values, the background model {}x{} pixels",
                depth.len(),
                self.height,
                self.width
            )
        })?;
        if let Some(m) = person {
            ensure(m.len() == n, "mask", || {
                format!(
                    "has {} values, the background model {}x{} pixels",
                    m.len(),
                    self.height,
                    self.width
                )
            })?;
        }
        let mut grown = std::mem::take(&mut self.grown);
        match person {
            Some(m) => grow(m, self.width, self.height, self.config.margin, &mut grown),
            None => grown.fill(false),
        }
        let config = self.config;
        let background = Arc::make_mut(&mut self.background);
        let (seen_new, learned_new) = learn_pixels(
            depth,
            &grown,
            &mut self.seen,
            &mut self.modes,
            background,
            &config,
        );
        self.seen_pixels += seen_new;
        self.learned_pixels += learned_new;
        self.grown = grown;
        self.frames += 1;
        Ok(())
    }

    /// Forgets everything learned.
    pub fn clear(&mut self) {
        *self = BackgroundModel::new(self.width, self.height, self.config)
            .expect("the config was valid");
    }
}

/// Learns from one frame's readings (`person`: the pixels not to learn); returns how
/// many pixels had their first reading and how many were learned for the first time.
fn learn_pixels(
    depth: &[f32],
    person: &[bool],
    seen: &mut [bool],
    modes: &mut [[Mode; 2]],
    background: &mut [f32],
    config: &BackgroundModelConfig,
) -> (usize, usize) {
    let needed = config.frames.min(u16::MAX as usize) as u16;
    let mut seen_new = 0;
    let mut learned_new = 0;
    let pixels = depth
        .iter()
        .zip(person)
        .zip(seen.iter_mut())
        .zip(modes.iter_mut().zip(background.iter_mut()));
    for (((&z, &person), seen), ([mode, challenger], b)) in pixels {
        // Without a reading (0, negative or NaN) nothing is learned.
        if !(z > 0.0 && z.is_finite()) {
            continue;
        }
        seen_new += usize::from(!*seen);
        *seen = true;
        if person {
            continue;
        }
        if mode.count == 0 {
            *mode = Mode { depth: z, count: 1 };
        } else if mode.agrees(z, config) {
            mode.add(z);
            challenger.count = challenger.count.saturating_sub(1);
        } else if challenger.agrees(z, config) {
            challenger.add(z);
        } else if challenger.count == 0 || z > challenger.depth {
            // A farther reading takes the challenger's place at once.
            *challenger = Mode { depth: z, count: 1 };
        } else {
            challenger.count -= 1;
        }
        // A stable challenger wins when it is farther (the mode was something in
        // front of it that has gone) or when the mode never became stable.
        if challenger.count >= needed && (challenger.depth > mode.depth || mode.count < needed) {
            *mode = *challenger;
            *challenger = Mode::default();
        }
        if mode.count >= needed {
            if *b == 0.0 {
                learned_new += 1;
                *b = mode.depth;
            } else if mode.depth >= *b - config.tolerance_at(*b) {
                // Only a farther stable depth, or the same one refined, replaces it.
                *b = mode.depth;
            }
        }
    }
    (seen_new, learned_new)
}

/// `mask` grown by `margin` pixels in every direction (a square structuring element),
/// into `out`: each row holding mask pixels is grown along itself by ORs of shifted
/// copies, then ORed into the rows within the margin (rows without any are skipped).
fn grow(mask: &[bool], width: usize, height: usize, margin: usize, out: &mut [bool]) {
    out.fill(false);
    let mut row = vec![false; width];
    let m = margin.min(width.saturating_sub(1));
    for r in 0..height {
        let src = &mask[r * width..][..width];
        if !src.contains(&true) {
            continue;
        }
        row.copy_from_slice(src);
        for d in 1..=m {
            for (t, &v) in row[..width - d].iter_mut().zip(&src[d..]) {
                *t |= v;
            }
            for (t, &v) in row[d..].iter_mut().zip(&src[..width - d]) {
                *t |= v;
            }
        }
        for rr in r.saturating_sub(margin)..(r + margin + 1).min(height) {
            for (t, &v) in out[rr * width..][..width].iter_mut().zip(&row) {
                *t |= v;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Error;

    const W: usize = 80;
    const H: usize = 60;

    /// The empty scene: a wall 4 m away above row 30, a floor below it getting nearer
    /// toward the bottom; a few pixels without a reading (the sensor's holes).
    fn empty_scene() -> Vec<f32> {
        (0..W * H)
            .map(|i| {
                let (r, c) = (i / W, i % W);
                if r == 5 && c < 3 {
                    0.0
                } else if r < 30 {
                    4.0
                } else {
                    4.0 - 0.05 * (r - 30) as f32
                }
            })
            .collect()
    }

    /// A small deterministic noise in ±1 cm.
    fn noise(frame: usize, i: usize) -> f32 {
        let h = (frame as u64 * 0x9e37_79b9 + i as u64).wrapping_mul(0x2545_f491_4f6c_dd1d);
        ((h >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 0.02
    }

    /// The scene with a person (a block 2.5 m away, rows 15..50) covering columns
    /// `cols`; the person's mask.
    fn with_person(frame: usize, cols: std::ops::Range<usize>) -> (Vec<f32>, Vec<bool>) {
        let mut depth = empty_scene();
        let mut mask = vec![false; W * H];
        for (i, z) in depth.iter_mut().enumerate() {
            let (r, c) = (i / W, i % W);
            if (15..50).contains(&r) && cols.contains(&c) {
                *z = 2.5;
                mask[i] = true;
            }
            if *z > 0.0 {
                *z += noise(frame, i);
            }
        }
        (depth, mask)
    }

    fn model() -> BackgroundModel {
        BackgroundModel::new(W, H, BackgroundModelConfig::default()).unwrap()
    }

    #[test]
    fn a_person_moving_across_leaves_the_empty_scene_learned_behind() {
        let mut m = model();
        let truth = empty_scene();
        let config = *m.config();
        let tol = |z: f32| config.tolerance_at(z);
        // Columns 30..40 are covered in every frame; the person walks from 10..40 to
        // 30..60 over 20 frames, then stays there for 20 more.
        let cols = |f: usize| {
            let start = 10 + f.min(20);
            start..start + 30
        };
        let mut ready_at = None;
        for f in 0..40 {
            let (depth, mask) = with_person(f, cols(f));
            m.update(&depth, Some(&mask)).unwrap();
            if ready_at.is_none() && m.ready() {
                ready_at = Some(f);
            }
        }
        assert_eq!(m.frames(), 40);
        assert!(ready_at.is_some_and(|f| f < 10), "ready at {ready_at:?}");
        let bg = m.background();
        let margin = m.config().margin;
        // Rows and columns within the margin of the person in every frame.
        let rows = 15 - margin..50 + margin;
        let always = 30 - margin..40 + margin;
        let mut left_behind = 0;
        for (i, (&b, &t)) in bg.iter().zip(&truth).enumerate() {
            let (r, c) = (i / W, i % W);
            if t == 0.0 {
                assert_eq!(b, 0.0, "a pixel without readings is unknown ({r}, {c})");
            } else if rows.contains(&r) && always.contains(&c) {
                assert_eq!(b, 0.0, "never uncovered but learned ({r}, {c})");
            } else if (15..50).contains(&r) && (10..always.start).contains(&c) {
                // Covered at first, then left.
                assert!((b - t).abs() < tol(t), "({r}, {c}): {b} vs {t}");
                left_behind += 1;
            } else if !(rows.contains(&r) && (10 - margin..60 + margin).contains(&c)) {
                // Never covered: the mean of many frames, much closer than the noise.
                assert!((b - t).abs() < 0.01, "({r}, {c}): {b} vs {t}");
            }
        }
        assert_eq!(left_behind, 35 * (always.start - 10));
        // The person's current place is never learned as background.
        let (_, mask) = with_person(40, cols(40));
        for (i, &on) in mask.iter().enumerate() {
            assert!(!on || bg[i] == 0.0 || (bg[i] - truth[i]).abs() < tol(truth[i]));
        }
        assert!(m.ready() && m.learned().is_some());
    }

    #[test]
    fn a_person_standing_still_is_not_learned() {
        let mut m = model();
        for f in 0..200 {
            let (depth, mask) = with_person(f, 20..40);
            m.update(&depth, Some(&mask)).unwrap();
        }
        let (_, mask) = with_person(0, 20..40);
        assert!(mask
            .iter()
            .zip(m.background())
            .all(|(&on, &b)| !on || b == 0.0));
        // The rest of the scene is known.
        assert!(m.ready());
        assert!(m.learned_share() > 0.7, "{}", m.learned_share());
    }

    #[test]
    fn a_nearer_stable_object_never_replaces_the_learned_background() {
        // The empty scene first; then an unmasked object stands in front of the wall for
        // a long time, then leaves.
        let mut m = model();
        let truth = empty_scene();
        for f in 0..10 {
            let (depth, _) = with_person(f, 0..0);
            m.update(&depth, None).unwrap();
        }
        for f in 10..200 {
            let (depth, _) = with_person(f, 20..40);
            m.update(&depth, None).unwrap();
        }
        let i = 20 * W + 30;
        assert!((m.background()[i] - truth[i]).abs() < 0.05);
        // An object there from the start that leaves: the farther depth is learned.
        let mut m = model();
        for f in 0..30 {
            let (depth, _) = with_person(f, 20..40);
            m.update(&depth, None).unwrap();
        }
        assert!((m.background()[i] - 2.5).abs() < 0.05);
        for f in 30..39 {
            let (depth, _) = with_person(f, 0..0);
            m.update(&depth, None).unwrap();
        }
        assert!((m.background()[i] - truth[i]).abs() < 0.05);
    }

    #[test]
    fn a_passing_reading_is_not_learned_and_the_stable_depth_is() {
        // Single readings far behind (flying pixels) or in front do not disturb a pixel.
        let mut m = model();
        let i = 10 * W + 10;
        for f in 0..20 {
            let (mut depth, _) = with_person(f, 0..0);
            if f % 5 == 2 {
                depth[i] = 7.0;
            } else if f % 5 == 4 {
                depth[i] = 1.0;
            }
            m.update(&depth, None).unwrap();
        }
        assert!(
            (m.background()[i] - 4.0).abs() < 0.02,
            "{}",
            m.background()[i]
        );
    }

    #[test]
    fn the_model_is_not_used_before_enough_is_learned() {
        let config = BackgroundModelConfig {
            frames: 5,
            min_learned_share: 0.9,
            ..BackgroundModelConfig::default()
        };
        let mut m = BackgroundModel::new(W, H, config).unwrap();
        assert!(!m.ready() && m.learned().is_none());
        for f in 0..4 {
            let (depth, _) = with_person(f, 0..0);
            m.update(&depth, None).unwrap();
        }
        assert!(!m.ready(), "4 frames of 5");
        let (depth, _) = with_person(4, 0..0);
        m.update(&depth, None).unwrap();
        assert!(m.ready());
        // A person standing in a third of the image from the start keeps it unready.
        let mut m = BackgroundModel::new(W, H, config).unwrap();
        for f in 0..50 {
            let (depth, mask) = with_person(f, 10..40);
            m.update(&depth, Some(&mask)).unwrap();
        }
        assert!(!m.ready(), "{}", m.learned_share());
        m.clear();
        assert_eq!(m.frames(), 0);
        assert!(m.background().iter().all(|&b| b == 0.0));
    }

    #[test]
    fn hostile_settings_and_sizes_are_rejected_by_name() {
        let field = |c: BackgroundModelConfig| match c.validate() {
            Err(Error::InvalidArgument { name, .. }) => name,
            other => panic!("expected an error, got {other:?}"),
        };
        let d = BackgroundModelConfig::default();
        assert!(d.validate().is_ok());
        for (c, name) in [
            (
                BackgroundModelConfig {
                    tolerance: f32::NAN,
                    ..d
                },
                "background_model.tolerance",
            ),
            (
                BackgroundModelConfig {
                    tolerance: -0.1,
                    ..d
                },
                "background_model.tolerance",
            ),
            (
                BackgroundModelConfig {
                    tolerance_quadratic: f32::INFINITY,
                    ..d
                },
                "background_model.tolerance_quadratic",
            ),
            (
                BackgroundModelConfig { frames: 0, ..d },
                "background_model.frames",
            ),
            (
                BackgroundModelConfig {
                    frames: MAX_FRAMES + 1,
                    ..d
                },
                "background_model.frames",
            ),
            (
                BackgroundModelConfig {
                    min_learned_share: 1.5,
                    ..d
                },
                "background_model.min_learned_share",
            ),
            (
                BackgroundModelConfig {
                    min_learned_share: f32::NAN,
                    ..d
                },
                "background_model.min_learned_share",
            ),
            (
                BackgroundModelConfig {
                    margin: MAX_MARGIN + 1,
                    ..d
                },
                "background_model.margin",
            ),
        ] {
            assert_eq!(field(c), name);
            assert!(BackgroundModel::new(W, H, c).is_err());
        }
        let mut m = model();
        let err = m.update(&[1.0; 10], None).unwrap_err();
        assert!(err.to_string().contains("depth"), "{err}");
        let err = m.update(&vec![1.0; W * H], Some(&[true; 3])).unwrap_err();
        assert!(err.to_string().contains("mask"), "{err}");
        // NaN, infinite and negative readings are no readings.
        let mut depth = vec![f32::NAN; W * H];
        depth[0] = f32::INFINITY;
        depth[1] = -1.0;
        for _ in 0..20 {
            m.update(&depth, None).unwrap();
        }
        assert_eq!(m.learned_share(), 0.0);
        assert!(m.background().iter().all(|&b| b == 0.0));
    }

    #[test]
    fn growing_a_mask_covers_the_chessboard_margin() {
        let (w, h) = (9, 7);
        let mut mask = vec![false; w * h];
        mask[3 * w + 4] = true;
        let mut out = vec![false; w * h];
        grow(&mask, w, h, 2, &mut out);
        for r in 0..h {
            for c in 0..w {
                let inside = r.abs_diff(3) <= 2 && c.abs_diff(4) <= 2;
                assert_eq!(out[r * w + c], inside, "({r}, {c})");
            }
        }
        grow(&mask, w, h, 0, &mut out);
        assert_eq!(out, mask);
    }

    #[test]
    fn growing_matches_a_brute_force_dilation() {
        // Masks of scattered pixels, at the borders too, and margins beyond the size.
        let (w, h) = (13, 9);
        for seed in 0..40u64 {
            let mask: Vec<bool> = (0..w * h)
                .map(|i| noise(seed as usize, i) > 0.008)
                .collect();
            for margin in [0, 1, 2, 5, 20] {
                let mut out = vec![false; w * h];
                grow(&mask, w, h, margin, &mut out);
                for r in 0..h {
                    for c in 0..w {
                        let want = (0..w * h).any(|j| {
                            mask[j]
                                && (j / w).abs_diff(r) <= margin
                                && (j % w).abs_diff(c) <= margin
                        });
                        assert_eq!(
                            out[r * w + c],
                            want,
                            "seed {seed} margin {margin} ({r}, {c})"
                        );
                    }
                }
            }
        }
    }
}
