//! Synthetic depth sequences of the ellipsoid body model moving in a room.
//!
//! [`make_sequence`] renders a [`Motion`] with the body renderer, adds a floor and a
//! back wall, and applies a Kinect-v1-like sensor model ([`apply_sensor`]): axial noise
//! σ(z) = 1.2 mm + 1.9 mm·(z − 0.4)², disparity quantisation (f = 580 px at 640
//! columns, baseline 7.5 cm, 1/8 px), a projector shadow to the image left of the body,
//! dropouts on the far side of depth edges and ~1 % random dropouts. The same seed gives
//! the same sequence; no external data.

use crate::body::rotation::{matrix_from_rotation_vector, rotation_vector_from_matrix};
use crate::body::{param, BodyModel, Pose, NUM_JOINTS, NUM_PARAMS};
use crate::camera::Camera;
use crate::error::{Error, Result};
use nalgebra::{Matrix3, Vector3};
use std::f64::consts::{PI, TAU};

/// Kinect v1 focal length (px) at 640 columns.
const KINECT_FOCAL_640: f64 = 580.0;
/// Kinect v1 projector-to-camera baseline (m); the projector is on the camera's +x side.
const KINECT_BASELINE: f64 = 0.075;
/// Disparity resolution (px).
const DISPARITY_STEP: f64 = 1.0 / 8.0;
/// Axial noise σ(z) = NOISE_SIGMA_0 + NOISE_SIGMA_2·(z − NOISE_Z_0)² (m).
const NOISE_SIGMA_0: f64 = 0.0012;
const NOISE_SIGMA_2: f64 = 0.0019;
const NOISE_Z_0: f64 = 0.4;
/// A neighbour this much nearer (m) makes a pixel the far side of a depth edge.
const EDGE_STEP: f64 = 0.05;
/// Dropout probability on the far side of an edge, and anywhere, at noise 1.
const EDGE_DROP: f64 = 0.5;
const RANDOM_DROP: f64 = 0.01;
/// A surface this much (m) behind the one the projector sees there is in its shadow.
const SHADOW_MARGIN: f64 = 0.05;
/// Largest depth a uint16 millimetre image holds.
const MAX_DEPTH_MM: f64 = 65535.0;
/// Forward lean of the trunk at the bottom of a squat (rad).
const SQUAT_LEAN: f64 = 0.5;
/// Joints whose height puts the body on the floor (the feet).
const FEET: [usize; 2] = [13, 14];

/// The motions a sequence shows; each is periodic in its phase `t` ∈ [0, 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Motion {
    /// One gait cycle: the swing knee flexes, the arms swing opposite; travels 0.8 m
    /// toward the camera over the sequence.
    Walk,
    /// The right arm raised, its forearm waving twice a cycle.
    Wave,
    /// Down and up, arms forward, the trunk leaning forward at the bottom.
    Squat,
    /// Standing, turned through a half turn over the sequence.
    Turn,
    /// Both arms raised sideways overhead and lowered.
    ArmRaise,
}

impl Motion {
    /// Every motion, in the order of [`Motion::name`]'s list.
    pub const ALL: [Motion; 5] = [
        Motion::Walk,
        Motion::Wave,
        Motion::Squat,
        Motion::Turn,
        Motion::ArmRaise,
    ];

    /// The motion's name: "walk", "wave", "squat", "turn" or "arm_raise".
    pub fn name(self) -> &'static str {
        match self {
            Motion::Walk => "walk",
            Motion::Wave => "wave",
            Motion::Squat => "squat",
            Motion::Turn => "turn",
            Motion::ArmRaise => "arm_raise",
        }
    }

    /// The motion called `name`.
    pub fn from_name(name: &str) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|m| m.name() == name)
            .ok_or_else(|| {
                let mut names: Vec<_> = Self::ALL.iter().map(|m| m.name()).collect();
                names.sort_unstable();
                Error::invalid(
                    "motion",
                    format!(
                        "unknown motion {}; choose from {names:?}",
                        crate::error::brief_text(name)
                    ),
                )
            })
    }

    /// The joint angles at phase `t` (taken modulo 1); the root parts are zero.
    pub fn pose(self, t: f64) -> Pose {
        let t = t.rem_euclid(1.0);
        let mut p = BodyModel::neutral_pose();
        p[..6].fill(0.0);
        let ph = TAU * t;
        // 0 → 1 → 0 over the cycle.
        let s = 0.5 * (1.0 - ph.cos());
        let (neck, rs, ls) = (param::NECK, param::R_SHOULDER, param::L_SHOULDER);
        match self {
            Motion::Walk => walk(&mut p, ph),
            Motion::Wave => {
                p[rs + 1] = 2.3;
                p[rs + 2] = -0.3;
                p[param::R_ELBOW] = 0.9 + 0.5 * (2.0 * ph).sin();
                p[neck + 1] = 0.1 * ph.sin();
            }
            Motion::Squat => {
                p[param::R_HIP] = 1.5 * s;
                p[param::L_HIP] = 1.5 * s;
                p[param::R_KNEE] = 2.0 * s;
                p[param::L_KNEE] = 2.0 * s;
                p[rs] = 1.4 * s;
                p[ls] = 1.4 * s;
                p[neck] = -0.3 * s;
            }
            Motion::Turn => {
                walk(&mut p, 0.0);
                p[param::R_ELBOW] = 0.2;
                p[param::L_ELBOW] = 0.2;
            }
            Motion::ArmRaise => {
                p[rs + 1] = 0.12 + 2.7 * s;
                p[ls + 1] = 0.12 + 2.7 * s;
                p[param::R_ELBOW] = 0.1;
                p[param::L_ELBOW] = 0.1;
            }
        }
        p
    }

    /// Yaw (rad) added over the whole sequence.
    fn yaw_sweep(self) -> f64 {
        if self == Motion::Turn {
            PI
        } else {
            0.0
        }
    }

    /// Distance (m) travelled forward over the whole sequence.
    fn travel(self) -> f64 {
        if self == Motion::Walk {
            0.8
        } else {
            0.0
        }
    }
}

/// The walk's joint angles at phase angle `ph`.
fn walk(p: &mut Pose, ph: f64) {
    let (sin, knee) = (ph.sin(), (ph + 0.8).sin());
    p[param::R_HIP] = 0.45 * sin;
    p[param::L_HIP] = -0.45 * sin;
    p[param::R_KNEE] = 0.1 + 0.6 * knee.max(0.0);
    p[param::L_KNEE] = 0.1 + 0.6 * (-knee).max(0.0);
    p[param::R_SHOULDER] = -0.35 * sin;
    p[param::L_SHOULDER] = 0.35 * sin;
    p[param::R_ELBOW] = 0.3 + 0.15 * (-sin).max(0.0);
    p[param::L_ELBOW] = 0.3 + 0.15 * sin.max(0.0);
}

/// What a sequence shows and how it is seen.
#[derive(Clone, Debug)]
pub struct SequenceConfig {
    pub motion: Motion,
    /// Number of frames, 1..=10000.
    pub frames: usize,
    /// Hip centre's distance ahead of the camera at the start (m), 0.8..=8.
    pub distance: f64,
    /// The subject's yaw (degrees, −360..=360): 0 faces the camera, +90 turns the left
    /// side toward it.
    pub view_deg: f64,
    /// Sensor noise scale, 0..=10 (0: the clean render).
    pub noise: f64,
    pub seed: u64,
    /// The subject's height (m).
    pub height: f64,
    /// Motion cycles over the sequence, 0..=100.
    pub cycles: f64,
    /// Frames per second (recorded with the sequence), 0.1..=1000.
    pub fps: f64,
    /// The camera's height above the floor (m), 0.2..=3.
    pub camera_height: f64,
    /// The camera's downward pitch (degrees), −45..=45.
    pub tilt_deg: f64,
    /// The back wall's distance (m), 1..=20 and at least 0.5 m behind the subject
    /// (None: 1.5 m behind the subject).
    pub wall_distance: Option<f64>,
}

impl Default for SequenceConfig {
    fn default() -> Self {
        SequenceConfig {
            motion: Motion::Wave,
            frames: 30,
            distance: 3.0,
            view_deg: 0.0,
            noise: 1.0,
            seed: 0,
            height: 1.75,
            cycles: 1.0,
            fps: 30.0,
            camera_height: 1.2,
            tilt_deg: 5.0,
            wall_distance: None,
        }
    }
}

/// `value` if it is a number within `lo..=hi`.
fn within(name: &str, value: f64, lo: f64, hi: f64) -> Result<f64> {
    if value.is_finite() && (lo..=hi).contains(&value) {
        Ok(value)
    } else {
        Err(Error::invalid(
            name,
            format!("must be a number within {lo}..{hi}, got {value}"),
        ))
    }
}

impl SequenceConfig {
    /// Checks every setting; returns the wall's distance.
    pub fn validate(&self) -> Result<f64> {
        if !(1..=10_000).contains(&self.frames) {
            return Err(Error::invalid(
                "frames",
                format!("must be within 1..10000, got {}", self.frames),
            ));
        }
        let distance = within("distance", self.distance, 0.8, 8.0)?;
        within("view_deg", self.view_deg, -360.0, 360.0)?;
        within("noise", self.noise, 0.0, 10.0)?;
        within("cycles", self.cycles, 0.0, 100.0)?;
        within("fps", self.fps, 0.1, 1000.0)?;
        within("camera_height", self.camera_height, 0.2, 3.0)?;
        within("tilt_deg", self.tilt_deg, -45.0, 45.0)?;
        let wall = match self.wall_distance {
            None => distance + 1.5,
            Some(w) => within("wall_distance", w, 1.0, 20.0)?,
        };
        if wall <= distance + 0.5 {
            return Err(Error::invalid(
                "wall_distance",
                "the wall must be at least 0.5 m behind the subject",
            ));
        }
        Ok(wall)
    }
}

/// A rendered sequence of T frames of H×W pixels, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Sequence {
    /// (T, H, W) millimetres, 0 = no reading.
    pub depth: Vec<u16>,
    /// (H, W) millimetres: the empty room through the same sensor.
    pub background: Vec<u16>,
    /// (T, H, W) the person's pixels.
    pub mask: Vec<bool>,
    /// (T, H, W) the body part of each person pixel, −1 elsewhere.
    pub labels: Vec<i16>,
    /// (T, 15, 3) joints, camera frame (m).
    pub joints: Vec<f32>,
    /// (T, 22) poses.
    pub poses: Vec<f64>,
    /// The back wall's distance (m).
    pub wall_distance: f64,
}

/// Rotation about the camera's x axis that pitches it down by `tilt` (rad): maps camera
/// directions to the world (x right, y down, z forward).
fn camera_to_world(tilt: f64) -> Matrix3<f64> {
    let (s, c) = tilt.sin_cos();
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, s, 0.0, -s, c)
}

/// Renders `config`'s sequence seen by `camera`.
pub fn make_sequence(camera: &Camera, config: &SequenceConfig) -> Result<Sequence> {
    let wall = config.validate()?;
    let model = BodyModel::new(config.height)?;
    let (frames, motion) = (config.frames, config.motion);
    let mut rng = Rng::new(config.seed);
    let r_wc = camera_to_world(config.tilt_deg.to_radians());
    let r_cw = r_wc.transpose();
    let n = camera.width * camera.height;
    let scene = scene_depth(camera, &r_wc, config.camera_height, wall);
    let mut seq = Sequence {
        depth: Vec::with_capacity(frames * n),
        background: Vec::new(),
        mask: Vec::with_capacity(frames * n),
        labels: Vec::with_capacity(frames * n),
        joints: Vec::with_capacity(frames * NUM_JOINTS * 3),
        poses: Vec::with_capacity(frames * NUM_PARAMS),
        wall_distance: wall,
    };
    let last = (frames.max(2) - 1) as f64;
    for f in 0..frames {
        let t = f as f64 / frames as f64 * config.cycles;
        let progress = f as f64 / last;
        let yaw = config.view_deg.to_radians() + motion.yaw_sweep() * progress;
        let lean = if motion == Motion::Squat {
            SQUAT_LEAN * 0.5 * (1.0 - (TAU * t).cos())
        } else {
            0.0
        };
        // Body axes in the world: yaw about the vertical, then lean forward (the body's
        // −z is its front: a positive rotation about body x tips the head forward).
        let yawed = matrix_from_rotation_vector(&Vector3::new(0.0, yaw, 0.0));
        let r_world = yawed * matrix_from_rotation_vector(&Vector3::new(lean, 0.0, 0.0));
        let forward = yawed * Vector3::new(0.0, 0.0, -1.0);
        let mut hip_w =
            Vector3::new(0.0, 0.0, config.distance) + motion.travel() * progress * forward;
        let mut pose = motion.pose(t);
        pose[..3].copy_from_slice((r_cw * hip_w).as_slice());
        pose[3..6].copy_from_slice(rotation_vector_from_matrix(&(r_cw * r_world)).as_slice());
        // Put the lower foot on the floor.
        let joints = model.joints(&pose);
        let lowest = FEET
            .iter()
            .map(|&j| (r_wc * joints[j]).y)
            .fold(f64::NEG_INFINITY, f64::max);
        hip_w.y += config.camera_height - model.shape.ankle_height - lowest;
        pose[..3].copy_from_slice((r_cw * hip_w).as_slice());
        let (body, labels) = model.render_depth(&pose, camera);
        let mut clean = scene.clone();
        let person: Vec<bool> = body
            .iter()
            .zip(&scene)
            .map(|(&b, &s)| b > 0.0 && (s == 0.0 || f64::from(b) < s))
            .collect();
        for ((c, &b), &p) in clean.iter_mut().zip(&body).zip(&person) {
            if p {
                *c = f64::from(b);
            }
        }
        let noisy = apply_sensor(&clean, camera, config.noise, &mut rng);
        seq.depth.extend(noisy.iter().map(|&z| millimetres(z)));
        seq.labels.extend(
            labels
                .iter()
                .zip(&person)
                .map(|(&l, &p)| if p { l } else { -1 }),
        );
        seq.mask.extend(person);
        let joints = model.joints(&pose);
        seq.joints
            .extend(joints.iter().flat_map(|j| j.iter().map(|&v| v as f32)));
        seq.poses.extend(pose);
    }
    let background = apply_sensor(&scene, camera, config.noise, &mut rng);
    seq.background = background.iter().map(|&z| millimetres(z)).collect();
    Ok(seq)
}

/// Metres as whole millimetres (ties to even), within the uint16 range.
fn millimetres(z: f64) -> u16 {
    (z * 1000.0).round_ties_even().clamp(0.0, MAX_DEPTH_MM) as u16
}

/// Depth (z) of the room seen by `camera`, pitched by `r_wc` (camera → world): the
/// floor `camera_height` below the camera and the back wall `wall` m ahead; 0 where
/// neither is seen.
fn scene_depth(camera: &Camera, r_wc: &Matrix3<f64>, camera_height: f64, wall: f64) -> Vec<f64> {
    let mut out = Vec::with_capacity(camera.width * camera.height);
    for v in 0..camera.height {
        for u in 0..camera.width {
            let ray = Vector3::new(
                (u as f64 - camera.cx) / camera.fx,
                (v as f64 - camera.cy) / camera.fy,
                1.0,
            );
            let d = r_wc * ray;
            let hit = |dir: f64, at: f64| if dir > 1e-9 { at / dir } else { f64::INFINITY };
            let z = hit(d.y, camera_height).min(hit(d.z, wall));
            out.push(if z.is_finite() { z } else { 0.0 });
        }
    }
    out
}

/// The Kinect-like sensor model applied to a clean depth image `z` (H×W metres, 0 =
/// none) of `camera`, scaled by `noise` (0: `z` as it is).
pub fn apply_sensor(z: &[f64], camera: &Camera, noise: f64, rng: &mut Rng) -> Vec<f64> {
    let mut out = z.to_vec();
    if noise <= 0.0 {
        return out;
    }
    let (h, w) = (camera.height, camera.width);
    let valid: Vec<bool> = z.iter().map(|&d| d > 0.0).collect();
    // Projector shadow: a z-buffer seen from the projector (+x), per row in projector
    // columns u − f·b/z; pixels behind a nearer surface there get no pattern.
    let fb = camera.fx * KINECT_BASELINE;
    let column = |i: usize| -> usize {
        let p = ((i % w) as f64 - fb / z[i]).round_ties_even() as i64;
        (p.clamp(-(w as i64), 2 * w as i64 - 1) + w as i64) as usize
    };
    let mut projector = vec![f64::INFINITY; h * 3 * w];
    for i in (0..h * w).filter(|&i| valid[i]) {
        let at = (i / w) * 3 * w + column(i);
        projector[at] = projector[at].min(z[i]);
    }
    for i in (0..h * w).filter(|&i| valid[i]) {
        if projector[(i / w) * 3 * w + column(i)] < z[i] - SHADOW_MARGIN {
            out[i] = 0.0;
        }
    }
    // The far side of depth edges (4-neighbours, wrapping at the borders), then random
    // dropouts.
    let far = |i: usize| {
        let (r, c) = (i / w, i % w);
        let neighbours = [
            r * w + (c + w - 1) % w,
            r * w + (c + 1) % w,
            ((r + h - 1) % h) * w + c,
            ((r + 1) % h) * w + c,
        ];
        valid[i]
            && neighbours
                .iter()
                .any(|&j| z[j] > 0.0 && z[j] < z[i] - EDGE_STEP)
    };
    let edge_drop = EDGE_DROP * noise.min(1.0);
    let mut drop: Vec<bool> = (0..h * w)
        .map(|i| rng.uniform() < edge_drop && far(i))
        .collect();
    for d in drop.iter_mut() {
        *d |= rng.uniform() < RANDOM_DROP * noise;
    }
    for (o, _) in out.iter_mut().zip(&drop).filter(|(_, &d)| d) {
        *o = 0.0;
    }
    // Axial noise, then disparity quantisation at the native Kinect resolution.
    let fb_native = KINECT_FOCAL_640 * KINECT_BASELINE;
    for o in out.iter_mut().filter(|o| **o > 0.0) {
        let sigma = noise * (NOISE_SIGMA_0 + NOISE_SIGMA_2 * (*o - NOISE_Z_0).powi(2));
        let noisy = *o + rng.normal() * sigma;
        let disparity =
            (fb_native / noisy.max(0.05) / DISPARITY_STEP).round_ties_even() * DISPARITY_STEP;
        *o = fb_native / disparity.max(DISPARITY_STEP);
    }
    out
}

/// The sensor model's random numbers: SplitMix64 (Steele, Lea and Flood 2014), uniform
/// in [0, 1) from the top 53 bits, normal by the Box–Muller transform.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed)
    }

    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut x = self.0;
        x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        x ^ (x >> 31)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Standard normal.
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform(); // (0, 1]
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> Camera {
        Camera::itop().scaled(0.5).unwrap()
    }

    #[test]
    fn same_seed_same_sequence_other_seed_other_noise() {
        let cfg = SequenceConfig {
            frames: 2,
            ..Default::default()
        };
        let a = make_sequence(&camera(), &cfg).unwrap();
        let b = make_sequence(&camera(), &cfg).unwrap();
        let c = make_sequence(
            &camera(),
            &SequenceConfig {
                seed: 1,
                ..cfg.clone()
            },
        )
        .unwrap();
        assert_eq!(a, b);
        assert_ne!(a.depth, c.depth);
        assert_eq!(a.mask, c.mask);
    }

    #[test]
    fn without_noise_the_person_is_the_render() {
        let cfg = SequenceConfig {
            frames: 1,
            noise: 0.0,
            ..Default::default()
        };
        let s = make_sequence(&camera(), &cfg).unwrap();
        assert!(s.mask.iter().filter(|&&m| m).count() > 300);
        assert!(s.mask.iter().zip(&s.depth).all(|(&m, &d)| !m || d > 0));
        assert!(s.mask.iter().zip(&s.labels).all(|(&m, &l)| m == (l >= 0)));
    }

    #[test]
    fn the_normal_numbers_have_unit_variance() {
        let mut rng = Rng::new(3);
        let v: Vec<f64> = (0..20_000).map(|_| rng.normal()).collect();
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len() as f64;
        assert!(
            mean.abs() < 0.03 && (var - 1.0).abs() < 0.05,
            "{mean} {var}"
        );
    }

    #[test]
    fn bad_settings_name_themselves() {
        for (cfg, name) in [
            (
                SequenceConfig {
                    frames: 0,
                    ..Default::default()
                },
                "frames",
            ),
            (
                SequenceConfig {
                    distance: -1.0,
                    ..Default::default()
                },
                "distance",
            ),
            (
                SequenceConfig {
                    noise: f64::NAN,
                    ..Default::default()
                },
                "noise",
            ),
            (
                SequenceConfig {
                    wall_distance: Some(3.2),
                    ..Default::default()
                },
                "wall_distance",
            ),
        ] {
            let e = make_sequence(&camera(), &cfg).unwrap_err().to_string();
            assert!(e.contains(name), "{e}");
        }
        assert!(Motion::from_name("moonwalk")
            .unwrap_err()
            .to_string()
            .contains("motion"));
    }
}
