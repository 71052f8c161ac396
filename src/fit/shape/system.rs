//! The shape step's cost and normal equations over the shape factors and every
//! frame's pose.

use crate::body::kinematics::SEGMENT_DOFS;
use crate::body::{
    BodyModel, Kinematics, Pose, ShapeFactors, NUM_PARAMS, NUM_SEGMENTS, NUM_SHAPE_FACTORS,
};
use crate::error::Result;
use crate::fit::terms::PointCost;
use nalgebra::{DMatrix, DVector, Vector3};
use rayon::prelude::*;

/// Number of shape factors (alias for the pose-style name).
pub(super) const S: usize = NUM_SHAPE_FACTORS;
/// Pose parameters per frame.
pub(super) const P: usize = NUM_PARAMS;
/// Central-difference step of the (linear) placed-ellipsoid geometry in the factors.
pub(super) const GEOMETRY_STEP: f64 = 0.05;

/// One frame of labelled points for [`shape_lm`](super::shape_lm): labels 0..[`NUM_SEGMENTS`] are
/// segments, anything else (−1, the EM's outlier label) is skipped.
#[derive(Debug, Clone, Copy)]
pub struct LabelledFrame<'a> {
    pub points: &'a [[f32; 3]],
    pub labels: &'a [i32],
}

/// ½·w·Σ(s − 1)².
pub(super) fn prior_cost(factors: &ShapeFactors, w: f64) -> f64 {
    0.5 * w * factors.iter().map(|f| (f - 1.0) * (f - 1.0)).sum::<f64>()
}

#[inline]
pub(super) fn vec3(p: &[f32; 3]) -> Vector3<f64> {
    Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64)
}

#[inline]
pub(super) fn cost_and_weight(pc: &PointCost, r: f64) -> (f64, f64) {
    let s2 = pc.sigma * pc.sigma;
    if r.abs() > pc.truncation {
        (pc.cap(), 0.0)
    } else {
        (pc.loss.rho(r) / s2, pc.loss.weight(r) / s2)
    }
}

/// The data cost of one frame: Σ over labelled points of ρ(min(|d|, T))/σ².
pub(super) fn frame_cost(
    model: &BodyModel,
    frame: &LabelledFrame,
    pose: &Pose,
    pc: &PointCost,
) -> f64 {
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
pub(super) struct FrameSystem {
    pub(super) hss: [f64; S * S],
    pub(super) hsp: [f64; S * P],
    pub(super) hpp: [f64; P * P],
    pub(super) gs: [f64; S],
    pub(super) gp: [f64; P],
    pub(super) cost: f64,
}

pub(super) fn frame_system(
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
pub(super) fn total_cost(
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
pub(super) fn normal_system(
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
