//! Developer tool: APE after each number of scales on the synthetic curved scene.
//! `cargo run --release -p pssba-core --example diagnose -- [method] [max_scales] [seed]`

use nalgebra::Isometry3;
use pssba_core::{Method, PssBaConfig, adjust};
use pssba_sim::{SceneSpec, curved_window, perturb_poses};

fn ape_m(gt: &[Isometry3<f64>], est: &[Isometry3<f64>]) -> f64 {
    let stamp = |poses: &[Isometry3<f64>]| {
        poses
            .iter()
            .enumerate()
            .map(|(k, p)| (k as f64 * 0.1, *p))
            .collect::<Vec<_>>()
    };
    pssba_eval::ape_translation(&stamp(gt), &stamp(est), 0.01)
        .map(|a| a.rmse_m)
        .unwrap_or(f64::NAN)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let method = match args.get(1).map(String::as_str) {
        Some("point2plane") => Method::Point2plane,
        Some("pss-ba-fs") => Method::PssBaFs,
        _ => Method::PssBa,
    };
    let max_scales: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(12);
    let seed: u64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(1);
    let spec = SceneSpec {
        frames: 20,
        points_per_frame: 6000,
        seed,
        ..SceneSpec::default()
    };
    let window = curved_window(&spec);
    let noise: f64 = std::env::var("NOISE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1.0);
    let initial = perturb_poses(&window.ground_truth, 0.2 * noise, 1.0 * noise, seed + 100);
    println!("initial APE {:.4}", ape_m(&window.ground_truth, &initial));
    for scales in 1..=max_scales {
        let config = PssBaConfig {
            method,
            max_scales: scales,
            ..PssBaConfig::default()
        };
        let result = adjust(&window.frames, &initial, &config).expect("adjust");
        let last = result.scales.last().expect("a scale");
        println!(
            "scales {scales} gamma {:.3} change {:.4} APE {:.4}",
            last.gamma_m,
            last.pose_change,
            ape_m(&window.ground_truth, &result.world_from_lidar)
        );
        if result.converged {
            break;
        }
    }
}
