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

/// Newton/bisection stops when the step is below this relative size: Newton converges
/// quadratically, so after a step of 1e-9 the error is at rounding level. (Asking for
/// steps of a few ulps makes the iteration chase rounding noise in H.)
const ROOT_TOLERANCE: f64 = 1e-9;
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

/// Root u of S(u) = Σ_k (a_k / (u + b_k))² = 1 on [lo, hi] (S decreasing, S(lo) ≥ 1 ≥
/// S(hi)); `a_k` ≥ 0, `b_k` ≥ 0.
#[inline]
fn solve_secular<const N: usize>(a: &[f64; N], b: &[f64; N], mut lo: f64, mut hi: f64) -> f64 {
    let mut u = lo;
    for _ in 0..MAX_ITERATIONS {
        let mut s = 0.0;
        let mut ds = 0.0;
        for k in 0..N {
            let inv = 1.0 / (u + b[k]);
            let q = a[k] * inv;
            let q2 = q * q;
            s += q2;
            ds += q2 * inv;
        }
        // H = S^{-1/2} − 1 (increasing), H' = −S' / (2 S^{3/2}) with S' = −2·ds.
        let inv_sqrt = 1.0 / s.sqrt();
        let h = inv_sqrt - 1.0;
        if h.abs() <= H_TOLERANCE {
            return u;
        }
        if h < 0.0 {
            lo = u;
        } else {
            hi = u;
        }
        let dh = ds * inv_sqrt / s;
        let mut next = u - h / dh;
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
}

impl Sorted {
    fn new(e: [f64; 3]) -> Self {
        Sorted {
            e,
            inv_e: [1.0 / e[0], 1.0 / e[1], 1.0 / e[2]],
            r: [(e[0] / e[2]).powi(2), (e[1] / e[2]).powi(2), 1.0],
        }
    }
}

/// Closest point for sorted axes e0 ≥ e1 ≥ e2 > 0, y ≥ 0.
#[inline]
fn closest_sorted(c: &Sorted, y: [f64; 3]) -> [f64; 3] {
    let e = c.e;
    if y[2] > 0.0 {
        let r = c.r;
        let z = [y[0] * c.inv_e[0], y[1] * c.inv_e[1], y[2] * c.inv_e[2]];
        let a = [r[0] * z[0], r[1] * z[1], z[2]];
        let b = [r[0] - 1.0, r[1] - 1.0, 0.0];
        let mut lo = z[2];
        for k in 0..2 {
            if z[k] > 0.0 {
                lo = lo.max(r[k] * (z[k] - 1.0) + 1.0);
            }
        }
        let hi = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        let u = solve_secular(&a, &b, lo, hi.max(lo));
        return [
            e[0] * a[0] / (u + b[0]),
            e[1] * a[1] / (u + b[1]),
            e[2] * a[2] / u,
        ];
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
