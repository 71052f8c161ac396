//! The AVX-512 set: 8 `f64` or 16 `f32` lanes, mask registers, and the expanding loads,
//! compressing stores and scatters of AVX-512F (with BMI2 for the lane bits).
//!
//! Every intrinsic here needs AVX-512F (or BMI2): they run only inside
//! [`Simd::vectorize`], compiled with those features, and an [`Avx512`] token exists
//! only where the CPU has them.

use super::lanes::{Lanes, Simd, WithSimd};
use std::arch::x86_64::*;

/// The token of the AVX-512 set (AVX-512F and BMI2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Avx512 {
    _private: (),
}

impl Avx512 {
    /// The token, where the CPU has AVX-512F and BMI2 and `DEPTHPOSE_NO_AVX512` is not
    /// set ([`crate::cpu::avx512`]).
    pub fn try_new() -> Option<Self> {
        (crate::cpu::avx512() && is_x86_feature_detected!("bmi2"))
            .then_some(Avx512 { _private: () })
    }

    /// The token where the CPU has the instructions, whatever the environment says
    /// (for tests that compare the sets).
    #[cfg(test)]
    pub fn detected() -> Option<Self> {
        (is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("bmi2"))
            .then_some(Avx512 { _private: () })
    }
}

impl Simd for Avx512 {
    #[inline(always)]
    fn vectorize<Op: WithSimd>(self, op: Op) -> Op::Output {
        #[target_feature(enable = "avx512f,bmi2")]
        unsafe fn run<Op: WithSimd>(simd: Avx512, op: Op) -> Op::Output {
            op.with_simd(simd)
        }
        // SAFETY: the token exists only where the CPU has these features.
        unsafe { run(self, op) }
    }
}

/// The mask of the first `n` (≤ 16) lanes.
#[inline(always)]
fn first(n: usize) -> u32 {
    (1u32 << n) - 1
}

/// Implements [`Lanes`] for one lane type: the operations that differ only by the
/// intrinsics' names.
macro_rules! lanes {
    (
        $elem:ident, $lanes:literal, $v:ty, $m:ty, $int:ty,
        set1: $set1:ident, add: $add:ident, sub: $sub:ident, mul: $mul:ident,
        div: $div:ident, sqrt: $sqrt:ident, abs: $abs:ident, max: $max:ident,
        cmp: $cmp:ident, blend: $blend:ident, loadu: $loadu:ident, maskz_loadu: $maskz_loadu:ident,
        storeu: $storeu:ident, mask_storeu: $mask_storeu:ident, expandloadu: $expandloadu:ident,
        compressstoreu: $compressstoreu:ident, cast_to_int: $to_int:ident, cast_from_int: $from_int:ident,
        set1_int: $set1_int:ident, xor_int: $mask_xor:ident, lane_ids: $lane_ids:expr,
        maskz_expand_int: $maskz_expand:ident, mask_add_int: $mask_add:ident,
        mask_mov_int: $mask_mov:ident, add_int: $add_int:ident, cmpeq_int: $cmpeq_int:ident
    ) => {
        // SAFETY: an `Avx512` token exists only where the CPU has AVX-512F and BMI2.
        unsafe impl Lanes<$elem> for Avx512 {
            const LANES: usize = $lanes;
            type V = $v;
            type M = $m;
            type Pos = __m512i;
            type Count = __m512i;
            type Expand = $m;
            type Compress = $m;

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
                unsafe { $abs(a) }
            }
            #[inline(always)]
            fn max(self, a: $v, b: $v) -> $v {
                unsafe { $max(a, b) }
            }
            #[inline(always)]
            fn negate_where(self, m: $m, a: $v) -> $v {
                unsafe {
                    let bits = $to_int(a);
                    $from_int($mask_xor(bits, m, bits, $set1_int(<$int>::MIN)))
                }
            }
            #[inline(always)]
            fn or_sign(self, a: $v, sign: $v) -> $v {
                unsafe {
                    let sign_bit = _mm512_and_si512($to_int(sign), $set1_int(<$int>::MIN));
                    $from_int(_mm512_or_si512($to_int(a), sign_bit))
                }
            }
            #[inline(always)]
            fn lt(self, a: $v, b: $v) -> $m {
                unsafe { $cmp::<_CMP_LT_OQ>(a, b) }
            }
            #[inline(always)]
            fn le(self, a: $v, b: $v) -> $m {
                unsafe { $cmp::<_CMP_LE_OQ>(a, b) }
            }
            #[inline(always)]
            fn gt(self, a: $v, b: $v) -> $m {
                unsafe { $cmp::<_CMP_GT_OQ>(a, b) }
            }
            #[inline(always)]
            fn ge(self, a: $v, b: $v) -> $m {
                unsafe { $cmp::<_CMP_GE_OQ>(a, b) }
            }
            #[inline(always)]
            fn eq(self, a: $v, b: $v) -> $m {
                unsafe { $cmp::<_CMP_EQ_OQ>(a, b) }
            }
            #[inline(always)]
            fn select(self, m: $m, yes: $v, no: $v) -> $v {
                unsafe { $blend(m, no, yes) }
            }
            #[inline(always)]
            fn and(self, a: $m, b: $m) -> $m {
                a & b
            }
            #[inline(always)]
            fn or(self, a: $m, b: $m) -> $m {
                a | b
            }
            #[inline(always)]
            fn bits(self, m: $m) -> u32 {
                m as u32
            }
            #[inline(always)]
            fn mask(self, bits: u32) -> $m {
                bits as $m
            }
            #[inline(always)]
            fn compress_bits(self, bits: u32, keep: u32) -> u32 {
                unsafe { _pext_u32(bits, keep) }
            }
            #[inline(always)]
            unsafe fn load_where(self, p: *const $elem, m: $m) -> $v {
                $maskz_loadu(m, p)
            }
            #[inline(always)]
            unsafe fn store(self, p: *mut $elem, v: $v) {
                $storeu(p, v)
            }
            #[inline(always)]
            unsafe fn store_where(self, p: *mut $elem, m: $m, v: $v) {
                $mask_storeu(p, m, v)
            }
            #[inline(always)]
            fn expand(self, load: u32) -> $m {
                load as $m
            }
            #[inline(always)]
            fn expand_mask(self, e: $m) -> $m {
                e
            }
            #[inline(always)]
            unsafe fn expand_load(self, v: $v, e: $m, p: *const $elem) -> $v {
                $expandloadu(v, e, p)
            }
            #[inline(always)]
            fn compress(self, keep: u32) -> $m {
                keep as $m
            }
            #[inline(always)]
            unsafe fn compress_store(self, p: *mut $elem, c: $m, v: $v) {
                $compressstoreu(p, c, v)
            }
            #[inline(always)]
            unsafe fn compress_store_lanes(self, p: *mut u32, c: $m, base: usize) {
                let keep = c as u32;
                let ids = _mm512_add_epi32(
                    _mm512_set_epi32(15, 14, 13, 12, 11, 10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 0),
                    _mm512_set1_epi32(base as i32),
                );
                _mm512_mask_compressstoreu_epi32(p as *mut i32, keep as __mmask16, ids)
            }
            #[inline(always)]
            fn count_zero(self) -> __m512i {
                unsafe { _mm512_setzero_si512() }
            }
            #[inline(always)]
            fn count_restart(self, c: __m512i, e: $m) -> __m512i {
                unsafe { $mask_mov(c, e, _mm512_setzero_si512()) }
            }
            #[inline(always)]
            fn count_step(self, c: __m512i) -> __m512i {
                unsafe { $add_int(c, $set1_int(1)) }
            }
            #[inline(always)]
            fn count_is(self, c: __m512i, n: usize) -> $m {
                unsafe { $cmpeq_int(c, $set1_int(n as $int)) }
            }
            #[inline(always)]
            fn positions(self) -> __m512i {
                unsafe { _mm512_setzero_si512() }
            }
            #[inline(always)]
            fn refill(self, pos: __m512i, free: u32, take: usize, next: usize) -> (u32, __m512i) {
                unsafe {
                    let load = _pdep_u32(first(take), free);
                    // The loaded lanes' positions: next + (rank among the loaded).
                    let rank = $maskz_expand(load as $m, $lane_ids);
                    (load, $mask_add(pos, load as $m, rank, $set1_int(next as $int)))
                }
            }
            lanes!(@scatter $elem, $v, $m);
        }
    };
    (@scatter f64, $v:ty, $m:ty) => {
        #[inline(always)]
        unsafe fn scatter(self, base: *mut f64, pos: __m512i, m: u32, v: $v) {
            _mm512_mask_i64scatter_pd::<8>(base, m as $m, pos, v)
        }
        #[inline(always)]
        unsafe fn scatter_indexed(self, base: *mut f64, index: *const u32, n: usize, v: $v) {
            let mut values = [0.0f64; 8];
            _mm512_storeu_pd(values.as_mut_ptr(), v);
            for (l, &x) in values.iter().enumerate().take(n) {
                *base.add(*index.add(l) as usize) = x;
            }
        }
    };
    (@scatter f32, $v:ty, $m:ty) => {
        #[inline(always)]
        unsafe fn scatter(self, base: *mut f32, pos: __m512i, m: u32, v: $v) {
            _mm512_mask_i32scatter_ps::<4>(base, m as $m, pos, v)
        }
        #[inline(always)]
        unsafe fn scatter_indexed(self, base: *mut f32, index: *const u32, n: usize, v: $v) {
            let index = _mm512_maskz_loadu_epi32(first(n) as __mmask16, index as *const i32);
            _mm512_mask_i32scatter_ps::<4>(base, first(n) as $m, index, v)
        }
    };
}

lanes!(
    f64, 8, __m512d, __mmask8, i64,
    set1: _mm512_set1_pd, add: _mm512_add_pd, sub: _mm512_sub_pd, mul: _mm512_mul_pd,
    div: _mm512_div_pd, sqrt: _mm512_sqrt_pd, abs: _mm512_abs_pd, max: _mm512_max_pd,
    cmp: _mm512_cmp_pd_mask, blend: _mm512_mask_blend_pd, loadu: _mm512_loadu_pd,
    maskz_loadu: _mm512_maskz_loadu_pd, storeu: _mm512_storeu_pd,
    mask_storeu: _mm512_mask_storeu_pd, expandloadu: _mm512_mask_expandloadu_pd,
    compressstoreu: _mm512_mask_compressstoreu_pd, cast_to_int: _mm512_castpd_si512,
    cast_from_int: _mm512_castsi512_pd, set1_int: _mm512_set1_epi64,
    xor_int: _mm512_mask_xor_epi64, lane_ids: _mm512_set_epi64(7, 6, 5, 4, 3, 2, 1, 0),
    maskz_expand_int: _mm512_maskz_expand_epi64, mask_add_int: _mm512_mask_add_epi64,
    mask_mov_int: _mm512_mask_mov_epi64, add_int: _mm512_add_epi64,
    cmpeq_int: _mm512_cmpeq_epi64_mask
);

lanes!(
    f32, 16, __m512, __mmask16, i32,
    set1: _mm512_set1_ps, add: _mm512_add_ps, sub: _mm512_sub_ps, mul: _mm512_mul_ps,
    div: _mm512_div_ps, sqrt: _mm512_sqrt_ps, abs: _mm512_abs_ps, max: _mm512_max_ps,
    cmp: _mm512_cmp_ps_mask, blend: _mm512_mask_blend_ps, loadu: _mm512_loadu_ps,
    maskz_loadu: _mm512_maskz_loadu_ps, storeu: _mm512_storeu_ps,
    mask_storeu: _mm512_mask_storeu_ps, expandloadu: _mm512_mask_expandloadu_ps,
    compressstoreu: _mm512_mask_compressstoreu_ps, cast_to_int: _mm512_castps_si512,
    cast_from_int: _mm512_castsi512_ps, set1_int: _mm512_set1_epi32,
    xor_int: _mm512_mask_xor_epi32,
    lane_ids: _mm512_set_epi32(15, 14, 13, 12, 11, 10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 0),
    maskz_expand_int: _mm512_maskz_expand_epi32, mask_add_int: _mm512_mask_add_epi32,
    mask_mov_int: _mm512_mask_mov_epi32, add_int: _mm512_add_epi32,
    cmpeq_int: _mm512_cmpeq_epi32_mask
);
