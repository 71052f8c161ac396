//! Fit benchmarks: one hard-EM frame at 320×240 and one (accepted) LM iteration on
//! 10,000 points.

use criterion::{criterion_group, criterion_main, Criterion};
use depthpose::body::{param, BodyModel, Pose};
use depthpose::cloud::{neighbour_graph, Cloud, Connectivity, DepthView};
use depthpose::fit::em::{
    hard_em, hard_em_from, unary_costs, unary_costs_for_labels, EmConfig, EmOptions, HeldLabels,
    NUM_LABELS,
};
use depthpose::fit::free_space::FreeSpaceImage;
use depthpose::fit::lm::{PoseObjective, N, NN};
use depthpose::fit::objective::{Loss, PointCost, PointObjective};
use depthpose::fit::{fit_pose, FitConfig};
use depthpose::graphcut::{CrfProblem, CrfSolver, MoveConfig};
use depthpose::Camera;
use std::hint::black_box;

fn pose() -> Pose {
    let mut p = BodyModel::neutral_pose();
    p[2] = 2.3;
    p[param::ROOT_R + 1] = 0.3;
    p[param::R_SHOULDER] = 0.4;
    p[param::R_SHOULDER + 1] = 0.5;
    p[param::R_ELBOW] = 0.9;
    p[param::L_SHOULDER + 1] = 0.3;
    p[param::R_HIP] = 0.3;
    p[param::R_KNEE] = 0.4;
    p
}

fn bench(c: &mut Criterion) {
    let model = BodyModel::default();
    let cam = Camera::itop();
    let truth = pose();
    let (depth, _) = model.render_depth(&truth, &cam);
    let view = DepthView::new(&depth, cam.height, cam.width, "depth").unwrap();
    let cloud = Cloud::from_depth(&view, &cam, None).unwrap();
    let graph = neighbour_graph(&cloud, Connectivity::Four);
    eprintln!("points {} edges {}", cloud.len(), graph.len());
    let mut init = truth;
    for (i, v) in init.iter_mut().enumerate().skip(6) {
        *v += if i % 2 == 0 { 0.15 } else { -0.15 };
    }
    init = BodyModel::clamp_pose(&init);
    let cfg = EmConfig::default();
    let r = hard_em(&model, &cloud.points, &graph, &init, None, &cfg).unwrap();
    eprintln!("EM iterations {} ({:?})", r.iterations, r.termination);

    let mut g = c.benchmark_group("fit");
    g.bench_function("em_frame_320x240", |b| {
        b.iter(|| hard_em(&model, &cloud.points, &graph, black_box(&init), None, &cfg).unwrap())
    });
    // The same EM with the free-space term, as `fit_pose` runs it on a depth image (one
    // start; `fit_pose` may add a recentred one on the other core). On this frame the
    // term also cuts the iterations: without it one limb creeps for several.
    let free_space = FreeSpaceImage {
        depth: &depth,
        camera: &cam,
        weight_scale: 1.0,
    };
    let free_space_options = EmOptions {
        free_space: Some(free_space),
        ..EmOptions::default()
    };
    let with_free_space = hard_em_from(
        &model,
        &cloud.points,
        &graph,
        &init,
        free_space_options,
        &cfg,
    )
    .unwrap();
    g.bench_function("em_frame_320x240_free_space", |b| {
        b.iter(|| {
            let options = EmOptions {
                free_space: Some(free_space),
                ..EmOptions::default()
            };
            hard_em_from(
                &model,
                &cloud.points,
                &graph,
                black_box(&init),
                options,
                &cfg,
            )
            .unwrap()
        })
    });
    // The same frame coarse to fine: EM on the stride-2 grid until it converges, then
    // at most 2 EM iterations on every pixel (`full_resolution_iterations`).
    let coarse_to_fine = FitConfig {
        stride: 2,
        full_resolution_iterations: 2,
        ..FitConfig::default()
    };
    let joint_error = |p: &Pose| {
        let (a, b) = (model.joints(p), model.joints(&truth));
        a.iter().zip(&b).map(|(x, y)| (x - y).norm()).sum::<f64>() / a.len() as f64
    };
    let ctf = fit_pose(&depth, &cam, &init, &model, None, None, &coarse_to_fine).unwrap();
    eprintln!(
        "mean joint error: whole EM {:.2} mm ({} iterations), with free space {:.2} mm ({} \
         iterations), coarse to fine {:.2} mm ({} iterations)",
        1e3 * joint_error(&r.pose),
        r.iterations,
        1e3 * joint_error(&with_free_space.pose),
        with_free_space.iterations,
        1e3 * joint_error(&ctf.pose),
        ctf.iterations
    );
    g.bench_function("em_frame_320x240_coarse_to_fine", |b| {
        b.iter(|| {
            fit_pose(
                &depth,
                &cam,
                black_box(&init),
                &model,
                None,
                None,
                &coarse_to_fine,
            )
            .unwrap()
        })
    });
    // A tracked frame: fit_pose with 4 EM iterations, on every pixel and on every
    // second pixel of every second row (plus the full-resolution labelling).
    for stride in [1, 2] {
        let fit_cfg = FitConfig {
            em: EmConfig {
                max_iterations: 4,
                ..EmConfig::default()
            },
            stride,
            ..FitConfig::default()
        };
        g.bench_function(format!("fit_pose_track_4it_stride{stride}"), |b| {
            b.iter(|| {
                fit_pose(&depth, &cam, black_box(&init), &model, None, None, &fit_cfg).unwrap()
            })
        });
    }
    // Parts of one EM iteration. The terms are computed once here too: the E-step
    // benches below take them as input, also when a filter skips `unary_costs` (they
    // would all be zero, and the expansion would start from a different problem).
    let mut unary = vec![0.0; cloud.len() * NUM_LABELS];
    unary_costs(&model, &cloud.points, &truth, &cfg, 0.1, &mut unary);
    g.bench_function("unary_costs", |b| {
        b.iter(|| {
            unary_costs(
                &model,
                &cloud.points,
                black_box(&truth),
                &cfg,
                0.1,
                &mut unary,
            )
        })
    });
    // The same for an E-step from the fit's labels: only the terms its expansion can
    // use (see `unary_costs_for_labels`).
    let weights = vec![0.5; graph.len()];
    let mut slack = vec![0.0; cloud.len()];
    for (&[i, j], &w) in graph.edges.iter().zip(&weights) {
        slack[i as usize] += w;
        slack[j as usize] += w;
    }
    let labels0: Vec<i32> = r
        .labels
        .iter()
        .map(|&l| if l < 0 { 16 } else { l })
        .collect();
    let mut pruned = vec![0.0; cloud.len() * NUM_LABELS];
    let mut skipped = vec![0u32; cloud.len()];
    g.bench_function("unary_costs_from_labels", |b| {
        b.iter(|| {
            let held = HeldLabels {
                labels: &labels0,
                slack: &slack,
                skipped: &mut skipped,
            };
            let pose = black_box(&truth);
            unary_costs_for_labels(&model, &cloud.points, pose, &cfg, 0.1, held, &mut pruned)
        })
    });
    let mut solver = CrfSolver::<f64>::new(cloud.len(), &graph.edges).unwrap();
    g.bench_function("e_step_expansion_warm", |b| {
        b.iter(|| {
            let p = CrfProblem {
                unary: &unary,
                n_labels: NUM_LABELS,
                edges: &graph.edges,
                weights: &weights,
                pairwise: None,
            };
            solver
                .alpha_expansion(&p, Some(&labels0), &MoveConfig { max_cycles: 3 })
                .unwrap()
        })
    });
    // One accepted LM iteration on 10,000 points: the cost at the trial pose, then the
    // normal system at that pose. The trial alternates between two poses so that
    // nothing computed for one iteration serves the next (the objective keeps the
    // distances of the last pose it evaluated; within one iteration that is the point).
    let n = 10_000;
    let pts: Vec<[f32; 3]> = (0..n).map(|i| cloud.points[i % cloud.len()]).collect();
    let labs: Vec<i32> = (0..n).map(|i| labels0[i % cloud.len()].min(15)).collect();
    let pc = PointCost {
        sigma: 0.02,
        loss: Loss::Squared,
        truncation: 0.2,
    };
    let mut obj = PointObjective::new(&model, &pts, &labs, pc);
    let (mut h, mut gr) = (Box::new([0.0; NN]), Box::new([0.0; N]));
    let trials = [truth, init];
    let mut k = 0;
    g.bench_function("lm_iteration_10k", |b| {
        b.iter(|| {
            k ^= 1;
            let cost = obj.cost(black_box(&trials[k]));
            obj.normal_equations(&trials[k], &mut h, &mut gr);
            cost
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
