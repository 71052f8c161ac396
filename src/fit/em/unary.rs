//! The unary terms of the E-step's CRF: each point's cost for every segment and for
//! the outlier label, computed only where an expansion from the held labels can use
//! them, with the expansion's candidate sets.

use super::config::EmConfig;
use super::labels::{NUM_LABELS, OUTLIER};
use crate::body::residuals::{to_f64, PoseGeometry};
use crate::body::{BodyModel, Pose, NUM_SEGMENTS};
use crate::fit::terms::data::CHUNK_POINTS;
use crate::fit::terms::PointCost;
use crate::graphcut::expansion::potts_candidate_mask;
use rayon::prelude::*;

/// Where the unary terms are evaluated: the points (and their weights) and the model at
/// a pose, with the settings and the outlier distance τ.
#[derive(Debug, Clone, Copy)]
pub struct UnaryAt<'a> {
    pub model: &'a BodyModel,
    pub points: &'a [[f32; 3]],
    /// Per point, a weight (finite, > 0) its whole row of terms is multiplied by: how
    /// much its reading is trusted (see [`crate::fit::DepthNoise`]). None: all 1.
    pub weights: Option<&'a [f32]>,
    pub pose: &'a Pose,
    pub config: &'a EmConfig,
    pub tau: f64,
}

/// What [`fill_unary`] computes besides the terms of every point and label: with
/// `held`, only the terms an expansion from those labels can use (see
/// [`unary_costs_for_labels`]); `own`, each point's signed distance to its held label's
/// ellipsoid at the pose (as [`PointObjective::kept_distances`] writes them; read only
/// at points held at a segment), which is then not computed again; `candidates`, the
/// expansion's candidate sets for the held labels (see `CrfSolver::expansion_with`).
///
/// [`PointObjective::kept_distances`]: crate::fit::terms::data::PointObjective::kept_distances
#[derive(Default)]
pub(super) struct UnaryRequest<'a> {
    pub held: Option<HeldLabels<'a>>,
    pub own: Option<&'a [f64]>,
    pub candidates: Option<&'a mut [u64]>,
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
    let at = UnaryAt {
        model,
        points,
        weights: None,
        pose,
        config,
        tau,
    };
    fill_unary(&at, UnaryRequest::default(), unary);
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
    let at = UnaryAt {
        model,
        points,
        weights: None,
        pose,
        config,
        tau,
    };
    let request = UnaryRequest {
        held: Some(held),
        ..UnaryRequest::default()
    };
    fill_unary(&at, request, unary);
}

/// Relative margin of the skip test of [`unary_costs_for_labels`], so that rounding
/// never skips a term the expansion's own test (with the exact term) would admit.
const SKIP_MARGIN: f64 = 1e-9;

/// Words of candidate sets per chunk of points (see [`EStep::set_pose`]).
pub(super) const CANDIDATE_WORDS_PER_CHUNK: usize = CHUNK_POINTS / 64 * NUM_LABELS;

/// The unary terms at `at` into `unary` (N × [`NUM_LABELS`]), and what `request`
/// asks besides.
pub(super) fn fill_unary(at: &UnaryAt<'_>, request: UnaryRequest<'_>, unary: &mut [f64]) {
    let UnaryAt {
        model,
        points,
        weights,
        pose,
        config,
        tau,
    } = *at;
    let UnaryRequest {
        held,
        own,
        candidates,
    } = request;
    const _: () = assert!(CHUNK_POINTS.is_multiple_of(64));
    let geo = PoseGeometry::new(model, pose);
    let pc = config.point_cost(tau);
    let costs = ChunkCosts {
        geo: &geo,
        pc: &pc,
        outlier: config.outlier_cost(tau),
    };
    let chunk = |c: usize,
                 u: &mut [f64],
                 pts: &[[f32; 3]],
                 held: Option<(&[i32], &[f64], &mut [u32])>,
                 words: Option<&mut [u64]>| {
        let range = c * CHUNK_POINTS..c * CHUNK_POINTS + pts.len();
        let own = own.map(|d| &d[range.clone()]);
        let weights = weights.map(|w| &w[range]);
        let held = held.map(|(labels, slack, skipped)| ChunkHeld {
            labels,
            slack,
            skipped,
            own_distance: own,
            candidate_words: words,
        });
        unary_chunk(&costs, u, pts, held, weights)
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

/// The costs every chunk's terms are made of.
struct ChunkCosts<'a> {
    geo: &'a PoseGeometry,
    pc: &'a PointCost,
    /// The outlier label's cost.
    outlier: f64,
}

/// One chunk's held labels and what comes with them (see [`UnaryRequest`]).
struct ChunkHeld<'a> {
    labels: &'a [i32],
    slack: &'a [f64],
    skipped: &'a mut [u32],
    own_distance: Option<&'a [f64]>,
    candidate_words: Option<&'a mut [u64]>,
}

/// The points of a chunk in groups: with held labels one group per label (each
/// label's points in ascending order), else one group of all the points in order.
/// `order()[j]` is the chunk index of the j-th point; group g is `order()[range(g)]`.
struct PointGroups {
    order: [u16; CHUNK_POINTS],
    n: usize,
    start: [usize; NUM_LABELS + 1],
    groups: usize,
}

impl PointGroups {
    /// No points yet.
    #[inline(always)]
    fn new() -> Self {
        PointGroups {
            order: [0; CHUNK_POINTS],
            n: 0,
            start: [0; NUM_LABELS + 1],
            groups: 0,
        }
    }

    /// One group of the `n` points in order.
    #[inline(always)]
    fn set_all(&mut self, n: usize) {
        for (j, o) in self.order.iter_mut().enumerate() {
            *o = j as u16;
        }
        self.n = n;
        self.start[1] = n;
        self.groups = 1;
    }

    /// The points by label (counting sort), each segment's in ascending order.
    #[inline(always)]
    fn set_by_label(&mut self, labels: &[i32]) {
        let start = &mut self.start;
        for &l in labels {
            start[l.clamp(0, OUTLIER) as usize + 1] += 1;
        }
        for k in 0..NUM_LABELS {
            start[k + 1] += start[k];
        }
        let mut next = *start;
        for (i, &l) in labels.iter().enumerate() {
            let k = l.clamp(0, OUTLIER) as usize;
            self.order[next[k]] = i as u16;
            next[k] += 1;
        }
        self.n = labels.len();
        self.groups = NUM_LABELS;
    }

    #[inline(always)]
    fn order(&self) -> &[u16] {
        &self.order[..self.n]
    }

    #[inline(always)]
    fn range(&self, g: usize) -> std::ops::Range<usize> {
        self.start[g]..self.start[g + 1]
    }
}

/// A chunk's points in group order, one coordinate per array (for the vectorised
/// split of the segment terms), and each group's bounding box and largest reach (as a
/// residual; none without labels).
struct GroupedPoints {
    soa: [[f64; CHUNK_POINTS]; 3],
    boxes: [([f64; 3], [f64; 3]); NUM_LABELS],
    reach: [f64; NUM_LABELS],
}

impl GroupedPoints {
    /// One box per group: smaller blocks (of 32 points within a label) cull no more,
    /// the segments' bounding spheres being loose.
    #[inline(always)]
    fn new() -> Self {
        GroupedPoints {
            soa: [[0.0f64; CHUNK_POINTS]; 3],
            boxes: [([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]); NUM_LABELS],
            reach: [f64::INFINITY; NUM_LABELS],
        }
    }

    /// The points of `groups` (coordinates in `buf`, reaches in `reach`).
    #[inline(always)]
    fn fill(&mut self, groups: &PointGroups, buf: &[[f64; 3]], reach: &[f64; CHUNK_POINTS]) {
        let order = groups.order();
        let GroupedPoints {
            soa,
            boxes,
            reach: group_reach,
        } = self;
        for (j, &i) in order.iter().enumerate() {
            for r in 0..3 {
                soa[r][j] = buf[i as usize][r];
            }
        }
        for g in 0..groups.groups {
            let (lo, hi) = &mut boxes[g];
            let mut most = f64::NEG_INFINITY;
            for j in groups.range(g) {
                for r in 0..3 {
                    lo[r] = lo[r].min(soa[r][j]);
                    hi[r] = hi[r].max(soa[r][j]);
                }
                most = most.max(reach[order[j] as usize]);
            }
            group_reach[g] = most;
        }
    }
}

/// [`fill_unary`] for one chunk of points: every segment's term starts at the cap and
/// the outlier's at its cost; with held labels each point's own label's term is exact
/// ([`own_label_terms`]); then every segment's terms of the points near enough to need
/// the exact distance ([`segment_terms`]), each row times its point's weight, and the
/// expansion's candidate sets.
///
/// With weights the terms are computed unweighted and scaled afterwards; what limits
/// the work is the weighted rows' reach: a term k is out of an expansion's reach when
/// w·(c_k − c_own) exceeds the slack, i.e. when c_k − c_own exceeds slack / w, so the
/// unweighted computation runs with the slacks divided by the weights.
fn unary_chunk(
    costs: &ChunkCosts<'_>,
    u: &mut [f64],
    pts: &[[f32; 3]],
    held: Option<ChunkHeld<'_>>,
    weights: Option<&[f32]>,
) {
    let cap = costs.pc.cap();
    let mut buf = [[0.0f64; 3]; CHUNK_POINTS];
    let buf = to_f64(pts, &mut buf);
    // Per point: the most another label may cost and still be within the expansion's
    // reach (then as the residual of that cost).
    let mut reach = [f64::INFINITY; CHUNK_POINTS];
    // Every segment's term starts at the cap (a whole row at a time); the own label's
    // and the near points' exact costs overwrite it below.
    for row in u.chunks_exact_mut(NUM_LABELS) {
        row[..NUM_SEGMENTS].fill(cap);
        row[NUM_SEGMENTS] = costs.outlier;
    }
    let mut groups = PointGroups::new();
    let mut unweighted_slack = [0.0f64; CHUNK_POINTS];
    let (skipped, candidates) = match held {
        Some(mut held) => {
            held.skipped.fill(0);
            let slack = held.slack;
            if let Some(w) = weights {
                for ((s, &v), &w) in unweighted_slack.iter_mut().zip(slack).zip(w) {
                    *s = v / w as f64;
                }
                held.slack = &unweighted_slack[..slack.len()];
            }
            own_label_terms(costs, u, buf, &held, (&mut groups, &mut reach));
            let ChunkHeld {
                labels,
                skipped,
                candidate_words,
                ..
            } = held;
            (skipped, candidate_words.map(|w| (labels, slack, w)))
        }
        None => {
            groups.set_all(pts.len());
            (&mut [][..], None)
        }
    };
    let mut grouped = GroupedPoints::new();
    grouped.fill(&groups, buf, &reach);
    segment_terms(costs, u, &groups, &grouped, &reach, skipped);
    if let Some(w) = weights {
        for (row, &w) in u.chunks_exact_mut(NUM_LABELS).zip(w) {
            row.iter_mut().for_each(|v| *v *= w as f64);
        }
    }
    if let Some((labels, slack, words)) = candidates {
        fill_candidate_words(u, labels, slack, words);
    }
}

/// With held labels: each point's exact term for its own label, and its reach (the
/// most another label may cost and still be within the expansion's reach, as the
/// residual of that cost); the points grouped by label into `groups`.
#[inline(always)]
fn own_label_terms(
    costs: &ChunkCosts<'_>,
    u: &mut [f64],
    buf: &[[f64; 3]],
    held: &ChunkHeld<'_>,
    (groups, reach): (&mut PointGroups, &mut [f64; CHUNK_POINTS]),
) {
    let ChunkCosts { geo, pc, outlier } = *costs;
    let (labels, slack) = (held.labels, held.slack);
    for (i, &l) in labels.iter().enumerate() {
        if l == OUTLIER {
            reach[i] = outlier + slack[i];
        }
    }
    groups.set_by_label(labels);
    for (k, e) in geo.segments.iter().enumerate() {
        let mine = &groups.order[groups.range(k)];
        let mut own_cost = |i: usize, d: f64| {
            let c = pc.cost(d);
            u[i * NUM_LABELS + k] = c;
            reach[i] = c + slack[i];
        };
        match held.own_distance {
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
}

/// Every segment's terms of the points near enough to need its exact distance. A
/// group clear of the segment keeps the cap; with held labels (`skipped` not empty) a
/// group or point whose distance certainly passes its reach is left out and marked in
/// `skipped`.
#[inline(always)]
fn segment_terms(
    costs: &ChunkCosts<'_>,
    u: &mut [f64],
    groups: &PointGroups,
    grouped: &GroupedPoints,
    reach: &[f64; CHUNK_POINTS],
    skipped: &mut [u32],
) {
    let ChunkCosts { geo, pc, .. } = *costs;
    let known = !skipped.is_empty();
    let (order, soa) = (groups.order(), &grouped.soa);
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
        for g in 0..groups.groups {
            let range = groups.range(g);
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
            let (lo, hi) = &grouped.boxes[g];
            let gap2: f64 = (0..3)
                .map(|r| (lo[r] - c[r]).max(c[r] - hi[r]).max(0.0).powi(2))
                .sum();
            if pc.truncation > 0.0 && gap2 >= clear_truncation * clear_truncation {
                continue;
            }
            if known {
                let clear_reach = margin(e.max_radius() + grouped.reach[g]);
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
            // would be mispredicted often.
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
}

/// The expansion's candidate sets for one chunk of points from their finished rows `u`,
/// labels and slacks: bit i % 64 of word (i / 64, a) where point i may switch to label
/// a.
pub(super) fn fill_candidate_words(u: &[f64], labels: &[i32], slack: &[f64], words: &mut [u64]) {
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
/// units of its largest half-axis (a tighter guess than the nearest bounding sphere, so
/// more terms are left out).
pub(super) fn nearest_segment_guess(
    model: &BodyModel,
    points: &[[f32; 3]],
    pose: &Pose,
) -> Vec<i32> {
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
pub(super) fn cheapest_label(row: &[f64]) -> i32 {
    (0..row.len())
        .min_by(|&a, &b| row[a].total_cmp(&row[b]))
        .unwrap_or(0) as i32
}

/// After an E-step on terms from [`unary_costs_for_labels`] at `at`: the exact cost of
/// every point that ended at a segment whose term was skipped (rare), so that the
/// energy of `labels` is exact. Returns how many terms were settled.
pub fn settle_unary(
    at: &UnaryAt<'_>,
    labels: &[i32],
    unary: &mut [f64],
    skipped: &mut [u32],
) -> usize {
    let UnaryAt {
        model,
        points,
        weights,
        pose,
        config,
        tau,
    } = *at;
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
        let w = weights.map_or(1.0, |w| w[i] as f64);
        unary[i * NUM_LABELS + k] = w * pc.cost(e.signed_distance_local(&y));
        skipped[i] &= !(1 << k);
        settled += 1;
    }
    settled
}
