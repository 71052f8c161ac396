use super::catalogue::{template_code, template_pose, LIMB_POSES, NUM_TEMPLATES, NUM_VIEWS};
use super::columns::QueryColumns;
use super::cost::{cost_matrix, pair_cost};
#[cfg(target_arch = "x86_64")]
use super::cost_kernel::{cost_rows_avx512, cost_rows_fma};
use super::database::TemplateDatabase;
use super::format::{config_from_vec, config_to_vec};
use super::matching::{rerank_points, Candidate, MatchConfig};
use super::prune::prune_sum;
use super::prune::{four_low, prune_stride, Representatives, PRUNE_DIRECTIONS};
use super::raster::rasterize_meshes_into;
use super::TemplateConfig;
use crate::body::superquadric::MeshConfig;
use crate::body::{BodyModel, NUM_JOINTS};
use crate::camera::Camera;
use crate::cloud::DepthView;
use crate::descriptor::Silhouette;
use nalgebra::Vector3;

#[test]
fn codes_cover_all_templates_once() {
    let mut seen = std::collections::HashSet::new();
    for i in 0..NUM_TEMPLATES {
        let (c, v) = template_code(i);
        assert!(c.iter().all(|&x| x < LIMB_POSES) && v < NUM_VIEWS);
        assert!(seen.insert((c, v)));
    }
    assert_eq!(NUM_TEMPLATES, 768);
}

#[test]
fn views_turn_the_named_side_to_the_camera() {
    let model = BodyModel::default();
    let j = |i: usize| model.joints(&template_pose(i, 3.0));
    let (rs, ls) = (2, 3); // RShoulder, LShoulder
    let front = j(0);
    assert!((front[rs].z - front[ls].z).abs() < 1e-9 && front[rs].x < front[ls].x);
    let left = j(256);
    assert!(left[ls].z < left[rs].z - 0.2);
    let right = j(512);
    assert!(right[rs].z < right[ls].z - 0.2);
    // Right arm raised sideways: the right hand at shoulder height, far to the side.
    let raised = j(64);
    assert!((raised[6].y - raised[rs].y).abs() < 0.1 && raised[6].x < raised[rs].x - 0.4);
    // Right knee raised: knee well in front of (closer than) the hip.
    let knee = j(3 * 4);
    assert!(knee[11].z < knee[9].z - 0.3);
}

#[test]
fn rasterizer_matches_the_ray_cast_ellipsoids() {
    // The ellipsoid super-quadric (d = 2, s = 0) mesh rasterised vs the analytic
    // ray cast of the same ellipsoid.
    let cam = Camera::new(150.0, 150.0, 31.5, 31.5, 64, 64).unwrap();
    let shape = crate::body::superquadric::SuperquadricShape {
        taper: 0.0,
        exponent: 2.0,
    };
    let cfg = MeshConfig {
        rings: 60,
        sectors: 80,
    };
    let mut mesh =
        crate::body::superquadric::superquadric_mesh(0.2, 0.15, 0.6, &shape, &cfg).unwrap();
    // Centre it at (0.05, 0, 2.5), long axis along y.
    for v in mesh.vertices.iter_mut() {
        *v = [v[0] + 0.05, v[2] - 0.3, v[1] + 2.5];
    }
    let mut raster = vec![0.0; 64 * 64];
    rasterize_meshes_into(&[mesh], &cam, &mut raster).unwrap();
    let e = crate::body::ellipsoid::PlacedEllipsoid {
        centre: Vector3::new(0.05, 0.0, 2.5),
        rotation: nalgebra::Matrix3::identity(),
        prepared: crate::body::ellipsoid::Prepared::new(&Vector3::new(0.2, 0.3, 0.15)),
    };
    let (mut exact, mut labels) = (vec![0.0; 64 * 64], vec![0i16; 64 * 64]);
    crate::render::render_ellipsoids_into(&[e], &[0], &cam, &mut exact, &mut labels).unwrap();
    let (mut both, mut differ) = (0, 0);
    for (r, x) in raster.iter().zip(&exact) {
        match (*r > 0.0, *x > 0.0) {
            (true, true) => {
                both += 1;
                assert!((r - x).abs() < 0.01, "{r} vs {x}");
            }
            (false, false) => {}
            _ => differ += 1,
        }
    }
    assert!(both > 300 && differ * 20 < both, "{both} {differ}");
    assert!(rasterize_meshes_into(&[], &cam, &mut [0.0; 3]).is_err());
}

#[test]
fn template_retrieves_itself_and_is_placed_at_the_body() {
    let db = super::eval::database();
    assert_eq!(db.len(), NUM_TEMPLATES);
    let model = BodyModel::default();
    let cam = Camera::itop();
    for &(t, x) in &[
        (0usize, 0.3),
        (77, -0.8),
        (300, 0.6),
        (555, -0.7),
        (700, 0.5),
        (520, -0.5),
    ] {
        let mut pose = template_pose(t, 3.0);
        pose[0] = x;
        pose[1] = 0.1;
        pose[2] = 3.4;
        let (d, _) = model.render_depth(&pose, &cam);
        let view = DepthView::new(&d, cam.height, cam.width, "depth").unwrap();
        let r = db
            .match_depth(&view, &cam, None, &MatchConfig::default())
            .unwrap();
        assert_eq!(r.candidates.len(), 5);
        let best = &r.candidates[0];
        let joints = model.joints(&pose);
        let err: f64 = best
            .joints
            .iter()
            .zip(&joints)
            .map(|(a, b)| (Vector3::from(*a) - b).norm())
            .sum::<f64>()
            / NUM_JOINTS as f64;
        assert!(
            err < 0.1,
            "template {t}: best {} mean joint error {err}",
            best.index
        );
        assert!((best.scale - 1.0).abs() < 0.15, "{}", best.scale);
    }
}

#[test]
fn arrays_round_trip_and_refuse_mismatches() {
    let db = super::eval::database();
    let a = db.to_arrays();
    let back = TemplateDatabase::from_arrays(&a, Some((&db.model, &db.config)), "f").unwrap();
    assert_eq!(&back, db);
    let mut v = a.clone();
    v.format_version += 1;
    assert!(matches!(
        TemplateDatabase::from_arrays(&v, None, "f"),
        Err(crate::Error::File { .. })
    ));
    let other = BodyModel::new(1.6).unwrap();
    assert!(matches!(
        TemplateDatabase::from_arrays(&a, Some((&other, &db.config)), "f"),
        Err(crate::Error::File { .. })
    ));
    let mut v = a.clone();
    v.descriptors.pop();
    assert!(TemplateDatabase::from_arrays(&v, None, "f").is_err());
    let mut v = a.clone();
    v.shape[0] += 0.01;
    assert!(TemplateDatabase::from_arrays(&v, None, "f").is_err());
    assert_eq!(
        config_from_vec(&config_to_vec(&db.config)).unwrap(),
        db.config
    );
}

/// The pruning score against brute force, for a template's own descriptors and for
/// perturbed noisy renders (no exact twin in the database), over many templates.
#[test]
fn pruned_score_equals_brute_force() {
    let db = super::eval::database();
    let cam = Camera::itop();
    let mut rng = super::eval::Rng(7);
    let mut queries = vec![db.templates[123].context.clone()];
    for t in [5usize, 300, 700] {
        queries.push(super::eval::query_context(db, t, &mut rng, &cam));
    }
    for q in &queries {
        let reps = Representatives::new(&db.prune, q, 8);
        let samples = &reps.samples;
        for t in (0..db.len()).step_by(17).chain([123, 767]) {
            let tc = &db.templates[t].context;
            for lw in [0.0f32, 0.1, 1.0] {
                let brute: f32 = samples
                    .iter()
                    .map(|&i| {
                        (0..tc.len())
                            .map(|j| pair_cost(q, i, tc, j, lw))
                            .fold(f32::INFINITY, f32::min)
                    })
                    .sum::<f32>()
                    / samples.len() as f32;
                let projected = &db.prune.projected[t];
                let sum = prune_sum(q, &reps, tc, projected, lw, f32::INFINITY, &mut Vec::new());
                let fast = sum.unwrap() / samples.len() as f32;
                // Giving up below the sum stops; at the sum (or above) it does not.
                let s = sum.unwrap();
                let at = prune_sum(q, &reps, tc, projected, lw, s, &mut Vec::new());
                assert_eq!(at, Some(s));
                if s > 0.0 {
                    let below = prune_sum(q, &reps, tc, projected, lw, s * 0.999, &mut Vec::new());
                    assert_eq!(below, None);
                }
                assert!(
                    (fast - brute).abs() <= 1e-5 * (1.0 + brute),
                    "template {t}, lw {lw}: {fast} vs {brute}"
                );
            }
        }
    }
}

#[test]
fn four_low_includes_the_least() {
    let v = [
        5.0f32, 1.0, 7.0, 0.5, 3.0, 0.75, 9.0, 2.0, 8.0, 0.25, 6.0, 6.0, 6.0, 6.0, 6.0, 6.0,
    ];
    let mut got = four_low(&v);
    got.sort();
    // Lane minima: 5 (0), 0.25 (9), 6 (10), 0.5 (3), 3 (4), 0.75 (5), 6 (14), 2 (7).
    assert_eq!(got, [3, 5, 7, 9]);
}

/// The cost matrix (template samples × query samples) holds `pair_cost` of every
/// pair to rounding, for sample counts that are and are not multiples of the
/// vector blocks.
#[test]
fn cost_matrix_equals_pair_costs() {
    let db = super::eval::database();
    let cam = Camera::itop();
    let mut rng = super::eval::Rng(11);
    let q = super::eval::query_context(db, 42, &mut rng, &cam);
    let columns = QueryColumns::new(&q);
    let mut cost = Vec::new();
    for t in [0usize, 42, 301, 767] {
        let tc = &db.templates[t].context;
        for lw in [0.0f32, 0.1] {
            cost_matrix(&q, &columns, tc, lw, &mut cost);
            assert_eq!(cost.len(), q.len() * tc.len());
            for j in 0..tc.len() {
                for i in 0..q.len() {
                    let want = pair_cost(&q, i, tc, j, lw) as f64;
                    let got = cost[j * q.len() + i];
                    assert!(
                        (got - want).abs() <= 1e-5 * want + 1e-6,
                        "{i} {j}: {got} vs {want}"
                    );
                }
            }
        }
    }
    assert!(
        db.templates
            .iter()
            .any(|t| !t.context.len().is_multiple_of(4))
            && !q.len().is_multiple_of(16),
        "no template or query exercises the leftover rows and columns"
    );
}

/// The AVX-512 and AVX2 cost kernels write the same rows, bit for bit (where the
/// CPU has both).
#[cfg(target_arch = "x86_64")]
#[test]
fn cost_kernels_agree_bit_for_bit() {
    if !(std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma"))
    {
        eprintln!("skipped: this CPU lacks AVX-512F, AVX2 or FMA");
        return;
    }
    let db = super::eval::database();
    let cam = Camera::itop();
    let mut rng = super::eval::Rng(5);
    for query in [7usize, 300, 600] {
        let q = super::eval::query_context(db, query, &mut rng, &cam);
        let columns = QueryColumns::new(&q);
        for t in [0usize, 42, 301, 767] {
            let tc = &db.templates[t].context;
            let n = q.len();
            let (mut a, mut b) = (vec![-1.0; n * tc.len()], vec![-1.0; n * tc.len()]);
            // SAFETY: the CPU has the features (checked above).
            let rows_a = unsafe { cost_rows_avx512(&columns, tc, 0.1, n, &mut a) };
            let rows_b = unsafe { cost_rows_fma(&columns, tc, 0.1, n, &mut b) };
            assert_eq!(rows_a, rows_b);
            assert_eq!(
                a[..rows_a * n],
                b[..rows_b * n],
                "query {query}, template {t}"
            );
        }
    }
}

/// The short list with the early give-up is the exhaustive ranking's: the best
/// `shortlist` templates by the full pruning score (ties by index), with the same
/// scores.
#[test]
fn shortlist_with_give_up_equals_full_ranking() {
    let db = super::eval::database();
    let cam = Camera::itop();
    let mut rng = super::eval::Rng(11);
    for t in [17usize, 260, 600, 750] {
        let q = super::eval::query_context(db, t, &mut rng, &cam);
        for shortlist in [1usize, 5, 16, 40] {
            let config = MatchConfig {
                shortlist,
                top_k: shortlist,
                ..Default::default()
            };
            let reps = Representatives::new(&db.prune, &q, config.representatives);
            let samples = &reps.samples;
            let lw = config.location_weight as f32;
            let mut full: Vec<(f64, usize)> = (0..db.len())
                .map(|t| {
                    let tc = &db.templates[t].context;
                    let sum = prune_sum(
                        &q,
                        &reps,
                        tc,
                        &db.prune.projected[t],
                        lw,
                        f32::INFINITY,
                        &mut Vec::new(),
                    );
                    ((sum.unwrap() / samples.len() as f32) as f64, t)
                })
                .collect();
            full.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let want: Vec<usize> = full[..shortlist].iter().map(|s| s.1).collect();
            let got = db.match_context(&q, &config).unwrap();
            assert_eq!(got.shortlist, want, "query {t}, shortlist {shortlist}");
            for c in &got.candidates {
                let score = full.iter().find(|s| s.1 == c.index).unwrap().0;
                assert_eq!(c.prune_cost, score);
            }
        }
    }
}

/// The pruning basis is orthonormal, so the descriptions' distances never exceed
/// the descriptors' own.
#[test]
fn prune_projection_is_a_lower_bound() {
    let db = super::eval::database();
    let (k, dim) = (db.prune.components, db.config.descriptor.dim());
    let directions = db.prune.directions;
    assert_eq!(directions, PRUNE_DIRECTIONS.min(dim));
    assert_eq!(k, directions + 1);
    for a in 0..directions {
        for b in 0..directions {
            let dot: f64 = (0..dim)
                .map(|d| db.prune.basis[a * dim + d] * db.prune.basis[b * dim + d])
                .sum();
            let want = if a == b { 1.0 } else { 0.0 };
            assert!((dot - want).abs() < 1e-9, "rows {a}, {b}: {dot}");
        }
    }
    let (ta, tb) = (&db.templates[10], &db.templates[500]);
    let (pa, pb) = (&db.prune.projected[10], &db.prune.projected[500]);
    let (na, nb) = (ta.context.len(), tb.context.len());
    let (sa, sb) = (prune_stride(na), prune_stride(nb));
    let mut tight = 0.0f64;
    let mut one = vec![0.0f32; k];
    for i in 0..na {
        // Stored projections are the basis applied to the descriptor.
        db.prune.project(ta.context.descriptor(i), &mut one);
        assert!((0..k).all(|c| one[c] == pa[c * sa + i]));
        for j in 0..nb {
            let full = crate::descriptor::squared_distance(
                ta.context.descriptor(i),
                tb.context.descriptor(j),
            );
            let lower: f32 = (0..k)
                .map(|c| (pa[c * sa + i] - pb[c * sb + j]).powi(2))
                .sum();
            assert!(lower <= full * 1.0001 + 1e-8, "{lower} > {full}");
            tight += (lower / full.max(1e-12)) as f64;
        }
    }
    // And the bound is useful: it holds most of the distance.
    let mean = tight / (ta.context.len() * tb.context.len()) as f64;
    eprintln!("mean bound / squared distance: {mean:.3}");
    assert!(mean > 0.7, "projected share of squared distance {mean}");
}

/// The re-ranking re-orders the exact stage's best `rerank` candidates by their
/// placed energy and nothing else; on perturbed front-view renders (where the
/// normals cannot tell an arm toward the camera from one hanging down) its first
/// candidates' joints lie nearer the truth than the descriptors' own.
#[test]
fn rerank_orders_the_best_candidates_by_their_placed_energy() {
    let db = super::eval::database();
    let cam = Camera::itop();
    let mut rng = super::eval::Rng(7);
    let truncated = |c: MatchConfig| MatchConfig { top_k: 10, ..c };
    let plain_cfg = truncated(MatchConfig::default());
    let rerank_cfg = MatchConfig {
        rerank: 10,
        ..plain_cfg
    };
    let (mut err_plain, mut err_rerank) = (0.0, 0.0);
    let queries = 12;
    for q in 0..queries {
        // Front views: templates 0..256.
        let t = (rng.uniform() * 256.0) as usize;
        let (d, pose) = super::eval::query(t, &mut rng, &cam, 0.1);
        let view = DepthView::new(&d, cam.height, cam.width, "depth").unwrap();
        let plain = db.match_depth(&view, &cam, None, &plain_cfg).unwrap();
        let rr = db.match_depth(&view, &cam, None, &rerank_cfg).unwrap();
        // A permutation of the same ten, the short list untouched.
        let mut a: Vec<usize> = plain.candidates.iter().map(|c| c.index).collect();
        let mut b: Vec<usize> = rr.candidates.iter().map(|c| c.index).collect();
        assert_eq!(plain.shortlist, rr.shortlist);
        if q == 0 {
            assert_ne!(a, b, "the first query's order should change");
        }
        a.sort_unstable();
        b.sort_unstable();
        assert_eq!(a, b);
        // In ascending placed energy.
        let dc = &db.config.descriptor;
        let sil = Silhouette::from_depth(&view, &cam, None, dc.normal_radius).unwrap();
        let pts = rerank_points(&sil);
        let energies: Vec<f64> = rr
            .candidates
            .iter()
            .map(|c| db.placed_energy(&pts, &d, &cam, &c.pose))
            .collect();
        assert!(energies.windows(2).all(|w| w[0] <= w[1]), "{energies:?}");
        // A shorter list is the head of the re-ranked one; rerank 0 and 1 are off.
        let head = db
            .match_depth(
                &view,
                &cam,
                None,
                &MatchConfig {
                    top_k: 3,
                    ..rerank_cfg
                },
            )
            .unwrap();
        assert_eq!(head.candidates[..], rr.candidates[..3]);
        for off in [0, 1] {
            let same = db
                .match_depth(
                    &view,
                    &cam,
                    None,
                    &MatchConfig {
                        rerank: off,
                        ..plain_cfg
                    },
                )
                .unwrap();
            assert_eq!(same, plain);
        }
        let truth = db.model.joints(&pose);
        let err = |c: &Candidate| {
            c.joints
                .iter()
                .zip(&truth)
                .map(|(j, t)| (Vector3::from(*j) - t).norm())
                .sum::<f64>()
                / NUM_JOINTS as f64
        };
        err_plain += err(&plain.candidates[0]) / queries as f64;
        err_rerank += err(&rr.candidates[0]) / queries as f64;
    }
    eprintln!("mean joint error of the first candidate: descriptors {err_plain:.4} m, re-ranked {err_rerank:.4} m");
    assert!(err_rerank < err_plain, "{err_rerank} vs {err_plain}");
    let bad = MatchConfig {
        rerank: NUM_TEMPLATES + 1,
        ..plain_cfg
    };
    assert!(bad.validate().is_err());
}

#[test]
fn hash_depends_on_model_and_settings() {
    let m = BodyModel::default();
    let c = TemplateConfig::default();
    let h = TemplateDatabase::settings_hash(&m, &c);
    assert_eq!(h, TemplateDatabase::settings_hash(&m, &c));
    assert_ne!(
        h,
        TemplateDatabase::settings_hash(&BodyModel::new(1.6).unwrap(), &c)
    );
    let c2 = TemplateConfig { width: 80, ..c };
    assert_ne!(h, TemplateDatabase::settings_hash(&m, &c2));
}
