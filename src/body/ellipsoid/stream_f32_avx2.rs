//! The single-precision stream of [`super::stream_f32`] for CPUs with AVX2 but not
//! AVX-512: 8 lanes to a register. The instructions AVX2 lacks are emulated as in
//! [`super::stream_avx2`]: the expanding load by a permutation table indexed by the
//! lane mask, the compressing store (the queue's set-up, with a cap) by another, the
//! scatters lane by lane. Every arithmetic operation is the AVX-512 kernel's, in its
//! order, so both give the same bits (a test compares them where both run).

use super::stream::BLOCK;
use super::stream_avx2::lane_ranks;
use super::stream_f32::{H_TOLERANCE_F32, ROOT_TOLERANCE_F32};
use super::{SortedPlacement, MAX_ITERATIONS};

/// Registers of 8 lanes iterated together.
const STREAMS: usize = 4;

/// For a mask of the lanes to fill: the source index of each lane for
/// `_mm256_permutevar8x32_ps`, moving entries 0, 1, 2, … of an 8-float load into the
/// set lanes in order (other lanes take entry 0).
const EXPAND: [[i32; 8]; 256] = ranks_table(false);

/// For a mask of lanes to keep: the source lane of each output position, packing the
/// set lanes to the front in order (the rest take lane 0).
const PACK: [[i32; 8]; 256] = ranks_table(true);

/// [`lane_ranks`] of every 8-lane mask: its `pack` half, or its `expand` half.
const fn ranks_table(pack: bool) -> [[i32; 8]; 256] {
    let mut table = [[0i32; 8]; 256];
    let mut mask = 0;
    while mask < 256 {
        let (expand, packed) = lane_ranks(mask, 8);
        table[mask] = if pack { packed } else { expand };
        mask += 1;
    }
    table
}

/// [`super::stream_f32::signed_distances_block_f32`] with AVX2 (same contract).
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
pub unsafe fn signed_distances_block_f32(
    e: &SortedPlacement,
    y: [&[f32]; 3],
    cap: Option<f32>,
    out: &mut [f32],
) {
    use std::arch::x86_64::*;
    use std::mem::MaybeUninit;
    let n = out.len();
    assert!(n <= BLOCK && y.iter().all(|c| c.len() >= n));
    let c = &e.sorted;
    let narrow = |v: [f64; 3]| v.map(|x| x as f32);
    let (inv_e, r, b, ee) = (narrow(c.inv_e), narrow(c.r), narrow(c.b), narrow(c.e));

    // Scratch (see the AVX-512 kernel), each row with 8 entries of slack: the set-up
    // stores whole registers at the queue's end, and the refill loads 8 at a time. The
    // set-up writes every entry up to the queue's end and one register beyond, so every
    // entry a load can reach is written; the rest stays uninitialised.
    const ROW: usize = BLOCK + 16;
    let mut scratch = MaybeUninit::<[[f32; ROW]; 9]>::uninit();
    let base_ptr = scratch.as_mut_ptr() as *mut f32;
    let queue = |k: usize| base_ptr.add(k * ROW);
    let (qa, qlo, qhi, roots) = ([queue(0), queue(1), queue(2)], queue(3), queue(4), queue(5));
    let qy = [queue(6), queue(7), queue(8)];
    let mut index = MaybeUninit::<[i32; ROW]>::uninit();
    let qi = index.as_mut_ptr() as *mut i32;
    let mut planar = [0u64; BLOCK / 64];

    let abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(i32::MAX));
    let abs = |v: __m256| _mm256_and_ps(v, abs_mask);
    let splat = |x: f32| _mm256_set1_ps(x);
    let (one, zero) = (splat(1.0), _mm256_setzero_ps());
    let lane_bits = _mm256_set_epi32(128, 64, 32, 16, 8, 4, 2, 1);
    // All ones in the lanes of `bits`.
    let lane_mask = |bits: usize| -> __m256 {
        let set = _mm256_and_si256(_mm256_set1_epi32(bits as i32), lane_bits);
        _mm256_castsi256_ps(_mm256_cmpeq_epi32(set, lane_bits))
    };
    let table =
        |t: &[[i32; 8]; 256], bits: usize| _mm256_loadu_si256(t[bits].as_ptr() as *const __m256i);
    let bits_of = |v: __m256| _mm256_movemask_ps(v) as usize;
    let lanes = |base: usize| -> usize {
        if n - base >= 8 {
            0xff
        } else {
            (1 << (n - base)) - 1
        }
    };
    let (axes, centre) = (e.axes.map(narrow), narrow(e.centre));
    let first_octant = |base: usize, m: usize| -> [__m256; 3] {
        let mask = _mm256_castps_si256(lane_mask(m));
        let load = |k: usize| _mm256_maskload_ps(y[k].as_ptr().add(base), mask);
        let p = [load(0), load(1), load(2)];
        let d = [
            _mm256_sub_ps(p[0], splat(centre[0])),
            _mm256_sub_ps(p[1], splat(centre[1])),
            _mm256_sub_ps(p[2], splat(centre[2])),
        ];
        std::array::from_fn(|k| {
            let a = axes[k];
            abs(_mm256_add_ps(
                _mm256_add_ps(
                    _mm256_mul_ps(splat(a[0]), d[0]),
                    _mm256_mul_ps(splat(a[1]), d[1]),
                ),
                _mm256_mul_ps(splat(a[2]), d[2]),
            ))
        })
    };

    // Set-up, 8 points at a time.
    let inv_e2 = narrow(e.inv_e2);
    let mut queued = 0;
    for base in (0..n).step_by(8) {
        let m = lanes(base);
        let [ys0, ys1, ys2] = first_octant(base, m);
        let z0 = _mm256_mul_ps(ys0, splat(inv_e[0]));
        let z1 = _mm256_mul_ps(ys1, splat(inv_e[1]));
        let z2 = _mm256_mul_ps(ys2, splat(inv_e[2]));
        let a0 = _mm256_mul_ps(splat(r[0]), z0);
        let a1 = _mm256_mul_ps(splat(r[1]), z1);
        let a2 = z2;
        let mut lo = z2;
        for (z, r) in [(z0, r[0]), (z1, r[1])] {
            let single = _mm256_add_ps(_mm256_mul_ps(splat(r), _mm256_sub_ps(z, one)), one);
            let pos = _mm256_cmp_ps::<_CMP_GT_OQ>(z, zero);
            lo = _mm256_blendv_ps(lo, _mm256_max_ps(lo, single), pos);
        }
        let sq = |v: __m256| _mm256_mul_ps(v, v);
        let hi = _mm256_sqrt_ps(_mm256_add_ps(_mm256_add_ps(sq(a0), sq(a1)), sq(a2)));
        let pair = _mm256_sub_ps(_mm256_sqrt_ps(_mm256_add_ps(sq(a1), sq(a2))), splat(b[1]));
        lo = _mm256_max_ps(_mm256_max_ps(lo, pair), _mm256_sub_ps(hi, splat(b[0])));
        let hi = _mm256_max_ps(hi, lo);
        let mut keep = m;
        if let Some(cap) = cap {
            let level = _mm256_add_ps(
                _mm256_add_ps(
                    _mm256_mul_ps(sq(ys0), splat(inv_e2[0])),
                    _mm256_mul_ps(sq(ys1), splat(inv_e2[1])),
                ),
                _mm256_mul_ps(sq(ys2), splat(inv_e2[2])),
            );
            let norm = _mm256_sqrt_ps(_mm256_add_ps(_mm256_add_ps(sq(ys0), sq(ys1)), sq(ys2)));
            let bound = _mm256_max_ps(
                _mm256_mul_ps(splat(ee[2]), _mm256_sub_ps(_mm256_sqrt_ps(level), one)),
                _mm256_sub_ps(norm, splat(ee[0])),
            );
            let far = m
                & bits_of(_mm256_cmp_ps::<_CMP_GT_OQ>(level, one))
                & bits_of(_mm256_cmp_ps::<_CMP_GE_OQ>(bound, splat(cap)));
            let far_mask = _mm256_castps_si256(lane_mask(far));
            _mm256_maskstore_ps(out.as_mut_ptr().add(base), far_mask, bound);
            keep &= !far;
        }
        let flat_v = _mm256_and_ps(_mm256_cmp_ps::<_CMP_EQ_OQ>(ys2, zero), lane_mask(keep));
        let flat = bits_of(flat_v);
        // The kept lanes packed to the front, stored at the queue's end.
        let at = queued;
        let pack = table(&PACK, keep);
        let mut rank = 0;
        for lane in 0..8 {
            if keep & (1 << lane) != 0 {
                if flat & (1 << lane) != 0 {
                    planar[(at + rank) / 64] |= 1 << ((at + rank) % 64);
                }
                rank += 1;
            }
        }
        let store = |dst: *mut f32, v: __m256| {
            _mm256_storeu_ps(dst.add(at), _mm256_permutevar8x32_ps(v, pack))
        };
        store(qa[0], _mm256_blendv_ps(a0, zero, flat_v));
        store(qa[1], _mm256_blendv_ps(a1, zero, flat_v));
        store(qa[2], _mm256_blendv_ps(a2, one, flat_v));
        store(qlo, _mm256_blendv_ps(lo, one, flat_v));
        store(qhi, _mm256_blendv_ps(hi, one, flat_v));
        store(qy[0], ys0);
        store(qy[1], ys1);
        store(qy[2], ys2);
        let ids = _mm256_add_epi32(
            _mm256_set_epi32(7, 6, 5, 4, 3, 2, 1, 0),
            _mm256_set1_epi32(base as i32),
        );
        _mm256_storeu_si256(
            qi.add(at) as *mut __m256i,
            _mm256_permutevar8x32_epi32(ids, pack),
        );
        queued += keep.count_ones() as usize;
    }
    // One register of harmless padding past the queue's end for the refill's loads.
    for q in [qa[0], qa[1], qa[2], qlo, qhi] {
        _mm256_storeu_ps(q.add(queued), one);
    }

    // The stream (see the AVX-512 kernels).
    let (b0, b1, b2) = (splat(b[0]), splat(b[1]), splat(b[2]));
    let (half, h_tol, root_tol) = (
        splat(0.5),
        splat(H_TOLERANCE_F32),
        splat(ROOT_TOLERANCE_F32),
    );
    let last_pass = _mm256_set1_epi32(MAX_ITERATIONS as i32);
    let step = _mm256_set1_epi32(1);
    type V = [__m256; STREAMS];
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
    let mut at = [[0usize; 8]; STREAMS];
    let mut passes = [_mm256_setzero_si256(); STREAMS];
    let mut going = [0usize; STREAMS];
    let mut next = 0usize;
    loop {
        for g in 0..STREAMS {
            let free = !going[g] & 0xff;
            if next < queued && free != 0 {
                let take = (free.count_ones() as usize).min(queued - next);
                let mut load = 0;
                let mut rest = free;
                for rank in 0..take {
                    let lane = rest.trailing_zeros() as usize;
                    rest &= rest - 1;
                    load |= 1 << lane;
                    at[g][lane] = next + rank;
                }
                let perm = table(&EXPAND, load);
                let fill = lane_mask(load);
                let from = |q: *const f32, v: __m256| {
                    let moved = _mm256_permutevar8x32_ps(_mm256_loadu_ps(q.add(next)), perm);
                    _mm256_blendv_ps(v, moved, fill)
                };
                a0[g] = from(qa[0], a0[g]);
                a1[g] = from(qa[1], a1[g]);
                a2[g] = from(qa[2], a2[g]);
                lo[g] = from(qlo, lo[g]);
                hi[g] = from(qhi, hi[g]);
                u[g] = _mm256_blendv_ps(u[g], lo[g], fill);
                passes[g] = _mm256_andnot_si256(_mm256_castps_si256(fill), passes[g]);
                going[g] |= load;
                next += take;
            }
        }
        if going.iter().all(|&g| g == 0) {
            break;
        }
        let t0 = each(|g| _mm256_add_ps(u[g], b0));
        let t1 = each(|g| _mm256_add_ps(u[g], b1));
        let t2 = each(|g| _mm256_add_ps(u[g], b2));
        let p01 = each(|g| _mm256_mul_ps(t0[g], t1[g]));
        let inv = each(|g| _mm256_div_ps(one, _mm256_mul_ps(p01[g], t2[g])));
        let r2 = each(|g| _mm256_mul_ps(inv[g], p01[g]));
        let inv = each(|g| _mm256_mul_ps(inv[g], t2[g]));
        let r1 = each(|g| _mm256_mul_ps(inv[g], t0[g]));
        let r0 = each(|g| _mm256_mul_ps(inv[g], t1[g]));
        let sq = |v: __m256| _mm256_mul_ps(v, v);
        let q0 = each(|g| sq(_mm256_mul_ps(a0[g], r0[g])));
        let q1 = each(|g| sq(_mm256_mul_ps(a1[g], r1[g])));
        let q2 = each(|g| sq(_mm256_mul_ps(a2[g], r2[g])));
        let sum = each(|g| _mm256_add_ps(_mm256_add_ps(q0[g], q1[g]), q2[g]));
        let ds = each(|g| {
            _mm256_add_ps(
                _mm256_add_ps(_mm256_mul_ps(q0[g], r0[g]), _mm256_mul_ps(q1[g], r1[g])),
                _mm256_mul_ps(q2[g], r2[g]),
            )
        });
        let root = each(|g| _mm256_sqrt_ps(sum[g]));
        let root_m1 = each(|g| _mm256_sub_ps(root[g], one));
        let newton = each(|g| {
            _mm256_add_ps(
                u[g],
                _mm256_div_ps(_mm256_mul_ps(sum[g], root_m1[g]), ds[g]),
            )
        });
        for g in 0..STREAMS {
            let at_root = _mm256_cmp_ps::<_CMP_LE_OQ>(abs(root_m1[g]), h_tol);
            let above = _mm256_cmp_ps::<_CMP_GT_OQ>(root[g], one);
            let lo_n = _mm256_blendv_ps(lo[g], u[g], above);
            let hi_n = _mm256_blendv_ps(u[g], hi[g], above);
            let inside = _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GT_OQ>(newton[g], lo_n),
                _mm256_cmp_ps::<_CMP_LT_OQ>(newton[g], hi_n),
            );
            let bisect = _mm256_mul_ps(half, _mm256_add_ps(lo_n, hi_n));
            let step_to = _mm256_blendv_ps(bisect, newton[g], inside);
            let small = _mm256_or_ps(
                _mm256_cmp_ps::<_CMP_LE_OQ>(
                    abs(_mm256_sub_ps(step_to, u[g])),
                    _mm256_mul_ps(root_tol, abs(u[g])),
                ),
                _mm256_cmp_ps::<_CMP_LE_OQ>(_mm256_sub_ps(hi_n, lo_n), _mm256_mul_ps(h_tol, hi_n)),
            );
            passes[g] = _mm256_add_epi32(passes[g], step);
            let last = _mm256_castsi256_ps(_mm256_cmpeq_epi32(passes[g], last_pass));
            let done = going[g] & bits_of(_mm256_or_ps(_mm256_or_ps(at_root, small), last));
            if done != 0 {
                let mut result = [0.0f32; 8];
                _mm256_storeu_ps(
                    result.as_mut_ptr(),
                    _mm256_blendv_ps(step_to, u[g], at_root),
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
            u[g] = _mm256_blendv_ps(u[g], step_to, keep);
            lo[g] = _mm256_blendv_ps(lo[g], lo_n, keep);
            hi[g] = _mm256_blendv_ps(hi[g], hi_n, keep);
            going[g] = go;
        }
    }

    // Finish, 8 queued points at a time, written to the points' places.
    let sign_bit = _mm256_castsi256_ps(_mm256_set1_epi32(i32::MIN));
    for base in (0..queued).step_by(8) {
        let m = if queued - base >= 8 {
            0xff
        } else {
            (1 << (queued - base)) - 1
        };
        let mask = _mm256_castps_si256(lane_mask(m));
        let from = |q: *const f32| _mm256_maskload_ps(q.add(base), mask);
        let (ys0, ys1, ys2) = (from(qy[0]), from(qy[1]), from(qy[2]));
        let u = from(roots);
        let (t0, t1, t2) = (
            _mm256_add_ps(u, b0),
            _mm256_add_ps(u, b1),
            _mm256_add_ps(u, b2),
        );
        let p01 = _mm256_mul_ps(t0, t1);
        let inv = _mm256_div_ps(one, _mm256_mul_ps(p01, t2));
        let r2 = _mm256_mul_ps(inv, p01);
        let inv = _mm256_mul_ps(inv, t2);
        let r1 = _mm256_mul_ps(inv, t0);
        let r0 = _mm256_mul_ps(inv, t1);
        let x = |k: usize, r: __m256| _mm256_mul_ps(_mm256_mul_ps(splat(ee[k]), from(qa[k])), r);
        let (x0, x1, x2) = (x(0, r0), x(1, r1), x(2, r2));
        let sq = |v: __m256| _mm256_mul_ps(v, v);
        let d = _mm256_sqrt_ps(_mm256_add_ps(
            _mm256_add_ps(sq(_mm256_sub_ps(ys0, x0)), sq(_mm256_sub_ps(ys1, x1))),
            sq(_mm256_sub_ps(ys2, x2)),
        ));
        let level = _mm256_add_ps(
            _mm256_add_ps(
                _mm256_mul_ps(sq(ys0), splat(inv_e2[0])),
                _mm256_mul_ps(sq(ys1), splat(inv_e2[1])),
            ),
            _mm256_mul_ps(sq(ys2), splat(inv_e2[2])),
        );
        let inside = _mm256_cmp_ps::<_CMP_LT_OQ>(level, one);
        let signed = _mm256_xor_ps(d, _mm256_and_ps(inside, sign_bit));
        if cap.is_none() {
            // Every point was queued: queue position = point index.
            _mm256_maskstore_ps(out.as_mut_ptr().add(base), mask, signed);
        } else {
            let mut values = [0.0f32; 8];
            _mm256_storeu_ps(values.as_mut_ptr(), signed);
            for (lane, &v) in values.iter().enumerate().take(m.count_ones() as usize) {
                out[*qi.add(base + lane) as usize] = v;
            }
        }
    }
    for (w, &bits) in planar.iter().enumerate() {
        let mut bits = bits;
        while bits != 0 {
            let i = *qi.add(64 * w + bits.trailing_zeros() as usize) as usize;
            bits &= bits - 1;
            let p = [y[0][i] as f64, y[1][i] as f64, y[2][i] as f64];
            out[i] = e.signed_distance(&p) as f32;
        }
    }
}
