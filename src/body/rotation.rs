//! Rotations as the pose and its exports write them: rotation vectors (the root's
//! three parameters) and the Z-X-Y Euler angles of BVH channels.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// The rotation matrix of rotation vector `v` (axis times angle, radians).
pub fn matrix_from_rotation_vector(v: &Vector3<f64>) -> Matrix3<f64> {
    Rotation3::from_scaled_axis(*v).into_inner()
}

/// The rotation vector (axis times angle in [0, π]) of rotation matrix `m`, by way of
/// its unit quaternion, so that it stays accurate for angles near π (where the skew
/// part of `m` vanishes). `m` is taken as a rotation (orthonormal, determinant 1).
pub fn rotation_vector_from_matrix(m: &Matrix3<f64>) -> Vector3<f64> {
    rotation_vector(&Rotation3::from_matrix_unchecked(*m))
}

/// The rotation vector (axis times angle in [0, π]) of `r`, accurate at every angle.
/// `Rotation3::scaled_axis` reads the axis from the skew part of the matrix, which
/// vanishes at a half turn: there it returns zero, the identity, for a rotation such as
/// a quarter roll of a body turned around. Every pose's root rotation is written with
/// this instead.
pub fn rotation_vector(r: &Rotation3<f64>) -> Vector3<f64> {
    UnitQuaternion::from_rotation_matrix(r).scaled_axis()
}

/// The Euler angles (z, x, y) in radians with m = Rz(z)·Rx(x)·Ry(y), x in [−π/2, π/2];
/// at the poles (x = ±π/2, where z and y turn about the same axis) y is 0.
pub fn euler_zxy_from_matrix(m: &Matrix3<f64>) -> [f64; 3] {
    let s = m[(2, 1)].clamp(-1.0, 1.0);
    let x = s.asin();
    if s.abs() < 1.0 - 1e-9 {
        let z = (-m[(0, 1)]).atan2(m[(1, 1)]);
        let y = (-m[(2, 0)]).atan2(m[(2, 2)]);
        [z, x, y]
    } else {
        [m[(1, 0)].atan2(m[(0, 0)]), x, 0.0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        /// Any rotation vector of angle below π comes back from its matrix; any Euler
        /// triple composes back to its matrix.
        #[test]
        fn round_trips(
            ax in -1.0f64..1.0, ay in -1.0f64..1.0, az in -1.0f64..1.0,
            angle in 0.0f64..3.1,
            z in -3.1f64..3.1, x in -1.5f64..1.5, y in -3.1f64..3.1,
        ) {
            let axis = Vector3::new(ax, ay, az);
            prop_assume!(axis.norm() > 1e-3);
            let v = axis.normalize() * angle;
            let back = rotation_vector_from_matrix(&matrix_from_rotation_vector(&v));
            prop_assert!((back - v).norm() < 1e-9 * (1.0 + 1.0 / (std::f64::consts::PI - angle)));
            let m = rz(z) * rx(x) * ry(y);
            let [z2, x2, y2] = euler_zxy_from_matrix(&m);
            prop_assert!((rz(z2) * rx(x2) * ry(y2) - m).norm() < 1e-9);
        }
    }

    fn rz(a: f64) -> Matrix3<f64> {
        matrix_from_rotation_vector(&Vector3::new(0.0, 0.0, a))
    }
    fn rx(a: f64) -> Matrix3<f64> {
        matrix_from_rotation_vector(&Vector3::new(a, 0.0, 0.0))
    }
    fn ry(a: f64) -> Matrix3<f64> {
        matrix_from_rotation_vector(&Vector3::new(0.0, a, 0.0))
    }

    #[test]
    fn rotation_vectors_round_trip_up_to_a_half_turn() {
        let axis = Vector3::new(0.3, -0.8, 0.52).normalize();
        for angle in [0.0, 1e-9, 0.4, 2.0, 3.1, std::f64::consts::PI - 1e-7] {
            let v = axis * angle;
            let back = rotation_vector_from_matrix(&matrix_from_rotation_vector(&v));
            assert!((back - v).norm() < 1e-6, "angle {angle}: {back:?} vs {v:?}");
        }
        // At exactly a half turn the axis's sign is free: either vector is the rotation.
        let v = axis * std::f64::consts::PI;
        let back = rotation_vector_from_matrix(&matrix_from_rotation_vector(&v));
        assert!(
            (back - v).norm() < 1e-6 || (back + v).norm() < 1e-6,
            "{back:?}"
        );
    }

    #[test]
    fn a_half_turn_about_any_axis_keeps_its_rotation() {
        // A quarter roll of a body turned around: a half turn about (1, 1, 0)/√2, whose
        // skew part is exactly zero.
        let r = Rotation3::from_matrix_unchecked(
            rz(std::f64::consts::FRAC_PI_2) * ry(std::f64::consts::PI),
        );
        let v = rotation_vector(&r);
        assert!((v.norm() - std::f64::consts::PI).abs() < 1e-9, "{v:?}");
        assert!((matrix_from_rotation_vector(&v) - r.matrix()).norm() < 1e-9);
    }

    #[test]
    fn euler_zxy_composes_back_to_the_matrix() {
        for &(z, x, y) in &[
            (0.3, -0.4, 1.2),
            (-2.5, 1.1, -0.2),
            (3.0, 0.0, -3.0),
            (0.7, 1.5, 0.1),
        ] {
            let m = rz(z) * rx(x) * ry(y);
            let [z2, x2, y2] = euler_zxy_from_matrix(&m);
            assert!((z2 - z).abs() < 1e-9 && (x2 - x).abs() < 1e-9 && (y2 - y).abs() < 1e-9);
        }
        // At a pole the angles still compose to the matrix.
        let m = rz(0.4) * rx(std::f64::consts::FRAC_PI_2) * ry(0.3);
        let [z, x, y] = euler_zxy_from_matrix(&m);
        assert!((rz(z) * rx(x) * ry(y) - m).norm() < 1e-6);
    }
}
