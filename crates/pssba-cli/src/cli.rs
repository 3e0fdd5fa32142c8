//! Command-line definitions (clap derive).

use clap::{Args, Parser, Subcommand, ValueEnum};
use pssba_core::Method;
use std::path::PathBuf;

/// LiDAR bundle adjustment with progressive spatial smoothing (PSS-BA).
///
/// A window of LiDAR frames with rough poses goes in; polynomial smoothing kernels fitted at a
/// kernel width that shrinks each scale (3 m, then /1.4) give point-to-surface constraints;
/// Levenberg-Marquardt corrects all poses. Datasets are folders with frames/*.pcd (points in
/// the sensor frame), poses.txt (TUM, world from lidar) and optionally gt.txt.
#[derive(Debug, Parser)]
#[command(name = "pssba", version, propagate_version = true)]
pub struct Cli {
    /// More log output (-v: debug, -vv: trace). RUST_LOG overrides.
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub verbose: u8,
    /// Only warnings and errors on stderr.
    #[arg(short, long, global = true)]
    pub quiet: bool,
    #[command(subcommand)]
    pub command: Command,
}

/// Subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Adjust the poses of a dataset folder.
    Adjust(AdjustArgs),
    /// Evaluate trajectories or maps.
    #[command(subcommand)]
    Eval(EvalCommand),
    /// Run the built-in simulated curved scene through the pipeline and print APE before and
    /// after (the main job, needs no data).
    Demo(DemoArgs),
}

/// The method variants as command-line values.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum MethodArg {
    /// Progressive spatial smoothing (the paper's method).
    #[value(name = "pss-ba")]
    PssBa,
    /// Fixed kernel width (ablation).
    #[value(name = "pss-ba-fs")]
    PssBaFs,
    /// Planar kernels on the progressive schedule (ablation).
    #[value(name = "point2plane")]
    Point2plane,
    /// The BALM baseline (Liu et al. 2023, BALM2): adaptive-voxel eigenvalue bundle
    /// adjustment; its settings come from the config file's `[balm]` table.
    #[value(name = "balm")]
    Balm,
}

impl MethodArg {
    /// The pssba-core variant, `None` for BALM (a separate crate, dispatched by the CLI).
    pub fn core_method(self) -> Option<Method> {
        match self {
            MethodArg::PssBa => Some(Method::PssBa),
            MethodArg::PssBaFs => Some(Method::PssBaFs),
            MethodArg::Point2plane => Some(Method::Point2plane),
            MethodArg::Balm => None,
        }
    }
}

/// `pssba adjust`.
#[derive(Debug, Args)]
pub struct AdjustArgs {
    /// Dataset folder (frames/*.pcd, poses.txt, optional gt.txt).
    pub dir: PathBuf,
    /// Method; overrides the config file's `method`.
    #[arg(long, value_enum)]
    pub method: Option<MethodArg>,
    /// TOML config (see config/default.toml); missing keys take the defaults.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Where to write the optimised poses (TUM, same stamps as poses.txt).
    /// Default: DIR/poses_<method>.txt.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also write the smoothed cloud (world frame) as binary PLY; with `--method balm`, the
    /// merged input cloud at BALM's poses.
    #[arg(long)]
    pub map: Option<PathBuf>,
    /// Print a machine-readable summary (JSON) on stdout.
    #[arg(long)]
    pub json: bool,
}

/// `pssba eval ...`.
#[derive(Debug, Subcommand)]
pub enum EvalCommand {
    /// Translation APE (RMSE after SE(3) Umeyama alignment), as `evo_ape tum GT EST -a`.
    Ape(ApeArgs),
    /// Occupied voxels of the merged cloud (fewer = sharper), averaged over grid offsets.
    Occupancy(OccupancyArgs),
}

/// `pssba eval ape`.
#[derive(Debug, Args)]
pub struct ApeArgs {
    /// Reference trajectory (TUM).
    pub gt: PathBuf,
    /// Estimated trajectory (TUM).
    pub est: PathBuf,
    /// Largest stamp difference (s) for two poses to be associated (evo's --t_max_diff).
    #[arg(long, default_value_t = 0.01)]
    pub max_diff: f64,
    /// Print JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// `pssba eval occupancy`.
#[derive(Debug, Args)]
pub struct OccupancyArgs {
    /// Dataset folder whose frames are merged.
    pub dir: PathBuf,
    /// Poses to merge the frames with (TUM, one per frame in file-name order).
    #[arg(long)]
    pub poses: PathBuf,
    /// Voxel edge (m).
    #[arg(long, default_value_t = 0.1)]
    pub voxel: f64,
    /// Number of seeded sub-voxel grid offsets the count is averaged over (a wall that falls
    /// on voxel boundaries would otherwise count double).
    #[arg(long, default_value_t = 8)]
    pub offsets: usize,
    /// Seed of the grid offsets.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Print JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// `pssba demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Frames of the simulated window.
    #[arg(long, default_value_t = 20)]
    pub frames: usize,
    /// Points per frame.
    #[arg(long, default_value_t = 8000)]
    pub points: usize,
    /// Seed of the scene and of the pose noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Method to run.
    #[arg(long, value_enum, default_value = "pss-ba")]
    pub method: MethodArg,
    /// TOML config (see config/default.toml); `--method` overrides its `method`.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Also write the simulated dataset folder (frames/, poses.txt, gt.txt) here.
    #[arg(long)]
    pub write_dataset: Option<PathBuf>,
    /// Print JSON on stdout.
    #[arg(long)]
    pub json: bool,
}
