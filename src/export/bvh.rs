//! BVH motion: one joint per body segment at its proximal joint, named as animation
//! tools expect ([`BVH_NAMES`]), each chain ending in an End Site at the far end of its
//! segment; y up, metres; per frame the root's position and every joint's rotation as
//! Z-X-Y Euler angles in degrees, relative to its parent.
//!
//! Exports are y-up, as Blender, three.js, glTF and BVH expect, while the camera frame
//! is y-down, z-forward (OpenCV): turning 180° about x maps (x, y, z) to (x, -y, -z).
//! The rest pose is all joint angles zero (segments parallel to the body frame).

use crate::body::{rotation, BodyModel, Kinematics, Pose, NUM_JOINTS, NUM_PARAMS, PART_NAMES};
use crate::error::{Error, Result};
use nalgebra::{Matrix3, Vector3};
use std::fmt::Write as _;
use std::path::Path;

/// Parent of each body segment (None: the root), in the order the hierarchy lists them.
pub const BVH_PARENTS: [(&str, Option<&str>); 16] = [
    ("pelvis", None),
    ("torso", Some("pelvis")),
    ("neck", Some("torso")),
    ("head", Some("neck")),
    ("r_upper_arm", Some("torso")),
    ("r_forearm", Some("r_upper_arm")),
    ("r_hand", Some("r_forearm")),
    ("l_upper_arm", Some("torso")),
    ("l_forearm", Some("l_upper_arm")),
    ("l_hand", Some("l_forearm")),
    ("r_thigh", Some("pelvis")),
    ("r_shin", Some("r_thigh")),
    ("r_foot", Some("r_shin")),
    ("l_thigh", Some("pelvis")),
    ("l_shin", Some("l_thigh")),
    ("l_foot", Some("l_shin")),
];

/// The BVH joint name of each body segment: the names animation tools map by default
/// (Blender, MotionBuilder, Mixamo-style retargeting); Left and Right are the
/// subject's.
pub const BVH_NAMES: [(&str, &str); 16] = [
    ("pelvis", "Hips"),
    ("torso", "Spine"),
    ("neck", "Neck"),
    ("head", "Head"),
    ("r_upper_arm", "RightArm"),
    ("r_forearm", "RightForeArm"),
    ("r_hand", "RightHand"),
    ("l_upper_arm", "LeftArm"),
    ("l_forearm", "LeftForeArm"),
    ("l_hand", "LeftHand"),
    ("r_thigh", "RightUpLeg"),
    ("r_shin", "RightLeg"),
    ("r_foot", "RightFoot"),
    ("l_thigh", "LeftUpLeg"),
    ("l_shin", "LeftLeg"),
    ("l_foot", "LeftFoot"),
];

/// Pose parameters and joints (ITOP order) of each leg: hip (2) and knee (1); the
/// joints whose confidence tells whether the leg was seen (hip, knee, foot).
const LEGS: [([usize; 3], [usize; 3]); 2] =
    [([16, 17, 18], [9, 11, 13]), ([19, 20, 21], [10, 12, 14])];

/// A tracked sequence to write.
#[derive(Debug, Clone, Copy)]
pub struct BvhMotion<'a> {
    /// One pose a frame; a failed frame is a pose of 22 NaN and repeats the previous
    /// frame.
    pub poses: &'a [Pose],
    /// Frames per second, in (0, 1e6].
    pub fps: f64,
    /// The estimators' per-joint confidence, one row a frame: a leg whose hip, knee and
    /// foot all have confidence 0 in a frame (not seen) is written at rest in that
    /// frame rather than with invented angles.
    pub confidence: Option<&'a [[f64; NUM_JOINTS]]>,
}

/// Index of a segment in [`PART_NAMES`] (the model's label order).
fn part(name: &str) -> usize {
    PART_NAMES.iter().position(|n| *n == name).unwrap_or(0)
}

/// The parent segment of segment `k` (label order).
fn parent(k: usize) -> Option<usize> {
    BVH_PARENTS
        .iter()
        .find(|(n, _)| *n == PART_NAMES[k])
        .and_then(|(_, p)| p.map(part))
}

/// `v` turned into the y-up frame (0 - y rather than -y, so that a zero stays +0 and
/// prints as 0.000000).
fn flip(v: Vector3<f64>) -> Vector3<f64> {
    Vector3::new(v.x, 0.0 - v.y, 0.0 - v.z)
}

/// `m` turned into the y-up frame: F·m·F with F = diag(1, -1, -1).
fn flip_rotation(m: &Matrix3<f64>) -> Matrix3<f64> {
    let f = Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0));
    f * m * f
}

/// Refuses poses that are not a sequence of whole or failed frames, and an fps out of
/// range; returns the poses with unseen legs at rest.
fn checked_poses(motion: &BvhMotion) -> Result<Vec<Pose>> {
    let fps = motion.fps;
    if !(fps.is_finite() && fps > 0.0 && fps <= 1e6) {
        return Err(Error::invalid(
            "fps",
            format!("must be a finite number in (0, 1000000], got {fps}"),
        ));
    }
    if motion.poses.is_empty() {
        return Err(Error::invalid("poses", "expected (T, 22), got no frame"));
    }
    if motion.poses.iter().flatten().any(|v| v.is_infinite()) {
        return Err(Error::invalid("poses", "holds an infinite value"));
    }
    for (k, p) in motion.poses.iter().enumerate() {
        let nan = p.iter().filter(|v| v.is_nan()).count();
        if nan > 0 && nan < NUM_PARAMS {
            return Err(Error::invalid(
                format!("poses[{k}]"),
                "some parameters are NaN, not all (a failed frame is all NaN)",
            ));
        }
    }
    if motion.poses.iter().all(|p| p[0].is_nan()) {
        return Err(Error::invalid("poses", "every frame is NaN"));
    }
    let mut poses = motion.poses.to_vec();
    if let Some(conf) = motion.confidence {
        if conf.len() != poses.len() {
            return Err(Error::invalid(
                "confidence",
                format!(
                    "expected shape ({}, {NUM_JOINTS}), got ({}, {NUM_JOINTS})",
                    poses.len(),
                    conf.len()
                ),
            ));
        }
        for (pose, c) in poses.iter_mut().zip(conf) {
            for (params, joints) in LEGS {
                if !pose[0].is_nan() && joints.iter().all(|&j| c[j] == 0.0) {
                    params.iter().for_each(|&p| pose[p] = 0.0);
                }
            }
        }
    }
    Ok(poses)
}

/// The End Site offset of each segment at the rest pose, y-up: where a ray from the
/// segment's joint leaves its ellipsoid (the top of the head, the tips of the hands and
/// feet). The ray runs through the ellipsoid's centre when that lies ahead along the
/// chain, else straight on along the chain (the head, centred near its joint); a lone
/// segment centred on its joint takes its long axis.
fn end_sites(model: &BodyModel) -> Vec<Vector3<f64>> {
    let kin = Kinematics::new(model, &[0.0; NUM_PARAMS]);
    let placed = model.placed_ellipsoids(&kin);
    (0..PART_NAMES.len())
        .map(|k| {
            let origin = kin.frames[k].translation.vector;
            let e = &placed[k];
            let chain = parent(k).map_or(Vector3::zeros(), |p| {
                origin - kin.frames[p].translation.vector
            });
            let mut d = e.centre - origin;
            if d.dot(&chain) <= 0.0 && chain.norm() > 1e-9 {
                d = chain;
            }
            let radii = e.prepared.radii();
            if d.norm() < 1e-9 {
                d = e.rotation.column(radii.imax()).into_owned();
            }
            let d = d.normalize();
            // |A (origin + t d - centre)| = 1, A mapping the ellipsoid to the unit sphere.
            let to_unit = |v: Vector3<f64>| (e.rotation.transpose() * v).component_div(radii);
            let (a, b) = (to_unit(d), to_unit(origin - e.centre));
            let disc = a.dot(&b).powi(2) - a.dot(&a) * (b.dot(&b) - 1.0);
            let t = (-a.dot(&b) + disc.max(0.0).sqrt()) / a.dot(&a);
            flip(t.max(0.0) * d)
        })
        .collect()
}

/// The BVH file of `motion` (see the module docs).
pub fn bvh_text(model: &BodyModel, motion: &BvhMotion) -> Result<String> {
    let poses = checked_poses(motion)?;
    let rest = Kinematics::new(model, &[0.0; NUM_PARAMS]);
    let origin = |k: usize| flip(rest.frames[k].translation.vector);
    let ends = end_sites(model);
    let children =
        |k: Option<usize>| (0..PART_NAMES.len()).filter(move |&c| parent(c) == k && Some(c) != k);
    let name = |k: usize| {
        BVH_NAMES
            .iter()
            .find(|(n, _)| *n == PART_NAMES[k])
            .map_or("", |(_, b)| b)
    };
    let mut out = String::from("HIERARCHY\n");
    let mut order = Vec::new();
    let root = children(None).next().unwrap_or(0);
    // Depth-first, children in label order; (segment, depth, opening) on the stack.
    let mut stack = vec![(root, 0usize, true)];
    while let Some((k, depth, opening)) = stack.pop() {
        let pad = "  ".repeat(depth);
        if !opening {
            if children(Some(k)).next().is_none() {
                let e = ends[k];
                let _ = write!(
                    out,
                    "{pad}  End Site\n{pad}  {{\n{pad}    OFFSET {:.6} {:.6} {:.6}\n{pad}  }}\n",
                    e.x, e.y, e.z
                );
            }
            let _ = writeln!(out, "{pad}}}");
            continue;
        }
        let off = parent(k).map_or(Vector3::zeros(), |p| origin(k) - origin(p));
        let (kind, channels) = match parent(k) {
            None => (
                "ROOT",
                "6 Xposition Yposition Zposition Zrotation Xrotation Yrotation",
            ),
            Some(_) => ("JOINT", "3 Zrotation Xrotation Yrotation"),
        };
        let _ = write!(
            out,
            "{pad}{kind} {}\n{pad}{{\n{pad}  OFFSET {:.6} {:.6} {:.6}\n{pad}  CHANNELS {channels}\n",
            name(k),
            off.x,
            off.y,
            off.z
        );
        order.push(k);
        stack.push((k, depth, false));
        let kids: Vec<usize> = children(Some(k)).collect();
        stack.extend(kids.into_iter().rev().map(|c| (c, depth + 1, true)));
    }
    let _ = write!(
        out,
        "MOTION\nFrames: {}\nFrame Time: {:.6}\n",
        poses.len(),
        1.0 / motion.fps
    );
    let mut last = poses
        .iter()
        .find(|p| !p[0].is_nan())
        .copied()
        .unwrap_or([0.0; NUM_PARAMS]);
    for pose in &poses {
        if !pose[0].is_nan() {
            last = *pose;
        }
        let frames = model.segment_transforms(&last);
        let world: Vec<Matrix3<f64>> = frames
            .iter()
            .map(|f| flip_rotation(f.rotation.to_rotation_matrix().matrix()))
            .collect();
        let mut values: Vec<f64> = Vec::with_capacity(3 + 3 * order.len());
        for &k in &order {
            let local = match parent(k) {
                None => {
                    values.extend(flip(frames[k].translation.vector).iter());
                    world[k]
                }
                Some(p) => world[p].transpose() * world[k],
            };
            values.extend(rotation::euler_zxy_from_matrix(&local).map(f64::to_degrees));
        }
        // + 0.0 turns an exact -0 into 0, which prints without a sign.
        let line: Vec<String> = values.iter().map(|v| format!("{:.6}", v + 0.0)).collect();
        out.push_str(&line.join(" "));
        out.push('\n');
    }
    Ok(out)
}

/// Writes `motion` as a BVH file at `path` (see [`bvh_text`]).
pub fn write_bvh(path: &Path, model: &BodyModel, motion: &BvhMotion) -> Result<()> {
    let text = bvh_text(model, motion)?;
    std::fs::write(path, text)
        .map_err(|e| Error::file(path.display().to_string(), format!("cannot write: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn motion(poses: &[Pose]) -> BvhMotion<'_> {
        BvhMotion {
            poses,
            fps: 30.0,
            confidence: None,
        }
    }

    #[test]
    fn hierarchy_names_every_segment_once() {
        let model = BodyModel::default();
        let mut pose = [0.0; NUM_PARAMS];
        pose[2] = 3.0;
        let text = bvh_text(&model, &motion(&[pose, [f64::NAN; NUM_PARAMS]])).unwrap();
        for (_, name) in BVH_NAMES {
            let line = if name == "Hips" {
                "ROOT Hips\n"
            } else {
                &*format!("JOINT {name}\n")
            };
            assert_eq!(text.matches(line).count(), 1, "{name}");
        }
        assert_eq!(text.matches("End Site").count(), 5);
        assert_eq!(text.matches('{').count(), text.matches('}').count());
        let motion_lines: Vec<&str> = text
            .split("Frame Time: 0.033333\n")
            .nth(1)
            .unwrap()
            .lines()
            .collect();
        assert_eq!(motion_lines.len(), 2);
        assert_eq!(
            motion_lines[0], motion_lines[1],
            "a failed frame repeats the last"
        );
        assert_eq!(motion_lines[0].split(' ').count(), 6 + 3 * 15);
    }

    #[test]
    fn bad_motion_is_refused_by_name() {
        let model = BodyModel::default();
        let mut partly = [0.0; NUM_PARAMS];
        partly[4] = f64::NAN;
        let mut inf = [0.0; NUM_PARAMS];
        inf[1] = f64::INFINITY;
        let nan = [f64::NAN; NUM_PARAMS];
        for (poses, fps, want) in [
            (vec![partly], 30.0, "poses[0]: some parameters are NaN"),
            (vec![inf], 30.0, "infinite"),
            (vec![nan, nan], 30.0, "every frame is NaN"),
            (vec![], 30.0, "no frame"),
            (vec![[0.0; NUM_PARAMS]], 0.0, "fps"),
            (vec![[0.0; NUM_PARAMS]], f64::NAN, "fps"),
        ] {
            let m = BvhMotion {
                poses: &poses,
                fps,
                confidence: None,
            };
            let e = bvh_text(&model, &m).unwrap_err().to_string();
            assert!(e.contains(want), "{want}: {e}");
        }
    }
}
