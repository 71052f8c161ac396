//! Exact distance from a point to an ellipsoid surface.
//!
//! The closest point x on the ellipsoid Σ (x_i/e_i)² = 1 to a point y satisfies
//! x_i = e_i² y_i / (t + e_i²) for the Lagrange multiplier t, the root of
//! F(t) = Σ (e_i y_i / (t + e_i²))² − 1 (Eberly, "Distance from a point to an ellipse,
//! an ellipsoid, or a hyperellipsoid", 2013). By symmetry we work in the first octant
//! with the axes sorted e0 ≥ e1 ≥ e2. When y2 > 0 the root is unique on
//! t > −e2²; we solve it in the normalised variable u = t/e2² + 1 ∈ (0, ∞), bracketed
//! by the single-term lower bound max_i r_i(z_i − 1) + 1 (r_i = (e_i/e2)², z_i = y_i/e_i)
//! and the upper bound |r⊙z|, with Newton steps on H(u) = S(u)^{-1/2} − 1
//! (S = F + 1; H is nearly linear, exactly so for a sphere) guarded by bisection. Points
//! on a coordinate plane (y2 = 0) reduce to Eberly's special cases: either the closest
//! point leaves the plane (t = −e2²) or the problem becomes the 2-D ellipse one.

use nalgebra::{Matrix3, Vector3};

mod stream;
#[cfg(target_arch = "x86_64")]
mod stream_avx2;
#[cfg(target_arch = "x86_64")]
mod stream_f32;
#[cfg(target_arch = "x86_64")]
mod stream_f32_avx2;

/// Newton/bisection stops when the step is below this relative size. Newton converges
/// quadratically, so the iterate after a step δ is off by about K·δ² (K = |H''/2H'|,
/// order one for the normalised H): with δ ≤ 1e-6 that is ~1e-12 relative, at the
/// level of rounding in the distance (against a 3000-step bisection reference on random
/// ellipsoids and points: distance and closest point within 1.1e-12 m, as with 1e-9),
/// and it saves the extra iteration a 1e-9 tolerance spends confirming it. (Asking
/// for steps of a few ulps makes the iteration chase rounding noise in H.)
const ROOT_TOLERANCE: f64 = 1e-6;
/// |H| below this is a root to rounding precision.
const H_TOLERANCE: f64 = 4.0 * f64::EPSILON;
/// Iteration cap; bisection alone halves the bracket each step, so 2 × 64 suffices.
const MAX_ITERATIONS: usize = 128;

/// Result of a point–ellipsoid query, in the ellipsoid's frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EllipsoidDistance {
    /// Signed distance: negative inside.
    pub distance: f64,
    /// Closest point on the surface.
    pub closest: Vector3<f64>,
    /// Outward unit normal at the closest point (the gradient of the signed distance
    /// with respect to the query point).
    pub normal: Vector3<f64>,
}

/// 1/(u + b_k) for every k with one division (batch inversion through the prefix
/// products): divisions dominate the root-finder's iterations. All factors are
/// positive and moderate (u > 0, b_k ≥ 0), so the products neither overflow nor
/// underflow.
#[inline(always)]
fn reciprocals<const N: usize>(u: f64, b: &[f64; N]) -> [f64; N] {
    let mut prefix = [1.0; N];
    let mut p = 1.0;
    for k in 0..N {
        prefix[k] = p;
        p *= u + b[k];
    }
    let mut inv = 1.0 / p;
    let mut out = [0.0; N];
    for k in (0..N).rev() {
        out[k] = inv * prefix[k];
        inv *= u + b[k];
    }
    out
}

/// Root u of S(u) = Σ_k (a_k / (u + b_k))² = 1 on [lo, hi] (S decreasing, S(lo) ≥ 1 ≥
/// S(hi)); `a_k` ≥ 0, `b_k` ≥ 0.
#[inline]
fn solve_secular<const N: usize>(a: &[f64; N], b: &[f64; N], mut lo: f64, mut hi: f64) -> f64 {
    let mut u = lo;
    for _ in 0..MAX_ITERATIONS {
        let mut s = 0.0;
        let mut ds = 0.0;
        let invs = reciprocals(u, b);
        for k in 0..N {
            let inv = invs[k];
            let q = a[k] * inv;
            let q2 = q * q;
            s += q2;
            ds += q2 * inv;
        }
        // H = S^{-1/2} − 1 is increasing and concave (a negative power mean of the
        // positive linear functions (u + b_k)/a_k), so Newton from the left end of the
        // bracket climbs monotonically to the root. The step −H/H' with
        // H' = S^{-3/2}·ds simplifies to S(√S − 1)/ds: one square root, one division.
        let root = s.sqrt();
        if (root - 1.0).abs() <= H_TOLERANCE {
            return u;
        }
        if root > 1.0 {
            lo = u;
        } else {
            hi = u;
        }
        let mut next = u + s * (root - 1.0) / ds;
        if !(next > lo && next < hi) {
            next = 0.5 * (lo + hi);
        }
        if (next - u).abs() <= ROOT_TOLERANCE * u.abs() || hi - lo <= H_TOLERANCE * hi {
            return next;
        }
        u = next;
    }
    u
}

/// Queries solved together by [`SortedPlacement::signed_distances_batched`]: two AVX2
/// registers of four (see `solve_secular_lanes`).
pub const LANES: usize = 8;
const _: () = assert!(
    LANES.is_multiple_of(4),
    "whole groups and registers of four"
);

/// [`solve_secular`] for `N` independent 3-term problems sharing `b`, in lockstep:
/// the same arithmetic and stopping rule lane by lane (so bit-identical results), but
/// the lanes' divisions and square roots are independent, so the CPU overlaps them
/// instead of waiting on one dependency chain.
#[inline]
fn solve_secular_lockstep<const N: usize>(
    a: &[[f64; 3]; N],
    b: &[f64; 3],
    mut lo: [f64; N],
    mut hi: [f64; N],
) -> [f64; N] {
    let mut u = lo;
    let mut out = [0.0; N];
    let mut done = [false; N];
    for _ in 0..MAX_ITERATIONS {
        let mut s = [0.0; N];
        let mut ds = [0.0; N];
        for l in 0..N {
            let invs = reciprocals(u[l], b);
            for k in 0..3 {
                let inv = invs[k];
                let q = a[l][k] * inv;
                let q2 = q * q;
                s[l] += q2;
                ds[l] += q2 * inv;
            }
        }
        let mut all_done = true;
        for l in 0..N {
            if done[l] {
                continue;
            }
            let root = s[l].sqrt();
            if (root - 1.0).abs() <= H_TOLERANCE {
                out[l] = u[l];
                done[l] = true;
                continue;
            }
            if root > 1.0 {
                lo[l] = u[l];
            } else {
                hi[l] = u[l];
            }
            let mut next = u[l] + s[l] * (root - 1.0) / ds[l];
            if !(next > lo[l] && next < hi[l]) {
                next = 0.5 * (lo[l] + hi[l]);
            }
            if (next - u[l]).abs() <= ROOT_TOLERANCE * u[l].abs()
                || hi[l] - lo[l] <= H_TOLERANCE * hi[l]
            {
                out[l] = next;
                done[l] = true;
                continue;
            }
            u[l] = next;
            all_done = false;
        }
        if all_done {
            return out;
        }
    }
    for l in 0..N {
        if !done[l] {
            out[l] = u[l];
        }
    }
    out
}

/// [`solve_secular_lockstep`] on the [`LANES`] lanes four at a time: without vector
/// instructions more lanes in lockstep gained nothing (measured) and each extra lane
/// iterates as long as the slowest of its group.
#[inline]
fn solve_secular_lanes_portable(
    a: &[[f64; 3]; LANES],
    b: &[f64; 3],
    lo: [f64; LANES],
    hi: [f64; LANES],
) -> [f64; LANES] {
    let mut out = [0.0; LANES];
    for g in (0..LANES).step_by(4) {
        let quad = |v: &[f64; LANES]| -> [f64; 4] { std::array::from_fn(|l| v[g + l]) };
        let aq: [[f64; 3]; 4] = std::array::from_fn(|l| a[g + l]);
        out[g..g + 4].copy_from_slice(&solve_secular_lockstep(&aq, b, quad(&lo), quad(&hi)));
    }
    out
}

/// [`solve_secular_lanes_portable`], with the lanes four to an AVX2 register where the
/// CPU has it (detected at run time): the same IEEE operations in the same order, lane by
/// lane (no fused multiply-adds), so bit-identical results. Each step's division and
/// square root then take one instruction per four lanes, and the two registers' long
/// dependency chains overlap. With one register (4 lanes) the iteration waited on those
/// latencies and was no faster than the scalar lanes; with two, a tracked fit is about a
/// fifth faster (docs/fit.md).
#[inline]
fn solve_secular_lanes(
    a: &[[f64; 3]; LANES],
    b: &[f64; 3],
    lo: [f64; LANES],
    hi: [f64; LANES],
) -> [f64; LANES] {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe { solve_secular_lanes_avx2(a, b, lo, hi) };
    }
    solve_secular_lanes_portable(a, b, lo, hi)
}

/// `reciprocals(u, b)` on four lanes: 1/(u + b_k) for k = 0, 1, 2 through the prefix
/// products, with the scalar code's operations in its order (so bit-identical to it).
/// Shared by the AVX2 lockstep and the AVX2 stream's passes and finish.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn reciprocals_avx2(
    u: std::arch::x86_64::__m256d,
    b: [std::arch::x86_64::__m256d; 3],
) -> [std::arch::x86_64::__m256d; 3] {
    use std::arch::x86_64::*;
    let (t0, t1, t2) = (
        _mm256_add_pd(u, b[0]),
        _mm256_add_pd(u, b[1]),
        _mm256_add_pd(u, b[2]),
    );
    let p01 = _mm256_mul_pd(t0, t1);
    let inv = _mm256_div_pd(_mm256_set1_pd(1.0), _mm256_mul_pd(p01, t2));
    let r2 = _mm256_mul_pd(inv, p01);
    let inv = _mm256_mul_pd(inv, t2);
    [_mm256_mul_pd(inv, t1), _mm256_mul_pd(inv, t0), r2]
}

/// The AVX2 body of [`solve_secular_lanes`]: each step of `solve_secular` on all lanes
/// at once, four per register, the registers interleaved (each step's division and
/// square root have a long latency; independent registers overlap them). A finished
/// lane keeps its result while the others go on.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn solve_secular_lanes_avx2(
    a: &[[f64; 3]; LANES],
    b: &[f64; 3],
    lo: [f64; LANES],
    hi: [f64; LANES],
) -> [f64; LANES] {
    use std::arch::x86_64::*;
    const REGS: usize = LANES / 4;
    type V = [__m256d; REGS];
    #[inline(always)]
    fn each(f: impl FnMut(usize) -> __m256d) -> V {
        std::array::from_fn(f)
    }
    // _mm256_set_pd takes the lanes from the highest down.
    let column = |k: usize| {
        each(|g| {
            let l = 4 * g;
            _mm256_set_pd(a[l + 3][k], a[l + 2][k], a[l + 1][k], a[l][k])
        })
    };
    let (a0, a1, a2) = (column(0), column(1), column(2));
    let (b0, b1, b2) = (
        _mm256_set1_pd(b[0]),
        _mm256_set1_pd(b[1]),
        _mm256_set1_pd(b[2]),
    );
    let one = _mm256_set1_pd(1.0);
    let half = _mm256_set1_pd(0.5);
    let h_tol = _mm256_set1_pd(H_TOLERANCE);
    let root_tol = _mm256_set1_pd(ROOT_TOLERANCE);
    let abs_mask = _mm256_castsi256_pd(_mm256_set1_epi64x(i64::MAX));
    let all = _mm256_castsi256_pd(_mm256_set1_epi64x(-1));
    let abs = |v: __m256d| _mm256_and_pd(v, abs_mask);
    let mut lo: V = each(|g| _mm256_loadu_pd(lo[4 * g..].as_ptr()));
    let mut hi: V = each(|g| _mm256_loadu_pd(hi[4 * g..].as_ptr()));
    let mut u = lo;
    let mut out: V = [_mm256_setzero_pd(); REGS];
    // All ones in the lanes still iterating.
    let mut going: V = [all; REGS];
    for _ in 0..MAX_ITERATIONS {
        let mut any = 0;
        for g in 0..REGS {
            let u = &mut u[g];
            let [r0, r1, r2] = reciprocals_avx2(*u, [b0, b1, b2]);
            let sq = |v: __m256d| _mm256_mul_pd(v, v);
            let (q0, q1, q2) = (
                sq(_mm256_mul_pd(a0[g], r0)),
                sq(_mm256_mul_pd(a1[g], r1)),
                sq(_mm256_mul_pd(a2[g], r2)),
            );
            let s = _mm256_add_pd(_mm256_add_pd(q0, q1), q2);
            let ds = _mm256_add_pd(
                _mm256_add_pd(_mm256_mul_pd(q0, r0), _mm256_mul_pd(q1, r1)),
                _mm256_mul_pd(q2, r2),
            );
            let root = _mm256_sqrt_pd(s);
            let root_m1 = _mm256_sub_pd(root, one);
            let at_root = _mm256_cmp_pd::<_CMP_LE_OQ>(abs(root_m1), h_tol);
            let above = _mm256_cmp_pd::<_CMP_GT_OQ>(root, one);
            // blendv(x, y, m): y where m is set.
            let lo_n = _mm256_blendv_pd(lo[g], *u, above);
            let hi_n = _mm256_blendv_pd(*u, hi[g], above);
            let newton = _mm256_add_pd(*u, _mm256_div_pd(_mm256_mul_pd(s, root_m1), ds));
            let inside = _mm256_and_pd(
                _mm256_cmp_pd::<_CMP_GT_OQ>(newton, lo_n),
                _mm256_cmp_pd::<_CMP_LT_OQ>(newton, hi_n),
            );
            let bisect = _mm256_mul_pd(half, _mm256_add_pd(lo_n, hi_n));
            let next = _mm256_blendv_pd(bisect, newton, inside);
            let small_step = _mm256_or_pd(
                _mm256_cmp_pd::<_CMP_LE_OQ>(
                    abs(_mm256_sub_pd(next, *u)),
                    _mm256_mul_pd(root_tol, abs(*u)),
                ),
                _mm256_cmp_pd::<_CMP_LE_OQ>(_mm256_sub_pd(hi_n, lo_n), _mm256_mul_pd(h_tol, hi_n)),
            );
            // A lane at the root returns u; else one with a small step returns next.
            let go = going[g];
            out[g] = _mm256_blendv_pd(out[g], next, _mm256_and_pd(go, small_step));
            out[g] = _mm256_blendv_pd(out[g], *u, _mm256_and_pd(go, at_root));
            let go = _mm256_andnot_pd(_mm256_or_pd(at_root, small_step), go);
            *u = _mm256_blendv_pd(*u, next, go);
            lo[g] = _mm256_blendv_pd(lo[g], lo_n, go);
            hi[g] = _mm256_blendv_pd(hi[g], hi_n, go);
            going[g] = go;
            any |= _mm256_movemask_pd(go);
        }
        if any == 0 {
            break;
        }
    }
    // Lanes still going after the cap return their last iterate.
    let mut result = [0.0; LANES];
    for g in 0..REGS {
        let o = _mm256_blendv_pd(out[g], u[g], going[g]);
        _mm256_storeu_pd(result[4 * g..].as_mut_ptr(), o);
    }
    result
}

/// Closest point for sorted axes e0 ≥ e1 > 0 in 2-D, y ≥ 0.
#[inline]
fn closest_2d(e: [f64; 2], y: [f64; 2]) -> [f64; 2] {
    if y[1] > 0.0 {
        if y[0] > 0.0 {
            let r0 = (e[0] / e[1]) * (e[0] / e[1]);
            let z = [y[0] / e[0], y[1] / e[1]];
            let a = [r0 * z[0], z[1]];
            let b = [r0 - 1.0, 0.0];
            let lo = z[1].max(r0 * (z[0] - 1.0) + 1.0);
            let hi = a[0].hypot(a[1]);
            let u = solve_secular(&a, &b, lo, hi.max(lo));
            [e[0] * a[0] / (u + b[0]), e[1] * a[1] / u]
        } else {
            [0.0, e[1]]
        }
    } else {
        let d0 = e[0] * e[0] - e[1] * e[1];
        let n0 = e[0] * y[0];
        if n0 < d0 {
            let x0 = e[0] * n0 / d0;
            let w = x0 / e[0];
            [x0, e[1] * (1.0 - w * w).max(0.0).sqrt()]
        } else {
            [e[0], 0.0]
        }
    }
}

/// Constants of a sorted ellipsoid reused by every query.
#[derive(Debug, Clone, Copy)]
struct Sorted {
    /// Half-axes, descending.
    e: [f64; 3],
    /// 1 / e_k.
    inv_e: [f64; 3],
    /// r_k = (e_k / e2)².
    r: [f64; 3],
    /// b_k = r_k − 1 (the shifts of the normalised secular equation).
    b: [f64; 3],
}

impl Sorted {
    fn new(e: [f64; 3]) -> Self {
        let r = [(e[0] / e[2]).powi(2), (e[1] / e[2]).powi(2), 1.0];
        Sorted {
            e,
            inv_e: [1.0 / e[0], 1.0 / e[1], 1.0 / e[2]],
            r,
            b: [r[0] - 1.0, r[1] - 1.0, 0.0],
        }
    }

    /// For y ≥ 0 with y2 > 0: the numerators a_k = r_k z_k of the normalised secular
    /// equation and its bracket [lo, hi].
    #[inline]
    fn secular_setup(&self, y: &[f64; 3]) -> ([f64; 3], f64, f64) {
        let r = self.r;
        let z = [
            y[0] * self.inv_e[0],
            y[1] * self.inv_e[1],
            y[2] * self.inv_e[2],
        ];
        let a = [r[0] * z[0], r[1] * z[1], z[2]];
        let mut lo = z[2];
        for k in 0..2 {
            if z[k] > 0.0 {
                lo = lo.max(r[k] * (z[k] - 1.0) + 1.0);
            }
        }
        let hi = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        // Grouped bounds: over any subset K of the terms, b_k ≤ max_K b gives
        // S(u) ≥ |a_K|² / (u + max_K b)², so the root is ≥ |a_K| − max_K b. With
        // K = {1, 2} this is nearly the root beside a limb (e1 ≈ e2, so b1 ≈ 0),
        // where the single-term bounds are far below it.
        let pair = (a[1] * a[1] + a[2] * a[2]).sqrt() - self.b[1];
        lo = lo.max(pair).max(hi - self.b[0]);
        (a, lo, hi.max(lo))
    }

    /// The closest point x_k = e_k a_k / (u + b_k) for the root u.
    #[inline]
    fn closest_from_root(&self, a: &[f64; 3], u: f64) -> [f64; 3] {
        let (e, inv) = (self.e, reciprocals(u, &self.b));
        [
            e[0] * a[0] * inv[0],
            e[1] * a[1] * inv[1],
            e[2] * a[2] * inv[2],
        ]
    }
}

/// Closest point for sorted axes e0 ≥ e1 ≥ e2 > 0, y ≥ 0.
#[inline]
fn closest_sorted(c: &Sorted, y: [f64; 3]) -> [f64; 3] {
    let e = c.e;
    if y[2] > 0.0 {
        let (a, lo, hi) = c.secular_setup(&y);
        let u = solve_secular(&a, &c.b, lo, hi);
        return c.closest_from_root(&a, u);
    }
    // y2 = 0: does the closest point leave the plane (t = −e2²)?
    let leave = |k: usize| -> Option<f64> {
        if y[k] == 0.0 {
            return Some(0.0);
        }
        let d = e[k] * e[k] - e[2] * e[2];
        (d > 0.0).then(|| e[k] * y[k] / d)
    };
    if let (Some(w0), Some(w1)) = (leave(0), leave(1)) {
        let rest = 1.0 - w0 * w0 - w1 * w1;
        if rest > 0.0 {
            return [e[0] * w0, e[1] * w1, e[2] * rest.sqrt()];
        }
    }
    let x = closest_2d([e[0], e[1]], [y[0], y[1]]);
    [x[0], x[1], 0.0]
}

/// Closest point, signed distance and normal for a point `y` given in the frame of an
/// axis-aligned ellipsoid centred at the origin with half-axes `radii` (all > 0).
pub fn closest_point_on_ellipsoid(radii: &Vector3<f64>, y: &Vector3<f64>) -> EllipsoidDistance {
    Prepared::new(radii).query(y)
}

/// Signed distance (negative inside) from `y` to the ellipsoid of half-axes `radii`.
pub fn signed_distance_to_ellipsoid(radii: &Vector3<f64>, y: &Vector3<f64>) -> f64 {
    Prepared::new(radii).query(y).distance
}

/// An axis-aligned ellipsoid with its axes sorted once for many queries.
#[derive(Debug, Clone, Copy)]
pub struct Prepared {
    /// perm[k] = original axis of sorted axis k (descending half-axes).
    perm: [usize; 3],
    sorted: Sorted,
    /// 1 / e_k² in sorted order.
    inv_e2: [f64; 3],
    radii: Vector3<f64>,
}

impl Prepared {
    pub fn new(radii: &Vector3<f64>) -> Self {
        let mut perm = [0usize, 1, 2];
        perm.sort_by(|&i, &j| radii[j].total_cmp(&radii[i]));
        let e = [radii[perm[0]], radii[perm[1]], radii[perm[2]]];
        Prepared {
            perm,
            sorted: Sorted::new(e),
            inv_e2: [
                1.0 / (e[0] * e[0]),
                1.0 / (e[1] * e[1]),
                1.0 / (e[2] * e[2]),
            ],
            radii: *radii,
        }
    }

    /// The query of [`closest_point_on_ellipsoid`].
    #[inline]
    pub fn query(&self, y: &Vector3<f64>) -> EllipsoidDistance {
        let ys = [
            y[self.perm[0]].abs(),
            y[self.perm[1]].abs(),
            y[self.perm[2]].abs(),
        ];
        let xs = closest_sorted(&self.sorted, ys);
        let mut closest = Vector3::zeros();
        let mut grad = Vector3::zeros();
        let mut level = 0.0;
        for k in 0..3 {
            let axis = self.perm[k];
            let x = xs[k].copysign(y[axis]);
            closest[axis] = x;
            grad[axis] = x * self.inv_e2[k];
            level += ys[k] * ys[k] * self.inv_e2[k];
        }
        let dist = (y - closest).norm();
        let distance = if level < 1.0 { -dist } else { dist };
        let normal = grad.normalize();
        EllipsoidDistance {
            distance,
            closest,
            normal,
        }
    }

    /// The half-axes in the original order.
    pub fn radii(&self) -> &Vector3<f64> {
        &self.radii
    }
}

/// An ellipsoid placed in the camera frame: centre, rotation (ellipsoid → camera) and
/// half-axes, prepared for distance queries and ray casting.
#[derive(Debug, Clone, Copy)]
pub struct PlacedEllipsoid {
    pub centre: Vector3<f64>,
    pub rotation: Matrix3<f64>,
    pub prepared: Prepared,
}

impl PlacedEllipsoid {
    /// Query with a camera-frame point; the returned closest point and normal are in the
    /// camera frame too.
    #[inline]
    pub fn query(&self, p: &Vector3<f64>) -> EllipsoidDistance {
        let local = self.rotation.tr_mul(&(p - self.centre));
        let r = self.prepared.query(&local);
        EllipsoidDistance {
            distance: r.distance,
            closest: self.rotation * r.closest + self.centre,
            normal: self.rotation * r.normal,
        }
    }

    /// Signed distance only.
    #[inline]
    pub fn signed_distance(&self, p: &Vector3<f64>) -> f64 {
        let local = self.rotation.tr_mul(&(p - self.centre));
        self.prepared.query(&local).distance
    }
}

/// A stream kernel: signed distances of a block of local points to an ellipsoid (and
/// normals, for the `NORMALS` forms) written through the pointers.
#[cfg(target_arch = "x86_64")]
type StreamKernel = unsafe fn(&SortedPlacement, [&[f64]; 3], *mut f64, [*mut f64; 3]);

/// Thresholds for [`SortedPlacement::is_beyond`] (one distance, one ellipsoid).
#[derive(Debug, Clone, Copy)]
pub struct Beyond {
    level: f64,
    norm2: f64,
}

/// A placed ellipsoid prepared for many camera-frame queries in a hot loop: the axis
/// sort is folded into the rotation (row k is the camera-frame direction of sorted
/// axis k), so a query is one 3×3 product, the first-octant closest-point solve and a
/// norm, with no permutation and no allocation. Gives the same distances as
/// [`PlacedEllipsoid::query`] (up to the summation order of the last norm).
#[derive(Debug, Clone, Copy)]
pub struct SortedPlacement {
    /// Camera-frame unit direction of each sorted axis (descending half-axes).
    axes: [[f64; 3]; 3],
    centre: [f64; 3],
    sorted: Sorted,
    /// 1 / e_k² in sorted order.
    inv_e2: [f64; 3],
}

impl SortedPlacement {
    pub fn new(placed: &PlacedEllipsoid) -> Self {
        let p = &placed.prepared;
        let col = |axis: usize| {
            let c = placed.rotation.column(axis);
            [c[0], c[1], c[2]]
        };
        SortedPlacement {
            axes: [col(p.perm[0]), col(p.perm[1]), col(p.perm[2])],
            centre: [placed.centre.x, placed.centre.y, placed.centre.z],
            sorted: p.sorted,
            inv_e2: p.inv_e2,
        }
    }

    /// Largest half-axis.
    #[inline]
    pub fn max_radius(&self) -> f64 {
        self.sorted.e[0]
    }

    /// Camera-frame centre.
    #[inline]
    pub fn centre(&self) -> [f64; 3] {
        self.centre
    }

    /// Smallest half-axis.
    #[inline]
    pub fn min_radius(&self) -> f64 {
        self.sorted.e[2]
    }

    /// The camera-frame point with coordinates `u` along the sorted axes scaled by the
    /// half-axes: a point of the surface when `u` is a unit vector (the same body point
    /// at every pose).
    #[inline]
    pub fn surface_point(&self, u: &[f64; 3]) -> [f64; 3] {
        let (e, a) = (&self.sorted.e, &self.axes);
        std::array::from_fn(|c| {
            self.centre[c] + e[0] * u[0] * a[0][c] + e[1] * u[1] * a[1][c] + e[2] * u[2] * a[2][c]
        })
    }

    /// Coordinates of camera-frame point `p` along the sorted axes (signed).
    #[inline]
    pub fn local(&self, p: &[f64; 3]) -> [f64; 3] {
        let d = [
            p[0] - self.centre[0],
            p[1] - self.centre[1],
            p[2] - self.centre[2],
        ];
        let a = &self.axes;
        [
            a[0][0] * d[0] + a[0][1] * d[1] + a[0][2] * d[2],
            a[1][0] * d[0] + a[1][1] * d[1] + a[1][2] * d[2],
            a[2][0] * d[0] + a[2][1] * d[1] + a[2][2] * d[2],
        ]
    }

    /// Σ (y_k / e_k)² of local coordinates `y` (< 1 inside).
    #[inline]
    fn level(&self, y: &[f64; 3]) -> f64 {
        y[0] * y[0] * self.inv_e2[0] + y[1] * y[1] * self.inv_e2[1] + y[2] * y[2] * self.inv_e2[2]
    }

    /// A lower bound of the unsigned distance from local point `y` to the surface,
    /// exact to compute (no iteration): for an outside point, both e_min·(s − 1) with
    /// s² the level (the map y ↦ y/e is (1/e_min)-Lipschitz) and |y| − e_max (the
    /// bounding sphere) bound it from below; for an inside point the bound is 0.
    #[inline]
    pub fn distance_lower_bound(&self, y: &[f64; 3]) -> f64 {
        let level = self.level(y);
        if level <= 1.0 {
            return 0.0;
        }
        let scaled = self.sorted.e[2] * (level.sqrt() - 1.0);
        let sphere = (y[0] * y[0] + y[1] * y[1] + y[2] * y[2]).sqrt() - self.sorted.e[0];
        scaled.max(sphere)
    }

    /// The thresholds of [`Self::is_beyond`] for distance `t`.
    #[inline]
    pub fn beyond(&self, t: f64) -> Beyond {
        if t <= 0.0 {
            // Every lower bound is ≥ 0 ≥ t.
            return Beyond {
                level: 0.0,
                norm2: 0.0,
            };
        }
        let s = 1.0 + t / self.sorted.e[2];
        let r = self.sorted.e[0] + t;
        Beyond {
            level: s * s,
            norm2: r * r,
        }
    }

    /// [`Self::distance_lower_bound`]`(y) >= t`, decided without square roots: the
    /// scaled bound passes t when the level passes (1 + t/e_min)², the sphere bound
    /// when |y|² passes (e_max + t)² (either puts `y` outside, for t > 0).
    #[inline]
    pub fn is_beyond(&self, b: &Beyond, y: &[f64; 3]) -> bool {
        self.level(y) >= b.level || y[0] * y[0] + y[1] * y[1] + y[2] * y[2] >= b.norm2
    }

    /// [`Self::is_beyond`]`(&self.beyond(t), y)` for a threshold `t` > 0 (infinite:
    /// false), with a multiplication by 1/e_min for the division: the same within a
    /// rounding, and no division for loops whose threshold changes at every point.
    #[inline]
    pub fn lower_bound_passes(&self, y: &[f64; 3], t: f64) -> bool {
        let s = 1.0 + t * self.sorted.inv_e[2];
        let r = self.sorted.e[0] + t;
        let b = Beyond {
            level: s * s,
            norm2: r * r,
        };
        self.is_beyond(&b, y)
    }

    /// [`Self::local`] and [`Self::is_beyond`] of many camera-frame points at once, the
    /// points given one coordinate per slice: `local[r][i]` and `beyond[i]` for point
    /// `i < beyond.len()`, bit for bit the one-point values, several points to a vector
    /// register (with AVX2 where the CPU has it).
    #[inline]
    pub fn locals_beyond(
        &self,
        b: &Beyond,
        points: [&[f64]; 3],
        local: [&mut [f64]; 3],
        beyond: &mut [bool],
    ) {
        locals_beyond_soa(self, b, points, local, beyond);
    }

    /// Splits camera-frame points by the truncation distance `t`: `far(i)` for each
    /// `(i, p)` of `items` whose distance lower bound is at least `t` (its exact
    /// distance is not needed), and the others, in local coordinates, written to the
    /// front of `near` and returned (for the batched distance queries). `near` must
    /// hold every item.
    #[inline]
    pub fn split_near<'n>(
        &self,
        t: f64,
        items: impl Iterator<Item = (usize, [f64; 3])>,
        mut far: impl FnMut(usize),
        near: &'n mut [(usize, [f64; 3])],
    ) -> &'n [(usize, [f64; 3])] {
        let beyond = self.beyond(t);
        let mut m = 0;
        for (i, p) in items {
            let y = self.local(&p);
            if self.is_beyond(&beyond, &y) {
                far(i);
            } else {
                near[m] = (i, y);
                m += 1;
            }
        }
        &near[..m]
    }

    /// Signed distance (negative inside) of local point `y` (from [`Self::local`]).
    #[inline]
    pub fn signed_distance_local(&self, y: &[f64; 3]) -> f64 {
        let ys = [y[0].abs(), y[1].abs(), y[2].abs()];
        let x = closest_sorted(&self.sorted, ys);
        self.signed_from_closest(&ys, &x)
    }

    /// Signed distance from the local point `y` and its closest point `x` (both
    /// first-octant, sorted).
    #[inline]
    fn signed_from_closest(&self, ys: &[f64; 3], x: &[f64; 3]) -> f64 {
        let d = ((ys[0] - x[0]) * (ys[0] - x[0])
            + (ys[1] - x[1]) * (ys[1] - x[1])
            + (ys[2] - x[2]) * (ys[2] - x[2]))
            .sqrt();
        if self.level(ys) < 1.0 {
            -d
        } else {
            d
        }
    }

    /// Signed distances of camera-frame points in single precision, for callers whose
    /// points and results are f32: `out[i]` for every `i < out.len()`. With AVX-512 or
    /// AVX2 the stream root-finder runs in f32 (modules `stream_f32` and
    /// `stream_f32_avx2`, the same bits: within ~3e-7 × max(1 m, |d|) of
    /// [`Self::signed_distance`]); else in f64, [`LANES`] points at a time in lockstep.
    ///
    /// With a `cap`, a point whose [`Self::distance_lower_bound`] reaches `cap` gets
    /// that bound instead of its distance (so every value below `cap` is exact, and
    /// each value is the same with or without a cap).
    pub fn signed_distances_camera_soa_f32(
        &self,
        p: [&[f32]; 3],
        cap: Option<f64>,
        out: &mut [f32],
    ) {
        #[cfg(target_arch = "x86_64")]
        {
            type BlockF32 = unsafe fn(&SortedPlacement, [&[f32]; 3], Option<f32>, &mut [f32]);
            let kernel: Option<BlockF32> = match stream::kernel() {
                stream::Kernel::Avx512 => Some(stream_f32::signed_distances_block_f32),
                stream::Kernel::Avx2 => Some(stream_f32_avx2::signed_distances_block_f32),
                stream::Kernel::Lockstep => None,
            };
            if let Some(kernel) = kernel {
                let cap = cap.map(|c| c as f32);
                for (b, o) in out.chunks_mut(stream::BLOCK).enumerate() {
                    let at = b * stream::BLOCK;
                    let block = [&p[0][at..], &p[1][at..], &p[2][at..]];
                    // SAFETY: the CPU has the kernel's instructions (`stream::kernel`).
                    unsafe { kernel(self, block, cap, o) };
                }
                return;
            }
        }
        self.signed_distances_camera_lockstep_f32(p, cap, out);
    }

    /// [`Self::signed_distances_camera_soa_f32`] without the stream: in f64, [`LANES`]
    /// points at a time in lockstep.
    fn signed_distances_camera_lockstep_f32(
        &self,
        p: [&[f32]; 3],
        cap: Option<f64>,
        out: &mut [f32],
    ) {
        for (b, o) in out.chunks_mut(stream::BLOCK).enumerate() {
            let at = b * stream::BLOCK;
            let mut near = [(0usize, [0.0f64; 3]); stream::BLOCK];
            let mut m = 0;
            for (i, v) in o.iter_mut().enumerate() {
                let j = at + i;
                let y = self.local(&[p[0][j] as f64, p[1][j] as f64, p[2][j] as f64]);
                match cap.map(|c| (c, self.distance_lower_bound(&y))) {
                    Some((c, lower)) if lower >= c => *v = lower as f32,
                    _ => {
                        near[m] = (i, y);
                        m += 1;
                    }
                }
            }
            self.signed_distances_batched(near[..m].iter().copied(), |i, d| o[i] = d as f32);
        }
    }

    /// Signed distances of many local points (from [`Self::local`]), [`LANES`] at a time
    /// through the lockstep root-finder: `emit(i, d)` receives each `(i, y)` of `items`
    /// with the same value [`Self::signed_distance_local`] gives (points on a coordinate
    /// plane at once, the others when their group of [`LANES`] fills or at the end).
    #[inline]
    pub fn signed_distances_batched(
        &self,
        items: impl Iterator<Item = (usize, [f64; 3])>,
        mut emit: impl FnMut(usize, f64),
    ) {
        #[cfg(target_arch = "x86_64")]
        if let Some(kernel) = Self::stream_kernel::<false>() {
            self.streamed::<false>(kernel, items, |i, d, _| emit(i, d));
            return;
        }
        self.closest_lockstep(items, |i, _, ys, x| {
            emit(i, self.signed_from_closest(ys, x))
        });
    }

    /// [`Self::signed_distances_batched`] with the normal: `emit(i, d, n)` receives the
    /// signed distance and camera-frame outward unit normal of each local point, the
    /// values [`Self::distance_and_normal`] gives for the camera-frame point.
    #[inline]
    pub fn distances_and_normals_batched(
        &self,
        items: impl Iterator<Item = (usize, [f64; 3])>,
        mut emit: impl FnMut(usize, f64, [f64; 3]),
    ) {
        #[cfg(target_arch = "x86_64")]
        if let Some(kernel) = Self::stream_kernel::<true>() {
            self.streamed::<true>(kernel, items, emit);
            return;
        }
        self.closest_lockstep(items, |i, y, ys, x| {
            emit(i, self.signed_from_closest(ys, x), self.normal_at(y, x))
        });
    }

    /// The stream kernel this CPU runs ([`stream::kernel`]), for distances and (with
    /// `NORMALS`) normals; None for the lockstep.
    #[cfg(target_arch = "x86_64")]
    fn stream_kernel<const NORMALS: bool>() -> Option<StreamKernel> {
        match stream::kernel() {
            stream::Kernel::Avx512 => Some(stream::distances_block::<NORMALS>),
            stream::Kernel::Avx2 => Some(stream_avx2::distances_block::<NORMALS>),
            stream::Kernel::Lockstep => None,
        }
    }

    /// The batched queries through a stream `kernel` (module `stream`): the items
    /// buffered one coordinate per array, [`stream::BLOCK`] at a time; `emit(i, d, n)`
    /// (`n` only with `NORMALS`, whose kernel computes them; else zeros).
    #[cfg(target_arch = "x86_64")]
    fn streamed<const NORMALS: bool>(
        &self,
        kernel: StreamKernel,
        items: impl Iterator<Item = (usize, [f64; 3])>,
        mut emit: impl FnMut(usize, f64, [f64; 3]),
    ) {
        use stream::BLOCK;
        // Left uninitialised (zeroing ~16 KB per call would cost more than a short
        // call's solve); only the entries written are read.
        let mut index = std::mem::MaybeUninit::<[usize; BLOCK]>::uninit();
        let mut columns = std::mem::MaybeUninit::<[[f64; BLOCK]; 7]>::uninit();
        let index = index.as_mut_ptr() as *mut usize;
        let base = columns.as_mut_ptr() as *mut f64;
        // SAFETY: the pointers stay inside the two buffers; a block's first m points
        // are written before slices are made of them, and its results are read only
        // after the kernel wrote them; the CPU has the kernel's instructions (the
        // callers take it from `stream_kernel`, or the test from feature detection).
        let mut flush = |m: usize| unsafe {
            let col = |k: usize| base.add(k * BLOCK);
            let y = [0, 1, 2].map(|k| std::slice::from_raw_parts(col(k), m));
            kernel(self, y, col(3), [col(4), col(5), col(6)]);
            let d = std::slice::from_raw_parts(col(3), m);
            if NORMALS {
                let n = [4, 5, 6].map(|k| std::slice::from_raw_parts(col(k), m));
                for j in 0..m {
                    emit(*index.add(j), d[j], [n[0][j], n[1][j], n[2][j]]);
                }
            } else {
                for (j, &dj) in d.iter().enumerate() {
                    emit(*index.add(j), dj, [0.0; 3]);
                }
            }
        };
        let mut m = 0;
        for (i, y) in items {
            // SAFETY: m < BLOCK.
            unsafe {
                *index.add(m) = i;
                for (k, &v) in y.iter().enumerate() {
                    *base.add(k * BLOCK + m) = v;
                }
            }
            m += 1;
            if m == BLOCK {
                flush(m);
                m = 0;
            }
        }
        if m > 0 {
            flush(m);
        }
    }

    /// The first-octant closest point `x` of each local point `y` of `items`:
    /// `emit(i, y, |y|, x)`, the values `closest_sorted` gives, through the lockstep
    /// root-finder [`LANES`] points at a time (points on a coordinate plane one by one,
    /// through the special cases). The batched queries' path without a stream kernel.
    #[inline]
    fn closest_lockstep(
        &self,
        items: impl Iterator<Item = (usize, [f64; 3])>,
        mut emit: impl FnMut(usize, &[f64; 3], &[f64; 3], &[f64; 3]),
    ) {
        let c = &self.sorted;
        let mut idx = [0usize; LANES];
        let mut yl = [[0.0; 3]; LANES];
        let mut ys = [[0.0; 3]; LANES];
        let mut n = 0;
        for (i, y) in items {
            let a = [y[0].abs(), y[1].abs(), y[2].abs()];
            if a[2] > 0.0 {
                idx[n] = i;
                yl[n] = y;
                ys[n] = a;
                n += 1;
                if n == LANES {
                    let mut sa = [[0.0; 3]; LANES];
                    let mut lo = [0.0; LANES];
                    let mut hi = [0.0; LANES];
                    for l in 0..LANES {
                        (sa[l], lo[l], hi[l]) = c.secular_setup(&ys[l]);
                    }
                    let u = solve_secular_lanes(&sa, &c.b, lo, hi);
                    for l in 0..LANES {
                        let x = c.closest_from_root(&sa[l], u[l]);
                        emit(idx[l], &yl[l], &ys[l], &x);
                    }
                    n = 0;
                }
            } else {
                emit(i, &y, &a, &closest_sorted(c, a));
            }
        }
        for l in 0..n {
            emit(idx[l], &yl[l], &ys[l], &closest_sorted(c, ys[l]));
        }
    }

    /// Camera-frame outward unit normal at the closest point `x` (first octant) of the
    /// local point `y` (signed).
    #[inline]
    fn normal_at(&self, y: &[f64; 3], x: &[f64; 3]) -> [f64; 3] {
        let g = [
            x[0].copysign(y[0]) * self.inv_e2[0],
            x[1].copysign(y[1]) * self.inv_e2[1],
            x[2].copysign(y[2]) * self.inv_e2[2],
        ];
        let inv = 1.0 / (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
        let a = &self.axes;
        let mut n = [0.0; 3];
        for (c, v) in n.iter_mut().enumerate() {
            *v = (g[0] * a[0][c] + g[1] * a[1][c] + g[2] * a[2][c]) * inv;
        }
        n
    }

    /// Signed distance (negative inside) of camera-frame point `p`.
    #[inline]
    pub fn signed_distance(&self, p: &[f64; 3]) -> f64 {
        self.signed_distance_local(&self.local(p))
    }

    /// Signed distance and camera-frame outward unit normal at the closest point (the
    /// gradient of the signed distance with respect to `p`).
    #[inline]
    pub fn distance_and_normal(&self, p: &[f64; 3]) -> (f64, [f64; 3]) {
        let y = self.local(p);
        let ys = [y[0].abs(), y[1].abs(), y[2].abs()];
        let x = closest_sorted(&self.sorted, ys);
        (self.signed_from_closest(&ys, &x), self.normal_at(&y, &x))
    }
}

avx2_dispatch! {
    /// [`SortedPlacement::locals_beyond`]: the same expressions as the one-point
    /// methods, in the same order (no reassociation, no fused multiply-add), so the
    /// values are identical.
    fn locals_beyond_soa(
        e: &SortedPlacement,
        b: &Beyond,
        points: [&[f64]; 3],
        local: [&mut [f64]; 3],
        beyond: &mut [bool],
    ) {
        let n = beyond.len();
        let [px, py, pz] = points;
        let (px, py, pz) = (&px[..n], &py[..n], &pz[..n]);
        let [l0, l1, l2] = local;
        let (l0, l1, l2) = (&mut l0[..n], &mut l1[..n], &mut l2[..n]);
        let (a, c, inv) = (&e.axes, &e.centre, &e.inv_e2);
        for i in 0..n {
            let d = [px[i] - c[0], py[i] - c[1], pz[i] - c[2]];
            let y0 = a[0][0] * d[0] + a[0][1] * d[1] + a[0][2] * d[2];
            let y1 = a[1][0] * d[0] + a[1][1] * d[1] + a[1][2] * d[2];
            let y2 = a[2][0] * d[0] + a[2][1] * d[1] + a[2][2] * d[2];
            l0[i] = y0;
            l1[i] = y1;
            l2[i] = y2;
            let level = y0 * y0 * inv[0] + y1 * y1 * inv[1] + y2 * y2 * inv[2];
            beyond[i] = (level >= b.level) | (y0 * y0 + y1 * y1 + y2 * y2 >= b.norm2);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Brute force: the nearest of a dense parametric sampling, refined by a local
    /// search on the sphere parameters.
    fn brute_force(e: &Vector3<f64>, y: &Vector3<f64>) -> f64 {
        let point = |th: f64, ph: f64| {
            Vector3::new(
                e.x * th.sin() * ph.cos(),
                e.y * th.sin() * ph.sin(),
                e.z * th.cos(),
            )
        };
        let n = 200;
        let mut best = (f64::INFINITY, 0.0, 0.0);
        for i in 0..=n {
            let th = std::f64::consts::PI * i as f64 / n as f64;
            for j in 0..2 * n {
                let ph = std::f64::consts::PI * j as f64 / n as f64;
                let d = (point(th, ph) - y).norm();
                if d < best.0 {
                    best = (d, th, ph);
                }
            }
        }
        // Pattern search refinement.
        let mut step = std::f64::consts::PI / n as f64;
        while step > 1e-12 {
            let mut improved = false;
            for (dt, dp) in [(step, 0.0), (-step, 0.0), (0.0, step), (0.0, -step)] {
                let (th, ph) = (best.1 + dt, best.2 + dp);
                let d = (point(th, ph) - y).norm();
                if d < best.0 {
                    best = (d, th, ph);
                    improved = true;
                }
            }
            if !improved {
                step *= 0.5;
            }
        }
        best.0
    }

    fn check(e: Vector3<f64>, y: Vector3<f64>) {
        let r = closest_point_on_ellipsoid(&e, &y);
        let bf = brute_force(&e, &y);
        assert!(
            (r.distance.abs() - bf).abs() < 1e-5,
            "e={e:?} y={y:?}: {} vs brute force {bf}",
            r.distance
        );
        // On the surface, and y = x + d·n.
        let level = (r.closest.component_div(&e)).norm_squared();
        assert!(
            (level - 1.0).abs() < 1e-9,
            "closest not on surface: {level}"
        );
        assert!((r.normal.norm() - 1.0).abs() < 1e-9);
        if r.distance.abs() > 1e-9 {
            assert!((r.closest + r.normal * r.distance - y).norm() < 1e-8);
        }
        let inside = (y.component_div(&e)).norm_squared() < 1.0;
        assert_eq!(inside, r.distance < 0.0);
    }

    #[test]
    fn special_cases() {
        let e = Vector3::new(0.3, 0.1, 0.05);
        check(e, Vector3::new(0.0, 0.0, 0.0));
        check(e, Vector3::new(0.1, 0.0, 0.0));
        check(e, Vector3::new(0.0, 0.02, 0.0));
        check(e, Vector3::new(0.0, 0.0, 0.01));
        check(e, Vector3::new(0.25, 0.05, 0.0));
        check(e, Vector3::new(5.0, 0.0, 0.0));
        check(e, Vector3::new(-3.0, 7.0, -2.0));
        check(e, Vector3::new(0.3, 0.0, 0.0));
        // Near-spherical and flat.
        check(Vector3::new(0.1, 0.1, 0.1), Vector3::new(0.02, -0.01, 0.03));
        check(Vector3::new(0.1, 0.1, 0.1), Vector3::new(0.0, 0.0, 0.0));
        check(
            Vector3::new(0.1, 0.1 + 1e-12, 0.1),
            Vector3::new(0.3, 0.2, -0.1),
        );
        check(Vector3::new(0.2, 0.2, 0.001), Vector3::new(0.05, 0.05, 0.0));
        check(
            Vector3::new(0.2, 0.2, 0.001),
            Vector3::new(0.05, 0.05, 1e-7),
        );
        check(
            Vector3::new(0.2, 0.15, 0.001),
            Vector3::new(0.15, 0.1, 1e-300),
        );
        check(Vector3::new(0.05, 0.4, 0.05), Vector3::new(1e-9, 0.0, 1e-9));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(40))]
        #[test]
        fn matches_brute_force(
            ex in 0.02f64..0.4, ey in 0.02f64..0.4, ez in 0.02f64..0.4,
            px in -1.0f64..1.0, py in -1.0f64..1.0, pz in -1.0f64..1.0, scale in 0.05f64..2.0,
        ) {
            let e = Vector3::new(ex, ey, ez);
            // Mix points near the surface and far away.
            let y = Vector3::new(px, py, pz).component_mul(&e) * (2.0 * scale);
            check(e, y);
        }
    }

    /// Independent reference: plain bisection on F(t) = Σ (e_i y_i / (t + e_i²))² − 1
    /// over (−e_min², |y|·e_max], run until the bracket cannot shrink any more (every
    /// f64 between the ends is tried), for points off the coordinate planes.
    fn bisection_reference(e: &Vector3<f64>, y: &Vector3<f64>) -> f64 {
        let f = |t: f64| {
            (0..3)
                .map(|i| (e[i] * y[i] / (t + e[i] * e[i])).powi(2))
                .sum::<f64>()
                - 1.0
        };
        let e_min2 = e.min() * e.min();
        let (mut lo, mut hi) = (-e_min2, y.norm() * e.max());
        loop {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break;
            }
            if f(mid) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let t = 0.5 * (lo + hi);
        let x = Vector3::from_fn(|i, _| e[i] * e[i] * y[i] / (t + e[i] * e[i]));
        let d = (y - x).norm();
        if y.component_div(e).norm_squared() < 1.0 {
            -d
        } else {
            d
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]
        /// The hot-loop path (axis sort folded into the rotation, distance-only and
        /// distance + normal variants, the lower bound) against the bisection reference.
        #[test]
        fn sorted_placement_matches_reference(
            ex in 0.01f64..0.4, ey in 0.01f64..0.4, ez in 0.01f64..0.4,
            flat in 0usize..4,
            px in -1.0f64..1.0, py in -1.0f64..1.0, pz in -1.0f64..1.0,
            scale in prop_oneof![0.001f64..0.5, 0.5f64..1.5, 1.5f64..40.0],
            angles in (-3.0f64..3.0, -1.5f64..1.5, -3.0f64..3.0),
        ) {
            // Include near-spherical, needle and pancake shapes.
            let e = match flat {
                0 => Vector3::new(ex, ey, ez),
                1 => Vector3::new(ex, ex * (1.0 + 1e-9), ex),
                2 => Vector3::new(ex, ey, 1e-3 * ez),
                _ => Vector3::new(ex, 1e-2 * ey, 1e-2 * ey),
            };
            prop_assume!(px.abs() > 1e-3 && py.abs() > 1e-3 && pz.abs() > 1e-3);
            let y = Vector3::new(px, py, pz).component_mul(&e) * scale;
            let reference = bisection_reference(&e, &y);
            let rot = nalgebra::Rotation3::from_euler_angles(angles.0, angles.1, angles.2);
            let placed = PlacedEllipsoid {
                centre: Vector3::new(0.3, -0.2, 2.5),
                rotation: *rot.matrix(),
                prepared: Prepared::new(&e),
            };
            let p = placed.rotation * y + placed.centre;
            let fast = SortedPlacement::new(&placed);
            let pa = [p.x, p.y, p.z];
            let d = fast.signed_distance(&pa);
            let tol = 1e-9 * (1.0 + y.norm());
            prop_assert!((d - reference).abs() < tol, "{d} vs reference {reference}");
            let (d2, n) = fast.distance_and_normal(&pa);
            prop_assert_eq!(d, d2);
            let q = placed.query(&p);
            prop_assert!((q.distance - d).abs() < 1e-12 * (1.0 + y.norm()));
            let n = Vector3::new(n[0], n[1], n[2]);
            prop_assert!((n - q.normal).norm() < 1e-9);
            let lower = fast.distance_lower_bound(&fast.local(&pa));
            // Relative slack: on a near-sphere the sphere bound *is* the distance, and
            // the two round differently (CI once saw 3.9238421640003 > 3.9238421639976).
            prop_assert!(lower >= 0.0 && lower <= d.abs() * (1.0 + 1e-11) + 1e-12, "{lower} > {d}");
            // The square-root-free test agrees with the bound, away from rounding ties
            // (whose width scales with the coordinates, not with t).
            let yl = fast.local(&pa);
            let tie = 1e-12 * (1.0 + y.norm());
            for t in [-0.1, 0.0, 0.5 * lower, lower * (1.0 - 1e-9), lower * (1.0 + 1e-9), 2.0 * lower + 0.01] {
                if t <= 0.0 || (lower - t).abs() > tie * (1.0 + t) {
                    prop_assert_eq!(fast.is_beyond(&fast.beyond(t), &yl), lower >= t, "t {}", t);
                }
                // The same with the division by e_min as a multiplication (t > 0).
                if t > 0.0 && (lower - t).abs() > tie * (1.0 + t) {
                    prop_assert_eq!(fast.lower_bound_passes(&yl, t), lower >= t, "t {}", t);
                }
            }
            prop_assert!(!fast.lower_bound_passes(&yl, f64::INFINITY));
            // Many points at once: the same local coordinates and test, bit for bit.
            let cloud: Vec<[f64; 3]> = (0..11)
                .map(|k| {
                    let f = 0.3 * k as f64 - 1.5;
                    [pa[0] + f * 0.1, pa[1] - f * f * 0.05, pa[2] + f * 0.07]
                })
                .collect();
            let coord = |r: usize| cloud.iter().map(|p| p[r]).collect::<Vec<f64>>();
            let (cx, cy, cz) = (coord(0), coord(1), coord(2));
            let mut local = [vec![0.0; 11], vec![0.0; 11], vec![0.0; 11]];
            let mut beyond = vec![false; 11];
            let b = fast.beyond(0.5 * lower + 0.01);
            let [l0, l1, l2] = &mut local;
            fast.locals_beyond(&b, [&cx, &cy, &cz], [l0, l1, l2], &mut beyond);
            for (i, p) in cloud.iter().enumerate() {
                let y = fast.local(p);
                prop_assert_eq!([local[0][i], local[1][i], local[2][i]], y);
                prop_assert_eq!(beyond[i], fast.is_beyond(&b, &y));
            }
            // The batched queries (lockstep lanes, and the scalar tail) give the same
            // distance and normal, whichever lane (or the tail) the point takes.
            let (d2, n2) = fast.distance_and_normal(&pa);
            let y_local = fast.local(&pa);
            let others = [[0.05, 0.1, -0.2], [-0.3, 0.02, 0.01], [0.2, -0.2, 0.4]];
            for slot in 0..=LANES {
                // `slot` points before it, then enough to fill the lanes: it sits in
                // lane `slot`, or (slot = LANES) alone in the tail.
                let mut items: Vec<[f64; 3]> = others.iter().cycle().take(slot).copied().collect();
                items.push(y_local);
                items.extend(others.iter().cycle().take(LANES.saturating_sub(slot + 1)));
                let mut got = None;
                fast.distances_and_normals_batched(
                    items.iter().copied().enumerate(),
                    |i, dd, nn| if i == slot { got = Some((dd, nn)) },
                );
                prop_assert_eq!(got, Some((d2, n2)));
                let mut got = None;
                fast.signed_distances_batched(items.iter().copied().enumerate(), |i, dd| {
                    if i == slot {
                        got = Some(dd)
                    }
                });
                prop_assert_eq!(got, Some(d2));
            }
        }
    }

    /// The AVX2 root-finder gives, lane by lane, bit for bit what the portable lanes and
    /// the scalar `solve_secular` give, over ellipsoids from near-spherical to flat and
    /// points inside, near and far (checked only where the CPU has AVX2).
    #[test]
    fn root_finder_lanes_agree_bit_for_bit() {
        let mut seed = 0x2545_F491_4F6C_DD1Du64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut compared = 0;
        for _ in 0..400 {
            let radii = Vector3::new(0.02 + 0.4 * rnd(), 0.02 + 0.4 * rnd(), 0.02 + 0.4 * rnd());
            let placed = PlacedEllipsoid {
                centre: Vector3::zeros(),
                rotation: Matrix3::identity(),
                prepared: Prepared::new(&radii),
            };
            let fast = SortedPlacement::new(&placed);
            let c = &fast.sorted;
            let scale = [0.01, 0.3, 1.0, 3.0][(rnd() * 4.0) as usize];
            let mut sa = [[0.0; 3]; LANES];
            let (mut lo, mut hi) = ([0.0; LANES], [0.0; LANES]);
            for l in 0..LANES {
                let y = [rnd() * scale, rnd() * scale, (rnd() * scale).max(1e-9)];
                (sa[l], lo[l], hi[l]) = c.secular_setup(&y);
            }
            let portable = solve_secular_lanes_portable(&sa, &c.b, lo, hi);
            for l in 0..LANES {
                let scalar = solve_secular(&sa[l], &c.b, lo[l], hi[l]);
                assert_eq!(portable[l].to_bits(), scalar.to_bits());
            }
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: AVX2 is present (checked just above).
                let wide = unsafe { solve_secular_lanes_avx2(&sa, &c.b, lo, hi) };
                for l in 0..LANES {
                    assert_eq!(wide[l].to_bits(), portable[l].to_bits(), "lane {l}");
                }
                compared += 1;
            }
        }
        eprintln!("AVX2 lanes compared on {compared} groups");
    }

    /// The batched distances and normals (through every stream kernel the CPU runs) and
    /// the lockstep ones give bit for bit the one-point values, over ellipsoids
    /// from near-spherical to flat, points inside, near and far, on coordinate planes
    /// and axes, batches that are not multiples of 8 and runs longer than one block.
    #[test]
    fn batched_closest_points_agree_bit_for_bit() {
        let mut seed = 0x9E37_79B9_7F4A_7C15u64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for trial in 0..300 {
            let mut radii =
                Vector3::new(0.02 + 0.4 * rnd(), 0.02 + 0.4 * rnd(), 0.02 + 0.4 * rnd());
            if trial % 7 == 0 {
                radii = Vector3::repeat(radii.x); // a sphere
            } else if trial % 7 == 1 {
                radii.y = radii.x; // a spheroid
            }
            let rot = nalgebra::Rotation3::from_euler_angles(rnd() * 3.0, rnd(), rnd() * 2.0);
            let e = SortedPlacement::new(&PlacedEllipsoid {
                centre: Vector3::new(rnd() - 0.5, rnd() - 0.5, 1.0 + 3.0 * rnd()),
                rotation: *rot.matrix(),
                prepared: Prepared::new(&radii),
            });
            let n = [1, 7, 8, 9, 100, 256, 257, 700][trial % 8];
            let scale = [0.01, 0.3, 1.0, 3.0][(rnd() * 4.0) as usize];
            let mut local = vec![[0.0; 3]; n];
            for y in local.iter_mut() {
                *y = [0.0; 3].map(|_| (2.0 * rnd() - 1.0) * scale);
                // Some points on coordinate planes and axes, and at the centre.
                match (rnd() * 12.0) as usize {
                    0 => y[0] = 0.0,
                    1 => y[1] = 0.0,
                    2 => y[2] = 0.0,
                    3 => (y[0], y[1]) = (0.0, 0.0),
                    4 => (y[1], y[2]) = (0.0, 0.0),
                    5 => *y = [0.0; 3],
                    _ => {}
                }
            }
            // Every other point, in a shuffled order, as the callers pass subsets.
            let items = || {
                (0..n)
                    .rev()
                    .filter(|i| i % 2 == 0 || n < 9)
                    .map(|i| (i, local[i]))
            };
            let mut seen = vec![0u32; n];
            let one_point = |i: usize| {
                let ys = local[i].map(f64::abs);
                let x = closest_sorted(&e.sorted, ys);
                (e.signed_from_closest(&ys, &x), e.normal_at(&local[i], &x))
            };
            e.distances_and_normals_batched(items(), |i, d, nrm| {
                let (d1, n1) = one_point(i);
                assert_eq!(d.to_bits(), d1.to_bits(), "trial {trial} point {i}");
                assert_eq!(nrm.map(f64::to_bits), n1.map(f64::to_bits));
                seen[i] += 1;
            });
            e.signed_distances_batched(items(), |i, d| {
                assert_eq!(d.to_bits(), e.signed_distance_local(&local[i]).to_bits());
                seen[i] += 1;
            });
            e.closest_lockstep(items(), |i, _, ys, x| {
                assert_eq!(
                    e.signed_from_closest(ys, x).to_bits(),
                    one_point(i).0.to_bits()
                );
                seen[i] += 1;
            });
            // Every stream kernel this CPU runs, whichever the process chose.
            #[cfg(target_arch = "x86_64")]
            for (distances, normals) in stream_kernels() {
                e.streamed::<true>(normals, items(), |i, d, nrm| {
                    let (d1, n1) = one_point(i);
                    assert_eq!(d.to_bits(), d1.to_bits(), "trial {trial} point {i}");
                    assert_eq!(nrm.map(f64::to_bits), n1.map(f64::to_bits));
                    seen[i] += 1;
                });
                e.streamed::<false>(distances, items(), |i, d, _| {
                    assert_eq!(d.to_bits(), one_point(i).0.to_bits());
                    seen[i] += 1;
                });
            }
            #[cfg(target_arch = "x86_64")]
            let calls = 3 + 2 * stream_kernels().len() as u32;
            #[cfg(not(target_arch = "x86_64"))]
            let calls = 3;
            for (i, &s) in seen.iter().enumerate() {
                assert_eq!(s, if i % 2 == 0 || n < 9 { calls } else { 0 }, "point {i}");
            }
        }
        #[cfg(target_arch = "x86_64")]
        eprintln!("stream kernels compared: {}", stream_kernels().len());
    }

    /// The (distances, distances and normals) stream kernels this CPU runs.
    #[cfg(target_arch = "x86_64")]
    fn stream_kernels() -> Vec<(StreamKernel, StreamKernel)> {
        let mut kernels: Vec<(StreamKernel, StreamKernel)> = Vec::new();
        if is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("bmi2") {
            kernels.push((
                stream::distances_block::<false>,
                stream::distances_block::<true>,
            ));
        }
        if is_x86_feature_detected!("avx2") {
            kernels.push((
                stream_avx2::distances_block::<false>,
                stream_avx2::distances_block::<true>,
            ));
        }
        kernels
    }

    /// The single-precision block distances stay within 2e-6 m of the f64 distances of
    /// the same (f32) points, over ellipsoids from near-spherical to flat and clouds
    /// from the surface out to a few metres, up to 6 m from the camera.
    #[test]
    fn f32_block_distances_match_f64() {
        let mut seed = 0xD1B5_4A32_D192_ED03u64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut worst, mut compared, mut bounded) = (0.0f64, 0usize, 0usize);
        let mut avx2_compared = 0;
        for trial in 0..400 {
            let mut radii =
                Vector3::new(0.02 + 0.4 * rnd(), 0.02 + 0.4 * rnd(), 0.02 + 0.4 * rnd());
            if trial % 7 == 0 {
                radii = Vector3::repeat(radii.x);
            } else if trial % 7 == 1 {
                radii.y = radii.x;
            } else if trial % 7 == 2 {
                radii.z = 0.005; // flat
            }
            let rot = nalgebra::Rotation3::from_euler_angles(rnd() * 3.0, rnd(), rnd() * 2.0);
            let centre = Vector3::new(2.0 * rnd() - 1.0, 2.0 * rnd() - 1.0, 1.0 + 3.0 * rnd());
            let e = SortedPlacement::new(&PlacedEllipsoid {
                centre,
                rotation: *rot.matrix(),
                prepared: Prepared::new(&radii),
            });
            let n = [1, 15, 16, 17, 100, 256, 257, 700][trial % 8];
            let scale = [0.01, 0.1, 0.3, 1.0, 2.0][(rnd() * 5.0) as usize];
            let mut p = [vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n]];
            for i in 0..n {
                // Around the surface: a point of the surface direction scaled in or out.
                let dir = Vector3::new(2.0 * rnd() - 1.0, 2.0 * rnd() - 1.0, 2.0 * rnd() - 1.0);
                let local = dir.component_mul(&radii) * (0.2 + 1.6 * rnd())
                    + dir.normalize() * scale * rnd();
                let q = centre + rot * local;
                for (c, v) in p.iter_mut().zip(q.iter()) {
                    c[i] = *v as f32;
                }
            }
            let pts = [&p[0][..], &p[1], &p[2]];
            let mut out = vec![f32::NAN; n];
            e.signed_distances_camera_soa_f32(pts, None, &mut out);
            let mut lockstep = vec![f32::NAN; n];
            e.signed_distances_camera_lockstep_f32(pts, None, &mut lockstep);
            // With a cap: exact below it (the same values), the lower bound above.
            let cap = [0.01, 0.05, 0.3][trial % 3];
            let mut capped = vec![f32::NAN; n];
            e.signed_distances_camera_soa_f32(pts, Some(cap), &mut capped);
            let mut capped_lockstep = vec![f32::NAN; n];
            e.signed_distances_camera_lockstep_f32(pts, Some(cap), &mut capped_lockstep);
            // Both single-precision kernels, where the CPU runs them, give the same bits
            // (the AVX2 one emulates the AVX-512 one's instructions, same arithmetic).
            #[cfg(target_arch = "x86_64")]
            if is_x86_feature_detected!("avx2") {
                for c in [None, Some(cap as f32)] {
                    let mut narrow = vec![f32::NAN; n];
                    for (b, o) in narrow.chunks_mut(stream::BLOCK).enumerate() {
                        let at = b * stream::BLOCK;
                        let block = [&p[0][at..], &p[1][at..], &p[2][at..]];
                        // SAFETY: the CPU has AVX2 (checked above).
                        unsafe { stream_f32_avx2::signed_distances_block_f32(&e, block, c, o) };
                    }
                    let reference = if c.is_some() { &capped } else { &out };
                    if stream::kernel() == stream::Kernel::Avx512 {
                        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                        assert_eq!(bits(&narrow), bits(reference), "trial {trial}, cap {c:?}");
                    }
                    for i in 0..n {
                        let q = [p[0][i] as f64, p[1][i] as f64, p[2][i] as f64];
                        let exact = e.signed_distance(&q);
                        if c.is_none() || (narrow[i] as f64) < cap {
                            assert!((narrow[i] as f64 - exact).abs() <= 2e-6);
                        } else {
                            assert!(narrow[i] as f64 >= cap - 1e-6);
                            assert!(narrow[i] as f64 <= exact + 1e-6);
                        }
                    }
                    avx2_compared += 1;
                }
            }
            for i in 0..n {
                let q = [p[0][i] as f64, p[1][i] as f64, p[2][i] as f64];
                let exact = e.signed_distance(&q);
                let err = (out[i] as f64 - exact).abs();
                assert!(
                    err <= 2e-6,
                    "trial {trial} point {i}: {} vs {exact}",
                    out[i]
                );
                assert!((lockstep[i] as f64 - exact).abs() <= 1e-6);
                worst = worst.max(err);
                compared += 1;
                for (c, full) in [(capped[i], out[i]), (capped_lockstep[i], lockstep[i])] {
                    if (c as f64) < cap {
                        assert_eq!(c, full, "trial {trial} point {i} below the cap");
                    } else {
                        assert!(c as f64 >= cap - 1e-6 && c <= full + 1e-6, "{c} vs {full}");
                        bounded += (c != full) as usize;
                    }
                }
            }
        }
        assert!(
            bounded > 1000,
            "the cap's bounds were exercised on {bounded} values"
        );
        eprintln!("f32 distances: worst error {worst:.2e} m over {compared} points");
        eprintln!("f32 AVX2 kernel compared on {avx2_compared} blocks");
    }

    #[test]
    fn placed_matches_local_query() {
        let rot = nalgebra::Rotation3::from_euler_angles(0.3, -0.7, 1.1);
        let placed = PlacedEllipsoid {
            centre: Vector3::new(0.1, -0.2, 2.0),
            rotation: *rot.matrix(),
            prepared: Prepared::new(&Vector3::new(0.1, 0.25, 0.07)),
        };
        let p = Vector3::new(0.3, 0.1, 2.2);
        let r = placed.query(&p);
        let local = rot.inverse() * (p - placed.centre);
        let l = closest_point_on_ellipsoid(&Vector3::new(0.1, 0.25, 0.07), &local);
        assert!((r.distance - l.distance).abs() < 1e-12);
        assert!((r.closest + r.normal * r.distance - p).norm() < 1e-9);
    }
}
