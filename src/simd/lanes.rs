//! The interface of the instruction sets: lane types, their vectors and operations,
//! and the kernels written over them.

/// A lane type: `f64` or `f32`.
pub(crate) trait Real: Copy + PartialEq + std::fmt::Debug + Send + Sync + 'static {
    const ZERO: Self;
    const ONE: Self;
    /// This value from an `f64` (rounded to the nearest for `f32`).
    fn from_f64(x: f64) -> Self;
}

impl Real for f64 {
    const ZERO: f64 = 0.0;
    const ONE: f64 = 1.0;
    #[inline(always)]
    fn from_f64(x: f64) -> f64 {
        x
    }
}

impl Real for f32 {
    const ZERO: f32 = 0.0;
    const ONE: f32 = 1.0;
    #[inline(always)]
    fn from_f64(x: f64) -> f32 {
        x as f32
    }
}

/// Vectors of `E` and their operations for one instruction set (`Self`, its token).
///
/// Lane masks are given as bits (bit l = lane l) where a kernel branches on them, and
/// as the set's own mask type `M` where they feed further vector operations.
///
/// # Safety
/// Implemented only by tokens that exist only where the CPU has the instructions the
/// operations use.
pub(crate) unsafe trait Lanes<E: Real>: Copy {
    /// Lanes per vector (at most 16).
    const LANES: usize;
    /// A vector of `LANES` values.
    type V: Copy;
    /// A lane mask.
    type M: Copy;
    /// Per lane, the position of the work item it holds (see [`Self::scatter`]).
    type Pos: Copy;
    /// Per lane, a count of integer steps (see [`Self::count_step`]).
    type Count: Copy;
    /// What [`Self::expand_load`] needs of a set of lanes to fill, made once for the
    /// several loads that fill them.
    type Expand: Copy;
    /// What [`Self::compress_store`] needs of a set of lanes to keep, made once for the
    /// several stores that keep them.
    type Compress: Copy;

    fn splat(self, x: E) -> Self::V;
    fn add(self, a: Self::V, b: Self::V) -> Self::V;
    fn sub(self, a: Self::V, b: Self::V) -> Self::V;
    fn mul(self, a: Self::V, b: Self::V) -> Self::V;
    fn div(self, a: Self::V, b: Self::V) -> Self::V;
    fn sqrt(self, a: Self::V) -> Self::V;
    fn abs(self, a: Self::V) -> Self::V;
    /// The instruction's maximum: `b` where either is NaN.
    fn max(self, a: Self::V, b: Self::V) -> Self::V;
    /// `a` with the sign bit flipped in the lanes of `m` (the scalar `-a`).
    fn negate_where(self, m: Self::M, a: Self::V) -> Self::V;
    /// `a` with the sign bit of `sign` or-ed in (`a.copysign(sign)` for `a` ≥ +0).
    fn or_sign(self, a: Self::V, sign: Self::V) -> Self::V;

    /// Ordered comparisons (false where either is NaN).
    fn lt(self, a: Self::V, b: Self::V) -> Self::M;
    fn le(self, a: Self::V, b: Self::V) -> Self::M;
    fn gt(self, a: Self::V, b: Self::V) -> Self::M;
    fn ge(self, a: Self::V, b: Self::V) -> Self::M;
    fn eq(self, a: Self::V, b: Self::V) -> Self::M;
    /// `yes` in the lanes of `m`, `no` in the others.
    fn select(self, m: Self::M, yes: Self::V, no: Self::V) -> Self::V;
    fn and(self, a: Self::M, b: Self::M) -> Self::M;
    fn or(self, a: Self::M, b: Self::M) -> Self::M;
    /// The lanes of a mask as bits.
    fn bits(self, m: Self::M) -> u32;
    /// The mask of the lanes of `bits`.
    fn mask(self, bits: u32) -> Self::M;
    /// The bits of `bits` at the set positions of `keep`, packed to the low end in
    /// order.
    fn compress_bits(self, bits: u32, keep: u32) -> u32;

    /// The lanes of `m` from `p` (lane l from `p[l]`), zeros in the others.
    ///
    /// # Safety
    /// `p` is valid for reading the lanes of `m`.
    unsafe fn load_where(self, p: *const E, m: Self::M) -> Self::V;
    /// # Safety
    /// `p` is valid for writing `LANES` values.
    unsafe fn store(self, p: *mut E, v: Self::V);
    /// Stores the lanes of `m` (lane l at `p[l]`).
    ///
    /// # Safety
    /// `p` is valid for writing `LANES` values.
    unsafe fn store_where(self, p: *mut E, m: Self::M, v: Self::V);
    /// The expansion into the lanes of `load` (bits).
    fn expand(self, load: u32) -> Self::Expand;
    /// The mask of the lanes an expansion fills.
    fn expand_mask(self, e: Self::Expand) -> Self::M;
    /// `v` with the lanes `e` fills replaced by `p[0]`, `p[1]`, … in lane order.
    ///
    /// # Safety
    /// `p` is valid for reading `LANES` values.
    unsafe fn expand_load(self, v: Self::V, e: Self::Expand, p: *const E) -> Self::V;
    /// The compression to the lanes of `keep` (bits).
    fn compress(self, keep: u32) -> Self::Compress;
    /// Stores the lanes `c` keeps to `p[0]`, `p[1]`, … in lane order.
    ///
    /// # Safety
    /// `p` is valid for writing `LANES` values.
    unsafe fn compress_store(self, p: *mut E, c: Self::Compress, v: Self::V);
    /// Stores `base + l` for the lanes l that `c` keeps to `p[0]`, `p[1]`, … in lane
    /// order.
    ///
    /// # Safety
    /// `p` is valid for writing `LANES` values.
    unsafe fn compress_store_lanes(self, p: *mut u32, c: Self::Compress, base: usize);

    /// Counts all zero.
    fn count_zero(self) -> Self::Count;
    /// `c` with the lanes that `e` fills at zero.
    fn count_restart(self, c: Self::Count, e: Self::Expand) -> Self::Count;
    /// `c` plus one in every lane.
    fn count_step(self, c: Self::Count) -> Self::Count;
    /// The lanes whose count is `n`.
    fn count_is(self, c: Self::Count, n: usize) -> Self::M;

    /// Positions all zero.
    fn positions(self) -> Self::Pos;
    /// Refills the lowest `take` of the `free` lanes (bits; at least `take` of them):
    /// returns those lanes (bits), and `pos` with them at `next`, `next + 1`, … in lane
    /// order.
    fn refill(self, pos: Self::Pos, free: u32, take: usize, next: usize) -> (u32, Self::Pos);
    /// `base[pos[l]] = v[l]` for the lanes l in `m` (bits).
    ///
    /// # Safety
    /// `base` is valid for writing at every such position.
    unsafe fn scatter(self, base: *mut E, pos: Self::Pos, m: u32, v: Self::V);
    /// `base[index[l]] = v[l]` for the first `n` lanes.
    ///
    /// # Safety
    /// `index` is valid for reading `n` values, `base` for writing at each.
    unsafe fn scatter_indexed(self, base: *mut E, index: *const u32, n: usize, v: Self::V);
}

/// An instruction set for both lane types, and the context its kernels run in.
pub(crate) trait Simd: Lanes<f64> + Lanes<f32> + Copy + Send + Sync {
    /// Runs `op` compiled for this set's target features.
    fn vectorize<Op: WithSimd>(self, op: Op) -> Op::Output;
}

/// A kernel generic over the instruction set.
pub(crate) trait WithSimd {
    type Output;
    fn with_simd<S: Simd>(self, simd: S) -> Self::Output;
}
