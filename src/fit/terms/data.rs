//! The data term of the M-step: labelled points against their segment ellipsoids.
//!
//! For a point p with label k the residual is its signed distance r to ellipsoid k and
//! its cost is ρ(r)/σ², where ρ is the (optionally robust) loss, truncated to the
//! constant ρ(T) beyond |r| > T (the truncation matches the E-step's unary, so the
//! M-step minimises exactly the E1 part of the EM energy). The Gauss–Newton system uses
//! IRLS weights w = ρ'(r)/r. Accumulation runs over fixed chunks of points in parallel,
//! each chunk into its own preallocated accumulator, summed afterwards in chunk order,
//! so the result is deterministic and no allocation happens per call once the buffers
//! have grown to the cloud size.

pub use super::loss::{Loss, PointCost};
use crate::body::ellipsoid::SortedPlacement;
use crate::body::residuals::{group_by_segment, PoseGeometry};
use crate::body::{BodyModel, Pose, NUM_SEGMENTS};
use crate::fit::system::{
    accumulate_row, add_segment_moments, mirror_upper, PoseObjective, N, NN, SYM6,
};
use rayon::prelude::*;

/// Points per parallel chunk.
pub const CHUNK_POINTS: usize = 512;

/// One chunk's share of the normal equations, per segment: with q = (n, p × n) of each
/// weighted point (see [`PoseGeometry::dof_basis`]), the upper triangle of Σ w q qᵀ and
/// Σ w r q. The segment's parameters enter only when the chunks are summed.
#[derive(Clone)]
struct Accumulator {
    qq: [[f64; SYM6]; NUM_SEGMENTS],
    qr: [[f64; 6]; NUM_SEGMENTS],
}

impl Default for Accumulator {
    fn default() -> Self {
        Accumulator {
            qq: [[0.0; SYM6]; NUM_SEGMENTS],
            qr: [[0.0; 6]; NUM_SEGMENTS],
        }
    }
}

/// Σ over labelled points of ρ(r)/σ², r = signed distance to the label's ellipsoid.
/// Labels outside 0..[`NUM_SEGMENTS`] (outliers, background) are skipped.
///
/// The labelled points are visited grouped by segment, so that each segment's exact
/// distances go through the lockstep root-finder a few points at a time. The distances
/// and normals of the last pose evaluated are kept: LM asks for the cost at a trial
/// pose and, when it accepts the step, for the normal equations at that same pose,
/// which then need only the Jacobian.
pub struct PointObjective<'a> {
    // Private: the kept evaluation is valid only for these (see `relabel`).
    model: &'a BodyModel,
    points: &'a [[f32; 3]],
    /// Per point: the weight its cost is multiplied by (see [`Self::with_weights`]).
    weights: Option<&'a [f32]>,
    point_cost: PointCost,
    /// The labels of the points (as given to `relabel`).
    labels: Vec<i32>,
    /// Indices of the labelled points, by segment (ascending), in input order within.
    order: Vec<u32>,
    /// The segment of each entry of `order`.
    segment: Vec<u8>,
    /// Per entry of `order` at the pose `evaluated`: the signed distance (infinite when
    /// the lower bound already passes the truncation) and the camera-frame normal.
    distance: Vec<f64>,
    normal: Vec<[f64; 3]>,
    /// Per chunk of `order` at the pose `evaluated`: Σ cost.
    partial_costs: Vec<f64>,
    evaluated: Option<Pose>,
    chunks: Vec<Accumulator>,
    /// Per entry of `order` in the last evaluation: whether its distance was computed
    /// there (not taken from `start`).
    computed: Vec<bool>,
    /// The evaluation the last `relabel` replaced (an M-step's last pose, usually).
    replaced: Evaluation,
    /// Distances at an M-step's start pose, by point (see [`StartDistances`]).
    start: StartDistances,
    /// Set by `relabel` with new labels: the next evaluation is an M-step's start.
    starting: bool,
}

/// One evaluation's entries in `order`'s layout, and where it was made.
#[derive(Default)]
struct Evaluation {
    order: Vec<u32>,
    segment: Vec<u8>,
    distance: Vec<f64>,
    normal: Vec<[f64; 3]>,
    pose: Option<Pose>,
    /// The truncation an infinite distance is known to pass.
    truncation: f64,
}

/// Each point's signed distance and normal at one pose, for the segment it had when
/// they were computed. An EM's M-step starts at the pose the one before it ended at
/// (its evaluation is `relabel`'s `replaced`), and the M-steps run ahead beside an
/// E-step's cycles all start at the same pose, each with labels that mostly did not
/// change: their first evaluation computes only the points whose segment is new.
/// Taken values are the computed ones bit for bit, so results do not change.
#[derive(Default)]
struct StartDistances {
    pose: Option<Pose>,
    /// An infinite distance is known to pass this truncation (the smallest of those in
    /// force where the entries were computed).
    truncation: f64,
    /// Per point; [`NO_SEGMENT`] where nothing is known.
    segment: Vec<u8>,
    distance: Vec<f64>,
    normal: Vec<[f64; 3]>,
}

const NO_SEGMENT: u8 = u8::MAX;

impl StartDistances {
    /// Forgets every entry and starts over at `pose`.
    fn reset(&mut self, pose: &Pose, truncation: f64, n: usize) {
        self.pose = Some(*pose);
        self.truncation = truncation;
        self.segment.clear();
        self.segment.resize(n, NO_SEGMENT);
        self.distance.resize(n, 0.0);
        self.normal.resize(n, [0.0; 3]);
    }

    /// The entry of point `i` for segment `k` where it can stand for a new evaluation
    /// under `truncation`: a finite distance always, an infinite one only if it passes
    /// this truncation too.
    #[inline]
    fn known(&self, i: usize, k: usize, truncation: f64) -> Option<(f64, [f64; 3])> {
        let d = self.distance[i];
        (self.segment[i] == k as u8 && (d.is_finite() || truncation <= self.truncation))
            .then(|| (d, self.normal[i]))
    }

    /// Records the entries of `order` (those with `keep`) at the kept pose.
    fn record(
        &mut self,
        truncation: f64,
        order: &[u32],
        segment: &[u8],
        distance: &[f64],
        normal: &[[f64; 3]],
        keep: impl Fn(usize) -> bool,
    ) {
        self.truncation = self.truncation.min(truncation);
        for (r, &i) in order.iter().enumerate() {
            if keep(r) {
                let i = i as usize;
                self.segment[i] = segment[r];
                self.distance[i] = distance[r];
                self.normal[i] = normal[r];
            }
        }
    }
}

impl<'a> PointObjective<'a> {
    /// `points` and `labels` must have the same length (checked by the callers that
    /// take user input).
    pub fn new(
        model: &'a BodyModel,
        points: &'a [[f32; 3]],
        labels: &[i32],
        point_cost: PointCost,
    ) -> Self {
        let mut objective = PointObjective {
            model,
            points,
            weights: None,
            point_cost,
            labels: Vec::new(),
            order: Vec::new(),
            segment: Vec::new(),
            distance: Vec::new(),
            normal: Vec::new(),
            partial_costs: Vec::new(),
            evaluated: None,
            chunks: Vec::new(),
            computed: Vec::new(),
            replaced: Evaluation::default(),
            start: StartDistances::default(),
            starting: false,
        };
        objective.relabel(labels, point_cost);
        objective
    }

    /// The same objective with each point's cost multiplied by its weight (one per
    /// point, finite and > 0, checked by the callers): Σ wᵢ·ρ(rᵢ)/σ², for points whose
    /// depth is known to different precision (see [`crate::fit::DepthNoise`]).
    pub fn with_weights(mut self, weights: Option<&'a [f32]>) -> Self {
        debug_assert!(weights.is_none_or(|w| w.len() == self.points.len()));
        self.weights = weights;
        self.evaluated = None;
        self
    }

    /// New labels (and cost settings) for the same points, reusing the buffers: the EM
    /// loop calls this once per M-step instead of building a new objective.
    ///
    /// With the labels it has already, the kept evaluation stays (an EM whose E-step
    /// left the labels as they were starts its next M-step at the pose the last one
    /// ended at): its chunk costs are recomputed for a new `point_cost`, or it is
    /// dropped if the truncation grows (a distance known only to pass the old
    /// truncation need not pass a larger one).
    pub fn relabel(&mut self, labels: &[i32], point_cost: PointCost) {
        debug_assert_eq!(self.points.len(), labels.len());
        if self.labels == labels {
            if point_cost != self.point_cost {
                if point_cost.truncation > self.point_cost.truncation {
                    self.evaluated = None;
                } else if self.evaluated.is_some() {
                    let weights = self.weights;
                    self.order
                        .par_chunks(CHUNK_POINTS)
                        .zip(self.distance.par_chunks(CHUNK_POINTS))
                        .zip(self.partial_costs.par_iter_mut())
                        .for_each(|((idx, dist), cost)| {
                            *cost = chunk_cost(idx, dist, &point_cost, weights)
                        });
                }
                self.point_cost = point_cost;
            }
            return;
        }
        if self.evaluated.is_some() {
            // Kept for the next evaluation (see `StartDistances`); its buffers take
            // the replaced one's.
            let r = &mut self.replaced;
            std::mem::swap(&mut self.order, &mut r.order);
            std::mem::swap(&mut self.segment, &mut r.segment);
            std::mem::swap(&mut self.distance, &mut r.distance);
            std::mem::swap(&mut self.normal, &mut r.normal);
            r.pose = self.evaluated;
            r.truncation = self.point_cost.truncation;
        }
        self.starting = true;
        self.labels.clear();
        self.labels.extend_from_slice(labels);
        self.order.resize(labels.len(), 0);
        let start = group_by_segment(labels, &mut self.order);
        let m = start[NUM_SEGMENTS];
        self.order.truncate(m);
        self.segment.clear();
        for k in 0..NUM_SEGMENTS {
            self.segment.resize(start[k + 1], k as u8);
        }
        let n_chunks = m.div_ceil(CHUNK_POINTS);
        self.distance.resize(m, 0.0);
        self.normal.resize(m, [0.0; 3]);
        self.computed.resize(m, true);
        self.partial_costs.resize(n_chunks, 0.0);
        self.chunks.resize_with(n_chunks, Accumulator::default);
        self.point_cost = point_cost;
        self.evaluated = None;
    }

    /// Whether the kept evaluation is at `pose`.
    fn evaluated_at(&self, pose: &Pose) -> bool {
        self.evaluated.as_ref() == Some(pose)
    }

    /// When the kept evaluation is at `pose` for `labels`: writes each labelled
    /// point's signed distance to its segment's ellipsoid into `out` (by point index;
    /// the other entries are left as they are) and returns true. The values are those
    /// of [`crate::body::ellipsoid::SortedPlacement::signed_distances_batched`] at `pose`, except
    /// that a distance certainly beyond the truncation may be infinite (it costs the
    /// cap either way, also under any smaller truncation). The E-step after an M-step
    /// takes its points' own-label terms from here instead of computing them again.
    pub fn kept_distances(&self, pose: &Pose, labels: &[i32], out: &mut [f64]) -> bool {
        if !self.evaluated_at(pose) || self.labels != labels || out.len() != labels.len() {
            return false;
        }
        for (&i, &d) in self.order.iter().zip(&self.distance) {
            out[i as usize] = d;
        }
        true
    }

    /// Distances, normals and chunk costs at `pose` with its geometry `geo` (kept until
    /// another pose comes). Only the first evaluation after new labels (an M-step's
    /// start) takes known distances (see [`StartDistances`]); LM's trials never come
    /// back to a start, and every other evaluation computes all of its own.
    fn evaluate(&mut self, pose: &Pose, geo: &PoseGeometry) {
        let (points, pc, n) = (self.points, self.point_cost, self.points.len());
        let weights = self.weights;
        let replaced = &mut self.replaced;
        if self.starting && replaced.pose.as_ref() == Some(pose) {
            // The last M-step ended here: its entries join the start pose's.
            if self.start.pose.as_ref() != Some(pose) {
                self.start.reset(pose, replaced.truncation, n);
            }
            let r = &*replaced;
            self.start.record(
                r.truncation,
                &r.order,
                &r.segment,
                &r.distance,
                &r.normal,
                |_| true,
            );
            replaced.pose = None;
        }
        let reuse = self.starting && self.start.pose.as_ref() == Some(pose);
        let start = &self.start;
        self.order
            .par_chunks(CHUNK_POINTS)
            .zip(self.segment.par_chunks(CHUNK_POINTS))
            .zip(self.distance.par_chunks_mut(CHUNK_POINTS))
            .zip(self.normal.par_chunks_mut(CHUNK_POINTS))
            .zip(self.computed.par_chunks_mut(CHUNK_POINTS))
            .zip(self.partial_costs.par_iter_mut())
            .for_each(|(((((idx, seg), dist), normal), computed), cost)| {
                let mut near_buf = [(0usize, [0.0f64; 3]); CHUNK_POINTS];
                for (k, run) in segment_runs(seg) {
                    let e = &geo.segments[k];
                    let point = |r: usize| (r, vec3(&points[idx[r] as usize]));
                    if reuse {
                        let mut taken = [false; CHUNK_POINTS];
                        for r in run.clone() {
                            if let Some(known) = start.known(idx[r] as usize, k, pc.truncation) {
                                taken[r] = true;
                                (dist[r], normal[r]) = known;
                            }
                        }
                        let items = run.clone().filter(|&r| !taken[r]).map(point);
                        distances_into(e, pc.truncation, items, dist, normal, &mut near_buf);
                        for r in run {
                            computed[r] = !taken[r];
                        }
                    } else {
                        let items = run.clone().map(point);
                        distances_into(e, pc.truncation, items, dist, normal, &mut near_buf);
                        computed[run].fill(true);
                    }
                }
                *cost = chunk_cost(idx, dist, &pc, weights);
            });
        if self.starting {
            if !reuse {
                self.start.reset(pose, pc.truncation, n);
            }
            let computed = &self.computed;
            self.start.record(
                pc.truncation,
                &self.order,
                &self.segment,
                &self.distance,
                &self.normal,
                |r| computed[r],
            );
        }
        self.starting = false;
        self.evaluated = Some(*pose);
    }

    /// Entries of the last evaluation whose distance was computed there (the others
    /// were known at its pose: an M-step's start, after new labels).
    pub fn distances_computed(&self) -> usize {
        self.computed.iter().filter(|&&c| c).count()
    }

    fn total_cost(&self) -> f64 {
        self.partial_costs.iter().sum()
    }
}

/// The signed distances and normals of `items` (entries of a chunk with their points)
/// to `e` into `dist` and `normal`; an entry certainly beyond `truncation` gets an
/// infinite distance (constant cost, zero weight) and no normal.
fn distances_into(
    e: &SortedPlacement,
    truncation: f64,
    items: impl Iterator<Item = (usize, [f64; 3])>,
    dist: &mut [f64],
    normal: &mut [[f64; 3]],
    near_buf: &mut [(usize, [f64; 3])],
) {
    let near = e.split_near(truncation, items, |r| dist[r] = f64::INFINITY, near_buf);
    e.distances_and_normals_batched(near.iter().copied(), |r, d, n| {
        dist[r] = d;
        normal[r] = n;
    });
}

/// Σ cost over one chunk's distances (of the points `idx`), in order, each times its
/// point's weight if there are weights (the kept chunk costs; `relabel` recomputes them
/// the same way for a new `PointCost`).
fn chunk_cost(idx: &[u32], dist: &[f64], pc: &PointCost, weights: Option<&[f32]>) -> f64 {
    match weights {
        None => dist.iter().map(|&d| pc.cost(d)).sum(),
        Some(w) => idx
            .iter()
            .zip(dist)
            .map(|(&i, &d)| w[i as usize] as f64 * pc.cost(d))
            .sum(),
    }
}

/// The runs of equal segment in `seg` (a chunk of a segment-sorted order): (segment,
/// index range).
fn segment_runs(seg: &[u8]) -> impl Iterator<Item = (usize, std::ops::Range<usize>)> + '_ {
    let mut start = 0;
    std::iter::from_fn(move || {
        let k = *seg.get(start)?;
        let len = seg[start..].iter().take_while(|&&s| s == k).count();
        let run = start..start + len;
        start += len;
        Some((k as usize, run))
    })
}

#[inline]
fn vec3(p: &[f32; 3]) -> [f64; 3] {
    [p[0] as f64, p[1] as f64, p[2] as f64]
}

impl PoseObjective for PointObjective<'_> {
    fn cost(&mut self, pose: &Pose) -> f64 {
        if !self.evaluated_at(pose) {
            let geo = PoseGeometry::new(self.model, pose);
            self.evaluate(pose, &geo);
        }
        self.total_cost()
    }

    fn normal_equations(&mut self, pose: &Pose, h: &mut [f64; NN], g: &mut [f64; N]) -> f64 {
        let geo = PoseGeometry::new(self.model, pose);
        if !self.evaluated_at(pose) {
            self.evaluate(pose, &geo);
        }
        let (points, pc, weights) = (self.points, self.point_cost, self.weights);
        self.chunks
            .par_iter_mut()
            .zip(self.order.par_chunks(CHUNK_POINTS))
            .zip(self.segment.par_chunks(CHUNK_POINTS))
            .zip(self.distance.par_chunks(CHUNK_POINTS))
            .zip(self.normal.par_chunks(CHUNK_POINTS))
            .for_each(|((((acc, idx), seg), dist), normal)| {
                *acc = Accumulator::default();
                for (k, run) in segment_runs(seg) {
                    // Local copies keep the 27 sums in registers.
                    let (mut qq, mut qr) = (acc.qq[k], acc.qr[k]);
                    for r in run {
                        let d = dist[r];
                        let (_, mut w) = pc.cost_and_weight(d);
                        if w == 0.0 {
                            continue;
                        }
                        if let Some(weights) = weights {
                            w *= weights[idx[r] as usize] as f64;
                        }
                        let p = vec3(&points[idx[r] as usize]);
                        accumulate_row(&p, &normal[r], d, w, &mut qq, &mut qr);
                    }
                    acc.qq[k] = qq;
                    acc.qr[k] = qr;
                }
            });
        h.fill(0.0);
        g.fill(0.0);
        for k in 0..NUM_SEGMENTS {
            // The chunks' sums in chunk order (deterministic).
            let (mut qq, mut qr) = ([0.0; SYM6], [0.0; 6]);
            for acc in &self.chunks {
                for (o, v) in qq.iter_mut().zip(&acc.qq[k]) {
                    *o += v;
                }
                for (o, v) in qr.iter_mut().zip(&acc.qr[k]) {
                    *o += v;
                }
            }
            add_segment_moments(&geo, k, &qq, &qr, h, g);
        }
        mirror_upper(h);
        self.total_cost()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::kinematics::tests::pose_for_tests;
    use crate::body::pose_with_root_increment;
    use nalgebra::Vector3;

    fn scattered(model: &BodyModel, pose: &Pose, n: usize) -> (Vec<[f32; 3]>, Vec<i32>) {
        let joints = model.joints(pose);
        let mut s = 12345u64;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64) / ((1u64 << 53) as f64) - 0.5
        };
        let pts: Vec<[f32; 3]> = (0..n)
            .map(|i| {
                let j = joints[i % 15];
                [
                    (j.x + 0.2 * next()) as f32,
                    (j.y + 0.2 * next()) as f32,
                    (j.z + 0.2 * next()) as f32,
                ]
            })
            .collect();
        let labels = (0..n)
            .map(|i| if i % 7 == 6 { -1 } else { (i % 17) as i32 })
            .collect();
        (pts, labels)
    }

    /// The gradient g = JᵀWr matches finite differences of the cost for every loss.
    #[test]
    fn gradient_matches_finite_differences() {
        let model = BodyModel::default();
        let pose = pose_for_tests(4);
        let (pts, labels) = scattered(&model, &pose, 1500);
        for loss in [Loss::Squared, Loss::Huber(0.03), Loss::Cauchy(0.04)] {
            let pc = PointCost {
                sigma: 0.03,
                loss,
                truncation: 0.5,
            };
            let mut obj = PointObjective::new(&model, &pts, &labels, pc);
            let (mut h, mut g) = ([0.0; NN], [0.0; N]);
            let c = obj.normal_equations(&pose, &mut h, &mut g);
            assert!((c - obj.cost(&pose)).abs() < 1e-9 * c.max(1.0));
            let eps = 1e-6;
            for dof in 0..N {
                let (plus, minus) = if (3..6).contains(&dof) {
                    let mut w = Vector3::zeros();
                    w[dof - 3] = eps;
                    (
                        pose_with_root_increment(&pose, &w),
                        pose_with_root_increment(&pose, &-w),
                    )
                } else {
                    let (mut a, mut b) = (pose, pose);
                    a[dof] += eps;
                    b[dof] -= eps;
                    (a, b)
                };
                let fd = (obj.cost(&plus) - obj.cost(&minus)) / (2.0 * eps);
                assert!(
                    (fd - g[dof]).abs() <= 1e-4 * fd.abs().max(g[dof].abs()).max(1.0),
                    "{loss:?} dof {dof}: fd {fd} vs {}",
                    g[dof]
                );
            }
            // Symmetric and positive semi-definite diagonal.
            for i in 0..N {
                assert!(h[i * N + i] >= 0.0);
                for j in 0..N {
                    assert_eq!(h[i * N + j], h[j * N + i]);
                }
            }
        }
    }

    /// With per-point weights the cost is Σ wᵢ·costᵢ (the sum, over groups of points of
    /// one weight, of weight times the group's unweighted cost) and the gradient
    /// matches finite differences of it.
    #[test]
    fn weighted_cost_and_gradient() {
        let model = BodyModel::default();
        let pose = pose_for_tests(2);
        let (pts, labels) = scattered(&model, &pose, 1200);
        let group_weight = |g: usize| 0.3 + 0.4 * g as f32;
        let weights: Vec<f32> = (0..pts.len()).map(|i| group_weight(i % 4)).collect();
        let pc = PointCost {
            sigma: 0.03,
            loss: Loss::Huber(0.03),
            truncation: 0.4,
        };
        let mut obj = PointObjective::new(&model, &pts, &labels, pc).with_weights(Some(&weights));
        let by_group: f64 = (0..4)
            .map(|g| {
                let only: Vec<i32> = (0..pts.len())
                    .map(|i| if i % 4 == g { labels[i] } else { -1 })
                    .collect();
                let c = PointObjective::new(&model, &pts, &only, pc).cost(&pose);
                group_weight(g) as f64 * c
            })
            .sum();
        let c = obj.cost(&pose);
        assert!((c - by_group).abs() <= 1e-9 * c, "{c} vs {by_group}");
        let (mut h, mut g) = ([0.0; NN], [0.0; N]);
        obj.normal_equations(&pose, &mut h, &mut g);
        let eps = 1e-6;
        for dof in 6..N {
            let (mut a, mut b) = (pose, pose);
            a[dof] += eps;
            b[dof] -= eps;
            let fd = (obj.cost(&a) - obj.cost(&b)) / (2.0 * eps);
            assert!(
                (fd - g[dof]).abs() <= 1e-4 * fd.abs().max(g[dof].abs()).max(1.0),
                "dof {dof}: fd {fd} vs {}",
                g[dof]
            );
        }
    }

    /// The normal equations, summed per segment as Bᵀ(QᵀWQ)B, equal JᵀWJ and JᵀWr
    /// built from the explicit Jacobian rows of [`BodyModel::residuals_and_jacobian`].
    #[test]
    fn normal_equations_equal_explicit_jacobian_products() {
        let model = BodyModel::default();
        for (seed, loss) in [
            (1, Loss::Squared),
            (4, Loss::Huber(0.03)),
            (7, Loss::Cauchy(0.04)),
        ] {
            let pose = pose_for_tests(seed);
            let (pts, labels) = scattered(&model, &pose, 2000);
            let labels: Vec<i32> = labels
                .iter()
                .map(|&l| if l < NUM_SEGMENTS as i32 { l } else { -1 })
                .collect();
            let pc = PointCost {
                sigma: 0.03,
                loss,
                truncation: 0.4,
            };
            let mut obj = PointObjective::new(&model, &pts, &labels, pc);
            let (mut h, mut g) = ([0.0; NN], [0.0; N]);
            obj.normal_equations(&pose, &mut h, &mut g);
            let n = pts.len();
            let (mut r, mut jac) = (vec![0.0; n], vec![0.0; n * N]);
            model
                .residuals_and_jacobian(&pts, &labels, &pose, &mut r, &mut jac)
                .unwrap();
            let (mut h_ref, mut g_ref) = ([0.0; NN], [0.0; N]);
            let mut weighted = 0;
            for i in (0..n).filter(|&i| labels[i] >= 0) {
                let (_, w) = pc.cost_and_weight(r[i]);
                weighted += (w > 0.0) as usize;
                let row = &jac[i * N..(i + 1) * N];
                for a in 0..N {
                    g_ref[a] += w * row[a] * r[i];
                    for b in 0..N {
                        h_ref[a * N + b] += w * row[a] * row[b];
                    }
                }
            }
            assert!(weighted > 500, "{weighted} weighted points");
            let scale = h_ref.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for (i, (x, y)) in h.iter().zip(&h_ref).enumerate() {
                assert!(
                    (x - y).abs() <= 1e-10 * scale,
                    "{loss:?} H[{i}]: {x} vs {y}"
                );
            }
            let scale = g_ref.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for (i, (x, y)) in g.iter().zip(&g_ref).enumerate() {
                assert!(
                    (x - y).abs() <= 1e-10 * scale,
                    "{loss:?} g[{i}]: {x} vs {y}"
                );
            }
        }
    }

    /// The kept distances are those of the pose asked for: the normal equations after
    /// costs at other poses (and after a cost at the same pose) equal a fresh
    /// objective's, bit for bit, and so does the cost.
    #[test]
    fn kept_evaluation_follows_the_pose() {
        let model = BodyModel::default();
        let (a, b) = (pose_for_tests(2), pose_for_tests(5));
        let (pts, labels) = scattered(&model, &a, 2500);
        let pc = PointCost {
            sigma: 0.03,
            loss: Loss::Huber(0.03),
            truncation: 0.15,
        };
        let fresh = |pose: &Pose| {
            let mut obj = PointObjective::new(&model, &pts, &labels, pc);
            let (mut h, mut g) = ([0.0; NN], [0.0; N]);
            let c = obj.normal_equations(pose, &mut h, &mut g);
            (c, h, g)
        };
        let (ca, ha, ga) = fresh(&a);
        let (cb, hb, gb) = fresh(&b);
        assert_ne!(ca, cb);
        let mut obj = PointObjective::new(&model, &pts, &labels, pc);
        let (mut h, mut g) = ([0.0; NN], [0.0; N]);
        for (pose, c, hh, gg) in [(&a, ca, ha, ga), (&b, cb, hb, gb), (&a, ca, ha, ga)] {
            assert_eq!(obj.cost(pose), c);
            assert_eq!(obj.normal_equations(pose, &mut h, &mut g), c);
            assert_eq!((h, g), (hh, gg));
            let other = if pose == &a { &b } else { &a };
            obj.cost(other);
            assert_eq!(obj.normal_equations(pose, &mut h, &mut g), c);
            assert_eq!((h, g), (hh, gg));
        }
    }

    /// An objective relabelled (fewer, then more labelled points; other cost settings;
    /// the same labels with a smaller, then a larger truncation) gives what a fresh
    /// objective for those labels gives, bit for bit. With the same labels the kept
    /// evaluation stays exactly while the truncation does not grow.
    #[test]
    fn relabel_equals_a_fresh_objective() {
        let model = BodyModel::default();
        let pose = pose_for_tests(6);
        let (pts, labels) = scattered(&model, &pose, 3000);
        let fewer: Vec<i32> = labels
            .iter()
            .enumerate()
            .map(|(i, &l)| if i % 3 == 0 { -1 } else { (l + 1) % 15 })
            .collect();
        let pc = |t: f64| PointCost {
            sigma: 0.02,
            loss: Loss::Cauchy(0.05),
            truncation: t,
        };
        let system = |obj: &mut PointObjective| {
            let (mut h, mut g) = ([0.0; NN], [0.0; N]);
            let c = obj.normal_equations(&pose, &mut h, &mut g);
            (c, h, g)
        };
        let mut reused = PointObjective::new(&model, &pts, &labels, pc(0.3));
        system(&mut reused);
        let steps = [
            (&fewer, 0.2, false),
            (&labels, 0.25, false),
            (&labels, 0.25, true),
            (&labels, 0.15, true),
            (&labels, 0.2, false),
        ];
        for (labs, t, kept) in steps {
            reused.relabel(labs, pc(t));
            assert_eq!(reused.evaluated_at(&pose), kept, "{t}");
            let mut fresh = PointObjective::new(&model, &pts, labs, pc(t));
            if kept {
                // The kept evaluation's cost, before any new evaluation.
                assert_eq!(reused.cost(&pose), fresh.cost(&pose));
            }
            assert_eq!(system(&mut reused), system(&mut fresh));
        }
    }

    /// An M-step's first evaluation at a pose where distances are known — from the
    /// evaluation `relabel` replaced, and from earlier starts there, also after
    /// evaluations elsewhere in between (an M-step abandoned part-way) — computes only
    /// the points whose segment is new there, plus those known only as "beyond a
    /// smaller truncation" when the truncation grows; its cost and normal equations
    /// equal a fresh objective's bit for bit at every step.
    #[test]
    fn a_start_evaluation_computes_only_the_points_with_new_segments() {
        let model = BodyModel::default();
        let (pose, elsewhere) = (pose_for_tests(4), pose_for_tests(7));
        let (pts, la) = scattered(&model, &pose, 3000);
        let labelled = |l: i32| (0..NUM_SEGMENTS as i32).contains(&l);
        let lb: Vec<i32> = la
            .iter()
            .enumerate()
            .map(|(i, &l)| match i {
                _ if i % 11 == 0 => -1,
                _ if i % 5 == 0 && labelled(l) => (l + 3) % NUM_SEGMENTS as i32,
                _ => l,
            })
            .collect();
        // Points labelled in both with another segment in `lb`.
        let moved = (0..pts.len())
            .filter(|&i| labelled(la[i]) && labelled(lb[i]) && la[i] != lb[i])
            .count();
        assert!(moved > 200, "{moved}");
        let pc = |t: f64| PointCost {
            sigma: 0.02,
            loss: Loss::Cauchy(0.05),
            truncation: t,
        };
        let system = |obj: &mut PointObjective, at: &Pose| {
            let (mut h, mut g) = ([0.0; NN], [0.0; N]);
            let c = obj.normal_equations(at, &mut h, &mut g);
            (c, h, g)
        };
        let fresh = |labels: &[i32], t: f64, at: &Pose| {
            system(&mut PointObjective::new(&model, &pts, labels, pc(t)), at)
        };
        let all = |labels: &[i32]| labels.iter().filter(|&&l| labelled(l)).count();

        let mut obj = PointObjective::new(&model, &pts, &la, pc(0.2));
        assert_eq!(system(&mut obj, &pose), fresh(&la, 0.2, &pose));
        assert_eq!(obj.distances_computed(), all(&la));
        // A trial elsewhere: nothing known there.
        assert_eq!(obj.cost(&elsewhere), fresh(&la, 0.2, &elsewhere).0);
        assert_eq!(obj.distances_computed(), all(&la));
        // New labels at the first pose (the last evaluation was elsewhere): the first
        // start's distances serve.
        obj.relabel(&lb, pc(0.15));
        assert_eq!(system(&mut obj, &pose), fresh(&lb, 0.15, &pose));
        assert_eq!(obj.distances_computed(), moved);
        // Back to the first labels: the points `lb` moved are known for their `lb`
        // segment only; those `lb` left unlabelled are still known from the first start.
        obj.relabel(&la, pc(0.15));
        assert_eq!(system(&mut obj, &pose), fresh(&la, 0.15, &pose));
        assert_eq!(obj.distances_computed(), moved);
        // A larger truncation: distances known only to pass 0.15 are computed again.
        let beyond = (0..pts.len())
            .filter(|&i| labelled(lb[i]) && lb[i] == la[i] && obj.start.distance[i].is_infinite())
            .count();
        assert!(beyond > 0);
        obj.relabel(&lb, pc(0.3));
        assert_eq!(system(&mut obj, &pose), fresh(&lb, 0.3, &pose));
        assert_eq!(obj.distances_computed(), moved + beyond);
        // Trials elsewhere and back, as LM makes them, stay exact; past the start every
        // evaluation computes all of its distances (also back at the start's pose).
        assert_eq!(obj.cost(&elsewhere), fresh(&lb, 0.3, &elsewhere).0);
        assert_eq!(obj.distances_computed(), all(&lb));
        assert_eq!(system(&mut obj, &pose), fresh(&lb, 0.3, &pose));
        assert_eq!(obj.distances_computed(), all(&lb));
    }

    /// `kept_distances` gives each labelled point's distance to its segment at the
    /// kept evaluation's pose (the batched query's value, or infinite only where that
    /// passes the truncation), leaves the other points alone, and gives nothing for
    /// another pose or other labels.
    #[test]
    fn kept_distances_are_the_evaluations() {
        let model = BodyModel::default();
        let pose = pose_for_tests(5);
        let (pts, labels) = scattered(&model, &pose, 2000);
        let pc = PointCost {
            sigma: 0.02,
            loss: Loss::Squared,
            truncation: 0.1,
        };
        let mut obj = PointObjective::new(&model, &pts, &labels, pc);
        let mut out = vec![f64::NAN; pts.len()];
        assert!(!obj.kept_distances(&pose, &labels, &mut out));
        obj.cost(&pose);
        let mut other_pose = pose;
        other_pose[7] += 1e-9;
        let mut other_labels = labels.clone();
        other_labels[3] = (other_labels[3] + 1) % 14;
        assert!(!obj.kept_distances(&other_pose, &labels, &mut out));
        assert!(!obj.kept_distances(&pose, &other_labels, &mut out));
        assert!(!obj.kept_distances(&pose, &labels, &mut out[1..]));
        assert!(out.iter().all(|d| d.is_nan()));
        assert!(obj.kept_distances(&pose, &labels, &mut out));
        let geo = PoseGeometry::new(&model, &pose);
        let (mut infinite, mut exact) = (0, 0);
        for (i, (p, &l)) in pts.iter().zip(&labels).enumerate() {
            if !(0..NUM_SEGMENTS as i32).contains(&l) {
                assert!(out[i].is_nan(), "point {i} (label {l}) was written");
                continue;
            }
            let e = &geo.segments[l as usize];
            let mut d = f64::NAN;
            e.signed_distances_batched(std::iter::once((0, e.local(&vec3(p)))), |_, v| d = v);
            if out[i].is_infinite() {
                assert!(d.abs() >= pc.truncation, "point {i}: {d} given as infinite");
                infinite += 1;
            } else {
                assert_eq!(out[i], d, "point {i}");
                exact += 1;
            }
        }
        assert!(
            infinite > 100 && exact > 100,
            "{infinite} infinite, {exact} exact"
        );
    }

    /// The cost is the sum of the per-point costs with one exact scalar query each
    /// (the grouping by segment and the lockstep root-finder change nothing but the
    /// summation order).
    #[test]
    fn cost_matches_scalar_queries() {
        let model = BodyModel::default();
        let pose = pose_for_tests(3);
        let (pts, labels) = scattered(&model, &pose, 3000);
        let pc = PointCost {
            sigma: 0.02,
            loss: Loss::Squared,
            truncation: 0.2,
        };
        let geo = PoseGeometry::new(&model, &pose);
        let expected: f64 = pts
            .iter()
            .zip(&labels)
            .filter(|(_, &l)| (0..NUM_SEGMENTS as i32).contains(&l))
            .map(|(p, &l)| pc.cost(geo.segments[l as usize].signed_distance(&vec3(p))))
            .sum();
        let mut obj = PointObjective::new(&model, &pts, &labels, pc);
        let c = obj.cost(&pose);
        assert!(
            (c - expected).abs() <= 1e-12 * expected,
            "{c} vs {expected}"
        );
    }

    #[test]
    fn truncated_points_add_a_constant() {
        let model = BodyModel::default();
        let pose = BodyModel::neutral_pose();
        let pts = vec![[5.0f32, 5.0, 5.0]; 3];
        let labels = vec![2, 5, -1];
        let pc = PointCost {
            sigma: 0.02,
            loss: Loss::Squared,
            truncation: 0.1,
        };
        let mut obj = PointObjective::new(&model, &pts, &labels, pc);
        let (mut h, mut g) = ([0.0; NN], [0.0; N]);
        let c = obj.normal_equations(&pose, &mut h, &mut g);
        assert!((c - 2.0 * pc.cap()).abs() < 1e-12);
        assert!(g.iter().all(|v| *v == 0.0) && h.iter().all(|v| *v == 0.0));
    }
}
