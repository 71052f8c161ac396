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

mod batched;
mod query;
mod solve;
mod sorted;
mod stream;
#[cfg(test)]
mod tests;

pub use query::{
    closest_point_on_ellipsoid, signed_distance_to_ellipsoid, EllipsoidDistance, PlacedEllipsoid,
    Prepared,
};
pub use solve::LANES;
pub use sorted::{Beyond, SortedPlacement};
