use super::*;
use proptest::prelude::*;

/// A smooth, aperiodic texture: a sum of sinusoids of random direction, wavelength
/// (3–16 px) and phase, defined at any real position.
struct Texture {
    waves: Vec<(f32, f32, f32, f32)>,
}

impl Texture {
    fn new(seed: u64) -> Self {
        let mut rng = SplitMix64::new(seed);
        let mut unit = || (rng.next_u64() >> 11) as f32 / (1u64 << 53) as f32;
        let waves = (0..24)
            .map(|_| {
                let angle = unit() * std::f32::consts::TAU;
                let k = std::f32::consts::TAU / (3.0 + 13.0 * unit());
                (
                    k * angle.cos(),
                    k * angle.sin(),
                    unit() * std::f32::consts::TAU,
                    0.5 + unit(),
                )
            })
            .collect();
        Texture { waves }
    }

    fn at(&self, u: f32, v: f32) -> f32 {
        self.waves
            .iter()
            .map(|&(kx, ky, phase, amp)| amp * (kx * u + ky * v + phase).sin())
            .sum()
    }
}

/// A slanted textured plane with disparity d(x, y) = a + b·x + c·y in the left image.
/// Right pixel x' shows the left point x = (x' + a + c·y) / (1 − b).
fn slanted_pair(w: usize, h: usize, (a, b, c): (f32, f32, f32)) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let tex = Texture::new(11);
    let mut left = vec![0.0; w * h];
    let mut right = vec![0.0; w * h];
    let mut truth = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let (xf, yf) = (x as f32, y as f32);
            left[y * w + x] = tex.at(xf, yf);
            truth[y * w + x] = a + b * xf + c * yf;
            right[y * w + x] = tex.at((xf + a + c * yf) / (1.0 - b), yf);
        }
    }
    (left, right, truth)
}

/// A random-dot stereogram: background at disparity `d_back`, a square at `d_front`.
/// Left pixel (x, y) copies right pixel (x − d, y). Returns also the true disparity and
/// whether each left pixel is visible in the right image (not hidden by the square).
fn random_dots(
    w: usize,
    h: usize,
    d_back: usize,
    d_front: usize,
    square: (usize, usize, usize, usize),
) -> (Vec<f32>, Vec<f32>, Vec<f32>, Vec<bool>) {
    let mut rng = SplitMix64::new(5);
    let right: Vec<f32> = (0..w * h).map(|_| rng.below(256) as f32).collect();
    let (x0, y0, x1, y1) = square;
    let mut left = vec![0.0; w * h];
    let mut truth = vec![f32::NAN; w * h];
    let mut visible = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let front = (x0..x1).contains(&x) && (y0..y1).contains(&y);
            let d = if front { d_front } else { d_back };
            if x < d {
                left[y * w + x] = rng.below(256) as f32;
                continue;
            }
            truth[y * w + x] = d as f32;
            // Background points whose right pixel the square covers are occluded: the
            // right camera does not see them, so they show fresh dots.
            let xr = x - d;
            let hidden = !front && (y0..y1).contains(&y) && xr + d_front >= x0 && xr + d_front < x1;
            visible[y * w + x] = !hidden;
            left[y * w + x] = if hidden {
                rng.below(256) as f32
            } else {
                right[y * w + x - d]
            };
        }
    }
    (left, right, truth, visible)
}

/// Whether pixel i of a w×h image has its 5×5 window inside the image.
fn inside(i: usize, w: usize, h: usize) -> bool {
    let (x, y) = (i % w, i / w);
    x >= 2 && y >= 2 && x + 2 < w && y + 2 < h
}

fn errors(
    result: &StereoResult,
    truth: &[f32],
    keep: impl Fn(usize) -> bool,
) -> (usize, usize, Vec<f32>) {
    let mut considered = 0;
    let mut matched = 0;
    let mut errs = Vec::new();
    for (i, (&t, &d)) in truth.iter().zip(&result.disparity).enumerate() {
        if t.is_nan() || !keep(i) {
            continue;
        }
        considered += 1;
        if !d.is_nan() {
            matched += 1;
            errs.push((d - t).abs());
        }
    }
    (considered, matched, errs)
}

#[test]
fn slanted_plane_is_recovered_to_subpixel_accuracy() {
    let (w, h) = (96, 64);
    let (left, right, truth) = slanted_pair(w, h, (6.0, 0.05, 0.03));
    let cfg = StereoConfig {
        max_disparity: Some(20),
        num_seeds: 50,
        ..Default::default()
    };
    let res = match_stereo(&left, &right, h, w, &cfg).unwrap();
    // Pixels whose window lies inside both images.
    let margin = 2 + 1;
    let (n, m, errs) = errors(&res, &truth, |i| {
        let (x, y) = (i % w, i / w);
        x >= margin + 12 && x + margin < w && y >= margin && y + margin < h
    });
    // A plane slanted by 0.05 px/px squeezes 20 left pixels into 19 right ones, so
    // uniqueness leaves one in 20 unmatched; gap filling recovers them.
    assert!(m as f32 >= 0.99 * n as f32, "density {m}/{n}");
    let no_fill = StereoConfig {
        fill_gaps: false,
        ..cfg.clone()
    };
    let sparse = match_stereo(&left, &right, h, w, &no_fill).unwrap();
    let (_, m_sparse, _) = errors(&sparse, &truth, |i| {
        let (x, y) = (i % w, i / w);
        x >= margin + 12 && x + margin < w && y >= margin && y + margin < h
    });
    assert!((m_sparse as f32) < 0.97 * n as f32 && m_sparse as f32 > 0.93 * n as f32);
    let mean = errs.iter().sum::<f32>() / m as f32;
    let worst = errs.iter().fold(0.0f32, |a, &b| a.max(b));
    assert!(mean < 0.12, "mean error {mean} px");
    assert!(worst < 0.6, "worst error {worst} px");
    // Subpixel refinement helps: integer disparities alone err by ~0.25 px on average.
    let int_cfg = StereoConfig {
        subpixel: false,
        ..cfg.clone()
    };
    let int_res = match_stereo(&left, &right, h, w, &int_cfg).unwrap();
    let (_, _, int_errs) = errors(&int_res, &truth, |i| {
        let (x, y) = (i % w, i / w);
        x >= margin + 12 && x + margin < w && y >= margin && y + margin < h
    });
    let int_mean = int_errs.iter().sum::<f32>() / int_errs.len() as f32;
    assert!(
        mean < 0.6 * int_mean,
        "subpixel {mean} vs integer {int_mean}"
    );
}

#[test]
fn random_dot_steps_are_recovered() {
    let (w, h) = (80, 60);
    let (left, right, truth, visible) = random_dots(w, h, 3, 11, (30, 18, 60, 44));
    let cfg = StereoConfig {
        max_disparity: Some(16),
        num_seeds: 40,
        ..Default::default()
    };
    let res = match_stereo(&left, &right, h, w, &cfg).unwrap();
    let (n, m, errs) = errors(&res, &truth, |i| {
        visible[i] && i % w >= 16 && inside(i, w, h)
    });
    let bad = errs.iter().filter(|&&e| e > 1.0).count();
    assert!(m as f32 >= 0.95 * n as f32, "density {m}/{n}");
    // The few errors sit on the square's outline, where windows straddle the step.
    assert!((bad as f32) < 0.02 * m as f32, "bad-1 {bad}/{m}");
    // Integer truth: the subpixel estimate stays close to it away from the steps.
    let (_, _, interior) = errors(&res, &truth, |i| {
        let (x, y) = (i % w, i / w);
        (36..56).contains(&x) && (22..40).contains(&y)
    });
    assert!(
        interior.iter().all(|&e| e < 0.25),
        "interior errors {interior:?}"
    );
}

#[test]
fn growth_from_user_seeds_alone() {
    let (w, h) = (80, 60);
    let (left, right, truth, visible) = random_dots(w, h, 3, 11, (30, 18, 60, 44));
    let cfg = StereoConfig {
        num_seeds: 0,
        max_disparity: Some(16),
        ..Default::default()
    };
    let seeds = [
        Seed {
            x: 40,
            y: 30,
            d: 11,
        },
        Seed { x: 20, y: 10, d: 3 },
    ];
    let res = match_stereo_seeded(&left, &right, h, w, &cfg, &seeds).unwrap();
    assert_eq!(res.seeds_used, 2);
    let (n, m, errs) = errors(&res, &truth, |i| {
        visible[i] && i % w >= 16 && inside(i, w, h)
    });
    assert!(m as f32 >= 0.9 * n as f32, "density {m}/{n}");
    assert!(errs.iter().filter(|&&e| e > 1.0).count() * 50 < m);
}

#[test]
fn matches_are_unique_in_the_right_image() {
    let (w, h) = (80, 60);
    let (left, right, _, _) = random_dots(w, h, 3, 11, (30, 18, 60, 44));
    let cfg = StereoConfig {
        subpixel: false,
        fill_gaps: false,
        ..Default::default()
    };
    let res = match_stereo(&left, &right, h, w, &cfg).unwrap();
    let mut used = vec![false; w * h];
    for (i, &d) in res.disparity.iter().enumerate() {
        if d.is_nan() {
            continue;
        }
        assert!(d >= 0.0 && d as usize <= i % w);
        let j = i - d as usize;
        assert!(!used[j], "right pixel {j} matched twice");
        used[j] = true;
        assert!(res.confidence[i] >= cfg.threshold);
    }
}

#[test]
fn left_right_check_keeps_correct_matches_and_drops_occlusions() {
    let (w, h) = (80, 60);
    let (left, right, truth, visible) = random_dots(w, h, 3, 11, (30, 18, 60, 44));
    let cfg = StereoConfig {
        max_disparity: Some(16),
        lr_check: true,
        threshold: 0.6,
        ..Default::default()
    };
    let res = match_stereo(&left, &right, h, w, &cfg).unwrap();
    let (n, m, errs) = errors(&res, &truth, |i| {
        visible[i] && i % w >= 16 && inside(i, w, h)
    });
    assert!(m as f32 >= 0.9 * n as f32, "density {m}/{n}");
    let bad = errs.iter().filter(|&&e| e > 1.0).count();
    // Errors on the step outline are consistent both ways; the check cannot see them.
    assert!(bad * 100 < m, "bad-1 {bad}/{m} after the left-right check");
    // Occluded background pixels (hidden behind the square's left edge) stay unmatched.
    let occluded: Vec<usize> = (0..w * h)
        .filter(|&i| !truth[i].is_nan() && !visible[i])
        .collect();
    let wrong = occluded
        .iter()
        .filter(|&&i| !res.disparity[i].is_nan())
        .count();
    assert!(
        wrong * 4 <= occluded.len(),
        "{wrong}/{} occluded matched",
        occluded.len()
    );
}

#[test]
fn small_segments_are_removed() {
    let mut disp = vec![UNMATCHED; 10 * 10];
    disp[..30].fill(5); // rows 0..3: one segment of 30
    disp[55] = 9;
    disp[56] = 9; // a segment of 2
    disp[77] = 2; // a lone pixel
    remove_small_segments(&mut disp, 10, 10, 3);
    assert_eq!(disp.iter().filter(|&&d| d != UNMATCHED).count(), 30);
    assert!(disp[..30].iter().all(|&d| d == 5));
}

#[test]
fn uniform_images_give_an_empty_result() {
    let (w, h) = (40, 30);
    let flat = vec![0.5f32; w * h];
    let res = match_stereo(&flat, &flat, h, w, &StereoConfig::default()).unwrap();
    assert_eq!(res.matched(), 0);
    assert!(res.confidence.iter().all(|c| c.is_nan()));
    // Texture in one half only: nothing is matched in the flat half.
    let (left, right, _, _) = random_dots(w, h, 2, 2, (0, 0, 0, 0));
    let mut l2 = left.clone();
    let mut r2 = right.clone();
    for y in 0..h {
        for x in 20..w {
            l2[y * w + x] = 7.0;
            r2[y * w + x] = 7.0;
        }
    }
    let res = match_stereo(&l2, &r2, h, w, &StereoConfig::default()).unwrap();
    assert!(res.matched() > 0);
    for y in 0..h {
        for x in 23..w {
            assert!(res.disparity[y * w + x].is_nan());
        }
    }
}

#[test]
fn bad_input_is_refused_with_the_argument_named() {
    let (w, h) = (20, 10);
    let img = vec![0.0f32; w * h];
    let named = |r: Result<StereoResult>, name: &str| match r {
        Err(Error::InvalidArgument { name: n, .. }) => assert_eq!(n, name),
        other => panic!("expected an error naming {name}, got {other:?}"),
    };
    let cfg = StereoConfig::default();
    named(match_stereo(&img, &img[..w * h - 1], h, w, &cfg), "right");
    named(match_stereo(&img[..5], &img, h, w, &cfg), "left");
    let mut nan = img.clone();
    nan[3] = f32::NAN;
    named(match_stereo(&img, &nan, h, w, &cfg), "right");
    for (cfg, name) in [
        (
            StereoConfig {
                window: 4,
                ..Default::default()
            },
            "window",
        ),
        (
            StereoConfig {
                window: 1,
                ..Default::default()
            },
            "window",
        ),
        (
            StereoConfig {
                threshold: 1.5,
                ..Default::default()
            },
            "threshold",
        ),
        (
            StereoConfig {
                threshold: f32::NAN,
                ..Default::default()
            },
            "threshold",
        ),
        (
            StereoConfig {
                num_seeds: 0,
                ..Default::default()
            },
            "num_seeds",
        ),
        (
            StereoConfig {
                num_seeds: 1 << 40,
                ..Default::default()
            },
            "num_seeds",
        ),
        (
            StereoConfig {
                max_disparity: Some(20),
                ..Default::default()
            },
            "max_disparity",
        ),
        (
            StereoConfig {
                seed_distinctness: 0.0,
                ..Default::default()
            },
            "seed_distinctness",
        ),
        (
            StereoConfig {
                min_texture: -1.0,
                ..Default::default()
            },
            "min_texture",
        ),
    ] {
        named(match_stereo(&img, &img, h, w, &cfg), name);
    }
    let seeds = [Seed { x: 3, y: 2, d: 5 }];
    named(match_stereo_seeded(&img, &img, h, w, &cfg, &seeds), "seeds");
    named(match_stereo(&[], &[], 0, 0, &cfg), "left");
}

#[test]
fn tiny_images_give_an_empty_result() {
    let img = vec![1.0, 2.0, 3.0, 4.0];
    let res = match_stereo(&img, &img, 2, 2, &StereoConfig::default()).unwrap();
    assert_eq!(res.matched(), 0);
}

#[test]
fn depth_follows_the_pinhole_formula() {
    let disp = [10.0f32, f32::NAN, 0.0, -40.0];
    let z = depth_from_disparity(&disp, 1000.0, 0.2, 30.0).unwrap();
    assert!((z[0] - 5.0).abs() < 1e-6);
    assert_eq!(z[1], 0.0);
    assert!((z[2] - 200.0 / 30.0).abs() < 1e-5);
    assert_eq!(z[3], 0.0);
    assert!(matches!(
        depth_from_disparity(&disp, 0.0, 0.2, 0.0),
        Err(Error::InvalidArgument { name, .. }) if name == "focal"
    ));
    assert!(depth_from_disparity(&disp, 1.0, -1.0, 0.0).is_err());
    assert!(depth_from_disparity(&disp, 1.0, 1.0, f64::NAN).is_err());
}

#[test]
fn gray_uses_luma_weights() {
    let g = gray_from_rgb(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 10.0, 10.0, 10.0]);
    assert_eq!(g.len(), 3);
    assert!((g[0] - 0.299).abs() < 1e-6 && (g[1] - 0.587).abs() < 1e-6);
    assert!((g[2] - 10.0).abs() < 1e-4);
}

/// The plain definition of the segment filter, a flood fill from every matched pixel:
/// the reference of `runs_remove_the_same_segments_as_a_flood_fill`.
fn remove_small_segments_by_flood_fill(
    disp: &mut [i32],
    width: usize,
    height: usize,
    min_size: usize,
) {
    let n = width * height;
    let mut seen = vec![false; n];
    for start in 0..n {
        if disp[start] == UNMATCHED || seen[start] {
            continue;
        }
        seen[start] = true;
        let (mut stack, mut members) = (vec![start], Vec::new());
        while let Some(i) = stack.pop() {
            members.push(i);
            let (x, y) = (i % width, i / width);
            let neighbours = [
                (x > 0).then(|| i - 1),
                (x + 1 < width).then(|| i + 1),
                (y > 0).then(|| i - width),
                (y + 1 < height).then(|| i + width),
            ];
            for j in neighbours.into_iter().flatten() {
                if disp[j] != UNMATCHED && !seen[j] && (disp[j] - disp[i]).abs() <= SEGMENT_STEP {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
        if members.len() < min_size {
            for i in members {
                disp[i] = UNMATCHED;
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]
    /// Random maps of few disparities and many holes: long, winding segments that join
    /// and split between rows, the cases a run-based filter can get wrong.
    #[test]
    fn runs_remove_the_same_segments_as_a_flood_fill(
        seed in 0u64..1_000_000,
        width in 1usize..40,
        height in 1usize..30,
        holes in 0u64..60,
        levels in 1u64..6,
        min_size in 0usize..40,
    ) {
        let mut rng = SplitMix64::new(seed);
        let mut disp: Vec<i32> = (0..width * height)
            .map(|_| if rng.below(100) < holes as usize { UNMATCHED } else { rng.below(levels as usize) as i32 })
            .collect();
        let mut want = disp.clone();
        remove_small_segments_by_flood_fill(&mut want, width, height, min_size);
        remove_small_segments(&mut disp, width, height, min_size);
        prop_assert_eq!(disp, want);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]
    /// On any textured pair: matches are one-to-one, inside the disparity bound, and
    /// scaling/shifting the intensities changes nothing (the correlation is invariant).
    #[test]
    fn invariants_hold_on_random_pairs(seed in 0u64..1000, d in 0usize..6, gain in 0.5f32..4.0) {
        let (w, h) = (32, 24);
        let mut rng = SplitMix64::new(seed);
        let right: Vec<f32> = (0..w * h).map(|_| rng.below(1000) as f32).collect();
        let left: Vec<f32> = (0..w * h).map(|i| if i % w >= d { right[i - d] } else { 0.0 }).collect();
        let cfg = StereoConfig { max_disparity: Some(8), num_seeds: 30, subpixel: false, fill_gaps: false, ..Default::default() };
        let a = match_stereo(&left, &right, h, w, &cfg).unwrap();
        let l2: Vec<f32> = left.iter().map(|v| v * gain + 3.0).collect();
        let r2: Vec<f32> = right.iter().map(|v| v * gain + 3.0).collect();
        let b = match_stereo(&l2, &r2, h, w, &cfg).unwrap();
        let mut used = vec![false; w * h];
        let mut same = 0;
        for i in 0..w * h {
            let (p, q) = (a.disparity[i], b.disparity[i]);
            if p.is_nan() { continue; }
            prop_assert!(p <= 8.0 && p as usize <= i % w);
            let j = i - p as usize;
            prop_assert!(!used[j]);
            used[j] = true;
            if p == q { same += 1; }
        }
        // Rounding in the normalisation may flip a tie; nearly all must agree.
        prop_assert!(same * 100 >= 98 * a.matched());
        prop_assert!(a.matched() * 2 > (w - 12) * (h - 4));
    }
}

#[test]
fn tall_images_grow_in_bands_without_seams() {
    // Taller than two bands: every band must be grown, and rows next to the band
    // borders must be matched like any other.
    let (w, h) = (40, 2 * BAND_ROWS + 30);
    let (left, right, truth, _) = random_dots(w, h, 5, 5, (0, 0, 0, 0));
    let cfg = StereoConfig {
        max_disparity: Some(10),
        num_seeds: 60,
        ..Default::default()
    };
    let res = match_stereo(&left, &right, h, w, &cfg).unwrap();
    let (n, m, errs) = errors(&res, &truth, |i| inside(i, w, h) && i % w >= 10);
    assert!(m * 100 >= 99 * n, "density {m}/{n}");
    assert!(errs.iter().all(|&e| e < 0.5));
    for y in [BAND_ROWS - 1, BAND_ROWS, 2 * BAND_ROWS - 1, 2 * BAND_ROWS] {
        assert!(
            (10..w - 2).all(|x| !res.disparity[y * w + x].is_nan()),
            "row {y}"
        );
    }
}

#[test]
fn result_does_not_depend_on_the_thread_count() {
    // Bands are fixed in size and grown independently, so one thread and several give
    // the same disparities and confidences bit for bit, left–right check included.
    let (w, h) = (70, 2 * BAND_ROWS + 40);
    let (left, right, _, _) = random_dots(w, h, 4, 9, (20, 30, 50, BAND_ROWS + 20));
    for lr_check in [false, true] {
        let cfg = StereoConfig {
            max_disparity: Some(14),
            num_seeds: 80,
            lr_check,
            ..Default::default()
        };
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| match_stereo(&left, &right, h, w, &cfg).unwrap())
        };
        let one = run(1);
        assert!(one.matched() * 2 > w * h, "lr_check {lr_check}: too sparse");
        for threads in [2, 3] {
            let many = run(threads);
            let same = |a: &[f32], b: &[f32]| {
                a.iter()
                    .zip(b)
                    .all(|(p, q)| p.to_bits() == q.to_bits() || (p.is_nan() && q.is_nan()))
            };
            assert!(same(&one.disparity, &many.disparity), "{threads} threads");
            assert!(same(&one.confidence, &many.confidence), "{threads} threads");
        }
    }
}

#[test]
fn results_do_not_depend_on_earlier_calls() {
    // Growers are pooled between calls: one left by a larger pair with other settings
    // must grow the next pair exactly as a new one would.
    let bits = |a: &[f32]| a.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    let (w, h) = (64, BAND_ROWS + 30);
    let (left, right, _, _) = random_dots(w, h, 3, 5, (10, 20, 30, BAND_ROWS / 2));
    let cfg = StereoConfig {
        max_disparity: Some(12),
        num_seeds: 60,
        ..Default::default()
    };
    let before = match_stereo(&left, &right, h, w, &cfg).unwrap();
    let (bw, bh) = (150, 2 * BAND_ROWS + 11);
    let (big_l, big_r, _, _) = random_dots(bw, bh, 7, 8, (5, 25, 45, BAND_ROWS));
    let other = StereoConfig {
        max_disparity: Some(30),
        lr_check: true,
        threshold: 0.3,
        ..Default::default()
    };
    for _ in 0..2 {
        assert!(
            match_stereo(&big_l, &big_r, bh, bw, &other)
                .unwrap()
                .matched()
                > 0
        );
        let again = match_stereo(&left, &right, h, w, &cfg).unwrap();
        assert_eq!(bits(&before.disparity), bits(&again.disparity));
        assert_eq!(bits(&before.confidence), bits(&again.confidence));
    }
}

#[test]
fn top_and_bottom_rows_are_matched_through_reflected_padding() {
    // Rows within half a window of the top and bottom have their windows completed by
    // reflection (the same rows in both images), so they are matched correctly too.
    let (w, h) = (60, 30);
    let (left, right, truth, _) = random_dots(w, h, 6, 6, (0, 0, 0, 0));
    let cfg = StereoConfig {
        max_disparity: Some(12),
        num_seeds: 100,
        min_segment: 0,
        ..Default::default()
    };
    let res = match_stereo(&left, &right, h, w, &cfg).unwrap();
    for y in [0, 1, h - 2, h - 1] {
        for x in 12..w - 2 {
            let (d, t) = (res.disparity[y * w + x], truth[y * w + x]);
            assert!(!d.is_nan(), "({x}, {y}) unmatched");
            assert!((d - t).abs() < 0.5, "({x}, {y}): {d} vs {t}");
        }
    }
    // Columns within half a window of the left or right border are not padded.
    assert!((0..h).all(|y| res.disparity[y * w + w - 1].is_nan()));
}
