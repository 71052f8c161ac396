//! [`SortedPlacement`]: a placed ellipsoid prepared for many camera-frame queries in a
//! hot loop, its one-point queries and its distance lower bounds.

use super::query::PlacedEllipsoid;
use super::solve::{closest_sorted, Sorted};

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
    pub(super) axes: [[f64; 3]; 3],
    pub(super) centre: [f64; 3],
    pub(super) sorted: Sorted,
    /// 1 / e_k² in sorted order.
    pub(super) inv_e2: [f64; 3],
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
    pub(super) fn signed_from_closest(&self, ys: &[f64; 3], x: &[f64; 3]) -> f64 {
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

    /// Camera-frame outward unit normal at the closest point `x` (first octant) of the
    /// local point `y` (signed).
    #[inline]
    pub(super) fn normal_at(&self, y: &[f64; 3], x: &[f64; 3]) -> [f64; 3] {
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
