//! The whole flight (DESIGN section 9, issue 38): sliding windows ([`SlidingWindows`]) plus
//! places seen again. Final frames become keyframes (`keyframes`); when a window's new frames
//! come near keyframes flown long before and outside the window, and their clouds overlap, the
//! new keyframes are aligned onto the old ones with the progressive schedule from 3 m (the old
//! ones held fixed): that measures the drift. A pose graph over the keyframes since the old
//! visit (`pose_graph`: relative poses from the windows, weighted by what each keyframe's
//! scene constrains, and the loop edges) spreads the correction over the frames in between;
//! frames between keyframes follow their keyframes. The next window starts from the corrected
//! poses. A flight that never comes back gets exactly the sliding windows' poses.

mod keyframes;
mod loop_closure;

pub use crate::solve::pose_graph::GraphReport;
pub use keyframes::{Keyframe, geometry_information};
pub use loop_closure::{GlobalPass, LoopClosure};

use crate::cloud::deskew::PointTimes;
use crate::config::{MotionPrior, PssBaConfig};
use crate::error::CoreError;
use crate::geometry::Pose;
use crate::lm::LmReport;
use crate::parallel::Parallelism;
use crate::schedule::progressive::{ProgressiveRun, ScaleStep};
use crate::schedule::sliding::{
    FailedWindow, FinalFrame, SlidingResult, SlidingWindows, SolveError, WindowOutcome, WindowSpec,
};
use crate::solve::pose_graph;
use keyframes::Keyframes;
use loop_closure::LoopEdge;
use nalgebra::{Isometry3, Point3};

/// How keyframes are kept and revisits found and closed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlightSettings {
    /// False: plain sliding windows (no keyframes, no loop closure).
    pub enabled: bool,
    /// After the last window of a flight that closed a loop, one pose graph over all its
    /// keyframes and loop edges (the global pass): every loop's correction shared by the
    /// whole flight, not only by the frames after the old visit.
    pub global_pass: bool,
    /// The motion prior of every window (`PssBaConfig::motion_prior`): the initial poses of a
    /// flight come from odometry, whose increments hold where the scene leaves directions
    /// open. Zero sigmas: off.
    pub motion_prior: MotionPrior,
    /// A final frame becomes a keyframe after this much motion from the last one (m) ...
    pub keyframe_step_m: f64,
    /// ... or this much rotation (deg).
    pub keyframe_step_deg: f64,
    /// Voxel edge of a keyframe's stored cloud (m).
    pub keyframe_voxel_m: f64,
    /// A keyframe this close to a new keyframe (m) is a revisit candidate ...
    pub revisit_radius_m: f64,
    /// ... when the flight went at least this far between them (m), so the recent past is
    /// not taken for a revisit.
    pub revisit_min_path_m: f64,
    /// Share of the new keyframes' occupied voxels (edge `overlap_voxel_m`) the old ones must
    /// also occupy to confirm a revisit.
    pub revisit_min_overlap: f64,
    /// Voxel edge of the overlap test (m). 2 m, not 1: with 1 m voxels an offset of half a
    /// voxel (drift the closure is there to remove) already empties most shared voxels, and on
    /// an hour's survey loops stopped closing after 15 minutes (overlap 0.01-0.26); at 2 m they
    /// close all hour, and the short revisit and survey flights keep their APE within 0.3 mm
    /// (BENCHMARK.md, 2026-12-07).
    pub overlap_voxel_m: f64,
    /// Old keyframes held fixed in one alignment, at most (the nearest).
    pub max_old_keyframes: usize,
    /// New keyframes aligned at once, at most (evenly spread).
    pub max_new_keyframes: usize,
    /// A drift larger than this (m) is not believed: the closure is skipped.
    pub max_correction_m: f64,
    /// Nor an alignment whose keyframes end farther than this (RMS, m) from one rigid
    /// correction of the window.
    pub max_alignment_spread_m: f64,
    /// What a window's relative pose between keyframes is good to along a direction its
    /// scene constrains (m).
    pub window_sigma_m: f64,
    /// What a loop edge is good to along a direction its scene constrains (m).
    pub loop_sigma_m: f64,
    /// The odometry's relative-pose sigma between keyframes, for the directions a scene
    /// leaves open (m and rad).
    pub odometry_sigma_m: f64,
    pub odometry_sigma_rad: f64,
}

impl Default for FlightSettings {
    fn default() -> Self {
        Self {
            enabled: true,
            global_pass: true,
            // Measured on the revisit flights (examples/revisit_flight.rs, BENCHMARK.md): 0.02 m
            // / 0.002 rad biased each visit (4.6 -> 5.6 mm), 0.1 / 0.01 let frames jitter
            // (26 mm jumps); 0.05 / 0.005 gave 3.2 mm and 14 mm.
            motion_prior: MotionPrior {
                translation_m: 0.05,
                rotation_rad: 0.005,
            },
            keyframe_step_m: 1.0,
            keyframe_step_deg: 10.0,
            keyframe_voxel_m: 0.4,
            revisit_radius_m: 8.0,
            revisit_min_path_m: 40.0,
            revisit_min_overlap: 0.3,
            overlap_voxel_m: 2.0,
            max_old_keyframes: 30,
            max_new_keyframes: 12,
            max_correction_m: 5.0,
            max_alignment_spread_m: 0.15,
            window_sigma_m: 0.005,
            loop_sigma_m: 0.005,
            odometry_sigma_m: 0.05,
            odometry_sigma_rad: 0.005,
        }
    }
}

impl FlightSettings {
    /// Checks the values; the error names the field.
    pub fn validate(&self) -> Result<(), CoreError> {
        let positive = [
            ("keyframe_step_m", self.keyframe_step_m),
            ("keyframe_step_deg", self.keyframe_step_deg),
            ("keyframe_voxel_m", self.keyframe_voxel_m),
            ("revisit_radius_m", self.revisit_radius_m),
            ("overlap_voxel_m", self.overlap_voxel_m),
            ("max_correction_m", self.max_correction_m),
            ("max_alignment_spread_m", self.max_alignment_spread_m),
            ("window_sigma_m", self.window_sigma_m),
            ("loop_sigma_m", self.loop_sigma_m),
            ("odometry_sigma_m", self.odometry_sigma_m),
            ("odometry_sigma_rad", self.odometry_sigma_rad),
        ];
        for (field, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(CoreError::InvalidConfig {
                    field,
                    value: value.to_string(),
                    reason: "must be finite and > 0",
                });
            }
        }
        if !(0.0..=1.0).contains(&self.revisit_min_overlap) {
            return Err(CoreError::InvalidConfig {
                field: "revisit_min_overlap",
                value: self.revisit_min_overlap.to_string(),
                reason: "must be in 0..=1",
            });
        }
        if self.max_old_keyframes == 0 || self.max_new_keyframes == 0 {
            return Err(CoreError::InvalidConfig {
                field: "max_old_keyframes",
                value: format!("{} / {}", self.max_old_keyframes, self.max_new_keyframes),
                reason: "max_old_keyframes and max_new_keyframes must be at least 1",
            });
        }
        Ok(())
    }
}

/// One window of the flight and what its revisit changed.
#[derive(Debug)]
pub struct FlightStep {
    /// The window; its `finals` carry the poses after any loop closure.
    pub outcome: WindowOutcome,
    /// The loop closure this window triggered, if any.
    pub closure: Option<LoopClosure>,
    /// The global pass, after the last window of a flight that closed a loop.
    pub global_pass: Option<GlobalPass>,
    /// Frames made final by earlier windows whose final pose the closure or the global pass
    /// moved, with their new poses (to publish again).
    pub revised: Vec<FinalFrame>,
}

/// The sliding windows of a whole flight, with keyframes and loop closure.
#[derive(Debug)]
pub struct FlightWindows {
    windows: SlidingWindows,
    settings: FlightSettings,
    keyframes: Keyframes,
    loop_edges: Vec<LoopEdge>,
    /// Last final frame: sequence, position and the distance flown to it (m).
    last_final: Option<(usize, nalgebra::Vector3<f64>, f64)>,
    /// Whether the last window ran with the motion prior (for the log).
    motion_prior_on: Option<bool>,
}

impl FlightWindows {
    /// An empty flight.
    pub fn new(spec: WindowSpec, settings: FlightSettings) -> Result<Self, CoreError> {
        settings.validate()?;
        Ok(Self {
            windows: SlidingWindows::new(spec)?,
            settings,
            keyframes: Keyframes::default(),
            loop_edges: Vec::new(),
            last_final: None,
            motion_prior_on: None,
        })
    }

    /// A flight that goes on after earlier windows (a process restarted after a crash): see
    /// [`SlidingWindows::resume`]. Keyframes start empty: places flown before the restart
    /// are not found again.
    pub fn resume(
        spec: WindowSpec,
        settings: FlightSettings,
        anchors: Vec<Isometry3<f64>>,
    ) -> Result<Self, CoreError> {
        let mut flight = Self::new(spec, settings)?;
        flight.windows = SlidingWindows::resume(spec, anchors)?;
        Ok(flight)
    }

    /// The sliding windows underneath (frames in, plans, final poses).
    pub fn windows(&self) -> &SlidingWindows {
        &self.windows
    }

    /// The sliding windows, to push frames and end the stream; windows run through
    /// [`Self::run_next`] (running them on this would skip the keyframes and loop closure).
    pub fn windows_mut(&mut self) -> &mut SlidingWindows {
        &mut self.windows
    }

    /// See [`SlidingWindows::push_frame`].
    pub fn push_frame(
        &mut self,
        stamp_s: f64,
        points: Vec<Point3<f64>>,
        initial: Isometry3<f64>,
    ) -> Result<usize, CoreError> {
        self.windows.push_frame(stamp_s, points, initial)
    }

    /// See [`SlidingWindows::push_moving_frame`].
    pub fn push_moving_frame(
        &mut self,
        stamp_s: f64,
        points: Vec<Point3<f64>>,
        times_s: Option<Vec<f32>>,
        initial: Isometry3<f64>,
    ) -> Result<usize, CoreError> {
        self.windows
            .push_moving_frame(stamp_s, points, times_s, initial)
    }

    /// See [`SlidingWindows::end_stream`].
    pub fn end_stream(&mut self) {
        self.windows.end_stream();
    }

    /// The keyframes, in stream order.
    pub fn keyframes(&self) -> &[Keyframe] {
        self.keyframes.all()
    }

    /// Keyframes kept, and the points they hold.
    pub fn keyframe_counts(&self) -> (usize, usize) {
        (self.keyframes.all().len(), self.keyframes.points())
    }

    /// Runs the next window with the per-scale solve in this process; the alignments run here
    /// too.
    pub fn run_next_local(
        &mut self,
        config: &PssBaConfig,
        parallelism: Parallelism,
    ) -> Option<FlightStep> {
        let config = self.window_config(config);
        let outcome = self.windows.run_next_local(&config, parallelism)?;
        Some(self.after_window(outcome, &config, parallelism))
    }

    /// `config` with this flight's motion prior, if the next window's initial poses look like
    /// odometry: what the next window runs with.
    pub fn window_config(&mut self, config: &PssBaConfig) -> PssBaConfig {
        let smooth = self.windows.next_plan().is_some_and(|plan| {
            let initial: Vec<Isometry3<f64>> = (plan.first..plan.end)
                .filter_map(|k| self.windows.initial_pose(k))
                .collect();
            let roughness_m = median_second_difference_m(&initial);
            let smooth = roughness_m.is_some_and(|r| r < self.settings.motion_prior.translation_m);
            if self.motion_prior_on != Some(smooth) && self.settings.motion_prior.is_on() {
                tracing::info!(
                    "window initial poses {} (median second difference of positions {}): \
                     motion prior {}",
                    if smooth {
                        "smooth, as odometry gives them"
                    } else {
                        "rough"
                    },
                    roughness_m.map_or("-".to_string(), |r| format!("{r:.3} m")),
                    if smooth { "on" } else { "off" }
                );
            }
            self.motion_prior_on = Some(smooth);
            smooth
        });
        PssBaConfig {
            motion_prior: if smooth {
                self.settings.motion_prior
            } else {
                MotionPrior::default()
            },
            ..config.clone()
        }
    }

    /// Runs the next window with `solve` (see [`SlidingWindows::run_next`]); the alignment of
    /// a revisit runs in this process.
    pub fn run_next<S>(
        &mut self,
        config: &PssBaConfig,
        parallelism: Parallelism,
        solve: S,
    ) -> Option<FlightStep>
    where
        S: FnMut(usize, &ProgressiveRun, &ScaleStep) -> Result<(Vec<Pose>, LmReport), SolveError>,
    {
        let config = self.window_config(config);
        let outcome = self.windows.run_next(&config, parallelism, solve)?;
        Some(self.after_window(outcome, &config, parallelism))
    }

    /// Keyframes from the window's new final frames, then the revisit check.
    fn after_window(
        &mut self,
        mut outcome: WindowOutcome,
        config: &PssBaConfig,
        parallelism: Parallelism,
    ) -> FlightStep {
        if !self.settings.enabled || outcome.finals.is_empty() {
            return FlightStep {
                outcome,
                closure: None,
                global_pass: None,
                revised: Vec::new(),
            };
        }
        let first_new = self.keyframes.all().len();
        self.add_keyframes(&outcome.finals);
        let closure = loop_closure::close(self, first_new, outcome.plan.first, config, parallelism);
        self.release_covered_clouds(first_new, outcome.plan.first);
        let global_pass = if self.windows.is_done() && self.settings.global_pass {
            loop_closure::global_pass(self)
        } else {
            None
        };
        let moved: std::collections::BTreeSet<usize> = closure
            .iter()
            .flat_map(|c| &c.moved)
            .chain(global_pass.iter().flat_map(|g| &g.moved))
            .copied()
            .collect();
        let mut revised = Vec::new();
        if !moved.is_empty() {
            let first_of_window = outcome.finals[0].sequence;
            for &sequence in &moved {
                let pose = self
                    .windows
                    .final_pose(sequence)
                    .expect("the closure moves final frames only");
                if sequence < first_of_window {
                    let stamp_s = self.windows.stamp_s(sequence);
                    revised.push(FinalFrame {
                        sequence,
                        stamp_s,
                        world_from_lidar: pose,
                    });
                }
            }
            for fin in &mut outcome.finals {
                fin.world_from_lidar = self
                    .windows
                    .final_pose(fin.sequence)
                    .unwrap_or(fin.world_from_lidar);
            }
        }
        FlightStep {
            outcome,
            closure,
            global_pass,
            revised,
        }
    }

    /// Frees the clouds of the window's new keyframes (from `first_new`) whose place an older
    /// keyframe with its cloud already holds: one before the window (`window_first`), flown
    /// at least `revisit_min_path_m` earlier, within `keyframe_step_m` and
    /// `keyframe_step_deg`. Later revisits align onto the older one; the clouds' memory grows
    /// with the ground covered, not with the time spent over it. Runs after the window's
    /// loop closure, which has used them; a flight that never comes back keeps every cloud.
    fn release_covered_clouds(&mut self, first_new: usize, window_first: usize) {
        let s = self.settings;
        let pose_of = |k: usize| self.windows.final_pose(k).expect("keyframes are final");
        let mut covered = Vec::new();
        let all = self.keyframes.all();
        for (n, keyframe) in all.iter().enumerate().skip(first_new) {
            let pose = pose_of(keyframe.sequence);
            let held = self
                .keyframes
                .near(&pose.translation.vector, s.keyframe_step_m)
                .into_iter()
                .any(|o| {
                    let old = &all[o];
                    !old.points.is_empty()
                        && old.sequence < window_first
                        && keyframe.path_m - old.path_m >= s.revisit_min_path_m
                        && pose_of(old.sequence).rotation.angle_to(&pose.rotation)
                            < s.keyframe_step_deg.to_radians()
                });
            if held {
                covered.push(n);
            }
        }
        for n in covered {
            self.keyframes.release_cloud(n);
        }
    }

    /// Makes keyframes of the window's new final frames: every `keyframe_step_m` or
    /// `keyframe_step_deg`, and always the last (so every final frame lies between two).
    fn add_keyframes(&mut self, finals: &[FinalFrame]) {
        for (i, fin) in finals.iter().enumerate() {
            let position = fin.world_from_lidar.translation.vector;
            let path_m = match self.last_final {
                Some((_, previous, path)) => path + (position - previous).norm(),
                None => 0.0,
            };
            self.last_final = Some((fin.sequence, position, path_m));
            let last_pose = self.keyframes.last().map(|last| {
                self.windows
                    .final_pose(last.sequence)
                    .expect("keyframes are final")
            });
            let due = last_pose.is_none_or(|last| {
                let moved = (last.translation.vector - position).norm();
                let turned = last.rotation.angle_to(&fin.world_from_lidar.rotation);
                moved >= self.settings.keyframe_step_m
                    || turned >= self.settings.keyframe_step_deg.to_radians()
                    || i + 1 == finals.len()
            });
            if due {
                let this = Pose::from_isometry(&fin.world_from_lidar);
                let from_previous =
                    last_pose.map(|last| pose_graph::relative(&Pose::from_isometry(&last), &this));
                self.keyframes.push(Keyframe::new(
                    fin.sequence,
                    path_m,
                    from_previous,
                    &self.windows.frame_points_deskewed(fin.sequence),
                    self.settings.keyframe_voxel_m,
                ));
            }
        }
        let windows = &self.windows;
        self.keyframes
            .reindex(|k| Pose::from_isometry(&windows.final_pose(k).expect("keyframes are final")));
    }
}

/// Median over frames of `|p_k+1 - 2 p_k + p_k-1|` (m), the positions' second difference:
/// millimetres to centimetres for odometry (a UAV accelerating at 2 m/s^2 moves 2 cm off a
/// straight line in 0.1 s), about 0.3 m for independent noise of 0.2 m per frame, where
/// the increments mean nothing and the motion prior would hold frames to noise (`pssba run`'s
/// built-in scene: APE 2.9 mm without it, 118 mm with). `None` under 3 poses.
fn median_second_difference_m(poses: &[Isometry3<f64>]) -> Option<f64> {
    let mut values: Vec<f64> = poses
        .windows(3)
        .map(|w| {
            let [a, b, c] = [0, 1, 2].map(|i| w[i].translation.vector);
            (c - 2.0 * b + a).norm()
        })
        .collect();
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    Some(values[values.len() / 2])
}

/// Everything a whole flight's windows produced.
#[derive(Debug)]
pub struct FlightResult {
    /// Final pose of every frame (after every closure).
    pub world_from_lidar: Vec<Isometry3<f64>>,
    /// Every window, in order (their `finals` with the poses after the window's own loop
    /// closure; later closures may have moved them again).
    pub windows: Vec<WindowOutcome>,
    /// The windows that failed.
    pub failures: Vec<FailedWindow>,
    /// The loop closures, in order.
    pub closures: Vec<LoopClosure>,
    /// The global pass after the last window, if one ran.
    pub global_pass: Option<GlobalPass>,
    /// Keyframes kept at the end, and their points.
    pub keyframes: (usize, usize),
}

impl FlightResult {
    /// The result as plain sliding windows report it.
    pub fn into_sliding(self) -> SlidingResult {
        SlidingResult {
            world_from_lidar: self.world_from_lidar,
            windows: self.windows,
            failures: self.failures,
        }
    }
}

/// Adjusts a whole flight in sliding windows with loop closure, in this process. `times`:
/// the frames' stamps and points' times, for frames taken while moving (`None`: every frame
/// at one instant, stamped by its index).
pub fn adjust_flight(
    frames: &[Vec<Point3<f64>>],
    world_from_lidar: &[Isometry3<f64>],
    times: Option<PointTimes<'_>>,
    config: &PssBaConfig,
    spec: WindowSpec,
    settings: FlightSettings,
    parallelism: Parallelism,
) -> Result<FlightResult, CoreError> {
    if frames.len() != world_from_lidar.len() {
        return Err(CoreError::CountMismatch {
            frames: frames.len(),
            poses: world_from_lidar.len(),
        });
    }
    config.validate()?;
    if let Some(times) = &times {
        let counts: Vec<usize> = frames.iter().map(Vec::len).collect();
        times.check(&counts)?;
    }
    let mut flight = FlightWindows::new(spec, settings)?;
    for (k, (points, pose)) in frames.iter().zip(world_from_lidar).enumerate() {
        let (stamp_s, times_s) = match &times {
            Some(t) => (t.stamps_s[k], Some(t.offsets_s[k].clone())),
            None => (k as f64, None),
        };
        flight.push_moving_frame(stamp_s, points.clone(), times_s, *pose)?;
    }
    flight.end_stream();
    let mut windows = Vec::new();
    let mut closures = Vec::new();
    let mut global_pass = None;
    while let Some(step) = flight.run_next_local(config, parallelism) {
        windows.push(step.outcome);
        closures.extend(step.closure);
        global_pass = global_pass.or(step.global_pass);
    }
    let world_from_lidar = flight
        .windows
        .final_poses()
        .into_iter()
        .map(|p| p.expect("the plan makes every frame final once the stream has ended"))
        .collect();
    Ok(FlightResult {
        world_from_lidar,
        windows,
        failures: flight.windows.failures().to_vec(),
        closures,
        global_pass,
        keyframes: flight.keyframe_counts(),
    })
}
