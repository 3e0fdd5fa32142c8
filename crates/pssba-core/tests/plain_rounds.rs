//! The plain rounds that end the schedule (`PssBaConfig::final_plain_rounds`), on the
//! synthetic curved scene (2 cm range noise).

use nalgebra::Isometry3;
use pssba_core::{Method, PssBaConfig, adjust};
use pssba_sim::{SceneSpec, curved_window, perturb_poses};

fn scene(frames: usize, seed: u64) -> pssba_sim::SimulatedWindow {
    curved_window(&SceneSpec {
        frames,
        points_per_frame: 4000,
        seed,
        ..SceneSpec::default()
    })
}

fn ape_m(gt: &[Isometry3<f64>], est: &[Isometry3<f64>]) -> f64 {
    pssba_eval::ape_translation_paired(gt, est)
        .expect("ape")
        .rmse_m
}

/// Started at the true poses, one round at the finest width with plain consensus surfaces
/// stays nearer to them than one with anchored surfaces: the anchor offset carries the noise
/// of a few points of one frame into every residual of its surface.
#[test]
fn plain_surfaces_are_less_noisy_than_anchored_ones_at_the_truth() {
    let window = scene(20, 4);
    let one_round = |anchored: bool| {
        let config = PssBaConfig {
            method: Method::PssBaFs,
            fixed_gamma_m: 0.4,
            max_scales: 1,
            final_plain_rounds: 0,
            anchor_offset_to_kernel_frame: anchored,
            ..PssBaConfig::default()
        };
        let result = adjust(&window.frames, &window.ground_truth, &config).expect("adjust");
        ape_m(&window.ground_truth, &result.world_from_lidar)
    };
    let (anchored, plain) = (one_round(true), one_round(false));
    eprintln!("APE after one round from the truth: anchored {anchored:.5} m, plain {plain:.5} m");
    assert!(
        plain < anchored,
        "plain {plain} against anchored {anchored}"
    );
}

/// `final_plain_rounds` adds that many scales at the finest width after the anchored schedule
/// converged, and they lower the error on this scene.
#[test]
fn plain_rounds_follow_the_converged_schedule() {
    let window = scene(20, 1);
    let initial = perturb_poses(&window.ground_truth, 0.2, 1.0, 101);
    let run = |rounds: usize| {
        let config = PssBaConfig {
            final_plain_rounds: rounds,
            ..PssBaConfig::default()
        };
        adjust(&window.frames, &initial, &config).expect("adjust")
    };
    let (without, with) = (run(0), run(2));
    assert!(without.converged && with.converged);
    assert_eq!(with.scales.len(), without.scales.len() + 2);
    assert_eq!((without.plain_rounds, with.plain_rounds), (0, 2));
    let gamma_min_m = PssBaConfig::default().gamma_min_m;
    assert!(
        with.scales[with.scales.len() - 2..]
            .iter()
            .all(|s| s.gamma_m == gamma_min_m)
    );
    let (a, b) = (
        ape_m(&window.ground_truth, &without.world_from_lidar),
        ape_m(&window.ground_truth, &with.world_from_lidar),
    );
    eprintln!("APE without plain rounds {a:.5} m, with two {b:.5} m");
    assert!(b < a, "with {b} against without {a}");
}
