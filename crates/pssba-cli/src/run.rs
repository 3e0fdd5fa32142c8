//! `pssba run` (the launcher) and `pssba stage ...` (the four stage processes it starts).

use crate::cli::{RunArgs, StageCommand};
use anyhow::{Context, bail};
use pssba_system::ingest::{IngestOptions, SimSpec, Source};
use pssba_system::{RunConfig, launcher, mcap_read};
use std::time::{Duration, Instant};

/// Windows of the built-in scene when no config is given, so that its 100 frames span
/// several windows (4: frames 0-40, 30-70, 60-100 with stride 30... see `sliding`).
const BUILTIN_WINDOW: (usize, usize) = (40, 30);

/// Runs the launcher.
pub fn run(args: &RunArgs, verbose: u8) -> anyhow::Result<()> {
    let mut config = RunConfig::load(args.config.as_deref())?;
    if args.config.is_none() && args.dataset.is_none() {
        config.system.window_frames = BUILTIN_WINDOW.0;
        config.system.window_stride = BUILTIN_WINDOW.1;
    }
    if args.dataset.is_none() && (args.sim_frames < 2 || args.sim_points == 0) {
        bail!(
            "--sim-frames must be at least 2 and --sim-points at least 1 (got {} and {})",
            args.sim_frames,
            args.sim_points
        );
    }
    if let Some(rate) = args.rate.filter(|r| !(r.is_finite() && *r > 0.0)) {
        bail!("--rate {rate}: must be a positive number of frames per second");
    }
    if let Some(dir) = &args.dataset {
        // Fail here, naming the folder, rather than in a stage.
        pssba_io::Dataset::open(dir)?;
    }
    let options = launcher::LaunchOptions {
        exe: std::env::current_exe().context("locating the pssba executable")?,
        config,
        dataset: args.dataset.clone(),
        sim: SimSpec {
            frames: args.sim_frames,
            points_per_frame: args.sim_points,
            seed: args.sim_seed,
        },
        out: args.out.clone(),
        rate_hz: args.rate,
        verbose,
        timeout: args.timeout.map(Duration::from_secs_f64),
    };
    let source = match &args.dataset {
        Some(dir) => dir.display().to_string(),
        None => format!(
            "built-in curved scene, {} frames x {} points, seed {}",
            args.sim_frames, args.sim_points, args.sim_seed
        ),
    };
    eprintln!(
        "pssba run: {source}; windows of {} frames, stride {}",
        options.config.system.window_frames, options.config.system.window_stride
    );
    let started = Instant::now();
    let config_path = launcher::launch(&options)?;
    let wall_s = started.elapsed().as_secs_f64();
    let recording = mcap_read::read_recording(&args.out)?;
    let frames = recording.optimized.len();
    eprintln!(
        "wrote {} ({frames} final poses; config {}) in {wall_s:.1} s: {:.1} frames/s",
        args.out.display(),
        config_path.display(),
        frames as f64 / wall_s
    );
    let ape = |poses: &[nalgebra::Isometry3<f64>]| {
        pssba_eval::ape_translation_paired(&recording.ground_truth, poses).ok()
    };
    let (before, after) = if recording.ground_truth.len() == frames && frames >= 3 {
        (ape(&recording.initial), ape(&recording.optimized))
    } else {
        (None, None)
    };
    match (&before, &after) {
        (Some(before), Some(after)) => eprintln!(
            "APE (translation RMSE after SE(3) alignment): initial {:.4} m -> optimised {:.4} m",
            before.rmse_m, after.rmse_m
        ),
        _ => eprintln!("no ground truth in the stream: APE not computed"),
    }
    if args.json {
        let summary = serde_json::json!({
            "out": args.out,
            "frames": frames,
            "wall_time_s": wall_s,
            "frames_per_s": frames as f64 / wall_s,
            "ape_initial_m": before.as_ref().map(|a| a.rmse_m),
            "ape_optimized_m": after.as_ref().map(|a| a.rmse_m),
            "messages": recording.counts,
        });
        println!("{summary}");
    }
    Ok(())
}

/// Runs one stage; its log lines carry the stage name.
pub fn stage(command: StageCommand) -> anyhow::Result<()> {
    let (name, outcome) = match command {
        StageCommand::Ingest {
            common,
            dataset,
            sim_frames,
            sim_points,
            sim_seed,
            rate,
        } => {
            let config = RunConfig::load(common.config.as_deref())?;
            let options = IngestOptions {
                prefix: common.prefix,
                source: match dataset {
                    Some(dir) => Source::Dataset(dir),
                    None => Source::Simulated(SimSpec {
                        frames: sim_frames,
                        points_per_frame: sim_points,
                        seed: sim_seed,
                    }),
                },
                rate_hz: rate,
                backpressure_timeout: Duration::from_secs_f64(config.system.backpressure_timeout_s),
                max_frame_points: config.system.max_frame_points,
            };
            let span = tracing::info_span!("ingest");
            (
                "ingest",
                span.in_scope(|| pssba_system::ingest::run(&options)),
            )
        }
        StageCommand::Smooth { common } => {
            let options = pssba_system::smooth::SmoothOptions {
                prefix: common.prefix,
                config: RunConfig::load(common.config.as_deref())?,
            };
            let span = tracing::info_span!("smooth");
            (
                "smooth",
                span.in_scope(|| pssba_system::smooth::run(&options)),
            )
        }
        StageCommand::Adjust { common } => {
            let config = RunConfig::load(common.config.as_deref())?;
            let options = pssba_system::adjust::AdjustOptions {
                prefix: common.prefix,
                backpressure_timeout: Duration::from_secs_f64(config.system.backpressure_timeout_s),
                max_window_frames: config.system.window_frames,
            };
            let span = tracing::info_span!("adjust");
            (
                "adjust",
                span.in_scope(|| pssba_system::adjust::run(&options)),
            )
        }
        StageCommand::Record { common, out } => {
            let options = pssba_system::record::RecordOptions {
                prefix: common.prefix,
                out,
            };
            let span = tracing::info_span!("record");
            (
                "record",
                span.in_scope(|| pssba_system::record::run(&options)),
            )
        }
    };
    outcome.with_context(|| format!("stage {name}"))
}
