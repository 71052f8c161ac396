//! The depth image seen as a cloud of 3-D points: validation, back-projection, surface
//! normals from the depth grid and the pixel-neighbourhood graph the CRF works on.
//! Foreground extraction lives in [`foreground`].

pub mod foreground;

mod depth;
mod graph;
mod normals;
mod points;
#[cfg(test)]
mod tests;

pub use depth::DepthView;
pub use graph::{neighbour_graph, neighbour_graph_into, Connectivity, PixelGraph};
pub use normals::{normals_from_depth, normals_into, surface_jump, NormalConfig};
pub use points::Cloud;

pub use foreground::{foreground_mask, ForegroundConfig};
