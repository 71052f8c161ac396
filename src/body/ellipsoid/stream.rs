//! Signed distances (and normals) of a block of points to one ellipsoid, the
//! root-finder run as a stream of points through AVX-512 registers.
//!
//! The lockstep root-finder ([`super::solve_secular_lanes`]) has two costs beyond its
//! arithmetic: a group of lanes iterates as long as its slowest lane (3.7 passes per
//! group of 8 against 2.7 per point on a cloud around the body), and one pass is a
//! chain of ~70 cycles of latency (two divisions and a square root in a row) that two
//! registers cannot fill. Here every lane takes the next point of the block as soon as
//! its own has converged — AVX-512's expanding loads put consecutive queued values into
//! exactly the free lanes, one instruction per state variable — and [`STREAMS`]
//! independent registers of 8 lanes are in flight at once, so the divider and the
//! square-root unit stay busy.
//!
//! The set-up (numerators and bracket) and the finish (closest point, signed distance
//! and normal from the root) are the scalar code's expressions evaluated 8 points at a
//! time. Every operation is
//! the scalar code's IEEE operation in the scalar code's order (no fused multiply-add,
//! no reassociation), and each lane runs the scalar stopping rule, so the distances and
//! normals are bit-identical to the scalar code's; a test checks it.

#[cfg(target_arch = "x86_64")]
use super::{closest_sorted, SortedPlacement, H_TOLERANCE, MAX_ITERATIONS, ROOT_TOLERANCE};

/// Points per call of the kernel (its queue lives on the stack).
pub const BLOCK: usize = 256;

/// Independent registers of 8 lanes iterated together (enough to cover one pass's
/// latency with the others' work; 4 measured best of 2–6).
const STREAMS: usize = 4;

/// The kernel behind the batched exact distances, decided once per process.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kernel {
    /// [`distances_block`]: AVX-512F and BMI2.
    Avx512,
    /// The AVX2 form (module `stream_avx2`).
    Avx2,
    /// No stream: the lockstep root-finder.
    Lockstep,
}

/// The best kernel this CPU runs: AVX-512 unless the environment variable
/// `DEPTHPOSE_NO_AVX512` is set, else the AVX2 stream unless `DEPTHPOSE_NO_STREAM` is set
/// (both for comparisons, and for testing the other paths), else the lockstep.
#[inline]
pub fn kernel() -> Kernel {
    use std::sync::atomic::{AtomicU8, Ordering};
    // 0: not decided yet; else 1 + the kernel's index.
    static DECIDED: AtomicU8 = AtomicU8::new(0);
    const KERNELS: [Kernel; 3] = [Kernel::Avx512, Kernel::Avx2, Kernel::Lockstep];
    match DECIDED.load(Ordering::Relaxed) {
        0 => {
            let set = |name: &str| std::env::var_os(name).is_some();
            // `cpu::avx512` also honours `DEPTHPOSE_NO_AVX512`; the stream needs BMI2 too.
            let k = if crate::cpu::avx512() && cpu_has_bmi2() {
                Kernel::Avx512
            } else if cpu_has_avx2() && !set("DEPTHPOSE_NO_STREAM") {
                Kernel::Avx2
            } else {
                Kernel::Lockstep
            };
            let index = KERNELS.iter().position(|&x| x == k).unwrap_or(2);
            DECIDED.store(1 + index as u8, Ordering::Relaxed);
            k
        }
        d => KERNELS[(d - 1) as usize],
    }
}

fn cpu_has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

fn cpu_has_bmi2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("bmi2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// `d[i]` = the signed distance to `e` of the local point `(y0[i], y1[i], y2[i])` (from
/// [`SortedPlacement::local`]), and with `NORMALS` `normal[c][i]` = the camera-frame outward
/// unit normal at its closest point: what [`SortedPlacement::signed_distance_local`] and
/// `normal_at` give, for every `i < y[0].len()` (≤ [`BLOCK`]; the three inputs equally
/// long).
///
/// # Safety
/// The CPU must support AVX-512F and BMI2 (see [`kernel`]); `d` and (with `NORMALS`)
/// each `normal[c]` must be valid for writing `y[0].len()` values (they may be
/// uninitialised: they are only written).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,bmi2")]
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

    // Scratch, written before it is read (left uninitialised: zeroing it cost more
    // than a tenth of the call). The queue: numerators and bracket of every point, in
    // point order; then the roots, by point.
    let mut scratch = MaybeUninit::<[[f64; BLOCK]; 6]>::uninit();
    let base_ptr = scratch.as_mut_ptr() as *mut f64;
    let queue = |k: usize| base_ptr.add(k * BLOCK);
    let (qa, qlo, qhi, roots) = ([queue(0), queue(1), queue(2)], queue(3), queue(4), queue(5));
    // Points on the plane y2 = 0 (bit i of word i / 64) take the scalar special cases.
    let mut planar = [0u64; BLOCK / 64];

    let abs = |v: __m512d| _mm512_abs_pd(v);
    let splat = |x: f64| _mm512_set1_pd(x);
    let (one, zero) = (splat(1.0), _mm512_setzero_pd());
    let lanes = |base: usize| -> __mmask8 {
        if n - base >= 8 {
            0xff
        } else {
            (1u8 << (n - base)) - 1
        }
    };
    // |local coordinates| of the points base.. (masked by m).
    let first_octant = |base: usize, m: __mmask8| -> [__m512d; 3] {
        std::array::from_fn(|k| abs(_mm512_maskz_loadu_pd(m, y[k].as_ptr().add(base))))
    };

    // Set-up, 8 points at a time: `Sorted::secular_setup` of |y|.
    for base in (0..n).step_by(8) {
        let m = lanes(base);
        let [ys0, ys1, ys2] = first_octant(base, m);
        let z0 = _mm512_mul_pd(ys0, splat(c.inv_e[0]));
        let z1 = _mm512_mul_pd(ys1, splat(c.inv_e[1]));
        let z2 = _mm512_mul_pd(ys2, splat(c.inv_e[2]));
        let a0 = _mm512_mul_pd(splat(c.r[0]), z0);
        let a1 = _mm512_mul_pd(splat(c.r[1]), z1);
        let a2 = z2;
        let mut lo = z2;
        // lo = lo.max(r_k (z_k − 1) + 1) where z_k > 0.
        for (z, r) in [(z0, c.r[0]), (z1, c.r[1])] {
            let single = _mm512_add_pd(_mm512_mul_pd(splat(r), _mm512_sub_pd(z, one)), one);
            let pos = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(z, zero);
            lo = _mm512_mask_max_pd(lo, pos, lo, single);
        }
        let sq = |v: __m512d| _mm512_mul_pd(v, v);
        let hi = _mm512_sqrt_pd(_mm512_add_pd(_mm512_add_pd(sq(a0), sq(a1)), sq(a2)));
        let pair = _mm512_sub_pd(_mm512_sqrt_pd(_mm512_add_pd(sq(a1), sq(a2))), splat(c.b[1]));
        lo = _mm512_max_pd(_mm512_max_pd(lo, pair), _mm512_sub_pd(hi, splat(c.b[0])));
        let hi = _mm512_max_pd(hi, lo);
        // A planar point gets a trivial problem (a = (0, 0, 1), lo = hi = 1: S(1) = 1,
        // done on the first pass); its distance comes from the scalar path below.
        let flat = _mm512_mask_cmp_pd_mask::<_CMP_EQ_OQ>(m, ys2, zero);
        planar[base / 64] |= (flat as u64) << (base % 64);
        let store = |dst: *mut f64, v: __m512d| _mm512_mask_storeu_pd(dst.add(base), m, v);
        store(qa[0], _mm512_mask_blend_pd(flat, a0, zero));
        store(qa[1], _mm512_mask_blend_pd(flat, a1, zero));
        store(qa[2], _mm512_mask_blend_pd(flat, a2, one));
        store(qlo, _mm512_mask_blend_pd(flat, lo, one));
        store(qhi, _mm512_mask_blend_pd(flat, hi, one));
    }

    // The stream: `solve_secular` on every queued point. Each operation of a pass is
    // written for all registers before the next one, so the instruction stream itself
    // interleaves the registers' independent chains (with one register's whole pass
    // after another's, the scheduler filled up with one chain's waiting operations).
    let (b0, b1, b2) = (splat(c.b[0]), splat(c.b[1]), splat(c.b[2]));
    let (half, h_tol, root_tol) = (splat(0.5), splat(H_TOLERANCE), splat(ROOT_TOLERANCE));
    let cap = _mm512_set1_epi64(MAX_ITERATIONS as i64);
    let step = _mm512_set1_epi64(1);
    let lane_ids = _mm512_set_epi64(7, 6, 5, 4, 3, 2, 1, 0);
    type V = [__m512d; STREAMS];
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
    let mut going: [__mmask8; STREAMS] = [0; STREAMS];
    let mut next = 0usize;
    loop {
        // Refill the free lanes from the queue.
        for g in 0..STREAMS {
            let free = !going[g];
            if next < n && free != 0 {
                let take = (free.count_ones() as usize).min(n - next);
                let load = _pdep_u32((1u32 << take) - 1, free as u32) as __mmask8;
                let from =
                    |q: *const f64, v: __m512d| _mm512_mask_expandloadu_pd(v, load, q.add(next));
                a0[g] = from(qa[0], a0[g]);
                a1[g] = from(qa[1], a1[g]);
                a2[g] = from(qa[2], a2[g]);
                lo[g] = from(qlo, lo[g]);
                hi[g] = from(qhi, hi[g]);
                u[g] = _mm512_mask_blend_pd(load, u[g], lo[g]);
                // The loaded lanes' queue positions: next + (rank among the loaded).
                let rank = _mm512_maskz_expand_epi64(load, lane_ids);
                at[g] = _mm512_mask_add_epi64(at[g], load, rank, _mm512_set1_epi64(next as i64));
                passes[g] = _mm512_mask_mov_epi64(passes[g], load, _mm512_setzero_si512());
                going[g] |= load;
                next += take;
            }
        }
        if going.iter().all(|&g| g == 0) {
            break;
        }
        // One pass of `solve_secular` on every register (see the scalar code for the
        // why); lanes not going compute too and are ignored.
        let t0 = each(|g| _mm512_add_pd(u[g], b0));
        let t1 = each(|g| _mm512_add_pd(u[g], b1));
        let t2 = each(|g| _mm512_add_pd(u[g], b2));
        let p01 = each(|g| _mm512_mul_pd(t0[g], t1[g]));
        let inv = each(|g| _mm512_div_pd(one, _mm512_mul_pd(p01[g], t2[g])));
        let r2 = each(|g| _mm512_mul_pd(inv[g], p01[g]));
        let inv = each(|g| _mm512_mul_pd(inv[g], t2[g]));
        let r1 = each(|g| _mm512_mul_pd(inv[g], t0[g]));
        let r0 = each(|g| _mm512_mul_pd(inv[g], t1[g]));
        let sq = |v: __m512d| _mm512_mul_pd(v, v);
        let q0 = each(|g| sq(_mm512_mul_pd(a0[g], r0[g])));
        let q1 = each(|g| sq(_mm512_mul_pd(a1[g], r1[g])));
        let q2 = each(|g| sq(_mm512_mul_pd(a2[g], r2[g])));
        let sum = each(|g| _mm512_add_pd(_mm512_add_pd(q0[g], q1[g]), q2[g]));
        let ds = each(|g| {
            _mm512_add_pd(
                _mm512_add_pd(_mm512_mul_pd(q0[g], r0[g]), _mm512_mul_pd(q1[g], r1[g])),
                _mm512_mul_pd(q2[g], r2[g]),
            )
        });
        let root = each(|g| _mm512_sqrt_pd(sum[g]));
        let root_m1 = each(|g| _mm512_sub_pd(root[g], one));
        let newton = each(|g| {
            _mm512_add_pd(
                u[g],
                _mm512_div_pd(_mm512_mul_pd(sum[g], root_m1[g]), ds[g]),
            )
        });
        for g in 0..STREAMS {
            let at_root = _mm512_cmp_pd_mask::<_CMP_LE_OQ>(abs(root_m1[g]), h_tol);
            let above = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(root[g], one);
            let lo_n = _mm512_mask_blend_pd(above, lo[g], u[g]);
            let hi_n = _mm512_mask_blend_pd(above, u[g], hi[g]);
            let inside = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(newton[g], lo_n)
                & _mm512_cmp_pd_mask::<_CMP_LT_OQ>(newton[g], hi_n);
            let bisect = _mm512_mul_pd(half, _mm512_add_pd(lo_n, hi_n));
            let step_to = _mm512_mask_blend_pd(inside, bisect, newton[g]);
            let small = _mm512_cmp_pd_mask::<_CMP_LE_OQ>(
                abs(_mm512_sub_pd(step_to, u[g])),
                _mm512_mul_pd(root_tol, abs(u[g])),
            ) | _mm512_cmp_pd_mask::<_CMP_LE_OQ>(
                _mm512_sub_pd(hi_n, lo_n),
                _mm512_mul_pd(h_tol, hi_n),
            );
            passes[g] = _mm512_add_epi64(passes[g], step);
            // After the last allowed pass the scalar loop returns its last iterate.
            let capped = _mm512_cmpeq_epi64_mask(passes[g], cap);
            let done = going[g] & (at_root | small | capped);
            if done != 0 {
                // A lane at the root returns u; one with a small step (or capped), next.
                let result = _mm512_mask_blend_pd(at_root, step_to, u[g]);
                _mm512_mask_i64scatter_pd::<8>(roots, done, at[g], result);
            }
            let go = going[g] & !done;
            u[g] = _mm512_mask_blend_pd(go, u[g], step_to);
            lo[g] = _mm512_mask_blend_pd(go, lo[g], lo_n);
            hi[g] = _mm512_mask_blend_pd(go, hi[g], hi_n);
            going[g] = go;
        }
    }
    // Finish, 8 points at a time: `Sorted::closest_from_root`,
    // `SortedPlacement::signed_from_closest` and `SortedPlacement::normal_at`.
    let (inv_e2, axes) = (e.inv_e2, e.axes);
    let sign_bit = _mm512_set1_epi64(i64::MIN);
    for base in (0..n).step_by(8) {
        let m = lanes(base);
        let from = |q: *const f64| _mm512_maskz_loadu_pd(m, q.add(base));
        let u = from(roots);
        let (t0, t1, t2) = (
            _mm512_add_pd(u, b0),
            _mm512_add_pd(u, b1),
            _mm512_add_pd(u, b2),
        );
        let p01 = _mm512_mul_pd(t0, t1);
        let inv = _mm512_div_pd(one, _mm512_mul_pd(p01, t2));
        let r2 = _mm512_mul_pd(inv, p01);
        let inv = _mm512_mul_pd(inv, t2);
        let r1 = _mm512_mul_pd(inv, t0);
        let r0 = _mm512_mul_pd(inv, t1);
        let closest =
            |k: usize, r: __m512d| _mm512_mul_pd(_mm512_mul_pd(splat(c.e[k]), from(qa[k])), r);
        let x = [closest(0, r0), closest(1, r1), closest(2, r2)];
        let yl: [__m512d; 3] = std::array::from_fn(|k| from(y[k].as_ptr()));
        let ys = yl.map(abs);
        let sq = |v: __m512d| _mm512_mul_pd(v, v);
        let dist = _mm512_sqrt_pd(_mm512_add_pd(
            _mm512_add_pd(
                sq(_mm512_sub_pd(ys[0], x[0])),
                sq(_mm512_sub_pd(ys[1], x[1])),
            ),
            sq(_mm512_sub_pd(ys[2], x[2])),
        ));
        let level = _mm512_add_pd(
            _mm512_add_pd(
                _mm512_mul_pd(sq(ys[0]), splat(inv_e2[0])),
                _mm512_mul_pd(sq(ys[1]), splat(inv_e2[1])),
            ),
            _mm512_mul_pd(sq(ys[2]), splat(inv_e2[2])),
        );
        // Negative inside: flip the sign bit (as the scalar `-d` does).
        let inside = _mm512_cmp_pd_mask::<_CMP_LT_OQ>(level, one);
        let bits = _mm512_castpd_si512(dist);
        let signed = _mm512_mask_xor_epi64(bits, inside, bits, sign_bit);
        _mm512_mask_storeu_pd(d.add(base), m, _mm512_castsi512_pd(signed));
        if NORMALS {
            // g_k = copysign(x_k, y_k) / e_k² (x_k ≥ +0, so the sign bit of y_k is
            // or-ed in), normalised, turned to the camera frame.
            let g: [__m512d; 3] = std::array::from_fn(|k| {
                let signed = _mm512_or_si512(
                    _mm512_castpd_si512(x[k]),
                    _mm512_and_si512(_mm512_castpd_si512(yl[k]), sign_bit),
                );
                _mm512_mul_pd(_mm512_castsi512_pd(signed), splat(inv_e2[k]))
            });
            let inv = _mm512_div_pd(
                one,
                _mm512_sqrt_pd(_mm512_add_pd(_mm512_add_pd(sq(g[0]), sq(g[1])), sq(g[2]))),
            );
            for (col, out) in normal.iter().enumerate() {
                let v = _mm512_add_pd(
                    _mm512_add_pd(
                        _mm512_mul_pd(g[0], splat(axes[0][col])),
                        _mm512_mul_pd(g[1], splat(axes[1][col])),
                    ),
                    _mm512_mul_pd(g[2], splat(axes[2][col])),
                );
                _mm512_mask_storeu_pd(out.add(base), m, _mm512_mul_pd(v, inv));
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
