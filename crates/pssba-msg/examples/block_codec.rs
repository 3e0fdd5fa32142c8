//! Bytes and encode/decode times of the factor blocks of one full-size window: the built-in
//! hangar scene, 100 frames x 20,000 rays (seed 3), every scale of the default schedule, each
//! scale solved in process. Prints one line per scale and the totals.
//!
//! `cargo run --release -p pssba-msg --example block_codec`

use pssba_core::lm::solve_block;
use pssba_core::{Parallelism, ProgressiveRun, PssBaConfig, Window};
use pssba_msg::{decode_block, encode_block};
use pssba_sim::{BuiltinScene, SimulationSpec, simulate_scene};
use std::time::Instant;

fn main() -> anyhow::Result<()> {
    let scene = BuiltinScene::Hangar.build();
    let data = simulate_scene(
        &scene,
        &SimulationSpec {
            frames: 100,
            seed: 3,
            ..SimulationSpec::default()
        },
    )?;
    let points: usize = data.frames.iter().map(Vec::len).sum();
    println!("hangar, 100 frames, {points} points");
    let config = PssBaConfig::default();
    let mut run = ProgressiveRun::new(
        Window {
            frames: &data.frames,
            world_from_lidar: &data.initial,
            fixed: None,
            times: None,
        },
        &config,
    )?;
    let (mut bytes, mut encode_s, mut decode_s) = (0usize, 0.0, 0.0);
    println!("scale  surfaces  points  words  MiB  encode_ms  decode_ms");
    while let Some(step) = run.next_step(Parallelism::Rayon)? {
        let started = Instant::now();
        let (header, words) = encode_block(
            0,
            step.index as u32,
            &step.block,
            run.poses(),
            run.fixed(),
            &step.settings,
        );
        let encoded = started.elapsed().as_secs_f64();
        let started = Instant::now();
        let decoded = decode_block(&header, &words)?;
        let decoded_s = started.elapsed().as_secs_f64();
        assert_eq!(decoded.block.points.len(), step.block.points.len());
        println!(
            "{:>5}  {:>8}  {:>6}  {:>5}  {:.2}  {:>9.2}  {:>9.2}",
            step.index,
            step.block.surfaces.len(),
            step.block.points.len(),
            words.len(),
            words.len() as f64 * 8.0 / (1 << 20) as f64,
            encoded * 1e3,
            decoded_s * 1e3
        );
        bytes += words.len() * 8;
        encode_s += encoded;
        decode_s += decoded_s;
        let (adjusted, lm) = solve_block(
            &step.block,
            run.poses(),
            run.fixed(),
            &step.settings,
            Parallelism::Rayon,
        );
        run.complete_step(step, adjusted, &lm)?;
    }
    println!(
        "total: {:.1} MiB, encode {:.1} ms, decode {:.1} ms",
        bytes as f64 / (1 << 20) as f64,
        encode_s * 1e3,
        decode_s * 1e3
    );
    Ok(())
}
