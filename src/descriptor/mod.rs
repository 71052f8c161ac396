//! Surface-context descriptors (paper Section II-C, eqs. 2–4; after the shape context of
//! Belongie, Malik and Puzicha).
//!
//! 1. The silhouette's pixels are summarised on a grid scaled to the silhouette (cell
//!    side `sqrt(area / (samples · cells_per_sample))`, origin at the silhouette's
//!    bounding box, jittered by the seed): each cell keeps its pixel count, mean pixel
//!    position and the sum of its surface normals.
//! 2. Sample points: a coarser grid of the same kind with about `samples` occupied
//!    cells; in each, the pixel nearest the cell centre.
//! 3. Around each sample, log-polar bins in the image plane (`radial_bins` log-spaced
//!    rings from `inner_radius` to `outer_radius` times the mean pairwise distance of
//!    the samples, `angular_bins` sectors); a bin holds the sum of the normals of the
//!    pixels falling in it divided by the silhouette's pixel count. The descriptor is
//!    those sums concatenated (3 values per bin).
//!
//! Because both grids and the radii scale with the silhouette, the descriptors do not
//! change (up to pixel quantisation) when the body moves in the image or comes closer;
//! every sum is order-independent, so neither does shuffling the input points. Normals
//! are first rotated so the line of sight to the body's centroid becomes +z, so a body
//! off the optical axis is described as if seen straight on.

mod config;
mod context;
mod distance;
mod silhouette;
#[cfg(test)]
mod tests;

pub use config::{DescriptorConfig, MAX_DEPTH_FROM_MEDIAN, MIN_POINTS, MIN_SAMPLES};
pub use context::{surface_context_from_points, surface_context_with_relief, SurfaceContext};
pub use distance::{descriptor_distance, squared_distance, squared_distances_x4};
pub use silhouette::{line_of_sight_alignment, surface_context_from_depth, Silhouette};
