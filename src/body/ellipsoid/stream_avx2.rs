//! The stream root-finder of [`super::stream`] for CPUs with AVX2 but not AVX-512:
//! 4 lanes to a register, and the two instructions AVX2 lacks emulated.
//!
//! - The expanding load (the next queued points into exactly the free lanes) is a plain
//!   load of the next 4 queue entries, permuted by a table indexed by the lane mask
//!   ([`EXPAND`]) and blended into the free lanes.
//! - The scatter of finished roots goes lane by lane.
//!
//! Everything else — set-up, pass, stopping rule, finish — is the AVX-512 kernel's,
//! operation for operation, so the results are bit-identical to it and to the scalar
//! code (a test checks it).

use super::stream::BLOCK;
use super::{
    closest_sorted, reciprocals_avx2, SortedPlacement, H_TOLERANCE, MAX_ITERATIONS, ROOT_TOLERANCE,
};

/// Registers of 4 lanes iterated together.
const STREAMS: usize = 4;

/// For a mask of `lanes` lanes (bit l = lane l): `expand[l]` = the rank of lane l among
/// the set lanes (0 for an unset lane), and `pack[r]` = the r-th set lane (0 past the
/// last). The permutation tables of the AVX2 kernels are made from these.
pub(super) const fn lane_ranks(mask: usize, lanes: usize) -> ([i32; 8], [i32; 8]) {
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

/// For a mask of the lanes to fill (bit l = lane l): the 32-bit source indices of
/// `_mm256_permutevar8x32_ps` that move entries 0, 1, 2, … of a 4-double load into
/// those lanes, in lane order (unfilled lanes take entry 0).
const EXPAND: [[i32; 8]; 16] = {
    let mut table = [[0i32; 8]; 16];
    let mut mask = 0;
    while mask < 16 {
        let rank = lane_ranks(mask, 4).0;
        let mut lane = 0;
        while lane < 4 {
            table[mask][2 * lane] = 2 * rank[lane];
            table[mask][2 * lane + 1] = 2 * rank[lane] + 1;
            lane += 1;
        }
        mask += 1;
    }
    table
};

/// For a mask of lanes: all ones in those lanes (as 64-bit integers), for blends.
const LANE_MASKS: [[i64; 4]; 16] = {
    let mut table = [[0i64; 4]; 16];
    let mut mask = 0;
    while mask < 16 {
        let mut lane = 0;
        while lane < 4 {
            if mask & (1 << lane) != 0 {
                table[mask][lane] = -1;
            }
            lane += 1;
        }
        mask += 1;
    }
    table
};

/// [`super::stream::distances_block`] with AVX2: `d[i]` = the signed distance to `e` of
/// the local point `(y0[i], y1[i], y2[i])` and with `NORMALS` `normal[c][i]` = the
/// camera-frame outward unit normal, for every `i < y[0].len()` (≤ [`BLOCK`]).
///
/// # Safety
/// The CPU must support AVX2; `d` and (with `NORMALS`) each
/// `normal[c]` must be valid for writing `y[0].len()` values (they may be
/// uninitialised: they are only written).
#[target_feature(enable = "avx2")]
pub unsafe fn distances_block<const NORMALS: bool>(
    e: &SortedPlacement,
    y: [&[f64]; 3],
    d: *mut f64,
    normal: [*mut f64; 3],
) {
    use std::arch::x86_64::*;
    use std::mem::MaybeUninit;
    let n = y[0].len();
    assert!(n <= BLOCK && y.iter().all(|c| c.len() == n));
    let c = &e.sorted;

    // Scratch: the queue (numerators and bracket, in point order, with 4 entries of
    // padding that the refill's 4-wide loads may read), then the roots by point. The
    // set-up writes whole registers up to n rounded up to 4 and the padding is zeroed,
    // so every entry a load can reach is written; the rest stays uninitialised.
    const ROW: usize = BLOCK + 8;
    let mut scratch = MaybeUninit::<[[f64; ROW]; 6]>::uninit();
    let base_ptr = scratch.as_mut_ptr() as *mut f64;
    let queue = |k: usize| base_ptr.add(k * ROW);
    let (qa, qlo, qhi, roots) = ([queue(0), queue(1), queue(2)], queue(3), queue(4), queue(5));
    let mut planar = [0u64; BLOCK / 64];

    let abs_mask = _mm256_castsi256_pd(_mm256_set1_epi64x(i64::MAX));
    let abs = |v: __m256d| _mm256_and_pd(v, abs_mask);
    let splat = |x: f64| _mm256_set1_pd(x);
    let (one, zero) = (splat(1.0), _mm256_setzero_pd());
    let lane_mask = |bits: usize| {
        _mm256_castsi256_pd(_mm256_loadu_si256(
            LANE_MASKS[bits].as_ptr() as *const __m256i
        ))
    };
    let lanes = |base: usize| -> usize {
        if n - base >= 4 {
            0xf
        } else {
            (1 << (n - base)) - 1
        }
    };
    let load_y = |k: usize, base: usize, m: usize| {
        _mm256_maskload_pd(y[k].as_ptr().add(base), _mm256_castpd_si256(lane_mask(m)))
    };

    // Set-up, 4 points at a time: `Sorted::secular_setup` of |y|.
    for base in (0..n).step_by(4) {
        let m = lanes(base);
        let [ys0, ys1, ys2] = [0, 1, 2].map(|k| abs(load_y(k, base, m)));
        let z0 = _mm256_mul_pd(ys0, splat(c.inv_e[0]));
        let z1 = _mm256_mul_pd(ys1, splat(c.inv_e[1]));
        let z2 = _mm256_mul_pd(ys2, splat(c.inv_e[2]));
        let a0 = _mm256_mul_pd(splat(c.r[0]), z0);
        let a1 = _mm256_mul_pd(splat(c.r[1]), z1);
        let a2 = z2;
        let mut lo = z2;
        // lo = lo.max(r_k (z_k − 1) + 1) where z_k > 0 (`vmaxpd`, as the AVX-512 kernel).
        for (z, r) in [(z0, c.r[0]), (z1, c.r[1])] {
            let single = _mm256_add_pd(_mm256_mul_pd(splat(r), _mm256_sub_pd(z, one)), one);
            let pos = _mm256_cmp_pd::<_CMP_GT_OQ>(z, zero);
            lo = _mm256_blendv_pd(lo, _mm256_max_pd(lo, single), pos);
        }
        let max = |a: __m256d, b: __m256d| _mm256_max_pd(a, b);
        let sq = |v: __m256d| _mm256_mul_pd(v, v);
        let hi = _mm256_sqrt_pd(_mm256_add_pd(_mm256_add_pd(sq(a0), sq(a1)), sq(a2)));
        let pair = _mm256_sub_pd(_mm256_sqrt_pd(_mm256_add_pd(sq(a1), sq(a2))), splat(c.b[1]));
        lo = max(max(lo, pair), _mm256_sub_pd(hi, splat(c.b[0])));
        let hi = max(hi, lo);
        // A planar point gets a trivial problem (a = (0, 0, 1), lo = hi = 1), and its
        // distance from the scalar path below.
        let flat_v = _mm256_and_pd(_mm256_cmp_pd::<_CMP_EQ_OQ>(ys2, zero), lane_mask(m));
        let flat = _mm256_movemask_pd(flat_v) as u64;
        planar[base / 64] |= flat << (base % 64);
        let store = |dst: *mut f64, v: __m256d| _mm256_storeu_pd(dst.add(base), v);
        store(qa[0], _mm256_blendv_pd(a0, zero, flat_v));
        store(qa[1], _mm256_blendv_pd(a1, zero, flat_v));
        store(qa[2], _mm256_blendv_pd(a2, one, flat_v));
        store(qlo, _mm256_blendv_pd(lo, one, flat_v));
        store(qhi, _mm256_blendv_pd(hi, one, flat_v));
    }
    let written = n.div_ceil(4) * 4;
    for q in [qa[0], qa[1], qa[2], qlo, qhi] {
        _mm256_storeu_pd(q.add(written), one);
    }

    // The stream (see the AVX-512 kernel).
    let (b0, b1, b2) = (splat(c.b[0]), splat(c.b[1]), splat(c.b[2]));
    let (half, h_tol, root_tol) = (splat(0.5), splat(H_TOLERANCE), splat(ROOT_TOLERANCE));
    let cap = _mm256_set1_epi64x(MAX_ITERATIONS as i64);
    let step = _mm256_set1_epi64x(1);
    type V = [__m256d; STREAMS];
    #[inline(always)]
    fn each<T>(f: impl FnMut(usize) -> T) -> [T; STREAMS] {
        std::array::from_fn(f)
    }
    let mut u: V = [zero; STREAMS];
    let mut lo: V = [zero; STREAMS];
    let mut hi: V = [zero; STREAMS];
    let mut a0: V = [zero; STREAMS];
    let mut a1: V = [zero; STREAMS];
    let mut a2: V = [zero; STREAMS];
    let mut at = [[0usize; 4]; STREAMS];
    let mut passes = [_mm256_setzero_si256(); STREAMS];
    let mut going = [0usize; STREAMS];
    let mut next = 0usize;
    loop {
        for g in 0..STREAMS {
            let free = !going[g] & 0xf;
            if next < n && free != 0 {
                // The first `take` free lanes.
                let take = (free.count_ones() as usize).min(n - next);
                let mut load = 0;
                let mut rest = free;
                for rank in 0..take {
                    let lane = rest.trailing_zeros() as usize;
                    rest &= rest - 1;
                    load |= 1 << lane;
                    at[g][lane] = next + rank;
                }
                let perm = _mm256_loadu_si256(EXPAND[load].as_ptr() as *const __m256i);
                let fill = lane_mask(load);
                let from = |q: *const f64, v: __m256d| {
                    let entries = _mm256_castpd_ps(_mm256_loadu_pd(q.add(next)));
                    let moved = _mm256_castps_pd(_mm256_permutevar8x32_ps(entries, perm));
                    _mm256_blendv_pd(v, moved, fill)
                };
                a0[g] = from(qa[0], a0[g]);
                a1[g] = from(qa[1], a1[g]);
                a2[g] = from(qa[2], a2[g]);
                lo[g] = from(qlo, lo[g]);
                hi[g] = from(qhi, hi[g]);
                u[g] = _mm256_blendv_pd(u[g], lo[g], fill);
                passes[g] = _mm256_andnot_si256(_mm256_castpd_si256(fill), passes[g]);
                going[g] |= load;
                next += take;
            }
        }
        if going.iter().all(|&g| g == 0) {
            break;
        }
        // `reciprocals_avx2` written out operation by operation over the registers, so
        // that their dependency chains interleave (see the AVX-512 kernel).
        let t0 = each(|g| _mm256_add_pd(u[g], b0));
        let t1 = each(|g| _mm256_add_pd(u[g], b1));
        let t2 = each(|g| _mm256_add_pd(u[g], b2));
        let p01 = each(|g| _mm256_mul_pd(t0[g], t1[g]));
        let inv = each(|g| _mm256_div_pd(one, _mm256_mul_pd(p01[g], t2[g])));
        let r2 = each(|g| _mm256_mul_pd(inv[g], p01[g]));
        let inv = each(|g| _mm256_mul_pd(inv[g], t2[g]));
        let r1 = each(|g| _mm256_mul_pd(inv[g], t0[g]));
        let r0 = each(|g| _mm256_mul_pd(inv[g], t1[g]));
        let sq = |v: __m256d| _mm256_mul_pd(v, v);
        let q0 = each(|g| sq(_mm256_mul_pd(a0[g], r0[g])));
        let q1 = each(|g| sq(_mm256_mul_pd(a1[g], r1[g])));
        let q2 = each(|g| sq(_mm256_mul_pd(a2[g], r2[g])));
        let sum = each(|g| _mm256_add_pd(_mm256_add_pd(q0[g], q1[g]), q2[g]));
        let ds = each(|g| {
            _mm256_add_pd(
                _mm256_add_pd(_mm256_mul_pd(q0[g], r0[g]), _mm256_mul_pd(q1[g], r1[g])),
                _mm256_mul_pd(q2[g], r2[g]),
            )
        });
        let root = each(|g| _mm256_sqrt_pd(sum[g]));
        let root_m1 = each(|g| _mm256_sub_pd(root[g], one));
        let newton = each(|g| {
            _mm256_add_pd(
                u[g],
                _mm256_div_pd(_mm256_mul_pd(sum[g], root_m1[g]), ds[g]),
            )
        });
        for g in 0..STREAMS {
            let at_root = _mm256_cmp_pd::<_CMP_LE_OQ>(abs(root_m1[g]), h_tol);
            let above = _mm256_cmp_pd::<_CMP_GT_OQ>(root[g], one);
            let lo_n = _mm256_blendv_pd(lo[g], u[g], above);
            let hi_n = _mm256_blendv_pd(u[g], hi[g], above);
            let inside = _mm256_and_pd(
                _mm256_cmp_pd::<_CMP_GT_OQ>(newton[g], lo_n),
                _mm256_cmp_pd::<_CMP_LT_OQ>(newton[g], hi_n),
            );
            let bisect = _mm256_mul_pd(half, _mm256_add_pd(lo_n, hi_n));
            let step_to = _mm256_blendv_pd(bisect, newton[g], inside);
            let small = _mm256_or_pd(
                _mm256_cmp_pd::<_CMP_LE_OQ>(
                    abs(_mm256_sub_pd(step_to, u[g])),
                    _mm256_mul_pd(root_tol, abs(u[g])),
                ),
                _mm256_cmp_pd::<_CMP_LE_OQ>(_mm256_sub_pd(hi_n, lo_n), _mm256_mul_pd(h_tol, hi_n)),
            );
            passes[g] = _mm256_add_epi64(passes[g], step);
            let last = _mm256_castsi256_pd(_mm256_cmpeq_epi64(passes[g], cap));
            let stop = _mm256_or_pd(_mm256_or_pd(at_root, small), last);
            let done = going[g] & _mm256_movemask_pd(stop) as usize;
            if done != 0 {
                // A lane at the root returns u; one with a small step (or capped), next.
                let mut result = [0.0f64; 4];
                _mm256_storeu_pd(
                    result.as_mut_ptr(),
                    _mm256_blendv_pd(step_to, u[g], at_root),
                );
                let mut bits = done;
                while bits != 0 {
                    let lane = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    *roots.add(at[g][lane]) = result[lane];
                }
            }
            let go = going[g] & !done;
            let keep = lane_mask(go);
            u[g] = _mm256_blendv_pd(u[g], step_to, keep);
            lo[g] = _mm256_blendv_pd(lo[g], lo_n, keep);
            hi[g] = _mm256_blendv_pd(hi[g], hi_n, keep);
            going[g] = go;
        }
    }

    // Finish, 4 points at a time (see the AVX-512 kernel).
    let (inv_e2, axes) = (e.inv_e2, e.axes);
    let sign_bit = _mm256_castsi256_pd(_mm256_set1_epi64x(i64::MIN));
    for base in (0..n).step_by(4) {
        let m = lanes(base);
        let mask = _mm256_castpd_si256(lane_mask(m));
        let from = |q: *const f64| _mm256_loadu_pd(q.add(base));
        let u = _mm256_maskload_pd(roots.add(base), mask);
        let [r0, r1, r2] = reciprocals_avx2(u, [b0, b1, b2]);
        let closest =
            |k: usize, r: __m256d| _mm256_mul_pd(_mm256_mul_pd(splat(c.e[k]), from(qa[k])), r);
        let x = [closest(0, r0), closest(1, r1), closest(2, r2)];
        let yl = [0, 1, 2].map(|k| load_y(k, base, m));
        let ys = yl.map(abs);
        let sq = |v: __m256d| _mm256_mul_pd(v, v);
        let dist = _mm256_sqrt_pd(_mm256_add_pd(
            _mm256_add_pd(
                sq(_mm256_sub_pd(ys[0], x[0])),
                sq(_mm256_sub_pd(ys[1], x[1])),
            ),
            sq(_mm256_sub_pd(ys[2], x[2])),
        ));
        let level = _mm256_add_pd(
            _mm256_add_pd(
                _mm256_mul_pd(sq(ys[0]), splat(inv_e2[0])),
                _mm256_mul_pd(sq(ys[1]), splat(inv_e2[1])),
            ),
            _mm256_mul_pd(sq(ys[2]), splat(inv_e2[2])),
        );
        // Negative inside: flip the sign bit (as the scalar `-d` does).
        let inside = _mm256_cmp_pd::<_CMP_LT_OQ>(level, one);
        let signed = _mm256_xor_pd(dist, _mm256_and_pd(inside, sign_bit));
        _mm256_maskstore_pd(d.add(base), mask, signed);
        if NORMALS {
            // g_k = copysign(x_k, y_k) / e_k² (x_k ≥ +0, so the sign bit of y_k is
            // or-ed in), normalised, turned to the camera frame.
            let g: [__m256d; 3] = std::array::from_fn(|k| {
                let signed = _mm256_or_pd(x[k], _mm256_and_pd(yl[k], sign_bit));
                _mm256_mul_pd(signed, splat(inv_e2[k]))
            });
            let inv = _mm256_div_pd(
                one,
                _mm256_sqrt_pd(_mm256_add_pd(_mm256_add_pd(sq(g[0]), sq(g[1])), sq(g[2]))),
            );
            for (col, out) in normal.iter().enumerate() {
                let v = _mm256_add_pd(
                    _mm256_add_pd(
                        _mm256_mul_pd(g[0], splat(axes[0][col])),
                        _mm256_mul_pd(g[1], splat(axes[1][col])),
                    ),
                    _mm256_mul_pd(g[2], splat(axes[2][col])),
                );
                _mm256_maskstore_pd(out.add(base), mask, _mm256_mul_pd(v, inv));
            }
        }
    }
    for (w, &bits) in planar.iter().enumerate() {
        let mut bits = bits;
        while bits != 0 {
            let i = 64 * w + bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let yi = [y[0][i], y[1][i], y[2][i]];
            let ys = [yi[0].abs(), yi[1].abs(), yi[2].abs()];
            let x = closest_sorted(c, ys);
            *d.add(i) = e.signed_from_closest(&ys, &x);
            if NORMALS {
                for (out, v) in normal.iter().zip(e.normal_at(&yi, &x)) {
                    *out.add(i) = v;
                }
            }
        }
    }
}
