//! `pssba demo`: the built-in simulated curved scene through the whole in-process pipeline
//! (simulate, perturb 0.2 m / 1 deg RMS, adjust with the chosen method, BALM included), APE
//! before and after.

use crate::balm::{BalmSummary, print_outer};
use crate::cli::DemoArgs;
use crate::report::{ApeSummary, RunSummary, ape_m, print_scales};
use anyhow::bail;
use pssba_core::{Method, PssBaConfig};
use pssba_io::{PcdEncoding, StampedPose};
use pssba_sim::{SceneSpec, curved_window, perturb_poses};
use std::time::Instant;

/// Peak resident memory of this process (kB), from /proc (Linux only).
fn peak_rss_kb() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// Runs the subcommand.
pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    if args.frames < 2 || args.points == 0 {
        bail!(
            "--frames must be at least 2 and --points at least 1 (got {} and {})",
            args.frames,
            args.points
        );
    }
    let spec = SceneSpec {
        frames: args.frames,
        points_per_frame: args.points,
        seed: args.seed,
        ..SceneSpec::default()
    };
    eprintln!(
        "simulating the curved scene: {} frames x {} points, 2 cm range noise, seed {}",
        spec.frames, spec.points_per_frame, spec.seed
    );
    let window = curved_window(&spec);
    let initial = perturb_poses(&window.ground_truth, 0.2, 1.0, args.seed.wrapping_add(100));
    let stamped = |poses: &[nalgebra::Isometry3<f64>]| -> Vec<(f64, nalgebra::Isometry3<f64>)> {
        window
            .stamps
            .iter()
            .copied()
            .zip(poses.iter().copied())
            .collect()
    };
    let mut outputs = Vec::new();
    if let Some(dir) = &args.write_dataset {
        let as_tum = |poses: &[nalgebra::Isometry3<f64>]| -> Vec<StampedPose> {
            stamped(poses)
                .into_iter()
                .map(|(stamp, world_from_lidar)| StampedPose {
                    stamp,
                    world_from_lidar,
                })
                .collect()
        };
        pssba_io::Dataset::write(
            dir,
            &window.frames,
            &as_tum(&initial),
            Some(&as_tum(&window.ground_truth)),
            PcdEncoding::Binary,
        )?;
        eprintln!("wrote dataset folder {}", dir.display());
        outputs.push(dir.display().to_string());
    }
    let settings = pssba_config::Config::load(args.config.as_deref())?;
    let started = Instant::now();
    let (name, world_from_lidar, report): (&str, Vec<nalgebra::Isometry3<f64>>, Report) =
        match args.method.core_method() {
            Some(method) => {
                let config = PssBaConfig {
                    method,
                    ..settings.algorithm
                };
                let result = pssba_core::adjust(&window.frames, &initial, &config)?;
                print_scales(&result);
                let poses = result.world_from_lidar.clone();
                (method.name(), poses, Report::Core(method, result))
            }
            None => {
                let result = pssba_balm::adjust(
                    &window.frames,
                    &initial,
                    &settings.balm,
                    pssba_core::Parallelism::Rayon,
                )?;
                print_outer(&result);
                let poses = result.world_from_lidar.clone();
                ("balm", poses, Report::Balm(result))
            }
        };
    let wall_time_s = started.elapsed().as_secs_f64();
    let ape = ApeSummary {
        initial_m: ape_m(&stamped(&window.ground_truth), &stamped(&initial))?,
        optimized_m: ape_m(&stamped(&window.ground_truth), &stamped(&world_from_lidar))?,
    };
    eprintln!(
        "{name}: APE initial {:.4} m -> optimized {:.4} m in {:.2} s{}",
        ape.initial_m,
        ape.optimized_m,
        wall_time_s,
        peak_rss_kb().map_or(String::new(), |kb| format!(
            ", peak memory {:.0} MB",
            kb as f64 / 1024.0
        ))
    );
    if args.json {
        let text = match &report {
            Report::Core(method, result) => serde_json::to_string_pretty(&RunSummary::new(
                *method,
                result,
                Some(ape),
                wall_time_s,
                outputs,
            ))?,
            Report::Balm(result) => serde_json::to_string_pretty(&BalmSummary::new(
                result,
                Some(ape),
                wall_time_s,
                outputs,
            ))?,
        };
        println!("{text}");
    }
    Ok(())
}

/// The result of the method that ran, for the JSON summary.
enum Report {
    Core(Method, pssba_core::AdjustResult),
    Balm(pssba_balm::BalmResult),
}
