//! The progressive schedule as a step-by-step state machine (DESIGN step 9), so the smoothing
//! (steps 1-6) and the adjustment (steps 7-8) can run in different places: in one call
//! ([`crate::adjust_window`]) or in two processes exchanging factor blocks and poses.
//!
//! One scale: [`ProgressiveRun::next_step`] builds the cloud and the factor block at the current
//! poses; someone runs [`crate::lm::solve_block`] on it; [`ProgressiveRun::complete_step`] takes
//! the adjusted poses, records the scale report and decides whether to go on.

use crate::cloud::deskew::{FrameMotion, FrameTimes, PointTimes};
use crate::cloud::scale_cloud::{DownsampledFrames, ScaleCloud};
use crate::config::{Method, PssBaConfig};
use crate::error::CoreError;
use crate::factor::FactorBlock;
use crate::geometry::{Pose, pose_change_norm, translation_change_rms_m};
use crate::kernels::fit::SurfaceModel;
use crate::kernels::smoothed::{smoothed_cloud, world_surfaces};
use crate::kernels::smoothing::extract_block;
use crate::parallel::Parallelism;
use crate::result::{AdjustResult, PhaseTimes, ScaleReport};
use crate::solve::lm::{LmReport, LmSettings};
use nalgebra::{Isometry3, Point3, Vector3};
use std::time::Instant;

/// The last scale's cloud is moved to the new poses rather than built again (same
/// downsampling edge) unless more than [`REFRESH_MAX_FAR_FRACTION`] of its points lie farther
/// than this fraction of the edge from where they were when its voxels were made. One edge
/// (was half an edge): the cloud of the first scale that reaches the 0.2 m floor is then moved
/// at the next scale too, not rebuilt (bench APE within 2 % on every scene, 3 seeds; one cloud
/// build and neighbour search fewer, 3-4 % of a 100-frame run; BENCHMARK.md, 2026-12-04).
const REFRESH_MAX_DRIFT_PER_EDGE: f64 = 1.0;
/// See [`REFRESH_MAX_DRIFT_PER_EDGE`].
const REFRESH_MAX_FAR_FRACTION: f64 = 0.1;

/// Input of one window.
#[derive(Debug, Clone, Copy)]
pub struct Window<'a> {
    /// Points of each frame in its lidar frame (m).
    pub frames: &'a [Vec<Point3<f64>>],
    /// Initial world-from-lidar pose of each frame.
    pub world_from_lidar: &'a [Isometry3<f64>],
    /// Frames held fixed (the gauge). `None`: frame 0 only.
    pub fixed: Option<&'a [bool]>,
    /// Each point's time after its frame's stamp, for frames taken while the sensor moved:
    /// every scale then de-skews the points along its current poses (see
    /// [`crate::PointTimes`]). `None`: every frame taken at one instant (its stamp).
    pub times: Option<PointTimes<'a>>,
}

/// Gamma of scale `index` for the configured method.
fn gamma_of_scale(config: &PssBaConfig, index: usize) -> f64 {
    match config.method {
        Method::PssBaFs => config.fixed_gamma_m,
        Method::PssBa | Method::Point2plane => {
            (config.gamma0_m / config.gamma_shrink.powi(index as i32)).max(config.gamma_min_m)
        }
    }
}

/// One scale's work order: the block to solve and how to solve it.
#[derive(Debug, Clone)]
pub struct ScaleStep {
    /// Scale index (0 = coarsest).
    pub index: usize,
    /// Kernel width gamma (m).
    pub gamma_m: f64,
    /// Surfaces and residual points of this scale.
    pub block: FactorBlock,
    /// LM settings for this scale (the pose prior only on coarse scales).
    pub settings: LmSettings,
    /// Downsampled points in the window at this scale.
    pub cloud_points: usize,
    started: Instant,
    /// Cloud, normals and extraction times; the solve's is measured from `extracted`.
    times: PhaseTimes,
    extracted: Instant,
}

/// State of one window's progressive run.
#[derive(Debug)]
pub struct ProgressiveRun {
    config: PssBaConfig,
    model: SurfaceModel,
    /// The input points (finite ones), until the scales reach their finest downsampling.
    /// With point times: the points de-skewed at the latest scale's poses.
    frames: Vec<Vec<Vector3<f64>>>,
    /// The raw points and their times, for frames taken while moving.
    motion: Option<FrameMotion>,
    poses: Vec<Pose>,
    fixed: Vec<bool>,
    next_index: usize,
    /// Plain rounds still to run (`final_plain_rounds`), once the anchored schedule converged.
    plain_rounds_left: Option<usize>,
    done: bool,
    converged: bool,
    scales: Vec<ScaleReport>,
    pending_cloud: Option<ScaleCloud>,
    /// Per-frame downsampling of the latest scale, reused while its edge stays the same
    /// (every scale at or below `gamma_min_m` shares the `downsample_min_m` floor).
    downsampled: Option<DownsampledFrames>,
    /// The cloud of the latest scale (freed when the next one is built) and the surfaces of the
    /// last completed scale (its block without residual points): the run's outputs.
    last_cloud: Option<ScaleCloud>,
    last_surfaces: Option<FactorBlock>,
    dropped_nonfinite_points: usize,
    sparse_frames_held: Vec<usize>,
}

/// A window's finite points: taken at one instant each, or with their times.
enum FramesIn {
    Still(Vec<Vec<Vector3<f64>>>),
    Moving(FrameMotion),
}

/// Frames and poses must pair up, and a window needs two frames.
fn check_counts(frames: usize, poses: usize) -> Result<(), CoreError> {
    if frames != poses {
        return Err(CoreError::CountMismatch { frames, poses });
    }
    if frames < 2 {
        return Err(CoreError::TooFewFrames(frames));
    }
    Ok(())
}

/// All three coordinates finite.
fn is_finite(p: &Point3<f64>) -> bool {
    p.coords.iter().all(|v| v.is_finite())
}

impl ProgressiveRun {
    /// Validates the window and prepares the run: drops non-finite points, holds sparse frames
    /// fixed (their points left out), sets the gauge. The run keeps a copy of the points (see
    /// [`Self::new_owned`] to hand them over instead).
    pub fn new(window: Window<'_>, config: &PssBaConfig) -> Result<Self, CoreError> {
        config.validate()?;
        check_counts(window.frames.len(), window.world_from_lidar.len())?;
        let frames: Vec<Vec<Vector3<f64>>> = window
            .frames
            .iter()
            .map(|f| {
                // Sized exactly: a collect from a filter would grow by doubling (1000 frames
                // x 20k points: 790 MB held instead of 470).
                let mut kept: Vec<Vector3<f64>> = Vec::with_capacity(f.len());
                kept.extend(f.iter().filter(|p| is_finite(p)).map(|p| p.coords));
                kept
            })
            .collect();
        let total: usize = window.frames.iter().map(Vec::len).sum();
        if let Some(times) = window.times {
            let counts: Vec<usize> = window.frames.iter().map(Vec::len).collect();
            times.check(&counts)?;
        }
        // Every point at its frame's stamp (or no times): exactly the run without times.
        let moving = window.times.filter(PointTimes::any_moving);
        let Some(times) = moving else {
            return Self::with_finite_frames(
                FramesIn::Still(frames),
                total,
                window.world_from_lidar,
                window.fixed,
                config,
            );
        };
        let offsets_s = times.filtered(window.frames, is_finite);
        let motion = FrameMotion::new(frames, offsets_s, times.stamps_s.to_vec());
        Self::with_finite_frames(
            FramesIn::Moving(motion),
            total,
            window.world_from_lidar,
            window.fixed,
            config,
        )
    }

    /// [`Self::new`] on points handed over: they are filtered in their own buffers, not
    /// copied (1000 frames x 20k points: 470 MB less), and freed once the scales no longer
    /// need them.
    pub fn new_owned(
        frames: Vec<Vec<Point3<f64>>>,
        world_from_lidar: &[Isometry3<f64>],
        fixed: Option<&[bool]>,
        times: Option<FrameTimes>,
        config: &PssBaConfig,
    ) -> Result<Self, CoreError> {
        config.validate()?;
        check_counts(frames.len(), world_from_lidar.len())?;
        let total: usize = frames.iter().map(Vec::len).sum();
        if let Some(times) = &times {
            let counts: Vec<usize> = frames.iter().map(Vec::len).collect();
            times.view().check(&counts)?;
        }
        let moving = times
            .filter(|t| t.view().any_moving())
            .map(|t| (t.view().filtered(&frames, is_finite), t.stamps_s));
        let frames = frames
            .into_iter()
            .map(|f| f.into_iter().filter(is_finite).map(|p| p.coords).collect())
            .collect();
        let frames_in = match moving {
            Some((offsets_s, stamps_s)) => {
                FramesIn::Moving(FrameMotion::new(frames, offsets_s, stamps_s))
            }
            None => FramesIn::Still(frames),
        };
        Self::with_finite_frames(frames_in, total, world_from_lidar, fixed, config)
    }

    /// The rest of [`Self::new`], from the finite points of `points_in` input points.
    fn with_finite_frames(
        frames_in: FramesIn,
        points_in: usize,
        world_from_lidar: &[Isometry3<f64>],
        fixed: Option<&[bool]>,
        config: &PssBaConfig,
    ) -> Result<Self, CoreError> {
        let (mut frames, mut motion) = match frames_in {
            FramesIn::Still(frames) => (frames, None),
            FramesIn::Moving(motion) => (Vec::new(), Some(motion)),
        };
        let counts: Vec<usize> = match &motion {
            Some(m) => m.point_counts(),
            None => frames.iter().map(Vec::len).collect(),
        };
        let n = counts.len();
        let poses: Vec<Pose> = world_from_lidar.iter().map(Pose::from_isometry).collect();
        if let Some(frame) = poses.iter().position(|p| !p.is_finite()) {
            return Err(CoreError::NonFinitePose { frame });
        }
        let dropped_nonfinite_points = points_in - counts.iter().sum::<usize>();
        if dropped_nonfinite_points > 0 {
            tracing::warn!(
                dropped_nonfinite_points,
                "dropped points with NaN or infinite coordinates"
            );
        }
        let mut fixed: Vec<bool> = match fixed {
            Some(mask) if mask.len() == n => mask.to_vec(),
            Some(mask) => {
                return Err(CoreError::FixedMaskLength {
                    frames: n,
                    mask: mask.len(),
                });
            }
            None => (0..n).map(|k| k == 0).collect(),
        };
        let sparse_frames_held: Vec<usize> = (0..n)
            .filter(|&k| !fixed[k] && counts[k] < config.min_points_per_frame)
            .collect();
        for &k in &sparse_frames_held {
            tracing::warn!(
                frame = k,
                points = counts[k],
                "frame has too few points; holding it fixed and leaving its points out"
            );
            fixed[k] = true;
            // Held at a pose nobody checked, its points would anchor the others to it.
            if let Some(frame) = frames.get_mut(k) {
                frame.clear();
            }
            if let Some(motion) = motion.as_mut() {
                motion.clear_frame(k);
            }
        }
        if fixed.iter().all(|&f| f) {
            return Err(CoreError::NothingToAdjust);
        }
        let model = match config.method {
            Method::Point2plane => SurfaceModel::Planar,
            Method::PssBa | Method::PssBaFs => SurfaceModel::Quadratic,
        };
        Ok(Self {
            config: config.clone(),
            model,
            frames,
            motion,
            poses,
            fixed,
            next_index: 0,
            plain_rounds_left: None,
            done: false,
            converged: false,
            scales: Vec::new(),
            pending_cloud: None,
            downsampled: None,
            last_cloud: None,
            last_surfaces: None,
            dropped_nonfinite_points,
            sparse_frames_held,
        })
    }

    /// Current poses (world from lidar).
    pub fn poses(&self) -> &[Pose] {
        &self.poses
    }

    /// Frames held fixed (gauge, anchors, sparse frames).
    pub fn fixed(&self) -> &[bool] {
        &self.fixed
    }

    /// Reports of the scales completed so far.
    pub fn scales(&self) -> &[ScaleReport] {
        &self.scales
    }

    /// Builds the next scale's factor block at the current poses; `Ok(None)` when the schedule
    /// has ended (converged, `max_scales` reached or a scale without constraints).
    pub fn next_step(&mut self, parallelism: Parallelism) -> Result<Option<ScaleStep>, CoreError> {
        let plain = self.plain_rounds_left.is_some();
        if self.done || (!plain && self.next_index >= self.config.max_scales) {
            self.done = true;
            return Ok(None);
        }
        let index = self.next_index;
        let started = Instant::now();
        let gamma_m = if plain {
            self.finest_gamma_m()
        } else {
            gamma_of_scale(&self.config, index)
        };
        let _span = tracing::info_span!("scale", index, gamma_m).entered();
        let downsample_m = self.config.downsample_m(gamma_m);
        // The last scale's cloud goes before this one's is built (two at once: 0.5 GB more at
        // 1000 frames); its surfaces stay for the outputs, over whichever cloud is newest.
        // Where it has the same points and they moved little since it was built, it is moved
        // to the current poses instead (see `ScaleCloud::refresh`).
        let max_drift_m = REFRESH_MAX_DRIFT_PER_EDGE * downsample_m;
        let last = self
            .last_cloud
            .take()
            // Points that move with the poses (de-skewed) are never moved as a block.
            .filter(|last| last.downsample_m == downsample_m && self.motion.is_none());
        let last = last.and_then(|mut last| {
            let moved = last.refresh(
                &self.poses,
                max_drift_m,
                REFRESH_MAX_FAR_FRACTION,
                parallelism,
            );
            // Refused: freed before the new one is built.
            moved.then_some(last)
        });
        if let Some(motion) = &self.motion {
            // The points move with the poses: de-skewed afresh, downsampled afresh.
            self.frames = motion.deskewed(&self.poses, parallelism);
            self.downsampled = None;
        }
        let cloud = match last {
            Some(moved) => moved,
            None => {
                let downsampled = match self.downsampled.take() {
                    Some(d) if d.voxel_m == downsample_m => d,
                    _ => DownsampledFrames::new(&self.frames, downsample_m, parallelism),
                };
                if self.motion.is_some()
                    || downsample_m == self.config.downsample_m(self.finest_gamma_m())
                {
                    // Every later scale downsamples with this edge, so it keeps these points:
                    // the input's copy (24 bytes a point, 470 MB for 1000 frames of 20k) goes.
                    self.frames = Vec::new();
                }
                ScaleCloud::from_downsampled(
                    self.downsampled.insert(downsampled),
                    &self.poses,
                    self.config.normal_neighbours,
                    parallelism,
                )
            }
        };
        let cloud_s = started.elapsed().as_secs_f64();
        let extract_started = Instant::now();
        // A plain round fits the paper's consensus surfaces, without anchor offsets (see
        // `PssBaConfig::final_plain_rounds`).
        let plain_config;
        let config = if plain {
            plain_config = PssBaConfig {
                anchor_offset_to_kernel_frame: false,
                ..self.config.clone()
            };
            &plain_config
        } else {
            &self.config
        };
        let block = extract_block(
            &cloud,
            &self.poses,
            gamma_m,
            self.model,
            config,
            parallelism,
        );
        let times = PhaseTimes {
            cloud_s: cloud_s - cloud.normals_s,
            normals_s: cloud.normals_s,
            extract_s: extract_started.elapsed().as_secs_f64(),
            solve_s: 0.0,
        };
        tracing::debug!(?times, "smoothing times");
        if block.points.is_empty() {
            if index == 0 {
                return Err(CoreError::NoConstraints {
                    gamma_m,
                    kernels_rejected: block.rejected.total(),
                });
            }
            tracing::warn!(gamma_m, "no usable constraint at this scale; stopping");
            // The outputs: the last surfaces over this scale's cloud (the same points).
            self.last_cloud = Some(cloud);
            self.done = true;
            return Ok(None);
        }
        let settings = self.lm_settings(gamma_m);
        let cloud_points = cloud.len();
        self.pending_cloud = Some(cloud);
        Ok(Some(ScaleStep {
            index,
            gamma_m,
            block,
            settings,
            cloud_points,
            started,
            times,
            extracted: Instant::now(),
        }))
    }

    /// LM settings at `gamma_m`. Coarse scales only carry the pose prior: their surfaces are
    /// crude and extrapolate; a frame that slid along them went 2 m astray (40 frames, seed 2),
    /// while a prior on every scale slowed the fine ones (20 frames: APE 0.0023 m without, up
    /// to 0.037 m with).
    fn lm_settings(&self, gamma_m: f64) -> LmSettings {
        let coarse = self.config.is_coarse(gamma_m);
        let prior = |sigma: f64| if coarse { sigma } else { f64::INFINITY };
        let on = self.config.motion_prior.is_on();
        let motion = |sigma: f64| if on { sigma } else { f64::INFINITY };
        LmSettings {
            max_iterations: self.config.lm_max_iterations,
            initial_lambda: self.config.lm_initial_lambda,
            prior_translation_m: prior(self.config.prior_translation_m),
            prior_rotation_rad: prior(self.config.prior_rotation_rad),
            motion_translation_m: motion(self.config.motion_prior.translation_m),
            motion_rotation_rad: motion(self.config.motion_prior.rotation_rad),
        }
    }

    /// Takes the adjusted poses of `step` (from [`crate::lm::solve_block`] on its block, with
    /// [`Self::poses`] and [`Self::fixed`]) and records the scale. A wrong pose count or a
    /// non-finite pose is refused and leaves the run unchanged.
    pub fn complete_step(
        &mut self,
        step: ScaleStep,
        adjusted: Vec<Pose>,
        lm: &LmReport,
    ) -> Result<&ScaleReport, CoreError> {
        if adjusted.len() != self.poses.len() {
            return Err(CoreError::CountMismatch {
                frames: self.poses.len(),
                poses: adjusted.len(),
            });
        }
        if let Some(frame) = adjusted.iter().position(|p| !p.is_finite()) {
            return Err(CoreError::NonFinitePose { frame });
        }
        let pose_change = pose_change_norm(&self.poses, &adjusted);
        let free: Vec<bool> = self.fixed.iter().map(|f| !f).collect();
        let move_rms_m = translation_change_rms_m(&self.poses, &adjusted, &free);
        self.poses = adjusted;
        let report = ScaleReport {
            gamma_m: step.gamma_m,
            cloud_points: step.cloud_points,
            kernels_used: step.block.surfaces.len(),
            kernels_rejected: step.block.rejected,
            residuals: lm.residuals,
            cost_before: lm.cost_before,
            cost_after: lm.cost_after,
            iterations: lm.iterations,
            pose_change,
            unconstrained_frames: lm.unconstrained_frames,
            wall_time_s: step.started.elapsed().as_secs_f64(),
            times: PhaseTimes {
                solve_s: step.extracted.elapsed().as_secs_f64(),
                ..step.times
            },
        };
        tracing::debug!(?report, move_rms_m, "scale done");
        if let Some(cloud) = self.pending_cloud.take() {
            // The outputs need the surfaces only: the residual points (40 bytes each, 17.6
            // million at the finest scale of 1000 frames) are freed before the next scale.
            let mut block = step.block;
            block.points = Vec::new();
            self.last_cloud = Some(cloud);
            self.last_surfaces = Some(block);
        }
        self.next_index = step.index + 1;
        // The paper's test (T_conv on the stacked change), or: at the finest width, the frames
        // have stopped moving, so a repeat would re-fit the same surfaces.
        let finest =
            self.config.method != Method::PssBaFs && step.gamma_m <= self.config.gamma_min_m;
        let settled = finest && move_rms_m < self.config.min_repeat_move_per_gamma * step.gamma_m;
        if let Some(left) = self.plain_rounds_left.as_mut() {
            *left -= 1;
            self.done = *left == 0;
        } else if pose_change < self.config.convergence_threshold || settled {
            self.converged = true;
            // The plain rounds, if any, follow at the finest width.
            let rounds = self.config.final_plain_rounds;
            self.plain_rounds_left = (rounds > 0).then_some(rounds);
            self.done = rounds == 0;
        }
        self.scales.push(report);
        Ok(self.scales.last().expect("just pushed"))
    }

    /// The smallest kernel width the schedule can reach.
    fn finest_gamma_m(&self) -> f64 {
        match self.config.method {
            Method::PssBaFs => self.config.fixed_gamma_m,
            Method::PssBa | Method::Point2plane => self.config.gamma_min_m,
        }
    }

    /// The result at the current poses: surfaces and smoothed cloud of the last completed scale.
    pub fn finish(self, parallelism: Parallelism) -> AdjustResult {
        let started = Instant::now();
        let cloud = self.last_cloud.as_ref().or(self.pending_cloud.as_ref());
        let (surfaces, smoothed) = match (cloud, &self.last_surfaces) {
            (Some(cloud), Some(block)) => (
                world_surfaces(block, &self.poses),
                smoothed_cloud(cloud, block, &self.poses, parallelism),
            ),
            (None, Some(block)) => (world_surfaces(block, &self.poses), Vec::new()),
            (_, None) => (Vec::new(), Vec::new()),
        };
        AdjustResult {
            world_from_lidar: self.poses.iter().map(Pose::to_isometry).collect(),
            surfaces,
            smoothed_cloud: smoothed,
            scales: self.scales,
            converged: self.converged,
            plain_rounds: (self.plain_rounds_left)
                .map_or(0, |left| self.config.final_plain_rounds - left),
            dropped_nonfinite_points: self.dropped_nonfinite_points,
            sparse_frames_held: self.sparse_frames_held,
            finish_s: started.elapsed().as_secs_f64(),
        }
    }
}
