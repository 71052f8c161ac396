//! Pose from scratch, one frame at a time: the person's pixels, the template search
//! with its swapped and mirrored hypotheses, brief EM fits of the most promising, full
//! fits of the best few, and the pose whose body explains the depth best.

use super::confidence::joint_confidence;
use super::config::PipelineConfig;
use super::hypotheses::{refined_hypotheses, rest_pose_penalty, template_starts};
use super::orientation::{
    every_roll, long_axis_tilt, rotate_about_optical_axis, rotated_view, search_rotations,
};
use super::resolution::WorkingResolution;
use super::result::{Clock, PoseResult, SegmentSummary, Source};
use super::size::SizedFit;
use crate::body::{BodyModel, Pose};
use crate::camera::Camera;
use crate::cloud::DepthView;
use crate::error::{Error, Result};
use crate::fit::{DepthNoise, FitConfig, FitProblem, FitResult, PosePrior};
use crate::render::depth_discrepancy;
use crate::segment::{segment_person, SegmentHint, Segmentation};
use crate::templates::{Candidate, MatchConfig, TemplateDatabase};
use rayon::prelude::*;
use std::sync::Arc;

/// The depth difference (m) at which a pixel of the discrepancy counts fully.
pub const DISCREPANCY_CAP: f64 = 0.1;

/// Pixels around the person in a rotated view.
const VIEW_MARGIN: usize = 8;

/// The short list of the template search's pruning stage.
const SHORTLIST: usize = 16;

/// Pose from scratch (see the module docs).
#[derive(Debug, Clone)]
pub struct Estimator {
    resolution: WorkingResolution,
    model: BodyModel,
    templates: Arc<TemplateDatabase>,
    config: PipelineConfig,
    /// The empty scene at the working resolution.
    background: Option<Vec<f32>>,
    /// Whether a search from scratch also finds the body's size ([`super::size`]).
    size_search: bool,
    /// The depth sensor's noise, when known ([`Self::set_depth_noise`]).
    depth_noise: Option<DepthNoise>,
}

/// A fit on its way into a [`PoseResult`].
pub(crate) struct Fitted<'m> {
    pub fit: FitResult,
    /// Its depth discrepancy.
    pub discrepancy: f64,
    /// The body it was fitted with.
    pub model: &'m BodyModel,
    /// The body's part labels rendered at the fit's pose, when a caller has them.
    pub rendered: Option<Vec<i16>>,
}

/// A frame at the working resolution: its depth, the person's pixels and how they
/// were found, and the fit problems built on it (one per stride).
pub struct Frame {
    pub depth: Vec<f32>,
    pub mask: Vec<bool>,
    pub segmentation: Option<Segmentation>,
    /// The part labels of the frame's result, at the working resolution (empty before).
    pub labels: Vec<i16>,
    problems: Vec<FitProblem>,
}

impl Estimator {
    /// An estimator for images of `camera` (the input's size and intrinsics).
    /// `background`: the empty scene (metres, the input's size), for background
    /// subtraction; without it the person is segmented automatically.
    pub fn new(
        camera: &Camera,
        model: BodyModel,
        templates: Arc<TemplateDatabase>,
        config: PipelineConfig,
        background: Option<&[f32]>,
    ) -> Result<Self> {
        config.validate()?;
        let resolution = WorkingResolution::for_camera(camera, config.working_focal)?;
        let background = match background {
            Some(b) => {
                DepthView::new(b, camera.height, camera.width, "background")?;
                Some(resolution.depth(b).0)
            }
            None => None,
        };
        Ok(Estimator {
            resolution,
            model,
            templates,
            config,
            background,
            size_search: true,
            depth_noise: None,
        })
    }

    /// Tells the estimator the depth sensor's noise (None: unknown, taken as none).
    /// What counts as a badly explained body ([`Self::explains_badly`]) then allows for
    /// what the noise adds to the discrepancy of a body whose own residuals have the
    /// fit's scale ([`DepthNoise::discrepancy_added`]).
    pub fn set_depth_noise(&mut self, noise: Option<DepthNoise>) {
        self.depth_noise = noise;
    }

    /// Whether a fit with depth discrepancy `score` explains the frame badly: above
    /// `lost_discrepancy`, raised by what the known depth noise adds. A tracker counts
    /// the frame lost then; a search runs the wide search.
    pub fn explains_badly(&self, frame: &Frame, score: f64) -> bool {
        let cfg = &self.config;
        if score <= cfg.lost_discrepancy {
            return false;
        }
        let sigma = cfg.fit.em.sigma;
        let added = self.depth_noise.map_or(0.0, |n| {
            n.discrepancy_added(&frame.depth, &frame.mask, sigma, DISCREPANCY_CAP)
        });
        score > cfg.lost_discrepancy + added
    }

    /// This estimator, with or without the size search from scratch (on by default;
    /// off when the caller knows the subject's shape).
    pub fn with_size_search(mut self, on: bool) -> Self {
        self.size_search = on;
        self
    }

    /// Whether a search from scratch also finds the body's size.
    pub fn size_search(&self) -> bool {
        self.size_search && self.config.size_range > 0.0
    }

    pub fn model(&self) -> &BodyModel {
        &self.model
    }

    pub(crate) fn set_model(&mut self, model: BodyModel) {
        self.model = model;
    }

    pub fn config(&self) -> &PipelineConfig {
        &self.config
    }

    /// Whether it was given a frame of the empty scene.
    pub fn has_background(&self) -> bool {
        self.background.is_some()
    }

    /// The input camera.
    pub fn camera(&self) -> &Camera {
        &self.resolution.input
    }

    pub fn resolution(&self) -> &WorkingResolution {
        &self.resolution
    }

    pub fn templates(&self) -> &Arc<TemplateDatabase> {
        &self.templates
    }

    /// The pose of one frame from scratch. `depth`: metres, the input's size;
    /// `mask`: the person's pixels (else segmented).
    pub fn estimate(&self, depth: &[f32], mask: Option<&[bool]>) -> Result<PoseResult> {
        let mut clock = Clock::start();
        let mut frame = self.prepare(depth, mask, None)?;
        clock.lap("foreground");
        let sized = self.fit_from_scratch(&mut frame, &mut clock, self.size_search())?;
        Ok(self.sized_result(&mut frame, sized, clock).0)
    }

    /// The frame at the working resolution with the person's pixels: `mask` (the
    /// input's size) when given, else the segmentation (with `hint`, a video's last).
    pub fn prepare(
        &self,
        depth: &[f32],
        mask: Option<&[bool]>,
        hint: Option<&SegmentHint>,
    ) -> Result<Frame> {
        let cam = &self.resolution.input;
        DepthView::new(depth, cam.height, cam.width, "depth")?;
        if let Some(m) = mask {
            if m.len() != depth.len() {
                return Err(Error::invalid(
                    "mask",
                    format!("has {} values for {} pixels", m.len(), depth.len()),
                ));
            }
        }
        let (work, source) = self.resolution.depth(depth);
        let camera = &self.resolution.working;
        let (mask, segmentation) = match mask {
            Some(m) => (self.resolution.mask(m, &source), None),
            None => {
                let view = DepthView::new(&work, camera.height, camera.width, "depth")?;
                let bg = self
                    .background
                    .as_ref()
                    .map(|b| DepthView::new(b, camera.height, camera.width, "background"))
                    .transpose()?;
                let seg = segment_person(&view, camera, bg.as_ref(), &self.config.segment, hint)?;
                (seg.mask.clone(), Some(seg))
            }
        };
        Ok(Frame {
            depth: work,
            mask,
            segmentation,
            labels: Vec::new(),
            problems: Vec::new(),
        })
    }

    /// The frame's fit problem for `config`'s stride, built on first use.
    pub(super) fn problem<'f>(
        &self,
        frame: &'f mut Frame,
        config: &FitConfig,
    ) -> Result<&'f mut FitProblem> {
        let k = match frame
            .problems
            .iter()
            .position(|p| p.config().stride == config.stride)
        {
            Some(k) => k,
            None => {
                let p = FitProblem::new(
                    &frame.depth,
                    &self.resolution.working,
                    Some(&frame.mask),
                    config,
                )?;
                frame.problems.push(p);
                frame.problems.len() - 1
            }
        };
        let p = &mut frame.problems[k];
        p.set_config(config)?;
        Ok(p)
    }

    /// EM fits from each of `inits` (with `resume`, each continuing an earlier fit), in
    /// parallel, with `prior` toward a pose.
    pub(crate) fn fits(
        &self,
        frame: &mut Frame,
        config: &FitConfig,
        inits: &[Pose],
        resume: Option<&[FitResult]>,
        prior: Option<&PosePrior>,
    ) -> Result<Vec<FitResult>> {
        let problem = &*self.problem(frame, config)?;
        let model = &self.model;
        inits
            .par_iter()
            .enumerate()
            .map(|(k, init)| problem.fit_from(model, init, resume.map(|r| &r[k]), prior))
            .collect()
    }

    /// How badly each of `poses` explains a prepared frame's depth, rendered in parallel
    /// (see [`crate::render::depth_discrepancy`]).
    pub fn discrepancies(&self, frame: &Frame, poses: &[Pose]) -> Result<Vec<f64>> {
        self.model.depth_discrepancies(
            poses,
            &self.resolution.working,
            &frame.depth,
            &frame.mask,
            DISCREPANCY_CAP,
        )
    }

    /// [`Self::discrepancies`] plus the rest-pose penalty: how poses compete.
    pub(super) fn rankings(&self, scores: &[f64], poses: &[Pose]) -> Vec<f64> {
        scores
            .iter()
            .zip(poses)
            .map(|(&s, p)| self.rank(s, p))
            .collect()
    }

    /// How a pose with depth discrepancy `score` competes: the discrepancy plus the
    /// pose's penalty ([`Self::penalty`]); lower is better.
    pub(crate) fn rank(&self, score: f64, pose: &Pose) -> f64 {
        score + self.penalty(pose)
    }

    /// What a pose's discrepancy is charged when poses compete: the rest-pose penalty
    /// and, with `penetration_weight`, its arms' depth inside the trunk.
    pub fn penalty(&self, pose: &Pose) -> f64 {
        let w = self.config.penetration_weight;
        let inside = if w > 0.0 {
            w * self.model.arm_trunk_penetration(pose)
        } else {
            0.0
        };
        rest_pose_penalty(pose, self.config.pose_prior_weight) + inside
    }

    /// The views the template search looks at first: the frame as it is, and, with
    /// `any_roll`, the views that turn a leaning or lying body upright, head up and
    /// head down ([`search_rotations`]). Rolls in radians.
    pub(crate) fn first_rolls(&self, frame: &Frame) -> Vec<f64> {
        if self.config.any_roll {
            search_rotations(long_axis_tilt(
                &frame.depth,
                &frame.mask,
                &self.resolution.working,
            ))
        } else {
            vec![0.0]
        }
    }

    /// Start poses from the template search (see [`template_starts`]) on the frame seen
    /// rolled by each of `rotations` (radians; 0 is the frame as it is), the candidates
    /// rolled back, each with the index of its view in `rotations`.
    pub(crate) fn template_hypotheses(
        &self,
        frame: &Frame,
        rotations: &[f64],
    ) -> Result<Vec<(Pose, usize)>> {
        let camera = &self.resolution.working;
        let config = MatchConfig {
            top_k: self.config.candidates,
            shortlist: SHORTLIST.max(self.config.candidates),
            ..MatchConfig::default()
        };
        // The views are matched in parallel (each match is parallel over the templates
        // too, but its descriptors are not) and their candidates kept in view order.
        let per_view: Vec<Result<Vec<Candidate>>> = rotations
            .par_iter()
            .map(|&roll| {
                if roll == 0.0 {
                    let view = DepthView::new(&frame.depth, camera.height, camera.width, "depth")?;
                    let found =
                        self.templates
                            .match_depth(&view, camera, Some(&frame.mask), &config)?;
                    return Ok(found.candidates);
                }
                let v = rotated_view(&frame.depth, &frame.mask, camera, -roll, VIEW_MARGIN)?;
                let c = &v.camera;
                let view = DepthView::new(&v.depth, c.height, c.width, "depth")?;
                let found = match self.templates.match_depth(&view, c, Some(&v.mask), &config) {
                    Ok(f) => f,
                    // A view the matcher cannot use (too few pixels) adds nothing.
                    Err(Error::NoBody(_)) => return Ok(Vec::new()),
                    Err(e) => return Err(e),
                };
                Ok(found
                    .candidates
                    .into_iter()
                    .map(|mut k| {
                        k.pose = rotate_about_optical_axis(&k.pose, roll);
                        k
                    })
                    .collect())
            })
            .collect();
        let (mut candidates, mut view_of) = (Vec::new(), Vec::new());
        for (view, found) in per_view.into_iter().enumerate() {
            let found = found?;
            view_of.extend(std::iter::repeat_n(view, found.len()));
            candidates.extend(found);
        }
        if candidates.is_empty() {
            return Err(Error::NoBody(
                "depth: no template matched the foreground".into(),
            ));
        }
        let starts = template_starts(&self.model, &candidates, self.config.back_views);
        Ok(starts
            .into_iter()
            .map(|(pose, candidate)| (pose, view_of[candidate]))
            .collect())
    }

    /// The best fit from the template hypotheses (see [`Self::search_views`]) on the
    /// first views ([`Self::first_rolls`]), each view's best-ranked hypothesis refined.
    pub(crate) fn search(
        &self,
        frame: &mut Frame,
        extra: &[Pose],
        hypotheses: usize,
        clock: Option<&mut Clock>,
    ) -> Result<(FitResult, f64)> {
        let rolls = self.first_rolls(frame);
        let views = Views {
            rolls: &rolls,
            distinct: true,
        };
        self.search_views(frame, extra, hypotheses, &views, clock)
    }

    /// The wide search, for a body the first views misread (upside down, doubled up,
    /// lying): [`Self::search_views`] on the views at every eighth of a turn
    /// ([`every_roll`]) not among the first views. None without `any_roll`.
    pub(crate) fn search_wide(
        &self,
        frame: &mut Frame,
        hypotheses: usize,
    ) -> Result<Option<(FitResult, f64)>> {
        if !self.config.any_roll {
            return Ok(None);
        }
        let first = self.first_rolls(frame);
        let wide: Vec<f64> = every_roll()
            .into_iter()
            .filter(|r| !first.iter().any(|f| (f - r).abs() < 1e-9))
            .collect();
        let views = Views {
            rolls: &wide,
            distinct: false,
        };
        self.search_views(frame, &[], hypotheses, &views, None)
            .map(Some)
    }

    /// The best fit from the template hypotheses on `views` (and `extra` start poses,
    /// always refined): the best `hypotheses` by their ranking (depth discrepancy and
    /// rest-pose penalty; with distinct views, each view's best among them: see
    /// [`refined_hypotheses`]) refined briefly by EM, the `finals` explaining the depth
    /// best refined fully (their EM continued), the best of all kept. Returns the fit and
    /// its discrepancy. The fit has its EM's labels only ([`Self::label_all`] completes
    /// it).
    pub(crate) fn search_views(
        &self,
        frame: &mut Frame,
        extra: &[Pose],
        hypotheses: usize,
        views: &Views,
        clock: Option<&mut Clock>,
    ) -> Result<(FitResult, f64)> {
        let cfg = &self.config;
        let found = self.template_hypotheses(frame, views.rolls)?;
        if let Some(clock) = clock {
            clock.lap("templates");
        }
        let mut starts: Vec<Pose> = found.iter().map(|&(pose, _)| pose).collect();
        let n = hypotheses.max(1);
        if n < starts.len() {
            let scores = self.discrepancies(frame, &starts)?;
            let order = stable_order(&self.rankings(&scores, &starts));
            let picked = if views.distinct {
                let view_of: Vec<usize> = found.iter().map(|&(_, view)| view).collect();
                refined_hypotheses(&order, &view_of, n)
            } else {
                order[..n].to_vec()
            };
            starts = picked.iter().map(|&i| starts[i]).collect();
        }
        let mut chosen: Vec<Pose> = extra.iter().chain(&starts).copied().collect();
        // Candidates continued at their own stride need no labels beyond their EM's.
        let brief = cfg.candidate_stride == cfg.final_stride;
        let mut candidate_config = cfg.fit_with(
            Some(cfg.candidate_iterations),
            cfg.candidate_stride,
            brief.then_some(false),
        );
        if candidate_config.recentred_start {
            // One brief EM per hypothesis, from the start or from its copy moved onto the
            // observed body, whichever explains the depth better, rather than one EM from
            // each keeping the lower energy: half the work, which pays for more finals.
            chosen = self.better_placed(frame, &candidate_config, chosen)?;
            candidate_config.recentred_start = false;
        }
        let fits = self.fits(frame, &candidate_config, &chosen, None, None)?;
        let poses: Vec<Pose> = fits.iter().map(|f| f.pose).collect();
        let scores = self.discrepancies(frame, &poses)?;
        let ranking = self.rankings(&scores, &poses);
        let order: Vec<usize> = stable_order(&ranking)
            .into_iter()
            .take(cfg.finals)
            .collect();
        let (mut best, mut best_score) = (fits[order[0]].clone(), scores[order[0]]);
        let best_rank = ranking[order[0]];
        // The best candidates' EM goes on where their brief fits stopped.
        let winners: Vec<FitResult> = order.iter().map(|&i| fits[i].clone()).collect();
        let winner_poses: Vec<Pose> = winners.iter().map(|f| f.pose).collect();
        let final_config = cfg.fit_with(cfg.final_iterations, cfg.final_stride, Some(false));
        let finals = self.fits(frame, &final_config, &winner_poses, Some(&winners), None)?;
        let (final_best, final_score, final_rank) = self.best_ranked(frame, finals)?;
        // (A brief candidate's labels cover only its own pixels: a final is kept then.)
        if brief || final_rank <= best_rank {
            (best, best_score) = (final_best, final_score);
        }
        Ok((best, best_score))
    }

    /// The first of `fits` (not empty) that ranks best ([`Self::rank`]), with its depth
    /// discrepancy and its rank.
    pub(super) fn best_ranked(
        &self,
        frame: &Frame,
        fits: Vec<FitResult>,
    ) -> Result<(FitResult, f64, f64)> {
        let poses: Vec<Pose> = fits.iter().map(|f| f.pose).collect();
        let scores = self.discrepancies(frame, &poses)?;
        let ranking = self.rankings(&scores, &poses);
        let k = first_min(&ranking);
        let best = fits.into_iter().nth(k).expect("k indexes the fits");
        Ok((best, scores[k], ranking[k]))
    }

    /// Each of `starts`, or its copy moved onto the observed body
    /// ([`FitProblem::recentred`]) where that one's depth discrepancy is lower.
    pub(super) fn better_placed(
        &self,
        frame: &mut Frame,
        config: &FitConfig,
        mut starts: Vec<Pose>,
    ) -> Result<Vec<Pose>> {
        let problem = self.problem(frame, config)?;
        let moved: Vec<(usize, Pose)> = starts
            .iter()
            .enumerate()
            .filter_map(|(i, s)| problem.recentred(&self.model, s).map(|m| (i, m)))
            .collect();
        let poses: Vec<Pose> = moved.iter().map(|&(_, m)| m).collect();
        let moved_scores = self.discrepancies(frame, &poses)?;
        let scores = self.discrepancies(frame, &starts)?;
        for (&(i, m), &score) in moved.iter().zip(&moved_scores) {
            if score < scores[i] {
                starts[i] = m;
            }
        }
        Ok(starts)
    }

    /// `fit`, a final of [`Self::search`] made with `model`, labelled at every pixel.
    pub(crate) fn label_all(
        &self,
        frame: &mut Frame,
        fit: FitResult,
        model: &BodyModel,
    ) -> Result<FitResult> {
        let config = self.config.fit_with(None, self.config.final_stride, None);
        if !config.label_all_pixels {
            return Ok(fit);
        }
        let problem = self.problem(frame, &config)?;
        problem.label_all(model, &fit, None)
    }

    /// The [`Self::result`] of a fit from scratch (its source the templates) and the
    /// body it was made with.
    pub(crate) fn sized_result(
        &self,
        frame: &mut Frame,
        sized: SizedFit,
        clock: Clock,
    ) -> (PoseResult, BodyModel) {
        let SizedFit {
            fit, score, model, ..
        } = sized;
        let fitted = Fitted {
            fit,
            discrepancy: score,
            model: &model,
            rendered: None,
        };
        let res = self.result(frame, fitted, Source::Templates, clock);
        (res, model)
    }

    /// The result of a frame: the fit's pose, its labels and the person's pixels at the
    /// input's size, the joints' confidence, the shape of the body fitted. The fit's
    /// labels at the working resolution stay in `frame.labels`.
    pub(crate) fn result(
        &self,
        frame: &mut Frame,
        fitted: Fitted,
        source: Source,
        clock: Clock,
    ) -> PoseResult {
        let camera = &self.resolution.working;
        let Fitted {
            fit,
            discrepancy,
            model,
            rendered,
        } = fitted;
        let rendered = rendered.unwrap_or_else(|| model.render_depth(&fit.pose, camera).1);
        let confidence = joint_confidence(&fit.joints, &fit.labels, &rendered, camera);
        let labels = self.resolution.upsample(&fit.labels, -1);
        let mask = self.resolution.upsample(&frame.mask, false);
        let converged = fit.converged();
        frame.labels = fit.labels;
        PoseResult {
            pose: fit.pose,
            joints: fit.joints,
            shape: model.shape,
            labels,
            mask,
            energy: fit.energy,
            iterations: fit.iterations,
            converged,
            confidence,
            timings: clock.finish(),
            source,
            discrepancy,
            segmentation: frame.segmentation.as_ref().map(|s| SegmentSummary {
                method: s.method,
                planes: s.planes.clone(),
                person: s.person,
                others: s.others.clone(),
            }),
        }
    }

    /// The discrepancy of one pose, from one rendering, and the rendering's part labels
    /// (for [`Self::result`]).
    pub(crate) fn discrepancy(&self, frame: &Frame, pose: &Pose) -> (f64, Vec<i16>) {
        self.discrepancy_with(frame, &self.model, pose)
    }

    /// [`Self::discrepancy`] of `pose` on the body `model`.
    pub(super) fn discrepancy_with(
        &self,
        frame: &Frame,
        model: &BodyModel,
        pose: &Pose,
    ) -> (f64, Vec<i16>) {
        let (rendered, labels) = model.render_depth(pose, &self.resolution.working);
        let score = depth_discrepancy(&rendered, &frame.depth, &frame.mask, DISCREPANCY_CAP);
        (score, labels)
    }
}

/// The views a search matches the templates on.
pub(crate) struct Views<'a> {
    /// Rolls of the frame about the optical axis (radians; 0 is the frame as it is).
    pub rolls: &'a [f64],
    /// Whether the views are distinct readings of the body (the first views: as it is,
    /// upright, upside down), each view's best hypothesis then refined, or a sweep whose
    /// neighbouring views read the body alike (the wide search), its hypotheses
    /// competing by rank alone.
    pub distinct: bool,
}

/// Indices sorting `values` ascending; equal values keep their order.
pub(crate) fn stable_order(values: &[f64]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..values.len()).collect();
    order.sort_by(|&a, &b| values[a].total_cmp(&values[b]));
    order
}

/// The index of the first smallest value.
fn first_min(values: &[f64]) -> usize {
    let mut k = 0;
    for (i, v) in values.iter().enumerate() {
        if *v < values[k] {
            k = i;
        }
    }
    k
}
