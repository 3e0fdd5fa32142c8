//! The linear algebra of one LM iteration on a long window (issue 12, target 4): the normal
//! equations of a factor block (serial and rayon) and one conjugate-gradient solve.
//!
//! The block is synthetic but shaped like the finest scale of a 1000-frame orbit
//! (`pssba simulate --scene hangar --frames 1000`): 1000 frames, surfaces on every frame,
//! each with residual points from frames near it and from frames half an orbit away, so
//! about a third of the frame pairs are coupled. `PSSBA_BENCH_FRAMES` and
//! `PSSBA_BENCH_SURFACES_PER_FRAME` resize it (defaults 1000 and 280).

mod common;

use common::env_or;
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Matrix3, Rotation3, Vector3};
use pssba_core::fit::Polynomial;
use pssba_core::geometry::Pose;
use pssba_core::lm::{
    BlockHessian, accumulate, cg_solve, into_ordered_by_frame_pair, variable_layout,
};
use pssba_core::{FactorBlock, FactorPoint, Parallelism, Surface};
use rand::{Rng, SeedableRng, rngs::StdRng};
use std::time::Duration;

/// Residual points per surface (the default `residuals_per_kernel`).
const POINTS_PER_SURFACE: usize = 64;
/// Frames either side of a surface's frame, and half an orbit away, that its points come from.
const NEAR_FRAMES: usize = 90;

fn synthetic_block(frames: usize, surfaces_per_frame: usize) -> (FactorBlock, Vec<Pose>) {
    let mut rng = StdRng::seed_from_u64(12);
    let poses: Vec<Pose> = (0..frames)
        .map(|k| {
            let angle = k as f64 / frames as f64 * std::f64::consts::TAU;
            Pose {
                rotation: *Rotation3::from_euler_angles(0.01, -0.02, angle).matrix(),
                translation: Vector3::new(30.0 * angle.cos(), 30.0 * angle.sin(), 5.0),
            }
        })
        .collect();
    let mut block = FactorBlock {
        gamma_m: 0.4,
        robust_scale_m: 0.05,
        ..FactorBlock::default()
    };
    for frame in 0..frames {
        for _ in 0..surfaces_per_frame {
            let surface = block.surfaces.len() as u32;
            let tangent: Matrix3<f64> = *Rotation3::from_euler_angles(
                rng.random_range(-3.0..3.0),
                rng.random_range(-3.0..3.0),
                rng.random_range(-3.0..3.0),
            )
            .matrix();
            block.surfaces.push(Surface {
                frame,
                kernel_in_lidar: Vector3::new(
                    rng.random_range(-20.0..20.0),
                    rng.random_range(-20.0..20.0),
                    rng.random_range(-3.0..3.0),
                ),
                tangent_from_lidar: tangent * poses[frame].rotation,
                polynomial: Polynomial {
                    coefficients: [0.3, -0.2, 0.1, 0.02, -0.01, 0.005],
                },
                gamma_m: 0.4,
            });
            let half_orbit = if rng.random_bool(0.5) { frames / 2 } else { 0 };
            for _ in 0..POINTS_PER_SURFACE {
                let offset = rng.random_range(1..=NEAR_FRAMES) + half_orbit;
                let other = if rng.random_bool(0.5) {
                    (frame + offset) % frames
                } else {
                    (frame + frames - offset % frames) % frames
                };
                let point_in_lidar = Vector3::new(
                    rng.random_range(-20.0..20.0),
                    rng.random_range(-20.0..20.0),
                    rng.random_range(-3.0..3.0),
                );
                let weight = rng.random_range(0.3..1.0);
                block.points.push(FactorPoint::new(
                    surface,
                    other as u32,
                    point_in_lidar,
                    weight,
                ));
            }
        }
    }
    (into_ordered_by_frame_pair(block, frames), poses)
}

/// LM's damping of H's diagonal, about as it is late in a scale.
const DAMP: fn(f64) -> f64 = |h| 1.001 * h + 1e-6;

fn long_window_iteration(c: &mut Criterion) {
    let frames = env_or("PSSBA_BENCH_FRAMES", 1000);
    let surfaces_per_frame = env_or("PSSBA_BENCH_SURFACES_PER_FRAME", 280);
    let (block, poses) = synthetic_block(frames, surfaces_per_frame);
    let fixed: Vec<bool> = (0..frames).map(|k| k == 0).collect();
    let (variable_of, dim) = variable_layout(&fixed);
    let normal_equations =
        |parallelism| accumulate(&block, &poses, &variable_of, dim, None, parallelism);
    let eq = normal_equations(Parallelism::Serial);
    let hessian: &BlockHessian = &eq.hessian;
    let pairs = hessian.stored_blocks() - hessian.frames();
    eprintln!(
        "{frames} frames, {} residuals, {pairs} coupled pairs ({:.0} % of all)",
        block.points.len(),
        100.0 * pairs as f64 / (hessian.frames() * (hessian.frames() - 1) / 2) as f64
    );
    let (_, report) = cg_solve::solve(hessian, &eq.gradient, DAMP, cg_solve::LM_RELATIVE_TOLERANCE)
        .expect("positive definite");
    eprintln!("conjugate gradients: {report:?}");
    let mut group = c.benchmark_group("long window");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(20))
        .warm_up_time(Duration::from_secs(1));
    for (name, parallelism) in [
        ("serial", Parallelism::Serial),
        ("rayon", Parallelism::Rayon),
    ] {
        group.bench_function(format!("normal equations {frames} frames, {name}"), |b| {
            b.iter(|| normal_equations(parallelism))
        });
    }
    // One thread: the product by H is bound by memory traffic (measured: two threads over
    // fixed parts of the blocks were slower than one).
    group.bench_function(format!("conjugate gradients {frames} frames"), |b| {
        b.iter(|| {
            cg_solve::solve(hessian, &eq.gradient, DAMP, cg_solve::LM_RELATIVE_TOLERANCE)
                .expect("positive definite")
        })
    });
    group.finish();
}

criterion_group!(benches, long_window_iteration);
criterion_main!(benches);
