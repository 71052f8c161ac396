//! Vector instructions behind one interface, so that a kernel is written once over a
//! generic instruction set and compiled for each one the CPU may have.
//!
//! The pattern is pulp's (and faer's): [`Lanes`] gives a vector type of `f64` or `f32`
//! and its operations for one instruction set, [`Simd`] is a token proving the CPU has
//! that set, and a kernel is a [`WithSimd`] operation whose `with_simd<S: Simd>` body
//! is generic. [`Simd::vectorize`] runs it inside a function compiled for the set's
//! target features, so that the generic body, whose operations are all
//! `#[inline(always)]`, becomes straight vector code. [`Arch::new`] picks the set at
//! run time. A kernel's vector operations belong in `#[inline(always)]` functions (or
//! macros), not in closures: a closure is a function of its own, compiled without the
//! set's target features, which then calls every operation out of line.
//!
//! Every operation is one IEEE operation per lane (no fused multiply-add, no
//! reassociation), so a kernel gives the same bits whatever the set and lane count,
//! and the same as scalar code doing the same operations in the same order. Besides
//! arithmetic, the sets offer the data movement a stream of work items needs: loading
//! the next queued values into exactly the free lanes, storing the kept lanes
//! contiguously, scattering lanes to their items' places; AVX-512 has instructions for
//! these, AVX2 emulates them.
//!
//! (pulp itself is not used: its AVX-512 set is a cargo feature of the pulp crate
//! shared with faer, which would switch faer's own kernels to AVX-512 and change the
//! rounding of the LM's Cholesky solve; and its generic interface has no expanding
//! loads, compressing stores or scatters.)

mod arch;
#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx512;
mod lanes;

pub(crate) use arch::Arch;
pub(crate) use lanes::{Lanes, Real, Simd, WithSimd};
