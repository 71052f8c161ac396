//! The calibration: rounds of per-frame pose and label fits and shape steps.

use super::config::ShapeConfig;
use super::lm::shape_lm;
use super::system::{prior_cost, LabelledFrame, S};
use crate::body::{pose_from_slice, BodyModel, Pose, ShapeFactors, NUM_JOINTS};
use crate::camera::Camera;
use crate::cloud::{neighbour_graph, Cloud, DepthView, PixelGraph};
use crate::error::{Error, Result};
use crate::fit::em::{
    crf_energy, edge_weights, hard_em, unary_costs, EmConfig, NUM_LABELS, OUTLIER,
};
use crate::fit::MIN_POINTS;
use nalgebra::Vector3;

/// One depth frame for [`fit_shape`]: H×W metres (row-major, the camera's size) and an
/// optional person mask (None = every reading).
#[derive(Debug, Clone, Copy)]
pub struct ShapeFrame<'a> {
    pub depth: &'a [f32],
    pub mask: Option<&'a [bool]>,
}

/// Outcome of [`fit_shape`].
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeResult {
    /// The fitted shape factors, relative to the base model.
    pub factors: ShapeFactors,
    /// The base model with the fitted shape.
    pub model: BodyModel,
    /// The fitted pose of every frame.
    pub poses: Vec<Pose>,
    /// The joints of every frame (fitted model and pose), camera frame.
    pub joints: Vec<[Vector3<f64>; NUM_JOINTS]>,
    /// H×W part labels of every frame: segment 0..15, −1 = background or outlier.
    pub labels: Vec<Vec<i16>>,
    /// The final energy E (see the module docs).
    pub energy: f64,
    /// E after every pose/label step and every shape step (non-increasing).
    pub energy_trace: Vec<f64>,
    /// Rounds run.
    pub rounds: usize,
}

/// A frame's cloud, graph and CRF edge weights.
pub(super) struct FrameData {
    pub(super) pixels: Vec<u32>,
    pub(super) points: Vec<[f32; 3]>,
    pub(super) graph: PixelGraph,
    pub(super) weights: Vec<f64>,
}

/// E_f at the final outlier distance for a pose and labels (0..=[`OUTLIER`]).
pub(super) fn frame_energy(
    model: &BodyModel,
    d: &FrameData,
    pose: &Pose,
    labels: &[i32],
    em: &EmConfig,
    unary: &mut Vec<f64>,
) -> f64 {
    unary.resize(d.points.len() * NUM_LABELS, 0.0);
    unary_costs(model, &d.points, pose, em, em.outlier_distance, unary);
    crf_energy(unary, &d.graph.edges, &d.weights, labels)
}

/// Calibrates the body shape on one or several frames (see the module docs): starting
/// from `base` and `init_poses` (one per frame), alternates per-frame pose/label fits
/// with a joint shape-and-pose LM. Deterministic; the energy trace never increases.
pub fn fit_shape(
    frames: &[ShapeFrame],
    camera: &Camera,
    base: &BodyModel,
    init_poses: &[Pose],
    config: &ShapeConfig,
) -> Result<ShapeResult> {
    config.validate()?;
    if frames.is_empty() {
        return Err(Error::invalid("depths", "needs at least one frame"));
    }
    if init_poses.len() != frames.len() {
        return Err(Error::invalid(
            "poses",
            format!(
                "has {} poses for {} depth frames",
                init_poses.len(),
                frames.len()
            ),
        ));
    }
    let em = config.fit.em;
    let mut data = Vec::with_capacity(frames.len());
    for (i, f) in frames.iter().enumerate() {
        let view = DepthView::new(
            f.depth,
            camera.height,
            camera.width,
            &format!("depths[{i}]"),
        )?;
        if let Some(m) = f.mask {
            if m.len() != f.depth.len() {
                return Err(Error::invalid(
                    format!("masks[{i}]"),
                    format!("has {} values for {} pixels", m.len(), f.depth.len()),
                ));
            }
        }
        let cloud = Cloud::from_depth(&view, camera, f.mask)?;
        if cloud.len() < MIN_POINTS {
            return Err(Error::NoBody(format!(
                "frame {i}: the foreground has {} points, at least {MIN_POINTS} are needed",
                cloud.len()
            )));
        }
        let graph = neighbour_graph(&cloud, config.fit.connectivity);
        let mut weights = Vec::new();
        edge_weights(&graph, &em, &mut weights);
        data.push(FrameData {
            pixels: cloud.pixels,
            points: cloud.points,
            graph,
            weights,
        });
    }
    let mut poses = Vec::with_capacity(init_poses.len());
    for (i, p) in init_poses.iter().enumerate() {
        poses.push(BodyModel::clamp_pose(&pose_from_slice(
            p,
            &format!("poses[{i}]"),
        )?));
    }
    let mut factors: ShapeFactors = [1.0; S];
    let mut labels: Vec<Option<Vec<i32>>> = vec![None; frames.len()];
    let mut energies = vec![0.0; frames.len()];
    let mut unary = Vec::new();
    let mut trace = Vec::new();
    let mut rounds = 0;
    let mut energy = f64::INFINITY;
    while rounds < config.rounds {
        rounds += 1;
        let energy_at_start = energy;
        // Pose/label step.
        let model = base.with_shape_factors(&factors)?;
        for (f, d) in data.iter().enumerate() {
            let r = hard_em(&model, &d.points, &d.graph, &poses[f], None, &em)?;
            let new_labels: Vec<i32> = r
                .labels
                .iter()
                .map(|&l| if l < 0 { OUTLIER } else { l })
                .collect();
            let e_new = frame_energy(&model, d, &r.pose, &new_labels, &em, &mut unary);
            let keep_old = match &labels[f] {
                Some(old) => frame_energy(&model, d, &poses[f], old, &em, &mut unary) <= e_new,
                None => false,
            };
            if !keep_old {
                poses[f] = r.pose;
                labels[f] = Some(new_labels);
                energies[f] = e_new;
            }
        }
        energy = energies.iter().sum::<f64>() + prior_cost(&factors, config.prior_weight);
        trace.push(energy);
        // Shape step.
        let lf: Vec<LabelledFrame> = data
            .iter()
            .zip(&labels)
            .map(|(d, l)| LabelledFrame {
                points: &d.points,
                labels: l.as_deref().unwrap_or(&[]),
            })
            .collect();
        shape_lm(base, &lf, &mut factors, &mut poses, config)?;
        let model = base.with_shape_factors(&factors)?;
        for (f, d) in data.iter().enumerate() {
            let l = labels[f].as_deref().unwrap_or(&[]);
            energies[f] = frame_energy(&model, d, &poses[f], l, &em, &mut unary);
        }
        // In exact arithmetic the shape step cannot raise E; guard against round-off.
        energy =
            (energies.iter().sum::<f64>() + prior_cost(&factors, config.prior_weight)).min(energy);
        trace.push(energy);
        if energy_at_start.is_finite()
            && energy_at_start - energy <= config.tolerance * energy.abs()
        {
            break;
        }
    }
    let model = base.with_shape_factors(&factors)?;
    let joints = poses.iter().map(|p| model.joints(p)).collect();
    let images = data
        .iter()
        .zip(&labels)
        .map(|(d, l)| {
            let mut img = vec![-1i16; camera.height * camera.width];
            if let Some(l) = l {
                for (&px, &lab) in d.pixels.iter().zip(l) {
                    img[px as usize] = if lab == OUTLIER { -1 } else { lab as i16 };
                }
            }
            img
        })
        .collect();
    Ok(ShapeResult {
        factors,
        model,
        poses,
        joints,
        labels: images,
        energy,
        energy_trace: trace,
        rounds,
    })
}
