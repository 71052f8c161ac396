//! Inverse kinematics: the pose whose 15 joints best match given joint positions.
//!
//! The root is initialised in closed form from the torso geometry (hip centre; body x =
//! right hip → left hip blended with right → left shoulder; body y = shoulder centre →
//! hip centre, orthogonalised; z = x × y). The limbs are then solved by LM on the joint
//! residuals with the analytic joints Jacobian, within the joint limits, from a few
//! start configurations per limb (a limb's IK has separate basins, e.g. arm raised
//! forward vs sideways); for each limb the start that fits its joints best is kept and a
//! final LM polishes the combination. NaN joints are skipped.

use super::lm::{LevenbergMarquardt, LmConfig};
use super::system::{PoseObjective, N, NN};
use crate::body::kinematics::Kinematics;
use crate::body::rotation::rotation_vector;
use crate::body::{param, BodyModel, Pose, NUM_JOINTS, NUM_PARAMS};
use crate::error::{Error, Result};
use nalgebra::{Matrix3, Rotation3, Vector3};

/// Joint indices (ITOP order).
mod joint {
    pub const HEAD: usize = 0;
    pub const NECK: usize = 1;
    pub const R_SHOULDER: usize = 2;
    pub const L_SHOULDER: usize = 3;
    pub const R_ELBOW: usize = 4;
    pub const L_ELBOW: usize = 5;
    pub const R_HAND: usize = 6;
    pub const L_HAND: usize = 7;
    pub const TORSO: usize = 8;
    pub const R_HIP: usize = 9;
    pub const L_HIP: usize = 10;
    pub const R_KNEE: usize = 11;
    pub const L_KNEE: usize = 12;
    pub const R_FOOT: usize = 13;
    pub const L_FOOT: usize = 14;
}

/// Start values of an arm (flexion, abduction, rotation; elbow fixed at
/// [`ARM_START_ELBOW`]), combined as a grid.
const ARM_START_FLEXION: [f64; 4] = [-0.7, 0.5, 1.5, 2.6];
const ARM_START_ABDUCTION: [f64; 3] = [0.1, 1.5, 2.8];
const ARM_START_ROTATION: [f64; 3] = [-1.0, 0.0, 1.0];
const ARM_START_ELBOW: f64 = 0.8;
/// Start values of a leg (flexion, abduction, knee), combined as a grid.
const LEG_START_FLEXION: [f64; 2] = [0.0, 1.2];
const LEG_START_ABDUCTION: [f64; 2] = [0.05, 0.8];
const LEG_START_KNEE: [f64; 2] = [0.3, 1.5];

fn arm_starts() -> impl Iterator<Item = [f64; 4]> {
    ARM_START_FLEXION.into_iter().flat_map(|f| {
        ARM_START_ABDUCTION.into_iter().flat_map(move |a| {
            ARM_START_ROTATION
                .into_iter()
                .map(move |r| [f, a, r, ARM_START_ELBOW])
        })
    })
}

fn leg_starts() -> Vec<[f64; 3]> {
    LEG_START_FLEXION
        .into_iter()
        .flat_map(|f| {
            LEG_START_ABDUCTION
                .into_iter()
                .flat_map(move |a| LEG_START_KNEE.into_iter().map(move |k| [f, a, k]))
        })
        .collect()
}

/// The limb chains: (first parameter, parameter count, joints they place).
const CHAINS: [(usize, usize, [usize; 2]); 5] = [
    (param::R_SHOULDER, 4, [joint::R_ELBOW, joint::R_HAND]),
    (param::L_SHOULDER, 4, [joint::L_ELBOW, joint::L_HAND]),
    (param::R_HIP, 3, [joint::R_KNEE, joint::R_FOOT]),
    (param::L_HIP, 3, [joint::L_KNEE, joint::L_FOOT]),
    (param::NECK, 2, [joint::HEAD, joint::HEAD]),
];

/// Fewer finite joints than this cannot fix a pose.
const MIN_FINITE_JOINTS: usize = 3;

/// ½ Σ_j |joint_j(θ) − target_j|² over the finite targets.
pub struct JointObjective<'a> {
    pub model: &'a BodyModel,
    pub targets: &'a [Vector3<f64>; NUM_JOINTS],
    /// 1 for finite targets, 0 for NaN ones.
    pub weights: [f64; NUM_JOINTS],
    jac: Box<[f64; NUM_JOINTS * 3 * NUM_PARAMS]>,
}

impl<'a> JointObjective<'a> {
    pub fn new(model: &'a BodyModel, targets: &'a [Vector3<f64>; NUM_JOINTS]) -> Self {
        let weights = std::array::from_fn(|j| {
            if targets[j].iter().all(|v| v.is_finite()) {
                1.0
            } else {
                0.0
            }
        });
        JointObjective {
            model,
            targets,
            weights,
            jac: Box::new([0.0; NUM_JOINTS * 3 * NUM_PARAMS]),
        }
    }

    fn residual(&self, j: usize, joints: &[Vector3<f64>; NUM_JOINTS]) -> Vector3<f64> {
        if self.weights[j] > 0.0 {
            joints[j] - self.targets[j]
        } else {
            Vector3::zeros()
        }
    }

    /// Squared error of each joint at `pose` (0 for NaN targets).
    pub fn squared_errors(&self, pose: &Pose) -> [f64; NUM_JOINTS] {
        let joints = self.model.joints(pose);
        std::array::from_fn(|j| self.residual(j, &joints).norm_squared())
    }
}

impl PoseObjective for JointObjective<'_> {
    fn cost(&mut self, pose: &Pose) -> f64 {
        0.5 * self.squared_errors(pose).iter().sum::<f64>()
    }

    fn normal_equations(&mut self, pose: &Pose, h: &mut [f64; NN], g: &mut [f64; N]) -> f64 {
        let kin = Kinematics::new(self.model, pose);
        kin.joints_jacobian(&mut self.jac);
        let joints = kin.joints();
        h.fill(0.0);
        g.fill(0.0);
        let mut cost = 0.0;
        for j in 0..NUM_JOINTS {
            if self.weights[j] == 0.0 {
                continue;
            }
            let r = self.residual(j, &joints);
            cost += 0.5 * r.norm_squared();
            for c in 0..3 {
                let row = &self.jac[(3 * j + c) * N..(3 * j + c + 1) * N];
                for a in 0..N {
                    if row[a] == 0.0 {
                        continue;
                    }
                    g[a] += row[a] * r[c];
                    for b in 0..N {
                        h[a * N + b] += row[a] * row[b];
                    }
                }
            }
        }
        cost
    }
}

fn finite(v: &Vector3<f64>) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn midpoint(a: &Vector3<f64>, b: &Vector3<f64>) -> Option<Vector3<f64>> {
    (finite(a) && finite(b)).then(|| 0.5 * (a + b))
}

/// Root translation and rotation from the torso joints, if they determine them.
fn root_from_torso(joints: &[Vector3<f64>; NUM_JOINTS]) -> Option<(Vector3<f64>, Rotation3<f64>)> {
    let hip_c = midpoint(&joints[joint::R_HIP], &joints[joint::L_HIP]);
    let sh_c = midpoint(&joints[joint::R_SHOULDER], &joints[joint::L_SHOULDER]);
    let centre = hip_c?;
    // Left-pointing axis from hips and shoulders (whichever exist).
    let mut x = Vector3::zeros();
    if finite(&joints[joint::R_HIP]) && finite(&joints[joint::L_HIP]) {
        x += (joints[joint::L_HIP] - joints[joint::R_HIP]).normalize();
    }
    if sh_c.is_some() {
        x += (joints[joint::L_SHOULDER] - joints[joint::R_SHOULDER]).normalize();
    }
    // Down axis: from the upper body toward the hips.
    let top = sh_c
        .or_else(|| finite(&joints[joint::NECK]).then_some(joints[joint::NECK]))
        .or_else(|| finite(&joints[joint::TORSO]).then_some(joints[joint::TORSO]))?;
    let mut y = centre - top;
    if y.norm() < 1e-9 || x.norm() < 1e-9 {
        return None;
    }
    x.normalize_mut();
    y -= x * x.dot(&y);
    if y.norm() < 1e-9 {
        return None;
    }
    y.normalize_mut();
    let z = x.cross(&y);
    let m = Matrix3::from_columns(&[x, y, z]);
    Some((centre, Rotation3::from_matrix_unchecked(m)))
}

/// Settings of [`pose_from_joints_with`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkConfig {
    pub lm: LmConfig,
}

impl Default for IkConfig {
    fn default() -> Self {
        IkConfig {
            lm: LmConfig {
                cost_tolerance: 1e-14,
                step_tolerance: 1e-10,
                gradient_tolerance: 1e-14,
                max_iterations: 100,
                ..LmConfig::default()
            },
        }
    }
}

/// The pose whose joints best fit `joints` (ITOP order, camera frame; NaN = unknown),
/// starting from `init` if given (else from the torso geometry).
pub fn pose_from_joints(
    model: &BodyModel,
    joints: &[Vector3<f64>; NUM_JOINTS],
    init: Option<&Pose>,
) -> Result<Pose> {
    pose_from_joints_with(model, joints, init, &IkConfig::default())
}

/// [`pose_from_joints`] with explicit settings.
pub fn pose_from_joints_with(
    model: &BodyModel,
    joints: &[Vector3<f64>; NUM_JOINTS],
    init: Option<&Pose>,
    config: &IkConfig,
) -> Result<Pose> {
    let n_finite = joints.iter().filter(|j| finite(j)).count();
    if n_finite < MIN_FINITE_JOINTS {
        return Err(Error::invalid(
            "joints",
            format!("needs at least {MIN_FINITE_JOINTS} finite joints, got {n_finite}"),
        ));
    }
    if let Some(p) = init {
        if p.iter().any(|v| !v.is_finite()) {
            return Err(Error::invalid("init", "pose has non-finite values"));
        }
    }
    let mut base = init.copied().unwrap_or_else(BodyModel::neutral_pose);
    if init.is_none() {
        if let Some((t, r)) = root_from_torso(joints) {
            base[..3].copy_from_slice(t.as_slice());
            base[param::ROOT_R..param::ROOT_R + 3].copy_from_slice(rotation_vector(&r).as_slice());
        } else {
            let mean = joints.iter().filter(|j| finite(j)).sum::<Vector3<f64>>() / n_finite as f64;
            base[..3].copy_from_slice(mean.as_slice());
        }
    }
    let mut lm = LevenbergMarquardt::new(config.lm)?;
    let mut objective = JointObjective::new(model, joints);

    // Fit the root alone first (limbs at their start values), so the limb starts are
    // evaluated in a sensible body frame.
    let mut candidates: Vec<Pose> = Vec::new();
    if let Some(p) = init {
        candidates.push(*p);
    }
    let legs = leg_starts();
    for (s, a) in arm_starts().enumerate() {
        let mut p = base;
        let l = legs[s % legs.len()];
        for start in [param::R_SHOULDER, param::L_SHOULDER] {
            p[start..start + 4].copy_from_slice(&a);
        }
        for start in [param::R_HIP, param::L_HIP] {
            p[start..start + 3].copy_from_slice(&l);
        }
        p[param::NECK] = 0.0;
        p[param::NECK + 1] = 0.0;
        candidates.push(p);
    }
    let mut best_chain: [(f64, Pose); CHAINS.len()] = [(f64::INFINITY, base); CHAINS.len()];
    let mut best_root = (f64::INFINITY, base);
    for mut p in candidates {
        lm.minimize(&mut objective, &mut p);
        let err = objective.squared_errors(&p);
        let total: f64 = err.iter().sum();
        if total < best_root.0 {
            best_root = (total, p);
        }
        for (c, (_, _, js)) in CHAINS.iter().enumerate() {
            let e = err[js[0]] + if js[0] != js[1] { err[js[1]] } else { 0.0 };
            if e < best_chain[c].0 {
                best_chain[c] = (e, p);
            }
        }
    }
    let mut pose = best_root.1;
    for (c, (start, count, _)) in CHAINS.iter().enumerate() {
        pose[*start..start + count].copy_from_slice(&best_chain[c].1[*start..start + count]);
    }
    lm.minimize(&mut objective, &mut pose);
    // The combination can only help, but keep whichever fits better.
    let (e_best, e_pose) = (best_root.0, objective.squared_errors(&pose).iter().sum());
    if e_best < e_pose {
        pose = best_root.1;
    }
    Ok(pose)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::kinematics::tests::pose_for_tests;

    fn max_error(model: &BodyModel, pose: &Pose, joints: &[Vector3<f64>; NUM_JOINTS]) -> f64 {
        let got = model.joints(pose);
        (0..NUM_JOINTS)
            .filter(|&j| finite(&joints[j]))
            .map(|j| (got[j] - joints[j]).norm())
            .fold(0.0, f64::max)
    }

    #[test]
    fn recovers_random_poses_from_scratch() {
        let model = BodyModel::default();
        for seed in 0..12 {
            let truth = pose_for_tests(100 + seed);
            let joints = model.joints(&truth);
            let pose = pose_from_joints(&model, &joints, None).unwrap();
            let err = max_error(&model, &pose, &joints);
            let got = model.joints(&pose);
            let per: Vec<f64> = (0..NUM_JOINTS)
                .map(|j| (got[j] - joints[j]).norm())
                .collect();
            assert!(
                err < 1e-3,
                "seed {seed}: max joint error {err} {per:?} truth {truth:?} got {pose:?}"
            );
            let (lo, hi) = (BodyModel::lower_bounds(), BodyModel::upper_bounds());
            assert!((0..N).all(|i| pose[i] >= lo[i] && pose[i] <= hi[i]));
        }
    }

    #[test]
    fn skips_nan_joints() {
        let model = BodyModel::default();
        let truth = pose_for_tests(7);
        let mut joints = model.joints(&truth);
        joints[joint::L_HAND] = Vector3::repeat(f64::NAN);
        joints[joint::HEAD] = Vector3::repeat(f64::NAN);
        let pose = pose_from_joints(&model, &joints, None).unwrap();
        assert!(pose.iter().all(|v| v.is_finite()));
        assert!(max_error(&model, &pose, &joints) < 1e-3);
        let all_nan = [Vector3::repeat(f64::NAN); NUM_JOINTS];
        let e = pose_from_joints(&model, &all_nan, None).unwrap_err();
        assert!(e.to_string().starts_with("joints"));
    }

    #[test]
    fn is_deterministic() {
        let model = BodyModel::default();
        let joints = model.joints(&pose_for_tests(3));
        let a = pose_from_joints(&model, &joints, None).unwrap();
        let b = pose_from_joints(&model, &joints, None).unwrap();
        assert_eq!(a, b);
    }
}
