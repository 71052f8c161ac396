//! Point–ellipsoid queries in the ellipsoid's frame ([`Prepared`]) and in the camera
//! frame ([`PlacedEllipsoid`]).

use super::solve::{closest_sorted, Sorted};
use nalgebra::{Matrix3, Vector3};

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
    pub(super) perm: [usize; 3],
    pub(super) sorted: Sorted,
    /// 1 / e_k² in sorted order.
    pub(super) inv_e2: [f64; 3],
    pub(super) radii: Vector3<f64>,
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
