//! Growing Correspondence Seeds on the Middlebury "cones" pair (450×375, disparities
//! 0–64), read from the shared data folder; skipped with a message when it is absent.

use criterion::{criterion_group, criterion_main, Criterion};
use depthpose::io::read_gray;
use depthpose::stereo::{match_stereo, StereoConfig};
use std::hint::black_box;
use std::path::Path;

/// Where the shared pair lives, relative to the crate root (a worktree of /work).
const CONES_DIR: &str = "../shared/data/stereo/cones";

/// The disparity range used for cones in the Middlebury evaluation.
const CONES_MAX_DISPARITY: usize = 64;

fn bench_stereo(c: &mut Criterion) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join(CONES_DIR);
    let (Ok(left), Ok(right)) = (
        read_gray(&dir.join("cones_left.tif")),
        read_gray(&dir.join("cones_right.tif")),
    ) else {
        eprintln!(
            "stereo bench skipped: cones pair not found in {}",
            dir.display()
        );
        return;
    };
    let config = StereoConfig {
        max_disparity: Some(CONES_MAX_DISPARITY),
        ..Default::default()
    };
    c.bench_function("gcs_cones_450x375_d64", |b| {
        b.iter(|| {
            let res = match_stereo(&left.data, &right.data, left.height, left.width, &config)
                .expect("cones match");
            black_box(res.matched())
        })
    });
}

criterion_group!(benches, bench_stereo);
criterion_main!(benches);
