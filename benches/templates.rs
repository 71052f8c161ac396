//! Surface-context descriptors and template matching.
//!
//! `cargo bench --bench templates -- --warm-up-time 1 --measurement-time 3`
//! Also prints the build time and the pruning stage's recall of the exhaustive winner.

use criterion::{criterion_group, criterion_main, Criterion};
use depthpose::body::{param, BodyModel, Pose};
use depthpose::camera::Camera;
use depthpose::cloud::DepthView;
use depthpose::descriptor::{surface_context_from_depth, DescriptorConfig, Silhouette};
use depthpose::templates::{
    matching_cost, template_pose, MatchConfig, TemplateConfig, TemplateDatabase, NUM_TEMPLATES,
};
use rayon::prelude::*;
use std::hint::black_box;
use std::time::Instant;

/// A deterministic generator for the query perturbations.
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Template `t`'s pose with joint angles perturbed by ±0.1 rad, placed off-centre,
/// rendered from the ellipsoid model at 320×240.
fn query(t: usize, rng: &mut Lcg, cam: &Camera) -> Vec<f32> {
    let mut pose: Pose = template_pose(t, 3.0);
    for v in pose[6..].iter_mut() {
        *v += 0.2 * rng.next() - 0.1;
    }
    pose = BodyModel::clamp_pose(&pose);
    pose[param::ROOT_T] = 0.6 * rng.next() - 0.3;
    pose[param::ROOT_T + 2] = 2.7 + rng.next();
    BodyModel::default().render_depth(&pose, cam).0
}

fn bench(c: &mut Criterion) {
    let model = BodyModel::default();
    let cfg = TemplateConfig::default();
    let start = Instant::now();
    let db = TemplateDatabase::build(&model, &cfg).unwrap();
    println!(
        "build of {NUM_TEMPLATES} templates: {:.3} s",
        start.elapsed().as_secs_f64()
    );
    let cam = Camera::itop();
    let mut rng = Lcg(7);

    // Pruning recall: is the exhaustive (exact) winner in the short list?
    let mc = MatchConfig::default();
    let queries = 40;
    let mut kept = 0;
    for _ in 0..queries {
        let t = (rng.next() * NUM_TEMPLATES as f64) as usize;
        let d = query(t, &mut rng, &cam);
        let view = DepthView::new(&d, cam.height, cam.width, "depth").unwrap();
        let sil = Silhouette::from_depth(&view, &cam, None, cfg.descriptor.normal_radius).unwrap();
        let q = sil.surface_context(&cfg.descriptor).unwrap();
        let costs: Vec<f64> = db
            .templates
            .par_iter()
            .map_init(
                || (Default::default(), Vec::new(), Vec::new()),
                |(ws, cm, a), tpl| {
                    matching_cost(
                        &q,
                        &tpl.context,
                        mc.location_weight,
                        mc.dummy_cost,
                        ws,
                        cm,
                        a,
                    )
                },
            )
            .collect();
        let best = (0..costs.len())
            .min_by(|&a, &b| costs[a].total_cmp(&costs[b]))
            .unwrap();
        let r = db.match_context(&q, &mc).unwrap();
        kept += r.shortlist.contains(&best) as usize;
    }
    println!(
        "pruning recall (exhaustive winner in the short list of {}): {kept}/{queries}",
        mc.shortlist
    );

    let d = query(100, &mut rng, &cam);
    let view = DepthView::new(&d, cam.height, cam.width, "depth").unwrap();
    let dc = DescriptorConfig::default();
    c.bench_function("surface_context_320x240", |b| {
        b.iter(|| black_box(surface_context_from_depth(&view, &cam, None, &dc).unwrap()))
    });
    c.bench_function("match_768_templates_320x240", |b| {
        b.iter(|| black_box(db.match_depth(&view, &cam, None, &mc).unwrap()))
    });
    // The same with the best ten re-ranked by their placed fit energy (`rerank`).
    let rerank = MatchConfig { rerank: 10, ..mc };
    c.bench_function("match_768_templates_320x240_rerank10", |b| {
        b.iter(|| black_box(db.match_depth(&view, &cam, None, &rerank).unwrap()))
    });
    let sil = Silhouette::from_depth(&view, &cam, None, dc.normal_radius).unwrap();
    let q = sil.surface_context(&dc).unwrap();
    c.bench_function("exact_assignment_one_template", |b| {
        let (mut ws, mut cm, mut a) = (Default::default(), Vec::new(), Vec::new());
        b.iter(|| {
            black_box(matching_cost(
                &q,
                &db.templates[100].context,
                mc.location_weight,
                mc.dummy_cost,
                &mut ws,
                &mut cm,
                &mut a,
            ))
        })
    });
    let mut group = c.benchmark_group("build");
    group.sample_size(10);
    group.bench_function("build_768_templates", |b| {
        b.iter(|| black_box(TemplateDatabase::build(&model, &cfg).unwrap()))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
