//! The whole pipeline, one native call per frame: [`Estimator`] finds the pose of a
//! frame from scratch, [`Tracker`] follows it through a video, [`StereoPipeline`] does
//! either on rectified stereo pairs.
//!
//! A frame is brought to the working resolution ([`resolution`]), the person's pixels
//! are found ([`crate::segment`]), start poses come from the template search
//! ([`hypotheses`]), EM fits ([`crate::fit`]) refine them and the pose whose rendered
//! body explains the observed depth best is kept. Results come back at the input's
//! pixel grid, in the camera frame.

pub mod confidence;
pub mod config;
pub mod estimator;
pub mod hypotheses;
pub mod limbs;
pub mod lost_limbs;
pub mod neutral;
pub mod orientation;
pub mod resolution;
pub mod result;
pub mod scratch;
pub mod size;
pub mod stereo;
pub mod tracker;
pub mod turns;

pub use config::PipelineConfig;
pub use estimator::Estimator;
pub use hypotheses::{mirror_view, rest_pose_penalty, swap_limbs, turn_around, turned};
pub use result::{PoseResult, SegmentSummary, Source, Timings};
pub use size::{size_steps, SizedFit};
pub use stereo::{StereoDepth, StereoDepthConfig, StereoPipeline, StereoPose, StereoRig};
pub use tracker::Tracker;

#[cfg(test)]
pub(crate) mod tests;
