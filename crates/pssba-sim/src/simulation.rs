//! The file-free entry point benchmarks and `pssba simulate` call (DESIGN.md sections 4-5):
//! fly a trajectory through a scene, ray-cast one Mid-360 frame per pose, perturb the poses.

use crate::{
    Mid360, RaycastError, Raycaster, Scene, TrajectoryKind, TrajectorySpec, perturb_poses,
};
use nalgebra::{Isometry3, Point3};
use rand::{SeedableRng, rngs::StdRng};

/// RMS of the Gaussian noise on the initial poses; `Default` is DESIGN.md section 4's
/// 0.2 m and 1 deg (per-axis sigma 0.2/sqrt(3) m and 1/sqrt(3) deg).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseNoise {
    /// Translation RMS (m).
    pub translation_rms_m: f64,
    /// Rotation RMS (deg).
    pub rotation_rms_deg: f64,
}

impl Default for PoseNoise {
    fn default() -> Self {
        Self {
            translation_rms_m: 0.2,
            rotation_rms_deg: 1.0,
        }
    }
}

/// What to simulate in a [`Scene`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimulationSpec {
    /// Number of frames (10 Hz by default).
    pub frames: usize,
    /// Seed of the range noise and of the pose noise; equal seeds give identical output.
    pub seed: u64,
    /// Path shape flown over the scene's default geometry; `None` keeps the scene's kind.
    pub trajectory: Option<TrajectoryKind>,
    /// Noise on the initial poses.
    pub pose_noise: PoseNoise,
    /// Sensor model.
    pub sensor: Mid360,
    /// Cast rays on rayon's current pool (identical result to the serial cast).
    pub parallel: bool,
    /// Each ray leaves from the true pose at its own time ([`Mid360::scan_moving`]) and the
    /// dataset carries every point's time; `false`: still frames, every ray from the frame's
    /// pose (no motion within a frame).
    pub motion_within_frames: bool,
}

impl Default for SimulationSpec {
    fn default() -> Self {
        Self {
            frames: 100,
            seed: 0,
            trajectory: None,
            pose_noise: PoseNoise::default(),
            sensor: Mid360::default(),
            parallel: true,
            motion_within_frames: false,
        }
    }
}

/// A simulated sequence, ready for `pssba_io::Dataset::write` or straight for the adjuster.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulatedDataset {
    /// Points of each frame in its lidar frame (m).
    pub frames: Vec<Vec<Point3<f64>>>,
    /// True `world_from_lidar` poses.
    pub ground_truth: Vec<Isometry3<f64>>,
    /// Initial `world_from_lidar` poses: the ground truth with seeded noise.
    pub initial: Vec<Isometry3<f64>>,
    /// Frame stamps (s): `k / frame_rate_hz`, the time of the frame's first ray and of its
    /// ground-truth pose.
    pub stamps: Vec<f64>,
    /// With motion within frames: each point's time after its frame's stamp (s), parallel to
    /// `frames`. `None` for still frames.
    pub point_times_s: Option<Vec<Vec<f32>>>,
    /// The trajectory actually flown.
    pub trajectory: TrajectorySpec,
}

/// Why a simulation cannot run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimulationError {
    /// Zero frames were asked for.
    #[error("frames must be at least 1")]
    NoFrames,
    /// A parameter is out of its range.
    #[error("{name} is {value}, expected {expected}")]
    BadParameter {
        /// The parameter.
        name: &'static str,
        /// Its value.
        value: f64,
        /// The valid range.
        expected: &'static str,
    },
    /// The scene mesh cannot be ray-cast.
    #[error("scene mesh: {0}")]
    Mesh(#[from] RaycastError),
}

/// Checks the numeric parameters, naming the first bad one.
fn validate(spec: &SimulationSpec) -> Result<(), SimulationError> {
    if spec.frames == 0 {
        return Err(SimulationError::NoFrames);
    }
    let s = &spec.sensor;
    let checks = [
        (
            "rays_per_frame",
            s.rays_per_frame as f64,
            s.rays_per_frame > 0,
            "at least 1",
        ),
        (
            "frame_rate_hz",
            s.frame_rate_hz,
            s.frame_rate_hz > 0.0 && s.frame_rate_hz.is_finite(),
            "> 0",
        ),
        ("min_range_m", s.min_range_m, s.min_range_m >= 0.0, ">= 0"),
        (
            "max_range_m",
            s.max_range_m,
            s.max_range_m > s.min_range_m && s.max_range_m.is_finite(),
            "finite and > min_range_m",
        ),
        (
            "range_noise_m",
            s.range_noise_m,
            s.range_noise_m >= 0.0 && s.range_noise_m.is_finite(),
            "finite and >= 0",
        ),
        (
            "translation_rms_m",
            spec.pose_noise.translation_rms_m,
            spec.pose_noise.translation_rms_m >= 0.0
                && spec.pose_noise.translation_rms_m.is_finite(),
            "finite and >= 0",
        ),
        (
            "rotation_rms_deg",
            spec.pose_noise.rotation_rms_deg,
            spec.pose_noise.rotation_rms_deg >= 0.0 && spec.pose_noise.rotation_rms_deg.is_finite(),
            "finite and >= 0",
        ),
    ];
    match checks.into_iter().find(|c| !c.2) {
        Some((name, value, _, expected)) => Err(SimulationError::BadParameter {
            name,
            value,
            expected,
        }),
        None => Ok(()),
    }
}

/// Seed of frame `frame`'s range noise, decorrelated from neighbouring frames and seeds.
fn frame_seed(seed: u64, frame: usize) -> u64 {
    seed.wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (frame as u64)
            .wrapping_add(1)
            .wrapping_mul(0xBF58_476D_1CE4_E5B9)
}

/// Frames of a scene one at a time, for flights too long to hold in memory: frame `k` at a
/// pose is exactly frame `k` of [`simulate_scene`] with the same spec at that pose.
pub struct SceneScanner {
    caster: Raycaster,
    spec: SimulationSpec,
}

impl std::fmt::Debug for SceneScanner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SceneScanner")
            .field("spec", &self.spec)
            .finish_non_exhaustive()
    }
}

impl SceneScanner {
    /// A scanner of `scene` with `spec`'s sensor, seed and parallelism (checked as
    /// [`simulate_scene`] checks them).
    pub fn new(scene: &Scene, spec: &SimulationSpec) -> Result<Self, SimulationError> {
        validate(spec)?;
        Ok(Self {
            caster: Raycaster::new(&scene.mesh)?,
            spec: *spec,
        })
    }

    /// Frame `k` taken while moving along `world_from_lidar_at` (a function of the time
    /// in s): lidar-frame points and each point's time after the frame's stamp (s).
    pub fn frame_moving(
        &self,
        k: usize,
        world_from_lidar_at: &(dyn Fn(f64) -> Isometry3<f64> + Sync),
    ) -> (Vec<Point3<f64>>, Vec<f32>) {
        let mut rng = StdRng::seed_from_u64(frame_seed(self.spec.seed, k));
        self.spec.sensor.scan_moving(
            &self.caster,
            world_from_lidar_at,
            k,
            &mut rng,
            self.spec.parallel,
        )
    }

    /// Frame `k` taken at `world_from_lidar` (lidar-frame points, m).
    pub fn frame(&self, k: usize, world_from_lidar: &Isometry3<f64>) -> Vec<Point3<f64>> {
        let mut rng = StdRng::seed_from_u64(frame_seed(self.spec.seed, k));
        self.spec.sensor.scan(
            &self.caster,
            world_from_lidar,
            k,
            &mut rng,
            self.spec.parallel,
        )
    }
}

/// [`simulate_scene_with_progress`] without progress reports.
pub fn simulate_scene(
    scene: &Scene,
    spec: &SimulationSpec,
) -> Result<SimulatedDataset, SimulationError> {
    simulate_scene_with_progress(scene, spec, |_, _| {})
}

/// Simulates `spec.frames` frames of `scene`: ground truth from the scene's trajectory
/// (kind overridden by `spec.trajectory`), one Mid-360 frame per pose (taken at that pose,
/// or moving through the frame with `spec.motion_within_frames`), initial poses from [`perturb_poses`]. Calls
/// `progress(frames_done, frames)` after each frame. Deterministic for a given spec.
pub fn simulate_scene_with_progress(
    scene: &Scene,
    spec: &SimulationSpec,
    mut progress: impl FnMut(usize, usize),
) -> Result<SimulatedDataset, SimulationError> {
    let scanner = SceneScanner::new(scene, spec)?;
    let trajectory = spec
        .trajectory
        .map_or(scene.trajectory, |kind| scene.trajectory.with_kind(kind));
    let rate = spec.sensor.frame_rate_hz;
    let ground_truth = trajectory.world_from_lidar(spec.frames, rate);
    let mut frames = Vec::with_capacity(spec.frames);
    let mut point_times_s = Vec::new();
    let total_s = TrajectorySpec::duration_s(spec.frames, rate);
    let pose_at = |t_s: f64| trajectory.pose_at(t_s, total_s);
    for (k, world_from_lidar) in ground_truth.iter().enumerate() {
        if spec.motion_within_frames {
            let (points, times_s) = scanner.frame_moving(k, &pose_at);
            frames.push(points);
            point_times_s.push(times_s);
        } else {
            frames.push(scanner.frame(k, world_from_lidar));
        }
        progress(k + 1, spec.frames);
    }
    let noise = spec.pose_noise;
    let initial = perturb_poses(
        &ground_truth,
        noise.translation_rms_m,
        noise.rotation_rms_deg,
        spec.seed ^ 0x0005_EED0_F0F0_5E5E,
    );
    Ok(SimulatedDataset {
        frames,
        stamps: (0..spec.frames).map(|k| k as f64 / rate).collect(),
        point_times_s: spec.motion_within_frames.then_some(point_times_s),
        ground_truth,
        initial,
        trajectory,
    })
}
