//! The root-finder of the closest-point problem and the scalar closest point: the
//! secular equation in one query and in lockstep over a few, the 2-D and planar special
//! cases, and the constants of a sorted ellipsoid.

/// Newton/bisection stops when the step is below this relative size. Newton converges
/// quadratically, so the iterate after a step δ is off by about K·δ² (K = |H''/2H'|,
/// order one for the normalised H): with δ ≤ 1e-6 that is ~1e-12 relative, at the
/// level of rounding in the distance (the tests compare with a bisection reference run
/// to the last bit), without the extra iteration a 1e-9 tolerance spends confirming
/// it. (Asking for steps of a few ulps makes the iteration chase rounding noise in H.)
pub(super) const ROOT_TOLERANCE: f64 = 1e-6;
/// |H| below this is a root to rounding precision.
pub(super) const H_TOLERANCE: f64 = 4.0 * f64::EPSILON;
/// Iteration cap; bisection alone halves the bracket each step, so 2 × 64 suffices.
pub(super) const MAX_ITERATIONS: usize = 128;

/// 1/(u + b_k) for every k with one division (batch inversion through the prefix
/// products): divisions dominate the root-finder's iterations. All factors are
/// positive and moderate (u > 0, b_k ≥ 0), so the products neither overflow nor
/// underflow.
#[inline(always)]
pub(super) fn reciprocals<const N: usize>(u: f64, b: &[f64; N]) -> [f64; N] {
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
pub(super) fn solve_secular<const N: usize>(
    a: &[f64; N],
    b: &[f64; N],
    mut lo: f64,
    mut hi: f64,
) -> f64 {
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

/// Queries solved together by the lockstep root-finder.
pub const LANES: usize = 4;

/// [`solve_secular`] for `N` independent 3-term problems sharing `b`, in lockstep:
/// the same arithmetic and stopping rule lane by lane (so bit-identical results), but
/// the lanes' divisions and square roots are independent, so the CPU overlaps them
/// instead of waiting on one dependency chain.
#[inline]
pub(super) fn solve_secular_lockstep<const N: usize>(
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

/// [`solve_secular_lockstep`] on the [`LANES`] lanes: without vector instructions a
/// lane in lockstep costs as much as a query of its own, but the lanes' divisions and
/// square roots overlap.
#[inline]
pub(super) fn solve_secular_lanes(
    a: &[[f64; 3]; LANES],
    b: &[f64; 3],
    lo: [f64; LANES],
    hi: [f64; LANES],
) -> [f64; LANES] {
    solve_secular_lockstep(a, b, lo, hi)
}

/// Closest point for sorted axes e0 ≥ e1 > 0 in 2-D, y ≥ 0.
#[inline]
pub(super) fn closest_2d(e: [f64; 2], y: [f64; 2]) -> [f64; 2] {
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
pub(super) struct Sorted {
    /// Half-axes, descending.
    pub(super) e: [f64; 3],
    /// 1 / e_k.
    pub(super) inv_e: [f64; 3],
    /// r_k = (e_k / e2)².
    pub(super) r: [f64; 3],
    /// b_k = r_k − 1 (the shifts of the normalised secular equation).
    pub(super) b: [f64; 3],
}

impl Sorted {
    pub(super) fn new(e: [f64; 3]) -> Self {
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
    pub(super) fn secular_setup(&self, y: &[f64; 3]) -> ([f64; 3], f64, f64) {
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
    pub(super) fn closest_from_root(&self, a: &[f64; 3], u: f64) -> [f64; 3] {
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
pub(super) fn closest_sorted(c: &Sorted, y: [f64; 3]) -> [f64; 3] {
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
