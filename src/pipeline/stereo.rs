//! Pose from a rectified stereo pair, the paper's own input: seed-growing stereo gives
//! the disparity, the disparity gives depth, and the depth goes through the estimator
//! or the tracker like a depth camera's frame.
//!
//! Depth from stereo differs from a depth camera's in three ways the pipeline accounts
//! for:
//! - **Fattening.** Window matching gives the background pixels along a silhouette the
//!   person's disparity; those matches are removed before the depth is formed
//!   ([`crate::stereo::fattening`]); with `matching.half_occlusion` (off by default:
//!   it also trims the left edge of every thin limb) so are the matches a nearer
//!   surface spreads into the half-occluded band on its left
//!   ([`crate::stereo::occlusion`]).
//! - **Noise grows as Z².** A disparity error of δ pixels is a depth error of
//!   Z²·δ/(f·B): at 4 m with a 0.12 m baseline and f = 570 px, a quarter of a metre per
//!   pixel. The segmentation's plane and background tolerances are widened to the depth
//!   that `disparity_tolerance` pixels span at each depth, so a floor matched within a
//!   pixel is still recognised as a floor. For a disparity error of `disparity_sigma`
//!   pixels ([`crate::fit::noise`]), the tracker's lost test allows for the discrepancy
//!   the noise adds (at 3 m, with f·B = 68 px·m and a quarter pixel, about 0.15 where
//!   the threshold is 0.5), and with `weigh_points` the fit weighs each point by how
//!   precisely its depth is known.
//! - **Video.** The previous frame's matches seed the next frame's growing (on a grid),
//!   so the person is matched from where it was even where random seeds miss it.
//!
//! The empty-scene pair is optional: when given, its depth is the background for
//! background subtraction; without it the person is segmented automatically.

use super::estimator::Estimator;
use super::result::PoseResult;
use super::tracker::Tracker;
use crate::camera::Camera;
use crate::error::{ensure, ensure_positive, Error, Result};
use crate::fit::{DepthNoise, FitConfig};
use crate::segment::SegmentConfig;
use crate::stereo::fattening::{remove_fattening, FatteningConfig};
use crate::stereo::occlusion::remove_half_occluded_for_window;
use crate::stereo::{depth_from_disparity, match_stereo_seeded, Seed, StereoConfig};
use std::time::Instant;

/// A rectified stereo rig whose left camera is the pipeline's camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoRig {
    /// Distance between the camera centres, metres.
    pub baseline: f64,
    /// The x-offset of the right principal point from the left one, pixels (as
    /// Middlebury's `doffs`; 0 for a pair rectified to a common principal point):
    /// Z = B·f / (d + doffs).
    pub doffs: f64,
}

impl StereoRig {
    pub fn validate(&self) -> Result<()> {
        ensure_positive(self.baseline, "baseline")?;
        ensure(self.doffs.is_finite(), "doffs", || {
            format!("must be finite, got {}", self.doffs)
        })
    }
}

/// Settings of the stereo stage.
#[derive(Debug, Clone, PartialEq)]
pub struct StereoDepthConfig {
    /// The matcher's settings; the default leaves `half_occlusion` off (module docs).
    pub matching: StereoConfig,
    /// Removal of foreground fattening (None: keep every match).
    pub fattening: Option<FatteningConfig>,
    /// Disparity error (pixels) the segmentation tolerates on a plane or against the
    /// background: the depth tolerances are widened to Z²·δ/(f·B) where that is larger.
    pub disparity_tolerance: f32,
    /// In a video, the previous frame's matches seed the next frame's on a grid of this
    /// spacing in pixels (0: no seeds from the previous frame).
    pub seed_spacing: usize,
    /// The matched disparity's standard deviation (pixels): the matcher's subpixel
    /// disparities on textured surfaces are within about a quarter pixel (RMS) of the
    /// truth (the default). The depth noise it implies is what the tracker's lost test
    /// allows for and, with `weigh_points`, what the fit weighs points by. 0: no noise
    /// model.
    pub disparity_sigma: f32,
    /// Weigh each point's data terms by 1/(σ² + σ_Z²) ([`crate::fit::noise`]). Off by
    /// default: the body model's own misfit (`sigma`) is of the order of the depth
    /// noise, and weighing the far side of the body down costs the from-scratch search
    /// more than it gains (see the benchmark docs).
    pub weigh_points: bool,
}

impl Default for StereoDepthConfig {
    fn default() -> Self {
        let matching = StereoConfig {
            half_occlusion: false,
            ..StereoConfig::default()
        };
        StereoDepthConfig {
            fattening: Some(FatteningConfig::for_window(matching.window)),
            matching,
            disparity_tolerance: 1.0,
            seed_spacing: 8,
            disparity_sigma: 0.25,
            weigh_points: false,
        }
    }
}

impl StereoDepthConfig {
    pub fn validate(&self) -> Result<()> {
        self.matching.validate()?;
        if let Some(f) = &self.fattening {
            f.validate()?;
        }
        ensure(
            self.disparity_tolerance.is_finite() && self.disparity_tolerance >= 0.0,
            "disparity_tolerance",
            || format!("must be finite and >= 0, got {}", self.disparity_tolerance),
        )?;
        ensure(
            self.disparity_sigma.is_finite() && self.disparity_sigma >= 0.0,
            "disparity_sigma",
            || format!("must be finite and >= 0, got {}", self.disparity_sigma),
        )
    }
}

/// A pair's disparity (pixels, NaN unmatched) and depth (metres, 0 = none), the left
/// image's size, and the time the stage took.
#[derive(Debug, Clone)]
pub struct StereoFrame {
    pub disparity: Vec<f32>,
    pub depth: Vec<f32>,
    /// Milliseconds of matching, fattening removal and conversion.
    pub ms: f64,
}

/// Depth from rectified pairs of one rig, remembering a video's last disparity.
#[derive(Debug, Clone)]
pub struct StereoDepth {
    camera: Camera,
    rig: StereoRig,
    config: StereoDepthConfig,
    previous: Option<Vec<f32>>,
}

impl StereoDepth {
    pub fn new(camera: &Camera, rig: StereoRig, config: StereoDepthConfig) -> Result<Self> {
        rig.validate()?;
        config.validate()?;
        // Depth Z = f·B/d: the noise and tolerances divide by f·B.
        let focal_baseline = camera.fx * rig.baseline;
        ensure(
            focal_baseline.is_normal() && (1.0 / focal_baseline).is_finite(),
            "baseline",
            || {
                format!(
                    "{} m times the focal length {} px is out of range",
                    rig.baseline, camera.fx
                )
            },
        )?;
        Ok(StereoDepth {
            camera: *camera,
            rig,
            config,
            previous: None,
        })
    }

    pub fn rig(&self) -> &StereoRig {
        &self.rig
    }

    pub fn config(&self) -> &StereoDepthConfig {
        &self.config
    }

    /// Forgets the previous frame's disparity.
    pub fn reset(&mut self) {
        self.previous = None;
    }

    /// `base` with the plane and background tolerances widened to this rig's depth
    /// noise (module docs): the quadratic coefficients become at least δ/(f·B). Pieces
    /// meeting the body across a seam without matches are kept only from
    /// `min_component` pixels: mismatches leave small islands beside the body.
    pub fn segment_config(&self, base: &SegmentConfig) -> SegmentConfig {
        let quadratic =
            (self.config.disparity_tolerance as f64 / (self.camera.fx * self.rig.baseline)) as f32;
        let mut c = *base;
        c.planes.tolerance_quadratic = c.planes.tolerance_quadratic.max(quadratic);
        c.foreground.bg_tolerance_quadratic = c.foreground.bg_tolerance_quadratic.max(quadratic);
        c.foreground.min_joined_piece = c
            .foreground
            .min_joined_piece
            .max(c.foreground.min_component);
        c
    }

    /// This rig's depth noise, for a disparity error of `disparity_sigma` pixels (None
    /// when that is 0).
    pub fn depth_noise(&self) -> Option<DepthNoise> {
        (self.config.disparity_sigma > 0.0).then_some(DepthNoise {
            focal_baseline: self.camera.fx * self.rig.baseline,
            disparity_sigma: self.config.disparity_sigma as f64,
        })
    }

    /// `base` weighing points by this rig's depth noise (module docs) when
    /// `weigh_points`, unless it has a noise model already.
    pub fn fit_config(&self, base: &FitConfig) -> FitConfig {
        let mut c = *base;
        if c.depth_noise.is_none() && self.config.weigh_points {
            c.depth_noise = self.depth_noise();
        }
        c
    }

    /// The disparity and depth of a gray pair (row-major, the camera's size, any
    /// intensity scale). With `video`, the previous pair's matches seed this one and
    /// this one's are kept for the next.
    pub fn frame(&mut self, left: &[f32], right: &[f32], video: bool) -> Result<StereoFrame> {
        let start = Instant::now();
        let (h, w) = (self.camera.height, self.camera.width);
        for (img, name) in [(left, "left"), (right, "right")] {
            ensure(img.len() == h * w, name, || {
                format!(
                    "has {} pixels, the camera {}x{} has {}",
                    img.len(),
                    w,
                    h,
                    h * w
                )
            })?;
        }
        let seeds = match (&self.previous, video) {
            (Some(prev), true) => grid_seeds(prev, h, w, self.config.seed_spacing),
            _ => Vec::new(),
        };
        // Both filters judge the matcher's own output: the half-occlusion filter's
        // removals must not widen the unmatched regions the fattening removal treats
        // as a far surface (the left edge against an unmatched wall would lose its
        // band twice).
        let matching = StereoConfig {
            half_occlusion: false,
            ..self.config.matching.clone()
        };
        let matched = match_stereo_seeded(left, right, h, w, &matching, &seeds)?;
        let occluded = if self.config.matching.half_occlusion {
            let (mut occluded, mut confidence) = (matched.disparity.clone(), matched.confidence);
            let window = self.config.matching.window;
            remove_half_occluded_for_window(&mut occluded, &mut confidence, w, window);
            Some(occluded)
        } else {
            None
        };
        let mut disparity = matched.disparity;
        if let Some(f) = &self.config.fattening {
            remove_fattening(&mut disparity, h, w, f)?;
        }
        for (d, o) in disparity.iter_mut().zip(occluded.iter().flatten()) {
            if o.is_nan() {
                *d = f32::NAN;
            }
        }
        let depth = depth_from_disparity(
            &disparity,
            self.camera.fx,
            self.rig.baseline,
            self.rig.doffs,
        )?;
        if let Some(k) = depth.iter().position(|z| !z.is_finite()) {
            return Err(Error::invalid(
                "doffs",
                format!(
                    "the depth at row {}, column {} is beyond the float32 range",
                    k / w,
                    k % w
                ),
            ));
        }
        if video {
            self.previous = Some(disparity.clone());
        }
        Ok(StereoFrame {
            disparity,
            depth,
            ms: start.elapsed().as_secs_f64() * 1e3,
        })
    }
}

/// Seeds at every `spacing`-th pixel of a previous disparity where it has a match.
fn grid_seeds(disparity: &[f32], height: usize, width: usize, spacing: usize) -> Vec<Seed> {
    if spacing == 0 {
        return Vec::new();
    }
    let mut seeds = Vec::new();
    for y in (spacing / 2..height).step_by(spacing) {
        for x in (spacing / 2..width).step_by(spacing) {
            let d = disparity[y * width + x];
            if d.is_finite() && d >= 0.0 && (d.round() as usize) <= x {
                seeds.push(Seed {
                    x,
                    y,
                    d: d.round() as usize,
                });
            }
        }
    }
    seeds
}

/// What a stereo pipeline does with each pair's depth.
#[derive(Debug, Clone)]
enum Stage {
    /// Each pair from scratch.
    Estimate(Box<Estimator>),
    /// A video.
    Track(Box<Tracker>),
}

/// Pose from rectified pairs: one from scratch per pair, or tracked through a video.
#[derive(Debug, Clone)]
pub struct StereoPipeline {
    stereo: StereoDepth,
    stage: Stage,
    /// The last pair's disparity.
    disparity: Option<Vec<f32>>,
}

/// A stereo pipeline's pose of a pair and the pair's disparity.
#[derive(Debug, Clone)]
pub struct StereoPose {
    /// The pose; its timings begin with the stereo stage (`stereo`).
    pub result: PoseResult,
    pub disparity: Vec<f32>,
}

impl StereoPipeline {
    /// A pipeline for pairs of `stereo`'s rig, estimating each pair from scratch with
    /// `estimator`, or tracking with `tracker`. The estimator's segmentation settings
    /// should come from [`StereoDepth::segment_config`]; it is told the rig's depth
    /// noise.
    pub fn estimating(stereo: StereoDepth, mut estimator: Estimator) -> Self {
        estimator.set_depth_noise(stereo.depth_noise());
        StereoPipeline {
            stereo,
            stage: Stage::Estimate(Box::new(estimator)),
            disparity: None,
        }
    }

    /// The tracker's lost test and search are told the rig's depth noise.
    pub fn tracking(stereo: StereoDepth, mut tracker: Tracker) -> Self {
        tracker.set_depth_noise(stereo.depth_noise());
        StereoPipeline {
            stereo,
            stage: Stage::Track(Box::new(tracker)),
            disparity: None,
        }
    }

    pub fn stereo(&self) -> &StereoDepth {
        &self.stereo
    }

    pub fn estimator(&self) -> &Estimator {
        match &self.stage {
            Stage::Estimate(e) => e,
            Stage::Track(t) => t.estimator(),
        }
    }

    /// The tracker, when the pipeline tracks.
    pub fn tracker(&self) -> Option<&Tracker> {
        match &self.stage {
            Stage::Estimate(_) => None,
            Stage::Track(t) => Some(t),
        }
    }

    /// The last pair's disparity (None before the first).
    pub fn disparity(&self) -> Option<&[f32]> {
        self.disparity.as_deref()
    }

    /// Forgets the video: the track (and the shape with `shape`) and the last disparity.
    pub fn reset(&mut self, shape: bool) {
        self.stereo.reset();
        if let Stage::Track(t) = &mut self.stage {
            t.reset(shape);
        }
    }

    /// The pose of the next pair (gray, row-major, the camera's size; `mask` the
    /// person's pixels in the left image, else segmented). A tracking pipeline forgets
    /// its last disparity when a pair fails, like the track.
    pub fn update(
        &mut self,
        left: &[f32],
        right: &[f32],
        mask: Option<&[bool]>,
    ) -> Result<StereoPose> {
        let video = matches!(self.stage, Stage::Track(_));
        let frame = self.stereo.frame(left, right, video)?;
        let result = match &mut self.stage {
            Stage::Estimate(e) => e.estimate(&frame.depth, mask),
            Stage::Track(t) => t.update(&frame.depth, mask),
        };
        let mut result = match result {
            Ok(r) => r,
            Err(e) => {
                self.stereo.reset();
                self.disparity = Some(frame.disparity);
                return Err(e);
            }
        };
        result.timings.stages.insert(0, ("stereo", frame.ms));
        result.timings.total += frame.ms;
        self.disparity = Some(frame.disparity.clone());
        Ok(StereoPose {
            result,
            disparity: frame.disparity,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth pseudo-random texture value at real position (u, v).
    fn texture(u: f32, v: f32, seed: f32) -> f32 {
        (0..6)
            .map(|k| {
                let k = k as f32;
                let (a, b) = ((1.3 + k) * seed, 0.7 * k + seed);
                (0.45 * u * a.cos() + 0.38 * v * a.sin() + b).sin() * (1.0 + 0.2 * k)
            })
            .sum()
    }

    /// A textured block (disparity 16) in front of a wall (disparity 6) whose left
    /// part is plain: the block's left edge has a half-occluded band, and its
    /// silhouette meets an unmatched wall on the left side of the image.
    fn pair(w: usize, h: usize) -> (Vec<f32>, Vec<f32>) {
        let (near, far, block) = (16.0f32, 6.0f32, 60..90);
        let wall = |x: f32, y: f32| if x < 40.0 { 0.0 } else { texture(x, y, 1.0) };
        let mut left = vec![0.0; w * h];
        let mut right = vec![0.0; w * h];
        for y in 0..h {
            for x in 0..w {
                let (xf, yf) = (x as f32, y as f32);
                left[y * w + x] = if block.contains(&x) {
                    texture(xf, yf, 2.0)
                } else {
                    wall(xf, yf)
                };
                // Right pixel x shows the block where x + near lies on it, else the wall.
                let on_block = block.contains(&((xf + near) as usize));
                right[y * w + x] = if on_block {
                    texture(xf + near, yf, 2.0)
                } else {
                    wall(xf + far, yf)
                };
            }
        }
        (left, right)
    }

    #[test]
    fn the_segmentation_follows_the_rigs_noise_and_keeps_only_large_joined_pieces() {
        // f·B = 100 × 0.1 = 10 px·m: one pixel of disparity tolerance spans 0.1·z² m.
        let camera = Camera::new(100.0, 100.0, 70.0, 20.0, 140, 40).unwrap();
        let rig = StereoRig {
            baseline: 0.1,
            doffs: 0.0,
        };
        let config = StereoDepthConfig {
            disparity_tolerance: 1.0,
            ..StereoDepthConfig::default()
        };
        let stereo = StereoDepth::new(&camera, rig, config).unwrap();
        let base = SegmentConfig::default();
        let c = stereo.segment_config(&base);
        assert!((c.foreground.bg_tolerance_quadratic - 0.1).abs() < 1e-6);
        assert!((c.planes.tolerance_quadratic - 0.1).abs() < 1e-6);
        assert_eq!(base.foreground.min_joined_piece, 0);
        assert_eq!(c.foreground.min_joined_piece, base.foreground.min_component);
    }

    #[test]
    fn both_filters_judge_the_matchers_own_output() {
        let (w, h) = (140, 40);
        let camera = Camera::new(100.0, 100.0, 70.0, 20.0, w, h).unwrap();
        let rig = StereoRig {
            baseline: 0.1,
            doffs: 0.0,
        };
        let (left, right) = pair(w, h);
        let mut config = StereoDepthConfig::default();
        config.matching.half_occlusion = true;
        let mut stereo = StereoDepth::new(&camera, rig, config.clone()).unwrap();
        let got = stereo.frame(&left, &right, false).unwrap().disparity;
        // The matcher's output and each filter on it alone.
        let plain = StereoConfig {
            half_occlusion: false,
            ..config.matching.clone()
        };
        let raw = match_stereo_seeded(&left, &right, h, w, &plain, &[]).unwrap();
        let mut fattening = raw.disparity.clone();
        let f = config.fattening.unwrap();
        remove_fattening(&mut fattening, h, w, &f).unwrap();
        let (mut occluded, mut confidence) = (raw.disparity.clone(), raw.confidence.clone());
        let window = config.matching.window;
        let removed = remove_half_occluded_for_window(&mut occluded, &mut confidence, w, window);
        assert!(
            removed > 0,
            "the block's left edge has a half-occluded band"
        );
        for k in 0..w * h {
            let kept = !fattening[k].is_nan() && !occluded[k].is_nan();
            assert_eq!(!got[k].is_nan(), kept, "pixel {k}");
        }
        // One after the other, the fattening removal would treat the half-occlusion
        // filter's removals as part of a large gap and remove more.
        let mut sequential = occluded.clone();
        remove_fattening(&mut sequential, h, w, &f).unwrap();
        let count = |d: &[f32]| d.iter().filter(|v| !v.is_nan()).count();
        assert!(
            count(&sequential) < count(&got),
            "{} {}",
            count(&sequential),
            count(&got)
        );
    }
}
