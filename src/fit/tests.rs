//! End-to-end fits on depth rendered from the model itself.

use super::*;
use crate::body::param;

/// A natural standing pose with bent limbs, 2.8 m from the camera.
fn natural_pose() -> Pose {
    let mut p = BodyModel::neutral_pose();
    p[2] = 2.8;
    p[param::ROOT_R + 1] = 0.3;
    p[param::R_SHOULDER] = 0.4;
    p[param::R_SHOULDER + 1] = 0.5;
    p[param::R_ELBOW] = 0.9;
    p[param::L_SHOULDER] = -0.2;
    p[param::L_SHOULDER + 1] = 0.3;
    p[param::L_ELBOW] = 0.4;
    p[param::R_HIP] = 0.3;
    p[param::R_KNEE] = 0.4;
    p[param::L_HIP + 1] = 0.15;
    p[param::NECK] = 0.1;
    p
}

/// Small deterministic generator in [−1, 1).
pub(crate) struct Rng(pub(crate) u64);
impl Rng {
    pub(crate) fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64) / ((1u64 << 52) as f64) - 1.0
    }
    fn gaussian(&mut self) -> f64 {
        let u1 = 0.5 * (self.next() + 1.0) + 1e-12;
        let u2 = 0.5 * (self.next() + 1.0);
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// `pose` perturbed by up to `angle` rad per rotation parameter and `shift` m.
pub(crate) fn perturbed(pose: &Pose, seed: u64, angle: f64, shift: f64) -> Pose {
    let mut rng = Rng(seed);
    let mut p = *pose;
    for (i, v) in p.iter_mut().enumerate() {
        *v += if i < 3 { shift } else { angle } * rng.next();
    }
    BodyModel::clamp_pose(&p)
}

/// `fit_pose` with the default settings, no mask and no prior.
fn fit_default(depth: &[f32], cam: &Camera, init: &Pose, model: &BodyModel) -> FitResult {
    fit_pose(depth, cam, init, model, None, None, &FitConfig::default()).unwrap()
}

fn joint_errors(model: &BodyModel, a: &Pose, b: &Pose) -> (f64, f64) {
    let (ja, jb) = (model.joints(a), model.joints(b));
    let e: Vec<f64> = (0..NUM_JOINTS).map(|j| (ja[j] - jb[j]).norm()).collect();
    (
        e.iter().sum::<f64>() / NUM_JOINTS as f64,
        e.iter().cloned().fold(0.0, f64::max),
    )
}

/// Start = truth perturbed by up to 20° per rotation parameter and 0.1 m: every one of
/// eight starts reaches a mean joint error below 1 cm (with the recentred second start;
/// from the given start alone a quarter fall into another basin); the energy trace never
/// increases, and the two-start fit never ends above the given start's own fit.
#[test]
fn recovers_pose_from_clean_rendered_depth() {
    let model = BodyModel::default();
    let cam = Camera::itop();
    let truth = natural_pose();
    let (depth, _) = model.render_depth(&truth, &cam);
    let alone = FitConfig {
        recentred_start: false,
        ..FitConfig::default()
    };
    let mut means = Vec::new();
    for seed in 1..9 {
        let init = perturbed(&truth, seed, 20f64.to_radians(), 0.1);
        let r = fit_default(&depth, &cam, &init, &model);
        means.push(joint_errors(&model, &r.pose, &truth).0);
        assert!(r.energy_trace.windows(2).all(|w| w[1] <= w[0]));
        assert_eq!(*r.energy_trace.last().unwrap(), r.energy);
        let single = fit_pose(&depth, &cam, &init, &model, None, None, &alone).unwrap();
        assert!(r.energy <= single.energy, "seed {seed}");
    }
    assert!(means.iter().all(|m| *m < 0.01), "{means:?}");
}

#[test]
fn recovers_pose_from_noisy_rendered_depth() {
    let model = BodyModel::default();
    let cam = Camera::itop();
    let truth = natural_pose();
    let (mut depth, _) = model.render_depth(&truth, &cam);
    // Kinect-like noise: σ = 1.5 mm · z², then millimetre quantisation.
    let mut rng = Rng(99);
    for z in depth.iter_mut().filter(|z| **z > 0.0) {
        let zz = *z as f64;
        *z = ((zz + 1.5e-3 * zz * zz * rng.gaussian()) * 1000.0).round() as f32 / 1000.0;
    }
    let init = perturbed(&truth, 5, 20f64.to_radians(), 0.1);
    let r = fit_default(&depth, &cam, &init, &model);
    let (mean, max) = joint_errors(&model, &r.pose, &truth);
    assert!(mean < 0.03, "mean {mean} max {max}");
}

#[test]
fn is_deterministic() {
    let model = BodyModel::default();
    let cam = Camera::itop().scaled(0.5).unwrap();
    let truth = natural_pose();
    let (depth, _) = model.render_depth(&truth, &cam);
    let init = perturbed(&truth, 3, 0.2, 0.05);
    let a = fit_default(&depth, &cam, &init, &model);
    let b = fit_default(&depth, &cam, &init, &model);
    assert_eq!(a, b);
}

#[test]
fn bad_input_names_the_argument() {
    let model = BodyModel::default();
    let cam = Camera::itop().scaled(0.25).unwrap();
    let (depth, _) = model.render_depth(&natural_pose(), &cam);
    let pose = natural_pose();
    let cfg = FitConfig::default();
    let err = |r: Result<FitResult>| r.unwrap_err().to_string();
    assert!(err(fit_pose(
        &depth,
        &cam,
        &pose[..21],
        &model,
        None,
        None,
        &cfg
    ))
    .starts_with("init_pose"));
    let mut nan = pose;
    nan[7] = f64::NAN;
    assert!(err(fit_pose(&depth, &cam, &nan, &model, None, None, &cfg)).starts_with("init_pose"));
    assert!(err(fit_pose(&depth[1..], &cam, &pose, &model, None, None, &cfg)).starts_with("depth"));
    let empty = vec![0.0f32; depth.len()];
    assert!(matches!(
        fit_pose(&empty, &cam, &pose, &model, None, None, &cfg),
        Err(Error::NoBody(_))
    ));
    let mask = vec![true; 3];
    assert!(err(fit_pose(
        &depth,
        &cam,
        &pose,
        &model,
        Some(&mask),
        None,
        &cfg
    ))
    .starts_with("mask"));
    let mut bad = cfg;
    bad.em.sigma = -1.0;
    assert!(err(fit_pose(&depth, &cam, &pose, &model, None, None, &bad)).starts_with("sigma"));
    let mut bad = cfg;
    bad.em.outlier_distance_start = 0.01;
    assert!(err(fit_pose(&depth, &cam, &pose, &model, None, None, &bad))
        .starts_with("outlier_distance_start"));
}

/// Leftover background (a wall patch 1.2 m behind the body) goes to the outlier label
/// and does not drag the fit.
#[test]
fn background_clutter_becomes_outliers() {
    let model = BodyModel::default();
    let cam = Camera::itop().scaled(0.5).unwrap();
    let truth = natural_pose();
    let (mut depth, _) = model.render_depth(&truth, &cam);
    let (w, h) = (cam.width, cam.height);
    let mut wall = Vec::new();
    for row in h / 4..h / 2 {
        for col in 0..w / 5 {
            let i = row * w + col;
            if depth[i] == 0.0 {
                depth[i] = 4.0;
                wall.push(i);
            }
        }
    }
    assert!(wall.len() > 100);
    let init = perturbed(&truth, 11, 0.1, 0.03);
    let r = fit_default(&depth, &cam, &init, &model);
    assert!(wall.iter().all(|&i| r.labels[i] == -1));
    assert!(r.outliers >= wall.len());
    let (mean, _) = joint_errors(&model, &r.pose, &truth);
    assert!(mean < 0.01, "mean {mean}");
}

/// EM on every second pixel of every second row, then one full-resolution E-step: the
/// pose is recovered about as well as at full resolution, every foreground pixel gets
/// a label, and the labels agree with the full-resolution fit almost everywhere.
#[test]
fn stride_two_recovers_pose_and_labels_every_pixel() {
    let model = BodyModel::default();
    let cam = Camera::itop();
    let truth = natural_pose();
    let (depth, _) = model.render_depth(&truth, &cam);
    let n_fg = depth.iter().filter(|z| **z > 0.0).count();
    let strided = FitConfig {
        stride: 2,
        ..FitConfig::default()
    };
    let mut good = 0;
    for seed in 1..7 {
        let init = perturbed(&truth, seed, 20f64.to_radians(), 0.1);
        let r = fit_pose(&depth, &cam, &init, &model, None, None, &strided).unwrap();
        assert!(r.energy_trace.windows(2).all(|w| w[1] <= w[0]));
        assert_eq!(r.part_counts.iter().sum::<usize>() + r.outliers, n_fg);
        let labelled = r.labels.iter().filter(|&&l| l >= 0).count();
        assert_eq!(labelled, n_fg - r.outliers);
        let mean = joint_errors(&model, &r.pose, &truth).0;
        if mean < 0.015 {
            good += 1;
            let full = fit_default(&depth, &cam, &init, &model);
            let same = r
                .labels
                .iter()
                .zip(&full.labels)
                .filter(|(a, b)| a == b)
                .count();
            let agree = (same - (depth.len() - n_fg)) as f64 / n_fg as f64;
            assert!(agree > 0.95, "seed {seed}: labels agree on {agree}");
        }
    }
    assert!(good >= 5, "{good} of 6 starts within 1.5 cm");
}

/// Without the full-resolution labelling a strided fit has the same pose and EM, its
/// labels sit on the sub-sampled pixels only (where a continued fit reads them back),
/// and a fit continued from it at the same stride converges and labels every pixel.
#[test]
fn strided_fit_without_full_labels_keeps_its_em() {
    let model = BodyModel::default();
    let cam = Camera::itop();
    let truth = natural_pose();
    let (depth, _) = model.render_depth(&truth, &cam);
    let w = cam.width;
    let all = FitConfig {
        stride: 2,
        em: EmConfig {
            max_iterations: 2,
            ..EmConfig::default()
        },
        ..FitConfig::default()
    };
    let brief = FitConfig {
        label_all_pixels: false,
        ..all
    };
    let init = perturbed(&truth, 3, 20f64.to_radians(), 0.1);
    let a = FitProblem::new(&depth, &cam, None, &all)
        .unwrap()
        .fit(&model, &init, None)
        .unwrap();
    let problem = FitProblem::new(&depth, &cam, None, &brief).unwrap();
    let b = problem.fit(&model, &init, None).unwrap();
    assert_eq!(a.pose, b.pose);
    assert_eq!(a.energy_trace, b.energy_trace);
    assert_eq!(a.iterations, b.iterations);
    let n_sub = (0..depth.len())
        .filter(|&px| depth[px] > 0.0 && (px / w).is_multiple_of(2) && (px % w).is_multiple_of(2))
        .count();
    assert_eq!(b.part_counts.iter().sum::<usize>() + b.outliers, n_sub);
    for (px, &l) in b.labels.iter().enumerate() {
        if l >= 0 {
            assert!(
                (px / w).is_multiple_of(2) && (px % w).is_multiple_of(2),
                "label at odd pixel {px}"
            );
        }
    }
    assert_eq!(
        b.labels.iter().filter(|&&l| l >= 0).count(),
        n_sub - b.outliers
    );
    // Labelled at every pixel afterwards: exactly the fit that labelled them itself; a
    // result labelled already comes back as it is.
    let labelled = problem.label_all(&model, &b, None).unwrap();
    assert_eq!(labelled, a);
    assert_eq!(problem.label_all(&model, &a, None).unwrap(), a);
    // Continued at stride 2 (labelling every pixel at the end), from either result.
    let more = FitConfig {
        em: EmConfig {
            max_iterations: 6,
            ..all.em
        },
        ..all
    };
    let cont = FitProblem::new(&depth, &cam, None, &more).unwrap();
    let from_b = cont.fit_from(&model, &b.pose, Some(&b), None).unwrap();
    assert!(from_b.energy_trace.windows(2).all(|w| w[1] <= w[0]));
    assert!(joint_errors(&model, &from_b.pose, &truth).0 < 0.015);
    assert_eq!(
        from_b.labels.iter().filter(|&&l| l >= 0).count() + from_b.outliers,
        depth.iter().filter(|z| **z > 0.0).count()
    );
}

#[test]
fn stride_out_of_range_is_an_error() {
    let model = BodyModel::default();
    let cam = Camera::itop().scaled(0.5).unwrap();
    let (depth, _) = model.render_depth(&natural_pose(), &cam);
    for stride in [0, MAX_STRIDE + 1] {
        let cfg = FitConfig {
            stride,
            ..FitConfig::default()
        };
        let err = fit_pose(&depth, &cam, &natural_pose(), &model, None, None, &cfg).unwrap_err();
        assert!(err.to_string().contains("stride"), "{err}");
    }
}

/// The batch builds the cloud and graph once and fits in parallel; every result must be
/// exactly the separate fit's.
#[test]
fn fit_each_equals_separate_fits() {
    let model = BodyModel::default();
    let cam = Camera::itop();
    let truth = natural_pose();
    let (depth, _) = model.render_depth(&truth, &cam);
    let inits: Vec<Pose> = (1..4)
        .map(|seed| perturbed(&truth, seed, 15f64.to_radians(), 0.05))
        .collect();
    for stride in [1, 2] {
        let mut config = FitConfig {
            stride,
            ..FitConfig::default()
        };
        config.em.max_iterations = 3;
        let batch = FitProblem::new(&depth, &cam, None, &config)
            .and_then(|p| p.fit_each(&model, &inits, None, None))
            .unwrap();
        assert_eq!(batch.len(), inits.len());
        for (init, b) in inits.iter().zip(&batch) {
            let a = fit_pose(&depth, &cam, init, &model, None, None, &config).unwrap();
            assert_eq!(&a, b);
        }
    }
}

/// Continuing a fit that stopped at its iteration limit gives the longer fit (pose,
/// labels, energy, iteration count); bad resume data is refused.
#[test]
fn resumed_fit_equals_the_longer_fit() {
    let model = BodyModel::default();
    let cam = Camera::itop();
    let truth = natural_pose();
    let (depth, _) = model.render_depth(&truth, &cam);
    let init = perturbed(&truth, 3, 20f64.to_radians(), 0.1);
    let config = |max_iterations| {
        let mut c = FitConfig::default();
        c.em.max_iterations = max_iterations;
        c
    };
    let problem = FitProblem::new(&depth, &cam, None, &config(8)).unwrap();
    let long = problem.fit(&model, &init, None).unwrap();
    let brief = FitProblem::new(&depth, &cam, None, &config(3))
        .unwrap()
        .fit(&model, &init, None)
        .unwrap();
    assert_eq!(brief.iterations, 3);
    let resumed = problem
        .fit_from(&model, &brief.pose, Some(&brief), None)
        .unwrap();
    assert_eq!(resumed.pose, long.pose);
    assert_eq!(resumed.labels, long.labels);
    assert_eq!(resumed.energy, long.energy);
    assert_eq!(resumed.iterations, long.iterations);
    assert_eq!(resumed.termination, long.termination);
    // The resumed trace is the tail of the long one.
    let tail = &long.energy_trace[long.energy_trace.len() - resumed.energy_trace.len()..];
    assert_eq!(resumed.energy_trace, tail);
    // Labels of another image size.
    let mut other = brief.clone();
    other.labels.pop();
    let err = problem.fit_from(&model, &brief.pose, Some(&other), None);
    assert!(matches!(err, Err(Error::InvalidArgument { ref name, .. }) if name == "resume"));
}

/// Adaptive annealing: a fit that settles while τ anneals takes the final τ at once and
/// stops sooner, at the same pose within a millimetre (the truth's here), its energy
/// trace non-increasing; without the cut it anneals to the end. A fit stopped at its
/// cut, continued, is the uninterrupted fit.
#[test]
fn a_settled_fit_cuts_its_annealing_and_resumes_after_the_cut() {
    let model = BodyModel::default();
    let cam = Camera::itop();
    let truth = natural_pose();
    let (depth, _) = model.render_depth(&truth, &cam);
    let init = perturbed(&truth, 3, 10f64.to_radians(), 0.05);
    let config = |adaptive_anneal, max_iterations| {
        let mut c = FitConfig::default();
        c.em.adaptive_anneal = adaptive_anneal;
        c.em.max_iterations = max_iterations;
        c
    };
    let fit = |c: &FitConfig| fit_pose(&depth, &cam, &init, &model, None, None, c).unwrap();
    let cut = fit(&config(true, 20));
    let full = fit(&config(false, 20));
    let anneal = FitConfig::default().em.anneal_iterations;
    let k = cut
        .anneal_cut
        .expect("the fit settles before τ has annealed");
    assert!(k + 1 < anneal, "cut after iteration {k}");
    // Settled (converged, or an iteration that changed nothing), not stopped by the limit.
    assert_ne!(cut.termination, EmTermination::MaxIterations);
    assert!(cut.iterations < full.iterations);
    assert!(full.iterations >= anneal);
    assert_eq!(full.anneal_cut, None);
    for r in [&cut, &full] {
        assert!(r.energy_trace.windows(2).all(|w| w[1] <= w[0]));
        assert!(joint_errors(&model, &r.pose, &truth).0 < 0.002);
    }
    assert!(joint_errors(&model, &cut.pose, &full.pose).1 < 0.001);
    // Stopped at the cut (the final τ decided, not used yet), then continued.
    let problem = FitProblem::new(&depth, &cam, None, &config(true, 20)).unwrap();
    let brief = fit(&config(true, k));
    assert_eq!((brief.iterations, brief.anneal_cut), (k, Some(k)));
    let resumed = problem
        .fit_from(&model, &brief.pose, Some(&brief), None)
        .unwrap();
    assert_eq!(resumed.pose, cut.pose);
    assert_eq!(resumed.labels, cut.labels);
    assert_eq!(resumed.energy, cut.energy);
    assert_eq!(resumed.iterations, cut.iterations);
    assert_eq!(resumed.anneal_cut, Some(k));
}

/// Coarse to fine: the full-resolution iterations continue the strided fit from its
/// pose and full-resolution labelling, so their energy starts at the strided result's
/// and never rises; they stop within their budget, label every pixel, and a brief
/// fit labelled afterwards ends the same way.
#[test]
fn full_resolution_iterations_continue_the_strided_fit() {
    let model = BodyModel::default();
    let cam = Camera::itop();
    let truth = natural_pose();
    let (depth, _) = model.render_depth(&truth, &cam);
    let n_fg = depth.iter().filter(|z| **z > 0.0).count();
    let strided = FitConfig {
        stride: 2,
        ..FitConfig::default()
    };
    let fine = FitConfig {
        full_resolution_iterations: 3,
        ..strided
    };
    let mut errors = Vec::new();
    for seed in 1..5 {
        let init = perturbed(&truth, seed, 20f64.to_radians(), 0.1);
        let coarse = fit_pose(&depth, &cam, &init, &model, None, None, &strided).unwrap();
        let r = fit_pose(&depth, &cam, &init, &model, None, None, &fine).unwrap();
        let tol = 1e-9 * coarse.energy.abs();
        assert!(
            (r.energy_trace[0] - coarse.energy).abs() <= tol,
            "seed {seed}"
        );
        assert!(
            r.energy_trace.windows(2).all(|w| w[1] <= w[0]),
            "seed {seed}"
        );
        assert!(r.energy <= coarse.energy + tol);
        assert!(r.iterations > coarse.iterations && r.iterations <= coarse.iterations + 3);
        assert_eq!(r.part_counts.iter().sum::<usize>() + r.outliers, n_fg);
        assert_eq!(
            r.labels.iter().filter(|&&l| l >= 0).count(),
            n_fg - r.outliers
        );
        errors.push(joint_errors(&model, &r.pose, &truth).0);
    }
    let good = errors.iter().filter(|&&e| e < 0.01).count();
    assert!(good >= 3, "joint errors {errors:?}");
    // A brief fit (EM labels only) labelled afterwards runs the same refinement.
    let brief = FitConfig {
        label_all_pixels: false,
        ..fine
    };
    let init = perturbed(&truth, 2, 20f64.to_radians(), 0.1);
    let problem = FitProblem::new(&depth, &cam, None, &brief).unwrap();
    let b = problem.fit(&model, &init, None).unwrap();
    let direct = fit_pose(&depth, &cam, &init, &model, None, None, &fine).unwrap();
    assert_eq!(problem.label_all(&model, &b, None).unwrap(), direct);
    // Out of range.
    let bad = FitConfig {
        full_resolution_iterations: MAX_FULL_RESOLUTION_ITERATIONS + 1,
        ..fine
    };
    let err = fit_pose(&depth, &cam, &init, &model, None, None, &bad).unwrap_err();
    assert!(
        err.to_string().contains("full_resolution_iterations"),
        "{err}"
    );
}

/// The swapped-limb starts include the default fit's starts, so their fit never ends at
/// a higher energy; a start with the legs exchanged is recovered; results repeat.
#[test]
fn swapped_limb_starts_never_end_higher() {
    let model = BodyModel::default();
    let cam = Camera::itop();
    let mut truth = natural_pose();
    truth[param::R_HIP] = 1.2;
    truth[param::R_KNEE] = 1.5;
    let (depth, _) = model.render_depth(&truth, &cam);
    let swapped = FitConfig {
        swapped_limb_starts: true,
        ..FitConfig::default()
    };
    for seed in 1..3 {
        let init = start::limbs_swapped(
            &perturbed(&truth, seed, 20f64.to_radians(), 0.1),
            true,
            false,
        );
        let plain = fit_default(&depth, &cam, &init, &model);
        let r = fit_pose(&depth, &cam, &init, &model, None, None, &swapped).unwrap();
        assert!(r.energy <= plain.energy, "seed {seed}");
        assert!(
            joint_errors(&model, &r.pose, &truth).0 < 0.01,
            "seed {seed}"
        );
        let again = fit_pose(&depth, &cam, &init, &model, None, None, &swapped).unwrap();
        assert_eq!(r, again);
    }
}

/// A depth image of absurd readings is refused naming `depth`, not failing later on
/// the CRF weights its point distances would overflow.
#[test]
fn a_fit_refuses_readings_beyond_its_farthest_depth() {
    let camera = Camera::itop();
    let n = camera.width * camera.height;
    for z in [1.0e30f32, 2.0 * MAX_FIT_DEPTH] {
        let depth = vec![z; n];
        let err = FitProblem::new(&depth, &camera, None, &FitConfig::default());
        assert!(
            matches!(err, Err(Error::InvalidArgument { ref name, .. }) if name == "depth"),
            "{z}: {:?}",
            err.err()
        );
    }
    let near = vec![MAX_FIT_DEPTH; n];
    assert!(FitProblem::new(&near, &camera, None, &FitConfig::default()).is_ok());
}
