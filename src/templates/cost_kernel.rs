//! The SIMD kernels of the cost matrix ([`super::cost`]), one per vector width.

use super::columns::QueryColumns;
use crate::descriptor::SurfaceContext;

/// Writes a cost-rows kernel for one vector width: 4 template samples × 2 vectors of
/// query samples give 8 independent FMA chains along the descriptor. Every lane sums in
/// the same order with the same fused operations whatever the width, so the kernels
/// agree bit for bit (tested). Returns the number of rows written, a multiple of 4 (the
/// rest are left to the caller).
macro_rules! cost_rows_kernel {
    (
        $(#[$doc:meta])*
        $name:ident, $feature:literal, $lanes:literal,
        zero: $zero:ident, set1: $set1:ident, load: $load:ident, store: $store:ident,
        sub: $sub:ident, add: $add:ident, mul: $mul:ident, fmadd: $fmadd:ident,
        sqrt: $sqrt:ident
    ) => {
        $(#[$doc])*
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $feature)]
        pub(super) unsafe fn $name(
            columns: &QueryColumns,
            t: &SurfaceContext,
            lw: f32,
            n: usize,
            cost: &mut [f64],
        ) -> usize {
            use std::arch::x86_64::*;
            const LANES: usize = $lanes;
            let (stride, dim) = (columns.stride, t.dim);
            assert!(
                columns.values.len() >= dim * stride
                    && stride >= n
                    && stride.is_multiple_of(2 * LANES)
                    && columns.x.len() >= stride
                    && columns.y.len() >= stride
                    && cost.len() >= n * t.len()
            );
            let quads = t.len() / 4 * 4;
            let lwv = $set1(lw);
            let mut out = [0.0f32; LANES];
            for j0 in (0..quads).step_by(4) {
                let b: [&[f32]; 4] = std::array::from_fn(|k| t.descriptor(j0 + k));
                for i0 in (0..n).step_by(2 * LANES) {
                    let mut acc = [[$zero(); 2]; 4];
                    for d in 0..dim {
                        // SAFETY: d·stride + i0 + 2·LANES <= dim·stride (i0 < n <=
                        // stride, stride a multiple of 2·LANES), asserted above.
                        let col = columns.values.as_ptr().add(d * stride + i0);
                        let q = [$load(col), $load(col.add(LANES))];
                        for (acc, b) in acc.iter_mut().zip(&b) {
                            let bd = $set1(*b.get_unchecked(d));
                            for (a, &q) in acc.iter_mut().zip(&q) {
                                let e = $sub(q, bd);
                                *a = $fmadd(e, e, *a);
                            }
                        }
                    }
                    for (k, acc) in acc.iter().enumerate() {
                        let j = j0 + k;
                        let (tx, ty) = ($set1(t.positions[j][0]), $set1(t.positions[j][1]));
                        for (h, &a) in acc.iter().enumerate() {
                            let i = i0 + LANES * h;
                            if i >= n {
                                break;
                            }
                            // SAFETY: i + LANES <= stride <= the lengths of x and y.
                            let dx = $sub($load(columns.x.as_ptr().add(i)), tx);
                            let dy = $sub($load(columns.y.as_ptr().add(i)), ty);
                            let loc = $sqrt($add($mul(dx, dx), $mul(dy, dy)));
                            let c = $add($sqrt(a), $mul(lwv, loc));
                            $store(out.as_mut_ptr(), c);
                            let row = &mut cost[j * n + i..j * n + n.min(i + LANES)];
                            for (o, &v) in row.iter_mut().zip(&out) {
                                *o = v as f64;
                            }
                        }
                    }
                }
            }
            quads
        }
    };
}

cost_rows_kernel!(
    /// The rows of [`cost_matrix`] for the template samples in groups of 4, with AVX2
    /// and FMA (8 query samples per vector).
    cost_rows_fma, "avx2,fma", 8,
    zero: _mm256_setzero_ps, set1: _mm256_set1_ps, load: _mm256_loadu_ps,
    store: _mm256_storeu_ps, sub: _mm256_sub_ps, add: _mm256_add_ps,
    mul: _mm256_mul_ps, fmadd: _mm256_fmadd_ps, sqrt: _mm256_sqrt_ps
);

cost_rows_kernel!(
    /// [`cost_rows_fma`] with AVX-512: 16 query samples per vector.
    cost_rows_avx512, "avx512f", 16,
    zero: _mm512_setzero_ps, set1: _mm512_set1_ps, load: _mm512_loadu_ps,
    store: _mm512_storeu_ps, sub: _mm512_sub_ps, add: _mm512_add_ps,
    mul: _mm512_mul_ps, fmadd: _mm512_fmadd_ps, sqrt: _mm512_sqrt_ps
);
