//! Sliding-window bundle adjustment over a stream of frames (DESIGN section 6), as a pure type
//! with plain state: frames go in one by one ([`SlidingWindows::push_frame`]), windows come out
//! as soon as the plan (`plan::next_window`) has enough frames, and every frame gets exactly
//! one final pose.
//!
//! Each window runs the progressive schedule ([`ProgressiveRun`]); the per-scale solve (DESIGN
//! steps 7-8) is a callback, so the same driver runs in one process ([`adjust_sliding`],
//! `pssba adjust --window-frames W`) and in the process system, where the solve is a round
//! trip to the adjust stage. If a window's adjustment fails, its new frames keep their
//! (anchor-corrected) initial poses: nothing accepted is lost, and the failure is recorded
//! ([`SlidingWindows::failures`]) for the caller to report.

mod plan;

pub use plan::WindowPlan;
use plan::{anchor_correction, next_window};

use crate::cloud::deskew::{PointTimes, deskew_frame};
use crate::config::PssBaConfig;
use crate::error::CoreError;
use crate::geometry::Pose;
use crate::parallel::Parallelism;
use crate::result::AdjustResult;
use crate::schedule::progressive::{ProgressiveRun, ScaleStep, Window};
use crate::solve::lm::{LmReport, solve_block};
use nalgebra::{Isometry3, Point3};
use std::borrow::Cow;

/// Window length and stride, in frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WindowSpec {
    /// Frames per window (W >= 2).
    pub window_frames: usize,
    /// New frames per window after the first (1 <= S < W).
    pub window_stride: usize,
}

impl WindowSpec {
    /// Checks the values; the error names the field.
    pub fn validate(&self) -> Result<(), CoreError> {
        if self.window_frames < 2 {
            return Err(CoreError::InvalidConfig {
                field: "window_frames",
                value: self.window_frames.to_string(),
                reason: "a window needs at least 2 frames",
            });
        }
        if self.window_stride == 0 || self.window_stride >= self.window_frames {
            return Err(CoreError::InvalidConfig {
                field: "window_stride",
                value: self.window_stride.to_string(),
                reason: "must be in 1..window_frames: later windows need at least one final \
                         frame to anchor them",
            });
        }
        Ok(())
    }
}

/// Why a solve done elsewhere (another process) failed.
pub type SolveError = Box<dyn std::error::Error + Send + Sync>;

/// Why one window's adjustment failed.
#[derive(Debug, thiserror::Error)]
pub enum WindowError {
    /// The algorithm refused the window (too few points, no constraint ...).
    #[error(transparent)]
    Core(#[from] CoreError),
    /// The per-scale solve failed.
    #[error("scale {scale}: {source}")]
    Solve {
        /// Scale index.
        scale: usize,
        /// What the solver said.
        source: SolveError,
    },
}

/// A frame that became final.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FinalFrame {
    /// Stream index (0-based, in arrival order).
    pub sequence: usize,
    /// The frame's stamp (s).
    pub stamp_s: f64,
    /// Its final pose.
    pub world_from_lidar: Isometry3<f64>,
}

/// One finished window.
#[derive(Debug)]
pub struct WindowOutcome {
    /// Window number (0-based).
    pub index: usize,
    /// Frames it covered and which were held fixed.
    pub plan: WindowPlan,
    /// The frames it made final, in order.
    pub finals: Vec<FinalFrame>,
    /// The adjustment, its surfaces' `frame` re-indexed to stream indices; the error when it
    /// failed (the frames in `finals` then kept their corrected initial poses).
    pub result: Result<AdjustResult, WindowError>,
}

/// A window whose adjustment failed.
#[derive(Debug, Clone, PartialEq)]
pub struct FailedWindow {
    /// Window number.
    pub index: usize,
    /// Stream indices of the frames that kept their (corrected) initial poses.
    pub kept_initial: std::ops::Range<usize>,
    /// Why it failed.
    pub error: String,
}

#[derive(Debug)]
struct StreamFrame {
    stamp_s: f64,
    initial: Isometry3<f64>,
    final_pose: Option<Isometry3<f64>>,
}

/// The sliding-window driver: frames received so far, final poses, failures.
#[derive(Debug)]
pub struct SlidingWindows {
    spec: WindowSpec,
    frames: Vec<StreamFrame>,
    /// Lidar-frame points of each frame (apart from `frames` so a window borrows a slice);
    /// emptied once no later window can reach back to the frame.
    points: Vec<Vec<Point3<f64>>>,
    /// Each point's time after its frame's stamp (s), parallel to `points`; empty for a
    /// frame taken at one instant. Emptied with the points.
    times: Vec<Vec<f32>>,
    finalised: usize,
    ended: bool,
    windows_done: usize,
    failures: Vec<FailedWindow>,
    /// Final poses of the first frames to be pushed ([`Self::resume`]).
    resumed_finals: Vec<Isometry3<f64>>,
}

impl SlidingWindows {
    /// An empty stream.
    pub fn new(spec: WindowSpec) -> Result<Self, CoreError> {
        spec.validate()?;
        Ok(Self {
            spec,
            frames: Vec::new(),
            points: Vec::new(),
            times: Vec::new(),
            finalised: 0,
            ended: false,
            windows_done: 0,
            failures: Vec::new(),
            resumed_finals: Vec::new(),
        })
    }

    /// A stream that goes on after earlier windows (a process restarted after a crash): the
    /// first `anchors.len()` frames pushed are already final, with these poses. Pass the last
    /// `W - S` final frames of the earlier windows: they anchor the next window exactly as
    /// they would have in one unbroken stream (same plan, same fixed frames, same initial
    /// poses), so the results are the same.
    pub fn resume(spec: WindowSpec, anchors: Vec<Isometry3<f64>>) -> Result<Self, CoreError> {
        let mut stream = Self::new(spec)?;
        stream.finalised = anchors.len();
        stream.resumed_finals = anchors;
        Ok(stream)
    }

    /// Appends the next frame (lidar-frame points, initial world-from-lidar); returns its
    /// stream index. Refused after [`Self::end_stream`].
    pub fn push_frame(
        &mut self,
        stamp_s: f64,
        points: Vec<Point3<f64>>,
        initial: Isometry3<f64>,
    ) -> Result<usize, CoreError> {
        self.push_moving_frame(stamp_s, points, None, initial)
    }

    /// [`Self::push_frame`] with each point's time after `stamp_s` (s; one per point, finite,
    /// checked here) for a frame taken while moving: its window then de-skews it at every
    /// scale (see [`crate::PointTimes`]).
    pub fn push_moving_frame(
        &mut self,
        stamp_s: f64,
        points: Vec<Point3<f64>>,
        times_s: Option<Vec<f32>>,
        initial: Isometry3<f64>,
    ) -> Result<usize, CoreError> {
        let sequence = self.frames.len();
        let times_s = times_s.unwrap_or_default();
        if !times_s.is_empty() {
            let offsets = std::slice::from_ref(&times_s);
            PointTimes {
                stamps_s: &[stamp_s],
                offsets_s: offsets,
            }
            .check(&[points.len()])
            .map_err(|e| match e {
                CoreError::PointTimesCount { points, times, .. } => CoreError::PointTimesCount {
                    frame: sequence,
                    points,
                    times,
                },
                CoreError::NonFinitePointTime { .. } => {
                    CoreError::NonFinitePointTime { frame: sequence }
                }
                other => other,
            })?;
        }
        if self.ended {
            return Err(CoreError::FrameAfterEndOfStream {
                sequence: self.frames.len(),
            });
        }
        let final_pose = self.resumed_finals.get(self.frames.len()).copied();
        self.frames.push(StreamFrame {
            stamp_s,
            initial,
            final_pose,
        });
        self.points.push(points);
        self.times.push(times_s);
        Ok(self.frames.len() - 1)
    }

    /// No more frames will come: the last window takes what is left.
    pub fn end_stream(&mut self) {
        self.ended = true;
    }

    /// Frames received.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// True before the first frame.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Frames `[0, finalised)` are final.
    pub fn finalised(&self) -> usize {
        self.finalised
    }

    /// True once the stream has ended.
    pub fn ended(&self) -> bool {
        self.ended
    }

    /// True once the stream has ended and every frame is final.
    pub fn is_done(&self) -> bool {
        self.ended && self.finalised == self.frames.len()
    }

    /// Windows run so far.
    pub fn windows_done(&self) -> usize {
        self.windows_done
    }

    /// Windows whose adjustment failed, in order.
    pub fn failures(&self) -> &[FailedWindow] {
        &self.failures
    }

    /// Final pose of every frame so far (`None` while not yet final).
    pub fn final_poses(&self) -> Vec<Option<Isometry3<f64>>> {
        self.frames.iter().map(|f| f.final_pose).collect()
    }

    /// Final pose of frame `sequence`, if it is final.
    pub fn final_pose(&self, sequence: usize) -> Option<Isometry3<f64>> {
        self.frames.get(sequence).and_then(|f| f.final_pose)
    }

    /// Initial pose of frame `sequence`, as pushed.
    pub fn initial_pose(&self, sequence: usize) -> Option<Isometry3<f64>> {
        self.frames.get(sequence).map(|f| f.initial)
    }

    /// Stamp of frame `sequence` (s; NaN if there is no such frame).
    pub fn stamp_s(&self, sequence: usize) -> f64 {
        self.frames.get(sequence).map_or(f64::NAN, |f| f.stamp_s)
    }

    /// Moves the final pose of a frame that is already final (a loop closure corrects it);
    /// the next window's anchors and initial poses follow. False if it is not final.
    pub(crate) fn revise_final_pose(&mut self, sequence: usize, pose: Isometry3<f64>) -> bool {
        match self.frames.get_mut(sequence) {
            Some(frame) if frame.final_pose.is_some() => {
                frame.final_pose = Some(pose);
                true
            }
            _ => false,
        }
    }

    /// Lidar-frame points of frame `sequence` while a later window can still use them (empty
    /// after).
    pub(crate) fn frame_points(&self, sequence: usize) -> &[Point3<f64>] {
        self.points.get(sequence).map_or(&[], Vec::as_slice)
    }

    /// [`Self::frame_points`] brought to the frame's stamp along the final poses of its
    /// neighbours, for a frame taken while moving (as pushed otherwise).
    pub(crate) fn frame_points_deskewed(&self, sequence: usize) -> Cow<'_, [Point3<f64>]> {
        let points = self.frame_points(sequence);
        let times = self.times.get(sequence).map_or(&[][..], Vec::as_slice);
        if times.len() != points.len() || times.iter().all(|&t| t == 0.0) {
            return Cow::Borrowed(points);
        }
        let around: Vec<usize> = (sequence.saturating_sub(1)..=sequence + 1)
            .filter(|&k| self.final_pose(k).is_some() || k == sequence)
            .collect();
        let pose_of = |k: usize| {
            self.final_pose(k)
                .or_else(|| self.initial_pose(k))
                .unwrap_or_else(Isometry3::identity)
        };
        let poses: Vec<Pose> = around
            .iter()
            .map(|&k| Pose::from_isometry(&pose_of(k)))
            .collect();
        let stamps: Vec<f64> = around.iter().map(|&k| self.stamp_s(k)).collect();
        let here = around.iter().position(|&k| k == sequence).unwrap_or(0);
        Cow::Owned(deskew_frame(points, times, &poses, &stamps, here))
    }

    /// The window's point times, when some frame in `first..end` has them: borrowed when every
    /// frame has them, else with zeros for the frames taken at one instant.
    fn window_times(&self, first: usize, end: usize) -> Option<Cow<'_, [Vec<f32>]>> {
        let times = &self.times[first..end];
        if times.iter().all(Vec::is_empty) {
            return None;
        }
        if times.iter().all(|t| !t.is_empty()) {
            return Some(Cow::Borrowed(times));
        }
        let filled = times
            .iter()
            .zip(&self.points[first..end])
            .map(|(t, p)| {
                if t.is_empty() {
                    vec![0.0; p.len()]
                } else {
                    t.clone()
                }
            })
            .collect();
        Some(Cow::Owned(filled))
    }

    /// The window that would run next, if enough frames have arrived.
    pub fn next_plan(&self) -> Option<WindowPlan> {
        next_window(
            self.spec.window_frames,
            self.spec.window_stride,
            self.finalised,
            self.frames.len(),
            self.ended,
        )
    }

    /// Runs the next window, solving each scale in this process.
    pub fn run_next_local(
        &mut self,
        config: &PssBaConfig,
        parallelism: Parallelism,
    ) -> Option<WindowOutcome> {
        self.run_next(config, parallelism, |_, run, step| {
            Ok(solve_block(
                &step.block,
                run.poses(),
                run.fixed(),
                &step.settings,
                parallelism,
            ))
        })
    }

    /// Runs the next window (`None` if it cannot run yet). `solve(window, run, step)` returns
    /// the adjusted poses of one scale: what [`solve_block`] returns on `step.block` at
    /// `run.poses()` with `run.fixed()`.
    pub fn run_next<S>(
        &mut self,
        config: &PssBaConfig,
        parallelism: Parallelism,
        mut solve: S,
    ) -> Option<WindowOutcome>
    where
        S: FnMut(usize, &ProgressiveRun, &ScaleStep) -> Result<(Vec<Pose>, LmReport), SolveError>,
    {
        let plan = self.next_plan()?;
        let index = self.windows_done;
        let poses = self.window_poses(&plan);
        tracing::info!(
            "window {index}: frames {}..{} ({} held fixed), {} received",
            plan.first,
            plan.end,
            plan.fixed.iter().filter(|&&f| f).count(),
            self.frames.len()
        );
        let stamps_s: Vec<f64> = self.frames[plan.first..plan.end]
            .iter()
            .map(|f| f.stamp_s)
            .collect();
        let offsets_s = self.window_times(plan.first, plan.end);
        let window = Window {
            frames: &self.points[plan.first..plan.end],
            world_from_lidar: &poses,
            fixed: Some(&plan.fixed),
            times: offsets_s.as_deref().map(|offsets_s| PointTimes {
                stamps_s: &stamps_s,
                offsets_s,
            }),
        };
        let mut result = run_window(window, config, parallelism, |run, step| {
            solve(index, run, step)
        });
        drop(offsets_s);
        let final_poses = match &mut result {
            Ok(adjusted) => {
                for surface in &mut adjusted.surfaces {
                    surface.frame += plan.first;
                }
                adjusted.world_from_lidar.clone()
            }
            Err(error) => {
                tracing::warn!(
                    "window {index}: adjustment failed ({error}); keeping the initial poses"
                );
                poses
            }
        };
        let mut finals = Vec::new();
        for (i, k) in (plan.first..plan.end).enumerate() {
            if self.frames[k].final_pose.is_none() {
                self.frames[k].final_pose = Some(final_poses[i]);
                finals.push(FinalFrame {
                    sequence: k,
                    stamp_s: self.frames[k].stamp_s,
                    world_from_lidar: final_poses[i],
                });
            }
        }
        self.finalised = plan.end;
        if let Err(error) = &result {
            let first_new = finals.first().map_or(plan.end, |f| f.sequence);
            self.failures.push(FailedWindow {
                index,
                kept_initial: first_new..plan.end,
                error: error.to_string(),
            });
        }
        // No later window starts before `finalised - W`.
        let keep_from = self.finalised.saturating_sub(self.spec.window_frames);
        for points in &mut self.points[..keep_from] {
            *points = Vec::new();
        }
        for times in &mut self.times[..keep_from] {
            *times = Vec::new();
        }
        self.windows_done += 1;
        Some(WindowOutcome {
            index,
            plan,
            finals,
            result,
        })
    }

    /// Initial poses of a window: final poses for the frames already final, the anchors' mean
    /// correction applied to the new frames' initial poses (identity in window 0).
    fn window_poses(&self, plan: &WindowPlan) -> Vec<Isometry3<f64>> {
        let anchors: Vec<_> = self.frames[plan.first..plan.end]
            .iter()
            .filter_map(|f| f.final_pose.map(|p| (f.initial, p)))
            .collect();
        let correction = anchor_correction(&anchors);
        self.frames[plan.first..plan.end]
            .iter()
            .map(|f| f.final_pose.unwrap_or(correction * f.initial))
            .collect()
    }
}

/// One window's progressive schedule with the given per-scale solve.
fn run_window<S>(
    window: Window<'_>,
    config: &PssBaConfig,
    parallelism: Parallelism,
    mut solve: S,
) -> Result<AdjustResult, WindowError>
where
    S: FnMut(&ProgressiveRun, &ScaleStep) -> Result<(Vec<Pose>, LmReport), SolveError>,
{
    let mut run = ProgressiveRun::new(window, config)?;
    while let Some(step) = run.next_step(parallelism)? {
        let scale = step.index;
        let (adjusted, lm) =
            solve(&run, &step).map_err(|source| WindowError::Solve { scale, source })?;
        let report = run.complete_step(step, adjusted, &lm)?;
        tracing::info!(
            "scale {scale}: gamma {:.3} m, {} kernels, {} residuals, pose change {:.4}",
            report.gamma_m,
            report.kernels_used,
            report.residuals,
            report.pose_change
        );
    }
    Ok(run.finish(parallelism))
}

/// Everything a whole stream's sliding windows produced.
#[derive(Debug)]
pub struct SlidingResult {
    /// Final pose of every frame.
    pub world_from_lidar: Vec<Isometry3<f64>>,
    /// Every window, in order.
    pub windows: Vec<WindowOutcome>,
    /// The windows that failed.
    pub failures: Vec<FailedWindow>,
}

/// Adjusts a whole sequence in sliding windows, in this process: what the process system
/// computes with the same `spec` and `config`.
pub fn adjust_sliding(
    frames: &[Vec<Point3<f64>>],
    world_from_lidar: &[Isometry3<f64>],
    config: &PssBaConfig,
    spec: WindowSpec,
    parallelism: Parallelism,
) -> Result<SlidingResult, CoreError> {
    if frames.len() != world_from_lidar.len() {
        return Err(CoreError::CountMismatch {
            frames: frames.len(),
            poses: world_from_lidar.len(),
        });
    }
    config.validate()?;
    let mut stream = SlidingWindows::new(spec)?;
    for (k, (points, pose)) in frames.iter().zip(world_from_lidar).enumerate() {
        stream.push_frame(k as f64, points.clone(), *pose)?;
    }
    stream.end_stream();
    let mut windows = Vec::new();
    while let Some(outcome) = stream.run_next_local(config, parallelism) {
        windows.push(outcome);
    }
    let world_from_lidar = stream
        .final_poses()
        .into_iter()
        .map(|p| p.expect("the plan makes every frame final once the stream has ended"))
        .collect();
    Ok(SlidingResult {
        world_from_lidar,
        windows,
        failures: stream.failures,
    })
}
