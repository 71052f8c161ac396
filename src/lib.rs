//! depthpose: 3-D human pose from depth images and stereo pairs.
//!
//! One module per pipeline stage (see `DESIGN.md` in the shared folder and the README):
//! camera → cloud (points, normals, neighbours, foreground) → stereo → body model →
//! render → descriptor/templates → graphcut → fit → pipeline. The PyO3 bindings live in
//! [`python`] behind the `python` feature; algorithms never live there.

pub mod assignment;
pub mod body;
pub mod camera;
pub mod cloud;
pub mod descriptor;
pub mod error;
pub mod fit;
pub mod graphcut;
pub mod io;
pub mod render;
pub mod stereo;
pub mod templates;

#[cfg(feature = "python")]
mod python;

pub use camera::Camera;
pub use error::{Error, Result};
