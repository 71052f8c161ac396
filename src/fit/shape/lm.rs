//! The shape step: Levenberg–Marquardt over the shape factors and every frame's pose
//! for fixed labels.

use super::config::ShapeConfig;
use super::system::{normal_system, total_cost, LabelledFrame, P, S};
use crate::body::{pose_from_slice, BodyModel, Pose, ShapeFactors, SHAPE_FACTOR_NAMES};
use crate::error::{Error, Result};
use crate::fit::lm::pose_after_step;
use crate::fit::lm::Termination as ShapeTermination;

/// Relative and absolute floors of the damping diagonal (as in [`crate::fit::lm`]).
pub(super) const DIAGONAL_FLOOR_RELATIVE: f64 = 1e-6;
pub(super) const DIAGONAL_FLOOR_ABSOLUTE: f64 = 1e-12;
/// A parameter within this distance of a bound counts as on it.
pub(super) const BOUND_EPSILON: f64 = 1e-12;

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

/// Checks the arguments shared by [`shape_lm`] and [`fit_shape`].
pub(super) fn check_factors(factors: &ShapeFactors, config: &ShapeConfig) -> Result<()> {
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
