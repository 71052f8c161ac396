//! Hard EM: CRF body-part labelling (E-step) alternating with Levenberg–Marquardt on the
//! labelled points (M-step).
//!
//! Energy (paper eqs. 6–9), over points i with labels V_i ∈ {0..15 segments, outlier}:
//!
//! E(Θ, V) = Σ_i U_i(V_i) + Σ_{(i,j) ∈ graph} w_ij · [V_i ≠ V_j]
//!
//! - U_i(k) = ρ(min(|d_ik|, T))/σ² with d_ik the signed distance of point i to the
//!   ellipsoid of segment k at pose Θ (ρ(r) = r²/2 by default: eq. 6), truncated at
//!   T = `truncation_factor`·τ; U_i(outlier) = ρ(τ)/σ², a constant, so leftover
//!   background, flying pixels and noise farther than τ from every part cost no more
//!   than that and do not drag the fit.
//! - w_ij = K + c·exp(−g_ij²/2σ_c²)·(d̄/d_ij) (generalised Potts, eq. 8, plus the
//!   depth-contrast term, eq. 9): g = depth difference, d_ij = 3-D edge length, d̄ the
//!   mean edge length of the frame (makes the ratio unitless). Cutting the labelling
//!   where the depth jumps is cheap; across a smooth surface it costs K + c.
//!
//! The E-step minimises over V by alpha-expansion (Potts is a metric) from the current
//! labels, so it never increases E. The M-step minimises E1 over Θ for fixed labels by
//! LM with the same truncated loss, so it never increases E either (E2 does not depend on
//! Θ). The outlier distance τ starts wide and shrinks geometrically to its final value
//! (a fixed tight cut-off strands limbs that start far away); a smaller τ lowers every
//! unary term, so the energy trace stays non-increasing across the schedule too. The
//! full energy is evaluated after every step and a step that would raise it is undone.

use super::lm::{LevenbergMarquardt, LmConfig, LmReport};
use super::system::PoseObjective;
use super::terms::data::{PointObjective, CHUNK_POINTS};
use super::terms::free_space::{FreeSpaceCost, FreeSpaceImage, FreeSpaceTerm};
use super::terms::{Loss, PointCost};
use super::terms::{PosePrior, WithPrior};
use crate::body::residuals::{to_f64, PoseGeometry};
use crate::body::{BodyModel, Pose, NUM_SEGMENTS};
use crate::cloud::PixelGraph;
use crate::error::{ensure, Error, Result};
use crate::graphcut::expansion::{
    potts_candidate_mask, potts_energy, ExpansionHints, NO_WORK_BESIDE,
};
use crate::graphcut::{CrfProblem, CrfSolver, MoveConfig};
use rayon::prelude::*;
use std::sync::atomic::AtomicBool;

/// Label of the outlier class inside the CRF (exported as −1).
pub const OUTLIER: i32 = NUM_SEGMENTS as i32;
/// CRF labels: the segments plus the outlier.
pub const NUM_LABELS: usize = NUM_SEGMENTS + 1;
/// Edge lengths below this (m) are treated as this (coincident points).
const MIN_EDGE_LENGTH: f64 = 1e-4;

/// Default weight of the free-space term ([`EmConfig::free_space_weight`]).
pub const DEFAULT_FREE_SPACE_WEIGHT: f64 = 3.0;

/// Settings of [`hard_em`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EmConfig {
    /// Residual scale σ (m) of the unary term.
    pub sigma: f64,
    /// Loss of the point residuals.
    pub loss: Loss,
    /// Generalised Potts weight K (eq. 8).
    pub potts: f64,
    /// Weight c of the depth-contrast term (eq. 9).
    pub contrast_weight: f64,
    /// Depth-difference scale σ_c (m) of the contrast term.
    pub contrast_sigma: f64,
    /// Final outlier distance τ (m).
    pub outlier_distance: f64,
    /// Outlier distance at the first iteration (≥ `outlier_distance`).
    pub outlier_distance_start: f64,
    /// τ reaches its final value after this many iterations.
    pub anneal_iterations: usize,
    /// Once the fit has settled while τ is still annealing (at most
    /// `label_change_tolerance` of the labels changed and no joint moved more than
    /// `settled_joint_motion` in an iteration), τ jumps to its final value for the next
    /// iteration instead of stepping down to it over the remaining ones: a settled fit
    /// needs no more gradual tightening, and a fit still moving anneals as before
    /// ([`EmResult::anneal_cut`]).
    pub adaptive_anneal: bool,
    /// See `adaptive_anneal` (m).
    pub settled_joint_motion: f64,
    /// Residuals beyond this multiple of τ are truncated (≥ 1).
    pub truncation_factor: f64,
    /// At most this many E/M iterations.
    pub max_iterations: usize,
    /// Converged when at most this fraction of the labels changed ...
    pub label_change_tolerance: f64,
    /// ... and the energy dropped by at most this fraction in the last iteration.
    pub energy_tolerance: f64,
    /// Alpha-expansion cycles per E-step.
    pub expansion_cycles: usize,
    /// Weight λ of the free-space term (one surface sample against one point; 0 turns
    /// it off; see [`super::free_space`]). Used when the fit has the depth image.
    pub free_space_weight: f64,
    /// Depth (m) a model sample may lie in front of the observed surface for free.
    pub free_space_margin: f64,
    /// Truncation (m) of the free-space residuals.
    pub free_space_truncation: f64,
    /// The M-step's LM settings.
    pub lm: LmConfig,
}

impl Default for EmConfig {
    fn default() -> Self {
        EmConfig {
            sigma: 0.02,
            loss: Loss::Squared,
            potts: 0.3,
            contrast_weight: 1.0,
            contrast_sigma: 0.02,
            outlier_distance: 0.1,
            outlier_distance_start: 0.2,
            anneal_iterations: 6,
            adaptive_anneal: true,
            settled_joint_motion: 1e-3,
            truncation_factor: 2.0,
            max_iterations: 20,
            label_change_tolerance: 0.002,
            energy_tolerance: 1e-4,
            expansion_cycles: 3,
            free_space_weight: DEFAULT_FREE_SPACE_WEIGHT,
            free_space_margin: 0.03,
            free_space_truncation: 0.05,
            lm: LmConfig {
                // The EM loop re-linearises after every E-step anyway; a few LM
                // iterations per M-step fit the shared sequences better and faster.
                max_iterations: 3,
                cost_tolerance: 1e-5,
                ..LmConfig::default()
            },
        }
    }
}

impl EmConfig {
    /// Checks every field, naming the bad one.
    pub fn validate(&self) -> Result<()> {
        let pos = |v: f64| v.is_finite() && v > 0.0;
        let nonneg = |v: f64| v.is_finite() && v >= 0.0;
        ensure(pos(self.sigma), "sigma", || {
            format!("must be finite and > 0, got {}", self.sigma)
        })?;
        match self.loss {
            Loss::Squared => {}
            Loss::Huber(d) | Loss::Cauchy(d) => ensure(pos(d), "loss", || {
                format!("robust loss scale must be finite and > 0, got {d}")
            })?,
        }
        ensure(nonneg(self.potts), "potts", || {
            format!("must be finite and >= 0, got {}", self.potts)
        })?;
        ensure(nonneg(self.contrast_weight), "contrast_weight", || {
            format!("must be finite and >= 0, got {}", self.contrast_weight)
        })?;
        ensure(pos(self.contrast_sigma), "contrast_sigma", || {
            format!("must be finite and > 0, got {}", self.contrast_sigma)
        })?;
        ensure(pos(self.outlier_distance), "outlier_distance", || {
            format!("must be finite and > 0, got {}", self.outlier_distance)
        })?;
        ensure(
            self.outlier_distance_start.is_finite()
                && self.outlier_distance_start >= self.outlier_distance,
            "outlier_distance_start",
            || {
                format!(
                    "must be finite and >= outlier_distance ({}), got {}",
                    self.outlier_distance, self.outlier_distance_start
                )
            },
        )?;
        ensure(
            self.truncation_factor.is_finite() && self.truncation_factor >= 1.0,
            "truncation_factor",
            || format!("must be >= 1, got {}", self.truncation_factor),
        )?;
        ensure(self.max_iterations > 0, "max_iterations", || {
            "must be at least 1".to_string()
        })?;
        ensure(
            (0.0..=1.0).contains(&self.label_change_tolerance),
            "label_change_tolerance",
            || format!("must be within 0..1, got {}", self.label_change_tolerance),
        )?;
        ensure(
            nonneg(self.settled_joint_motion),
            "settled_joint_motion",
            || format!("must be finite and >= 0, got {}", self.settled_joint_motion),
        )?;
        ensure(nonneg(self.energy_tolerance), "energy_tolerance", || {
            format!("must be finite and >= 0, got {}", self.energy_tolerance)
        })?;
        ensure(self.expansion_cycles > 0, "expansion_cycles", || {
            "must be at least 1".to_string()
        })?;
        ensure(nonneg(self.free_space_weight), "free_space_weight", || {
            format!("must be finite and >= 0, got {}", self.free_space_weight)
        })?;
        ensure(nonneg(self.free_space_margin), "free_space_margin", || {
            format!("must be finite and >= 0, got {}", self.free_space_margin)
        })?;
        ensure(
            pos(self.free_space_truncation),
            "free_space_truncation",
            || format!("must be finite and > 0, got {}", self.free_space_truncation),
        )?;
        self.lm.validate()
    }

    /// Whether iteration `it`'s E-step (0: the initial one) has the final τ in a run
    /// whose annealing was cut after iteration `cut` ([`EmResult::anneal_cut`]).
    pub fn annealed_in(&self, it: usize, cut: Option<usize>) -> bool {
        it >= self.anneal_iterations || cut.is_some_and(|k| k < it)
    }

    /// τ of iteration `it`'s E-step in a run whose annealing was cut after iteration
    /// `cut`: the final value once [`Self::annealed_in`], else
    /// [`Self::outlier_distance_at`].
    pub fn outlier_distance_in(&self, it: usize, cut: Option<usize>) -> f64 {
        if self.annealed_in(it, cut) {
            self.outlier_distance
        } else {
            self.outlier_distance_at(it)
        }
    }

    /// τ at iteration `it` (0-based): geometric from the start value to the final one.
    pub fn outlier_distance_at(&self, it: usize) -> f64 {
        if self.anneal_iterations == 0 || it >= self.anneal_iterations {
            return self.outlier_distance;
        }
        let t = it as f64 / self.anneal_iterations as f64;
        self.outlier_distance_start.powf(1.0 - t) * self.outlier_distance.powf(t)
    }

    fn point_cost(&self, tau: f64) -> PointCost {
        PointCost {
            sigma: self.sigma,
            loss: self.loss,
            truncation: self.truncation_factor * tau,
        }
    }

    /// The free-space term's settings, its weight scaled by `weight_scale` (a
    /// sub-sampled fit has fewer points per sample).
    pub fn free_space_cost(&self, weight_scale: f64) -> FreeSpaceCost {
        FreeSpaceCost {
            weight: self.free_space_weight * weight_scale,
            margin: self.free_space_margin,
            sigma: self.sigma,
            truncation: self.free_space_truncation,
        }
    }

    fn outlier_cost(&self, tau: f64) -> f64 {
        self.loss.rho(tau) / (self.sigma * self.sigma)
    }
}

/// Why the EM loop stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EmTermination {
    /// Labels and energy settled.
    Converged,
    /// An iteration changed neither labels nor pose.
    Stationary,
    /// `max_iterations` reached.
    MaxIterations,
}

impl EmTermination {
    pub fn name(self) -> &'static str {
        match self {
            EmTermination::Converged => "converged",
            EmTermination::Stationary => "stationary",
            EmTermination::MaxIterations => "max_iterations",
        }
    }
}

/// Outcome of [`hard_em`].
#[derive(Debug, Clone, PartialEq)]
pub struct EmResult {
    pub pose: Pose,
    /// Per point: segment 0..15 or −1 (outlier).
    pub labels: Vec<i32>,
    /// Final energy.
    pub energy: f64,
    /// Energy after the initial E-step and after every M- and E-step (non-increasing;
    /// while τ anneals, an M-step's entry is already at the next E-step's τ).
    pub energy_trace: Vec<f64>,
    pub iterations: usize,
    pub termination: EmTermination,
    /// Some(k): the fit had settled at iteration k while τ was still annealing, and τ
    /// took its final value from iteration k + 1 on ([`EmConfig::adaptive_anneal`]; a
    /// resumed run continues so).
    pub anneal_cut: Option<usize>,
    /// Points per segment.
    pub part_counts: [usize; NUM_SEGMENTS],
    /// Points labelled outlier.
    pub outliers: usize,
}

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

/// Fills `unary` (N × [`NUM_LABELS`]) for `pose` and outlier distance `tau`.
pub fn unary_costs(
    model: &BodyModel,
    points: &[[f32; 3]],
    pose: &Pose,
    config: &EmConfig,
    tau: f64,
    unary: &mut [f64],
) {
    fill_unary(model, points, pose, config, tau, None, None, unary, None);
}

/// What an E-step knows before its unary terms: each point's label (0..=[`OUTLIER`])
/// and the most its edges can give back when it switches (the sum of its edge
/// weights, Potts), and where to mark the terms it leaves out.
pub struct HeldLabels<'a> {
    pub labels: &'a [i32],
    pub slack: &'a [f64],
    /// Per point: bit k set where segment k's cost was not computed (see
    /// [`unary_costs_for_labels`]).
    pub skipped: &'a mut [u32],
}

/// [`unary_costs`] for an E-step that starts from `held.labels`, computing only the
/// terms its expansion can use. A point's cost for its own label is exact; another
/// segment whose cost, bounded below without the exact distance, exceeds that cost by
/// more than the point's `slack` (the sum of its edge weights) is not computed: no
/// move from the point's label can reach it (the expansion's pruning test leaves it
/// out) and its term is set to the cap, which is at least the true cost. Such terms
/// are marked in `skipped` so that a point that does end at one (possible only after
/// first moving to a costlier label) gets its exact cost back ([`settle_unary`]). The
/// energy stays exact at every labelling the EM keeps, and an E-step from `labels`
/// can only lower it.
pub fn unary_costs_for_labels(
    model: &BodyModel,
    points: &[[f32; 3]],
    pose: &Pose,
    config: &EmConfig,
    tau: f64,
    held: HeldLabels<'_>,
    unary: &mut [f64],
) {
    fill_unary(
        model,
        points,
        pose,
        config,
        tau,
        Some(held),
        None,
        unary,
        None,
    );
}

/// Relative margin of the skip test of [`unary_costs_for_labels`], so that rounding
/// never skips a term the expansion's own test (with the exact term) would admit.
const SKIP_MARGIN: f64 = 1e-9;

/// Words of candidate sets per chunk of points (see [`EStep::set_pose`]).
const CANDIDATE_WORDS_PER_CHUNK: usize = CHUNK_POINTS / 64 * NUM_LABELS;

/// The unary terms; with `held` and `candidates`, also the expansion's candidate sets
/// for the held labels (see `CrfSolver::expansion_with`). With `held`, `own` may give
/// each point's signed distance to its held label's ellipsoid at `pose` (as
/// [`PointObjective::kept_distances`] writes them; read only at points held at a
/// segment), which are then not computed again.
#[allow(clippy::too_many_arguments)]
fn fill_unary(
    model: &BodyModel,
    points: &[[f32; 3]],
    pose: &Pose,
    config: &EmConfig,
    tau: f64,
    held: Option<HeldLabels<'_>>,
    own: Option<&[f64]>,
    unary: &mut [f64],
    candidates: Option<&mut [u64]>,
) {
    const _: () = assert!(CHUNK_POINTS.is_multiple_of(64));
    let geo = PoseGeometry::new(model, pose);
    let pc = config.point_cost(tau);
    let chunk = |c: usize,
                 u: &mut [f64],
                 pts: &[[f32; 3]],
                 held: Option<(&[i32], &[f64], &mut [u32])>,
                 words: Option<&mut [u64]>| {
        let own = own.map(|d| &d[c * CHUNK_POINTS..c * CHUNK_POINTS + pts.len()]);
        unary_chunk(
            &geo,
            &pc,
            config.outlier_cost(tau),
            u,
            pts,
            held,
            own,
            words,
        )
    };
    let rows = unary.par_chunks_mut(CHUNK_POINTS * NUM_LABELS);
    let pts = points.par_chunks(CHUNK_POINTS).enumerate();
    match held {
        None => rows
            .zip(pts)
            .for_each(|(u, (c, p))| chunk(c, u, p, None, None)),
        Some(h) => {
            debug_assert!(h.labels.len() == points.len() && h.slack.len() == points.len());
            debug_assert!(own.is_none_or(|d| d.len() == points.len()));
            let chunks = rows
                .zip(pts)
                .zip(h.labels.par_chunks(CHUNK_POINTS))
                .zip(h.slack.par_chunks(CHUNK_POINTS))
                .zip(h.skipped.par_chunks_mut(CHUNK_POINTS));
            match candidates {
                None => chunks
                    .for_each(|((((u, (c, p)), l), w), sk)| chunk(c, u, p, Some((l, w, sk)), None)),
                Some(words) => {
                    debug_assert_eq!(words.len(), points.len().div_ceil(64) * NUM_LABELS);
                    chunks
                        .zip(words.par_chunks_mut(CANDIDATE_WORDS_PER_CHUNK))
                        .for_each(|(((((u, (c, p)), l), w), sk), cw)| {
                            chunk(c, u, p, Some((l, w, sk)), Some(cw))
                        })
                }
            }
        }
    }
}

/// [`fill_unary`] for one chunk of points (see [`unary_costs_for_labels`] for `held`).
#[allow(clippy::too_many_arguments)]
fn unary_chunk(
    geo: &PoseGeometry,
    pc: &PointCost,
    outlier: f64,
    u: &mut [f64],
    pts: &[[f32; 3]],
    held: Option<(&[i32], &[f64], &mut [u32])>,
    own_distance: Option<&[f64]>,
    candidate_words: Option<&mut [u64]>,
) {
    let cap = pc.cap();
    let labels_and_slack = held.as_ref().map(|(l, w, _)| (*l, *w));
    let mut buf = [[0.0f64; 3]; CHUNK_POINTS];
    let buf = to_f64(pts, &mut buf);
    // Per point: the most another label may cost and still be within the expansion's
    // reach (then as the residual of that cost).
    let mut reach = [f64::INFINITY; CHUNK_POINTS];
    // With labels: the points by label (each label's in ascending order) and where
    // each label's points start.
    let mut held_order = None;
    let mut skipped: &mut [u32] = &mut [];
    // Every segment's term starts at the cap (a whole row at a time); the own label's
    // and the near points' exact costs overwrite it below.
    for row in u.chunks_exact_mut(NUM_LABELS) {
        row[..NUM_SEGMENTS].fill(cap);
        row[NUM_SEGMENTS] = outlier;
    }
    if let Some((labels, slack, sk)) = held {
        sk.fill(0);
        skipped = sk;
        for (i, &l) in labels.iter().enumerate() {
            if l == OUTLIER {
                reach[i] = outlier + slack[i];
            }
        }
        // The points by label (counting sort), each segment's in ascending order.
        let mut start = [0usize; NUM_LABELS + 1];
        for &l in labels {
            start[l.clamp(0, OUTLIER) as usize + 1] += 1;
        }
        for k in 0..NUM_LABELS {
            start[k + 1] += start[k];
        }
        let mut by_label = [0u16; CHUNK_POINTS];
        let mut next = start;
        for (i, &l) in labels.iter().enumerate() {
            let k = l.clamp(0, OUTLIER) as usize;
            by_label[next[k]] = i as u16;
            next[k] += 1;
        }
        for (k, e) in geo.segments.iter().enumerate() {
            let mine = &by_label[start[k]..start[k + 1]];
            let mut own_cost = |i: usize, d: f64| {
                let c = pc.cost(d);
                u[i * NUM_LABELS + k] = c;
                reach[i] = c + slack[i];
            };
            match own_distance {
                // Known from the M-step that gave this pose.
                Some(d) => mine
                    .iter()
                    .for_each(|&i| own_cost(i as usize, d[i as usize])),
                None => e.signed_distances_batched(
                    mine.iter()
                        .map(|&i| (i as usize, e.local(&buf[i as usize]))),
                    own_cost,
                ),
            }
        }
        for r in &mut reach[..labels.len()] {
            *r += SKIP_MARGIN * (1.0 + r.abs());
            // From here on the reach as a residual: a term is certainly beyond it when
            // the distance's lower bound passes this (ρ's inverse is exact to a
            // rounding, far inside the margin).
            *r = pc.residual_within(*r);
        }
        held_order = Some((by_label, start));
    }
    let known = !skipped.is_empty();
    let n = pts.len();
    // The points in groups: with labels, one per label (the counting sort's order),
    // else one of all the points in order. `order[j]` is the chunk index of the j-th.
    let identity: [u16; CHUNK_POINTS];
    let all = [0, n];
    let (order, groups) = match &held_order {
        Some((by_label, start)) => (&by_label[..n], &start[..]),
        None => {
            identity = std::array::from_fn(|j| j as u16);
            (&identity[..n], &all[..])
        }
    };
    // The points one coordinate per array in group order, for the vectorised split
    // below.
    let mut soa = [[0.0f64; CHUNK_POINTS]; 3];
    for (j, &i) in order.iter().enumerate() {
        for r in 0..3 {
            soa[r][j] = buf[i as usize][r];
        }
    }
    // Each group's bounding box and largest reach (as a residual; none without
    // labels). Smaller blocks (of 32 points within a label) culled no more on the
    // bench frame: its segments' bounding spheres are loose.
    let n_groups = groups.len() - 1;
    let mut boxes = [([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]); NUM_LABELS];
    let mut group_reach = [f64::INFINITY; NUM_LABELS];
    for g in 0..n_groups {
        let (lo, hi) = &mut boxes[g];
        let mut most = f64::NEG_INFINITY;
        for j in groups[g]..groups[g + 1] {
            for r in 0..3 {
                lo[r] = lo[r].min(soa[r][j]);
                hi[r] = hi[r].max(soa[r][j]);
            }
            most = most.max(reach[order[j] as usize]);
        }
        group_reach[g] = most;
    }
    let mut local = [[0.0f64; CHUNK_POINTS]; 3];
    let mut beyond = [false; CHUNK_POINTS];
    // Group positions j of the points that need a segment's exact distance.
    let mut near = [0u16; CHUNK_POINTS];
    let margin = |x: f64| x * (1.0 + 1e-9) + 1e-9;
    for (k, e) in geo.segments.iter().enumerate() {
        let c = e.centre();
        let clear_truncation = margin(e.max_radius() + pc.truncation);
        let beyond_truncation = e.beyond(pc.truncation);
        let mut m = 0;
        for g in 0..n_groups {
            let range = groups[g]..groups[g + 1];
            // The own label's terms are there already.
            if range.is_empty() || (known && g == k) {
                continue;
            }
            // A group whose box stays clear of the segment's bounding sphere grown by
            // the truncation has every point beyond the truncation (the per-point test
            // |y| ≥ e_max + t below would say so): its terms are the cap, exactly
            // what the exact distance would give. Grown by the group's largest reach,
            // every point's distance lower bound passes its reach: each term is left
            // out as the per-point skip test below would (the points also beyond the
            // truncation are marked skipped too: their terms are the cap either way).
            // The margins cover the rounding of the per-point tests (relative ~1e-15).
            let (lo, hi) = &boxes[g];
            let gap2: f64 = (0..3)
                .map(|r| (lo[r] - c[r]).max(c[r] - hi[r]).max(0.0).powi(2))
                .sum();
            if pc.truncation > 0.0 && gap2 >= clear_truncation * clear_truncation {
                continue;
            }
            if known {
                let clear_reach = margin(e.max_radius() + group_reach[g]);
                if gap2 >= clear_reach * clear_reach {
                    for &i in &order[range] {
                        skipped[i as usize] |= 1 << k;
                    }
                    continue;
                }
            }
            // A lower bound of the distance at or beyond the truncation means the cost
            // is the cap, exactly what the exact distance would give; only the points
            // nearer than that need the exact (iterative) distance.
            let [l0, l1, l2] = &mut local;
            let r = range.clone();
            e.locals_beyond(
                &beyond_truncation,
                [&soa[0][r.clone()], &soa[1][r.clone()], &soa[2][r.clone()]],
                [&mut l0[r.clone()], &mut l1[r.clone()], &mut l2[r.clone()]],
                &mut beyond[r],
            );
            for j in range {
                near[m] = j as u16;
                m += usize::from(!beyond[j]);
            }
        }
        if known {
            // Also the points whose cost is certainly beyond reach: whose distance's
            // lower bound passes the reach as a residual (no square root, no division).
            // Branch-free: which points pass is data-dependent, and a branch per point
            // was mispredicted often enough to show in profiles.
            let mut kept = 0;
            for q in 0..m {
                let j = near[q] as usize;
                let i = order[j] as usize;
                let y = [local[0][j], local[1][j], local[2][j]];
                let skip = e.lower_bound_passes(&y, reach[i]);
                skipped[i] |= u32::from(skip) << k;
                near[kept] = near[q];
                kept += usize::from(!skip);
            }
            m = kept;
        }
        let items = near[..m].iter().map(|&j| {
            let j = j as usize;
            (order[j] as usize, [local[0][j], local[1][j], local[2][j]])
        });
        e.signed_distances_batched(items, |i, d| u[i * NUM_LABELS + k] = pc.cost(d));
    }
    if let (Some(words), Some((labels, slack))) = (candidate_words, labels_and_slack) {
        fill_candidate_words(u, labels, slack, words);
    }
}

/// The expansion's candidate sets for one chunk of points from their finished rows `u`,
/// labels and slacks: bit i % 64 of word (i / 64, a) where point i may switch to label
/// a.
fn fill_candidate_words(u: &[f64], labels: &[i32], slack: &[f64], words: &mut [u64]) {
    words.fill(0);
    for (i, (&l, &w)) in labels.iter().zip(slack).enumerate() {
        let row = &u[i * NUM_LABELS..(i + 1) * NUM_LABELS];
        let mut mask = potts_candidate_mask(row, l.clamp(0, OUTLIER) as usize, w);
        let block = &mut words[i / 64 * NUM_LABELS..(i / 64 + 1) * NUM_LABELS];
        while mask != 0 {
            block[mask.trailing_zeros() as usize] |= 1 << (i % 64);
            mask &= mask - 1;
        }
    }
}

/// A cheap guess of each point's segment at `pose`: the one whose centre is nearest in
/// units of its largest half-axis (on the bench frame this left out more terms than the
/// nearest bounding sphere did).
fn nearest_segment_guess(model: &BodyModel, points: &[[f32; 3]], pose: &Pose) -> Vec<i32> {
    let geo = PoseGeometry::new(model, pose);
    let centres: [[f64; 3]; NUM_SEGMENTS] = std::array::from_fn(|k| geo.segments[k].centre());
    let inv_r2: [f64; NUM_SEGMENTS] =
        std::array::from_fn(|k| 1.0 / geo.segments[k].max_radius().powi(2));
    points
        .par_iter()
        .with_min_len(CHUNK_POINTS)
        .map(|p| {
            let mut best = (f64::INFINITY, 0);
            for k in 0..NUM_SEGMENTS {
                let c = &centres[k];
                let d2 = (p[0] as f64 - c[0]).powi(2)
                    + (p[1] as f64 - c[1]).powi(2)
                    + (p[2] as f64 - c[2]).powi(2);
                let v = d2 * inv_r2[k];
                if v < best.0 {
                    best = (v, k as i32);
                }
            }
            best.1
        })
        .collect()
}

/// The label of least cost in a unary row (the first of equals).
fn cheapest_label(row: &[f64]) -> i32 {
    (0..row.len())
        .min_by(|&a, &b| row[a].total_cmp(&row[b]))
        .unwrap_or(0) as i32
}

/// After an E-step on terms from [`unary_costs_for_labels`]: the exact cost of every
/// point that ended at a segment whose term was skipped (rare), so that the energy
/// of `labels` is exact. Returns how many terms were settled.
#[allow(clippy::too_many_arguments)]
pub fn settle_unary(
    model: &BodyModel,
    points: &[[f32; 3]],
    pose: &Pose,
    config: &EmConfig,
    tau: f64,
    labels: &[i32],
    unary: &mut [f64],
    skipped: &mut [u32],
) -> usize {
    let pc = config.point_cost(tau);
    // The pose's geometry only once a point needs it (most E-steps have none).
    let mut geo = None;
    let mut settled = 0;
    for (i, &l) in labels.iter().enumerate() {
        if !(0..OUTLIER).contains(&l) || skipped[i] >> l & 1 == 0 {
            continue;
        }
        let k = l as usize;
        let e = &geo
            .get_or_insert_with(|| PoseGeometry::new(model, pose))
            .segments[k];
        let p = points[i];
        let y = e.local(&[p[0] as f64, p[1] as f64, p[2] as f64]);
        unary[i * NUM_LABELS + k] = pc.cost(e.signed_distance_local(&y));
        skipped[i] &= !(1 << k);
        settled += 1;
    }
    settled
}

fn problem<'a>(unary: &'a [f64], edges: &'a [[u32; 2]], weights: &'a [f64]) -> CrfProblem<'a, f64> {
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

/// Labels as reported to callers, with what they contain.
#[derive(Debug, Clone, PartialEq)]
pub struct PointLabels {
    /// Per point: segment 0..[`NUM_SEGMENTS`], −1 = outlier.
    pub labels: Vec<i32>,
    /// Points labelled with each segment.
    pub part_counts: [usize; NUM_SEGMENTS],
    /// Points labelled outlier.
    pub outliers: usize,
}

impl PointLabels {
    /// From the solver's labels (outlier label [`OUTLIER`]).
    fn new(solver_labels: Vec<i32>) -> Self {
        let mut part_counts = [0usize; NUM_SEGMENTS];
        let mut outliers = 0;
        let labels = solver_labels
            .into_iter()
            .map(|l| {
                if l == OUTLIER {
                    outliers += 1;
                    -1
                } else {
                    part_counts[l as usize] += 1;
                    l
                }
            })
            .collect();
        PointLabels {
            labels,
            part_counts,
            outliers,
        }
    }
}

/// An E-step's labels and their CRF energy ([`EStep::energy`], at the terms that
/// E-step left).
struct Expanded {
    labels: Vec<i32>,
    energy: f64,
}

/// The E-step's CRF over one point set, its buffers reused across a fit's E-steps: the
/// edge weights, the unary terms at the current pose and τ, and the expansion solver.
struct EStep<'g> {
    graph: &'g PixelGraph,
    weights: Vec<f64>,
    /// Per point: the sum of its edge weights (see [`unary_costs_for_labels`]).
    slack: Vec<f64>,
    unary: Vec<f64>,
    /// Per point: the segments whose terms `unary` left out (bit per segment).
    skipped: Vec<u32>,
    /// The pose and τ of `unary`.
    pose: Pose,
    tau: f64,
    solver: CrfSolver<f64>,
    moves: MoveConfig,
    /// The expansion's candidate sets for `candidates_for` (words as
    /// `CrfSolver::expansion_with` takes them), computed with `unary`; valid until
    /// `unary` changes otherwise.
    candidate_words: Vec<u64>,
    candidates_for: Vec<i32>,
    candidates_valid: bool,
    /// `solver` has run an expansion on `graph`'s edges and `weights` (which stay as
    /// they are for the E-step's life): later ones need not check them again.
    structure_checked: bool,
}

impl<'g> EStep<'g> {
    /// Without unary terms yet (the fits start with [`Self::at_pose`]).
    #[cfg(test)]
    fn new(graph: &'g PixelGraph, n: usize, config: &EmConfig) -> Result<Self> {
        let solver = CrfSolver::new(n, &graph.edges)?;
        Ok(Self::with_solver(graph, n, config, solver))
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
    /// label, whose cost needs no distance, left out fewer: its reach is ≈ τ.)
    #[allow(clippy::too_many_arguments)]
    fn at_pose(
        graph: &'g PixelGraph,
        model: &BodyModel,
        points: &[[f32; 3]],
        pose: &Pose,
        config: &EmConfig,
        tau: f64,
        labels: Option<&[i32]>,
    ) -> Result<Self> {
        let n = points.len();
        let (solver, mut crf) = rayon::join(
            || CrfSolver::new(n, &graph.edges),
            || {
                // A solver for no nodes stands in until the real one is built.
                let empty = CrfSolver::new(0, &[]).expect("no edges to check");
                let mut crf = Self::with_solver(graph, n, config, empty);
                let guess;
                let held = match labels {
                    Some(labels) => labels,
                    None => {
                        guess = nearest_segment_guess(model, points, pose);
                        &guess
                    }
                };
                crf.set_pose(model, points, pose, config, tau, held, None);
                crf
            },
        );
        crf.solver = solver?;
        Ok(crf)
    }

    fn with_solver(
        graph: &'g PixelGraph,
        n: usize,
        config: &EmConfig,
        solver: CrfSolver<f64>,
    ) -> Self {
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
    #[allow(clippy::too_many_arguments)]
    fn set_pose(
        &mut self,
        model: &BodyModel,
        points: &[[f32; 3]],
        pose: &Pose,
        config: &EmConfig,
        tau: f64,
        labels: &[i32],
        own: Option<&[f64]>,
    ) {
        self.pose = *pose;
        self.tau = tau;
        let held = HeldLabels {
            labels,
            slack: &self.slack,
            skipped: &mut self.skipped,
        };
        let words = Some(&mut self.candidate_words[..]);
        fill_unary(
            model,
            points,
            pose,
            config,
            tau,
            Some(held),
            own,
            &mut self.unary,
            words,
        );
        self.candidates_for.clear();
        self.candidates_for.extend_from_slice(labels);
        self.candidates_valid = true;
    }

    /// Every unary term at `pose` and `tau`, exact (no labels held): the reference the
    /// tests compare the E-step's terms with.
    #[cfg(test)]
    fn set_all_terms(
        &mut self,
        model: &BodyModel,
        points: &[[f32; 3]],
        pose: &Pose,
        config: &EmConfig,
        tau: f64,
    ) {
        self.pose = *pose;
        self.tau = tau;
        self.candidates_valid = false;
        self.skipped.fill(0);
        unary_costs(model, points, pose, config, tau, &mut self.unary)
    }

    /// The CRF energy of `labels` (without the prior).
    fn energy(&self, labels: &[i32]) -> f64 {
        crf_energy(&self.unary, &self.graph.edges, &self.weights, labels)
    }

    /// The cheapest label of each point, ignoring the pairwise terms; also the
    /// expansion's candidate sets for these labels (both in parallel: the initial
    /// expansion need not collect its sets on one thread).
    fn cheapest_labels(&mut self) -> Vec<i32> {
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
    fn expand(
        &mut self,
        model: &BodyModel,
        points: &[[f32; 3]],
        config: &EmConfig,
        init: &[i32],
        init_energy: Option<f64>,
    ) -> Result<Expanded> {
        self.expand_with(model, points, config, init, init_energy, NO_WORK_BESIDE)
            .map(|(expanded, _)| expanded)
    }

    /// [`Self::expand`] with `beside` run beside its cycles (see
    /// [`CrfSolver::alpha_expansion_beside`]): its output for the labels returned, if
    /// it ran for them.
    fn expand_beside<R: Send>(
        &mut self,
        model: &BodyModel,
        points: &[[f32; 3]],
        config: &EmConfig,
        init: &[i32],
        init_energy: Option<f64>,
        beside: &mut (impl FnMut(&[i32], &AtomicBool) -> R + Send),
    ) -> Result<(Expanded, Option<R>)> {
        self.expand_with(model, points, config, init, init_energy, Some(beside))
    }

    fn expand_with<R: Send>(
        &mut self,
        model: &BodyModel,
        points: &[[f32; 3]],
        config: &EmConfig,
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
        let energy = match self.settle(model, points, config, &labelling.labels) {
            0 => labelling.energy,
            _ => self.energy(&labelling.labels),
        };
        debug_assert_eq!(energy, self.energy(&labelling.labels));
        let labels = labelling.labels;
        Ok((Expanded { labels, energy }, output))
    }

    /// Makes the terms of `labels` exact (see [`settle_unary`]); how many changed.
    fn settle(
        &mut self,
        model: &BodyModel,
        points: &[[f32; 3]],
        config: &EmConfig,
        labels: &[i32],
    ) -> usize {
        self.candidates_valid = false;
        settle_unary(
            model,
            points,
            &self.pose,
            config,
            self.tau,
            labels,
            &mut self.unary,
            &mut self.skipped,
        )
    }
}

/// One E-step on its own: the CRF labels of `points` for a fixed `pose` at outlier
/// distance `tau`, by alpha-expansion from `init` (labels in `0..NUM_LABELS`, the outlier
/// label being [`NUM_SEGMENTS`]). Returns the labels and the CRF energy. Used to label
/// the full-resolution cloud after EM ran on a sub-sampled one.
pub fn label_points(
    model: &BodyModel,
    points: &[[f32; 3]],
    graph: &PixelGraph,
    pose: &Pose,
    init: &[i32],
    tau: f64,
    config: &EmConfig,
) -> Result<(PointLabels, f64)> {
    config.validate()?;
    let n = points.len();
    if init.len() != n {
        return Err(Error::invalid(
            "init",
            format!("has {} labels for {n} points", init.len()),
        ));
    }
    let mut crf = EStep::at_pose(graph, model, points, pose, config, tau, Some(init))?;
    let Expanded { labels, energy } = crf.expand(model, points, config, init, None)?;
    Ok((PointLabels::new(labels), energy))
}

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
    hard_em_from(model, points, graph, init, None, prior, None, config)
}

/// An EM run to continue (see [`hard_em_from`]): the per-point labels it ended with
/// (segment 0..15 or [`OUTLIER`]), the iterations it ran and where its annealing was
/// cut ([`EmResult::anneal_cut`]).
#[derive(Debug, Clone, Copy)]
pub struct EmResume<'a> {
    pub labels: &'a [i32],
    pub iterations: usize,
    pub anneal_cut: Option<usize>,
}

/// [`hard_em`], or with `resume` its continuation: from `init` (the pose that run
/// ended with) and its labels, at its iteration count (so τ continues its annealing
/// and `max_iterations` counts the earlier iterations too), without a new initial
/// E-step. Continuing a run that stopped at its iteration limit gives the run that
/// would have gone on. With `free_space` (the depth image the points came from) and a
/// positive [`EmConfig::free_space_weight`], the M-step and the energy include the
/// free-space term ([`super::free_space`]). Runs on a worker of rayon's pool
/// ([`crate::pool::on_worker`]).
#[allow(clippy::too_many_arguments)]
pub fn hard_em_from(
    model: &BodyModel,
    points: &[[f32; 3]],
    graph: &PixelGraph,
    init: &Pose,
    resume: Option<EmResume<'_>>,
    prior: Option<&PosePrior>,
    free_space: Option<FreeSpaceImage<'_>>,
    config: &EmConfig,
) -> Result<EmResult> {
    crate::pool::on_worker(|| {
        let run = run_hard_em(
            model, points, graph, init, resume, prior, free_space, config, true,
        );
        run.map(|(result, _)| result)
    })
}

/// One M-step: LM from `start` on the objective's labels (with the pose-only terms).
fn m_step(
    lm: &mut LevenbergMarquardt,
    objective: &mut PointObjective,
    prior: Option<&PosePrior>,
    free_space: Option<&FreeSpaceTerm>,
    start: &Pose,
) -> (Pose, LmReport) {
    let mut pose = *start;
    let mut with_prior = WithPrior {
        objective,
        prior,
        free_space,
    };
    let report = lm.minimize(&mut with_prior, &mut pose);
    (pose, report)
}

/// [`m_step`] for the labels `labels`, run ahead beside an E-step: abandoned (`None`)
/// once `abandon` is raised.
#[allow(clippy::too_many_arguments)]
fn m_step_ahead(
    lm: &mut LevenbergMarquardt,
    objective: &mut PointObjective,
    labels: &[i32],
    point_cost: PointCost,
    prior: Option<&PosePrior>,
    free_space: Option<&FreeSpaceTerm>,
    start: &Pose,
    abandon: &AtomicBool,
) -> Option<(Pose, LmReport)> {
    objective.relabel(labels, point_cost);
    // The distances at the start even if abandoned: the M-step that is used starts
    // here too, with mostly the same labels, and takes them from here (see
    // `PointObjective`), so this is work off its path on the thread the E-step's cycle
    // leaves idle.
    objective.cost(start);
    let mut pose = *start;
    let mut with_prior = WithPrior {
        objective,
        prior,
        free_space,
    };
    let report = lm.minimize_unless(&mut with_prior, &mut pose, abandon)?;
    Some((pose, report))
}

/// The next M-step (from `start`, at `point_cost`) as the work beside an expansion's
/// cycles, for the labels each cycle starts from (see `EStep::expand_beside`); counts
/// its runs in `runs`. Its free-space term is its own (see `run_hard_em`).
fn m_step_beside<'s, 'd: 's>(
    lm: &'s mut LevenbergMarquardt,
    objective: &'s mut PointObjective<'d>,
    free_space: &'s mut Option<FreeSpaceTerm<'d>>,
    prior: Option<&'s PosePrior>,
    (start, point_cost): (Pose, PointCost),
    runs: &'s mut usize,
) -> impl FnMut(&[i32], &AtomicBool) -> Option<(Pose, LmReport)> + Send + use<'s, 'd> {
    move |seen, abandon| {
        *runs += 1;
        let fs = free_space.as_mut().map(|f| &*f);
        m_step_ahead(lm, objective, seen, point_cost, prior, fs, &start, abandon)
    }
}

/// M-steps run beside an E-step, and how many of them were used (they had the labels
/// the E-step ended with); the others were discarded or abandoned.
#[derive(Debug, Default, Clone, Copy, PartialEq)]
struct MStepsAhead {
    run: usize,
    used: usize,
    /// Of those used, the ones run beside an expansion's last cycle.
    used_beside_last_cycle: usize,
}

/// An M-step run beside an E-step, for the labels the E-step started from or for
/// those it ended with.
enum RunAhead {
    ForOldLabels((Pose, LmReport)),
    ForNewLabels((Pose, LmReport)),
}

/// [`hard_em_from`] on the calling thread; with `m_steps_ahead`, late M-steps run
/// beside the E-step before them (see the E-step below; the result is the same either
/// way). Also returns how many M-steps were run ahead and what became of them.
#[allow(clippy::too_many_arguments)]
fn run_hard_em(
    model: &BodyModel,
    points: &[[f32; 3]],
    graph: &PixelGraph,
    init: &Pose,
    resume: Option<EmResume<'_>>,
    prior: Option<&PosePrior>,
    free_space: Option<FreeSpaceImage<'_>>,
    config: &EmConfig,
    m_steps_ahead: bool,
) -> Result<(EmResult, MStepsAhead)> {
    config.validate()?;
    if let Some(f) = &free_space {
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
    let free_space_term = || {
        free_space
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
    let free_space = free_space_term();
    // The same term for an M-step run beside an E-step (see below): the term keeps its
    // last cost, which each of two M-steps running at once should have to itself.
    let mut free_space_ahead = free_space_term();
    let n = points.len();
    if n == 0 {
        return Err(Error::NoBody("no foreground points to fit".into()));
    }
    if let Some(i) = init.iter().position(|v| !v.is_finite()) {
        return Err(Error::invalid(
            "init_pose",
            format!("parameter {i} is not finite"),
        ));
    }
    if let Some(r) = resume {
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
    let mut pose = BodyModel::clamp_pose(init);
    let mut iterations = resume.map_or(0, |r| r.iterations);
    let mut anneal_cut = resume.and_then(|r| r.anneal_cut);
    let mut tau = config.outlier_distance_in(iterations, anneal_cut);
    // The unary terms at the start: for a resumed run those its labels need, else all
    // of them (for the cheapest labels).
    let resumed_labels = resume.map(|r| r.labels);
    let mut crf = EStep::at_pose(graph, model, points, &pose, config, tau, resumed_labels)?;
    let mut lm = LevenbergMarquardt::new(config.lm)?;
    let mut ahead = MStepsAhead::default();
    // The pose-only terms of the energy: the prior and the free space.
    let pose_cost = |p: &Pose| {
        prior.map_or(0.0, |pr| pr.cost(p)) + free_space.as_ref().map_or(0.0, |f| f.cost(p))
    };

    // The first M-step, run beside the initial E-step (see the E-step below).
    let mut next_m_step: Option<(Pose, LmReport)> = None;
    // (Relabelled before each M-step.)
    let mut objective =
        PointObjective::new(model, points, &vec![OUTLIER; n], config.point_cost(tau));
    // The CRF energy of `labels` at the current terms, where known.
    let (mut labels, mut labels_energy): (Vec<i32>, Option<f64>) = match resumed_labels {
        Some(labels) => (labels.to_vec(), None),
        None => {
            // Initial labels: the cheapest label of each point, then the CRF.
            let cheapest = crf.cheapest_labels();
            if m_steps_ahead && iterations < config.max_iterations {
                let mut beside = m_step_beside(
                    &mut lm,
                    &mut objective,
                    &mut free_space_ahead,
                    prior,
                    (pose, config.point_cost(tau)),
                    &mut ahead.run,
                );
                let (expanded, m_step) =
                    crf.expand_beside(model, points, config, &cheapest, None, &mut beside)?;
                // The first M-step's labels are these.
                next_m_step = m_step.flatten();
                ahead.used += usize::from(next_m_step.is_some());
                ahead.used_beside_last_cycle += usize::from(next_m_step.is_some());
                (expanded.labels, Some(expanded.energy))
            } else {
                let expanded = crf.expand(model, points, config, &cheapest, None)?;
                (expanded.labels, Some(expanded.energy))
            }
        }
    };
    let mut energy = labels_energy.unwrap_or_else(|| crf.energy(&labels)) + pose_cost(&pose);
    let mut trace = vec![energy];
    let mut own_distance = vec![0.0; n];
    let mut termination = EmTermination::MaxIterations;
    // The label changes of the last E-step (none yet).
    let mut last_changed = None;
    while iterations < config.max_iterations {
        iterations += 1;
        let energy_at_start = energy;
        let pose_at_start = pose;
        // M-step (the objective was built for the first one).
        let (new_pose, report) = match next_m_step.take() {
            Some(done) => done,
            None => {
                objective.relabel(&labels, config.point_cost(tau));
                m_step(&mut lm, &mut objective, prior, free_space.as_ref(), &pose)
            }
        };
        let pose_moved = report.accepted > 0;
        // Anneal τ: every unary term can only drop. The unary terms for the moved pose
        // are computed once, at the next τ: E(new pose, next τ) ≤ E(new pose, τ) ≤
        // E(pose, τ), so the energy still never increases (checked, not assumed).
        let next_tau = config.outlier_distance_in(iterations, anneal_cut);
        if pose_moved {
            // The points' own-label distances at the new pose, from the M-step's last
            // evaluation (when it was at that pose: LM's last trial may have been a
            // rejected one).
            let own = objective.kept_distances(&new_pose, &labels, &mut own_distance);
            let own = own.then_some(&own_distance[..]);
            crf.set_pose(model, points, &new_pose, config, next_tau, &labels, own);
            let crf_energy = crf.energy(&labels);
            let e = crf_energy + pose_cost(&new_pose);
            if e <= energy {
                pose = new_pose;
                energy = e;
                tau = next_tau;
                labels_energy = Some(crf_energy);
            } else {
                // Cannot happen in exact arithmetic; keep the better state.
                crf.set_pose(model, points, &pose, config, tau, &labels, None);
                labels_energy = None;
            }
            trace.push(energy);
        }
        if next_tau != tau {
            tau = next_tau;
            crf.set_pose(model, points, &pose, config, tau, &labels, None);
            let crf_energy = crf.energy(&labels);
            energy = crf_energy + pose_cost(&pose);
            labels_energy = Some(crf_energy);
        }
        // E-step. The expansion runs on one core; the next M-step runs beside it on
        // the other, for labels the E-step is likely to end with, with the next
        // M-step's other inputs (the pose and τ are this E-step's). It is used only if
        // the labels it ran for are the ones the next M-step starts from, so the EM is
        // the same as run one step after the other. Once an E-step has left the labels
        // as they were (the late iterations), the M-step runs beside the whole E-step
        // for the labels it starts from; else beside the expansion's last cycle, for
        // the labels that cycle starts from (see `CrfSolver::alpha_expansion_beside`).
        let may_run_ahead = m_steps_ahead && iterations < config.max_iterations;
        let point_cost = config.point_cost(tau);
        let (expanded, m_step_ahead) = if may_run_ahead && last_changed == Some(0) {
            ahead.run += 1;
            let (expanded, m_step_done) = rayon::join(
                || crf.expand(model, points, config, &labels, labels_energy),
                || {
                    objective.relabel(&labels, point_cost);
                    let free_space = free_space_ahead.as_mut().map(|f| &*f);
                    m_step(&mut lm, &mut objective, prior, free_space, &pose)
                },
            );
            (expanded?, Some(RunAhead::ForOldLabels(m_step_done)))
        } else if may_run_ahead {
            let mut beside = m_step_beside(
                &mut lm,
                &mut objective,
                &mut free_space_ahead,
                prior,
                (pose, point_cost),
                &mut ahead.run,
            );
            let (expanded, m_step_done) =
                crf.expand_beside(model, points, config, &labels, labels_energy, &mut beside)?;
            (expanded, m_step_done.flatten().map(RunAhead::ForNewLabels))
        } else {
            (
                crf.expand(model, points, config, &labels, labels_energy)?,
                None,
            )
        };
        let new_labels = expanded.labels;
        let changed = new_labels
            .iter()
            .zip(&labels)
            .filter(|(a, b)| a != b)
            .count();
        let e = expanded.energy + pose_cost(&pose);
        let accept = e <= energy;
        if accept {
            labels = new_labels;
            energy = e;
            labels_energy = Some(expanded.energy);
        } else {
            // (Only a rounding tie could get here.) The old labels stay; their energy
            // is summed afresh if needed.
            labels_energy = None;
        }
        // Whether the M-step run ahead had the labels the next M-step starts from.
        next_m_step = match m_step_ahead {
            Some(RunAhead::ForOldLabels(m)) if changed == 0 || !accept => Some(m),
            Some(RunAhead::ForNewLabels(m)) if changed == 0 || accept => {
                ahead.used_beside_last_cycle += 1;
                Some(m)
            }
            _ => None,
        };
        ahead.used += usize::from(next_m_step.is_some());
        last_changed = Some(changed);
        trace.push(energy);
        let annealed = config.annealed_in(iterations, anneal_cut);
        if changed == 0 && !pose_moved {
            termination = EmTermination::Stationary;
            break;
        }
        let drop = energy_at_start - energy;
        let labels_settled = (changed as f64) <= config.label_change_tolerance * n as f64;
        if annealed && labels_settled && drop <= config.energy_tolerance * energy.abs() {
            termination = EmTermination::Converged;
            break;
        }
        // (Only a cut before the schedule's last step changes anything.)
        if !annealed
            && config.adaptive_anneal
            && labels_settled
            && iterations + 1 < config.anneal_iterations
        {
            let moved = model
                .joints(&pose)
                .iter()
                .zip(&model.joints(&pose_at_start))
                .map(|(a, b)| (a - b).norm())
                .fold(0.0, f64::max);
            if moved <= config.settled_joint_motion {
                // Settled at a τ still annealing: the final τ from the next iteration on.
                anneal_cut = Some(iterations);
            }
        }
    }
    let PointLabels {
        labels,
        part_counts,
        outliers,
    } = PointLabels::new(labels);
    let result = EmResult {
        pose,
        labels,
        energy,
        energy_trace: trace,
        iterations,
        termination,
        anneal_cut,
        part_counts,
        outliers,
    };
    Ok((result, ahead))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::kinematics::tests::pose_for_tests;
    use crate::body::signed_distance_to_ellipsoid;

    /// The cloud of a depth image and its 4-neighbour graph.
    fn cloud_and_graph(depth: &[f32], cam: &crate::Camera) -> (crate::cloud::Cloud, PixelGraph) {
        use crate::cloud::{neighbour_graph, Cloud, Connectivity, DepthView};
        let view = DepthView::new(depth, cam.height, cam.width, "depth").unwrap();
        let cloud = Cloud::from_depth(&view, cam, None).unwrap();
        let graph = neighbour_graph(&cloud, Connectivity::Four);
        (cloud, graph)
    }

    /// The neutral pose 2.3 m in front of the ITOP camera with one joint angle set (the
    /// truth), and the cloud and graph of its rendered depth.
    fn bent_frame(
        model: &BodyModel,
        joint: usize,
        angle: f64,
    ) -> (Pose, crate::cloud::Cloud, PixelGraph) {
        let cam = crate::Camera::itop();
        let mut truth = BodyModel::neutral_pose();
        truth[2] = 2.3;
        truth[joint] = angle;
        let (depth, _) = model.render_depth(&truth, &cam);
        let (cloud, graph) = cloud_and_graph(&depth, &cam);
        (truth, cloud, graph)
    }

    /// Running late M-steps beside the E-step before them changes nothing: the same
    /// pose, labels, energies and iterations as one step after the other, with and
    /// without the free-space term and from several starts; and it does happen.
    #[test]
    fn m_steps_run_ahead_give_the_same_em() {
        use crate::body::param;
        let model = BodyModel::default();
        let cam = crate::Camera::itop();
        let mut truth = BodyModel::neutral_pose();
        truth[2] = 2.3;
        truth[param::ROOT_R + 1] = 0.3;
        truth[param::R_SHOULDER + 1] = 0.5;
        truth[param::R_ELBOW] = 0.9;
        truth[param::L_SHOULDER + 1] = 0.3;
        truth[param::R_KNEE] = 0.4;
        let (depth, _) = model.render_depth(&truth, &cam);
        let (cloud, graph) = cloud_and_graph(&depth, &cam);
        let image = FreeSpaceImage {
            depth: &depth,
            camera: &cam,
            weight_scale: 1.0,
        };
        // The same depth with a 12×12-pixel patch 0.13 m in front of the body's middle:
        // under a slow anneal its points turn outlier only when the outlier distance
        // has shrunk past them, after the other labels have settled, so an E-step
        // changes labels after one that kept them and the M-step run beside that one
        // is discarded.
        let w = cam.width;
        let fg: Vec<usize> = (0..depth.len()).filter(|&i| depth[i] > 0.0).collect();
        let (cr, cc) = (
            fg.iter().map(|i| i / w).sum::<usize>() / fg.len(),
            fg.iter().map(|i| i % w).sum::<usize>() / fg.len(),
        );
        let mut patched = depth.clone();
        for r in cr - 6..cr + 6 {
            for c in cc - 6..cc + 6 {
                if patched[r * w + c] > 0.0 {
                    patched[r * w + c] -= 0.13;
                }
            }
        }
        let (patched_cloud, patched_graph) = cloud_and_graph(&patched, &cam);
        let slow_anneal = EmConfig {
            anneal_iterations: 12,
            max_iterations: 16,
            ..EmConfig::default()
        };
        let mut total = MStepsAhead::default();
        for seed in 1..=6 {
            let (cloud, graph, free_space, config) = match seed % 3 {
                0 => (&cloud, &graph, None, EmConfig::default()),
                1 => (&cloud, &graph, Some(image), EmConfig::default()),
                _ => (&patched_cloud, &patched_graph, None, slow_anneal),
            };
            let init = crate::fit::tests::perturbed(&truth, seed, 0.2, 0.05);
            let run = |ahead| {
                run_hard_em(
                    &model,
                    &cloud.points,
                    graph,
                    &init,
                    None,
                    None,
                    free_space,
                    &config,
                    ahead,
                )
                .unwrap()
            };
            let (one_by_one, none) = run(false);
            let (with_ahead, counts) = run(true);
            assert_eq!(none, MStepsAhead::default());
            assert!(
                one_by_one == with_ahead,
                "seed {seed}: energy traces {:?} and {:?}",
                one_by_one.energy_trace,
                with_ahead.energy_trace
            );
            total.run += counts.run;
            total.used += counts.used;
            total.used_beside_last_cycle += counts.used_beside_last_cycle;
        }
        // Both kinds used, and some discarded.
        let beside_whole_e_step = total.used - total.used_beside_last_cycle;
        assert!(
            beside_whole_e_step > 0 && total.used_beside_last_cycle > 0 && total.run > total.used,
            "{total:?}"
        );
    }

    /// The unary with lower-bound skipping and lockstep root solves equals the unary
    /// computed with one exact scalar query per point and segment.
    #[test]
    fn unary_matches_exact_distances() {
        let model = BodyModel::default();
        let config = EmConfig::default();
        for seed in 0..3u64 {
            let pose = pose_for_tests(seed + 2);
            let joints = model.joints(&pose);
            let mut s = seed * 7919 + 1;
            let mut next = || {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((s >> 11) as f64) / ((1u64 << 53) as f64) - 0.5
            };
            let points: Vec<[f32; 3]> = (0..1500)
                .map(|i| {
                    let j = joints[i % joints.len()];
                    let spread = if i % 5 == 0 { 1.5 } else { 0.3 };
                    [
                        (j.x + spread * next()) as f32,
                        (j.y + spread * next()) as f32,
                        (j.z + spread * next()) as f32,
                    ]
                })
                .collect();
            let tau = 0.1 + 0.05 * seed as f64;
            let mut unary = vec![0.0; points.len() * NUM_LABELS];
            unary_costs(&model, &points, &pose, &config, tau, &mut unary);
            let pc = config.point_cost(tau);
            let frames = model.segment_transforms(&pose);
            let ell = model.shape.ellipsoids();
            let mut saturated = 0;
            for (i, p) in points.iter().enumerate() {
                let pc3 = nalgebra::Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                for k in 0..NUM_SEGMENTS {
                    let local = frames[k].inverse_transform_point(&pc3).coords - ell[k].centre;
                    let exact = pc.cost(signed_distance_to_ellipsoid(&ell[k].radii, &local));
                    let got = unary[i * NUM_LABELS + k];
                    assert!(
                        (got - exact).abs() <= 1e-9 * exact.max(1.0),
                        "point {i} segment {k}: {got} vs exact {exact}"
                    );
                    saturated += (got == pc.cap()) as usize;
                }
                assert_eq!(
                    unary[i * NUM_LABELS + NUM_SEGMENTS],
                    config.outlier_cost(tau)
                );
            }
            // The skipping is exercised: many pairs are saturated.
            assert!(saturated > points.len() * 4, "{saturated}");
        }
    }

    /// The candidate sets the E-step computes in its unary pass (and with the cheapest
    /// labels) are those the solver collects itself, and the expansion from them ends
    /// where the solver's own does.
    #[test]
    fn e_step_candidate_sets_are_the_solvers() {
        let model = BodyModel::default();
        let (truth, cloud, graph) = bent_frame(&model, crate::body::param::R_ELBOW, 0.9);
        let (points, n) = (&cloud.points, cloud.len());
        assert_ne!(
            n % 64,
            0,
            "a last block of 64 points that is only partly used"
        );
        let config = EmConfig::default();
        let tau = config.outlier_distance_at(0);
        let mut crf = EStep::new(&graph, n, &config).unwrap();
        let start = crate::fit::tests::perturbed(&truth, 3, 0.2, 0.05);
        crf.set_all_terms(&model, points, &start, &config, tau);
        assert!(!crf.candidates_valid);
        let cheapest = crf.cheapest_labels();
        // The cheapest labels (first of equals) and, for them, the sets the solver
        // would collect.
        for (i, &l) in cheapest.iter().enumerate() {
            let row = &crf.unary[i * NUM_LABELS..(i + 1) * NUM_LABELS];
            assert!(row.iter().all(|&u| u >= row[l as usize]));
            assert!(row[..l as usize].iter().all(|&u| u > row[l as usize]));
        }
        assert!(crf.candidates_valid);
        let p = problem(&crf.unary, &graph.edges, &crf.weights);
        let want = CrfSolver::new(n, &graph.edges)
            .unwrap()
            .collected_candidate_words(&p, &cheapest);
        assert_eq!(crf.candidate_words, want);
        let labels = crf
            .expand(&model, points, &config, &cheapest, None)
            .unwrap()
            .labels;
        // Also labels off the E-step's result: every 7th point moved to another label.
        let mixed: Vec<i32> = labels
            .iter()
            .enumerate()
            .map(|(i, &l)| {
                if i % 7 == 0 {
                    (l + 3) % NUM_LABELS as i32
                } else {
                    l
                }
            })
            .collect();
        let near = crate::fit::tests::perturbed(&truth, 4, 0.1, 0.02);
        for held in [&labels, &mixed] {
            crf.set_pose(&model, points, &near, &config, tau, held, None);
            assert!(crf.candidates_valid);
            let p = problem(&crf.unary, &graph.edges, &crf.weights);
            let mut solver = CrfSolver::new(n, &graph.edges).unwrap();
            let want = solver.collected_candidate_words(&p, held);
            let members: u32 = want.iter().map(|w| w.count_ones()).sum();
            assert!(members as usize > n / 10, "{members} candidates");
            assert_eq!(crf.candidate_words, want);
            let moves = MoveConfig {
                max_cycles: config.expansion_cycles,
            };
            let own = solver
                .alpha_expansion(&p, Some(held), &moves)
                .unwrap()
                .labels;
            // With the start's energy handed over, as the EM does.
            let held_energy = crf.energy(held);
            let expanded = crf
                .expand(&model, points, &config, held, Some(held_energy))
                .unwrap();
            assert_eq!(expanded.labels, own);
            assert_eq!(expanded.energy, crf.energy(&own));
            assert!(
                !crf.candidates_valid,
                "the settled terms are not the sets' terms"
            );
        }
    }

    /// A fresh start's terms (held at guessed segments, see `EStep::at_pose`) give the
    /// cheapest labels and candidate sets of the exact terms, bit for bit; every term
    /// is exact or skipped (the cap, out of the cheapest label's reach), and the
    /// expansion from them ends where the one on exact terms does.
    #[test]
    fn fresh_start_terms_give_the_exact_cheapest_labels_and_sets() {
        let model = BodyModel::default();
        let (truth, cloud, graph) = bent_frame(&model, crate::body::param::L_ELBOW, 1.1);
        let (points, n) = (&cloud.points, cloud.len());
        let config = EmConfig::default();
        for (seed, tau) in [(7, config.outlier_distance_at(0)), (8, 0.1)] {
            let start = crate::fit::tests::perturbed(&truth, seed, 0.3, 0.08);
            let mut exact = EStep::new(&graph, n, &config).unwrap();
            exact.set_all_terms(&model, points, &start, &config, tau);
            let want = exact.cheapest_labels();
            let mut fresh =
                EStep::at_pose(&graph, &model, points, &start, &config, tau, None).unwrap();
            let got = fresh.cheapest_labels();
            assert_eq!(got, want);
            assert_eq!(fresh.candidate_words, exact.candidate_words);
            let cap = config.point_cost(tau).cap();
            let mut n_skipped = 0;
            for i in 0..n {
                let row = i * NUM_LABELS..(i + 1) * NUM_LABELS;
                let (f, e) = (&fresh.unary[row.clone()], &exact.unary[row]);
                for k in 0..NUM_LABELS {
                    if fresh.skipped[i] >> k & 1 == 1 {
                        n_skipped += 1;
                        assert_eq!(f[k], cap);
                        assert!(e[k] - e[want[i] as usize] > fresh.slack[i], "{i} {k}");
                    } else {
                        assert_eq!(f[k], e[k], "{i} {k}");
                    }
                }
            }
            assert!(n_skipped > n, "{n_skipped} terms left out");
            let a = fresh.expand(&model, points, &config, &got, None).unwrap();
            let b = exact.expand(&model, points, &config, &want, None).unwrap();
            assert_eq!(a.labels, b.labels);
        }
    }

    /// An E-step's terms with the own-label distances an M-step kept (at the pose it
    /// ended at, for the labels it fitted) are the terms it computes without them:
    /// unary terms, skipped terms and candidate sets, bit for bit, also at the smaller
    /// τ of the iterations after.
    #[test]
    fn own_distances_from_the_m_step_give_the_same_terms() {
        let model = BodyModel::default();
        let (truth, cloud, graph) = bent_frame(&model, crate::body::param::L_KNEE, 0.7);
        let (points, n) = (&cloud.points, cloud.len());
        let config = EmConfig::default();
        let tau = config.outlier_distance_at(0);
        let start = crate::fit::tests::perturbed(&truth, 5, 0.3, 0.08);
        let mut crf = EStep::at_pose(&graph, &model, points, &start, &config, tau, None).unwrap();
        let cheapest = crf.cheapest_labels();
        let labels = crf
            .expand(&model, points, &config, &cheapest, None)
            .unwrap()
            .labels;
        // Every 9th point at a segment far from it, for distances beyond the truncation.
        let labels: Vec<i32> = (labels.iter().enumerate())
            .map(|(i, &l)| match i % 9 {
                0 if l < OUTLIER => (l + 7) % NUM_SEGMENTS as i32,
                _ => l,
            })
            .collect();
        let mut objective = PointObjective::new(&model, points, &labels, config.point_cost(tau));
        let mut lm = LevenbergMarquardt::new(config.lm).unwrap();
        let (pose, report) = m_step(&mut lm, &mut objective, None, None, &start);
        assert!(report.accepted > 0);
        let mut own = vec![f64::NAN; n];
        assert!(objective.kept_distances(&pose, &labels, &mut own));
        let far = own.iter().filter(|d| d.is_infinite()).count();
        let near = own.iter().filter(|d| d.is_finite()).count();
        assert!(
            far > 0 && near > n / 2,
            "{far} beyond the truncation, {near} within"
        );
        for tau in [tau, config.outlier_distance_at(1), config.outlier_distance] {
            let mut computed = EStep::new(&graph, n, &config).unwrap();
            computed.set_pose(&model, points, &pose, &config, tau, &labels, None);
            let mut given = EStep::new(&graph, n, &config).unwrap();
            given.set_pose(&model, points, &pose, &config, tau, &labels, Some(&own));
            assert!(computed.unary == given.unary, "τ {tau}");
            assert_eq!(computed.skipped, given.skipped, "τ {tau}");
            assert_eq!(computed.candidate_words, given.candidate_words, "τ {tau}");
        }
    }

    /// With labels: the own label's term exact; every other term exact or, where
    /// skipped, the cap with an exact cost beyond the own cost plus the slack (out of
    /// the expansion's reach); `settle_unary` makes the labels' terms exact.
    #[test]
    fn unary_for_labels_skips_only_terms_out_of_reach() {
        let model = BodyModel::default();
        let config = EmConfig::default();
        let pose = pose_for_tests(3);
        let joints = model.joints(&pose);
        let mut s = 17u64;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64) / ((1u64 << 53) as f64)
        };
        let n = 2000;
        let points: Vec<[f32; 3]> = (0..n)
            .map(|i| {
                let j = joints[i % joints.len()];
                [
                    (j.x + 0.3 * (next() - 0.5)) as f32,
                    (j.y + 0.3 * (next() - 0.5)) as f32,
                    (j.z + 0.3 * (next() - 0.5)) as f32,
                ]
            })
            .collect();
        let slack: Vec<f64> = (0..n).map(|_| 8.0 * next()).collect();
        let tau = 0.15;
        let mut exact = vec![0.0; n * NUM_LABELS];
        unary_costs(&model, &points, &pose, &config, tau, &mut exact);
        // Every other point at its cheapest label (as after an E-step), the rest at random.
        let labels: Vec<i32> = (0..n)
            .map(|i| {
                let row = &exact[i * NUM_LABELS..(i + 1) * NUM_LABELS];
                match i % 2 {
                    0 => cheapest_label(row),
                    _ => (next() * 17.0) as i32 % 17,
                }
            })
            .collect();
        let mut unary = vec![-1.0; n * NUM_LABELS];
        let mut skipped = vec![u32::MAX; n];
        let held = HeldLabels {
            labels: &labels,
            slack: &slack,
            skipped: &mut skipped,
        };
        unary_costs_for_labels(&model, &points, &pose, &config, tau, held, &mut unary);
        let cap = config.point_cost(tau).cap();
        let mut n_skipped = 0;
        for i in 0..n {
            let own = exact[i * NUM_LABELS + labels[i] as usize];
            for k in 0..NUM_LABELS {
                let (got, want) = (unary[i * NUM_LABELS + k], exact[i * NUM_LABELS + k]);
                if skipped[i] >> k & 1 == 1 {
                    n_skipped += 1;
                    assert!(k != labels[i] as usize && k < NUM_SEGMENTS);
                    assert_eq!(got, cap);
                    assert!(want - own > slack[i], "point {i} segment {k}: {want} {own}");
                } else {
                    assert!(
                        (got - want).abs() <= 1e-12 * want.max(1.0),
                        "{i} {k}: {got} {want}"
                    );
                }
            }
        }
        assert!(n_skipped > n, "the skipping is exercised: {n_skipped}");
        // Points moved to a skipped segment get its exact term back.
        let moved: Vec<i32> = (0..n)
            .map(|i| match skipped[i].trailing_zeros() {
                k if k < NUM_SEGMENTS as u32 => k as i32,
                _ => labels[i],
            })
            .collect();
        let settled = settle_unary(
            &model,
            &points,
            &pose,
            &config,
            tau,
            &moved,
            &mut unary,
            &mut skipped,
        );
        assert_eq!(
            settled,
            moved.iter().zip(&labels).filter(|(a, b)| a != b).count()
        );
        for (i, &l) in moved.iter().enumerate() {
            let k = i * NUM_LABELS + l as usize;
            assert!((unary[k] - exact[k]).abs() <= 1e-12 * exact[k].max(1.0));
            assert_eq!(skipped[i] >> l & 1, 0);
        }
    }
}
