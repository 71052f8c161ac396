use super::config::EmConfig;
use super::estep::{problem, EStep, EmInputs};
use super::labels::{NUM_LABELS, OUTLIER};
use super::mstep::{m_step, MStepsAhead, PoseTerms};
use super::run::{run_hard_em, EmOptions};
use super::unary::{cheapest_label, settle_unary, unary_costs, unary_costs_for_labels};
use super::unary::{HeldLabels, UnaryAt};
use crate::body::kinematics::tests::pose_for_tests;
use crate::body::signed_distance_to_ellipsoid;
use crate::body::{BodyModel, Pose, NUM_SEGMENTS};
use crate::cloud::PixelGraph;
use crate::fit::lm::LevenbergMarquardt;
use crate::fit::terms::data::PointObjective;
use crate::fit::terms::free_space::FreeSpaceImage;
use crate::graphcut::{CrfSolver, MoveConfig};

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
        let options = EmOptions {
            free_space,
            ..EmOptions::default()
        };
        let run = |ahead| {
            run_hard_em(&model, &cloud.points, graph, &init, options, &config, ahead).unwrap()
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
    let inputs = EmInputs {
        model: &model,
        points,
        weights: None,
        config: &config,
    };
    let mut crf = EStep::new(&graph, inputs).unwrap();
    let start = crate::fit::tests::perturbed(&truth, 3, 0.2, 0.05);
    crf.set_all_terms(&start, tau);
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
    let labels = crf.expand(&cheapest, None).unwrap().labels;
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
        crf.set_pose(&near, tau, held, None);
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
        let expanded = crf.expand(held, Some(held_energy)).unwrap();
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
    let inputs = EmInputs {
        model: &model,
        points,
        weights: None,
        config: &config,
    };
    for (seed, tau) in [(7, config.outlier_distance_at(0)), (8, 0.1)] {
        let start = crate::fit::tests::perturbed(&truth, seed, 0.3, 0.08);
        let mut exact = EStep::new(&graph, inputs).unwrap();
        exact.set_all_terms(&start, tau);
        let want = exact.cheapest_labels();
        let mut fresh = EStep::at_pose(&graph, inputs, &start, tau, None).unwrap();
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
        let a = fresh.expand(&got, None).unwrap();
        let b = exact.expand(&want, None).unwrap();
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
    let inputs = EmInputs {
        model: &model,
        points,
        weights: None,
        config: &config,
    };
    let mut crf = EStep::at_pose(&graph, inputs, &start, tau, None).unwrap();
    let cheapest = crf.cheapest_labels();
    let labels = crf.expand(&cheapest, None).unwrap().labels;
    // Every 9th point at a segment far from it, for distances beyond the truncation.
    let labels: Vec<i32> = (labels.iter().enumerate())
        .map(|(i, &l)| match i % 9 {
            0 if l < OUTLIER => (l + 7) % NUM_SEGMENTS as i32,
            _ => l,
        })
        .collect();
    let mut objective = PointObjective::new(&model, points, &labels, config.point_cost(tau));
    let mut lm = LevenbergMarquardt::new(config.lm).unwrap();
    let (pose, report) = m_step(&mut lm, &mut objective, PoseTerms::default(), &start);
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
        let mut computed = EStep::new(&graph, inputs).unwrap();
        computed.set_pose(&pose, tau, &labels, None);
        let mut given = EStep::new(&graph, inputs).unwrap();
        given.set_pose(&pose, tau, &labels, Some(&own));
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
    // Each row is its point's weight times the exact one; a term is skipped (left at
    // the weighted cap) only where it is out of the expansion's reach. Returns how many
    // were skipped.
    let check = |rows: &[f64], skipped: &[u32], weight: &dyn Fn(usize) -> f64| {
        let mut n_skipped = 0;
        for i in 0..n {
            let w = weight(i);
            let own = w * exact[i * NUM_LABELS + labels[i] as usize];
            for k in 0..NUM_LABELS {
                let (got, want) = (rows[i * NUM_LABELS + k], w * exact[i * NUM_LABELS + k]);
                if skipped[i] >> k & 1 == 1 {
                    n_skipped += 1;
                    assert!(k != labels[i] as usize && k < NUM_SEGMENTS);
                    assert_eq!(got, w * cap);
                    assert!(want - own > slack[i], "point {i} segment {k}: {want} {own}");
                } else {
                    assert!(
                        (got - want).abs() <= 1e-12 * want.max(1.0),
                        "{i} {k}: {got} {want}"
                    );
                }
            }
        }
        n_skipped
    };
    let n_skipped = check(&unary, &skipped, &|_| 1.0);
    assert!(n_skipped > n, "the skipping is exercised: {n_skipped}");
    // With weights: each row is its weight times the unweighted one, a term skipped
    // only where the weighted rows put it out of reach.
    let weights: Vec<f32> = (0..n).map(|i| 0.2 + 0.3 * (i % 7) as f32).collect();
    let at = UnaryAt {
        model: &model,
        points: &points,
        weights: Some(&weights),
        pose: &pose,
        config: &config,
        tau,
    };
    let mut weighted = vec![-1.0; n * NUM_LABELS];
    let mut weighted_skipped = vec![u32::MAX; n];
    let request = super::unary::UnaryRequest {
        held: Some(HeldLabels {
            labels: &labels,
            slack: &slack,
            skipped: &mut weighted_skipped,
        }),
        ..Default::default()
    };
    super::unary::fill_unary(&at, request, &mut weighted);
    let n_weighted_skipped = check(&weighted, &weighted_skipped, &|i| weights[i] as f64);
    assert!(n_weighted_skipped > n, "{n_weighted_skipped}");
    // Points moved to a skipped segment get its exact term back.
    let moved: Vec<i32> = (0..n)
        .map(|i| match skipped[i].trailing_zeros() {
            k if k < NUM_SEGMENTS as u32 => k as i32,
            _ => labels[i],
        })
        .collect();
    let at = UnaryAt {
        model: &model,
        points: &points,
        weights: None,
        pose: &pose,
        config: &config,
        tau,
    };
    let settled = settle_unary(&at, &moved, &mut unary, &mut skipped);
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

/// Weights that vary with depth (as [`crate::fit::DepthNoise`] gives them): every
/// E-step row is its weight times the unweighted row (the terms an expansion can use
/// exactly, the others capped), the EM's energy never increases, and weights of 1
/// give the unweighted EM exactly.
#[test]
fn weighted_points_scale_their_terms_and_keep_the_em_monotone() {
    use crate::body::param;
    let model = BodyModel::default();
    let (truth, cloud, graph) = bent_frame(&model, param::R_ELBOW, 1.0);
    let n = cloud.len();
    let weights: Vec<f32> = cloud
        .points
        .iter()
        .enumerate()
        .map(|(i, p)| (0.5 + 0.5 * (p[2] - 2.0).abs() + 0.25 * (i % 3) as f32).max(0.05))
        .collect();
    let config = EmConfig::default();
    let init = crate::fit::tests::perturbed(&truth, 3, 0.15, 0.04);
    let tau = config.outlier_distance_at(0);
    // The rows at the start, all terms.
    let mut plain = vec![0.0; n * NUM_LABELS];
    unary_costs(&model, &cloud.points, &init, &config, tau, &mut plain);
    let at = UnaryAt {
        model: &model,
        points: &cloud.points,
        weights: Some(&weights),
        pose: &init,
        config: &config,
        tau,
    };
    let mut weighted = vec![0.0; n * NUM_LABELS];
    super::unary::fill_unary(&at, Default::default(), &mut weighted);
    for i in 0..n {
        for a in 0..NUM_LABELS {
            let (u, v) = (plain[i * NUM_LABELS + a], weighted[i * NUM_LABELS + a]);
            assert_eq!(v, weights[i] as f64 * u, "point {i} label {a}");
        }
    }
    // The EM: monotone energy, and a different fit from the unweighted one.
    let run = |w: Option<&[f32]>| {
        let options = EmOptions {
            point_weights: w,
            ..EmOptions::default()
        };
        run_hard_em(&model, &cloud.points, &graph, &init, options, &config, true)
            .unwrap()
            .0
    };
    let em = run(Some(&weights));
    for pair in em.energy_trace.windows(2) {
        assert!(pair[1] <= pair[0] * (1.0 + 1e-9), "{:?}", em.energy_trace);
    }
    let unweighted = run(None);
    assert_ne!(em.energy, unweighted.energy);
    let ones = vec![1.0f32; n];
    assert!(run(Some(&ones)) == unweighted);
    // A weight per point, finite and positive.
    let mut zero = ones.clone();
    zero[5] = 0.0;
    for bad in [&ones[1..], &zero[..]] {
        let options = EmOptions {
            point_weights: Some(bad),
            ..EmOptions::default()
        };
        let err = run_hard_em(&model, &cloud.points, &graph, &init, options, &config, true)
            .err()
            .unwrap();
        assert!(err.to_string().contains("point_weights"), "{err}");
    }
}
