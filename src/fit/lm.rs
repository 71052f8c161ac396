//! Levenberg–Marquardt over the 22 pose parameters, with joint limits.
//!
//! An objective ([`PoseObjective`]) supplies its cost and its Gauss–Newton system at a
//! pose: H = JᵀWJ and g = JᵀWr (the cost's gradient), root-rotation columns with respect
//! to the body-frame increment ω (see [`crate::body`]). Each iteration solves
//! (H + λ·D) δ = −g with D = diag(H) (floored so that parameters no point constrains
//! stay put) by an in-place faer Cholesky in preallocated storage, applies δ (rotation
//! increment composed on the right, joint angles clamped into their limits) and keeps it
//! only if the cost drops; otherwise λ grows tenfold and the system is solved again
//! without being rebuilt, until the step is at most 0.9 of the rejected one's length
//! (a larger λ that barely shortens the step would only evaluate the same trial
//! again). Parameters sitting on a bound with the gradient pushing them outward
//! are held fixed for the step (a projected / active-set LM), so a joint at its limit
//! does not block the others. The cost therefore never increases.

use crate::body::{pose_with_root_increment, BodyModel, Pose};
use crate::error::{ensure, Result};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt;
use faer::{Mat, Par};
use nalgebra::Vector3;
use std::sync::atomic::{AtomicBool, Ordering as AtomicOrdering};

pub use super::system::{PoseObjective, N, NN};

/// Relative floor of the damping diagonal (times the largest diagonal entry).
const DIAGONAL_FLOOR_RELATIVE: f64 = 1e-6;
/// Absolute floor of the damping diagonal.
const DIAGONAL_FLOOR_ABSOLUTE: f64 = 1e-12;
/// A parameter within this distance of a bound counts as on it.
const BOUND_EPSILON: f64 = 1e-12;
/// After a rejected step the next trial's length (in the damping metric) is at most
/// this fraction of the rejected one's: a step within 10 % of a rejected step's length
/// is, while λ·D is still small beside H, nearly the same trial, and not worth a cost
/// evaluation. (Shorter bounds save more evaluations but skip steps that would have
/// been kept, and cost tracking accuracy: docs/design.md.)
const REJECTED_STEP_SHRINK: f64 = 0.9;

/// Settings of [`LevenbergMarquardt`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmConfig {
    /// λ at the first iteration (relative to diag(JᵀJ)).
    pub initial_damping: f64,
    /// After a rejected step λ is multiplied by this (> 1), repeatedly, until the
    /// damped step is at most 0.9 of the rejected one's length (scaled by the damping
    /// diagonal): the system is solved again for each λ, the cost evaluated only for
    /// the last.
    pub damping_increase: f64,
    /// λ is multiplied by this after an accepted step (in (0, 1)).
    pub damping_decrease: f64,
    /// Give up when λ exceeds this (no step lowers the cost).
    pub max_damping: f64,
    /// Stop when an accepted step lowers the cost by less than this fraction.
    pub cost_tolerance: f64,
    /// Stop when the step's largest component is below this (m or rad).
    pub step_tolerance: f64,
    /// Stop when the largest gradient component of the free parameters is below this.
    pub gradient_tolerance: f64,
    /// At most this many iterations (each builds one normal system).
    pub max_iterations: usize,
}

impl Default for LmConfig {
    fn default() -> Self {
        LmConfig {
            initial_damping: 1e-3,
            damping_increase: 10.0,
            damping_decrease: 0.3,
            max_damping: 1e10,
            cost_tolerance: 1e-6,
            step_tolerance: 1e-7,
            gradient_tolerance: 1e-10,
            max_iterations: 20,
        }
    }
}

impl LmConfig {
    /// Checks every field, naming the bad one.
    pub fn validate(&self) -> Result<()> {
        let pos = |v: f64| v.is_finite() && v > 0.0;
        let nonneg = |v: f64| v.is_finite() && v >= 0.0;
        ensure(pos(self.initial_damping), "initial_damping", || {
            format!("must be finite and > 0, got {}", self.initial_damping)
        })?;
        ensure(
            self.damping_increase.is_finite() && self.damping_increase > 1.0,
            "damping_increase",
            || format!("must be > 1, got {}", self.damping_increase),
        )?;
        ensure(
            self.damping_decrease > 0.0 && self.damping_decrease < 1.0,
            "damping_decrease",
            || format!("must be in (0, 1), got {}", self.damping_decrease),
        )?;
        ensure(
            pos(self.max_damping) && self.max_damping > self.initial_damping,
            "max_damping",
            || {
                format!(
                    "must be finite and > initial_damping, got {}",
                    self.max_damping
                )
            },
        )?;
        ensure(nonneg(self.cost_tolerance), "cost_tolerance", || {
            format!("must be finite and >= 0, got {}", self.cost_tolerance)
        })?;
        ensure(nonneg(self.step_tolerance), "step_tolerance", || {
            format!("must be finite and >= 0, got {}", self.step_tolerance)
        })?;
        ensure(
            nonneg(self.gradient_tolerance),
            "gradient_tolerance",
            || format!("must be finite and >= 0, got {}", self.gradient_tolerance),
        )?;
        ensure(self.max_iterations > 0, "max_iterations", || {
            "must be at least 1".to_string()
        })
    }
}

/// Why the solver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Termination {
    /// The relative cost decrease of an accepted step fell below `cost_tolerance`.
    CostTolerance,
    /// The step fell below `step_tolerance`.
    StepTolerance,
    /// The gradient fell below `gradient_tolerance` (a stationary point).
    GradientTolerance,
    /// The cost is exactly zero.
    ZeroCost,
    /// `max_iterations` reached.
    MaxIterations,
    /// λ exceeded `max_damping`: no step along the damped direction lowers the cost.
    DampingLimit,
}

impl Termination {
    /// A short lower-case name (used by the Python layer).
    pub fn name(self) -> &'static str {
        match self {
            Termination::CostTolerance => "cost_tolerance",
            Termination::StepTolerance => "step_tolerance",
            Termination::GradientTolerance => "gradient_tolerance",
            Termination::ZeroCost => "zero_cost",
            Termination::MaxIterations => "max_iterations",
            Termination::DampingLimit => "damping_limit",
        }
    }

    /// Whether this is a convergence (rather than a budget or failure) stop.
    pub fn converged(self) -> bool {
        !matches!(self, Termination::MaxIterations | Termination::DampingLimit)
    }
}

/// Outcome of a solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmReport {
    pub initial_cost: f64,
    pub cost: f64,
    /// Normal systems built.
    pub iterations: usize,
    /// Steps accepted.
    pub accepted: usize,
    pub termination: Termination,
}

/// `pose` moved by the LM step `delta` (root rotation via the body-frame increment) and
/// clamped into the joint limits.
pub fn pose_after_step(pose: &Pose, delta: &[f64; N]) -> Pose {
    let omega = Vector3::new(delta[3], delta[4], delta[5]);
    let mut p = pose_with_root_increment(pose, &omega);
    for i in 0..N {
        if !(3..6).contains(&i) {
            p[i] += delta[i];
        }
    }
    BodyModel::clamp_pose(&p)
}

/// Reusable LM solver: all storage is allocated once here.
pub struct LevenbergMarquardt {
    pub config: LmConfig,
    h: Box<[f64; NN]>,
    g: Box<[f64; N]>,
    a: Mat<f64>,
    rhs: Mat<f64>,
    scratch: MemBuffer,
    lower: Pose,
    upper: Pose,
}

impl LevenbergMarquardt {
    /// A solver with `config` (validated).
    pub fn new(config: LmConfig) -> Result<Self> {
        config.validate()?;
        let req = llt::factor::cholesky_in_place_scratch::<f64>(N, Par::Seq, Default::default())
            .or(llt::solve::solve_in_place_scratch::<f64>(N, 1, Par::Seq));
        Ok(LevenbergMarquardt {
            config,
            h: Box::new([0.0; NN]),
            g: Box::new([0.0; N]),
            a: Mat::zeros(N, N),
            rhs: Mat::zeros(N, 1),
            scratch: MemBuffer::new(req),
            lower: BodyModel::lower_bounds(),
            upper: BodyModel::upper_bounds(),
        })
    }

    /// Minimises `objective` from `pose` (clamped into the limits first); `pose` is
    /// updated in place.
    pub fn minimize<O: PoseObjective>(&mut self, objective: &mut O, pose: &mut Pose) -> LmReport {
        let never = AtomicBool::new(false);
        self.minimize_unless(objective, pose, &never)
            .expect("the flag is never raised")
    }

    /// [`Self::minimize`], abandoned (`None`, `pose` then part-way) once `abandon` is
    /// raised: checked before each new normal system (the first included), so another
    /// thread can stop a minimisation whose result it knows will not be used.
    pub fn minimize_unless<O: PoseObjective>(
        &mut self,
        objective: &mut O,
        pose: &mut Pose,
        abandon: &AtomicBool,
    ) -> Option<LmReport> {
        let cfg = self.config;
        *pose = BodyModel::clamp_pose(pose);
        if abandon.load(AtomicOrdering::Relaxed) {
            return None;
        }
        let mut lambda = cfg.initial_damping;
        let mut cost = objective.normal_equations(pose, &mut self.h, &mut self.g);
        let initial_cost = cost;
        let (mut iterations, mut accepted) = (1, 0);
        let mut fixed = [false; N];
        let termination = 'outer: loop {
            if cost == 0.0 {
                break Termination::ZeroCost;
            }
            // Active set: parameters on a bound whose descent direction leaves the box.
            let mut gmax = 0.0f64;
            for i in 0..N {
                let at_lo = pose[i] <= self.lower[i] + BOUND_EPSILON && self.g[i] > 0.0;
                let at_hi = pose[i] >= self.upper[i] - BOUND_EPSILON && self.g[i] < 0.0;
                fixed[i] = at_lo || at_hi;
                if !fixed[i] {
                    gmax = gmax.max(self.g[i].abs());
                }
            }
            if gmax <= cfg.gradient_tolerance {
                break Termination::GradientTolerance;
            }
            let dmax = (0..N).map(|i| self.h[i * N + i]).fold(0.0, f64::max);
            let floor = DIAGONAL_FLOOR_RELATIVE * dmax + DIAGONAL_FLOOR_ABSOLUTE;
            // Inner loop: raise λ until a step lowers the cost.
            let mut delta = [0.0; N];
            let mut solved = self.solve_damped(lambda, floor, &fixed, &mut delta);
            loop {
                // The (scaled) length the next trial must not exceed: after a rejected
                // trial, 0.9 of its length (while λ·D is small beside H a tenfold λ
                // barely shortens the step; those near-copies of the rejected trial are
                // solved but not evaluated); none after a failed solve.
                let mut target = f64::INFINITY;
                if solved {
                    let trial = pose_after_step(pose, &delta);
                    let step = (0..N).map(|i| delta[i].abs()).fold(0.0, f64::max);
                    let new_cost = objective.cost(&trial);
                    if new_cost.is_finite() && new_cost < cost {
                        let decrease = cost - new_cost;
                        *pose = trial;
                        accepted += 1;
                        lambda = (lambda * cfg.damping_decrease).max(f64::MIN_POSITIVE);
                        if decrease <= cfg.cost_tolerance * cost {
                            cost = new_cost;
                            break 'outer Termination::CostTolerance;
                        }
                        if step <= cfg.step_tolerance {
                            cost = new_cost;
                            break 'outer Termination::StepTolerance;
                        }
                        if iterations >= cfg.max_iterations {
                            cost = new_cost;
                            break 'outer Termination::MaxIterations;
                        }
                        if abandon.load(AtomicOrdering::Relaxed) {
                            return None;
                        }
                        cost = objective.normal_equations(pose, &mut self.h, &mut self.g);
                        iterations += 1;
                        break;
                    }
                    if step <= cfg.step_tolerance {
                        break 'outer Termination::StepTolerance;
                    }
                    target = REJECTED_STEP_SHRINK * self.scaled_length(&delta, floor);
                }
                loop {
                    lambda *= cfg.damping_increase;
                    if lambda > cfg.max_damping {
                        break 'outer Termination::DampingLimit;
                    }
                    solved = self.solve_damped(lambda, floor, &fixed, &mut delta);
                    if solved && self.scaled_length(&delta, floor) <= target {
                        break;
                    }
                }
            }
        };
        Some(LmReport {
            initial_cost,
            cost,
            iterations,
            accepted,
            termination,
        })
    }

    /// The length of `delta` in the metric of the damping, √(Σ max(H_ii, floor)·δ_i²):
    /// a step's size in units each parameter's curvature makes comparable.
    fn scaled_length(&self, delta: &[f64; N], floor: f64) -> f64 {
        (0..N)
            .map(|i| self.h[i * N + i].max(floor) * delta[i] * delta[i])
            .sum::<f64>()
            .sqrt()
    }

    /// Solves (H + λ·max(diag H, floor)) δ = −g with fixed parameters pinned to δ = 0.
    /// Returns false if the factorisation fails.
    fn solve_damped(
        &mut self,
        lambda: f64,
        floor: f64,
        fixed: &[bool; N],
        delta: &mut [f64; N],
    ) -> bool {
        for i in 0..N {
            for j in 0..N {
                let v = if fixed[i] || fixed[j] {
                    if i == j {
                        1.0
                    } else {
                        0.0
                    }
                } else {
                    let mut v = self.h[i * N + j];
                    if i == j {
                        v += lambda * v.max(floor);
                    }
                    v
                };
                self.a[(i, j)] = v;
            }
            self.rhs[(i, 0)] = if fixed[i] { 0.0 } else { -self.g[i] };
        }
        let stack = MemStack::new(&mut self.scratch);
        if llt::factor::cholesky_in_place(
            self.a.as_mut(),
            Default::default(),
            Par::Seq,
            stack,
            Default::default(),
        )
        .is_err()
        {
            return false;
        }
        let stack = MemStack::new(&mut self.scratch);
        llt::solve::solve_in_place(self.a.as_ref(), self.rhs.as_mut(), Par::Seq, stack);
        for (i, d) in delta.iter_mut().enumerate() {
            *d = self.rhs[(i, 0)];
        }
        delta.iter().all(|d| d.is_finite())
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // parallel arrays indexed together
mod tests {
    use super::*;
    use crate::body::root_rotation;
    use crate::fit::terms::{PosePrior, WithPrior};

    /// A quadratic bowl with a non-diagonal Hessian: cost ½ (θ − c)ᵀ A (θ − c) on the
    /// non-rotation parameters, minimum at c (inside the limits).
    struct Bowl {
        a: [f64; NN],
        c: Pose,
        evaluations: usize,
    }

    impl Bowl {
        fn new() -> Self {
            let mut a = [0.0; NN];
            for i in 0..N {
                a[i * N + i] = 2.0 + i as f64 * 0.1;
                if i + 1 < N {
                    a[i * N + i + 1] = 0.5;
                    a[(i + 1) * N + i] = 0.5;
                }
            }
            for i in 3..6 {
                for j in 0..N {
                    a[i * N + j] = if i == j { 1.0 } else { 0.0 };
                    a[j * N + i] = if i == j { 1.0 } else { 0.0 };
                }
            }
            let mut c = BodyModel::neutral_pose();
            c[param_index("r_elbow_flexion")] = 1.0;
            c[0] = 0.2;
            Bowl {
                a,
                c,
                evaluations: 0,
            }
        }
        fn diff(&self, pose: &Pose) -> [f64; N] {
            let mut d = [0.0; N];
            for i in 0..N {
                d[i] = if (3..6).contains(&i) {
                    0.0
                } else {
                    pose[i] - self.c[i]
                };
            }
            d
        }
    }

    fn param_index(name: &str) -> usize {
        crate::body::PARAM_NAMES
            .iter()
            .position(|n| *n == name)
            .unwrap()
    }

    impl PoseObjective for Bowl {
        fn cost(&mut self, pose: &Pose) -> f64 {
            self.evaluations += 1;
            let d = self.diff(pose);
            let mut c = 0.0;
            for i in 0..N {
                for j in 0..N {
                    c += 0.5 * d[i] * self.a[i * N + j] * d[j];
                }
            }
            c
        }
        fn normal_equations(&mut self, pose: &Pose, h: &mut [f64; NN], g: &mut [f64; N]) -> f64 {
            let d = self.diff(pose);
            h.copy_from_slice(&self.a);
            for i in 0..N {
                g[i] = (0..N).map(|j| self.a[i * N + j] * d[j]).sum();
                if (3..6).contains(&i) {
                    g[i] = 0.0;
                }
            }
            self.cost(pose)
        }
    }

    #[test]
    fn solves_a_quadratic_in_few_iterations() {
        let mut bowl = Bowl::new();
        let mut lm = LevenbergMarquardt::new(LmConfig::default()).unwrap();
        let mut pose = BodyModel::neutral_pose();
        let report = lm.minimize(&mut bowl, &mut pose);
        assert!(report.cost < 1e-12, "{report:?}");
        assert!(report.termination.converged(), "{report:?}");
        for i in 0..N {
            if !(3..6).contains(&i) {
                assert!((pose[i] - bowl.c[i]).abs() < 1e-6, "param {i}");
            }
        }
    }

    #[test]
    fn respects_limits_and_keeps_cost_monotone() {
        let mut bowl = Bowl::new();
        // Minimum outside the elbow's limits: the solution sits on the bound.
        let e = param_index("l_elbow_flexion");
        bowl.c[e] = -0.5;
        let tight = LmConfig {
            cost_tolerance: 1e-15,
            max_iterations: 100,
            ..LmConfig::default()
        };
        let mut lm = LevenbergMarquardt::new(tight).unwrap();
        let mut pose = BodyModel::neutral_pose();
        let report = lm.minimize(&mut bowl, &mut pose);
        assert!(report.cost <= report.initial_cost);
        assert_eq!(pose[e], 0.0);
        let (lo, hi) = (BodyModel::lower_bounds(), BodyModel::upper_bounds());
        assert!((0..N).all(|i| pose[i] >= lo[i] && pose[i] <= hi[i]));
        // The other parameters still reach their (coupled) optimum: the gradient of the
        // free parameters vanishes.
        let (mut h, mut g) = ([0.0; NN], [0.0; N]);
        bowl.normal_equations(&pose, &mut h, &mut g);
        // (On a bound the gradient may only point out of the box.)
        for i in 0..N {
            if pose[i] <= lo[i] {
                assert!(g[i] > -1e-6, "param {i}: gradient {}", g[i]);
            } else if pose[i] >= hi[i] {
                assert!(g[i] < 1e-6, "param {i}: gradient {}", g[i]);
            } else {
                assert!(g[i].abs() < 1e-6, "param {i}: gradient {}", g[i]);
            }
        }
    }

    /// The bowl, raising `flag` while it builds its `at`-th normal system.
    struct RaiseAt<'a> {
        bowl: Bowl,
        systems: usize,
        at: usize,
        flag: &'a AtomicBool,
    }

    impl PoseObjective for RaiseAt<'_> {
        fn cost(&mut self, pose: &Pose) -> f64 {
            self.bowl.cost(pose)
        }
        fn normal_equations(&mut self, pose: &Pose, h: &mut [f64; NN], g: &mut [f64; N]) -> f64 {
            self.systems += 1;
            if self.systems == self.at {
                self.flag.store(true, AtomicOrdering::Relaxed);
            }
            self.bowl.normal_equations(pose, h, g)
        }
    }

    #[test]
    fn a_raised_flag_abandons_the_minimisation() {
        let tight = LmConfig {
            cost_tolerance: 1e-15,
            max_iterations: 100,
            ..LmConfig::default()
        };
        let run = |at: usize| {
            let flag = AtomicBool::new(false);
            let mut objective = RaiseAt {
                bowl: Bowl::new(),
                systems: 0,
                at,
                flag: &flag,
            };
            let mut lm = LevenbergMarquardt::new(tight).unwrap();
            let mut pose = BodyModel::neutral_pose();
            let report = lm.minimize_unless(&mut objective, &mut pose, &flag);
            (report, pose, objective.systems)
        };
        // Never raised: the same as `minimize`, over several normal systems.
        let (report, pose, systems) = run(usize::MAX);
        let mut plain_pose = BodyModel::neutral_pose();
        let mut lm = LevenbergMarquardt::new(tight).unwrap();
        let plain = lm.minimize(&mut Bowl::new(), &mut plain_pose);
        assert_eq!((report, pose), (Some(plain), plain_pose));
        assert!(systems >= 4, "{systems} normal systems");
        // Raised while building the k-th system: no further system is built.
        for at in 1..systems {
            let (report, _, built) = run(at);
            assert_eq!((report, built), (None, at));
        }
        // Raised before the start: no system at all.
        let raised = AtomicBool::new(true);
        let mut bowl = Bowl::new();
        let mut pose = BodyModel::neutral_pose();
        let mut lm = LevenbergMarquardt::new(tight).unwrap();
        assert_eq!(lm.minimize_unless(&mut bowl, &mut pose, &raised), None);
        assert_eq!(pose, BodyModel::neutral_pose());
        assert_eq!(bowl.evaluations, 0);
    }

    /// ½·atan(θ₀ − c)² in the root's x: far from c the Gauss–Newton step overshoots by
    /// a factor 1 + (θ₀ − c)². Records every trial.
    struct Saturating {
        c: f64,
        trials: Vec<(f64, f64)>,
    }

    impl PoseObjective for Saturating {
        fn cost(&mut self, pose: &Pose) -> f64 {
            let cost = 0.5 * (pose[0] - self.c).atan().powi(2);
            self.trials.push((pose[0], cost));
            cost
        }
        fn normal_equations(&mut self, pose: &Pose, h: &mut [f64; NN], g: &mut [f64; N]) -> f64 {
            let x = pose[0] - self.c;
            let (r, j) = (x.atan(), 1.0 / (1.0 + x * x));
            h.fill(0.0);
            g.fill(0.0);
            h[0] = j * j;
            g[0] = j * r;
            0.5 * r * r
        }
    }

    #[test]
    fn a_trial_nearly_the_rejected_one_is_not_evaluated() {
        let config = LmConfig {
            cost_tolerance: 1e-12,
            max_iterations: 100,
            ..LmConfig::default()
        };
        let mut lm = LevenbergMarquardt::new(config).unwrap();
        let c = 0.2;
        let mut objective = Saturating {
            c,
            trials: Vec::new(),
        };
        let mut pose = BodyModel::neutral_pose();
        pose[0] = c + 3.0;
        let start_cost = 0.5 * 3.0f64.atan().powi(2);
        let report = lm.minimize(&mut objective, &mut pose);
        assert!(report.termination.converged(), "{report:?}");
        assert!((pose[0] - c).abs() < 1e-5, "ended at {}", pose[0]);
        // Replay the trials: the kept pose's cost never rises, and after a rejected
        // trial the next one lies within 0.9 of its distance (one parameter: the
        // scaled length is the distance times a constant).
        let (mut at, mut cost) = (c + 3.0, start_cost);
        let mut rejected = 0;
        let mut last_rejected: Option<f64> = None;
        for &(x, trial_cost) in &objective.trials {
            if let Some(length) = last_rejected {
                assert!((x - at).abs() <= 0.9 * length, "{x} after {length}");
            }
            if trial_cost < cost {
                (at, cost) = (x, trial_cost);
                last_rejected = None;
            } else {
                rejected += 1;
                last_rejected = Some((x - at).abs());
            }
        }
        assert_eq!(pose[0], at);
        assert!(rejected > 0, "no step overshot: the test tests nothing");
        // The first step overshoots to c − 9.5; λ·10, λ·100 and λ·1000 still
        // overshoot, λ·10⁴ is kept: five evaluations for the first iteration with λ
        // growing tenfold per evaluation. λ·10 and λ·100 shorten the step by 1 % and
        // 9 %, so they are not evaluated: three evaluations (λ, λ·1000, λ·10⁴).
        let first_kept = objective
            .trials
            .iter()
            .position(|&(_, cost)| cost < start_cost)
            .unwrap();
        assert_eq!(first_kept + 1, 3, "{:?}", objective.trials);
    }

    #[test]
    fn prior_pulls_toward_its_pose() {
        let mut bowl = Bowl::new();
        let mut prior_pose = bowl.c;
        prior_pose[0] = 0.6;
        prior_pose[4] = 0.3;
        let prior = PosePrior::uniform(prior_pose, 1e6, 1e6);
        let mut obj = WithPrior {
            objective: &mut bowl,
            prior: Some(&prior),
            free_space: None,
        };
        let mut lm = LevenbergMarquardt::new(LmConfig::default()).unwrap();
        let mut pose = BodyModel::neutral_pose();
        lm.minimize(&mut obj, &mut pose);
        assert!((pose[0] - 0.6).abs() < 1e-3);
        let rel = root_rotation(&prior_pose).inverse() * root_rotation(&pose);
        assert!(rel.angle() < 1e-4);
    }

    #[test]
    fn config_errors_name_the_field() {
        let bad = LmConfig {
            damping_decrease: 1.5,
            ..LmConfig::default()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .starts_with("damping_decrease"));
        let bad = LmConfig {
            max_iterations: 0,
            ..LmConfig::default()
        };
        assert!(LevenbergMarquardt::new(bad)
            .err()
            .unwrap()
            .to_string()
            .starts_with("max_iterations"));
    }
}
