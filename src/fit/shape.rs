//! Body-shape calibration: the shape factors ([`crate::body::SHAPE_FACTOR_NAMES`]) and
//! the poses of one or several frames, fitted together.
//!
//! # Objective
//! The same energy as the pose fit ([`super::em`]), summed over the frames, at the final
//! outlier distance τ, plus a weak quadratic prior on the shape factors:
//!
//! E(s, Θ, V) = Σ_f E_f(s, θ_f, V_f) + ½·w·Σ_j (s_j − 1)²
//!
//! where s are the factors of the base model's shape ([`crate::body::BodyShape::scaled`]),
//! θ_f the pose and V_f the part labels of frame f.
//!
//! # Algorithm ([`fit_shape`])
//! Rounds of two steps, each of which never increases E:
//! 1. *Pose/label step*: every frame is refitted by hard EM ([`super::hard_em`]) with the
//!    current shape from its current pose; the new pose and labels replace the old ones
//!    only if they lower E_f (hard EM restarts its outlier schedule and labelling, so it
//!    may end above the previous state).
//! 2. *Shape step* ([`shape_lm`]): for fixed labels, Levenberg–Marquardt over the shape
//!    factors jointly with every frame's pose, minimising Σ ρ(min(|d|, T))/σ² over the
//!    labelled points (d = signed point-to-ellipsoid distance: exactly the E1 part of
//!    E_f; the pairwise part does not depend on s or θ) plus the prior. Bounds: factors
//!    within [`ShapeConfig::lower`]..[`ShapeConfig::upper`], joint angles within their
//!    limits (projected LM with an active set, as in [`super::lm`]); a step is kept only
//!    if it lowers the cost.
//!
//! # Jacobian
//! Analytic for both parts. Pose columns: −n·v (n the outward normal at the closest
//! point, v the velocity of the point under the parameter), as in the pose fit. Shape
//! columns: with the pose fixed, every placed ellipsoid's centre c (camera frame) and
//! half-axes r are *linear* in the factors (segment lengths only translate frames), so
//! their derivatives dc/ds_j, dr/ds_j are taken exactly as central differences of the
//! placed ellipsoids (16 ellipsoids, once per frame and factor, not per point). Per
//! point, d(d)/dc = −n and d(d)/dr_i = −n_i·x_i/r_i (x the closest point and n the
//! normal in the ellipsoid frame: the surface's normal speed when r_i grows).
//!
//! Deterministic: frames are accumulated independently and summed in frame order.

use super::em::{crf_energy, edge_weights, hard_em, unary_costs, EmConfig, NUM_LABELS, OUTLIER};
use super::lm::pose_after_step;
/// Why [`shape_lm`] stopped (same meanings as [`super::Termination`]).
pub use super::lm::Termination as ShapeTermination;
use super::terms::PointCost;
use super::{FitConfig, MIN_POINTS};
use crate::body::kinematics::SEGMENT_DOFS;
use crate::body::{
    pose_from_slice, BodyModel, Kinematics, Pose, ShapeFactors, NUM_JOINTS, NUM_PARAMS,
    NUM_SEGMENTS, NUM_SHAPE_FACTORS, SHAPE_FACTOR_NAMES,
};
use crate::camera::Camera;
use crate::cloud::{neighbour_graph, Cloud, DepthView, PixelGraph};
use crate::error::{ensure, Error, Result};
use nalgebra::{DMatrix, DVector, Vector3};
use rayon::prelude::*;

/// Number of shape factors (alias for the pose-style name).
const S: usize = NUM_SHAPE_FACTORS;
/// Pose parameters per frame.
const P: usize = NUM_PARAMS;
/// Relative and absolute floors of the damping diagonal (as in [`super::lm`]).
const DIAGONAL_FLOOR_RELATIVE: f64 = 1e-6;
const DIAGONAL_FLOOR_ABSOLUTE: f64 = 1e-12;
/// A parameter within this distance of a bound counts as on it.
const BOUND_EPSILON: f64 = 1e-12;
/// Central-difference step of the (linear) placed-ellipsoid geometry in the factors.
const GEOMETRY_STEP: f64 = 0.05;

/// Settings of [`fit_shape`] and [`shape_lm`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShapeConfig {
    /// The per-frame pose fits (hard EM) and the CRF neighbourhood; the shape step uses
    /// the same σ, loss and truncation at the final outlier distance.
    pub fit: FitConfig,
    /// At most this many rounds of pose/label step + shape step.
    pub rounds: usize,
    /// At most this many LM iterations per shape step.
    pub lm_iterations: usize,
    /// Bounds of every shape factor (0 < lower ≤ 1 ≤ upper).
    pub lower: f64,
    pub upper: f64,
    /// Weight w of the prior ½·w·Σ(s − 1)² (≥ 0): keeps factors the data hardly
    /// constrain (e.g. the depth of the torso seen from the front) near the base shape.
    /// Default 1e5: on the shared synthetic sequences (a mesh body, not ellipsoids) a
    /// weaker prior (1e3) trades joint accuracy for surface fit (docs/fit.md).
    pub prior_weight: f64,
    /// Stop when a round lowers the energy by less than this fraction.
    pub tolerance: f64,
}

impl Default for ShapeConfig {
    fn default() -> Self {
        ShapeConfig {
            fit: FitConfig::default(),
            rounds: 3,
            lm_iterations: 20,
            lower: 0.7,
            upper: 1.4,
            prior_weight: 1e5,
            tolerance: 1e-4,
        }
    }
}

impl ShapeConfig {
    /// Checks every field, naming the bad one.
    pub fn validate(&self) -> Result<()> {
        self.fit.em.validate()?;
        ensure(self.rounds > 0, "rounds", || "must be at least 1".into())?;
        ensure(self.lm_iterations > 0, "lm_iterations", || {
            "must be at least 1".into()
        })?;
        ensure(
            self.lower.is_finite() && self.lower > 0.0 && self.lower <= 1.0,
            "lower",
            || format!("must be within (0, 1], got {}", self.lower),
        )?;
        ensure(self.upper.is_finite() && self.upper >= 1.0, "upper", || {
            format!("must be finite and >= 1, got {}", self.upper)
        })?;
        ensure(
            self.prior_weight.is_finite() && self.prior_weight >= 0.0,
            "prior_weight",
            || format!("must be finite and >= 0, got {}", self.prior_weight),
        )?;
        ensure(
            self.tolerance.is_finite() && self.tolerance >= 0.0,
            "tolerance",
            || format!("must be finite and >= 0, got {}", self.tolerance),
        )
    }

    /// The per-point cost of the shape step (final outlier distance).
    pub fn point_cost(&self) -> PointCost {
        point_cost(&self.fit.em)
    }
}

fn point_cost(em: &EmConfig) -> PointCost {
    PointCost {
        sigma: em.sigma,
        loss: em.loss,
        truncation: em.truncation_factor * em.outlier_distance,
    }
}

/// One frame of labelled points for [`shape_lm`]: labels 0..[`NUM_SEGMENTS`] are
/// segments, anything else (−1, the EM's outlier label) is skipped.
#[derive(Debug, Clone, Copy)]
pub struct LabelledFrame<'a> {
    pub points: &'a [[f32; 3]],
    pub labels: &'a [i32],
}

/// Outcome of [`shape_lm`].
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeLmReport {
    pub initial_cost: f64,
    pub cost: f64,
    /// Cost after every accepted step (strictly decreasing), starting with the initial.
    pub cost_trace: Vec<f64>,
    pub iterations: usize,
    pub accepted: usize,
    pub termination: ShapeTermination,
}

/// ½·w·Σ(s − 1)².
fn prior_cost(factors: &ShapeFactors, w: f64) -> f64 {
    0.5 * w * factors.iter().map(|f| (f - 1.0) * (f - 1.0)).sum::<f64>()
}

#[inline]
fn vec3(p: &[f32; 3]) -> Vector3<f64> {
    Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64)
}

#[inline]
fn cost_and_weight(pc: &PointCost, r: f64) -> (f64, f64) {
    let s2 = pc.sigma * pc.sigma;
    if r.abs() > pc.truncation {
        (pc.cap(), 0.0)
    } else {
        (pc.loss.rho(r) / s2, pc.loss.weight(r) / s2)
    }
}

/// The data cost of one frame: Σ over labelled points of ρ(min(|d|, T))/σ².
fn frame_cost(model: &BodyModel, frame: &LabelledFrame, pose: &Pose, pc: &PointCost) -> f64 {
    let kin = Kinematics::new(model, pose);
    let placed = model.placed_ellipsoids(&kin);
    frame
        .points
        .iter()
        .zip(frame.labels)
        .filter(|(_, &l)| l >= 0 && (l as usize) < NUM_SEGMENTS)
        .map(|(p, &l)| pc.cost(placed[l as usize].signed_distance(&vec3(p))))
        .sum()
}

/// One frame's share of the normal equations: shape block, shape×pose block, pose
/// block (row-major), gradients and cost.
struct FrameSystem {
    hss: [f64; S * S],
    hsp: [f64; S * P],
    hpp: [f64; P * P],
    gs: [f64; S],
    gp: [f64; P],
    cost: f64,
}

fn frame_system(
    base: &BodyModel,
    factors: &ShapeFactors,
    frame: &LabelledFrame,
    pose: &Pose,
    pc: &PointCost,
) -> Result<FrameSystem> {
    let model = base.with_shape_factors(factors)?;
    let kin = Kinematics::new(&model, pose);
    let placed = model.placed_ellipsoids(&kin);
    // d(centre)/ds_j and d(radii)/ds_j of every placed ellipsoid: exact central
    // differences, the geometry being linear in the factors for a fixed pose.
    let mut dc = [[Vector3::zeros(); NUM_SEGMENTS]; S];
    let mut dr = [[Vector3::zeros(); NUM_SEGMENTS]; S];
    for j in 0..S {
        let (mut fp, mut fm) = (*factors, *factors);
        fp[j] += GEOMETRY_STEP;
        fm[j] -= GEOMETRY_STEP;
        let mp = base.with_shape_factors(&fp)?;
        let mm = base.with_shape_factors(&fm)?;
        let pp = mp.placed_ellipsoids(&Kinematics::new(&mp, pose));
        let pm = mm.placed_ellipsoids(&Kinematics::new(&mm, pose));
        for k in 0..NUM_SEGMENTS {
            dc[j][k] = (pp[k].centre - pm[k].centre) / (2.0 * GEOMETRY_STEP);
            dr[j][k] = (pp[k].prepared.radii() - pm[k].prepared.radii()) / (2.0 * GEOMETRY_STEP);
        }
    }
    let mut sys = FrameSystem {
        hss: [0.0; S * S],
        hsp: [0.0; S * P],
        hpp: [0.0; P * P],
        gs: [0.0; S],
        gp: [0.0; P],
        cost: 0.0,
    };
    for (p, &l) in frame.points.iter().zip(frame.labels) {
        if l < 0 || l as usize >= NUM_SEGMENTS {
            continue;
        }
        let k = l as usize;
        let p = vec3(p);
        let e = &placed[k];
        let local = e.rotation.tr_mul(&(p - e.centre));
        let q = e.prepared.query(&local);
        let (c, w) = cost_and_weight(pc, q.distance);
        sys.cost += c;
        if w == 0.0 {
            continue;
        }
        let normal = e.rotation * q.normal;
        let radii = e.prepared.radii();
        // d(distance)/d(r_i) = −n_i·x_i/r_i (ellipsoid frame).
        let dd_dr = Vector3::from_fn(|i, _| -q.normal[i] * q.closest[i] / radii[i]);
        let mut js = [0.0; S];
        for j in 0..S {
            js[j] = -normal.dot(&dc[j][k]) + dd_dr.dot(&dr[j][k]);
        }
        let mut jp = [0.0; P];
        for (dof, o) in jp.iter_mut().enumerate() {
            if SEGMENT_DOFS[k] & (1 << dof) != 0 {
                *o = -normal.dot(&kin.point_velocity(dof, &p));
            }
        }
        let wr = w * q.distance;
        for a in 0..S {
            let wa = w * js[a];
            sys.gs[a] += js[a] * wr;
            for (b, &jb) in js.iter().enumerate().skip(a) {
                sys.hss[a * S + b] += wa * jb;
            }
            for (b, &jb) in jp.iter().enumerate() {
                if jb != 0.0 {
                    sys.hsp[a * P + b] += wa * jb;
                }
            }
        }
        for a in 0..P {
            if jp[a] == 0.0 {
                continue;
            }
            let wa = w * jp[a];
            sys.gp[a] += jp[a] * wr;
            for (b, &jb) in jp.iter().enumerate().skip(a) {
                sys.hpp[a * P + b] += wa * jb;
            }
        }
    }
    for a in 0..S {
        for b in 0..a {
            sys.hss[a * S + b] = sys.hss[b * S + a];
        }
    }
    for a in 0..P {
        for b in 0..a {
            sys.hpp[a * P + b] = sys.hpp[b * P + a];
        }
    }
    Ok(sys)
}

/// Total cost of the shape step: data over all frames plus the prior.
fn total_cost(
    base: &BodyModel,
    factors: &ShapeFactors,
    frames: &[LabelledFrame],
    poses: &[Pose],
    pc: &PointCost,
    prior_weight: f64,
) -> Result<f64> {
    let model = base.with_shape_factors(factors)?;
    let costs: Vec<f64> = frames
        .par_iter()
        .zip(poses)
        .map(|(f, pose)| frame_cost(&model, f, pose, pc))
        .collect();
    Ok(costs.iter().sum::<f64>() + prior_cost(factors, prior_weight))
}

/// The dense normal system over [shape factors, pose of frame 0, pose of frame 1, ...]:
/// (cost, H, g).
fn normal_system(
    base: &BodyModel,
    factors: &ShapeFactors,
    frames: &[LabelledFrame],
    poses: &[Pose],
    pc: &PointCost,
    prior_weight: f64,
) -> Result<(f64, DMatrix<f64>, DVector<f64>)> {
    let systems: Vec<FrameSystem> = frames
        .par_iter()
        .zip(poses)
        .map(|(f, pose)| frame_system(base, factors, f, pose, pc))
        .collect::<Result<_>>()?;
    let n = S + P * frames.len();
    let mut h = DMatrix::zeros(n, n);
    let mut g = DVector::zeros(n);
    let mut cost = prior_cost(factors, prior_weight);
    for a in 0..S {
        h[(a, a)] += prior_weight;
        g[a] += prior_weight * (factors[a] - 1.0);
    }
    for (f, sys) in systems.iter().enumerate() {
        let o = S + P * f;
        cost += sys.cost;
        for a in 0..S {
            g[a] += sys.gs[a];
            for b in 0..S {
                h[(a, b)] += sys.hss[a * S + b];
            }
            for b in 0..P {
                h[(a, o + b)] = sys.hsp[a * P + b];
                h[(o + b, a)] = sys.hsp[a * P + b];
            }
        }
        for a in 0..P {
            g[o + a] = sys.gp[a];
            for b in 0..P {
                h[(o + a, o + b)] = sys.hpp[a * P + b];
            }
        }
    }
    Ok((cost, h, g))
}

/// Checks the arguments shared by [`shape_lm`] and [`fit_shape`].
fn check_factors(factors: &ShapeFactors, config: &ShapeConfig) -> Result<()> {
    if let Some(j) = factors
        .iter()
        .position(|f| !(f.is_finite() && (config.lower..=config.upper).contains(f)))
    {
        return Err(Error::invalid(
            "factors",
            format!(
                "{} must be within {}..{}, got {}",
                SHAPE_FACTOR_NAMES[j], config.lower, config.upper, factors[j]
            ),
        ));
    }
    Ok(())
}

/// The shape step: LM over the shape factors and every frame's pose for fixed labels
/// (see the module docs). `factors` and `poses` are updated in place; the cost never
/// increases and the factors stay within the bounds.
pub fn shape_lm(
    base: &BodyModel,
    frames: &[LabelledFrame],
    factors: &mut ShapeFactors,
    poses: &mut [Pose],
    config: &ShapeConfig,
) -> Result<ShapeLmReport> {
    config.validate()?;
    if frames.is_empty() {
        return Err(Error::invalid("frames", "needs at least one frame"));
    }
    if poses.len() != frames.len() {
        return Err(Error::invalid(
            "poses",
            format!("has {} poses for {} frames", poses.len(), frames.len()),
        ));
    }
    for (i, f) in frames.iter().enumerate() {
        if f.points.len() != f.labels.len() {
            return Err(Error::invalid(
                "labels",
                format!(
                    "frame {i} has {} labels for {} points",
                    f.labels.len(),
                    f.points.len()
                ),
            ));
        }
    }
    for (i, p) in poses.iter_mut().enumerate() {
        pose_from_slice(p, &format!("poses[{i}]"))?;
        *p = BodyModel::clamp_pose(p);
    }
    check_factors(factors, config)?;
    let pc = config.point_cost();
    let w = config.prior_weight;
    let n = S + P * frames.len();
    let (plo, phi) = (BodyModel::lower_bounds(), BodyModel::upper_bounds());
    let lower = |i: usize| {
        if i < S {
            config.lower
        } else {
            plo[(i - S) % P]
        }
    };
    let upper = |i: usize| {
        if i < S {
            config.upper
        } else {
            phi[(i - S) % P]
        }
    };
    let value = |f: &ShapeFactors, poses: &[Pose], i: usize| {
        if i < S {
            f[i]
        } else {
            poses[(i - S) / P][(i - S) % P]
        }
    };
    let lm = config.fit.em.lm;
    let (mut cost, mut h, mut g) = normal_system(base, factors, frames, poses, &pc, w)?;
    let initial_cost = cost;
    let mut trace = vec![cost];
    let mut lambda = lm.initial_damping;
    let (mut iterations, mut accepted) = (1, 0);
    let termination = 'outer: loop {
        if cost == 0.0 {
            break ShapeTermination::ZeroCost;
        }
        let mut fixed = vec![false; n];
        let mut gmax = 0.0f64;
        for (i, fx) in fixed.iter_mut().enumerate() {
            let v = value(factors, poses, i);
            let at_lo = v <= lower(i) + BOUND_EPSILON && g[i] > 0.0;
            let at_hi = v >= upper(i) - BOUND_EPSILON && g[i] < 0.0;
            *fx = at_lo || at_hi;
            if !*fx {
                gmax = gmax.max(g[i].abs());
            }
        }
        if gmax <= lm.gradient_tolerance {
            break ShapeTermination::GradientTolerance;
        }
        let dmax = (0..n).map(|i| h[(i, i)]).fold(0.0f64, f64::max);
        let floor = (DIAGONAL_FLOOR_RELATIVE * dmax).max(DIAGONAL_FLOOR_ABSOLUTE);
        loop {
            if lambda > lm.max_damping {
                break 'outer ShapeTermination::DampingLimit;
            }
            let mut a = h.clone();
            let mut rhs = -&g;
            for i in 0..n {
                if fixed[i] {
                    for j in 0..n {
                        a[(i, j)] = 0.0;
                        a[(j, i)] = 0.0;
                    }
                    a[(i, i)] = 1.0;
                    rhs[i] = 0.0;
                } else {
                    a[(i, i)] += lambda * h[(i, i)].max(floor);
                }
            }
            let Some(chol) = a.cholesky() else {
                lambda *= lm.damping_increase;
                continue;
            };
            let delta = chol.solve(&rhs);
            let mut new_factors = *factors;
            for (j, f) in new_factors.iter_mut().enumerate() {
                *f = (*f + delta[j]).clamp(config.lower, config.upper);
            }
            let new_poses: Vec<Pose> = (0..frames.len())
                .map(|f| {
                    let d: [f64; P] = std::array::from_fn(|i| delta[S + P * f + i]);
                    pose_after_step(&poses[f], &d)
                })
                .collect();
            let step = delta.amax();
            let new_cost = total_cost(base, &new_factors, frames, &new_poses, &pc, w)?;
            if new_cost < cost {
                let drop = cost - new_cost;
                *factors = new_factors;
                poses.copy_from_slice(&new_poses);
                cost = new_cost;
                trace.push(cost);
                accepted += 1;
                lambda = (lambda * lm.damping_decrease).max(1e-12);
                if drop <= lm.cost_tolerance * cost.abs() {
                    break 'outer ShapeTermination::CostTolerance;
                }
                if step <= lm.step_tolerance {
                    break 'outer ShapeTermination::StepTolerance;
                }
                break;
            }
            if step <= lm.step_tolerance {
                break 'outer ShapeTermination::StepTolerance;
            }
            lambda *= lm.damping_increase;
        }
        if iterations >= config.lm_iterations {
            break ShapeTermination::MaxIterations;
        }
        iterations += 1;
        let (c, hh, gg) = normal_system(base, factors, frames, poses, &pc, w)?;
        cost = c;
        h = hh;
        g = gg;
    };
    Ok(ShapeLmReport {
        initial_cost,
        cost,
        cost_trace: trace,
        iterations,
        accepted,
        termination,
    })
}

/// One depth frame for [`fit_shape`]: H×W metres (row-major, the camera's size) and an
/// optional person mask (None = every reading).
#[derive(Debug, Clone, Copy)]
pub struct ShapeFrame<'a> {
    pub depth: &'a [f32],
    pub mask: Option<&'a [bool]>,
}

/// Outcome of [`fit_shape`].
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeResult {
    /// The fitted shape factors, relative to the base model.
    pub factors: ShapeFactors,
    /// The base model with the fitted shape.
    pub model: BodyModel,
    /// The fitted pose of every frame.
    pub poses: Vec<Pose>,
    /// The joints of every frame (fitted model and pose), camera frame.
    pub joints: Vec<[Vector3<f64>; NUM_JOINTS]>,
    /// H×W part labels of every frame: segment 0..15, −1 = background or outlier.
    pub labels: Vec<Vec<i16>>,
    /// The final energy E (see the module docs).
    pub energy: f64,
    /// E after every pose/label step and every shape step (non-increasing).
    pub energy_trace: Vec<f64>,
    /// Rounds run.
    pub rounds: usize,
}

/// A frame's cloud, graph and CRF edge weights.
struct FrameData {
    pixels: Vec<u32>,
    points: Vec<[f32; 3]>,
    graph: PixelGraph,
    weights: Vec<f64>,
}

/// E_f at the final outlier distance for a pose and labels (0..=[`OUTLIER`]).
fn frame_energy(
    model: &BodyModel,
    d: &FrameData,
    pose: &Pose,
    labels: &[i32],
    em: &EmConfig,
    unary: &mut Vec<f64>,
) -> f64 {
    unary.resize(d.points.len() * NUM_LABELS, 0.0);
    unary_costs(model, &d.points, pose, em, em.outlier_distance, unary);
    crf_energy(unary, &d.graph.edges, &d.weights, labels)
}

/// Calibrates the body shape on one or several frames (see the module docs): starting
/// from `base` and `init_poses` (one per frame), alternates per-frame pose/label fits
/// with a joint shape-and-pose LM. Deterministic; the energy trace never increases.
pub fn fit_shape(
    frames: &[ShapeFrame],
    camera: &Camera,
    base: &BodyModel,
    init_poses: &[Pose],
    config: &ShapeConfig,
) -> Result<ShapeResult> {
    config.validate()?;
    if frames.is_empty() {
        return Err(Error::invalid("depths", "needs at least one frame"));
    }
    if init_poses.len() != frames.len() {
        return Err(Error::invalid(
            "poses",
            format!(
                "has {} poses for {} depth frames",
                init_poses.len(),
                frames.len()
            ),
        ));
    }
    let em = config.fit.em;
    let mut data = Vec::with_capacity(frames.len());
    for (i, f) in frames.iter().enumerate() {
        let view = DepthView::new(
            f.depth,
            camera.height,
            camera.width,
            &format!("depths[{i}]"),
        )?;
        if let Some(m) = f.mask {
            if m.len() != f.depth.len() {
                return Err(Error::invalid(
                    format!("masks[{i}]"),
                    format!("has {} values for {} pixels", m.len(), f.depth.len()),
                ));
            }
        }
        let cloud = Cloud::from_depth(&view, camera, f.mask)?;
        if cloud.len() < MIN_POINTS {
            return Err(Error::NoBody(format!(
                "frame {i}: the foreground has {} points, at least {MIN_POINTS} are needed",
                cloud.len()
            )));
        }
        let graph = neighbour_graph(&cloud, config.fit.connectivity);
        let mut weights = Vec::new();
        edge_weights(&graph, &em, &mut weights);
        data.push(FrameData {
            pixels: cloud.pixels,
            points: cloud.points,
            graph,
            weights,
        });
    }
    let mut poses = Vec::with_capacity(init_poses.len());
    for (i, p) in init_poses.iter().enumerate() {
        poses.push(BodyModel::clamp_pose(&pose_from_slice(
            p,
            &format!("poses[{i}]"),
        )?));
    }
    let mut factors: ShapeFactors = [1.0; S];
    let mut labels: Vec<Option<Vec<i32>>> = vec![None; frames.len()];
    let mut energies = vec![0.0; frames.len()];
    let mut unary = Vec::new();
    let mut trace = Vec::new();
    let mut rounds = 0;
    let mut energy = f64::INFINITY;
    while rounds < config.rounds {
        rounds += 1;
        let energy_at_start = energy;
        // Pose/label step.
        let model = base.with_shape_factors(&factors)?;
        for (f, d) in data.iter().enumerate() {
            let r = hard_em(&model, &d.points, &d.graph, &poses[f], None, &em)?;
            let new_labels: Vec<i32> = r
                .labels
                .iter()
                .map(|&l| if l < 0 { OUTLIER } else { l })
                .collect();
            let e_new = frame_energy(&model, d, &r.pose, &new_labels, &em, &mut unary);
            let keep_old = match &labels[f] {
                Some(old) => frame_energy(&model, d, &poses[f], old, &em, &mut unary) <= e_new,
                None => false,
            };
            if !keep_old {
                poses[f] = r.pose;
                labels[f] = Some(new_labels);
                energies[f] = e_new;
            }
        }
        energy = energies.iter().sum::<f64>() + prior_cost(&factors, config.prior_weight);
        trace.push(energy);
        // Shape step.
        let lf: Vec<LabelledFrame> = data
            .iter()
            .zip(&labels)
            .map(|(d, l)| LabelledFrame {
                points: &d.points,
                labels: l.as_deref().unwrap_or(&[]),
            })
            .collect();
        shape_lm(base, &lf, &mut factors, &mut poses, config)?;
        let model = base.with_shape_factors(&factors)?;
        for (f, d) in data.iter().enumerate() {
            let l = labels[f].as_deref().unwrap_or(&[]);
            energies[f] = frame_energy(&model, d, &poses[f], l, &em, &mut unary);
        }
        // In exact arithmetic the shape step cannot raise E; guard against round-off.
        energy =
            (energies.iter().sum::<f64>() + prior_cost(&factors, config.prior_weight)).min(energy);
        trace.push(energy);
        if energy_at_start.is_finite()
            && energy_at_start - energy <= config.tolerance * energy.abs()
        {
            break;
        }
    }
    let model = base.with_shape_factors(&factors)?;
    let joints = poses.iter().map(|p| model.joints(p)).collect();
    let images = data
        .iter()
        .zip(&labels)
        .map(|(d, l)| {
            let mut img = vec![-1i16; camera.height * camera.width];
            if let Some(l) = l {
                for (&px, &lab) in d.pixels.iter().zip(l) {
                    img[px as usize] = if lab == OUTLIER { -1 } else { lab as i16 };
                }
            }
            img
        })
        .collect();
    Ok(ShapeResult {
        factors,
        model,
        poses,
        joints,
        labels: images,
        energy,
        energy_trace: trace,
        rounds,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::{param, BodyShape, NUM_SHAPE_PARAMS, SHAPE_FACTOR_GROUPS};
    use crate::fit::terms::Loss;
    use crate::fit::tests::perturbed;

    /// Small deterministic generator in [−1, 1).
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((self.0 >> 11) as f64) / ((1u64 << 52) as f64) - 1.0
        }
    }

    fn truth_factors() -> ShapeFactors {
        let mut f = [1.0; S];
        f[1] = 1.1; // torso width
        f[4] = 0.85; // upper arm
        f[5] = 0.85; // forearm
        f[6] = 1.06; // thigh
        f[8] = 1.08; // shoulder width
        f
    }

    fn poses_for_tests() -> Vec<Pose> {
        let mut a = BodyModel::neutral_pose();
        a[2] = 2.8;
        a[param::ROOT_R + 1] = 0.3;
        a[param::R_SHOULDER] = 0.4;
        a[param::R_SHOULDER + 1] = 0.5;
        a[param::R_ELBOW] = 0.9;
        a[param::L_SHOULDER + 1] = 0.9;
        a[param::L_ELBOW] = 0.4;
        a[param::R_HIP] = 0.3;
        a[param::R_KNEE] = 0.4;
        let mut b = BodyModel::neutral_pose();
        b[2] = 3.0;
        b[param::ROOT_R + 1] = -0.4;
        b[param::R_SHOULDER + 1] = 1.2;
        b[param::R_ELBOW] = 0.3;
        b[param::L_SHOULDER] = 0.8;
        b[param::L_ELBOW] = 1.2;
        b[param::L_HIP] = 0.5;
        b[param::L_KNEE] = 0.8;
        b[param::L_HIP + 1] = 0.2;
        vec![a, b]
    }

    /// Points on every segment's ellipsoid surface (all around), labelled.
    fn surface_points(model: &BodyModel, pose: &Pose, seed: u64) -> (Vec<[f32; 3]>, Vec<i32>) {
        let kin = Kinematics::new(model, pose);
        let placed = model.placed_ellipsoids(&kin);
        let mut rng = Rng(seed);
        let (mut pts, mut labels) = (Vec::new(), Vec::new());
        for (k, e) in placed.iter().enumerate() {
            for _ in 0..150 {
                let u = loop {
                    let u = Vector3::new(rng.next(), rng.next(), rng.next());
                    let n = u.norm();
                    if n > 0.1 && n <= 1.0 {
                        break u / n;
                    }
                };
                let p = e.centre + e.rotation * u.component_mul(e.prepared.radii());
                pts.push([p.x as f32, p.y as f32, p.z as f32]);
                labels.push(k as i32);
            }
        }
        (pts, labels)
    }

    #[test]
    fn factors_scale_their_groups() {
        let base = BodyShape::default();
        assert_eq!(base.scaled(&[1.0; S]).unwrap(), base);
        let mut seen = [0; NUM_SHAPE_PARAMS];
        for g in SHAPE_FACTOR_GROUPS {
            for &i in g {
                seen[i] += 1;
            }
        }
        assert!(seen.iter().all(|&c| c == 1), "{seen:?}");
        let f = truth_factors();
        let s = base.scaled(&f).unwrap();
        assert!((s.upper_arm_length - 0.85 * base.upper_arm_length).abs() < 1e-12);
        assert!((s.chest_radius_x - 1.1 * base.chest_radius_x).abs() < 1e-12);
        assert_eq!(s.thigh_radius, base.thigh_radius);
        assert!(base.scaled(&[1.0; 3]).is_err());
        let mut bad = [1.0; S];
        bad[3] = f64::NAN;
        assert!(base.scaled(&bad).is_err());
        bad[3] = -1.0;
        assert!(base.scaled(&bad).is_err());
    }

    /// The analytic gradient (shape and pose columns) matches central differences of
    /// the cost, for every loss.
    #[test]
    fn gradient_matches_finite_differences() {
        let base = BodyModel::default();
        let truth = base.with_shape_factors(&truth_factors()).unwrap();
        let poses = poses_for_tests();
        let data: Vec<_> = poses
            .iter()
            .enumerate()
            .map(|(i, p)| surface_points(&truth, p, 7 + i as u64))
            .collect();
        let frames: Vec<LabelledFrame> = data
            .iter()
            .map(|(p, l)| LabelledFrame {
                points: p,
                labels: l,
            })
            .collect();
        let factors = [1.02; S];
        for loss in [Loss::Squared, Loss::Huber(0.02), Loss::Cauchy(0.03)] {
            let pc = PointCost {
                sigma: 0.02,
                loss,
                truncation: 0.5,
            };
            let w = 10.0;
            let (c, h, g) = normal_system(&base, &factors, &frames, &poses, &pc, w).unwrap();
            let c2 = total_cost(&base, &factors, &frames, &poses, &pc, w).unwrap();
            assert!((c - c2).abs() <= 1e-9 * c.max(1.0));
            assert!((&h - h.transpose()).amax() == 0.0);
            let eps = 1e-6;
            for j in 0..S {
                let (mut fp, mut fm) = (factors, factors);
                fp[j] += eps;
                fm[j] -= eps;
                let fd = (total_cost(&base, &fp, &frames, &poses, &pc, w).unwrap()
                    - total_cost(&base, &fm, &frames, &poses, &pc, w).unwrap())
                    / (2.0 * eps);
                assert!(
                    (fd - g[j]).abs() <= 1e-4 * fd.abs().max(g[j].abs()).max(1.0),
                    "{loss:?} factor {j}: fd {fd} vs {}",
                    g[j]
                );
            }
            for f in 0..poses.len() {
                for dof in [0, 2, 4, 9, 11, 17] {
                    let mut d = [0.0; P];
                    d[dof] = eps;
                    let mut pp = poses.clone();
                    pp[f] = pose_after_step(&poses[f], &d);
                    let mut pm = poses.clone();
                    d[dof] = -eps;
                    pm[f] = pose_after_step(&poses[f], &d);
                    let fd = (total_cost(&base, &factors, &frames, &pp, &pc, w).unwrap()
                        - total_cost(&base, &factors, &frames, &pm, &pc, w).unwrap())
                        / (2.0 * eps);
                    let gi = g[S + P * f + dof];
                    assert!(
                        (fd - gi).abs() <= 1e-4 * fd.abs().max(gi.abs()).max(1.0),
                        "{loss:?} frame {f} dof {dof}: fd {fd} vs {gi}"
                    );
                }
            }
        }
    }

    /// On exact surface points of a body with known factors, the joint LM from the base
    /// shape and perturbed poses recovers every factor within 1 %; the cost trace
    /// strictly decreases and the factors stay within the bounds.
    #[test]
    fn shape_lm_recovers_factors_from_surface_points() {
        let base = BodyModel::default();
        let f_true = truth_factors();
        let truth = base.with_shape_factors(&f_true).unwrap();
        let true_poses = poses_for_tests();
        let data: Vec<_> = true_poses
            .iter()
            .enumerate()
            .map(|(i, p)| surface_points(&truth, p, 3 + i as u64))
            .collect();
        let frames: Vec<LabelledFrame> = data
            .iter()
            .map(|(p, l)| LabelledFrame {
                points: p,
                labels: l,
            })
            .collect();
        let mut poses: Vec<Pose> = true_poses
            .iter()
            .enumerate()
            .map(|(i, p)| perturbed(p, 11 + i as u64, 0.05, 0.02))
            .collect();
        let mut factors = [1.0; S];
        let config = ShapeConfig {
            prior_weight: 0.0,
            lm_iterations: 50,
            ..ShapeConfig::default()
        };
        let r = shape_lm(&base, &frames, &mut factors, &mut poses, &config).unwrap();
        assert!(r.cost_trace.windows(2).all(|w| w[1] < w[0]), "{r:?}");
        assert!(r.cost < 1e-3 * r.initial_cost, "{r:?}");
        for j in 0..S {
            assert!(
                (factors[j] - f_true[j]).abs() < 0.01,
                "{}: {} vs {}",
                SHAPE_FACTOR_NAMES[j],
                factors[j],
                f_true[j]
            );
        }
        // Bounds hold even when the truth lies outside them.
        let mut tight = [1.0; S];
        let cfg = ShapeConfig {
            lower: 0.95,
            upper: 1.05,
            prior_weight: 0.0,
            ..ShapeConfig::default()
        };
        let mut poses2 = true_poses.clone();
        let r = shape_lm(&base, &frames, &mut tight, &mut poses2, &cfg).unwrap();
        assert!(tight.iter().all(|f| (0.95..=1.05).contains(f)), "{tight:?}");
        assert!((tight[4] - 0.95).abs() < 1e-12 && (tight[1] - 1.05).abs() < 1e-12);
        assert!(r.cost_trace.windows(2).all(|w| w[1] < w[0]));
    }

    /// Depth rendered from a body with arms 15 % shorter, a 10 % wider torso, longer
    /// thighs and wider shoulders, fitted from the base model: the factors the front
    /// views observe come back within a few percent, the joints of the fitted model
    /// are closer to the truth than those of a pose-only fit, and E never increases.
    #[test]
    fn fit_shape_recovers_shape_from_rendered_depth() {
        let base = BodyModel::default();
        let f_true = truth_factors();
        let truth = base.with_shape_factors(&f_true).unwrap();
        let cam = Camera::itop();
        let true_poses = poses_for_tests();
        let depths: Vec<Vec<f32>> = true_poses
            .iter()
            .map(|p| truth.render_depth(p, &cam).0)
            .collect();
        let frames: Vec<ShapeFrame> = depths
            .iter()
            .map(|d| ShapeFrame {
                depth: d,
                mask: None,
            })
            .collect();
        let init: Vec<Pose> = true_poses
            .iter()
            .enumerate()
            .map(|(i, p)| perturbed(p, 21 + i as u64, 0.05, 0.03))
            .collect();
        // The data are the model's own ellipsoids: a weak prior (the default is tuned
        // for real bodies, whose surfaces the ellipsoids only approximate).
        let config = ShapeConfig {
            prior_weight: 1e3,
            ..ShapeConfig::default()
        };
        let r = fit_shape(&frames, &cam, &base, &init, &config).unwrap();
        assert!(
            r.energy_trace.windows(2).all(|w| w[1] <= w[0]),
            "{:?}",
            r.energy_trace
        );
        for j in [1, 4, 5, 6, 8] {
            assert!(
                (r.factors[j] - f_true[j]).abs() < 0.04,
                "{}: {} vs {} ({:?})",
                SHAPE_FACTOR_NAMES[j],
                r.factors[j],
                f_true[j],
                r.factors
            );
        }
        for f in r.factors {
            assert!((0.7..=1.4).contains(&f));
        }
        // Joint error: pose fit with the base model vs the calibrated one.
        let mean_err = |model: &BodyModel, pose: &Pose, truth_pose: &Pose| {
            let (a, b) = (model.joints(pose), truth.joints(truth_pose));
            (0..NUM_JOINTS).map(|j| (a[j] - b[j]).norm()).sum::<f64>() / NUM_JOINTS as f64
        };
        let (mut e_base, mut e_fit) = (0.0, 0.0);
        for (f, d) in depths.iter().enumerate() {
            let cfg = FitConfig::default();
            let a = super::super::fit_pose(d, &cam, &init[f], &base, None, None, &cfg).unwrap();
            let b = super::super::fit_pose(d, &cam, &init[f], &r.model, None, None, &cfg).unwrap();
            e_base += mean_err(&base, &a.pose, &true_poses[f]);
            e_fit += mean_err(&r.model, &b.pose, &true_poses[f]);
        }
        assert!(e_fit < 0.5 * e_base, "base {e_base} vs fitted {e_fit}");
        // Deterministic.
        let r2 = fit_shape(&frames, &cam, &base, &init, &config).unwrap();
        assert_eq!(r.factors, r2.factors);
    }

    #[test]
    fn bad_input_is_rejected() {
        let base = BodyModel::default();
        let cam = Camera::itop();
        let depth = vec![0.0f32; cam.width * cam.height];
        let pose = BodyModel::neutral_pose();
        let frame = ShapeFrame {
            depth: &depth,
            mask: None,
        };
        let cfg = ShapeConfig::default();
        assert!(matches!(
            fit_shape(&[], &cam, &base, &[], &cfg),
            Err(Error::InvalidArgument { .. })
        ));
        assert!(matches!(
            fit_shape(&[frame], &cam, &base, &[pose, pose], &cfg),
            Err(Error::InvalidArgument { .. })
        ));
        let mut nan = pose;
        nan[7] = f64::NAN;
        let (d2, _) = base.render_depth(&pose, &cam);
        let f2 = ShapeFrame {
            depth: &d2,
            mask: None,
        };
        assert!(matches!(
            fit_shape(&[f2], &cam, &base, &[nan], &cfg),
            Err(Error::InvalidArgument { .. })
        ));
        assert!(matches!(
            fit_shape(&[frame], &cam, &base, &[pose], &cfg),
            Err(Error::NoBody(_))
        ));
        let short = vec![0.0f32; 10];
        let f3 = ShapeFrame {
            depth: &short,
            mask: None,
        };
        assert!(fit_shape(&[f3], &cam, &base, &[pose], &cfg).is_err());
        let mask = vec![true; 3];
        let f4 = ShapeFrame {
            depth: &d2,
            mask: Some(&mask),
        };
        assert!(fit_shape(&[f4], &cam, &base, &[pose], &cfg).is_err());
        for bad in [
            ShapeConfig { rounds: 0, ..cfg },
            ShapeConfig { lower: 1.2, ..cfg },
            ShapeConfig { upper: 0.9, ..cfg },
            ShapeConfig {
                prior_weight: -1.0,
                ..cfg
            },
        ] {
            assert!(fit_shape(&[f2], &cam, &base, &[pose], &bad).is_err());
        }
        let mut out_of_bounds = [1.0; S];
        out_of_bounds[2] = 2.0;
        let mut poses = [pose];
        let (pts, labels) = (vec![[0.0f32; 3]; 4], vec![0i32; 3]);
        let lf = LabelledFrame {
            points: &pts,
            labels: &labels,
        };
        assert!(shape_lm(&base, &[lf], &mut [1.0; S], &mut poses, &cfg).is_err());
        let labels = vec![0i32; 4];
        let lf = LabelledFrame {
            points: &pts,
            labels: &labels,
        };
        assert!(shape_lm(&base, &[lf], &mut out_of_bounds, &mut poses, &cfg).is_err());
    }
}
