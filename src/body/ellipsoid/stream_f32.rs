//! The stream root-finder of [`super::stream`] in single precision: 16 lanes to an
//! AVX-512 register instead of 8, and a division or square root of 16 lanes issues
//! as fast as one of 8 doubles, so a distance costs about half as much.
//!
//! For [`crate::body::BodyModel::distances`], which takes f32 points and returns f32
//! distances, so the f64 solve's extra digits are mostly lost anyway. Single precision
//! rounding keeps the distances within about 3e-7 × max(1 m, |d|) of the f64 solve's,
//! a few units in the last place of the f32 result. A test bounds the difference by
//! 2e-6 m on clouds up to 6 m from the camera; the issue asks 1e-5 m against a dense
//! surface sampling. The fit keeps the f64 solver, whose results are bit-identical
//! across its scalar, lockstep and stream forms.
//!
//! The arithmetic is the f64 kernel's, with two single-precision tolerances: a root is
//! accepted when |H| ≤ 4 ε₃₂, and Newton stops after a step below 1e-4 relative (the
//! iterate is then off by about (1e-4)², under ε₃₂; the f64 tolerance of 1e-6 would
//! ask the iteration to chase rounding noise).

use super::stream::BLOCK;
use super::{SortedPlacement, MAX_ITERATIONS};

/// Registers of 16 lanes iterated together.
const STREAMS: usize = 4;
/// |H| below this is a root to single-precision rounding.
pub(super) const H_TOLERANCE_F32: f32 = 4.0 * f32::EPSILON;
/// Newton/bisection stops when the step is below this relative size.
pub(super) const ROOT_TOLERANCE_F32: f32 = 1e-4;

/// `out[i]` = signed distance to `e` of camera-frame point `(y0[i], y1[i], y2[i])`, for
/// every `i < out.len()` (≤ [`BLOCK`]; the inputs at least as long), solved in single
/// precision (within ~3e-7 × max(1 m, |d|) of [`SortedPlacement::signed_distance`]).
///
/// With a `cap`, a point whose distance lower bound
/// ([`SortedPlacement::distance_lower_bound`], here in f32) reaches it gets that bound
/// and skips the solve; the others are queued, so the stream only sees the points whose
/// exact distance is wanted, and get the same value as without a cap.
///
/// # Safety
/// The CPU must support AVX-512F and BMI2 (see [`super::stream::kernel`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,bmi2")]
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

    // Scratch, written before it is read (left uninitialised: zeroing it cost more
    // than a tenth of the call). The queue, in point order: numerators and bracket,
    // |local coordinates| and the point's index; then the roots, by queue position.
    let mut scratch = MaybeUninit::<[[f32; BLOCK]; 9]>::uninit();
    let base_ptr = scratch.as_mut_ptr() as *mut f32;
    let queue = |k: usize| base_ptr.add(k * BLOCK);
    let (qa, qlo, qhi, roots) = ([queue(0), queue(1), queue(2)], queue(3), queue(4), queue(5));
    let qy = [queue(6), queue(7), queue(8)];
    let mut index = MaybeUninit::<[i32; BLOCK]>::uninit();
    let qi = index.as_mut_ptr() as *mut i32;
    // Queued points on the plane y2 = 0 (bit j of word j / 64 for queue position j)
    // take the scalar special cases.
    let mut planar = [0u64; BLOCK / 64];
    let lane_ids = _mm512_set_epi32(15, 14, 13, 12, 11, 10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 0);

    let abs = |v: __m512| _mm512_abs_ps(v);
    let splat = |x: f32| _mm512_set1_ps(x);
    let (one, zero) = (splat(1.0), _mm512_setzero_ps());
    let lanes = |base: usize| -> __mmask16 {
        if n - base >= 16 {
            0xffff
        } else {
            (1u16 << (n - base)) - 1
        }
    };
    // |local coordinates| of the points base.. (masked by m), the scalar expressions.
    let (axes, centre) = (e.axes.map(narrow), narrow(e.centre));
    let first_octant = |base: usize, m: __mmask16| -> [__m512; 3] {
        let load = |k: usize| _mm512_maskz_loadu_ps(m, y[k].as_ptr().add(base));
        let p = [load(0), load(1), load(2)];
        let d = [
            _mm512_sub_ps(p[0], splat(centre[0])),
            _mm512_sub_ps(p[1], splat(centre[1])),
            _mm512_sub_ps(p[2], splat(centre[2])),
        ];
        std::array::from_fn(|k| {
            let a = axes[k];
            abs(_mm512_add_ps(
                _mm512_add_ps(
                    _mm512_mul_ps(splat(a[0]), d[0]),
                    _mm512_mul_ps(splat(a[1]), d[1]),
                ),
                _mm512_mul_ps(splat(a[2]), d[2]),
            ))
        })
    };

    // Set-up, 16 points at a time: `Sorted::secular_setup` of |y|.
    let inv_e2 = narrow(e.inv_e2);
    let mut queued = 0;
    for base in (0..n).step_by(16) {
        let m = lanes(base);
        let [ys0, ys1, ys2] = first_octant(base, m);
        let z0 = _mm512_mul_ps(ys0, splat(inv_e[0]));
        let z1 = _mm512_mul_ps(ys1, splat(inv_e[1]));
        let z2 = _mm512_mul_ps(ys2, splat(inv_e[2]));
        let a0 = _mm512_mul_ps(splat(r[0]), z0);
        let a1 = _mm512_mul_ps(splat(r[1]), z1);
        let a2 = z2;
        let mut lo = z2;
        // lo = lo.max(r_k (z_k − 1) + 1) where z_k > 0.
        for (z, r) in [(z0, r[0]), (z1, r[1])] {
            let single = _mm512_add_ps(_mm512_mul_ps(splat(r), _mm512_sub_ps(z, one)), one);
            let pos = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(z, zero);
            lo = _mm512_mask_max_ps(lo, pos, lo, single);
        }
        let sq = |v: __m512| _mm512_mul_ps(v, v);
        let hi = _mm512_sqrt_ps(_mm512_add_ps(_mm512_add_ps(sq(a0), sq(a1)), sq(a2)));
        let pair = _mm512_sub_ps(_mm512_sqrt_ps(_mm512_add_ps(sq(a1), sq(a2))), splat(b[1]));
        lo = _mm512_max_ps(_mm512_max_ps(lo, pair), _mm512_sub_ps(hi, splat(b[0])));
        let hi = _mm512_max_ps(hi, lo);
        // Points whose lower bound reaches the cap get the bound and leave the queue:
        // outside (level > 1), the larger of e_min (√level − 1) and |y| − e_max.
        let mut keep = m;
        if let Some(cap) = cap {
            let level = _mm512_add_ps(
                _mm512_add_ps(
                    _mm512_mul_ps(sq(ys0), splat(inv_e2[0])),
                    _mm512_mul_ps(sq(ys1), splat(inv_e2[1])),
                ),
                _mm512_mul_ps(sq(ys2), splat(inv_e2[2])),
            );
            let norm = _mm512_sqrt_ps(_mm512_add_ps(_mm512_add_ps(sq(ys0), sq(ys1)), sq(ys2)));
            let bound = _mm512_max_ps(
                _mm512_mul_ps(splat(ee[2]), _mm512_sub_ps(_mm512_sqrt_ps(level), one)),
                _mm512_sub_ps(norm, splat(ee[0])),
            );
            let far = _mm512_mask_cmp_ps_mask::<_CMP_GT_OQ>(m, level, one)
                & _mm512_cmp_ps_mask::<_CMP_GE_OQ>(bound, splat(cap));
            _mm512_mask_storeu_ps(out.as_mut_ptr().add(base), far, bound);
            keep &= !far;
        }
        // A planar point gets a trivial problem (a = (0, 0, 1), lo = hi = 1: S(1) = 1,
        // done on the first pass); its distance comes from the scalar path below.
        let flat = _mm512_mask_cmp_ps_mask::<_CMP_EQ_OQ>(keep, ys2, zero);
        let at = queued;
        let bits = _pext_u32(flat as u32, keep as u32) as u64;
        planar[at / 64] |= bits << (at % 64);
        if at % 64 + 16 > 64 && at / 64 + 1 < planar.len() {
            planar[at / 64 + 1] |= bits >> (64 - at % 64);
        }
        let store = |dst: *mut f32, v: __m512| _mm512_mask_compressstoreu_ps(dst.add(at), keep, v);
        store(qa[0], _mm512_mask_blend_ps(flat, a0, zero));
        store(qa[1], _mm512_mask_blend_ps(flat, a1, zero));
        store(qa[2], _mm512_mask_blend_ps(flat, a2, one));
        store(qlo, _mm512_mask_blend_ps(flat, lo, one));
        store(qhi, _mm512_mask_blend_ps(flat, hi, one));
        store(qy[0], ys0);
        store(qy[1], ys1);
        store(qy[2], ys2);
        let ids = _mm512_add_epi32(lane_ids, _mm512_set1_epi32(base as i32));
        _mm512_mask_compressstoreu_epi32(qi.add(at), keep, ids);
        queued += keep.count_ones() as usize;
    }

    // The stream: `solve_secular` on every queued point. Each operation of a pass is
    // written for all registers before the next one, so the instruction stream itself
    // interleaves the registers' independent chains (with one register's whole pass
    // after another's, the scheduler filled up with one chain's waiting operations).
    let (b0, b1, b2) = (splat(b[0]), splat(b[1]), splat(b[2]));
    let (half, h_tol, root_tol) = (
        splat(0.5),
        splat(H_TOLERANCE_F32),
        splat(ROOT_TOLERANCE_F32),
    );
    let last_pass = _mm512_set1_epi32(MAX_ITERATIONS as i32);
    let step = _mm512_set1_epi32(1);
    type V = [__m512; STREAMS];
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
    // Queue position of each lane's point, and the passes it has had.
    let mut at = [_mm512_setzero_si512(); STREAMS];
    let mut passes = [_mm512_setzero_si512(); STREAMS];
    let mut going: [__mmask16; STREAMS] = [0; STREAMS];
    let mut next = 0usize;
    loop {
        // Refill the free lanes from the queue.
        for g in 0..STREAMS {
            let free = !going[g];
            if next < queued && free != 0 {
                let take = (free.count_ones() as usize).min(queued - next);
                let load = _pdep_u32((1u32 << take) - 1, free as u32) as __mmask16;
                let from =
                    |q: *const f32, v: __m512| _mm512_mask_expandloadu_ps(v, load, q.add(next));
                a0[g] = from(qa[0], a0[g]);
                a1[g] = from(qa[1], a1[g]);
                a2[g] = from(qa[2], a2[g]);
                lo[g] = from(qlo, lo[g]);
                hi[g] = from(qhi, hi[g]);
                u[g] = _mm512_mask_blend_ps(load, u[g], lo[g]);
                // The loaded lanes' queue positions: next + (rank among the loaded).
                let rank = _mm512_maskz_expand_epi32(load, lane_ids);
                at[g] = _mm512_mask_add_epi32(at[g], load, rank, _mm512_set1_epi32(next as i32));
                passes[g] = _mm512_mask_mov_epi32(passes[g], load, _mm512_setzero_si512());
                going[g] |= load;
                next += take;
            }
        }
        if going.iter().all(|&g| g == 0) {
            break;
        }
        // One pass of `solve_secular` on every register (see the scalar code for the
        // why); lanes not going compute too and are ignored.
        let t0 = each(|g| _mm512_add_ps(u[g], b0));
        let t1 = each(|g| _mm512_add_ps(u[g], b1));
        let t2 = each(|g| _mm512_add_ps(u[g], b2));
        let p01 = each(|g| _mm512_mul_ps(t0[g], t1[g]));
        let inv = each(|g| _mm512_div_ps(one, _mm512_mul_ps(p01[g], t2[g])));
        let r2 = each(|g| _mm512_mul_ps(inv[g], p01[g]));
        let inv = each(|g| _mm512_mul_ps(inv[g], t2[g]));
        let r1 = each(|g| _mm512_mul_ps(inv[g], t0[g]));
        let r0 = each(|g| _mm512_mul_ps(inv[g], t1[g]));
        let sq = |v: __m512| _mm512_mul_ps(v, v);
        let q0 = each(|g| sq(_mm512_mul_ps(a0[g], r0[g])));
        let q1 = each(|g| sq(_mm512_mul_ps(a1[g], r1[g])));
        let q2 = each(|g| sq(_mm512_mul_ps(a2[g], r2[g])));
        let sum = each(|g| _mm512_add_ps(_mm512_add_ps(q0[g], q1[g]), q2[g]));
        let ds = each(|g| {
            _mm512_add_ps(
                _mm512_add_ps(_mm512_mul_ps(q0[g], r0[g]), _mm512_mul_ps(q1[g], r1[g])),
                _mm512_mul_ps(q2[g], r2[g]),
            )
        });
        let root = each(|g| _mm512_sqrt_ps(sum[g]));
        let root_m1 = each(|g| _mm512_sub_ps(root[g], one));
        let newton = each(|g| {
            _mm512_add_ps(
                u[g],
                _mm512_div_ps(_mm512_mul_ps(sum[g], root_m1[g]), ds[g]),
            )
        });
        for g in 0..STREAMS {
            let at_root = _mm512_cmp_ps_mask::<_CMP_LE_OQ>(abs(root_m1[g]), h_tol);
            let above = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(root[g], one);
            let lo_n = _mm512_mask_blend_ps(above, lo[g], u[g]);
            let hi_n = _mm512_mask_blend_ps(above, u[g], hi[g]);
            let inside = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(newton[g], lo_n)
                & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(newton[g], hi_n);
            let bisect = _mm512_mul_ps(half, _mm512_add_ps(lo_n, hi_n));
            let step_to = _mm512_mask_blend_ps(inside, bisect, newton[g]);
            let small = _mm512_cmp_ps_mask::<_CMP_LE_OQ>(
                abs(_mm512_sub_ps(step_to, u[g])),
                _mm512_mul_ps(root_tol, abs(u[g])),
            ) | _mm512_cmp_ps_mask::<_CMP_LE_OQ>(
                _mm512_sub_ps(hi_n, lo_n),
                _mm512_mul_ps(h_tol, hi_n),
            );
            passes[g] = _mm512_add_epi32(passes[g], step);
            // After the last allowed pass the scalar loop returns its last iterate.
            let last = _mm512_cmpeq_epi32_mask(passes[g], last_pass);
            let done = going[g] & (at_root | small | last);
            if done != 0 {
                // A lane at the root returns u; one with a small step (or capped), next.
                let result = _mm512_mask_blend_ps(at_root, step_to, u[g]);
                _mm512_mask_i32scatter_ps::<4>(roots, done, at[g], result);
            }
            let go = going[g] & !done;
            u[g] = _mm512_mask_blend_ps(go, u[g], step_to);
            lo[g] = _mm512_mask_blend_ps(go, lo[g], lo_n);
            hi[g] = _mm512_mask_blend_ps(go, hi[g], hi_n);
            going[g] = go;
        }
    }
    // Finish, 16 queued points at a time: `Sorted::closest_from_root` and
    // `SortedPlacement::signed_from_closest`, written to the points' places.
    for base in (0..queued).step_by(16) {
        let m = if queued - base >= 16 {
            0xffff
        } else {
            (1u16 << (queued - base)) - 1
        };
        let from = |q: *const f32| _mm512_maskz_loadu_ps(m, q.add(base));
        let (ys0, ys1, ys2) = (from(qy[0]), from(qy[1]), from(qy[2]));
        let u = from(roots);
        let (t0, t1, t2) = (
            _mm512_add_ps(u, b0),
            _mm512_add_ps(u, b1),
            _mm512_add_ps(u, b2),
        );
        let p01 = _mm512_mul_ps(t0, t1);
        let inv = _mm512_div_ps(one, _mm512_mul_ps(p01, t2));
        let r2 = _mm512_mul_ps(inv, p01);
        let inv = _mm512_mul_ps(inv, t2);
        let r1 = _mm512_mul_ps(inv, t0);
        let r0 = _mm512_mul_ps(inv, t1);
        let x = |k: usize, r: __m512| _mm512_mul_ps(_mm512_mul_ps(splat(ee[k]), from(qa[k])), r);
        let (x0, x1, x2) = (x(0, r0), x(1, r1), x(2, r2));
        let sq = |v: __m512| _mm512_mul_ps(v, v);
        let d = _mm512_sqrt_ps(_mm512_add_ps(
            _mm512_add_ps(sq(_mm512_sub_ps(ys0, x0)), sq(_mm512_sub_ps(ys1, x1))),
            sq(_mm512_sub_ps(ys2, x2)),
        ));
        let level = _mm512_add_ps(
            _mm512_add_ps(
                _mm512_mul_ps(sq(ys0), splat(inv_e2[0])),
                _mm512_mul_ps(sq(ys1), splat(inv_e2[1])),
            ),
            _mm512_mul_ps(sq(ys2), splat(inv_e2[2])),
        );
        // Negative inside: flip the sign bit (as the scalar `-d` does).
        let inside = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(level, one);
        let d = _mm512_castps_si512(d);
        let signed = _mm512_mask_xor_epi32(d, inside, d, _mm512_set1_epi32(i32::MIN));
        let signed = _mm512_castsi512_ps(signed);
        if cap.is_none() {
            // Every point was queued: queue position = point index.
            _mm512_mask_storeu_ps(out.as_mut_ptr().add(base), m, signed);
        } else {
            let at = _mm512_maskz_loadu_epi32(m, qi.add(base));
            _mm512_mask_i32scatter_ps::<4>(out.as_mut_ptr(), m, at, signed);
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
