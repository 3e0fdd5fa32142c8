//! `pssba run` (the launcher) and `pssba stage ...` (the four stage processes it starts).

use crate::cli::{RunArgs, StageCommand};
use anyhow::{Context, bail};
use pssba_config::Config;
use pssba_recording::Recording;
use pssba_system::Stage;
use pssba_system::launcher;
use pssba_system::source::{InputSpec, SimSpec, SourceSpec};
use std::time::{Duration, Instant};

/// Runs the launcher.
pub fn run(args: &RunArgs, verbose: u8) -> anyhow::Result<()> {
    let mut config = Config::load(args.config.as_deref())?;
    let live = args.input.as_ref().is_some_and(|p| p.as_os_str() == "live");
    if live && let Some(text) = &args.recording.frames {
        config.system.live_max_frames = match text.trim().parse::<u64>() {
            Ok(n) if n > 0 => n,
            _ => bail!("--frames '{text}': with --input live, the number of frames to take (>= 1)"),
        };
    }
    if flight_files(&args.out).contains(&args.out) {
        bail!(
            "--out {}: the trajectory and map are written beside the recording as .tum, .ply \
             and .pcd; name the recording .mcap",
            args.out.display()
        );
    }
    if let Some(rate) = args.rate.filter(|r| !(r.is_finite() && *r > 0.0)) {
        bail!("--rate {rate}: must be a positive number of frames per second");
    }
    let source = match (&args.dataset, &args.input) {
        (_, Some(path)) if path.as_os_str() == "live" => {
            SourceSpec::Live(args.instance.clone().unwrap_or_default())
        }
        (Some(path), None) | (None, Some(path)) => SourceSpec::Input(InputSpec::Path {
            path: path.clone(),
            options: args.recording.open_options(&config.recording)?,
        }),
        (Some(_), Some(_)) => bail!("--dataset and --input name the same thing: give one"),
        (None, None) => SourceSpec::Input(InputSpec::Simulated(SimSpec {
            frames: args.sim_frames,
            points_per_frame: args.sim_points,
            seed: args.sim_seed,
        })),
    };
    // Fail here, naming the folder or value, rather than in a stage.
    source.check()?;
    eprintln!(
        "pssba run: {}; windows of {} frames, stride {}",
        source.describe(),
        config.windows.window_frames,
        config.windows.window_stride
    );
    let allow_failed_windows = config.system.allow_failed_windows;
    let map_voxel_m = config.output.map_voxel_m;
    let options = launcher::LaunchOptions {
        exe: std::env::current_exe().context("locating the pssba executable")?,
        config,
        source,
        out: args.out.clone(),
        rate_hz: args.rate,
        verbose,
        timeout: args.timeout.map(Duration::from_secs_f64),
    };
    let started = Instant::now();
    let launched = launcher::launch(&options);
    summarize_parts(&args.out);
    let config_path = launched?;
    let wall_s = started.elapsed().as_secs_f64();
    let recording = pssba_recording::read_recording_parts(&args.out)?;
    let parts = pssba_recording::existing_parts(&args.out);
    if parts.len() > 1 {
        eprintln!(
            "the record stage was restarted: the recording is in {} parts ({} ... {})",
            parts.len(),
            args.out.display(),
            parts
                .last()
                .map_or(String::new(), |p| p.display().to_string())
        );
    }
    let frames = recording.optimized.len();
    eprintln!(
        "wrote {} ({frames} final poses; config {}) in {wall_s:.1} s: {:.1} frames/s",
        args.out.display(),
        config_path.display(),
        frames as f64 / wall_s
    );
    let flight = flight_files(&args.out);
    if frames > 0 {
        let [tum, ply, pcd] = flight.clone();
        crate::export::write_flight(&args.out, Some(&tum), &[ply, pcd], map_voxel_m)?;
        eprintln!(
            "wrote the final trajectory and map beside it: {}",
            flight
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    if let Some(dropped) = recording.frames_dropped.filter(|&n| n > 0) {
        eprintln!(
            "{dropped} frames were dropped by the smooth stage (live_overflow = drop): they are \
             recorded without final poses"
        );
    }
    let (before, after) = match ape_summary(&recording, frames) {
        Ok((before, after)) => {
            eprintln!(
                "APE (translation RMSE after SE(3) alignment): initial {:.4} m -> optimised {:.4} m",
                before.rmse_m, after.rmse_m
            );
            (Some(before), Some(after))
        }
        Err(why) => {
            eprintln!("{why}");
            (None, None)
        }
    };
    let failed = failed_windows(&recording);
    if args.json {
        let summary = serde_json::json!({
            "windows": recording.windows.len(),
            "failed_windows": failed.len(),
            "out": args.out,
            "frames": frames,
            "frames_dropped": recording.frames_dropped,
            "wall_time_s": wall_s,
            "frames_per_s": frames as f64 / wall_s,
            "ape_initial_m": before.as_ref().map(|a| a.rmse_m),
            "ape_optimized_m": after.as_ref().map(|a| a.rmse_m),
            "messages": recording.counts,
            "trajectory": (frames > 0).then(|| &flight[0]),
            "map": (frames > 0).then(|| [&flight[1], &flight[2]]),
        });
        println!("{summary}");
    }
    report_failed_windows(&failed, recording.windows.len(), allow_failed_windows)
}

/// Gives every part the run left without a summary section (one the recorder ended after a
/// crash, or one torn by a recorder that was not restarted) a full one. Best effort, after
/// every stage has stopped: a part that cannot be rewritten (a full disk) stays readable by
/// scanning, and a warning says so.
fn summarize_parts(out: &std::path::Path) {
    match pssba_recording::add_summaries(out) {
        Ok(rewritten) => {
            for (part, done) in rewritten {
                if let pssba_recording::Summarized::Rewritten { messages, torn } = done {
                    eprintln!(
                        "{}: had no summary section; rewritten with one ({messages} messages{})",
                        part.display(),
                        if torn { ", its torn end left out" } else { "" }
                    );
                }
            }
        }
        Err(error) => tracing::warn!(
            "could not add a summary section to the recording's parts ({:#}); they stay \
             readable by scanning",
            anyhow::Error::from(error)
        ),
    }
}

/// The files beside the recording RUN.mcap: RUN.tum (the final trajectory), RUN.ply and
/// RUN.pcd (the map).
fn flight_files(out: &std::path::Path) -> [std::path::PathBuf; 3] {
    ["tum", "ply", "pcd"].map(|extension| out.with_extension(extension))
}

/// APE before and after, or why it was not computed (said once, and true: no ground truth, a
/// partial one, or an alignment the trajectory cannot support, e.g. a straight line).
fn ape_summary(
    recording: &Recording,
    frames: usize,
) -> Result<(pssba_eval::ApeResult, pssba_eval::ApeResult), String> {
    let gt = &recording.ground_truth;
    if gt.is_empty() {
        return Err("no ground truth in the input: APE not computed".into());
    }
    if gt.len() != frames {
        return Err(format!(
            "ground truth for {} of {frames} frames: APE not computed",
            gt.len()
        ));
    }
    let ape = |poses: &[nalgebra::Isometry3<f64>]| {
        pssba_eval::ape_translation_paired(gt, poses)
            .map_err(|e| format!("warning: APE vs the ground truth not computed: {e}"))
    };
    Ok((ape(&recording.initial)?, ape(&recording.optimized)?))
}

/// The failure rule of sliding windows, for `pssba run` and `pssba adjust --window-frames`:
/// with failed windows (one line each in `failed`), an error unless `allow` (then a warning).
pub fn report_failed_windows(failed: &[String], windows: usize, allow: bool) -> anyhow::Result<()> {
    if failed.is_empty() {
        return Ok(());
    }
    let message = format!(
        "{} of {windows} windows failed: {}",
        failed.len(),
        failed.join("; ")
    );
    if !allow {
        bail!("{message} (set system.allow_failed_windows = true to accept this)");
    }
    eprintln!("warning: {message} (accepted: system.allow_failed_windows = true)");
    Ok(())
}

/// One line per failed window: its number, the frames that kept their initial poses, why.
fn failed_windows(recording: &Recording) -> Vec<String> {
    recording
        .windows
        .iter()
        .filter_map(|w| {
            let error = w.error.as_ref()?;
            let frames = match (w.final_frames.first(), w.final_frames.last()) {
                (Some(first), Some(last)) => format!("frames {first}..={last}"),
                _ => "no frames".to_string(),
            };
            Some(format!(
                "window {} ({frames} kept their initial poses): {error}",
                w.window
            ))
        })
        .collect()
}

/// Runs one stage; its log lines carry the stage name.
pub fn stage(command: StageCommand) -> anyhow::Result<()> {
    let (stage, args) = command.into_args();
    // Span names are static: one per stage, so log lines read `ingest: ...`.
    let span = match stage {
        Stage::Ingest => tracing::info_span!("ingest"),
        Stage::Smooth => tracing::info_span!("smooth"),
        Stage::Adjust => tracing::info_span!("adjust"),
        Stage::Record => tracing::info_span!("record"),
    };
    let outcome = span.in_scope(|| pssba_system::stages::run_stage(stage, args));
    if let Some(peak_mib) = peak_memory_mib() {
        let (user_s, system_s) = cpu_times_s().unwrap_or((f64::NAN, f64::NAN));
        tracing::info!(
            "stage {stage}: peak memory {peak_mib:.0} MiB, cpu {user_s:.2} s user + {system_s:.2} s system"
        );
    }
    outcome.with_context(|| format!("stage {stage}"))
}

/// This process's user and system CPU time (s), from /proc/self/stat (at 100 ticks a second,
/// Linux's USER_HZ).
fn cpu_times_s() -> Option<(f64, f64)> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let after = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = after.split_whitespace().collect();
    let ticks = |i: usize| fields.get(i)?.parse::<f64>().ok();
    Some((ticks(11)? / 100.0, ticks(12)? / 100.0))
}

/// This process's peak resident memory (VmHWM of /proc/self/status), where Linux tells it.
fn peak_memory_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}
