//! Bodies that are not upright in the image: the template search knows upright bodies
//! only (its 768 poses stand on their feet), so a body lying, leaning or upside down
//! (a cartwheel, a flip) is searched in a view rotated about the camera's optical axis
//! until its long axis is vertical, head up and head down, and the candidates are
//! rotated back.
//!
//! Rotating the image by θ about the principal point is rotating the scene by θ about
//! the optical axis (exactly so with square pixels, and in normalised image
//! coordinates in general): a pose found in the rotated view is the original pose
//! rotated by θ, root translation and root rotation alike.

use crate::body::rotation::rotation_vector;
use crate::body::{root_rotation, Pose};
use crate::camera::Camera;
use crate::error::Result;
use nalgebra::{Rotation3, Vector3};
use std::f64::consts::PI;

/// Below this tilt (radians) of the body's long axis from the image vertical, the body
/// counts as upright and is searched as it is.
pub const UPRIGHT_TILT: f64 = 20.0 * PI / 180.0;

/// The tilt of the person's long axis from the image's vertical, radians in
/// (−π/2, π/2]: the principal axis of the person's pixels in normalised image
/// coordinates ((u − cx)/fx, (v − cy)/fy). None for fewer than three pixels.
pub fn long_axis_tilt(depth: &[f32], mask: &[bool], camera: &Camera) -> Option<f64> {
    let (mut n, mut sx, mut sy, mut sxx, mut syy, mut sxy) = (0.0f64, 0.0, 0.0, 0.0, 0.0, 0.0);
    for (i, (&z, &m)) in depth.iter().zip(mask).enumerate() {
        if !m || z.is_nan() || z <= 0.0 {
            continue;
        }
        let x = ((i % camera.width) as f64 - camera.cx) / camera.fx;
        let y = ((i / camera.width) as f64 - camera.cy) / camera.fy;
        n += 1.0;
        sx += x;
        sy += y;
        sxx += x * x;
        syy += y * y;
        sxy += x * y;
    }
    if n < 3.0 {
        return None;
    }
    let (mx, my) = (sx / n, sy / n);
    let (cxx, cyy, cxy) = (sxx / n - mx * mx, syy / n - my * my, sxy / n - mx * my);
    // The major axis of [[cxx, cxy], [cxy, cyy]] is at angle φ from the x axis with
    // tan 2φ = 2cxy / (cxx − cyy); the tilt from the vertical is φ − π/2.
    let phi = 0.5 * (2.0 * cxy).atan2(cxx - cyy);
    let mut tilt = phi - 0.5 * PI;
    if tilt <= -0.5 * PI {
        tilt += PI;
    }
    Some(tilt)
}

/// The views to search: the frame as it is; and when the body is not about upright,
/// also the view turning its long axis vertical, head up and head down (an upright
/// body is not searched upside down: a standing person is by far the likelier reading,
/// and the extra hypotheses would crowd out the right ones).
pub fn search_rotations(tilt: Option<f64>) -> Vec<f64> {
    match tilt {
        Some(t) if t.abs() >= UPRIGHT_TILT => {
            vec![0.0, t, if t > 0.0 { t - PI } else { t + PI }]
        }
        _ => vec![0.0],
    }
}

/// The rolls of the wide search, radians in (−π, π]: every eighth of a turn, so that
/// a body at any roll is within 22.5° of upright in one of the views.
pub fn every_roll() -> Vec<f64> {
    (0..8)
        .map(|k| {
            let r = k as f64 * PI / 4.0;
            if r > PI + 1e-9 {
                r - 2.0 * PI
            } else {
                r
            }
        })
        .collect()
}

/// The largest side of a rotated view (pixels).
const MAX_VIEW_SIDE: usize = 4096;

/// A view of the frame rotated by `theta` about the optical axis: its depth, mask and
/// camera (same focal lengths, a canvas just holding the rotated person).
pub struct RotatedView {
    pub depth: Vec<f32>,
    pub mask: Vec<bool>,
    pub camera: Camera,
}

/// The person's pixels seen by a camera rolled by −`theta` (the scene turned by
/// `theta` about the optical axis: a body tilted by −`theta` becomes upright). Nearest
/// sampling; `margin` pixels around the person.
pub fn rotated_view(
    depth: &[f32],
    mask: &[bool],
    camera: &Camera,
    theta: f64,
    margin: usize,
) -> Result<RotatedView> {
    let (s, c) = theta.sin_cos();
    let norm = |i: usize| {
        (
            ((i % camera.width) as f64 - camera.cx) / camera.fx,
            ((i / camera.width) as f64 - camera.cy) / camera.fy,
        )
    };
    // The rotated person's box in normalised coordinates.
    let (mut lo, mut hi) = ((f64::MAX, f64::MAX), (f64::MIN, f64::MIN));
    for (i, &m) in mask.iter().enumerate() {
        if m {
            let (x, y) = norm(i);
            let (xr, yr) = (c * x - s * y, s * x + c * y);
            lo = (lo.0.min(xr), lo.1.min(yr));
            hi = (hi.0.max(xr), hi.1.max(yr));
        }
    }
    let m = margin as f64;
    let (u0, v0) = (lo.0 * camera.fx - m, lo.1 * camera.fy - m);
    let width = ((hi.0 - lo.0) * camera.fx + 2.0 * m).ceil().max(1.0) as usize + 1;
    let height = ((hi.1 - lo.1) * camera.fy + 2.0 * m).ceil().max(1.0) as usize + 1;
    // The principal point may lie far outside this canvas (the person is off-axis), which
    // `Camera::new` refuses for a user's camera; here it is intended.
    let rotated = Camera {
        fx: camera.fx,
        fy: camera.fy,
        cx: -u0,
        cy: -v0,
        width: width.min(MAX_VIEW_SIDE),
        height: height.min(MAX_VIEW_SIDE),
    };
    let (w, h) = (rotated.width, rotated.height);
    let mut out_depth = vec![0.0f32; w * h];
    let mut out_mask = vec![false; w * h];
    for row in 0..h {
        for col in 0..w {
            let xr = (col as f64 - rotated.cx) / rotated.fx;
            let yr = (row as f64 - rotated.cy) / rotated.fy;
            // Back to the source: rotate by −theta.
            let (x, y) = (c * xr + s * yr, -s * xr + c * yr);
            let u = (x * camera.fx + camera.cx).round();
            let v = (y * camera.fy + camera.cy).round();
            if u < 0.0 || v < 0.0 || u >= camera.width as f64 || v >= camera.height as f64 {
                continue;
            }
            let i = v as usize * camera.width + u as usize;
            out_depth[row * w + col] = depth[i];
            out_mask[row * w + col] = mask[i];
        }
    }
    Ok(RotatedView {
        depth: out_depth,
        mask: out_mask,
        camera: rotated,
    })
}

/// `pose` turned by `theta` about the camera's optical axis (the camera frame's z).
pub fn rotate_about_optical_axis(pose: &Pose, theta: f64) -> Pose {
    let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), theta);
    let t = rz * Vector3::new(pose[0], pose[1], pose[2]);
    let r = rz * root_rotation(pose);
    let mut out = *pose;
    out[0..3].copy_from_slice(t.as_slice());
    out[3..6].copy_from_slice(rotation_vector(&r).as_slice());
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::BodyModel;
    use crate::pipeline::tests::rendered_person;

    #[test]
    fn an_upright_body_has_no_tilt_and_a_rolled_one_its_roll() {
        let camera = Camera::itop();
        let model = BodyModel::new(1.75).unwrap();
        for roll in [0.0, 0.5, -1.2, 2.0] {
            let pose = rotate_about_optical_axis(&BodyModel::neutral_pose(), roll);
            let (depth, mask) = rendered_person(&model, &pose, &camera);
            let tilt = long_axis_tilt(&depth, &mask, &camera).unwrap();
            // The tilt is the roll up to a half turn.
            let mut d = (tilt - roll).rem_euclid(PI);
            if d > 0.5 * PI {
                d -= PI;
            }
            assert!(d.abs() < 0.08, "roll {roll}: tilt {tilt}");
        }
    }

    #[test]
    fn the_rotated_view_of_a_rolled_body_is_the_upright_body() {
        let camera = Camera::itop();
        let model = BodyModel::new(1.75).unwrap();
        let upright = BodyModel::neutral_pose();
        let roll = 1.1;
        let rolled = rotate_about_optical_axis(&upright, roll);
        let (depth, mask) = rendered_person(&model, &rolled, &camera);
        let view = rotated_view(&depth, &mask, &camera, -roll, 4).unwrap();
        // The upright body rendered by the view's camera covers the same pixels.
        let (want, _) = model.render_depth(&upright, &view.camera);
        let (mut same, mut total) = (0usize, 0usize);
        for (&a, &b) in view.depth.iter().zip(&want) {
            if a > 0.0 || b > 0.0 {
                total += 1;
                same += usize::from(a > 0.0 && b > 0.0 && (a - b).abs() < 0.02);
            }
        }
        assert!(same as f64 > 0.93 * total as f64, "{same} of {total}");
        // And turning a pose found there back gives the rolled pose's joints.
        let back = rotate_about_optical_axis(&upright, roll);
        for (a, b) in model.joints(&back).iter().zip(&model.joints(&rolled)) {
            assert!((a - b).norm() < 1e-9);
        }
    }

    #[test]
    fn the_wide_search_sees_every_eighth_of_a_turn_once() {
        let r = every_roll();
        assert_eq!(r.len(), 8);
        for (k, v) in r.iter().enumerate() {
            assert!(*v > -PI && *v <= PI);
            let turns = (v / (PI / 4.0)).rem_euclid(8.0);
            assert!((turns - k as f64).abs() < 1e-9, "roll {v}");
        }
    }

    #[test]
    fn a_tilted_body_is_searched_upright_both_ways_an_upright_one_as_it_is() {
        assert_eq!(search_rotations(Some(0.1)), vec![0.0]);
        assert_eq!(search_rotations(None), vec![0.0]);
        let r = search_rotations(Some(1.0));
        assert_eq!(r[..2], [0.0, 1.0]);
        assert!((r[2] - (1.0 - PI)).abs() < 1e-12);
    }
}
