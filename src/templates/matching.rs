//! Matching a depth image against the database: the pruning scores, the exact
//! assignment on the short list, placing each candidate at the observed body, and the
//! re-ranking by placed fit energy.

use super::catalogue::NUM_TEMPLATES;
use super::columns::QueryColumns;
use super::cost::{matching_cost_with, MatchScratch};
use super::database::TemplateDatabase;
use super::prune::prune_sum;
use super::prune::Representatives;
use super::template::metric_size;
use crate::assignment::AssignmentWorkspace;
use crate::body::rotation::rotation_vector;
use crate::body::{param, Pose, NUM_JOINTS};
use crate::camera::Camera;
use crate::cloud::DepthView;
use crate::descriptor::{Silhouette, SurfaceContext};
use crate::error::{ensure, Result};
use nalgebra::{Rotation3, Vector3};
use rayon::prelude::*;

/// Settings of [`TemplateDatabase::match_depth`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MatchConfig {
    /// Candidates returned.
    pub top_k: usize,
    /// Templates kept by the pruning stage for the exact assignment.
    pub shortlist: usize,
    /// Query samples used as representatives in the pruning stage.
    pub representatives: usize,
    /// Weight of the normalised-position distance in a pair's cost.
    pub location_weight: f64,
    /// Cost of leaving a sample unmatched.
    pub dummy_cost: f64,
    /// Re-rank the exact stage's best this-many templates (0 or 1 = off; at most the
    /// short list counts) by how well each, placed at the observed body, explains the
    /// depth in 3-D: the fit's data and free-space terms at the placed pose (see
    /// [`TemplateDatabase::match_depth`]). Off by default: it costs about 0.22 ms per
    /// candidate and improves the placed pose, not the fit that follows
    /// (docs/design.md).
    pub rerank: usize,
}

impl Default for MatchConfig {
    fn default() -> Self {
        MatchConfig {
            top_k: 5,
            shortlist: 16,
            representatives: 8,
            location_weight: 0.1,
            dummy_cost: 0.15,
            rerank: 0,
        }
    }
}

impl MatchConfig {
    pub fn validate(&self) -> Result<()> {
        ensure((1..=NUM_TEMPLATES).contains(&self.top_k), "top_k", || {
            format!("must be in 1..={NUM_TEMPLATES}, got {}", self.top_k)
        })?;
        // Before the short list, which the Python layer grows to `rerank`.
        ensure(self.rerank <= NUM_TEMPLATES, "rerank", || {
            format!("must be in 0..={NUM_TEMPLATES}, got {}", self.rerank)
        })?;
        ensure(
            (1..=NUM_TEMPLATES).contains(&self.shortlist),
            "shortlist",
            || format!("must be in 1..={NUM_TEMPLATES}, got {}", self.shortlist),
        )?;
        ensure(self.representatives >= 1, "representatives", || {
            "must be >= 1".to_string()
        })?;
        ensure(
            self.location_weight.is_finite() && self.location_weight >= 0.0,
            "location_weight",
            || format!("must be finite and >= 0, got {}", self.location_weight),
        )?;
        crate::error::ensure_positive(self.dummy_cost, "dummy_cost")
    }
}

/// A template matched to a depth image.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    /// Template index (see [`template_code`](super::template_code)).
    pub index: usize,
    pub view: usize,
    /// Initial pose: the template placed at the observed body.
    pub pose: Pose,
    /// Joints of `pose` (camera frame).
    pub joints: [[f64; 3]; NUM_JOINTS],
    /// Mean cost per sample of the exact assignment.
    pub cost: f64,
    /// Pruning-stage score.
    pub prune_cost: f64,
    /// Observed body size over the template body size (≈ subject height / model height).
    pub scale: f64,
}

/// The result of a match: candidates best first, plus the full pruning ranking.
#[derive(Debug, Clone, PartialEq)]
pub struct MatchResult {
    pub candidates: Vec<Candidate>,
    /// Templates in the short list, best pruning score first.
    pub shortlist: Vec<usize>,
}

/// The re-ranking ([`MatchConfig::rerank`]) scores every this-many-th observed point
/// (in pixel order): 2,000 of a typical 8,000-point body.
pub(super) const RERANK_POINT_STEP: usize = 4;

/// The points the re-ranking scores: every [`RERANK_POINT_STEP`]-th point of the body
/// the descriptors saw.
pub(super) fn rerank_points(sil: &Silhouette) -> Vec<[f32; 3]> {
    sil.cloud
        .points
        .iter()
        .step_by(RERANK_POINT_STEP)
        .copied()
        .collect()
}

impl TemplateDatabase {
    /// Matches the (masked) body of a depth image against every template: pruning, the
    /// exact assignment on the short list, each candidate placed at the observed body,
    /// and with [`MatchConfig::rerank`] the best few re-ordered by their placed fit
    /// energy (which sees depth the normals-only descriptor cannot: an arm held toward
    /// the camera against one hanging in front of the body).
    pub fn match_depth(
        &self,
        depth: &DepthView,
        camera: &Camera,
        mask: Option<&[bool]>,
        config: &MatchConfig,
    ) -> Result<MatchResult> {
        config.validate()?;
        let d = &self.config.descriptor;
        let sil = Silhouette::from_depth(depth, camera, mask, d.normal_radius)?;
        let query = sil.surface_context(d)?;
        let rerank = config.rerank.min(config.shortlist);
        let wide = MatchConfig {
            top_k: config.top_k.max(rerank),
            ..*config
        };
        let mut result = self.match_context(&query, &wide)?;
        let size = metric_size(&query, &sil.centroid, camera);
        for c in result.candidates.iter_mut() {
            self.place(c, &sil, size);
        }
        if rerank > 1 {
            let points = rerank_points(&sil);
            let n = result.candidates.len().min(rerank);
            let energies: Vec<f64> = result.candidates[..n]
                .iter()
                .map(|c| self.placed_energy(&points, depth.data, camera, &c.pose))
                .collect();
            let mut order: Vec<usize> = (0..n).collect();
            order.sort_by(|&a, &b| energies[a].total_cmp(&energies[b]).then(a.cmp(&b)));
            let reordered: Vec<Candidate> = order
                .iter()
                .map(|&k| result.candidates[k].clone())
                .collect();
            result.candidates.splice(..n, reordered);
        }
        result.candidates.truncate(config.top_k);
        Ok(result)
    }

    /// Ranks the templates for a query's descriptors (candidate poses stay the
    /// templates' own; [`Self::match_depth`] places them).
    pub fn match_context(
        &self,
        query: &SurfaceContext,
        config: &MatchConfig,
    ) -> Result<MatchResult> {
        config.validate()?;
        ensure(!self.templates.is_empty(), "templates", || {
            "the database is empty".to_string()
        })?;
        ensure(query.dim == self.templates[0].context.dim, "query", || {
            format!(
                "descriptors have {} values, the templates {}",
                query.dim, self.templates[0].context.dim
            )
        })?;
        let reps = Representatives::new(&self.prune, query, config.representatives);
        let lw = config.location_weight as f32;
        // Early give-up, exact: a template's sum over the representatives only grows
        // (every pair cost is ≥ 0, and adding a non-negative f32 never lowers a sum), so
        // once its partial sum exceeds the sum of the `keep`-th best template finished
        // so far, `keep` templates score strictly lower and it cannot make the short
        // list. Most templates are far worse than the short list and stop after a few
        // representatives. The finished sums' `keep` smallest live in a shared heap; the
        // current limit is read lock-free (f32 bits of non-negative sums order as u32).
        let keep = config.shortlist.min(self.templates.len());
        let best_sums = std::sync::Mutex::new(std::collections::BinaryHeap::<u32>::new());
        let limit = std::sync::atomic::AtomicU32::new(f32::INFINITY.to_bits());
        let finished = |sum: f32| {
            let bits = sum.to_bits();
            let mut heap = best_sums.lock().unwrap_or_else(|e| e.into_inner());
            if heap.len() < keep {
                heap.push(bits);
            } else if heap.peek().is_some_and(|&top| bits < top) {
                heap.pop();
                heap.push(bits);
            }
            if heap.len() == keep {
                if let Some(&top) = heap.peek() {
                    limit.fetch_min(top, std::sync::atomic::Ordering::Relaxed);
                }
            }
        };
        let n_reps = reps.samples.len() as f32;
        let mut scores: Vec<(f64, usize)> = self
            .templates
            .par_iter()
            .zip(&self.prune.projected)
            .enumerate()
            .map_init(Vec::new, |scratch, (t, (tpl, projected))| {
                let give_up = f32::from_bits(limit.load(std::sync::atomic::Ordering::Relaxed));
                let sum = prune_sum(query, &reps, &tpl.context, projected, lw, give_up, scratch)?;
                finished(sum);
                Some(((sum / n_reps) as f64, t))
            })
            .flatten()
            .collect();
        scores.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let shortlist: Vec<usize> = scores[..config.shortlist.min(scores.len())]
            .iter()
            .map(|s| s.1)
            .collect();
        let prune_of: std::collections::HashMap<usize, f64> =
            scores.iter().map(|&(s, t)| (t, s)).collect();
        let columns = QueryColumns::new(query);
        let mut exact: Vec<(f64, usize)> = shortlist
            .par_iter()
            .map_init(
                || (AssignmentWorkspace::default(), Vec::new(), Vec::new()),
                |(ws, cost, assign), &t| {
                    let weights = (config.location_weight, config.dummy_cost);
                    let scratch = MatchScratch { ws, cost, assign };
                    let tpl = &self.templates[t].context;
                    let c = matching_cost_with(query, &columns, tpl, weights, scratch);
                    (c, t)
                },
            )
            .collect();
        exact.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let candidates = exact
            .iter()
            .take(config.top_k)
            .map(|&(cost, t)| {
                let tpl = &self.templates[t];
                Candidate {
                    index: t,
                    view: tpl.view,
                    pose: tpl.pose,
                    joints: tpl.joints,
                    cost,
                    prune_cost: prune_of[&t],
                    scale: 1.0,
                }
            })
            .collect();
        Ok(MatchResult {
            candidates,
            shortlist,
        })
    }

    /// How well `pose` explains the observed `points` (a sub-sample of the body's) and
    /// the free space of `depth`: the data terms of the fit's energy (default
    /// [`crate::fit::em::EmConfig`], outlier distance at its starting value) with every
    /// point at its cheapest label, pairwise terms left out, per point.
    pub(super) fn placed_energy(
        &self,
        points: &[[f32; 3]],
        depth: &[f32],
        camera: &Camera,
        pose: &Pose,
    ) -> f64 {
        use crate::fit::em::{unary_costs, EmConfig, NUM_LABELS};
        use crate::fit::free_space::FreeSpaceTerm;
        let cfg = EmConfig::default();
        let mut unary = vec![0.0; points.len() * NUM_LABELS];
        unary_costs(
            &self.model,
            points,
            pose,
            &cfg,
            cfg.outlier_distance_start,
            &mut unary,
        );
        let data: f64 = unary
            .chunks_exact(NUM_LABELS)
            .map(|row| row.iter().copied().fold(f64::INFINITY, f64::min))
            .sum();
        // The free-space samples weigh against the full point set: its weight shrinks
        // with the points kept (1 / step), as a strided fit's does (1 / stride²).
        let weight_scale = 1.0 / RERANK_POINT_STEP as f64;
        let free_space = FreeSpaceTerm::new(
            &self.model,
            depth,
            camera,
            cfg.free_space_cost(weight_scale),
        );
        (data + free_space.cost(pose)) / points.len().max(1) as f64
    }

    /// Moves a candidate's template onto the observed body: the template's visible
    /// centroid goes to the observed one, its view relative to the line of sight is
    /// kept, and the hip sits at the template's centroid → hip offset (which carries
    /// the body's half thickness behind the visible surface) scaled by the size ratio.
    pub(super) fn place(&self, c: &mut Candidate, sil: &Silhouette, size: f64) {
        let tpl = &self.templates[c.index];
        let ct = Vector3::from(tpl.centroid);
        let align_t = crate::descriptor::line_of_sight_alignment(&ct.normalize());
        // Template camera → query camera rotation.
        let m: Rotation3<f64> = sil.alignment.inverse() * align_t;
        let scale = size / tpl.size;
        let hip = Vector3::new(
            tpl.pose[param::ROOT_T],
            tpl.pose[param::ROOT_T + 1],
            tpl.pose[param::ROOT_T + 2],
        );
        let t = sil.centroid + m * (hip - ct) * scale;
        let r = m * crate::body::root_rotation(&tpl.pose);
        let mut pose = tpl.pose;
        pose[param::ROOT_T..param::ROOT_T + 3].copy_from_slice(t.as_slice());
        pose[param::ROOT_R..param::ROOT_R + 3].copy_from_slice(rotation_vector(&r).as_slice());
        c.pose = pose;
        c.joints = self.model.joints(&pose).map(|j| [j.x, j.y, j.z]);
        c.scale = scale;
    }
}
