//! The settings of the surface-context descriptors.

use crate::error::{ensure, Result};

/// Settings of the surface-context descriptors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DescriptorConfig {
    /// Target number of sample points (the actual count is within a few of it).
    pub samples: usize,
    /// Log-spaced rings.
    pub radial_bins: usize,
    /// Sectors.
    pub angular_bins: usize,
    /// Inner and outer ring radius, in units of the mean pairwise sample distance;
    /// points closer than `inner_radius` fall in the first ring, farther than
    /// `outer_radius` in none.
    pub inner_radius: f64,
    pub outer_radius: f64,
    /// Summary cells per sample cell (the normal grid is this many times finer).
    pub cells_per_sample: f64,
    /// Seed of the grid jitter; equal seeds give identical descriptors.
    pub seed: u64,
    /// Normal estimation.
    pub normal_radius: usize,
    /// Weight of the optional fourth value per bin, the body's relief: the depth of
    /// each point relative to the body's centre, in units of the body's RMS radius
    /// across the line of sight (so it is scale-invariant like the rest), summed per
    /// bin like the normals. 0 (the default): off, the paper's normals-only
    /// descriptor. The normals alone cannot tell an arm held toward the camera from
    /// one hanging down in front of the body; the relief can (docs/design.md).
    pub depth_weight: f64,
}

impl Default for DescriptorConfig {
    fn default() -> Self {
        DescriptorConfig {
            samples: 100,
            radial_bins: 5,
            angular_bins: 12,
            inner_radius: 0.125,
            outer_radius: 2.0,
            cells_per_sample: 4.0,
            seed: 0,
            normal_radius: 2,
            depth_weight: 0.0,
        }
    }
}

/// Fewest sample points / silhouette pixels we describe.
pub const MIN_SAMPLES: usize = 4;
pub const MIN_POINTS: usize = 20;
/// Silhouette points farther than this from the median depth (m) are not the body: a
/// body with an arm stretched toward the camera spans well under it.
pub const MAX_DEPTH_FROM_MEDIAN: f32 = 1.0;
/// Refinements of the sample-grid step toward the target sample count.
pub(super) const GRID_REFINEMENTS: usize = 3;

impl DescriptorConfig {
    pub fn validate(&self) -> Result<()> {
        ensure(
            (MIN_SAMPLES..=10_000).contains(&self.samples),
            "samples",
            || format!("must be in {MIN_SAMPLES}..=10000, got {}", self.samples),
        )?;
        ensure((1..=32).contains(&self.radial_bins), "radial_bins", || {
            format!("must be in 1..=32, got {}", self.radial_bins)
        })?;
        ensure(
            (1..=64).contains(&self.angular_bins),
            "angular_bins",
            || format!("must be in 1..=64, got {}", self.angular_bins),
        )?;
        ensure(
            self.inner_radius.is_finite()
                && self.inner_radius > 0.0
                && self.outer_radius.is_finite()
                && self.outer_radius > self.inner_radius,
            "inner_radius/outer_radius",
            || {
                format!(
                    "need 0 < inner < outer, got {} and {}",
                    self.inner_radius, self.outer_radius
                )
            },
        )?;
        ensure(
            self.cells_per_sample.is_finite() && (1.0..=100.0).contains(&self.cells_per_sample),
            "cells_per_sample",
            || format!("must be in 1..=100, got {}", self.cells_per_sample),
        )?;
        ensure(
            (1..=32).contains(&self.normal_radius),
            "normal_radius",
            || format!("must be in 1..=32, got {}", self.normal_radius),
        )?;
        ensure(
            self.depth_weight.is_finite() && (0.0..=100.0).contains(&self.depth_weight),
            "depth_weight",
            || format!("must be in 0..=100, got {}", self.depth_weight),
        )
    }

    /// Values per bin: the normal sum, and the relief sum when `depth_weight` > 0.
    pub fn values_per_bin(&self) -> usize {
        if self.depth_weight > 0.0 {
            4
        } else {
            3
        }
    }

    /// Values per descriptor.
    pub fn dim(&self) -> usize {
        self.values_per_bin() * self.radial_bins * self.angular_bins
    }
}
