//! Start poses from the template search, and the ambiguities of a depth image that
//! every search has to try both ways: left and right limbs, a view and its mirror image.
//!
//! Pose layout ([`crate::body::PARAM_NAMES`]): 0..3 root translation, 3..6 root rotation
//! vector, 6 neck flexion, 7 neck lateral bend, 8..12 right shoulder (3) and elbow,
//! 12..16 the same on the left, 16..19 right hip (2) and knee, 19..22 the same on the
//! left. The joint angles are anatomical (the same motion on both sides), so exchanging
//! the right and left blocks and negating the lateral neck bend mirrors the body in its
//! own sagittal plane.

use super::orientation::rotate_about_optical_axis;
use crate::body::rotation::rotation_vector;
use crate::body::{root_rotation, BodyModel, Pose, NUM_PARAMS};
use crate::templates::Candidate;
use nalgebra::{Rotation3, Vector3};
use std::f64::consts::PI;

/// The neck's lateral bend.
const NECK_LATERAL: usize = 7;
/// The limb angles: shoulders (3 each), elbows, hips (2 each), knees.
pub const LIMB_ANGLES: std::ops::Range<usize> = 8..NUM_PARAMS;
/// Right arm, left arm, right leg, left leg.
const R_ARM: usize = 8;
const L_ARM: usize = 12;
const ARM: usize = 4;
const R_LEG: usize = 16;
const L_LEG: usize = 19;
const LEG: usize = 3;

/// Two hypotheses whose joints are within this mean distance (m) are one.
const DUPLICATE_DISTANCE: f64 = 0.03;

/// The neutral body (upright, arms down) facing each quarter turn about its own
/// vertical axis, rolled about the optical axis by each of `rolls`: starts that reach a
/// body in any orientation without a template's limb poses (a tucked, split or
/// cartwheeling body no standing template resembles), for the EM to bend its limbs.
pub fn rolled_neutral_bodies(rolls: &[f64]) -> Vec<Pose> {
    let neutral = BodyModel::neutral_pose();
    rolls
        .iter()
        .flat_map(|&roll| {
            (0..4).map(move |q| {
                rotate_about_optical_axis(&turned(&neutral, q as f64 * PI / 2.0), roll)
            })
        })
        .collect()
}

/// The left/right-swapped pose: the body mirrored in its own sagittal plane (right and
/// left limb angles exchanged, lateral neck bend negated), root unchanged. In a side
/// view this puts the far leg where the near one was. An involution.
pub fn swap_limbs(pose: &Pose) -> Pose {
    let mut out = *pose;
    out[R_ARM..R_ARM + ARM].copy_from_slice(&pose[L_ARM..L_ARM + ARM]);
    out[L_ARM..L_ARM + ARM].copy_from_slice(&pose[R_ARM..R_ARM + ARM]);
    out[R_LEG..R_LEG + LEG].copy_from_slice(&pose[L_LEG..L_LEG + LEG]);
    out[L_LEG..L_LEG + LEG].copy_from_slice(&pose[R_LEG..R_LEG + LEG]);
    out[NECK_LATERAL] = -pose[NECK_LATERAL];
    out
}

/// The mirror image of the posed body in the camera's vertical plane through the hip
/// centre (x → −x about the hip centre): the same silhouette flipped left-right, limbs
/// swapped so that the body stays a right-handed one. With F = diag(−1, 1, 1), the root
/// rotation R becomes F·R·F, whose rotation vector is (v_x, −v_y, −v_z). An involution.
pub fn mirror_view(pose: &Pose) -> Pose {
    let mut out = swap_limbs(pose);
    out[4] = -out[4];
    out[5] = -out[5];
    out
}

/// The body turned about its own vertical axis (body y) through the hip centre by
/// `angle` (radians), limb angles unchanged.
pub fn turned(pose: &Pose, angle: f64) -> Pose {
    let r = root_rotation(pose) * Rotation3::from_axis_angle(&Vector3::y_axis(), angle);
    let mut out = *pose;
    out[3..6].copy_from_slice(rotation_vector(&r).as_slice());
    out
}

/// The body turned about its own vertical axis by a half turn ([`turned`]): a front
/// view becomes a back view with the same limb angles. The image silhouette of the
/// turned body is about the mirror image of the original's, so
/// `turn_around(mirror_view(p))` is the back-view reading of a front-view template
/// `p`. An involution up to the rotation vector's representation.
pub fn turn_around(pose: &Pose) -> Pose {
    turned(pose, PI)
}

/// `weight` × Σ θ² over the 14 limb angles (radians; 0 is the rest pose: arms hanging,
/// legs straight): a pose's distance from the ordinary, added to its depth discrepancy
/// where poses compete.
pub fn rest_pose_penalty(pose: &Pose, weight: f64) -> f64 {
    weight * pose[LIMB_ANGLES].iter().map(|v| v * v).sum::<f64>()
}

/// Start poses from template candidates: each candidate's pose, its left/right-swapped
/// pose, the mirror images of both (the search cannot tell a side view's near limbs
/// from its far ones, nor a view from its mirror image) and, with `back_views`, all
/// four turned around (a body seen from behind has about the silhouette of one seen
/// from the front); near-duplicates dropped. Each start comes with the index of its
/// candidate.
pub fn template_starts(
    model: &BodyModel,
    candidates: &[Candidate],
    back_views: bool,
) -> Vec<(Pose, usize)> {
    let mut out: Vec<(Pose, usize)> = Vec::with_capacity(8 * candidates.len());
    let mut kept: Vec<[Vector3<f64>; crate::body::NUM_JOINTS]> = Vec::new();
    for (k, c) in candidates.iter().enumerate() {
        let p = c.pose;
        let s = swap_limbs(&p);
        let front = [p, s, mirror_view(&p), mirror_view(&s)];
        let back = front.map(|q| turn_around(&q));
        let all = if back_views {
            &[front, back][..]
        } else {
            &[front][..]
        };
        for q in all.iter().flatten().copied() {
            let j = model.joints(&q);
            let duplicate = kept.iter().any(|kj| {
                let mean =
                    kj.iter().zip(&j).map(|(a, b)| (a - b).norm()).sum::<f64>() / j.len() as f64;
                mean < DUPLICATE_DISTANCE
            });
            if !duplicate {
                kept.push(j);
                out.push((q, k));
            }
        }
    }
    out
}

/// The hypotheses a search refines: the best `n` of `order` (hypothesis indices, the
/// best-ranked first), except that the best-ranked hypothesis of each view
/// (`views[i]`: the view hypothesis `i` comes from) is always among them, in place of
/// the worst-ranked others. The views of a search are distinct readings of the body (as
/// it is, its long axis upright, upside down); ranked together, the readings of some
/// views can fill the whole budget and crowd out a view whose template poses match less
/// well before the fit but whose fit explains the depth best (a raised arm tilting an
/// upright body's silhouette). When there are more views than `n`, the best-ranked
/// views' hypotheses are kept. Returned in the order of `order`.
pub fn refined_hypotheses(order: &[usize], views: &[usize], n: usize) -> Vec<usize> {
    let n = n.min(order.len());
    let n_views = order.iter().map(|&i| views[i] + 1).max().unwrap_or(0);
    let mut seen = vec![false; n_views];
    let mut view_best = vec![false; order.len()];
    let mut reserved = 0;
    for (rank, &i) in order.iter().enumerate() {
        if !seen[views[i]] && reserved < n {
            seen[views[i]] = true;
            view_best[rank] = true;
            reserved += 1;
        }
    }
    let mut others = n - reserved;
    let mut picked = Vec::with_capacity(n);
    for (rank, &i) in order.iter().enumerate() {
        if view_best[rank] {
            picked.push(i);
        } else if others > 0 {
            others -= 1;
            picked.push(i);
        }
    }
    picked
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::BodyModel;

    fn pose() -> Pose {
        let mut p = BodyModel::neutral_pose();
        p[3..6].copy_from_slice(&[0.2, 0.7, -0.3]);
        for (k, v) in p.iter_mut().enumerate().skip(6) {
            *v += 0.05 * k as f64;
        }
        p
    }

    #[test]
    fn swap_and_mirror_are_involutions() {
        let p = pose();
        assert_eq!(swap_limbs(&swap_limbs(&p)), p);
        assert_eq!(mirror_view(&mirror_view(&p)), p);
    }

    #[test]
    fn the_mirror_image_mirrors_the_joints() {
        let model = BodyModel::new(1.75).unwrap();
        let p = pose();
        let (j, m) = (model.joints(&p), model.joints(&mirror_view(&p)));
        let hip_x = p[0];
        // Joint k of the mirror image is the mirrored joint of k's other side.
        let other = [0, 1, 3, 2, 5, 4, 7, 6, 8, 10, 9, 12, 11, 14, 13];
        for k in 0..j.len() {
            let a = m[k];
            let b = j[other[k]];
            let want = Vector3::new(2.0 * hip_x - b.x, b.y, b.z);
            assert!((a - want).norm() < 1e-9, "joint {k}: {a} vs {want}");
        }
    }

    #[test]
    fn the_mirrored_rotation_is_f_r_f() {
        let v = Vector3::new(0.3, -1.2, 0.8);
        let f = nalgebra::Matrix3::from_diagonal(&Vector3::new(-1.0, 1.0, 1.0));
        let r = Rotation3::from_scaled_axis(v).into_inner();
        let mut p = [0.0; NUM_PARAMS];
        p[3..6].copy_from_slice(v.as_slice());
        let m = mirror_view(&p);
        let got = Rotation3::from_scaled_axis(Vector3::new(m[3], m[4], m[5])).into_inner();
        assert!((got - f * r * f).norm() < 1e-12);
    }

    #[test]
    fn turning_around_faces_the_body_the_other_way() {
        let model = BodyModel::new(1.75).unwrap();
        let p = pose();
        let t = turn_around(&p);
        // Twice is the same body.
        let (j, jj) = (model.joints(&p), model.joints(&turn_around(&t)));
        for (a, b) in j.iter().zip(&jj) {
            assert!((a - b).norm() < 1e-9);
        }
        // Each joint is reflected through the body's vertical axis: in the body frame
        // (x left, y down, z back) x and z change sign, y stays.
        let r = root_rotation(&p);
        let jt = model.joints(&t);
        let hip = Vector3::new(p[0], p[1], p[2]);
        for (a, b) in j.iter().zip(&jt) {
            let (ba, bb) = (r.inverse() * (a - hip), r.inverse() * (b - hip));
            assert!((bb - Vector3::new(-ba.x, ba.y, -ba.z)).norm() < 1e-9);
        }
    }

    #[test]
    fn each_views_best_hypothesis_is_refined_in_place_of_the_worst_others() {
        // Ranked 5, 3, 0, 4, 1, 2: view 0 holds the four best, view 1 ranks fifth.
        let order = [5, 3, 0, 4, 1, 2];
        let views = [0, 1, 1, 0, 0, 0];
        assert_eq!(refined_hypotheses(&order, &views, 3), vec![5, 3, 1]);
        // A budget holding it anyway changes nothing.
        assert_eq!(refined_hypotheses(&order, &views, 5), vec![5, 3, 0, 4, 1]);
        // One view: the best n.
        assert_eq!(refined_hypotheses(&order, &[0; 6], 2), vec![5, 3]);
        // More views than the budget: the best-ranked views' best.
        let spread = [2, 0, 3, 1, 4, 5];
        assert_eq!(refined_hypotheses(&order, &spread, 2), vec![5, 3]);
    }

    proptest::proptest! {
        #[test]
        fn refined_hypotheses_keep_each_views_best_then_the_best_ranked(
            views in proptest::collection::vec(0usize..4, 1..30),
            seed in 0u64..1000,
            n in 1usize..12,
        ) {
            // A ranking: the indices shuffled by the seed.
            let mut order: Vec<usize> = (0..views.len()).collect();
            order.sort_by_key(|&i| (i as u64 * 2654435761 + seed * 97) % 1009);
            let picked = refined_hypotheses(&order, &views, n);
            let n = n.min(order.len());
            proptest::prop_assert_eq!(picked.len(), n);
            // In the order of the ranking, each at most once.
            let position = |i: usize| order.iter().position(|&o| o == i).unwrap();
            proptest::prop_assert!(picked.windows(2).all(|w| position(w[0]) < position(w[1])));
            // Each view's best is in, when the budget holds every view.
            let mut bests: Vec<usize> = Vec::new();
            for &i in &order {
                if !bests.iter().any(|&b| views[b] == views[i]) {
                    bests.push(i);
                }
            }
            if bests.len() <= n {
                for b in &bests {
                    proptest::prop_assert!(picked.contains(b));
                }
            }
            // The others are the best-ranked of the rest: none left out ranks above one in.
            let others: Vec<usize> = picked.iter().copied().filter(|i| !bests.contains(i)).collect();
            let worst_in = others.iter().map(|&i| position(i)).max();
            let best_out = order
                .iter()
                .filter(|i| !picked.contains(i) && !bests.contains(i))
                .map(|&i| position(i))
                .min();
            if let (Some(w), Some(b)) = (worst_in, best_out) {
                proptest::prop_assert!(w < b);
            }
        }
    }

    #[test]
    fn the_penalty_sums_the_limb_angles() {
        let mut p = [0.0; NUM_PARAMS];
        p[0] = 5.0; // the root does not count
        p[6] = 1.0; // nor the neck
        p[8] = 0.5;
        p[21] = -2.0;
        assert!((rest_pose_penalty(&p, 0.1) - 0.1 * (0.25 + 4.0)).abs() < 1e-15);
    }
}
