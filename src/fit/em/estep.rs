//! The E-step: the CRF over one point set (edge weights, unary terms at a pose and
//! τ) and its alpha-expansion from the current labels.

use super::config::EmConfig;
use super::labels::{PointLabels, NUM_LABELS};
use super::unary::{
    cheapest_label, fill_candidate_words, fill_unary, nearest_segment_guess, settle_unary,
    HeldLabels, UnaryAt, UnaryRequest, CANDIDATE_WORDS_PER_CHUNK,
};
use crate::body::{BodyModel, Pose};
use crate::cloud::PixelGraph;
use crate::error::{Error, Result};
use crate::fit::terms::data::CHUNK_POINTS;
use crate::graphcut::expansion::{potts_energy, ExpansionHints, NO_WORK_BESIDE};
use crate::graphcut::{CrfProblem, CrfSolver, MoveConfig};
use rayon::prelude::*;
use std::sync::atomic::AtomicBool;

/// Edge lengths below this (m) are treated as this (coincident points).
const MIN_EDGE_LENGTH: f64 = 1e-4;

/// The CRF weight of each graph edge (see the module docs).
pub fn edge_weights(graph: &PixelGraph, config: &EmConfig, out: &mut Vec<f64>) {
    out.clear();
    let n = graph.len().max(1) as f64;
    let mean = graph
        .distance
        .iter()
        .map(|&d| (d as f64).max(MIN_EDGE_LENGTH))
        .sum::<f64>()
        / n;
    let s2 = 2.0 * config.contrast_sigma * config.contrast_sigma;
    out.extend(
        graph
            .distance
            .iter()
            .zip(&graph.depth_diff)
            .map(|(&d, &g)| {
                let g = g as f64;
                config.potts
                    + config.contrast_weight * (-g * g / s2).exp() * mean
                        / (d as f64).max(MIN_EDGE_LENGTH)
            }),
    );
}

pub(super) fn problem<'a>(
    unary: &'a [f64],
    edges: &'a [[u32; 2]],
    weights: &'a [f64],
) -> CrfProblem<'a, f64> {
    CrfProblem {
        unary,
        n_labels: NUM_LABELS,
        edges,
        weights,
        pairwise: None,
    }
}

/// E(V) for fixed unary terms and edge weights.
pub fn crf_energy(unary: &[f64], edges: &[[u32; 2]], weights: &[f64], labels: &[i32]) -> f64 {
    // The expansion solver's own sum (same order, same bits), so that the EM can take
    // an E-step's energy from the solver.
    potts_energy(unary, NUM_LABELS, edges, weights, labels)
}

/// What an E-step's terms are computed from, fixed for a fit: the body model, the
/// points (and their weights, see [`UnaryAt::weights`]) and the settings.
#[derive(Debug, Clone, Copy)]
pub(super) struct EmInputs<'a> {
    pub model: &'a BodyModel,
    pub points: &'a [[f32; 3]],
    pub weights: Option<&'a [f32]>,
    pub config: &'a EmConfig,
}

impl<'a> EmInputs<'a> {
    /// Where the unary terms are evaluated at `pose` and `tau`.
    pub fn at<'p>(&self, pose: &'p Pose, tau: f64) -> UnaryAt<'p>
    where
        'a: 'p,
    {
        UnaryAt {
            model: self.model,
            points: self.points,
            weights: self.weights,
            pose,
            config: self.config,
            tau,
        }
    }
}

/// An E-step's labels and their CRF energy ([`EStep::energy`], at the terms that
/// E-step left).
pub(super) struct Expanded {
    pub labels: Vec<i32>,
    pub energy: f64,
}

/// The E-step's CRF over one point set, its buffers reused across a fit's E-steps: the
/// edge weights, the unary terms at the current pose and τ, and the expansion solver.
pub(super) struct EStep<'g> {
    pub inputs: EmInputs<'g>,
    pub graph: &'g PixelGraph,
    pub weights: Vec<f64>,
    /// Per point: the sum of its edge weights (see [`unary_costs_for_labels`]).
    pub slack: Vec<f64>,
    pub unary: Vec<f64>,
    /// Per point: the segments whose terms `unary` left out (bit per segment).
    pub skipped: Vec<u32>,
    /// The pose and τ of `unary`.
    pub pose: Pose,
    pub tau: f64,
    pub solver: CrfSolver<f64>,
    pub moves: MoveConfig,
    /// The expansion's candidate sets for `candidates_for` (words as
    /// `CrfSolver::expansion_with` takes them), computed with `unary`; valid until
    /// `unary` changes otherwise.
    pub candidate_words: Vec<u64>,
    pub candidates_for: Vec<i32>,
    pub candidates_valid: bool,
    /// `solver` has run an expansion on `graph`'s edges and `weights` (which stay as
    /// they are for the E-step's life): later ones need not check them again.
    pub structure_checked: bool,
}

impl<'g> EStep<'g> {
    /// Without unary terms yet (the fits start with [`Self::at_pose`]).
    #[cfg(test)]
    pub fn new(graph: &'g PixelGraph, inputs: EmInputs<'g>) -> Result<Self> {
        let solver = CrfSolver::new(inputs.points.len(), &graph.edges)?;
        Ok(Self::with_solver(graph, inputs, solver))
    }

    /// [`Self::new`] with its unary terms at `pose` and `tau` ([`Self::set_pose`]
    /// with `labels`). The expansion solver's graph is built on one worker of rayon's
    /// pool while the others compute the edge weights and the unary terms.
    ///
    /// Without `labels` (a fresh start, for [`Self::cheapest_labels`]) the terms are
    /// those for every point held at a guessed segment ([`nearest_segment_guess`]): a
    /// term that exceeds the guess's cost by more than the point's slack is left out
    /// (and set to the cap, marked skipped). Any label's cost bounds the cheapest
    /// label's from above, so such a term is neither the cheapest nor, with cap or
    /// exact value alike, a candidate for the expansion from the cheapest labels: both
    /// come out as with every term exact, and the terms stay as exact as every later
    /// E-step's (see [`unary_costs_for_labels`]). (Holding every point at the outlier
    /// label, whose cost needs no distance, would leave out fewer: its reach is ≈ τ.)
    pub fn at_pose(
        graph: &'g PixelGraph,
        inputs: EmInputs<'g>,
        pose: &Pose,
        tau: f64,
        labels: Option<&[i32]>,
    ) -> Result<Self> {
        let EmInputs { model, points, .. } = inputs;
        let n = points.len();
        let (solver, mut crf) = rayon::join(
            || CrfSolver::new(n, &graph.edges),
            || {
                // A solver for no nodes stands in until the real one is built.
                let empty = CrfSolver::new(0, &[]).expect("no edges to check");
                let mut crf = Self::with_solver(graph, inputs, empty);
                let guess;
                let held = match labels {
                    Some(labels) => labels,
                    None => {
                        guess = nearest_segment_guess(model, points, pose);
                        &guess
                    }
                };
                crf.set_pose(pose, tau, held, None);
                crf
            },
        );
        crf.solver = solver?;
        Ok(crf)
    }

    fn with_solver(graph: &'g PixelGraph, inputs: EmInputs<'g>, solver: CrfSolver<f64>) -> Self {
        let (n, config) = (inputs.points.len(), inputs.config);
        let mut weights = Vec::with_capacity(graph.len());
        edge_weights(graph, config, &mut weights);
        let mut slack = vec![0.0; n];
        for (&[i, j], &w) in graph.edges.iter().zip(&weights) {
            if i != j {
                slack[i as usize] += w;
                slack[j as usize] += w;
            }
        }
        EStep {
            inputs,
            graph,
            weights,
            slack,
            unary: vec![0.0; n * NUM_LABELS],
            skipped: vec![0; n],
            pose: [0.0; crate::body::NUM_PARAMS],
            tau: 0.0,
            solver,
            moves: MoveConfig {
                max_cycles: config.expansion_cycles,
            },
            candidate_words: vec![0; n.div_ceil(64) * NUM_LABELS],
            candidates_for: Vec::with_capacity(n),
            candidates_valid: false,
            structure_checked: false,
        }
    }

    /// The unary terms of `points` at `pose` and outlier distance `tau` that an
    /// expansion from `labels` can use (see [`unary_costs_for_labels`]), and also the
    /// expansion's candidate sets for `labels` (computed in the same parallel pass, so
    /// that the expansion need not collect them on one thread). `own` may give the
    /// points' distances to their labels' ellipsoids at `pose` (see [`fill_unary`]).
    pub fn set_pose(&mut self, pose: &Pose, tau: f64, labels: &[i32], own: Option<&[f64]>) {
        self.pose = *pose;
        self.tau = tau;
        let held = HeldLabels {
            labels,
            slack: &self.slack,
            skipped: &mut self.skipped,
        };
        let request = UnaryRequest {
            held: Some(held),
            own,
            candidates: Some(&mut self.candidate_words[..]),
        };
        fill_unary(&self.inputs.at(pose, tau), request, &mut self.unary);
        self.candidates_for.clear();
        self.candidates_for.extend_from_slice(labels);
        self.candidates_valid = true;
    }

    /// Every unary term at `pose` and `tau`, exact (no labels held): the reference the
    /// tests compare the E-step's terms with.
    #[cfg(test)]
    pub fn set_all_terms(&mut self, pose: &Pose, tau: f64) {
        self.pose = *pose;
        self.tau = tau;
        self.candidates_valid = false;
        self.skipped.fill(0);
        fill_unary(
            &self.inputs.at(pose, tau),
            UnaryRequest::default(),
            &mut self.unary,
        )
    }

    /// The CRF energy of `labels` (without the prior).
    pub fn energy(&self, labels: &[i32]) -> f64 {
        crf_energy(&self.unary, &self.graph.edges, &self.weights, labels)
    }

    /// The cheapest label of each point, ignoring the pairwise terms; also the
    /// expansion's candidate sets for these labels (both in parallel: the initial
    /// expansion need not collect its sets on one thread).
    pub fn cheapest_labels(&mut self) -> Vec<i32> {
        let mut cheapest = vec![0; self.slack.len()];
        self.unary
            .par_chunks(CHUNK_POINTS * NUM_LABELS)
            .zip(cheapest.par_chunks_mut(CHUNK_POINTS))
            .zip(self.slack.par_chunks(CHUNK_POINTS))
            .zip(
                self.candidate_words
                    .par_chunks_mut(CANDIDATE_WORDS_PER_CHUNK),
            )
            .for_each(|(((u, labels), slack), words)| {
                for (row, l) in u.chunks_exact(NUM_LABELS).zip(labels.iter_mut()) {
                    *l = cheapest_label(row);
                }
                fill_candidate_words(u, labels, slack, words);
            });
        self.candidates_for.clone_from(&cheapest);
        self.candidates_valid = true;
        cheapest
    }

    /// Alpha-expansion from `init`, whose energy [`Self::energy`] may give as
    /// `init_energy` (at the current terms); the terms of the labels it ends with are
    /// exact (see [`settle_unary`]).
    pub fn expand(&mut self, init: &[i32], init_energy: Option<f64>) -> Result<Expanded> {
        self.expand_with(init, init_energy, NO_WORK_BESIDE)
            .map(|(expanded, _)| expanded)
    }

    /// [`Self::expand`] with `beside` run beside its cycles (see
    /// [`CrfSolver::alpha_expansion_beside`]): its output for the labels returned, if
    /// it ran for them.
    pub fn expand_beside<R: Send>(
        &mut self,
        init: &[i32],
        init_energy: Option<f64>,
        beside: &mut (impl FnMut(&[i32], &AtomicBool) -> R + Send),
    ) -> Result<(Expanded, Option<R>)> {
        self.expand_with(init, init_energy, Some(beside))
    }

    fn expand_with<R: Send>(
        &mut self,
        init: &[i32],
        init_energy: Option<f64>,
        beside: Option<&mut (impl FnMut(&[i32], &AtomicBool) -> R + Send)>,
    ) -> Result<(Expanded, Option<R>)> {
        let p = problem(&self.unary, &self.graph.edges, &self.weights);
        let hints = ExpansionHints {
            // The candidate sets, if computed for `init` (see `set_pose`).
            candidates: (self.candidates_valid && self.candidates_for == init)
                .then_some(&self.candidate_words[..]),
            init_energy,
            same_structure: self.structure_checked,
        };
        let (labelling, output) =
            self.solver
                .expansion_with(&p, Some(init), &self.moves, hints, beside)?;
        self.structure_checked = true;
        // The solver's energy is `Self::energy`'s sum; settled terms change it.
        let energy = match self.settle(&labelling.labels) {
            0 => labelling.energy,
            _ => self.energy(&labelling.labels),
        };
        debug_assert_eq!(energy, self.energy(&labelling.labels));
        let labels = labelling.labels;
        Ok((Expanded { labels, energy }, output))
    }

    /// Makes the terms of `labels` exact (see [`settle_unary`]); how many changed.
    fn settle(&mut self, labels: &[i32]) -> usize {
        self.candidates_valid = false;
        let at = self.inputs.at(&self.pose, self.tau);
        settle_unary(&at, labels, &mut self.unary, &mut self.skipped)
    }
}

/// One E-step on its own: the CRF labels of `at.points` (with their `graph`) for the
/// fixed pose and outlier distance of `at`, by alpha-expansion from `init` (labels in
/// `0..NUM_LABELS`, the outlier label being [`NUM_SEGMENTS`]). Returns the labels and
/// the CRF energy. Used to label the full-resolution cloud after EM ran on a
/// sub-sampled one.
///
/// [`NUM_SEGMENTS`]: crate::body::NUM_SEGMENTS
pub fn label_points(
    at: &UnaryAt<'_>,
    graph: &PixelGraph,
    init: &[i32],
) -> Result<(PointLabels, f64)> {
    let UnaryAt {
        model,
        points,
        weights,
        pose,
        config,
        tau,
    } = *at;
    config.validate()?;
    let n = points.len();
    if init.len() != n {
        return Err(Error::invalid(
            "init",
            format!("has {} labels for {n} points", init.len()),
        ));
    }
    super::run::check_weights(weights, n)?;
    let inputs = EmInputs {
        model,
        points,
        weights,
        config,
    };
    let mut crf = EStep::at_pose(graph, inputs, pose, tau, Some(init))?;
    let Expanded { labels, energy } = crf.expand(init, None)?;
    Ok((PointLabels::new(labels), energy))
}
