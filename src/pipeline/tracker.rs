//! Pose through a depth video: each frame starts from the previous pose.
//!
//! A tracked frame starts from the previous pose extrapolated by a damped
//! constant-velocity model, with a prior toward that prediction. The track is lost when
//! the fitted body explains too little of the person or the depth much worse than
//! lately; a lost frame runs the template search (with the tracked pose and its
//! readings with left and right exchanged — whole body, legs only, arms only — among
//! the starts) and keeps its best. Its search refits `lost_hypotheses` templates; when
//! its best still explains the depth badly, the frame may be a cut to an unrelated
//! scene, and the search runs again with as many as from scratch (`hypotheses`). The
//! best is then turned as a fit from scratch is ([`super::turns`]): the half turn and
//! the left/right exchanges, and every eighth of a turn when it explains the depth
//! badly. A lost frame's body that still draws a limb off the person has that limb
//! re-initialised ([`super::lost_limbs`]). With `recheck_every` set, the search also
//! runs every that many tracked frames, and the track switches when a hypothesis
//! explains the depth clearly better. A sensor whose depth noise is known
//! ([`Tracker::set_depth_noise`], as the stereo pipeline's) raises the absolute lost
//! threshold by as much as its noise raises the discrepancy of a body that fits as well
//! as the model can.
//!
//! **Size and shape.** Unless told the shape, the tracker finds the body's size on its
//! first frame ([`super::size`]). A size found on a frame it explains badly is
//! provisional: a later frame still explained badly (the 2nd, 3rd, 5th, 9th, ...: a few
//! searches, not one a frame) is read again from scratch with the size searched, and a
//! reading that explains it well and ranks better replaces the track and its size. It
//! then collects usable frames (any but a track's first whose fit explains enough of
//! the person) and, once it has enough, fits the body shape to them all together
//! ([`crate::fit::fit_shape`]), starting from the sized body; it tracks with that shape
//! from then on. A calibration that fails leaves the shape as it was and is not
//! retried.
//!
//! **Learned background.** With `learn_background` and no background frame, every frame
//! whose fit explains the person teaches a [`BackgroundModel`] the scene's static depth
//! outside the person's mask; once it is reliable, the next frames' segmentation uses it
//! ([`crate::segment::Method::Learned`]). It survives `reset` (the same scene).

use super::estimator::{Estimator, Fitted, Frame};
use super::hypotheses::swap_limbs;
use super::result::{Clock, PoseResult, Source};
use crate::body::rotation::rotation_vector;
use crate::body::{param, root_rotation, BodyModel, Pose, NUM_SHAPE_FACTORS};
use crate::error::{Error, Result};
use crate::fit::start::limbs_swapped;
use crate::fit::{fit_shape, DepthNoise, PosePrior, ShapeConfig, ShapeFrame, ShapeResult};
use crate::segment::{BackgroundModel, SegmentHint};
use nalgebra::Rotation3;
use std::collections::VecDeque;
use std::time::Instant;

/// Recent discrepancies kept for the lost-track test.
const RECENT: usize = 15;
/// The lost-track test compares with the median once this many are known.
const RECENT_MIN: usize = 3;

/// The motion state of a track.
#[derive(Debug, Clone, Default)]
struct Track {
    previous: Option<Pose>,
    before: Option<Pose>,
    recent: VecDeque<f64>,
    since_check: usize,
    hint: Option<SegmentHint>,
}

/// What the shape calibration has collected and found.
#[derive(Debug, Clone, Default)]
pub struct Calibration {
    /// Frames kept for it: depth and mask at the working resolution, pose.
    buffer: Vec<(Vec<f32>, Vec<bool>, Pose)>,
    seen: usize,
    /// The fitted shape, when it ran and succeeded.
    pub result: Option<ShapeResult>,
    /// Why it failed, when it did.
    pub error: Option<String>,
    /// The number of frames `update` had been given when it ran.
    pub frame: Option<usize>,
}

/// Pose through a depth video (see the module docs).
#[derive(Debug, Clone)]
pub struct Tracker {
    estimator: Estimator,
    base_model: BodyModel,
    calibrate: bool,
    /// The body's size relative to the base model, once found (on the first frame).
    size: Option<f64>,
    /// The size was found on a frame it explains badly: see [`Tracker::resized`].
    size_provisional: bool,
    track: Track,
    calibration: Calibration,
    frames: usize,
    /// Frames whose track was lost.
    pub lost_frames: usize,
    /// Frames where the track switched to a search's result or re-initialised a limb.
    pub switches: usize,
    /// The learned background, when it learns one.
    background: Option<BackgroundModel>,
}

impl Tracker {
    /// A tracker over `estimator`'s camera and settings. `calibrate`: fit the body shape
    /// over the first frames (when `config.calibration_frames > 0`).
    pub fn new(estimator: Estimator, calibrate: bool) -> Self {
        let base_model = estimator.model().clone();
        let cfg = estimator.config();
        let working = &estimator.resolution().working;
        let background = (cfg.learn_background && !estimator.has_background()).then(|| {
            BackgroundModel::new(working.width, working.height, cfg.background_model)
                .expect("validated with the estimator's config")
        });
        Tracker {
            estimator,
            base_model,
            calibrate,
            size: None,
            size_provisional: false,
            track: Track::default(),
            calibration: Calibration::default(),
            frames: 0,
            lost_frames: 0,
            switches: 0,
            background,
        }
    }

    /// Tells the lost test and the search the depth sensor's noise (see
    /// [`Estimator::set_depth_noise`]).
    pub fn set_depth_noise(&mut self, noise: Option<DepthNoise>) {
        self.estimator.set_depth_noise(noise);
    }

    pub fn estimator(&self) -> &Estimator {
        &self.estimator
    }

    /// The model the tracker started with.
    pub fn base_model(&self) -> &BodyModel {
        &self.base_model
    }

    /// The model it tracks with (the calibrated one once calibrated).
    pub fn model(&self) -> &BodyModel {
        self.estimator.model()
    }

    pub fn calibration(&self) -> &Calibration {
        &self.calibration
    }

    /// Whether the tracker is still collecting frames to calibrate the shape.
    pub fn calibrating(&self) -> bool {
        self.calibrate
            && self.estimator.config().calibration_frames > 0
            && self.calibration.result.is_none()
            && self.calibration.error.is_none()
    }

    /// The calibrated shape factors relative to the base model (None before).
    pub fn shape_factors(&self) -> Option<[f64; NUM_SHAPE_FACTORS]> {
        let size = self.size.unwrap_or(1.0);
        self.calibration
            .result
            .as_ref()
            .map(|r| r.factors.map(|f| f * size))
    }

    /// The body's size relative to the base model found on the first frame (None
    /// before, or when the size is not searched).
    pub fn size(&self) -> Option<f64> {
        self.size
    }

    /// Forgets the track. The calibrated shape is kept (the same subject) unless
    /// `shape`: then the starting model is restored and calibrated again.
    pub fn reset(&mut self, shape: bool) {
        self.track = Track::default();
        self.lost_frames = 0;
        self.switches = 0;
        if shape {
            self.calibration = Calibration::default();
            self.estimator.set_model(self.base_model.clone());
            self.size = None;
            self.size_provisional = false;
            self.frames = 0;
        }
    }

    /// Starts the track from a known pose: the next update refines it instead of
    /// searching the templates.
    pub fn start_from(&mut self, pose: &Pose) -> Result<()> {
        if let Some(i) = pose.iter().position(|v| !v.is_finite()) {
            return Err(Error::invalid(
                "pose",
                format!("value {i} is not finite ({})", pose[i]),
            ));
        }
        self.reset(false);
        self.track.previous = Some(*pose);
        Ok(())
    }

    /// The pose of the next frame (`depth` metres, the input's size; `mask` the
    /// person's pixels, else segmented).
    pub fn update(&mut self, depth: &[f32], mask: Option<&[bool]>) -> Result<PoseResult> {
        let first = self.track.previous.is_none();
        let (res, frame, switched) = match self.track.previous {
            None => {
                let mut clock = Clock::start();
                let est = &self.estimator;
                let mut frame = est.prepare(depth, mask, None)?;
                clock.lap("foreground");
                let search_size = self.size.is_none() && est.size_search();
                let sized = est.fit_from_scratch(&mut frame, &mut clock, search_size)?;
                let scale = sized.scale;
                let (res, model) = est.sized_result(&mut frame, sized, clock);
                if search_size {
                    let provisional = est.explains_badly(&frame, res.discrepancy);
                    self.take_size(model, scale, provisional);
                }
                (res, frame, true)
            }
            Some(_) => {
                let (res, frame, switched) = self.tracked(depth, mask)?;
                // Tried on the 2nd, 3rd, 5th, 9th, ... frame: a size nothing explains well
                // (a noisy sensor) costs a few searches, not one per frame.
                if self.size_provisional
                    && self.frames.is_power_of_two()
                    && self.estimator.explains_badly(&frame, res.discrepancy)
                {
                    self.resized(frame, res, switched)?
                } else {
                    (res, frame, switched)
                }
            }
        };
        self.frames += 1;
        self.track.hint = frame.segmentation.as_ref().map(|s| s.hint());
        if switched {
            self.switches += usize::from(!first);
            self.track.before = None;
            self.track.recent.clear();
        } else {
            self.track.before = self.track.previous;
        }
        self.track.previous = Some(res.pose);
        if res.discrepancy.is_finite() {
            if self.track.recent.len() == RECENT {
                self.track.recent.pop_front();
            }
            self.track.recent.push_back(res.discrepancy);
        }
        let mut res = res;
        // Whether the fit explains the person decides what the background model and the
        // shape calibration take from the frame; counted only when either wants it.
        let calibrate = self.calibrating() && !first;
        let explained =
            (calibrate || self.background.is_some()) && self.explains_enough(&frame, &frame.labels);
        self.learn_background(&frame, explained, &mut res)?;
        if calibrate && explained {
            self.collect(frame, &mut res);
        }
        Ok(res)
    }

    /// A frame tracked from the previous pose; the search runs when the track is lost
    /// or a re-check is due. Returns the result, the frame and whether it switched.
    fn tracked(
        &mut self,
        depth: &[f32],
        mask: Option<&[bool]>,
    ) -> Result<(PoseResult, Frame, bool)> {
        let est = &self.estimator;
        let cfg = est.config().clone();
        let mut clock = Clock::start();
        let mut frame = est.prepare(depth, mask, self.track.hint.as_ref())?;
        clock.lap("foreground");
        let pred = self.predict();
        let prior = PosePrior::uniform(pred, cfg.prior_weight, cfg.prior_weight);
        let fit_config = cfg.fit_with(Some(cfg.track_iterations), cfg.track_stride, None);
        let fit = est
            .fits(&mut frame, &fit_config, &[pred], None, Some(&prior))?
            .pop()
            .expect("one fit");
        let (score, rendered) = est.discrepancy(&frame, &fit.pose);
        clock.lap("fit");
        let lost = self.lost(&frame, &fit.labels, score);
        self.track.since_check += 1;
        let recheck = cfg.recheck_every > 0 && self.track.since_check >= cfg.recheck_every;
        if !(lost || recheck) {
            let fitted = Fitted {
                fit,
                discrepancy: score,
                model: est.model(),
                rendered: Some(rendered),
            };
            let res = est.result(&mut frame, fitted, Source::Tracking, clock);
            return Ok((res, frame, false));
        }
        self.track.since_check = 0;
        if lost {
            self.lost_frames += 1;
        }
        let pose = fit.pose;
        let n = if lost {
            cfg.lost_hypotheses
        } else {
            cfg.recheck_hypotheses
        };
        // The tracked pose and its readings with the sides exchanged, whole body, legs
        // only or arms only: a side view's near and far limbs look alike.
        let own = [
            pose,
            swap_limbs(&pose),
            limbs_swapped(&pose, true, false),
            limbs_swapped(&pose, false, true),
        ];
        let (mut best, mut best_score) = est.search(&mut frame, &own, n, None)?;
        if lost && est.explains_badly(&frame, best_score) && cfg.hypotheses > n {
            // Still explained badly: perhaps a cut, which has nothing to go on but the
            // templates; they get as many hypotheses as from scratch.
            let (other, other_score) = est.search(&mut frame, &own, cfg.hypotheses, None)?;
            if est.rank(other_score, &other.pose) < est.rank(best_score, &best.pose) {
                (best, best_score) = (other, other_score);
            }
        }
        if lost && est.explains_badly(&frame, best_score) {
            // Still explained badly: the wide search, as from scratch. A lost track has
            // no reading to defend, so the better-ranked fit is kept with no margin.
            if let Some((other, other_score)) = est.search_wide(&mut frame, n)? {
                if est.rank(other_score, &other.pose) < est.rank(best_score, &best.pose) {
                    (best, best_score) = (other, other_score);
                }
            }
        }
        if lost {
            // A lost frame has only the templates and the tracked pose to go on, as from
            // scratch: its best is turned as a fit from scratch is, front and back and
            // left and right resolved explicitly ([`super::turns`]).
            (best, best_score) = est.try_turns(&mut frame, best, best_score)?;
        }
        let margin = if lost { 0.0 } else { cfg.switch_margin };
        let rank_best = est.rank(best_score, &best.pose);
        let rank_track = est.rank(score, &pose);
        let switch = rank_best < rank_track * (1.0 - margin);
        let (mut fit, mut score, mut rendered, source) = if switch {
            (best, best_score, None, Source::Templates)
        } else {
            (fit, score, Some(rendered), Source::Tracking)
        };
        let mut refound = false;
        if lost {
            // The body kept may still draw limbs off the person: re-initialise those.
            (fit, score, refound) = est.refind_lost_limbs(&mut frame, fit, score)?;
            if refound {
                rendered = None;
            }
        }
        if switch || refound {
            fit = est.label_all(&mut frame, fit, est.model())?;
        }
        clock.lap("search");
        let fitted = Fitted {
            fit,
            discrepancy: score,
            model: est.model(),
            rendered,
        };
        let res = est.result(&mut frame, fitted, source, clock);
        Ok((res, frame, switch || refound))
    }

    /// A tracked frame (`res`) that still explains the depth badly while the body's size
    /// is provisional, read again from scratch with the size searched from the base
    /// model; a reading that explains the depth well and ranks better replaces the
    /// track's, body size included, and the shape calibration starts again at that
    /// size. Returns the result, the frame and whether it switched.
    ///
    /// A first frame explained badly is a poor witness of the body's size (a raised
    /// arm read as the head makes the body taller), and every later frame is then
    /// searched at that size: the track cannot recover. So a size found on a frame it
    /// explains badly stays provisional until a frame read from scratch is explained
    /// well.
    fn resized(
        &mut self,
        mut frame: Frame,
        mut res: PoseResult,
        switched: bool,
    ) -> Result<(PoseResult, Frame, bool)> {
        // The search's whole time is the result's "resize" stage, whatever it finds.
        let mut clock = Clock::start();
        let tracked_model = self.estimator.model().clone();
        self.estimator.set_model(self.base_model.clone());
        let sized = self
            .estimator
            .fit_from_scratch(&mut frame, &mut clock, true);
        self.estimator.set_model(tracked_model);
        let sized = sized?;
        res.timings.push("resize", clock.finish().total);
        let est = &self.estimator;
        let better = est.rank(sized.score, &sized.fit.pose) < est.rank(res.discrepancy, &res.pose);
        if !better || est.explains_badly(&frame, sized.score) {
            return Ok((res, frame, switched));
        }
        let scale = sized.scale;
        let (mut new, model) = est.sized_result(&mut frame, sized, Clock::start());
        new.timings.add(&res.timings);
        self.take_size(model, scale, false);
        Ok((new, frame, true))
    }

    /// Tracks with `model`, the base model at `scale`, from now on (`provisional`: see
    /// [`Tracker::resized`]). Frames kept for the shape calibration, or a shape fitted,
    /// belong to another size: the calibration starts again.
    fn take_size(&mut self, model: BodyModel, scale: f64, provisional: bool) {
        self.size = Some(scale);
        self.size_provisional = provisional;
        self.estimator.set_model(model);
        self.calibration = Calibration::default();
    }

    /// The previous pose moved on by the damped velocity, within the joint limits.
    fn predict(&self) -> Pose {
        let prev = self.track.previous.expect("a track");
        match self.track.before {
            Some(before) => extrapolate(&before, &prev, self.estimator.config().velocity_damping),
            None => prev,
        }
    }

    /// At least `min_inlier_share` of the person's pixels labelled as body (`labels`
    /// at the working resolution).
    fn explains_enough(&self, frame: &Frame, labels: &[i16]) -> bool {
        let n = frame.mask.iter().filter(|&&m| m).count();
        let inliers = labels.iter().filter(|&&l| l >= 0).count();
        n > 0 && inliers as f64 >= self.estimator.config().min_inlier_share * n as f64
    }

    fn lost(&self, frame: &Frame, labels: &[i16], score: f64) -> bool {
        let cfg = self.estimator.config();
        if !self.explains_enough(frame, labels) {
            return true;
        }
        if self.estimator.explains_badly(frame, score) {
            return true;
        }
        let recent = &self.track.recent;
        if recent.len() >= RECENT_MIN {
            let mut sorted: Vec<f64> = recent.iter().copied().collect();
            sorted.sort_by(f64::total_cmp);
            let m = sorted.len();
            let median = if m % 2 == 1 {
                sorted[m / 2]
            } else {
                0.5 * (sorted[m / 2 - 1] + sorted[m / 2])
            };
            return score > cfg.lost_ratio * median;
        }
        false
    }

    /// Keeps a usable frame for the shape calibration; runs it when there are enough.
    fn collect(&mut self, frame: Frame, res: &mut PoseResult) {
        let cfg = self.estimator.config().clone();
        let c = &mut self.calibration;
        c.seen += 1;
        if !(c.seen - 1).is_multiple_of(cfg.calibration_every) {
            return;
        }
        c.buffer.push((frame.depth, frame.mask, res.pose));
        if c.buffer.len() < cfg.calibration_frames {
            return;
        }
        let start = Instant::now();
        let buffer = std::mem::take(&mut c.buffer);
        c.frame = Some(self.frames);
        let frames: Vec<ShapeFrame> = buffer
            .iter()
            .map(|(d, m, _)| ShapeFrame {
                depth: d,
                mask: Some(m),
            })
            .collect();
        let poses: Vec<Pose> = buffer.iter().map(|b| b.2).collect();
        let shape_config = ShapeConfig {
            fit: cfg.fit,
            rounds: cfg.calibration_rounds,
            prior_weight: cfg.calibration_prior_weight,
            ..ShapeConfig::default()
        };
        let camera = self.estimator.resolution().working;
        // From the body at the size found on the first frame (the base model without).
        let sized = self.estimator.model();
        let outcome = fit_shape(&frames, &camera, sized, &poses, &shape_config);
        self.finish_calibration(outcome);
        let ms = start.elapsed().as_secs_f64() * 1e3;
        res.timings.push("calibration", ms);
    }
}

impl Tracker {
    /// The learned background (working resolution), when the tracker learns one.
    pub fn background_model(&self) -> Option<&BackgroundModel> {
        self.background.as_ref()
    }

    /// Learns the background from the frame when its fit `explained` the person
    /// (outside its mask) and hands what is reliably known to the next frame's
    /// segmentation; the time it takes is the result's `background` stage.
    fn learn_background(
        &mut self,
        frame: &Frame,
        explained: bool,
        res: &mut PoseResult,
    ) -> Result<()> {
        let Some(model) = self.background.as_mut() else {
            return Ok(());
        };
        let start = Instant::now();
        if explained {
            model.update(&frame.depth, Some(&frame.mask))?;
        }
        if let Some(hint) = self.track.hint.as_mut() {
            hint.background = model.learned();
        }
        let ms = start.elapsed().as_secs_f64() * 1e3;
        res.timings.push("background", ms);
        Ok(())
    }

    /// Takes the calibration's outcome: a fitted shape is tracked with from now on (from
    /// this frame's pose under it; the velocity and the discrepancy history belong to
    /// the old shape); a failure is recorded and the model kept. Either way the
    /// calibration does not run again until `reset(true)`.
    fn finish_calibration(&mut self, outcome: Result<ShapeResult>) {
        match outcome {
            Err(e) => self.calibration.error = Some(error_text(&e)),
            Ok(r) => {
                self.estimator.set_model(r.model.clone());
                self.track.previous = r.poses.last().copied();
                self.track.before = None;
                self.track.recent.clear();
                self.calibration.result = Some(r);
            }
        }
    }
}

/// The pose after `prev` at the damped constant velocity from `before` to `prev`,
/// within the joint limits. Translation and joint angles move on linearly; the root
/// rotation moves on along the rotation from `before` to `prev` (on SO(3), not in the
/// rotation-vector components, which jump where a turning body's rotation angle
/// passes π).
fn extrapolate(before: &Pose, prev: &Pose, damping: f64) -> Pose {
    let mut pred: Pose = std::array::from_fn(|i| prev[i] + damping * (prev[i] - before[i]));
    let r_prev = root_rotation(prev);
    let step = rotation_vector(&(r_prev * root_rotation(before).inverse())) * damping;
    let r_pred = Rotation3::from_scaled_axis(step) * r_prev;
    pred[param::ROOT_R..param::ROOT_R + 3].copy_from_slice(rotation_vector(&r_pred).as_slice());
    BodyModel::clamp_pose(&pred)
}

/// An error as "Kind: message", the kind named as Python names it.
fn error_text(e: &Error) -> String {
    let kind = match e {
        Error::InvalidArgument { .. } => "InvalidInputError",
        Error::File { .. } => "FileFormatError",
        Error::NoBody(_) => "NoBodyError",
        Error::NotFound { .. } => "MissingFileError",
        Error::ResourceLimit { .. } => "ResourceLimitError",
    };
    format!("{kind}: {e}")
}

#[cfg(test)]
mod tests {
    use super::super::tests::{
        default_templates, mean_joint_error_of, rendered_person, room_posed, room_with_body,
        walking, with_depth_noise,
    };
    use super::*;
    use crate::camera::Camera;
    use crate::pipeline::PipelineConfig;

    #[test]
    fn a_side_view_tracked_with_its_legs_exchanged_is_recovered() {
        // A body walking across the view, seen from its side, mid-stride: its near and
        // far legs differ only in depth.
        let model = BodyModel::default();
        let side = |t: f64| {
            let mut p = walking(&model, t);
            p[param_root_yaw()] = std::f64::consts::FRAC_PI_2;
            p
        };
        let config = PipelineConfig {
            calibration_frames: 0,
            recheck_every: 1,
            ..PipelineConfig::default()
        };
        let mut tracker = tracker_of(&model, config);
        let pose = side(1.2);
        let first = crate::pool::on_worker(|| tracker.update(&room_posed(&model, &pose), None));
        assert!(mean_joint_error_of(&model, &first.unwrap(), &pose) < 0.05);
        // The track goes on with the legs exchanged, as after a wrong step.
        let previous = tracker.track.previous.unwrap();
        tracker.track.previous = Some(limbs_swapped(&previous, true, false));
        tracker.track.before = None;
        let pose = side(1.25);
        let r = crate::pool::on_worker(|| tracker.update(&room_posed(&model, &pose), None));
        let err = mean_joint_error_of(&model, &r.unwrap(), &pose);
        assert!(err < 0.05, "mean joint error {err}");
    }

    #[test]
    fn a_size_misread_on_a_first_frame_explained_badly_is_found_again() {
        // A 1.57 m body seen from its side, one arm overhead, the other folded by the
        // head and a knee raised: from scratch the raised arm reads as the head and the
        // body is sized far too tall, and it explains the depth badly. Then the same
        // body turned toward the camera, arms folded up: at the first frame's size no
        // search explains it; read from scratch with its size searched again, it is.
        let model = BodyModel::new(1.57).unwrap();
        let first: Pose = [
            -0.080, 0.0, 3.214, 0.056, 2.024, 0.089, -0.131, 0.079, 2.820, 0.366, 0.571, 0.695,
            2.029, 0.484, -0.444, 1.800, 1.708, 0.823, 0.586, 0.206, 0.029, 0.32,
        ];
        let later: Pose = [
            -0.165, 0.0, 3.151, -0.093, 0.945, 0.130, 0.061, 0.243, 2.807, 0.860, -0.162, 1.563,
            0.891, 1.856, 0.332, 2.249, -0.105, 0.007, 0.297, 0.065, 0.063, 0.175,
        ];
        let config = PipelineConfig {
            calibration_frames: 0,
            ..PipelineConfig::default()
        };
        let mut tracker = tracker_of(&BodyModel::default(), config);
        // The body alone, its mask given, with 5 mm of depth noise at 3.2 m.
        let noise = crate::fit::DepthNoise {
            focal_baseline: 100.0,
            disparity_sigma: 0.049,
        };
        let camera = Camera::itop();
        let seen = |pose: &Pose, seed: u64| {
            let (depth, mask) = rendered_person(&model, pose, &camera);
            (with_depth_noise(&depth, &noise, seed), mask)
        };
        let (depth, mask) = seen(&first, 1);
        let r = crate::pool::on_worker(|| tracker.update(&depth, Some(&mask))).unwrap();
        let err = mean_joint_error_of(&model, &r, &first);
        assert!(
            err > 0.15,
            "mean joint error {err}: the first frame is read right"
        );
        assert!(tracker.size.unwrap() > 0.95, "sized {:?}", tracker.size);
        assert!(tracker.size_provisional);
        let (depth, mask) = seen(&later, 2);
        let r = crate::pool::on_worker(|| tracker.update(&depth, Some(&mask))).unwrap();
        let err = mean_joint_error_of(&model, &r, &later);
        assert!(err < 0.02, "mean joint error {err}");
        assert!(r.timings.get("resize").is_some());
        let size = tracker.size.unwrap();
        assert!((size - 1.57 / 1.75).abs() < 0.02, "sized {size}");
        assert!(!tracker.size_provisional);
    }

    /// A tracker of [`Camera::itop`] with `model` and `config`, its shape not calibrated.
    fn tracker_of(model: &BodyModel, config: PipelineConfig) -> Tracker {
        let est = Estimator::new(
            &Camera::itop(),
            model.clone(),
            default_templates(),
            config,
            None,
        );
        Tracker::new(est.unwrap(), false)
    }

    #[test]
    fn a_cut_the_lost_search_explains_badly_is_searched_as_from_scratch() {
        // A walker facing the camera, then (a cut) a body seen from behind, the right
        // arm overhead, the left pointing forward, the left knee raised and the right
        // heel raised behind. The lost search with one hypothesis (and its turns) leaves
        // it explained badly; the search with the hypotheses of a search from scratch
        // finds it.
        let model = BodyModel::default();
        let front = walking(&model, 0.4);
        let mut cut = walking(&model, 1.5);
        cut[param_root_yaw()] = 3.0;
        cut[param::R_SHOULDER] = 2.9;
        cut[param::L_SHOULDER] = 1.45;
        cut[param::L_HIP] = 1.4;
        cut[param::L_KNEE] = 1.6;
        cut[param::R_HIP] = 0.0;
        cut[param::R_KNEE] = 1.6;
        let run = |hypotheses: usize| {
            let config = PipelineConfig {
                calibration_frames: 0,
                hypotheses,
                lost_hypotheses: 1,
                ..PipelineConfig::default()
            };
            let mut tracker = tracker_of(&model, config);
            crate::pool::on_worker(|| {
                tracker.update(&room_posed(&model, &front), None).unwrap();
                let r = tracker.update(&room_posed(&model, &cut), None).unwrap();
                (tracker.lost_frames, mean_joint_error_of(&model, &r, &cut))
            })
        };
        let (lost, err) = run(20);
        assert_eq!(lost, 1);
        assert!(err < 0.05, "mean joint error {err}");
        // With as few hypotheses from scratch as when lost, nothing finds it.
        let (lost, err) = run(1);
        assert_eq!(lost, 1);
        assert!(err > 0.1, "mean joint error {err}");
    }

    fn param_root_yaw() -> usize {
        crate::body::param::ROOT_R + 1
    }

    /// A pose turned about the vertical by `yaw`, with its rotation vector written as
    /// given (any of the equivalent vectors).
    fn yawed(yaw: f64) -> Pose {
        let mut p = BodyModel::neutral_pose();
        p[param_root_yaw()] = yaw;
        p[param::L_ELBOW] = 0.4;
        p
    }

    #[test]
    fn the_prediction_turns_on_through_a_half_turn() {
        use std::f64::consts::PI;
        // A body turning by 0.1 rad a frame through a half turn, its rotation vector
        // jumping from (0, π − 0.05, 0) to the equivalent (0, −π + 0.05, 0).
        let before = yawed(PI - 0.05);
        let prev = yawed(PI + 0.05 - 2.0 * PI);
        let pred = extrapolate(&before, &prev, 0.5);
        let expected = Rotation3::from_scaled_axis(nalgebra::Vector3::y() * (PI + 0.10));
        let angle = (root_rotation(&pred).inverse() * expected).angle();
        assert!(angle < 1e-12, "predicted rotation off by {angle} rad");
        // The joint angles and translation move on linearly.
        let mut moved = prev;
        moved[param::ROOT_T] += 0.1;
        moved[param::L_ELBOW] += 0.2;
        let pred = extrapolate(&prev, &moved, 0.5);
        assert!((pred[param::ROOT_T] - moved[param::ROOT_T] - 0.05).abs() < 1e-12);
        assert!((pred[param::L_ELBOW] - 0.7).abs() < 1e-12);
        assert!((root_rotation(&pred).inverse() * root_rotation(&prev)).angle() < 1e-12);
    }

    #[test]
    fn the_prediction_is_the_linear_one_away_from_a_half_turn() {
        let pred = extrapolate(&yawed(0.2), &yawed(0.3), 0.5);
        assert!((pred[param_root_yaw()] - 0.35).abs() < 1e-12);
        assert_eq!(pred[param::ROOT_R], 0.0);
    }

    #[test]
    fn a_failed_calibration_keeps_the_model_and_is_not_retried() {
        let (camera, _, _) = room_with_body(0.0);
        let est = Estimator::new(
            &camera,
            BodyModel::new(1.75).unwrap(),
            default_templates(),
            PipelineConfig::default(),
            None,
        )
        .unwrap();
        let mut tracker = Tracker::new(est, true);
        let base = tracker.model().clone();
        assert!(tracker.calibrating());
        tracker.finish_calibration(Err(Error::NoBody("frame 0: 3 points".into())));
        assert!(!tracker.calibrating());
        assert_eq!(tracker.model(), &base);
        assert!(tracker.shape_factors().is_none());
        assert_eq!(
            tracker.calibration().error.as_deref(),
            Some("NoBodyError: frame 0: 3 points")
        );
        // reset(true) calibrates again.
        tracker.reset(true);
        assert!(tracker.calibrating());
    }
}
