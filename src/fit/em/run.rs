//! A hard-EM run: its checks and set-up, the initial E-step, then M- and E-steps until
//! the labels and the energy settle.

use super::config::EmConfig;
use super::estep::{EStep, EmInputs, Expanded};
use super::labels::{PointLabels, OUTLIER};
use super::mstep::{m_step, m_step_beside, MStepsAhead, PoseTerms, RunAhead};
use super::result::{EmResult, EmResume, EmTermination};
use crate::body::{BodyModel, Pose};
use crate::cloud::PixelGraph;
use crate::error::{Error, Result};
use crate::fit::lm::{LevenbergMarquardt, LmReport};
use crate::fit::terms::data::PointObjective;
use crate::fit::terms::free_space::{FreeSpaceImage, FreeSpaceTerm};
use crate::fit::terms::PosePrior;

/// Runs hard EM on `points` (with their neighbourhood `graph`) from `init`. `prior`, if
/// given, adds ½Σ w(θ − θ_prior)² to the M-step (and to the energy).
pub fn hard_em(
    model: &BodyModel,
    points: &[[f32; 3]],
    graph: &PixelGraph,
    init: &Pose,
    prior: Option<&PosePrior>,
    config: &EmConfig,
) -> Result<EmResult> {
    let options = EmOptions {
        prior,
        ..EmOptions::default()
    };
    hard_em_from(model, points, graph, init, options, config)
}

/// What a hard-EM run may take besides the points, their graph and the start pose.
#[derive(Debug, Clone, Copy, Default)]
pub struct EmOptions<'a> {
    /// An earlier run to continue (see [`hard_em_from`]).
    pub resume: Option<EmResume<'a>>,
    /// A prior: ½Σ w(θ − θ_prior)² is added to the M-step and to the energy.
    pub prior: Option<&'a PosePrior>,
    /// The depth image the points came from, for the free-space term.
    pub free_space: Option<FreeSpaceImage<'a>>,
    /// Per point, a weight (finite, > 0) its data terms are multiplied by, in the
    /// E-step and the M-step alike: how much its reading is trusted (see
    /// [`crate::fit::DepthNoise`]). None: all 1.
    pub point_weights: Option<&'a [f32]>,
}

/// [`hard_em`] with the `options`. With a `resume`, the continuation of that run: from
/// `init` (the pose that run ended with) and its labels, at its iteration count (so τ
/// continues its annealing and `max_iterations` counts the earlier iterations too),
/// without a new initial E-step. Continuing a run that stopped at its iteration limit
/// gives the run that would have gone on. With `free_space` (the depth image the points
/// came from) and a positive [`EmConfig::free_space_weight`], the M-step and the energy
/// include the free-space term ([`crate::fit::terms::free_space`]). Runs on a worker of
/// rayon's pool ([`crate::pool::on_worker`]).
pub fn hard_em_from(
    model: &BodyModel,
    points: &[[f32; 3]],
    graph: &PixelGraph,
    init: &Pose,
    options: EmOptions<'_>,
    config: &EmConfig,
) -> Result<EmResult> {
    crate::pool::on_worker(|| {
        let run = run_hard_em(model, points, graph, init, options, config, true);
        run.map(|(result, _)| result)
    })
}

/// [`hard_em_from`] on the calling thread; with `m_steps_ahead`, late M-steps run
/// beside the E-step before them (see [`EmRun::e_step`]; the result is the same either
/// way). Also returns how many M-steps were run ahead and what became of them.
pub(super) fn run_hard_em(
    model: &BodyModel,
    points: &[[f32; 3]],
    graph: &PixelGraph,
    init: &Pose,
    options: EmOptions<'_>,
    config: &EmConfig,
    m_steps_ahead: bool,
) -> Result<(EmResult, MStepsAhead)> {
    check_inputs(points, init, &options, config)?;
    let inputs = EmInputs {
        model,
        points,
        weights: options.point_weights,
        config,
    };
    let mut run = EmRun::new(inputs, graph, init, options, m_steps_ahead)?;
    if options.resume.is_none() {
        run.initial_labels()?;
    }
    run.start_energy();
    let termination = run.iterate()?;
    Ok(run.finish(termination))
}

/// Checks the settings and that the inputs fit together, naming the bad argument.
fn check_inputs(
    points: &[[f32; 3]],
    init: &Pose,
    options: &EmOptions<'_>,
    config: &EmConfig,
) -> Result<()> {
    config.validate()?;
    if let Some(f) = &options.free_space {
        let (w, h) = (f.camera.width, f.camera.height);
        if f.depth.len() != w * h {
            return Err(Error::invalid(
                "depth",
                format!(
                    "has {} readings, the camera's {h}x{w} image {}",
                    f.depth.len(),
                    w * h
                ),
            ));
        }
    }
    let n = points.len();
    if n == 0 {
        return Err(Error::NoBody("no foreground points to fit".into()));
    }
    check_weights(options.point_weights, n)?;
    if let Some(i) = init.iter().position(|v| !v.is_finite()) {
        return Err(Error::invalid(
            "init_pose",
            format!("parameter {i} is not finite"),
        ));
    }
    if let Some(r) = options.resume {
        if r.labels.len() != n {
            return Err(Error::invalid(
                "resume",
                format!("has {} labels for {n} points", r.labels.len()),
            ));
        }
        if let Some(i) = r.labels.iter().position(|&l| !(0..=OUTLIER).contains(&l)) {
            return Err(Error::invalid(
                "resume",
                format!(
                    "label {} of point {i} is not a part or the outlier",
                    r.labels[i]
                ),
            ));
        }
    }
    Ok(())
}

/// Checks that `weights`, if any, has one finite positive weight per point.
pub(super) fn check_weights(weights: Option<&[f32]>, n: usize) -> Result<()> {
    let Some(w) = weights else { return Ok(()) };
    if w.len() != n {
        return Err(Error::invalid(
            "point_weights",
            format!("has {} weights for {n} points", w.len()),
        ));
    }
    if let Some(i) = w.iter().position(|&v| !(v.is_finite() && v > 0.0)) {
        return Err(Error::invalid(
            "point_weights",
            format!("weight {i} is {}, not finite and > 0", w[i]),
        ));
    }
    Ok(())
}

/// The state of a hard-EM run between its steps.
struct EmRun<'a> {
    inputs: EmInputs<'a>,
    prior: Option<&'a PosePrior>,
    /// Whether late M-steps run beside the E-step before them.
    m_steps_ahead: bool,
    /// The free-space term of the M-steps and the energy.
    free_space: Option<FreeSpaceTerm<'a>>,
    /// The same term for an M-step run beside an E-step: the term keeps its last cost,
    /// which each of two M-steps running at once should have to itself.
    free_space_ahead: Option<FreeSpaceTerm<'a>>,
    crf: EStep<'a>,
    lm: LevenbergMarquardt,
    /// The M-steps' data term (relabelled before each M-step).
    objective: PointObjective<'a>,
    ahead: MStepsAhead,
    pose: Pose,
    /// The outlier distance of the current terms.
    tau: f64,
    iterations: usize,
    anneal_cut: Option<usize>,
    labels: Vec<i32>,
    /// The CRF energy of `labels` at the current terms, where known.
    labels_energy: Option<f64>,
    energy: f64,
    trace: Vec<f64>,
    /// The points' distances to their labels' ellipsoids at an M-step's pose.
    own_distance: Vec<f64>,
    /// The next M-step, when it ran beside the E-step before it.
    next_m_step: Option<(Pose, LmReport)>,
    /// The label changes of the last E-step (none yet).
    last_changed: Option<usize>,
}

impl<'a> EmRun<'a> {
    /// A run from `init` (or from `options.resume`, whose labels it takes), with the
    /// unary terms at the start: for a resumed run those its labels need, else all of
    /// them (for the cheapest labels).
    fn new(
        inputs: EmInputs<'a>,
        graph: &'a PixelGraph,
        init: &Pose,
        options: EmOptions<'a>,
        m_steps_ahead: bool,
    ) -> Result<Self> {
        let EmInputs {
            model,
            points,
            weights,
            config,
        } = inputs;
        let free_space_term = || {
            options
                .free_space
                .filter(|f| config.free_space_weight > 0.0 && f.weight_scale > 0.0)
                .map(|f| {
                    FreeSpaceTerm::new(
                        model,
                        f.depth,
                        f.camera,
                        config.free_space_cost(f.weight_scale),
                    )
                })
        };
        let n = points.len();
        let pose = BodyModel::clamp_pose(init);
        let iterations = options.resume.map_or(0, |r| r.iterations);
        let anneal_cut = options.resume.and_then(|r| r.anneal_cut);
        let tau = config.outlier_distance_in(iterations, anneal_cut);
        let resumed_labels = options.resume.map(|r| r.labels);
        let crf = EStep::at_pose(graph, inputs, &pose, tau, resumed_labels)?;
        Ok(EmRun {
            inputs,
            prior: options.prior,
            m_steps_ahead,
            free_space: free_space_term(),
            free_space_ahead: free_space_term(),
            crf,
            lm: LevenbergMarquardt::new(config.lm)?,
            objective: PointObjective::new(
                model,
                points,
                &vec![OUTLIER; n],
                config.point_cost(tau),
            )
            .with_weights(weights),
            ahead: MStepsAhead::default(),
            pose,
            tau,
            iterations,
            anneal_cut,
            labels: resumed_labels.map_or_else(Vec::new, <[i32]>::to_vec),
            labels_energy: None,
            energy: 0.0,
            trace: Vec::new(),
            own_distance: vec![0.0; n],
            next_m_step: None,
            last_changed: None,
        })
    }

    /// The terms of the energy that depend on the pose alone.
    fn pose_terms(&self) -> PoseTerms<'_> {
        PoseTerms {
            prior: self.prior,
            free_space: self.free_space.as_ref(),
        }
    }

    /// Whether the next M-step may run beside the E-step before it.
    fn may_run_ahead(&self) -> bool {
        self.m_steps_ahead && self.iterations < self.inputs.config.max_iterations
    }

    /// The initial E-step of a fresh run: each point's cheapest label, then the CRF
    /// from there, with the first M-step run beside it.
    fn initial_labels(&mut self) -> Result<()> {
        let cheapest = self.crf.cheapest_labels();
        let expanded = if self.may_run_ahead() {
            let mut beside = m_step_beside(
                &mut self.lm,
                &mut self.objective,
                &mut self.free_space_ahead,
                self.prior,
                (self.pose, self.inputs.config.point_cost(self.tau)),
                &mut self.ahead.run,
            );
            let (expanded, m_step) = self.crf.expand_beside(&cheapest, None, &mut beside)?;
            // The first M-step's labels are these.
            self.next_m_step = m_step.flatten();
            self.ahead.used += usize::from(self.next_m_step.is_some());
            self.ahead.used_beside_last_cycle += usize::from(self.next_m_step.is_some());
            expanded
        } else {
            self.crf.expand(&cheapest, None)?
        };
        self.labels = expanded.labels;
        self.labels_energy = Some(expanded.energy);
        Ok(())
    }

    /// The energy of the start (the first entry of the trace).
    fn start_energy(&mut self) {
        let crf_energy = match self.labels_energy {
            Some(e) => e,
            None => self.crf.energy(&self.labels),
        };
        self.energy = crf_energy + self.pose_terms().cost(&self.pose);
        self.trace = vec![self.energy];
    }

    /// M- and E-steps until the run converges, stands still or reaches its iteration
    /// limit.
    fn iterate(&mut self) -> Result<EmTermination> {
        let config = self.inputs.config;
        while self.iterations < config.max_iterations {
            self.iterations += 1;
            let (energy_at_start, pose_at_start) = (self.energy, self.pose);
            let (new_pose, report) = self.m_step();
            let pose_moved = report.accepted > 0;
            // Anneal τ: every unary term can only drop. The unary terms for the moved
            // pose are computed once, at the next τ: E(new pose, next τ) ≤ E(new pose,
            // τ) ≤ E(pose, τ), so the energy still never increases (checked, not
            // assumed).
            let next_tau = config.outlier_distance_in(self.iterations, self.anneal_cut);
            if pose_moved {
                self.take_pose(&new_pose, next_tau);
            }
            if next_tau != self.tau {
                self.anneal(next_tau);
            }
            let changed = self.e_step()?;
            if let Some(end) = self.settled(changed, pose_moved, energy_at_start, &pose_at_start) {
                return Ok(end);
            }
        }
        Ok(EmTermination::MaxIterations)
    }

    /// The M-step: the one run ahead beside the last E-step if it had these labels,
    /// else LM from the current pose on the current labels.
    fn m_step(&mut self) -> (Pose, LmReport) {
        match self.next_m_step.take() {
            Some(done) => done,
            None => {
                let point_cost = self.inputs.config.point_cost(self.tau);
                self.objective.relabel(&self.labels, point_cost);
                let terms = PoseTerms {
                    prior: self.prior,
                    free_space: self.free_space.as_ref(),
                };
                m_step(&mut self.lm, &mut self.objective, terms, &self.pose)
            }
        }
    }

    /// Moves to the M-step's `new_pose` with the unary terms at `next_tau`, if that does
    /// not raise the energy.
    fn take_pose(&mut self, new_pose: &Pose, next_tau: f64) {
        // The points' own-label distances at the new pose, from the M-step's last
        // evaluation (when it was at that pose: LM's last trial may have been a
        // rejected one).
        let own = self
            .objective
            .kept_distances(new_pose, &self.labels, &mut self.own_distance);
        let own = own.then_some(&self.own_distance[..]);
        self.crf.set_pose(new_pose, next_tau, &self.labels, own);
        let crf_energy = self.crf.energy(&self.labels);
        let e = crf_energy + self.pose_terms().cost(new_pose);
        if e <= self.energy {
            self.pose = *new_pose;
            self.energy = e;
            self.tau = next_tau;
            self.labels_energy = Some(crf_energy);
        } else {
            // Cannot happen in exact arithmetic; keep the better state.
            self.crf.set_pose(&self.pose, self.tau, &self.labels, None);
            self.labels_energy = None;
        }
        self.trace.push(self.energy);
    }

    /// The unary terms at the current pose and the next outlier distance.
    fn anneal(&mut self, next_tau: f64) {
        self.tau = next_tau;
        self.crf.set_pose(&self.pose, self.tau, &self.labels, None);
        let crf_energy = self.crf.energy(&self.labels);
        self.energy = crf_energy + self.pose_terms().cost(&self.pose);
        self.labels_energy = Some(crf_energy);
    }

    /// The E-step; returns how many labels it changed.
    ///
    /// The expansion runs on one core; the next M-step runs beside it on the other, for
    /// labels the E-step is likely to end with, with the next M-step's other inputs (the
    /// pose and τ are this E-step's). It is used only if the labels it ran for are the
    /// ones the next M-step starts from, so the EM is the same as run one step after
    /// the other. Once an E-step has left the labels as they were (the late
    /// iterations), the M-step runs beside the whole E-step for the labels it starts
    /// from; else beside the expansion's last cycle, for the labels that cycle starts
    /// from (see `CrfSolver::alpha_expansion_beside`).
    fn e_step(&mut self) -> Result<usize> {
        let (expanded, run_ahead) = self.expand()?;
        Ok(self.take_labels(expanded, run_ahead))
    }

    /// The expansion from the current labels, with the next M-step run ahead beside it
    /// where it may (see [`Self::e_step`]).
    fn expand(&mut self) -> Result<(Expanded, Option<RunAhead>)> {
        let may_run_ahead = self.may_run_ahead();
        let last_changed = self.last_changed;
        let EmRun {
            inputs,
            prior,
            free_space_ahead,
            crf,
            lm,
            objective,
            ahead,
            pose,
            tau,
            labels,
            labels_energy,
            ..
        } = self;
        let point_cost = inputs.config.point_cost(*tau);
        let labels_energy = *labels_energy;
        if may_run_ahead && last_changed == Some(0) {
            ahead.run += 1;
            let (expanded, m_step_done) = rayon::join(
                || crf.expand(labels, labels_energy),
                || {
                    objective.relabel(labels, point_cost);
                    let terms = PoseTerms {
                        prior: *prior,
                        free_space: free_space_ahead.as_mut().map(|f| &*f),
                    };
                    m_step(lm, objective, terms, pose)
                },
            );
            Ok((expanded?, Some(RunAhead::ForOldLabels(m_step_done))))
        } else if may_run_ahead {
            let mut beside = m_step_beside(
                lm,
                objective,
                free_space_ahead,
                *prior,
                (*pose, point_cost),
                &mut ahead.run,
            );
            let (expanded, m_step_done) = crf.expand_beside(labels, labels_energy, &mut beside)?;
            Ok((expanded, m_step_done.flatten().map(RunAhead::ForNewLabels)))
        } else {
            Ok((crf.expand(labels, labels_energy)?, None))
        }
    }

    /// Takes the E-step's labels if they do not raise the energy, and keeps the M-step
    /// run ahead if it had the labels the next M-step starts from. Returns how many
    /// labels the E-step changed.
    fn take_labels(&mut self, expanded: Expanded, run_ahead: Option<RunAhead>) -> usize {
        let new_labels = expanded.labels;
        let changed = new_labels
            .iter()
            .zip(&self.labels)
            .filter(|(a, b)| a != b)
            .count();
        let e = expanded.energy + self.pose_terms().cost(&self.pose);
        let accept = e <= self.energy;
        if accept {
            self.labels = new_labels;
            self.energy = e;
            self.labels_energy = Some(expanded.energy);
        } else {
            // (Only a rounding tie could get here.) The old labels stay; their energy
            // is summed afresh if needed.
            self.labels_energy = None;
        }
        // Whether the M-step run ahead had the labels the next M-step starts from.
        self.next_m_step = match run_ahead {
            Some(RunAhead::ForOldLabels(m)) if changed == 0 || !accept => Some(m),
            Some(RunAhead::ForNewLabels(m)) if changed == 0 || accept => {
                self.ahead.used_beside_last_cycle += 1;
                Some(m)
            }
            _ => None,
        };
        self.ahead.used += usize::from(self.next_m_step.is_some());
        self.last_changed = Some(changed);
        self.trace.push(self.energy);
        changed
    }

    /// Whether the run ends after this iteration, which changed `changed` labels, moved
    /// the pose or not, and started at `energy_at_start` and `pose_at_start`: it stands
    /// still, or it has converged. Else, if the fit has settled while τ still anneals,
    /// the annealing is cut ([`EmConfig::adaptive_anneal`]).
    fn settled(
        &mut self,
        changed: usize,
        pose_moved: bool,
        energy_at_start: f64,
        pose_at_start: &Pose,
    ) -> Option<EmTermination> {
        let EmInputs {
            model,
            points,
            config,
            ..
        } = self.inputs;
        let annealed = config.annealed_in(self.iterations, self.anneal_cut);
        if changed == 0 && !pose_moved {
            return Some(EmTermination::Stationary);
        }
        let drop = energy_at_start - self.energy;
        let labels_settled =
            (changed as f64) <= config.label_change_tolerance * points.len() as f64;
        if annealed && labels_settled && drop <= config.energy_tolerance * self.energy.abs() {
            return Some(EmTermination::Converged);
        }
        // (Only a cut before the schedule's last step changes anything.)
        if !annealed
            && config.adaptive_anneal
            && labels_settled
            && self.iterations + 1 < config.anneal_iterations
        {
            let moved = model
                .joints(&self.pose)
                .iter()
                .zip(&model.joints(pose_at_start))
                .map(|(a, b)| (a - b).norm())
                .fold(0.0, f64::max);
            if moved <= config.settled_joint_motion {
                // Settled at a τ still annealing: the final τ from the next iteration on.
                self.anneal_cut = Some(self.iterations);
            }
        }
        None
    }

    /// The result, and what became of the M-steps run ahead.
    fn finish(self, termination: EmTermination) -> (EmResult, MStepsAhead) {
        let PointLabels {
            labels,
            part_counts,
            outliers,
        } = PointLabels::new(self.labels);
        let result = EmResult {
            pose: self.pose,
            labels,
            energy: self.energy,
            energy_trace: self.trace,
            iterations: self.iterations,
            termination,
            anneal_cut: self.anneal_cut,
            part_counts,
            outliers,
        };
        (result, self.ahead)
    }
}
