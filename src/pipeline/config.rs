//! Settings of the estimator and the tracker.

use crate::error::{ensure, Result};
use crate::fit::FitConfig;
use crate::segment::{BackgroundModelConfig, SegmentConfig};

/// Settings of [`super::Estimator`] and [`super::Tracker`].
#[derive(Debug, Clone, PartialEq)]
pub struct PipelineConfig {
    /// Template candidates taken from the search when estimating from scratch; each also
    /// gives its left/right-swapped and mirrored-view hypotheses.
    pub candidates: usize,
    /// Hypotheses (after ranking all by their depth discrepancy) refined by EM; the
    /// best-ranked of each of the search's first views is always among them
    /// ([`super::hypotheses::refined_hypotheses`]).
    pub hypotheses: usize,
    /// Each template hypothesis is also tried turned around (seen from behind).
    pub back_views: bool,
    /// The template search also runs on the view that makes a lying or leaning body
    /// upright, and upside down.
    pub any_roll: bool,
    /// From scratch, the search's best fit also tries each limb in the poses of
    /// [`super::limbs`] (arms overhead, kicks, …), kept where they explain the depth
    /// better. (A tracked body keeps its limbs: its motion tells them better.)
    pub limb_poses: bool,
    /// EM iterations of each hypothesis before choosing: one brief EM per hypothesis,
    /// from the hypothesis or from its copy moved onto the observed body, whichever
    /// explains the depth better.
    pub candidate_iterations: usize,
    /// The best this many candidate fits are refined fully, in parallel, and the best of
    /// those kept.
    pub finals: usize,
    /// EM iterations of each final, the candidate iterations included (None: the fit
    /// settings' `max_iterations`).
    pub final_iterations: Option<usize>,
    /// Pixel stride of the brief candidate fits.
    pub candidate_stride: usize,
    /// Pixel stride of the finals' continued EM; the final labels cover every pixel.
    pub final_stride: usize,
    /// Tracking: weight of the prior toward the predicted pose.
    pub prior_weight: f64,
    /// Tracking: EM iterations per tracked frame.
    pub track_iterations: usize,
    /// Tracking: pixel stride of a tracked frame's EM.
    pub track_stride: usize,
    /// Tracking: share of the previous velocity carried into the prediction.
    pub velocity_damping: f64,
    /// Tracking: a frame is lost when fewer than this share of the foreground points are
    /// explained by the body, ...
    pub min_inlier_share: f64,
    /// ... or its depth discrepancy exceeds this many times the running median of the
    /// track's recent ones, ...
    pub lost_ratio: f64,
    /// ... or this absolute value (raised by what the sensor's noise adds, when it is
    /// known: see [`super::Estimator::set_depth_noise`]). A search whose best body
    /// explains the depth worse than this also runs the wide search (every eighth of a
    /// turn about the optical axis; with `any_roll`).
    pub lost_discrepancy: f64,
    /// Tracking: every this many frames the template search runs again and the track
    /// switches when a hypothesis explains the depth clearly better (0 = never: the
    /// search runs only when the track is lost).
    pub recheck_every: usize,
    /// ... with this many template hypotheses besides the tracked pose and its
    /// swapped-limbs pose.
    pub recheck_hypotheses: usize,
    /// Tracking: template hypotheses refined when the track is lost; when the best fit
    /// still explains the depth badly, the search runs again with `hypotheses`.
    pub lost_hypotheses: usize,
    /// "Clearly better": a lower discrepancy by at least this share. From scratch, the
    /// wide search's and the size end's fits replace the first by the same margin, and
    /// on a lost frame a re-initialised limb replaces the tracked one by it too.
    pub switch_margin: f64,
    /// Weight of the rest-pose term added to the depth discrepancy wherever poses
    /// compete: `pose_prior_weight` × Σ θ² over the 14 limb angles (radians; 0 is the
    /// rest pose). Where the depth cannot tell where a limb is (hidden behind the
    /// torso), it prefers the ordinary pose.
    pub pose_prior_weight: f64,
    /// Weight (per metre) of the arm-through-trunk term added to the depth discrepancy
    /// wherever poses compete: how far the arms' axes pass into the torso and pelvis
    /// beyond a limb radius ([`crate::body::BodyModel::arm_trunk_penetration`]). An arm
    /// hidden inside the trunk contradicts no pixel and saves its rest-pose penalty;
    /// this charges the pose no body takes (0 = never).
    pub penetration_weight: f64,
    /// From scratch, when the subject's shape is not given, the best fit is also
    /// refitted with the body scaled by 1 ± k·`size_step` up to ± `size_range`, and the
    /// size explaining the depth best is kept ([`super::size`]; 0 = never). A result
    /// still explained badly is searched again with the body at the end of the range
    /// the size search leaned toward. A tracker does so on its first frame and
    /// calibrates the shape from there.
    pub size_range: f64,
    /// ... in steps of this share of the model's size.
    pub size_step: f64,
    /// The fits' settings.
    pub fit: FitConfig,
    /// Shape calibration: the body shape is fitted once to this many usable frames and
    /// kept (0 = never).
    pub calibration_frames: usize,
    /// ... taking every this many usable frames.
    pub calibration_every: usize,
    /// ... with this weight of the prior toward the starting shape.
    pub calibration_prior_weight: f64,
    /// ... and at most this many rounds.
    pub calibration_rounds: usize,
    /// Person segmentation.
    pub segment: SegmentConfig,
    /// Tracking without a background frame: learn the scene's static background over
    /// the frames ([`crate::segment::BackgroundModel`]) and, once enough of it is known,
    /// segment the person as what lies in front of it, the support-plane test deciding
    /// the pixels not yet learned.
    pub learn_background: bool,
    /// ... with these settings.
    pub background_model: BackgroundModelConfig,
    /// The working focal length (pixels): larger images are reduced by the whole factor
    /// nearest `focal / working_focal`, so that every sensor is processed at about the
    /// resolution the pipeline is built for (a 320×240 Kinect-like image). Results
    /// come back in the input's pixel grid and camera frame.
    pub working_focal: f64,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        PipelineConfig {
            candidates: 4,
            hypotheses: 20,
            back_views: true,
            limb_poses: true,
            any_roll: true,
            candidate_iterations: 2,
            finals: 5,
            final_iterations: Some(10),
            candidate_stride: 2,
            final_stride: 2,
            prior_weight: 100.0,
            track_iterations: 4,
            track_stride: 2,
            velocity_damping: 0.5,
            min_inlier_share: 0.75,
            lost_ratio: 1.6,
            lost_discrepancy: 0.5,
            recheck_every: 0,
            recheck_hypotheses: 4,
            lost_hypotheses: 8,
            switch_margin: 0.05,
            pose_prior_weight: 0.005,
            penetration_weight: 0.3,
            size_range: 0.15,
            size_step: 0.05,
            fit: FitConfig::default(),
            calibration_frames: 8,
            calibration_every: 1,
            calibration_prior_weight: 1e5,
            calibration_rounds: 3,
            segment: SegmentConfig::default(),
            learn_background: false,
            background_model: BackgroundModelConfig::default(),
            working_focal: 300.0,
        }
    }
}

/// The template search returns at most this many candidates.
pub const MAX_CANDIDATES: usize = 768;

impl PipelineConfig {
    /// Checks every field; the error names the first nonsensical one.
    pub fn validate(&self) -> Result<()> {
        let at_least = |v: usize, low: usize, name: &str| {
            ensure(v >= low, name, || {
                format!("expected an integer >= {low}, got {v}")
            })
        };
        at_least(self.candidates, 1, "candidates")?;
        ensure(self.candidates <= MAX_CANDIDATES, "candidates", || {
            format!("expected 1..{MAX_CANDIDATES}, got {}", self.candidates)
        })?;
        at_least(self.finals, 1, "finals")?;
        at_least(self.candidate_iterations, 1, "candidate_iterations")?;
        if let Some(n) = self.final_iterations {
            at_least(n, 1, "final_iterations")?;
        }
        at_least(self.track_iterations, 1, "track_iterations")?;
        for (v, name) in [
            (self.track_stride, "track_stride"),
            (self.candidate_stride, "candidate_stride"),
            (self.final_stride, "final_stride"),
        ] {
            ensure((1..=crate::fit::MAX_STRIDE).contains(&v), name, || {
                format!("expected 1..{}, got {v}", crate::fit::MAX_STRIDE)
            })?;
        }
        at_least(self.recheck_hypotheses, 1, "recheck_hypotheses")?;
        at_least(self.lost_hypotheses, 1, "lost_hypotheses")?;
        at_least(self.calibration_every, 1, "calibration_every")?;
        at_least(self.calibration_rounds, 1, "calibration_rounds")?;
        let real = |v: f64, low: f64, high: f64, inf: bool, name: &str| {
            let ok = (v.is_finite() || (inf && v == f64::INFINITY)) && v >= low && v <= high;
            ensure(ok, name, || {
                let what = if inf {
                    "number (or inf)"
                } else {
                    "finite number"
                };
                format!("expected a {what} in [{low}, {high}], got {v}")
            })
        };
        real(self.prior_weight, 0.0, f64::INFINITY, false, "prior_weight")?;
        real(self.velocity_damping, 0.0, 1.0, false, "velocity_damping")?;
        real(self.min_inlier_share, 0.0, 1.0, false, "min_inlier_share")?;
        real(self.lost_ratio, 0.0, f64::INFINITY, true, "lost_ratio")?;
        real(
            self.lost_discrepancy,
            0.0,
            f64::INFINITY,
            true,
            "lost_discrepancy",
        )?;
        real(self.switch_margin, 0.0, 1.0, false, "switch_margin")?;
        real(
            self.pose_prior_weight,
            0.0,
            f64::INFINITY,
            false,
            "pose_prior_weight",
        )?;
        real(
            self.penetration_weight,
            0.0,
            f64::INFINITY,
            false,
            "penetration_weight",
        )?;
        real(
            self.calibration_prior_weight,
            0.0,
            f64::INFINITY,
            false,
            "calibration_prior_weight",
        )?;
        real(self.size_range, 0.0, 0.5, false, "size_range")?;
        real(self.size_step, 0.01, 0.5, false, "size_step")?;
        real(self.working_focal, 1.0, 1e6, false, "working_focal")?;
        self.fit.validate()?;
        self.background_model.validate()?;
        self.segment.validate()
    }

    /// The settings of one short EM (a tracked frame's budget) from a pose already on
    /// the body, as the limb-pose and size refits run it: no recentred or swapped
    /// starts (the pose is on the body already), labels of the EM's pixels only.
    pub(crate) fn short_refit(&self) -> FitConfig {
        let mut f = self.fit_with(Some(self.track_iterations), self.final_stride, Some(false));
        f.recentred_start = false;
        f.swapped_limb_starts = false;
        f
    }

    /// The fit settings with another iteration limit, stride and full-pixel labelling.
    pub(crate) fn fit_with(
        &self,
        iterations: Option<usize>,
        stride: usize,
        label_all_pixels: Option<bool>,
    ) -> FitConfig {
        let mut f = self.fit;
        if let Some(n) = iterations {
            f.em.max_iterations = n;
        }
        f.stride = stride;
        if let Some(l) = label_all_pixels {
            f.label_all_pixels = l;
        }
        f
    }
}
