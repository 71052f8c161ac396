//! The body's size from one frame.
//!
//! A body model of the wrong size puts every joint off: fitted to a 1.60 m subject, a
//! 1.75 m body stands its hips too low or its head too high and stretches its limbs
//! past the hands and feet. From scratch the subject's size is unknown, so the best fit
//! of the search is refitted with the body scaled uniformly to sizes in a range
//! around the model's (1 ± k·`size_step`, up to ± `size_range`), and the size whose fit
//! explains the observed depth best is kept: the depth discrepancy of the rendered body
//! plus the rest-pose penalty, the measure by which poses compete everywhere in the
//! pipeline. A smaller body leaves observed pixels unexplained, a larger one covers
//! pixels off the person, so the discrepancy has its minimum near the subject's size.
//!
//! Only the search's best reading is sized, and the search compares its readings at the
//! model's size, where a subject far from it can be explained better by a wrong reading
//! than by the right one. A result that still explains the depth badly is searched again
//! with the body at the end of the size range toward which its size search
//! leaned (`Estimator::search_size_end`).

use super::estimator::{Estimator, Frame};
use crate::body::{BodyModel, Pose, NUM_SHAPE_FACTORS};
use crate::error::Result;
use crate::fit::{FitConfig, FitResult};
use rayon::prelude::*;

/// A fit and the body it was made with.
#[derive(Debug, Clone)]
pub struct SizedFit {
    pub fit: FitResult,
    /// Its depth discrepancy.
    pub score: f64,
    /// The body's size relative to the estimator's model.
    pub scale: f64,
    /// Which way the size search leaned: −1 or +1 when the smaller or the larger of the
    /// two sizes first tried beside its start ranked better, 0 when none was tried.
    pub lean: i64,
    /// The body.
    pub model: BodyModel,
}

/// How many steps of `step` the sizes 1 ± k·`step` may take on each side of 1 within
/// `range` (a little tolerance for rounding); 0 when either is not positive.
pub fn size_steps(range: f64, step: f64) -> usize {
    if !(range > 0.0 && step > 0.0) {
        return 0;
    }
    ((range + 1e-9) / step).floor() as usize
}

impl Estimator {
    /// `fit` (the search's best, made with the estimator's model, `score` its
    /// discrepancy) with the body's size found when `search` (see the module docs),
    /// labelled at every pixel with the body kept.
    pub(crate) fn fit_size(
        &self,
        frame: &mut Frame,
        fit: FitResult,
        score: f64,
        search: bool,
    ) -> Result<SizedFit> {
        let steps = if search { self.size_steps() } else { 0 };
        self.walk_sizes(frame, fit, score, 0, steps)
    }

    /// The sizes 1 + k·`size_step` the size search may try have |k| up to this.
    fn size_steps(&self) -> i64 {
        let cfg = self.config();
        size_steps(cfg.size_range, cfg.size_step) as i64
    }

    /// The scale of size step `k`: 1 + `k`·`size_step`.
    fn scale_at(&self, k: i64) -> f64 {
        1.0 + k as f64 * self.config().size_step
    }

    /// The estimator's model scaled by [`Self::scale_at`] `k`.
    fn model_at_size(&self, k: i64) -> Result<BodyModel> {
        self.model()
            .with_shape_factors(&[self.scale_at(k); NUM_SHAPE_FACTORS])
    }

    /// `fit` (made with the body at size step `from`, `score` its discrepancy) refitted
    /// at the sizes 1 + k·`size_step`, |k| ≤ `steps`, walking outward from `from`, the
    /// best kept and labelled at every pixel.
    ///
    /// The walk goes in rounds of two fits run in parallel: the two sizes beside `from`
    /// first, then, while the best size is the outermost tried on its side, the next
    /// two on that side. The discrepancy is smooth in the size and has one minimum near
    /// the subject's, so the walk finds the grid's best in two rounds where trying every
    /// size would take three or more.
    fn walk_sizes(
        &self,
        frame: &mut Frame,
        fit: FitResult,
        score: f64,
        from: i64,
        steps: i64,
    ) -> Result<SizedFit> {
        let mut best = SizedFit {
            fit,
            score,
            scale: self.scale_at(from),
            lean: 0,
            model: self.model_at_size(from)?,
        };
        let mut lean = 0;
        if steps > 0 {
            let mut rank = self.rank(best.score, &best.fit.pose);
            // One short EM from the fitted pose per size: it is on the body already.
            let config = self.config().short_refit();
            let start = best.fit.pose;
            let within = |k: &i64| k.abs() <= steps;
            let mut round: Vec<i64> = [from - 1, from + 1].into_iter().filter(within).collect();
            let (mut low, mut high) = (from, from);
            while !round.is_empty() {
                let scales: Vec<f64> = round.iter().map(|&k| self.scale_at(k)).collect();
                let tried = self.fits_at_sizes(frame, &config, &start, &scales)?;
                low = low.min(round.iter().copied().min().unwrap_or(from));
                high = high.max(round.iter().copied().max().unwrap_or(from));
                let ranks: Vec<f64> = tried
                    .iter()
                    .map(|t| self.rank(t.score, &t.fit.pose))
                    .collect();
                if lean == 0 {
                    let better = (0..round.len()).min_by(|&a, &b| ranks[a].total_cmp(&ranks[b]));
                    lean = better.map_or(0, |i| (round[i] - from).signum());
                }
                let mut moved = None;
                for ((t, &k), &r) in tried.into_iter().zip(&round).zip(&ranks) {
                    if r < rank {
                        rank = r;
                        moved = Some(k);
                        best = t;
                    }
                }
                // Walk on only while the best is the outermost size tried on its side.
                let side = match moved {
                    Some(k) if k == low && k < from => -1,
                    Some(k) if k == high && k > from => 1,
                    _ => break,
                };
                let edge = if side < 0 { low } else { high };
                round = [edge + side, edge + 2 * side]
                    .into_iter()
                    .filter(within)
                    .collect();
            }
        }
        // A body the walk resized is turned again with its own size; at `from` the
        // caller's turns (or its choice to run none) stand.
        let mut best = self.turned_at_size(frame, best, self.scale_at(from))?;
        best.fit = self.label_all(frame, best.fit, &best.model)?;
        best.lean = lean;
        Ok(best)
    }

    /// The first search ([`Self::search`], then the limb poses and the turns) made with
    /// the body at the end of the size range toward which `lean` points, its fit then
    /// sized by walking inward from there. `lean` is the way the size search leaned for
    /// the reading the search preferred ([`SizedFit::lean`]): wrong as that reading may
    /// be, it was fitted to the same pixels. At the model's size a subject far from it
    /// may be explained better by a wrong reading (upside down, the limbs crossed) than
    /// by the right one, which then never reaches the size search. None when `lean` is
    /// 0 or no size is searched.
    pub(crate) fn search_size_end(
        &self,
        frame: &mut Frame,
        hypotheses: usize,
        lean: i64,
    ) -> Result<Option<SizedFit>> {
        let steps = self.size_steps();
        if steps == 0 || lean == 0 {
            return Ok(None);
        }
        let end = lean.signum() * steps;
        let mut at_end = self.clone();
        at_end.set_model(self.model_at_size(end)?);
        let (best, score) = at_end.search(frame, &[], hypotheses, None)?;
        let (best, score) = at_end.reposed_and_turned(frame, best, score)?;
        self.walk_sizes(frame, best, score, end, steps).map(Some)
    }

    /// Fits from `start` with the body scaled uniformly to each of `scales`, in
    /// parallel, each with its depth discrepancy.
    fn fits_at_sizes(
        &self,
        frame: &mut Frame,
        config: &FitConfig,
        start: &Pose,
        scales: &[f64],
    ) -> Result<Vec<SizedFit>> {
        let models = scales
            .iter()
            .map(|&s| self.model().with_shape_factors(&[s; NUM_SHAPE_FACTORS]))
            .collect::<Result<Vec<_>>>()?;
        let fits = {
            let problem = &*self.problem(frame, config)?;
            models
                .par_iter()
                .map(|m| problem.fit_from(m, start, None, None))
                .collect::<Result<Vec<_>>>()?
        };
        let frame = &*frame;
        Ok(fits
            .into_par_iter()
            .zip(models)
            .zip(scales)
            .map(|((fit, model), &scale)| {
                let score = self.discrepancy_with(frame, &model, &fit.pose).0;
                SizedFit {
                    fit,
                    score,
                    scale,
                    lean: 0,
                    model,
                }
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use crate::pipeline::tests::{estimator, mean_joint_distance, mean_joint_error_of, room_with};
    use crate::pipeline::{PipelineConfig, Tracker};

    #[test]
    fn a_short_subject_is_fitted_at_its_size() {
        // A 1.60 m body (0.914 of the 1.75 m model) walking in the room.
        let subject = BodyModel::new(1.60).unwrap();
        let (camera, depth, pose) = room_with(&subject, 0.6);
        let sized = estimator(&camera, PipelineConfig::default());
        let fixed = sized.clone().with_size_search(false);
        let (a, b) =
            crate::pool::on_worker(|| (sized.estimate(&depth, None), fixed.estimate(&depth, None)));
        let (a, b) = (a.unwrap(), b.unwrap());
        let height = a.shape.standing_height() / BodyModel::default().shape.standing_height();
        assert!((0.875..=0.955).contains(&height), "relative size {height}");
        let (ea, eb) = (
            mean_joint_error_of(&subject, &a, &pose),
            mean_joint_error_of(&subject, &b, &pose),
        );
        assert!(ea < 0.04 && ea < eb, "sized {ea}, fixed {eb}");
        assert!(a.discrepancy < b.discrepancy);
        // Sizes are not searched when the estimator is told the shape.
        assert_eq!(b.shape, BodyModel::default().shape);
    }

    #[test]
    fn a_tracker_sizes_the_body_once_and_calibrates_from_there() {
        let subject = BodyModel::new(1.90).unwrap();
        let config = PipelineConfig {
            calibration_frames: 3,
            ..PipelineConfig::default()
        };
        let mut tracker = Tracker::new(estimator(&Camera::itop(), config), true);
        for k in 0..5 {
            let (_, depth, pose) = room_with(&subject, 0.3 * k as f64);
            let r = crate::pool::on_worker(|| tracker.update(&depth, None)).unwrap();
            let err = mean_joint_error_of(&subject, &r, &pose);
            assert!(err < 0.05, "frame {k}: mean joint error {err}");
        }
        let size = tracker.size().expect("sized on the first frame");
        assert!((1.05..=1.15).contains(&size), "{size}");
        // The calibrated factors are relative to the base model, the size included.
        let factors = tracker.shape_factors().expect("calibrated");
        let mean = factors.iter().sum::<f64>() / factors.len() as f64;
        assert!((mean - 1.9 / 1.75).abs() < 0.06, "{factors:?}");
        tracker.reset(true);
        assert_eq!(tracker.size(), None);
        assert_eq!(tracker.model(), tracker.base_model());
    }

    /// The mean distance between the joints of a sized fit and of `subject` at `pose`.
    fn sized_joint_error(sized: &SizedFit, subject: &BodyModel, pose: &Pose) -> f64 {
        mean_joint_distance(&sized.model.joints(&sized.fit.pose), &subject.joints(pose))
    }

    #[test]
    fn the_size_walk_from_an_end_of_the_range_comes_inward_to_the_subject() {
        // A 0.95-scale subject, fitted first with the body at the range's small end.
        let subject = BodyModel::default()
            .with_shape_factors(&[0.95; NUM_SHAPE_FACTORS])
            .unwrap();
        let (camera, depth, pose) = room_with(&subject, 0.6);
        let est = estimator(&camera, PipelineConfig::default());
        let sized = crate::pool::on_worker(|| {
            let mut frame = est.prepare(&depth, None, None)?;
            let steps = est.size_steps();
            let small = est.model_at_size(-steps)?;
            let config = est.config().short_refit();
            let fit = est
                .problem(&mut frame, &config)?
                .fit_from(&small, &pose, None, None)?;
            let score = est.discrepancy_with(&frame, &small, &fit.pose).0;
            est.walk_sizes(&mut frame, fit, score, -steps, steps)
        })
        .unwrap();
        assert!((sized.scale - 0.95).abs() < 0.026, "size {}", sized.scale);
        // Only the larger neighbour of the range's end was tried first: it leaned there.
        assert_eq!(sized.lean, 1);
        let error = sized_joint_error(&sized, &subject, &pose);
        assert!(error < 0.03, "mean joint error {error}");
    }

    #[test]
    fn the_search_at_the_small_end_of_the_size_range_finds_a_small_subject() {
        let subject = BodyModel::new(1.50).unwrap();
        let (camera, depth, pose) = room_with(&subject, 0.6);
        let est = estimator(&camera, PipelineConfig::default());
        let (small, large, none) = crate::pool::on_worker(|| {
            let mut frame = est.prepare(&depth, None, None)?;
            let hypotheses = est.config().hypotheses;
            Ok::<_, crate::error::Error>((
                est.search_size_end(&mut frame, hypotheses, -1)?,
                est.search_size_end(&mut frame, hypotheses, 1)?,
                est.search_size_end(&mut frame, hypotheses, 0)?,
            ))
        })
        .unwrap();
        // A size search that did not lean says nothing: no search.
        assert!(none.is_none());
        // From the small end, sized near 1.50/1.75 = 0.857.
        let small = small.expect("searched");
        assert!((0.8..=0.9).contains(&small.scale), "size {}", small.scale);
        let error = sized_joint_error(&small, &subject, &pose);
        assert!(error < 0.05, "mean joint error {error}");
        // From the large end the walk comes inward as far as the subject's size allows.
        let large = large.expect("searched");
        assert!(large.scale < 1.15, "size {}", large.scale);
        let rank = |s: &SizedFit| est.rank(s.score, &s.fit.pose);
        assert!(rank(&small) < rank(&large));
    }

    #[test]
    fn size_steps_stay_within_the_range() {
        assert_eq!(size_steps(0.0, 0.05), 0);
        assert_eq!(size_steps(0.1, 0.0), 0);
        // 0.15 / 0.05 is 2.999… in floating point: the tolerance counts it as 3.
        assert_eq!(size_steps(0.15, 0.05), 3);
        assert_eq!(size_steps(0.12, 0.05), 2);
    }
}
