//! One benchmark case: simulate a scene with one seed, then run every method on the same
//! frames and initial poses and measure APE, occupancy and wall time.

use nalgebra::{Isometry3, Point3};
use pssba_config::Config;
use pssba_core::{Method, Parallelism};
use pssba_sim::{Mid360, Scene, SimulatedDataset, SimulationSpec};
use std::time::Instant;

/// The paper's Table I rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BenchMethod {
    /// The perturbed input poses.
    Initial,
    /// The BALM baseline (pssba-balm).
    Balm,
    /// Planar kernels (pssba-core).
    Point2plane,
    /// Fixed kernel width (pssba-core).
    PssBaFs,
    /// Progressive spatial smoothing (pssba-core).
    PssBa,
}

impl BenchMethod {
    /// Every row, in the paper's order.
    pub const ALL: [BenchMethod; 5] = [
        Self::Initial,
        Self::Balm,
        Self::Point2plane,
        Self::PssBaFs,
        Self::PssBa,
    ];

    /// Name in JSON and file names.
    pub fn name(self) -> &'static str {
        match self {
            Self::Initial => "initial",
            Self::Balm => "balm",
            Self::Point2plane => "point2plane",
            Self::PssBaFs => "pss-ba-fs",
            Self::PssBa => "pss-ba",
        }
    }

    /// Row label as in the paper.
    pub fn label(self) -> &'static str {
        match self {
            Self::Initial => "Initial",
            Self::Balm => "BALM",
            Self::Point2plane => "Point2Plane",
            Self::PssBaFs => "PSS-BA(FS)",
            Self::PssBa => "PSS-BA",
        }
    }
}

/// Voxel edge of the occupancy metric (m), DESIGN.md section 4.
pub const VOXEL_M: f64 = 0.1;
/// Grid offsets the occupancy is averaged over (as `pssba eval occupancy`).
pub const OFFSETS: usize = 8;
/// Seed of the grid offsets (`pssba eval occupancy`'s default, so its numbers match).
pub const OFFSET_SEED: u64 = 0;

/// What one method did on one case.
#[derive(Debug, Clone)]
pub struct Measurement {
    /// The row.
    pub method: BenchMethod,
    /// APE (m), `None` when the method failed.
    pub ape_m: Option<f64>,
    /// Mean occupied voxels, `None` when the method failed.
    pub occupancy: Option<f64>,
    /// Wall time of the method (s); `None` for Initial.
    pub time_s: Option<f64>,
    /// The error, when the method failed.
    pub error: Option<String>,
    /// The poses it returned (empty when it failed).
    pub world_from_lidar: Vec<Isometry3<f64>>,
}

/// Simulates `scene` with `seed`: `frames` frames of `rays` rays, pose noise 0.2 m / 1 deg.
pub fn simulate(
    scene: &Scene,
    frames: usize,
    rays: usize,
    seed: u64,
) -> anyhow::Result<SimulatedDataset> {
    let spec = SimulationSpec {
        frames,
        seed,
        sensor: Mid360 {
            rays_per_frame: rays,
            ..Mid360::default()
        },
        ..SimulationSpec::default()
    };
    Ok(pssba_sim::simulate_scene(scene, &spec)?)
}

/// Runs one method; an error from the method is recorded, not returned.
fn run_method(
    method: BenchMethod,
    data: &SimulatedDataset,
    settings: &Config,
) -> Result<(Vec<Isometry3<f64>>, Option<f64>), String> {
    let core = |m: Method| {
        let config = pssba_core::PssBaConfig {
            method: m,
            ..settings.algorithm.clone()
        };
        let started = Instant::now();
        let result = pssba_core::adjust(&data.frames, &data.initial, &config);
        let time_s = started.elapsed().as_secs_f64();
        result
            .map(|r| (r.world_from_lidar, Some(time_s)))
            .map_err(|e| e.to_string())
    };
    match method {
        BenchMethod::Initial => Ok((data.initial.clone(), None)),
        BenchMethod::Balm => {
            let started = Instant::now();
            let result = pssba_balm::adjust(
                &data.frames,
                &data.initial,
                &settings.balm,
                Parallelism::Rayon,
            );
            let time_s = started.elapsed().as_secs_f64();
            result
                .map(|r| (r.world_from_lidar, Some(time_s)))
                .map_err(|e| e.to_string())
        }
        BenchMethod::Point2plane => core(Method::Point2plane),
        BenchMethod::PssBaFs => core(Method::PssBaFs),
        BenchMethod::PssBa => core(Method::PssBa),
    }
}

/// APE and occupancy of `poses`; a metric that cannot be computed (e.g. non-finite poses
/// from a diverged method) is an error too.
fn metrics(
    frames: &[Vec<Point3<f64>>],
    ground_truth: &[Isometry3<f64>],
    poses: &[Isometry3<f64>],
) -> Result<(f64, f64), String> {
    let ape =
        pssba_eval::ape_translation_paired(ground_truth, poses).map_err(|e| format!("APE: {e}"))?;
    let occupancy = pssba_eval::occupancy_of_frames(frames, poses, VOXEL_M, OFFSETS, OFFSET_SEED)
        .map_err(|e| format!("occupancy: {e}"))?;
    Ok((ape.rmse_m, occupancy.mean_voxels))
}

/// Runs `method` on the case and measures it.
pub fn measure(method: BenchMethod, data: &SimulatedDataset, settings: &Config) -> Measurement {
    let outcome = run_method(method, data, settings).and_then(|(poses, time_s)| {
        let (ape_m, occupancy) = metrics(&data.frames, &data.ground_truth, &poses)?;
        Ok((poses, time_s, ape_m, occupancy))
    });
    match outcome {
        Ok((world_from_lidar, time_s, ape_m, occupancy)) => Measurement {
            method,
            ape_m: Some(ape_m),
            occupancy: Some(occupancy),
            time_s,
            error: None,
            world_from_lidar,
        },
        Err(error) => Measurement {
            method,
            ape_m: None,
            occupancy: None,
            time_s: None,
            error: Some(error),
            world_from_lidar: Vec::new(),
        },
    }
}
