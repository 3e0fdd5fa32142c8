//! `pssba adjust DIR|RECORDING`: load a dataset folder or a recording's frames, run the configured method (PSS-BA and its
//! ablations in pssba-core, or the BALM baseline in pssba-balm), write the poses.

use crate::balm::{BalmSummary, merged_cloud, print_outer};
use crate::cli::{AdjustArgs, MethodArg};
use crate::input::{Loaded, load};
use crate::report::{ApeSummary, RunSummary, ape_m, print_scales};
use anyhow::Context;
use nalgebra::{Isometry3, Point3};
use pssba_config::Config;
use pssba_core::Parallelism;
use pssba_io::StampedPose;
use std::borrow::Cow;
use std::time::Instant;

fn as_stamped(poses: &[StampedPose]) -> Vec<(f64, nalgebra::Isometry3<f64>)> {
    poses
        .iter()
        .map(|p| (p.stamp, p.world_from_lidar))
        .collect()
}

/// What one method run returned.
enum Outcome {
    /// PSS-BA or one of its ablations.
    Core(pssba_core::AdjustResult),
    /// The BALM baseline.
    Balm(pssba_balm::BalmResult),
    /// PSS-BA over the whole flight: sliding windows with loop closure (input longer than one
    /// window, or `--window-frames`, `--window-stride`).
    Flight(pssba_core::FlightResult),
}

impl Outcome {
    fn world_from_lidar(&self) -> &[Isometry3<f64>] {
        match self {
            Outcome::Core(r) => &r.world_from_lidar,
            Outcome::Balm(r) => &r.world_from_lidar,
            Outcome::Flight(r) => &r.world_from_lidar,
        }
    }

    fn print_report(&self) {
        match self {
            Outcome::Core(r) => print_scales(r),
            Outcome::Balm(r) => print_outer(r),
            Outcome::Flight(r) => {
                for window in &r.windows {
                    let plan = &window.plan;
                    eprintln!(
                        "window {}: frames {}..{} ({} held fixed)",
                        window.index,
                        plan.first,
                        plan.end,
                        plan.fixed.iter().filter(|&&f| f).count()
                    );
                    match &window.result {
                        Ok(result) => print_scales(result),
                        Err(error) => eprintln!("  failed: {error}"),
                    }
                }
                for c in &r.closures {
                    eprintln!(
                        "window {}: revisit of {} old keyframes (overlap {:.2}): drift {:.3} m, \
                         {} frames moved",
                        c.window,
                        c.old_keyframes.len(),
                        c.overlap,
                        c.mean_correction_m,
                        c.moved.len()
                    );
                }
                if let Some(g) = &r.global_pass {
                    eprintln!(
                        "global pass: {} keyframes, {} loop edges, {} frames moved ({:.2} s)",
                        g.keyframes,
                        g.loop_edges,
                        g.moved.len(),
                        g.seconds
                    );
                }
                eprintln!(
                    "{} loop closures; {} keyframes ({} points) kept",
                    r.closures.len(),
                    r.keyframes.0,
                    r.keyframes.1
                );
            }
        }
    }

    /// The `--map` cloud: PSS-BA's smoothed cloud, or the merged input at BALM's poses.
    fn map_cloud(
        &self,
        frames: &[Vec<Point3<f64>>],
        times: Option<pssba_core::PointTimes<'_>>,
    ) -> anyhow::Result<Cow<'_, [Point3<f64>]>> {
        Ok(match self {
            Outcome::Core(r) => Cow::Borrowed(&r.smoothed_cloud),
            Outcome::Balm(r) => Cow::Owned(merged_cloud(frames, &r.world_from_lidar)),
            // The windows' smoothed clouds are at their poses before any later loop closure:
            // the input at the final poses instead, de-skewed along them.
            Outcome::Flight(r) => {
                Cow::Owned(pssba_core::world_cloud(frames, times, &r.world_from_lidar)?)
            }
        })
    }
}

/// Runs the subcommand.
pub fn run(args: &AdjustArgs) -> anyhow::Result<()> {
    let settings = Config::load(args.config.as_deref())?;
    let mut config = settings.algorithm;
    if let Some(method) = args.method.and_then(MethodArg::core_method) {
        config.method = method;
    }
    let balm = matches!(args.method, Some(MethodArg::Balm));
    let name = if balm { "balm" } else { config.method.name() };
    let Loaded {
        mut frames,
        initial: initial_stamped,
        ground_truth,
        mut point_times_s,
        default_out: (out_dir, out_prefix),
    } = {
        let source = args.recording.open(&args.dir, &settings.recording)?;
        tracing::info!("{}: a {}", args.dir.display(), source.kind());
        load(&args.dir, source.as_ref())?
    };
    tracing::info!(
        "{}: {} frames, method {name}",
        args.dir.display(),
        frames.len()
    );
    let initial: Vec<_> = initial_stamped.iter().map(|p| p.world_from_lidar).collect();
    let stamps_s: Vec<f64> = initial_stamped.iter().map(|p| p.stamp).collect();
    if let Some(times) = &point_times_s {
        let (lo, hi) = times
            .iter()
            .flatten()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &t| {
                (a.min(t), b.max(t))
            });
        if balm {
            tracing::warn!(
                "the frames have point times ({:.1} to {:.1} ms after their stamps); BALM takes \
                 frames as taken at one instant and ignores them",
                lo * 1e3,
                hi * 1e3
            );
        } else {
            tracing::info!(
                "point times {:.1} to {:.1} ms after the frames' stamps: every scale de-skews \
                 the points along its current poses; each output pose is the sensor's pose at \
                 its frame's stamp",
                lo * 1e3,
                hi * 1e3
            );
        }
    }
    let started = Instant::now();
    let context = || format!("adjusting {}", args.dir.display());
    let windows_asked = args.window_frames.is_some() || args.window_stride.is_some();
    if args.one_window && windows_asked {
        anyhow::bail!(
            "--one-window adjusts all frames in one window; --window-frames/--window-stride set \
             the sliding windows of the whole-flight pipeline: give one or the other"
        );
    }
    if balm && windows_asked {
        anyhow::bail!(
            "--window-frames/--window-stride run PSS-BA's sliding windows; BALM runs one window"
        );
    }
    let spec = pssba_core::WindowSpec {
        window_frames: args.window_frames.unwrap_or(settings.windows.window_frames),
        window_stride: args.window_stride.unwrap_or(settings.windows.window_stride),
    };
    // The whole flight when asked, or by default once the input is longer than one window.
    let flight = !balm && !args.one_window && (windows_asked || frames.len() > spec.window_frames);
    if flight {
        tracing::info!(
            "the whole-flight pipeline: windows of {} frames, stride {} (--one-window: one \
             window of all {} frames)",
            spec.window_frames,
            spec.window_stride,
            frames.len()
        );
    }
    let mut ape_by_scale_m: Vec<Option<f64>> = Vec::new();
    let outcome = if balm {
        let result = pssba_balm::adjust(&frames, &initial, &settings.balm, Parallelism::Rayon);
        Outcome::Balm(result.with_context(context)?)
    } else if flight {
        let times = point_times_s
            .as_deref()
            .map(|offsets_s| pssba_core::PointTimes {
                stamps_s: &stamps_s,
                offsets_s,
            });
        let result = pssba_core::adjust_flight(
            &frames,
            &initial,
            times,
            &config,
            spec,
            settings.flight.settings(),
            Parallelism::Rayon,
        );
        Outcome::Flight(result.with_context(context)?)
    } else {
        // With a ground truth, the error after each scale shows what each scale bought.
        let gt_stamped = ground_truth.as_deref().map(as_stamped);
        // Handed over (the smoothed map does not need them): 470 MB less at 1000 x 20k.
        let owned = std::mem::take(&mut frames);
        let times = point_times_s
            .take()
            .map(|offsets_s| pssba_core::FrameTimes {
                stamps_s: stamps_s.clone(),
                offsets_s,
            });
        let result = pssba_core::adjust_frames_observed(
            owned,
            &initial,
            times,
            &config,
            Parallelism::Rayon,
            |_, poses| {
                if let Some(gt) = &gt_stamped {
                    let stamped: Vec<_> = (initial_stamped.iter().zip(poses))
                        .map(|(p, pose)| (p.stamp, pose.to_isometry()))
                        .collect();
                    ape_by_scale_m.push(ape_m(gt, &stamped).ok());
                }
            },
        );
        Outcome::Core(result.with_context(context)?)
    };
    let wall_time_s = started.elapsed().as_secs_f64();
    outcome.print_report();
    if !ape_by_scale_m.is_empty() {
        let listed: Vec<String> = ape_by_scale_m
            .iter()
            .map(|a| a.map_or("-".to_string(), |m| format!("{:.2}", 1e3 * m)))
            .collect();
        eprintln!("APE after each scale (mm): {}", listed.join(" "));
    }

    let optimized: Vec<StampedPose> = initial_stamped
        .iter()
        .zip(outcome.world_from_lidar())
        .map(|(p, pose)| StampedPose {
            stamp: p.stamp,
            world_from_lidar: *pose,
        })
        .collect();
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| out_dir.join(format!("{out_prefix}poses_{name}.txt")));
    pssba_io::write_tum(&out, &optimized)?;
    let mut outputs = vec![out.display().to_string()];
    eprintln!("wrote {} poses to {}", optimized.len(), out.display());
    if let Some(map) = &args.map {
        let times = point_times_s
            .as_deref()
            .map(|offsets_s| pssba_core::PointTimes {
                stamps_s: &stamps_s,
                offsets_s,
            });
        let deskewed = times.is_some();
        let cloud = outcome.map_cloud(&frames, times)?;
        pssba_io::write_ply(map, &cloud)?;
        let what = match (&outcome, deskewed) {
            (Outcome::Core(_), _) => "smoothed",
            (Outcome::Flight(_), true) => "merged (de-skewed at the final poses)",
            _ => "merged",
        };
        eprintln!(
            "wrote {what} cloud ({} points) to {}",
            cloud.len(),
            map.display()
        );
        outputs.push(map.display().to_string());
    }
    // The poses are written: an APE that cannot be computed (e.g. a straight-line
    // trajectory, on which the SE(3) alignment is degenerate) is a warning, not a failure.
    let ape = match &ground_truth {
        Some(gt) => {
            let summary =
                ape_m(&as_stamped(gt), &as_stamped(&initial_stamped)).and_then(|initial_m| {
                    Ok(ApeSummary {
                        initial_m,
                        optimized_m: ape_m(&as_stamped(gt), &as_stamped(&optimized))?,
                    })
                });
            match summary {
                Ok(summary) => {
                    eprintln!(
                        "APE vs gt.txt: initial {:.4} m, optimized {:.4} m",
                        summary.initial_m, summary.optimized_m
                    );
                    Some(summary)
                }
                Err(error) => {
                    eprintln!("warning: APE vs gt.txt not computed: {error:#}");
                    None
                }
            }
        }
        None => None,
    };
    if args.json {
        let text = match &outcome {
            Outcome::Core(result) => serde_json::to_string_pretty(&RunSummary::new(
                config.method,
                result,
                ape,
                wall_time_s,
                outputs,
            ))?,
            Outcome::Balm(result) => {
                serde_json::to_string_pretty(&BalmSummary::new(result, ape, wall_time_s, outputs))?
            }
            Outcome::Flight(result) => serde_json::to_string_pretty(&serde_json::json!({
                "method": config.method.name(),
                "windows": result.windows.len(),
                "failed_windows": result.failures.len(),
                "loop_closures": result.closures.len(),
                "global_pass": result.global_pass.as_ref().map(|g| serde_json::json!({
                    "keyframes": g.keyframes,
                    "loop_edges": g.loop_edges,
                    "frames_moved": g.moved.len(),
                    "seconds": g.seconds,
                })),
                "keyframes": result.keyframes.0,
                "ape": ape,
                "wall_time_s": wall_time_s,
                "outputs": outputs,
            }))?,
        };
        println!("{text}");
    }
    if let Outcome::Flight(result) = &outcome {
        let failed: Vec<String> = result
            .failures
            .iter()
            .map(|f| {
                format!(
                    "window {} (frames {}..{} kept their initial poses): {}",
                    f.index, f.kept_initial.start, f.kept_initial.end, f.error
                )
            })
            .collect();
        crate::run::report_failed_windows(
            &failed,
            result.windows.len(),
            settings.system.allow_failed_windows,
        )?;
    }
    Ok(())
}
