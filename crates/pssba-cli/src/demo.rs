//! `pssba demo`: the built-in simulated curved scene through the whole in-process pipeline
//! (simulate, perturb 0.2 m / 1 deg RMS, adjust), APE before and after.

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
    let method: Method = args.method.into();
    let config = PssBaConfig {
        method,
        ..crate::settings::load_config(args.config.as_deref())?
    };
    let started = Instant::now();
    let result = pssba_core::adjust(&window.frames, &initial, &config)?;
    let wall_time_s = started.elapsed().as_secs_f64();
    print_scales(&result);
    let ape = ApeSummary {
        initial_m: ape_m(&stamped(&window.ground_truth), &stamped(&initial))?,
        optimized_m: ape_m(
            &stamped(&window.ground_truth),
            &stamped(&result.world_from_lidar),
        )?,
    };
    eprintln!(
        "{}: APE initial {:.4} m -> optimized {:.4} m in {:.2} s{}",
        method.name(),
        ape.initial_m,
        ape.optimized_m,
        wall_time_s,
        peak_rss_kb().map_or(String::new(), |kb| format!(
            ", peak memory {:.0} MB",
            kb as f64 / 1024.0
        ))
    );
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&RunSummary::new(
                method,
                &result,
                Some(ape),
                wall_time_s,
                outputs
            ))?
        );
    }
    Ok(())
}
