//! The pose of a frame with nothing known: the template search, then the limb poses
//! ([`super::limbs`]), then the body's size ([`super::size`]). `Estimator::estimate`
//! and a track's first frame both run it.

use super::estimator::{Estimator, Frame};
use super::result::Clock;
use super::size::SizedFit;
use crate::error::Result;

impl Estimator {
    /// The best fit of `frame` from scratch, with the body's size found when `size`,
    /// labelled at every pixel. Laps `clock` at "templates" and "fit".
    pub(crate) fn fit_from_scratch(
        &self,
        frame: &mut Frame,
        clock: &mut Clock,
        size: bool,
    ) -> Result<SizedFit> {
        let hypotheses = self.config().hypotheses;
        let (best, score) = self.search(frame, &[], hypotheses, Some(clock))?;
        let (best, score) = self.repose_limbs(frame, best, score)?;
        let sized = self.fit_size(frame, best, score, size)?;
        clock.lap("fit");
        Ok(sized)
    }
}
