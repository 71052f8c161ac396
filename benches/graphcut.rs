//! Max-flow on image grids (4/8-connected, 320×240 and 640×480) with contrast-sensitive
//! weights from a real image, and alpha-expansion on body-part-like labellings.

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use depthpose::graphcut::{grid_edges, CrfProblem, CrfSolver, Graph, MoveConfig};
use depthpose::io::read_gray;
use std::hint::black_box;
use std::path::Path;

const IMAGE: &str = "../shared/data/stereo/cones/cones_left.tif";
/// Smoothness weight of the segmentation benches (relative to unit unaries).
const LAMBDA: f64 = 2.0;

/// The cones image resampled (nearest neighbour) to h×w, gray in [0, 1]. Falls back to a
/// synthetic gradient pattern if the shared data are missing.
fn image(h: usize, w: usize) -> Vec<f64> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(IMAGE);
    match read_gray(&path) {
        Ok(img) => (0..h * w)
            .map(|k| {
                let (r, c) = (k / w, k % w);
                let (sr, sc) = (r * img.height / h, c * img.width / w);
                img.data[sr * img.width + sc] as f64
            })
            .collect(),
        Err(_) => (0..h * w)
            .map(|k| (((k / w) as f64 * 0.07).sin() * ((k % w) as f64 * 0.05).cos() + 1.0) / 2.0)
            .collect(),
    }
}

/// Contrast-sensitive weights λ·exp(−ΔI² / 2σ²) with σ² the mean ΔI² over the edges.
fn contrast_weights(img: &[f64], edges: &[[u32; 2]]) -> Vec<f64> {
    let d2: Vec<f64> = edges
        .iter()
        .map(|&[i, j]| (img[i as usize] - img[j as usize]).powi(2))
        .collect();
    let sigma2 = (d2.iter().sum::<f64>() / d2.len() as f64).max(1e-9);
    d2.iter()
        .map(|&d| LAMBDA * (-d / (2.0 * sigma2)).exp())
        .collect()
}

/// Foreground/background segmentation graph: Gaussian intensity models at the 25th and
/// 75th percentiles, unaries = squared normalised distances.
fn segmentation_graph(h: usize, w: usize, connectivity: u8) -> Graph<f64> {
    let img = image(h, w);
    let edges = grid_edges(h, w, connectivity).unwrap();
    let wts = contrast_weights(&img, &edges);
    let mut sorted = img.clone();
    sorted.sort_by(f64::total_cmp);
    let (bg, fg) = (sorted[sorted.len() / 4], sorted[3 * sorted.len() / 4]);
    let s2 = ((fg - bg) / 2.0).powi(2).max(1e-6);
    let mut g = Graph::with_capacity(h * w, edges.len());
    let src: Vec<u32> = edges.iter().map(|e| e[0]).collect();
    let dst: Vec<u32> = edges.iter().map(|e| e[1]).collect();
    g.add_edges(&src, &dst, &wts, &wts).unwrap();
    for (i, &v) in img.iter().enumerate() {
        // Source side = foreground: a node pays its foreground cost if cut from the
        // source (sink side) and its background cost otherwise.
        let cost_fg = (v - fg).powi(2) / (2.0 * s2);
        let cost_bg = (v - bg).powi(2) / (2.0 * s2);
        g.add_tweights(i, cost_bg, cost_fg).unwrap();
    }
    g.finalize();
    g
}

fn bench_maxflow(c: &mut Criterion) {
    for (h, w) in [(240, 320), (480, 640)] {
        for conn in [4u8, 8] {
            let g = segmentation_graph(h, w, conn);
            eprintln!(
                "{w}x{h} {conn}-connected: {:.1} bytes/node",
                g.memory_bytes() as f64 / (h * w) as f64
            );
            // All of the pool's threads (row bands solved in parallel, then joined),
            // then one thread.
            for (threads, suffix) in [(0, ""), (1, "_1thread")] {
                let mut g = g.clone();
                g.set_max_threads(threads);
                c.bench_function(&format!("maxflow_grid{conn}_{w}x{h}{suffix}"), |b| {
                    b.iter_batched(
                        || g.clone(),
                        |mut g| black_box(g.maxflow()),
                        BatchSize::LargeInput,
                    )
                });
            }
        }
    }
    c.bench_function("build_grid4_640x480", |b| {
        let edges = grid_edges(480, 640, 4).unwrap();
        let src: Vec<u32> = edges.iter().map(|e| e[0]).collect();
        let dst: Vec<u32> = edges.iter().map(|e| e[1]).collect();
        let wts = vec![1.0; edges.len()];
        b.iter(|| {
            let mut g = Graph::<f64>::with_capacity(480 * 640, edges.len());
            g.add_edges(&src, &dst, &wts, &wts).unwrap();
            g.finalize();
            black_box(g.n_edges())
        })
    });
}

/// A body-part-like labelling problem on an h×w grid: `l` part centres spread over the
/// image, unary = squared distance to the part centre (normalised) plus an intensity
/// term, Potts weights from image contrast.
fn parts_problem(h: usize, w: usize, l: usize) -> (Vec<f64>, Vec<[u32; 2]>, Vec<f64>) {
    let img = image(h, w);
    let edges = grid_edges(h, w, 4).unwrap();
    let wts = contrast_weights(&img, &edges);
    let cols = (l as f64).sqrt().ceil() as usize;
    let rows = l.div_ceil(cols);
    let centres: Vec<(f64, f64)> = (0..l)
        .map(|k| {
            let (r, c) = (k / cols, k % cols);
            (
                (r as f64 + 0.5) * h as f64 / rows as f64,
                (c as f64 + 0.5) * w as f64 / cols as f64,
            )
        })
        .collect();
    let scale = (h * h + w * w) as f64 / (l as f64 * 4.0);
    let mut unary = Vec::with_capacity(h * w * l);
    for (k, &value) in img.iter().enumerate().take(h * w) {
        let (r, c) = ((k / w) as f64, (k % w) as f64);
        for (p, &(cr, cc)) in centres.iter().enumerate() {
            let d2 = ((r - cr).powi(2) + (c - cc).powi(2)) / scale;
            let tone = (value - p as f64 / l as f64).abs();
            unary.push(d2 + tone);
        }
    }
    (unary, edges, wts)
}

fn bench_expansion(c: &mut Criterion) {
    for (name, h, w, l) in [
        ("expansion_14labels_320x240", 240, 320, 14),
        ("expansion_15labels_100x100", 100, 100, 15),
    ] {
        let (unary, edges, wts) = parts_problem(h, w, l);
        let problem = CrfProblem {
            unary: &unary,
            n_labels: l,
            edges: &edges,
            weights: &wts,
            pairwise: None,
        };
        let mut solver = CrfSolver::new(h * w, &edges).unwrap();
        let cfg = MoveConfig::default();
        let r = solver.alpha_expansion(&problem, None, &cfg).unwrap();
        eprintln!(
            "{name}: energy {:.3} -> {:.3}, {} cycles, {} moves",
            r.trace[0], r.energy, r.cycles, r.moves_tried
        );
        c.bench_function(name, |b| {
            b.iter(|| black_box(solver.alpha_expansion(&problem, None, &cfg).unwrap().energy))
        });
        // EM-like warm start: the previous E-step's labels, unaries moved a little.
        let shifted: Vec<f64> = unary
            .iter()
            .enumerate()
            .map(|(k, &u)| u * (1.0 + 0.05 * ((k % 7) as f64 / 7.0 - 0.5)))
            .collect();
        let warm = CrfProblem {
            unary: &shifted,
            ..problem
        };
        c.bench_function(&format!("{name}_warm"), |b| {
            b.iter(|| {
                black_box(
                    solver
                        .alpha_expansion(&warm, Some(&r.labels), &cfg)
                        .unwrap()
                        .energy,
                )
            })
        });
    }
}

criterion_group!(benches, bench_maxflow, bench_expansion);
criterion_main!(benches);
