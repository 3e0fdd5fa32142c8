//! Developer tool: per-frame APE errors after a run on the synthetic curved scene.
//! `cargo run --release -p pssba-core --example diagnose -- FRAMES POINTS SEED [max_scales]`

use nalgebra::Isometry3;
use pssba_core::{PssBaConfig, adjust};
use pssba_sim::{SceneSpec, curved_window, perturb_poses};

fn errors(gt: &[Isometry3<f64>], est: &[Isometry3<f64>]) -> (f64, Vec<f64>) {
    let ape = pssba_eval::ape_translation_paired(gt, est).expect("ape");
    (ape.rmse_m, ape.errors_m)
}

fn main() {
    let arg = |i: usize, d: usize| {
        std::env::args()
            .nth(i)
            .and_then(|s| s.parse().ok())
            .unwrap_or(d)
    };
    let spec = SceneSpec {
        frames: arg(1, 40),
        points_per_frame: arg(2, 8000),
        seed: arg(3, 2) as u64,
        ..SceneSpec::default()
    };
    let window = curved_window(&spec);
    let initial = perturb_poses(&window.ground_truth, 0.2, 1.0, spec.seed + 100);
    let config = PssBaConfig {
        max_scales: arg(4, 10),
        ..PssBaConfig::default()
    };
    let result = adjust(&window.frames, &initial, &config).expect("adjust");
    let (rmse0, e0) = errors(&window.ground_truth, &initial);
    let (rmse1, e1) = errors(&window.ground_truth, &result.world_from_lidar);
    println!("APE {rmse0:.4} -> {rmse1:.4}");
    for (k, (a, b)) in e0.iter().zip(&e1).enumerate() {
        println!(
            "frame {k:3} points {:5} error {a:.3} -> {b:.3}",
            window.frames[k].len()
        );
    }
}
