//! The pose of a frame with nothing known: the template search, then the limb poses
//! ([`super::limbs`]), the turns ([`super::turns`]: the half turn and the left/right
//! exchanges always, every eighth of a turn for a badly explained fit), then the body's
//! size ([`super::size`]), whose search runs the turns again when it changes the body.
//! When the search looked at more than one first view (a leaning or lying silhouette)
//! and its fit explains the depth badly, each first view is also searched alone, with
//! its own limb poses and turns (`Estimator::searched_per_view`).
//! `Estimator::estimate` and a track's first frame both run it.
//!
//! A result that explains the depth badly ([`Estimator::explains_badly`]: what the
//! tracker calls lost) may be a subject whose size misled the search: the first search
//! runs again with the body at the end of the size range toward which its size search
//! leaned (`Estimator::search_size_end`), and its fit replaces the first when it ranks
//! better by `switch_margin`. A result still explained badly may be a body the first
//! views misread: upside down but about vertical, doubled up, or in a pose no template
//! holds upright but one holds rolled. The search then also runs on the frame seen at
//! every eighth of a turn, and its fit replaces the result when it ranks better by
//! `switch_margin`. When the wide search's fit explains the depth badly too, the body
//! may be one no template resembles (airborne, tucked, split): the neutral bodies at
//! every orientation ([`super::neutral`]) are fitted as well and the better-ranked
//! reading competes. The size end comes first because upright readings are by far the
//! commonest: they get the size they need before the rolled ones compete with them.
//! Frames explained well pay for none of these.

use super::estimator::{Estimator, Frame, Views};
use super::result::Clock;
use super::size::SizedFit;
use crate::body::Pose;
use crate::error::Result;
use crate::fit::FitResult;

impl Estimator {
    /// The best fit of `frame` from scratch, with the body's size found when `size`,
    /// labelled at every pixel. Laps `clock` at "templates", "fit" and, when the wide
    /// search runs, "wide" (and "neutral" for the neutral bodies' fits), "sizes" when
    /// the search at an end of the size range runs, and "views" when each first view is
    /// searched alone.
    pub(crate) fn fit_from_scratch(
        &self,
        frame: &mut Frame,
        clock: &mut Clock,
        size: bool,
    ) -> Result<SizedFit> {
        let hypotheses = self.config().hypotheses;
        let (best, score) = self.search(frame, &[], hypotheses, Some(clock))?;
        let searched = best.pose;
        let (best, score) = self.reposed_and_turned(frame, best, score)?;
        let (best, score) = self.searched_per_view(frame, best, score, &searched, clock)?;
        let unsized_rank = self.rank(score, &best.pose);
        let mut sized = self.fit_size(frame, best, score, size)?;
        clock.lap("fit");
        let keep = 1.0 - self.config().switch_margin;
        let rank = |s: &SizedFit| self.rank(s.score, &s.fit.pose);
        if size && self.explains_badly(frame, sized.score) {
            // Explained badly: the subject's size may be far enough from the model's
            // that the search, at the model's size, preferred a wrong reading. The ends
            // of the size range are less likely: `switch_margin`. This runs before the
            // wide search so that the commonest readings, upright ones, have the size
            // they need before the rolled ones compete with them.
            if let Some(other) = self.search_size_end(frame, hypotheses, sized.lean)? {
                if rank(&other) < rank(&sized) * keep {
                    sized = other;
                }
                clock.lap("sizes");
            }
        }
        if self.explains_badly(frame, sized.score) {
            // A body explained this badly may be one the first views misread: the wide
            // search runs too. Its readings are the less likely ones (a body upright in
            // the image is by far the commonest), so, like a tracker's re-check, it
            // replaces the first result only when it ranks better by `switch_margin`:
            // at the model's own size first, then sized.
            if let Some((mut best, mut score)) = self.search_wide(frame, hypotheses)? {
                if self.explains_badly(frame, score) {
                    // Explained badly at every roll too: a body no template resembles.
                    clock.lap("wide");
                    let (other, other_score) = self.search_neutral(frame)?;
                    if self.rank(other_score, &other.pose) < self.rank(score, &best.pose) {
                        (best, score) = (other, other_score);
                    }
                    clock.lap("neutral");
                }
                let (best, score) = self.repose_limbs(frame, best, score)?;
                if self.rank(score, &best.pose) < unsized_rank * keep {
                    let other = self.fit_size(frame, best, score, size)?;
                    if rank(&other) < rank(&sized) * keep {
                        sized = other;
                    }
                }
                clock.lap("wide");
            }
        }
        Ok(sized)
    }

    /// A search's `fit` (with `score`, its depth discrepancy) with its limbs re-posed
    /// ([`super::limbs`]) and then turned ([`super::turns`]) where each ranks better.
    pub(super) fn reposed_and_turned(
        &self,
        frame: &mut Frame,
        fit: FitResult,
        score: f64,
    ) -> Result<(FitResult, f64)> {
        let (fit, score) = self.repose_limbs(frame, fit, score)?;
        self.try_turns(frame, fit, score)
    }

    /// `fit` (with `score`, its depth discrepancy) or, when it explains the depth badly
    /// and the search looked at more than one first view, the best-ranked of the
    /// searches on each first view alone, each followed by its limb poses and turns,
    /// where that ranks better. `searched` is the first search's result before its limb
    /// poses and turns: a view whose search ends there adds nothing. Laps `clock` at
    /// "views" when they run.
    ///
    /// Searched together, the views compete for the hypotheses and only the winner's
    /// fit is turned: a raised arm tilts an upright body's silhouette, a view rolled
    /// upright then draws it upside down well enough to win, and the upright reading,
    /// which explains the depth better once its limbs are reposed and it is turned, is
    /// never reached. Alone, each view has the whole budget, its own limb poses and its
    /// own turns. These are first-view readings, as likely as the first search's, so no
    /// `switch_margin` applies.
    fn searched_per_view(
        &self,
        frame: &mut Frame,
        fit: FitResult,
        score: f64,
        searched: &Pose,
        clock: &mut Clock,
    ) -> Result<(FitResult, f64)> {
        if !self.explains_badly(frame, score) {
            return Ok((fit, score));
        }
        let rolls = self.first_rolls(frame);
        if rolls.len() < 2 {
            return Ok((fit, score));
        }
        clock.lap("fit");
        let (mut best, mut best_score) = (fit, score);
        let mut best_rank = self.rank(score, &best.pose);
        let hypotheses = self.config().hypotheses;
        for roll in rolls {
            let views = Views {
                rolls: &[roll],
                distinct: true,
            };
            let (fit, score) = self.search_views(frame, &[], hypotheses, &views, None)?;
            if fit.pose == *searched {
                // The first search's own result: its limb poses and turns ran already.
                continue;
            }
            let (fit, score) = self.reposed_and_turned(frame, fit, score)?;
            let rank = self.rank(score, &fit.pose);
            if rank < best_rank {
                (best, best_score, best_rank) = (fit, score, rank);
            }
        }
        clock.lap("views");
        Ok((best, best_score))
    }
}
