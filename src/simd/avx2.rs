//! The AVX2 set: 4 `f64` or 8 `f32` lanes, masks as vectors of all-ones lanes. The
//! expanding load and the compressing store are permutations from tables indexed by
//! the lane mask; scatters go lane by lane.
//!
//! Every intrinsic here needs AVX2: they run only inside [`Simd::vectorize`], compiled
//! with it, and an [`Avx2`] token exists only where the CPU has it.

use super::lanes::{Lanes, Simd, WithSimd};
use std::arch::x86_64::*;

/// The token of the AVX2 set.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Avx2 {
    _private: (),
}

impl Avx2 {
    /// The token, where the CPU has AVX2.
    pub fn try_new() -> Option<Self> {
        is_x86_feature_detected!("avx2").then_some(Avx2 { _private: () })
    }
}

impl Simd for Avx2 {
    #[inline(always)]
    fn vectorize<Op: WithSimd>(self, op: Op) -> Op::Output {
        #[target_feature(enable = "avx2")]
        unsafe fn run<Op: WithSimd>(simd: Avx2, op: Op) -> Op::Output {
            op.with_simd(simd)
        }
        // SAFETY: the token exists only where the CPU has AVX2.
        unsafe { run(self, op) }
    }
}

/// For a mask of `lanes` lanes (bit l = lane l): `expand[l]` = the rank of lane l among
/// the set lanes (0 for an unset lane), and `pack[r]` = the r-th set lane (0 past the
/// last).
const fn lane_ranks(mask: usize, lanes: usize) -> ([i32; 8], [i32; 8]) {
    let (mut expand, mut pack) = ([0i32; 8], [0i32; 8]);
    let (mut rank, mut lane) = (0, 0);
    while lane < lanes {
        if mask & (1 << lane) != 0 {
            expand[lane] = rank as i32;
            pack[rank] = lane as i32;
            rank += 1;
        }
        lane += 1;
    }
    (expand, pack)
}

/// The 32-bit source indices of `_mm256_permutevar8x32_ps` for every mask of `lanes`
/// lanes of `width` 32-bit words each: with `pack`, the set lanes moved to the front in
/// order; else entries 0, 1, 2, … moved into the set lanes in order (unset lanes take
/// entry 0).
const fn permutations<const MASKS: usize>(
    lanes: usize,
    width: usize,
    pack: bool,
) -> [[i32; 8]; MASKS] {
    let mut table = [[0i32; 8]; MASKS];
    let mut mask = 0;
    while mask < MASKS {
        let (expand, packed) = lane_ranks(mask, lanes);
        let ranks = if pack { packed } else { expand };
        let mut lane = 0;
        while lane < lanes {
            let mut w = 0;
            while w < width {
                table[mask][width * lane + w] = width as i32 * ranks[lane] + w as i32;
                w += 1;
            }
            lane += 1;
        }
        mask += 1;
    }
    table
}

/// Expanding and packing permutations of 4 `f64` lanes and of 8 `f32` lanes.
const EXPAND_F64: [[i32; 8]; 16] = permutations(4, 2, false);
const PACK_F64: [[i32; 8]; 16] = permutations(4, 2, true);
const EXPAND_F32: [[i32; 8]; 256] = permutations(8, 1, false);
const PACK_F32: [[i32; 8]; 256] = permutations(8, 1, true);

/// The bits of `bits` at the set positions of `keep`, packed to the low end.
#[inline(always)]
fn compress_bits(bits: u32, keep: u32) -> u32 {
    let (mut out, mut rank, mut rest) = (0, 0, keep);
    while rest != 0 {
        let lane = rest.trailing_zeros();
        out |= ((bits >> lane) & 1) << rank;
        rank += 1;
        rest &= rest - 1;
    }
    out
}

/// Implements [`Lanes`] for one lane type: the operations that differ only by the
/// intrinsics' names and the permutation tables.
macro_rules! lanes {
    (
        $elem:ident, $lanes:literal, $v:ty, $int:ty,
        set1: $set1:ident, add: $add:ident, sub: $sub:ident, mul: $mul:ident,
        div: $div:ident, sqrt: $sqrt:ident, max: $max:ident, and: $and:ident, or: $or:ident,
        xor: $xor:ident, cmp: $cmp:ident, blendv: $blendv:ident, movemask: $movemask:ident,
        loadu: $loadu:ident, maskload: $maskload:ident, storeu: $storeu:ident,
        maskstore: $maskstore:ident, to_int: $to_int:ident, from_int: $from_int:ident,
        to_ps: $to_ps:ident, from_ps: $from_ps:ident, set1_int: $set1_int:ident,
        cmpeq_int: $cmpeq_int:ident, add_int: $add_int:ident, lane_bits: $lane_bits:expr,
        expand: $expand:ident, pack: $pack:ident
    ) => {
        // SAFETY: an `Avx2` token exists only where the CPU has AVX2.
        unsafe impl Lanes<$elem> for Avx2 {
            const LANES: usize = $lanes;
            type V = $v;
            type M = $v;
            type Pos = [u32; $lanes];
            /// The permutation that moves the queued values into the lanes to fill,
            /// and those lanes' mask.
            type Count = __m256i;
            type Expand = (__m256i, $v);
            /// The permutations that pack the kept lanes of a vector and of 32-bit
            /// lane indices to the front.
            type Compress = (__m256i, __m256i);

            #[inline(always)]
            fn splat(self, x: $elem) -> $v {
                unsafe { $set1(x) }
            }
            #[inline(always)]
            fn add(self, a: $v, b: $v) -> $v {
                unsafe { $add(a, b) }
            }
            #[inline(always)]
            fn sub(self, a: $v, b: $v) -> $v {
                unsafe { $sub(a, b) }
            }
            #[inline(always)]
            fn mul(self, a: $v, b: $v) -> $v {
                unsafe { $mul(a, b) }
            }
            #[inline(always)]
            fn div(self, a: $v, b: $v) -> $v {
                unsafe { $div(a, b) }
            }
            #[inline(always)]
            fn sqrt(self, a: $v) -> $v {
                unsafe { $sqrt(a) }
            }
            #[inline(always)]
            fn abs(self, a: $v) -> $v {
                unsafe { $and(a, $from_int($set1_int(<$int>::MAX))) }
            }
            #[inline(always)]
            fn max(self, a: $v, b: $v) -> $v {
                unsafe { $max(a, b) }
            }
            #[inline(always)]
            fn negate_where(self, m: $v, a: $v) -> $v {
                unsafe { $xor(a, $and(m, $from_int($set1_int(<$int>::MIN)))) }
            }
            #[inline(always)]
            fn or_sign(self, a: $v, sign: $v) -> $v {
                unsafe { $or(a, $and(sign, $from_int($set1_int(<$int>::MIN)))) }
            }
            #[inline(always)]
            fn lt(self, a: $v, b: $v) -> $v {
                unsafe { $cmp::<_CMP_LT_OQ>(a, b) }
            }
            #[inline(always)]
            fn le(self, a: $v, b: $v) -> $v {
                unsafe { $cmp::<_CMP_LE_OQ>(a, b) }
            }
            #[inline(always)]
            fn gt(self, a: $v, b: $v) -> $v {
                unsafe { $cmp::<_CMP_GT_OQ>(a, b) }
            }
            #[inline(always)]
            fn ge(self, a: $v, b: $v) -> $v {
                unsafe { $cmp::<_CMP_GE_OQ>(a, b) }
            }
            #[inline(always)]
            fn eq(self, a: $v, b: $v) -> $v {
                unsafe { $cmp::<_CMP_EQ_OQ>(a, b) }
            }
            #[inline(always)]
            fn select(self, m: $v, yes: $v, no: $v) -> $v {
                unsafe { $blendv(no, yes, m) }
            }
            #[inline(always)]
            fn and(self, a: $v, b: $v) -> $v {
                unsafe { $and(a, b) }
            }
            #[inline(always)]
            fn or(self, a: $v, b: $v) -> $v {
                unsafe { $or(a, b) }
            }
            #[inline(always)]
            fn bits(self, m: $v) -> u32 {
                unsafe { $movemask(m) as u32 }
            }
            #[inline(always)]
            fn mask(self, bits: u32) -> $v {
                unsafe {
                    let lane_bits = $lane_bits;
                    let set = _mm256_and_si256($set1_int(bits as $int), lane_bits);
                    $from_int($cmpeq_int(set, lane_bits))
                }
            }
            #[inline(always)]
            fn compress_bits(self, bits: u32, keep: u32) -> u32 {
                compress_bits(bits, keep)
            }
            #[inline(always)]
            unsafe fn load_where(self, p: *const $elem, m: $v) -> $v {
                $maskload(p, $to_int(m))
            }
            #[inline(always)]
            unsafe fn store(self, p: *mut $elem, v: $v) {
                $storeu(p, v)
            }
            #[inline(always)]
            unsafe fn store_where(self, p: *mut $elem, m: $v, v: $v) {
                $maskstore(p, $to_int(m), v)
            }
            #[inline(always)]
            fn expand(self, load: u32) -> (__m256i, $v) {
                // SAFETY: `load` < 2^LANES indexes the table.
                let perm = unsafe {
                    _mm256_loadu_si256($expand[load as usize].as_ptr() as *const __m256i)
                };
                (perm, Lanes::<$elem>::mask(self, load))
            }
            #[inline(always)]
            fn expand_mask(self, e: (__m256i, $v)) -> $v {
                e.1
            }
            #[inline(always)]
            unsafe fn expand_load(self, v: $v, (perm, fill): (__m256i, $v), p: *const $elem) -> $v {
                let moved = $from_ps(_mm256_permutevar8x32_ps($to_ps($loadu(p)), perm));
                $blendv(v, moved, fill)
            }
            #[inline(always)]
            fn compress(self, keep: u32) -> (__m256i, __m256i) {
                // SAFETY: `keep` < 2^LANES indexes the tables.
                unsafe {
                    (
                        _mm256_loadu_si256($pack[keep as usize].as_ptr() as *const __m256i),
                        _mm256_loadu_si256(PACK_F32[keep as usize].as_ptr() as *const __m256i),
                    )
                }
            }
            #[inline(always)]
            unsafe fn compress_store(self, p: *mut $elem, (perm, _): (__m256i, __m256i), v: $v) {
                $storeu(p, $from_ps(_mm256_permutevar8x32_ps($to_ps(v), perm)))
            }
            #[inline(always)]
            unsafe fn compress_store_lanes(
                self,
                p: *mut u32,
                (_, perm): (__m256i, __m256i),
                base: usize,
            ) {
                let ids = _mm256_add_epi32(
                    _mm256_set_epi32(7, 6, 5, 4, 3, 2, 1, 0),
                    _mm256_set1_epi32(base as i32),
                );
                _mm256_storeu_si256(p as *mut __m256i, _mm256_permutevar8x32_epi32(ids, perm));
            }
            #[inline(always)]
            fn count_zero(self) -> __m256i {
                unsafe { _mm256_setzero_si256() }
            }
            #[inline(always)]
            fn count_restart(self, c: __m256i, (_, fill): (__m256i, $v)) -> __m256i {
                unsafe { _mm256_andnot_si256($to_int(fill), c) }
            }
            #[inline(always)]
            fn count_step(self, c: __m256i) -> __m256i {
                unsafe { $add_int(c, $set1_int(1)) }
            }
            #[inline(always)]
            fn count_is(self, c: __m256i, n: usize) -> $v {
                unsafe { $from_int($cmpeq_int(c, $set1_int(n as $int))) }
            }
            #[inline(always)]
            fn positions(self) -> [u32; $lanes] {
                [0; $lanes]
            }
            #[inline(always)]
            fn refill(
                self,
                mut pos: [u32; $lanes],
                free: u32,
                take: usize,
                next: usize,
            ) -> (u32, [u32; $lanes]) {
                let (mut load, mut rest) = (0, free);
                for rank in 0..take {
                    let lane = rest.trailing_zeros();
                    rest &= rest - 1;
                    load |= 1 << lane;
                    pos[lane as usize] = (next + rank) as u32;
                }
                (load, pos)
            }
            #[inline(always)]
            unsafe fn scatter(self, base: *mut $elem, pos: [u32; $lanes], m: u32, v: $v) {
                let mut values = [0.0 as $elem; $lanes];
                $storeu(values.as_mut_ptr(), v);
                let mut rest = m;
                while rest != 0 {
                    let lane = rest.trailing_zeros() as usize;
                    *base.add(pos[lane] as usize) = values[lane];
                    rest &= rest - 1;
                }
            }
            #[inline(always)]
            unsafe fn scatter_indexed(self, base: *mut $elem, index: *const u32, n: usize, v: $v) {
                let mut values = [0.0 as $elem; $lanes];
                $storeu(values.as_mut_ptr(), v);
                for (l, &x) in values.iter().enumerate().take(n) {
                    *base.add(*index.add(l) as usize) = x;
                }
            }
        }
    };
}

lanes!(
    f64, 4, __m256d, i64,
    set1: _mm256_set1_pd, add: _mm256_add_pd, sub: _mm256_sub_pd, mul: _mm256_mul_pd,
    div: _mm256_div_pd, sqrt: _mm256_sqrt_pd, max: _mm256_max_pd, and: _mm256_and_pd,
    or: _mm256_or_pd, xor: _mm256_xor_pd, cmp: _mm256_cmp_pd, blendv: _mm256_blendv_pd,
    movemask: _mm256_movemask_pd, loadu: _mm256_loadu_pd, maskload: _mm256_maskload_pd,
    storeu: _mm256_storeu_pd, maskstore: _mm256_maskstore_pd, to_int: _mm256_castpd_si256,
    from_int: _mm256_castsi256_pd, to_ps: _mm256_castpd_ps, from_ps: _mm256_castps_pd,
    set1_int: _mm256_set1_epi64x, cmpeq_int: _mm256_cmpeq_epi64, add_int: _mm256_add_epi64,
    lane_bits: _mm256_set_epi64x(8, 4, 2, 1), expand: EXPAND_F64, pack: PACK_F64
);

lanes!(
    f32, 8, __m256, i32,
    set1: _mm256_set1_ps, add: _mm256_add_ps, sub: _mm256_sub_ps, mul: _mm256_mul_ps,
    div: _mm256_div_ps, sqrt: _mm256_sqrt_ps, max: _mm256_max_ps, and: _mm256_and_ps,
    or: _mm256_or_ps, xor: _mm256_xor_ps, cmp: _mm256_cmp_ps, blendv: _mm256_blendv_ps,
    movemask: _mm256_movemask_ps, loadu: _mm256_loadu_ps, maskload: _mm256_maskload_ps,
    storeu: _mm256_storeu_ps, maskstore: _mm256_maskstore_ps, to_int: _mm256_castps_si256,
    from_int: _mm256_castsi256_ps, to_ps: identity_ps, from_ps: identity_ps,
    set1_int: _mm256_set1_epi32, cmpeq_int: _mm256_cmpeq_epi32, add_int: _mm256_add_epi32,
    lane_bits: _mm256_set_epi32(128, 64, 32, 16, 8, 4, 2, 1), expand: EXPAND_F32,
    pack: PACK_F32
);

/// The identity, where the `f32` lanes need no cast for the 32-bit permutation.
#[inline(always)]
fn identity_ps(v: __m256) -> __m256 {
    v
}
