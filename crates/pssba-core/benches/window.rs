//! Speed target of issue 2: one full progressive run on a window of 100 frames x 20,000
//! points within 5 s wall on 2 cores (peak memory: run `pssba demo --frames 100 --points
//! 20000`, which prints it). `PSSBA_BENCH_FRAMES` / `PSSBA_BENCH_POINTS` shrink it.

mod common;

use common::env_or;
use criterion::{Criterion, criterion_group, criterion_main};
use pssba_core::{PssBaConfig, adjust};
use pssba_sim::{SceneSpec, curved_window, perturb_poses};
use std::time::Duration;

fn full_progressive_run(c: &mut Criterion) {
    let spec = SceneSpec {
        frames: env_or("PSSBA_BENCH_FRAMES", 100),
        points_per_frame: env_or("PSSBA_BENCH_POINTS", 20_000),
        ..SceneSpec::default()
    };
    let window = curved_window(&spec);
    let initial = perturb_poses(&window.ground_truth, 0.2, 1.0, 101);
    let config = PssBaConfig::default();
    let mut group = c.benchmark_group("window");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(60))
        .warm_up_time(Duration::from_secs(1));
    group.bench_function(
        format!("pss-ba {}x{}", spec.frames, spec.points_per_frame),
        |b| b.iter(|| adjust(&window.frames, &initial, &config).expect("adjust")),
    );
    group.finish();
}

criterion_group!(benches, full_progressive_run);
criterion_main!(benches);
