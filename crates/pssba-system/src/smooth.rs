//! The smooth stage: collects frames into sliding windows and runs the progressive schedule of
//! each window, extracting kernels here (DESIGN steps 1-6) and handing every scale's factor
//! block to the adjust stage (steps 7-8), whose poses start the next scale. Publishes each
//! finished window: final poses, surfaces, smoothed cloud and per-scale reports.

use crate::latency::LatencyStats;
use crate::shm::{self, WAKE_INTERVAL};
use crate::sliding::{WindowPlan, anchor_correction, next_window};
use crate::stream::FrameStore;
use anyhow::{Context, bail};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::PortFactory;
use nalgebra::Isometry3;
use pssba_core::geometry::Pose;
use pssba_core::lm::LmReport;
use pssba_core::{Parallelism, ProgressiveRun, ScaleStep, Window};
use pssba_msg::services::{self, names};
use pssba_msg::types::{block_kind, result_kind};
use pssba_msg::{
    BlockHeader, FinalPose, FrameHeader, PointXyz, PoseMsg, PoseSetHeader, ResultHeader,
    WindowResult,
};
use std::time::{Duration, Instant};

/// Options of the smooth stage.
#[derive(Debug, Clone)]
pub struct SmoothOptions {
    /// iceoryx2 prefix of this run.
    pub prefix: String,
    /// Algorithm and system settings.
    pub config: crate::RunConfig,
}

struct Ports {
    node: Node<ipc::Service>,
    frames_service: services::FramesService,
    blocks_service: services::BlocksService,
    results_service: services::ResultsService,
    frames: Subscriber<ipc::Service, [PointXyz], FrameHeader>,
    frames_listener: Listener<ipc::Service>,
    blocks: Publisher<ipc::Service, [f64], BlockHeader>,
    blocks_notifier: Notifier<ipc::Service>,
    poses: Subscriber<ipc::Service, [PoseMsg], PoseSetHeader>,
    poses_listener: Listener<ipc::Service>,
    results: Publisher<ipc::Service, [f64], ResultHeader>,
    results_notifier: Notifier<ipc::Service>,
}

fn open_ports(options: &SmoothOptions) -> anyhow::Result<Ports> {
    let timeout = Duration::from_secs_f64(options.config.system.backpressure_timeout_s);
    let node = services::create_node(&options.prefix, "smooth")?;
    let frames_service = services::frames_service(&node)?;
    let blocks_service = services::blocks_service(&node)?;
    let poses_service = services::pose_sets_service(&node)?;
    let results_service = services::results_service(&node)?;
    let sub_err = |e| anyhow::anyhow!("creating a subscriber: {e:?}");
    let frames = frames_service
        .subscriber_builder()
        .create()
        .map_err(sub_err)?;
    let ready = shm::notifier(&services::event_service(&node, shm::FRAMES_READY)?)?;
    shm::connect_and_report_ready(
        &node,
        &frames_service,
        &frames,
        &ready,
        shm::ready_id::SMOOTH,
        Duration::from_secs(60),
    )?;
    let ports = Ports {
        frames,
        frames_listener: shm::listener(&services::event_service(&node, names::FRAMES)?)?,
        blocks: services::publisher(
            &blocks_service,
            options.config.system.max_block_words,
            timeout,
        )?,
        blocks_notifier: shm::notifier(&services::event_service(&node, names::BLOCKS)?)?,
        poses: poses_service
            .subscriber_builder()
            .create()
            .map_err(sub_err)?,
        poses_listener: shm::listener(&services::event_service(&node, names::POSE_SETS)?)?,
        results: services::publisher(
            &results_service,
            options.config.system.max_result_words,
            timeout,
        )?,
        results_notifier: shm::notifier(&services::event_service(&node, names::RESULTS)?)?,
        node,
        frames_service,
        blocks_service,
        results_service,
    };
    // adjust, and record for the results.
    shm::wait_for_subscribers(
        &ports.node,
        &ports.blocks_service,
        1,
        "factor blocks",
        Duration::from_secs(60),
    )?;
    shm::wait_for_subscribers(
        &ports.node,
        &ports.results_service,
        1,
        "results",
        Duration::from_secs(60),
    )?;
    Ok(ports)
}

/// Runs the stage until the stream has ended and every frame is final.
pub fn run(options: &SmoothOptions) -> anyhow::Result<()> {
    let ports = open_ports(options)?;
    let system = &options.config.system;
    let mut store = FrameStore::default();
    let mut latency = LatencyStats::default();
    let mut window_index = 0u64;
    loop {
        store.receive(&ports.frames, &mut latency)?;
        while let Some(plan) = next_window(
            system.window_frames,
            system.window_stride,
            store.finalised(),
            store.len(),
            store.ended(),
        ) {
            run_window(&ports, options, &mut store, &plan, window_index)?;
            window_index += 1;
            store.forget_before(store.finalised().saturating_sub(system.window_frames));
        }
        if store.ended() && store.finalised() == store.len() {
            break;
        }
        if shm::termination_requested(&ports.node) {
            bail!(
                "interrupted with {} frames received, {} final",
                store.len(),
                store.finalised()
            );
        }
        if !store.ended() && ports.frames_service.dynamic_config().number_of_publishers() == 0 {
            // Drain what the producer sent before it left, then decide.
            store.receive(&ports.frames, &mut latency)?;
            if !store.ended() {
                bail!(
                    "the frame producer left before the end of the stream ({} frames received)",
                    store.len()
                );
            }
            continue;
        }
        ports
            .frames_listener
            .timed_wait(|_| {}, WAKE_INTERVAL)
            .map_err(|e| anyhow::anyhow!("waiting for frames: {e:?}"))?;
    }
    latency.log_summary(store.largest_frame_points(), system.window_frames);
    let end = ResultHeader {
        kind: result_kind::END_OF_RUN,
        window: window_index,
        ..ResultHeader::default()
    };
    shm::publish_slice(&ports.results, &ports.results_notifier, end, &[])?;
    let shutdown = BlockHeader {
        kind: block_kind::SHUTDOWN,
        ..BlockHeader::default()
    };
    shm::publish_slice(&ports.blocks, &ports.blocks_notifier, shutdown, &[])?;
    tracing::info!("{} frames final in {window_index} windows", store.len());
    let Ports {
        node,
        frames,
        poses,
        blocks_service,
        results_service,
        ..
    } = ports;
    // Consumers first: the adjust stage lingers until this stage stops reading its poses.
    drop(frames);
    drop(poses);
    let linger = Duration::from_secs_f64(system.backpressure_timeout_s);
    shm::linger_until_unsubscribed(&node, &results_service, "results", linger);
    shm::linger_until_unsubscribed(&node, &blocks_service, "factor blocks", linger);
    Ok(())
}

/// Initial poses of the window: final poses for fixed frames, the anchors' mean correction
/// applied to the new frames' initial poses (identity in window 0).
fn window_poses(store: &FrameStore, plan: &WindowPlan) -> Vec<Isometry3<f64>> {
    let anchors: Vec<_> = (plan.first..plan.end)
        .filter_map(|k| {
            store
                .frame(k)
                .final_pose
                .map(|f| (store.frame(k).initial, f))
        })
        .collect();
    let correction = anchor_correction(&anchors);
    (plan.first..plan.end)
        .map(|k| {
            let frame = store.frame(k);
            frame.final_pose.unwrap_or(correction * frame.initial)
        })
        .collect()
}

fn run_window(
    ports: &Ports,
    options: &SmoothOptions,
    store: &mut FrameStore,
    plan: &WindowPlan,
    window: u64,
) -> anyhow::Result<()> {
    let started = Instant::now();
    let poses = window_poses(store, plan);
    let frames: Vec<_> = (plan.first..plan.end)
        .map(|k| store.frame(k).points.clone())
        .collect();
    tracing::info!(
        "window {window}: frames {}..{} ({} anchors), {} received",
        plan.first,
        plan.end,
        plan.fixed.iter().filter(|&&f| f).count(),
        store.len()
    );
    let outcome = ProgressiveRun::new(
        Window {
            frames: &frames,
            world_from_lidar: &poses,
            fixed: Some(&plan.fixed),
        },
        &options.config.pssba,
    )
    .map_err(anyhow::Error::from)
    .and_then(|mut run| {
        while let Some(step) = run.next_step(Parallelism::Rayon)? {
            let (adjusted, lm) = remote_solve(ports, options, &run, &step, window)?;
            let scale = step.index;
            let report = run.complete_step(step, adjusted, &lm)?;
            tracing::info!(
                "window {window} scale {scale}: gamma {:.3} m, {} kernels, {} residuals, pose change {:.4}",
                report.gamma_m,
                report.kernels_used,
                report.residuals,
                report.pose_change
            );
        }
        Ok(run.finish(Parallelism::Rayon))
    });
    let (final_poses, mut result) = match outcome {
        Ok(result) => (result.world_from_lidar.clone(), Some(result)),
        Err(error) => {
            // Nothing accepted is lost: the frames keep their (corrected) initial poses.
            tracing::warn!(
                "window {window}: adjustment failed ({error:#}); keeping the initial poses"
            );
            (poses.clone(), None)
        }
    };
    let mut finals = Vec::new();
    for (i, k) in (plan.first..plan.end).enumerate() {
        if store.frame(k).final_pose.is_none() {
            store.set_final(k, final_poses[i]);
            finals.push(FinalPose {
                sequence: k as u64,
                stamp_s: store.frame(k).stamp_s,
                world_from_lidar: final_poses[i],
            });
        }
    }
    let message = WindowResult {
        window,
        converged: result.as_ref().is_some_and(|r| r.converged),
        finals,
        surfaces: result
            .as_mut()
            .map(|r| {
                let mut surfaces = std::mem::take(&mut r.surfaces);
                for s in &mut surfaces {
                    s.frame += plan.first;
                }
                surfaces
            })
            .unwrap_or_default(),
        map: result
            .as_mut()
            .map(|r| std::mem::take(&mut r.smoothed_cloud))
            .unwrap_or_default(),
        scales: result.map(|r| r.scales).unwrap_or_default(),
    };
    let message = fit_result(message, options.config.system.max_result_words);
    let (header, words) = pssba_msg::encode_result(&message);
    shm::publish_slice(&ports.results, &ports.results_notifier, header, &words)
        .context("publishing the window result")?;
    tracing::info!(
        "progress: frames in {}, windows done {}, {} frames final ({:.1} s for this window)",
        store.len(),
        window + 1,
        store.finalised(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Publishes the step's factor block and waits for the adjust stage's poses.
fn remote_solve(
    ports: &Ports,
    options: &SmoothOptions,
    run: &ProgressiveRun,
    step: &ScaleStep,
    window: u64,
) -> anyhow::Result<(Vec<Pose>, LmReport)> {
    let (header, words) = pssba_msg::encode_block(
        window,
        step.index as u32,
        &step.block,
        run.poses(),
        run.fixed(),
        &step.settings,
    );
    let limit = options.config.system.max_block_words;
    if words.len() > limit {
        bail!(
            "window {window} scale {}: the factor block needs {} words, system.max_block_words \
             is {limit} (raise it, or lower residuals_per_scale)",
            step.index,
            words.len()
        );
    }
    shm::publish_slice(&ports.blocks, &ports.blocks_notifier, header, &words)
        .context("publishing a factor block")?;
    let timeout = Duration::from_secs_f64(options.config.system.reply_timeout_s);
    let sent = Instant::now();
    loop {
        while let Some(sample) = ports
            .poses
            .receive()
            .map_err(|e| anyhow::anyhow!("receiving poses: {e:?}"))?
        {
            let h = *sample.user_header();
            if h.window != window || h.scale != step.index as u32 {
                tracing::warn!(
                    "ignoring poses for window {} scale {} (stale)",
                    h.window,
                    h.scale
                );
                continue;
            }
            if h.rejected != 0 {
                bail!(
                    "the adjust stage rejected window {window} scale {}",
                    step.index
                );
            }
            if sample.payload().len() != run.poses().len() {
                bail!(
                    "poses from the adjust stage: {} poses for a {}-frame window",
                    sample.payload().len(),
                    run.poses().len()
                );
            }
            let poses = sample
                .payload()
                .iter()
                .enumerate()
                .map(|(k, p)| p.to_pose("pose set", k as u64))
                .collect::<Result<Vec<_>, _>>()?;
            let lm = LmReport {
                cost_before: h.cost_before,
                cost_after: h.cost_after,
                iterations: h.iterations as usize,
                residuals: h.residuals as usize,
                unconstrained_frames: h.unconstrained_frames as usize,
            };
            return Ok((poses, lm));
        }
        if sent.elapsed() > timeout {
            bail!(
                "no poses from the adjust stage within {:.0} s",
                timeout.as_secs_f64()
            );
        }
        if shm::termination_requested(&ports.node) {
            bail!("interrupted while waiting for the adjust stage");
        }
        ports
            .poses_listener
            .timed_wait(|_| {}, WAKE_INTERVAL)
            .map_err(|e| anyhow::anyhow!("waiting for poses: {e:?}"))?;
    }
}

/// Thins the smoothed map (every k-th point) so the encoded result fits `max_words`.
fn fit_result(mut message: WindowResult, max_words: usize) -> WindowResult {
    let fixed_words =
        message.finals.len() * 14 + message.surfaces.len() * 20 + message.scales.len() * 15;
    let room = max_words.saturating_sub(fixed_words) / 3;
    if message.map.len() > room {
        let stride = message.map.len().div_ceil(room.max(1));
        tracing::warn!(
            "window {}: smoothed map of {} points thinned to every {stride}th point to fit \
             system.max_result_words",
            message.window,
            message.map.len()
        );
        message.map = message.map.into_iter().step_by(stride).take(room).collect();
        if fixed_words > max_words {
            message.surfaces.clear();
        }
    }
    message
}
