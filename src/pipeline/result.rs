//! The pose of one frame, as the estimator and the tracker return it.

use crate::body::{BodyShape, Pose, NUM_JOINTS};
use crate::segment::{Cluster, Method, Plane};
use nalgebra::Vector3;
use std::time::Instant;

/// How a frame's start pose was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// The template search (from scratch, or a tracker that re-initialised or switched).
    Templates,
    /// The previous frame's pose.
    Tracking,
}

impl Source {
    pub fn name(self) -> &'static str {
        match self {
            Source::Templates => "templates",
            Source::Tracking => "tracking",
        }
    }
}

/// Milliseconds spent in each stage of a frame, in the order they ran; `total` covers
/// the whole call.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Timings {
    pub stages: Vec<(&'static str, f64)>,
    pub total: f64,
}

impl Timings {
    /// Adds `other`'s stages (summed where both ran one) and total: one result for
    /// work done twice on the same frame.
    pub fn add(&mut self, other: &Timings) {
        for &(stage, ms) in &other.stages {
            self.add_stage(stage, ms);
        }
        self.total += other.total;
    }

    /// Adds a stage that took `ms` (to the stage's time when it ran already) and its
    /// time to the total: work done after the frame's clock stopped.
    pub fn push(&mut self, stage: &'static str, ms: f64) {
        self.add_stage(stage, ms);
        self.total += ms;
    }

    /// Adds `ms` to `stage` (a new stage when it has not run); the total is the caller's.
    fn add_stage(&mut self, stage: &'static str, ms: f64) {
        match self.stages.iter_mut().find(|(s, _)| *s == stage) {
            Some(entry) => entry.1 += ms,
            None => self.stages.push((stage, ms)),
        }
    }

    /// The time of `stage`, if it ran.
    pub fn get(&self, stage: &str) -> Option<f64> {
        self.stages.iter().find(|(s, _)| *s == stage).map(|s| s.1)
    }
}

/// A stopwatch that records stages as they end.
pub(crate) struct Clock {
    start: Instant,
    last: Instant,
    timings: Timings,
}

impl Clock {
    pub fn start() -> Self {
        let now = Instant::now();
        Clock {
            start: now,
            last: now,
            timings: Timings::default(),
        }
    }

    /// Records the time since the last stage ended as `stage`.
    pub fn lap(&mut self, stage: &'static str) {
        let now = Instant::now();
        let ms = (now - self.last).as_secs_f64() * 1e3;
        self.last = now;
        self.timings.add_stage(stage, ms);
    }

    pub fn finish(mut self) -> Timings {
        self.timings.total = (Instant::now() - self.start).as_secs_f64() * 1e3;
        self.timings
    }
}

/// How the person was found in a frame (none when the caller gave the mask).
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentSummary {
    pub method: Method,
    pub planes: Vec<Plane>,
    pub person: Cluster,
    pub others: Vec<Cluster>,
}

/// The pose of one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseResult {
    /// The 22 pose parameters.
    pub pose: Pose,
    /// The 15 joints (ITOP order), camera frame, metres.
    pub joints: [Vector3<f64>; NUM_JOINTS],
    /// The body shape the pose was fitted with.
    pub shape: BodyShape,
    /// Part label of every input pixel (−1 = not body), row-major, the input's size.
    pub labels: Vec<i16>,
    /// The person's pixels, the input's size.
    pub mask: Vec<bool>,
    pub energy: f64,
    pub iterations: usize,
    pub converged: bool,
    /// Per-joint confidence in [0, 1] (see [`super::confidence::joint_confidence`]).
    pub confidence: [f64; NUM_JOINTS],
    pub timings: Timings,
    pub source: Source,
    /// How badly the fitted body explains the depth: 0 = perfectly, about 1 = unrelated
    /// (see [`crate::render::depth_discrepancy`]).
    pub discrepancy: f64,
    pub segmentation: Option<SegmentSummary>,
}
