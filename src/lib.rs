//! depthpose: 3-D human pose from depth images and stereo pairs.
//!
//! One module per pipeline stage (see `DESIGN.md` in the shared folder and the README):
//! camera → cloud (points, normals, neighbours, foreground) → stereo → body model →
//! render → descriptor/templates → graphcut → fit → pipeline; `synth` renders synthetic
//! sequences to test them on. The PyO3 bindings live in `python` behind the `python`
//! feature; algorithms never live there.

/// Defines `fn $name(args) { body }` twice over: compiled for AVX2, used where the CPU
/// has it and `DEPTHPOSE_NO_AVX2` is not set ([`cpu::avx2`], decided once per process),
/// and the portable build otherwise. The body is an `#[inline(always)]` inner function,
/// so each variant gets its own code. Same results either way: Rust does not fuse
/// multiplies and adds on its own. Closures in the body (rayon's, for instance) are
/// functions of their own and do not inherit the AVX2 build: dispatch inside them.
macro_rules! avx2_dispatch {
    ($(#[$meta:meta])* $vis:vis fn $name:ident($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)? $body:block) => {
        $(#[$meta])*
        $vis fn $name($($arg: $ty),*) $(-> $ret)? {
            #[inline(always)]
            fn body($($arg: $ty),*) $(-> $ret)? $body
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx2")]
            unsafe fn avx2($($arg: $ty),*) $(-> $ret)? {
                body($($arg),*)
            }
            #[cfg(target_arch = "x86_64")]
            if $crate::cpu::avx2() {
                // SAFETY: `cpu::avx2` holds only where the CPU supports AVX2.
                return unsafe { avx2($($arg),*) };
            }
            body($($arg),*)
        }
    };
}

pub mod assignment;
pub mod body;
pub mod camera;
pub mod cloud;
mod cpu;
pub mod descriptor;
pub mod error;
pub mod export;
pub mod fit;
pub mod graphcut;
pub mod io;
pub mod pipeline;
pub mod pool;
pub mod render;
pub mod segment;
pub mod sequence;
mod simd;
pub mod stereo;
pub mod synth;
pub mod templates;
mod union_find;

#[cfg(feature = "python")]
mod python;

pub use camera::Camera;
pub use error::{Error, Result};
