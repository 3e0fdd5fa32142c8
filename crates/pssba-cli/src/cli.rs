//! Command-line definitions (clap derive).

use clap::{Args, Parser, Subcommand, ValueEnum};
use pssba_core::Method;
use pssba_sim::{PoseNoise, TrajectoryKind};
use pssba_system::Stage;
use pssba_system::stages::table::StageArgs;
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
    /// Adjust the poses of an input: a dataset folder, a KITTI odometry sequence or a
    /// recording (ROS 1 bag, rosbag2 folder, MCAP, .db3, a `pssba run` recording).
    Adjust(AdjustArgs),
    /// Show a recording's topics, types, counts and time range, and which topics, extrinsic
    /// and frames `adjust`, `import` and `run --input` would use; of another input (a dataset
    /// folder, a KITTI sequence), what it is and its frames.
    Inspect(InspectArgs),
    /// Write an input's frames and initial poses (a recording, a KITTI sequence) as a dataset
    /// folder (frames/*.pcd, poses.txt, meta.json naming where they came from: the topics,
    /// extrinsic and skipped frames of a recording).
    Import(ImportArgs),
    /// Evaluate trajectories or maps.
    #[command(subcommand)]
    Eval(EvalCommand),
    /// Run the built-in simulated curved scene through the in-process pipeline and print APE
    /// before and after.
    Demo(DemoArgs),
    /// Simulate a Livox Mid-360 flight through a built-in scene or an STL mesh and write a
    /// dataset folder (frames/*.pcd, gt.txt, noisy poses.txt, meta.json).
    Simulate(SimulateArgs),
    /// The paper's Table I benchmark: simulate every scene, run Initial, BALM, Point2Plane,
    /// PSS-BA(FS) and PSS-BA on the same frames, print APE, occupancy and wall time tables.
    Bench(crate::bench::BenchArgs),
    /// Run the process system: ingest, smooth, adjust and record as separate processes over
    /// iceoryx2 shared memory, results in MCAP. With no arguments: the built-in simulated
    /// scene over several sliding windows, written to out/, APE before and after printed.
    Run(RunArgs),
    /// Write the flight out of a `pssba run` recording (all its parts): the final trajectory
    /// as TUM and the map (every final frame's points in the world frame, one point per
    /// voxel) as PLY or PCD. `pssba run` writes the same files beside its recording.
    Export(ExportArgs),
    /// One stage of the process system (started by `pssba run`; not for direct use).
    #[command(hide = true)]
    Stage(StageCommand),
}

/// `pssba export`.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// The recording: RUN.mcap as given to `pssba run --out` (its later parts,
    /// RUN.part2.mcap ..., are read with it).
    #[arg(value_name = "RUN.mcap")]
    pub recording: PathBuf,
    /// Write the final trajectory here: TUM (stamp x y z qx qy qz qw, world from lidar, one
    /// line per final frame, stamped as the input).
    #[arg(long, value_name = "F.tum")]
    pub poses: Option<PathBuf>,
    /// Write the map here: .ply (binary) or .pcd (binary), told apart by the extension;
    /// points in the world frame, float64.
    #[arg(long, value_name = "F.ply|F.pcd")]
    pub map: Option<PathBuf>,
    /// Edge of the map's voxels (m); each keeps the centroid of its points. Default: [output]
    /// map_voxel_m of --config, else 0.1.
    #[arg(long, value_name = "M")]
    pub map_voxel: Option<f64>,
    /// TOML config whose [output] table gives the defaults.
    #[arg(long)]
    pub config: Option<PathBuf>,
}

/// `pssba run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// TOML config: the PSS-BA keys of config/default.toml, its [windows] table (window length
    /// and stride) and its [system] table (failure policy, timeouts, sample size). Keys left
    /// out take the defaults of config/default.toml.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Dataset folder to replay (frames/*.pcd, poses.txt, optional gt.txt); any input --input
    /// takes works too. Default: the built-in simulated curved scene.
    #[arg(long, conflicts_with = "input")]
    pub dataset: Option<PathBuf>,
    /// Input to replay, decoded by the ingest stage as it goes: a dataset folder
    /// (frames/*.pcd, poses.txt, optional gt.txt), a KITTI odometry sequence (velodyne/*.bin,
    /// calib.txt, times.txt, KITTI poses), a ROS 1 .bag, a rosbag2 folder, an .mcap or .db3
    /// file, or a `pssba run` recording; told apart by content. `live`: no ingest stage;
    /// frames come from your own process on the frames service of --instance (see
    /// docs/interface.md).
    #[arg(long)]
    pub input: Option<PathBuf>,
    /// With --input live: the instance name outside producers connect to (letters, digits,
    /// '-' and '_'; its iceoryx2 prefix is `pssba-live-NAME-`).
    #[arg(long, required_if_eq("input", "live"))]
    pub instance: Option<String>,
    #[command(flatten)]
    pub recording: RecordingArgs,
    /// Output MCAP file (Foxglove-viewable). Beside it: the effective config (.config.toml),
    /// the final trajectory (.tum) and the map (.ply and .pcd, [output] map_voxel_m voxels).
    #[arg(long, default_value = "out/pssba-run.mcap")]
    pub out: PathBuf,
    /// Publish frames at this rate (Hz) instead of as fast as the stages take them.
    #[arg(long)]
    pub rate: Option<f64>,
    /// Frames of the built-in scene (200: three windows with the default W = 100, S = 80).
    #[arg(long, default_value_t = 200)]
    pub sim_frames: usize,
    /// Points per frame of the built-in scene.
    #[arg(long, default_value_t = 8000)]
    pub sim_points: usize,
    /// Seed of the built-in scene.
    #[arg(long, default_value_t = 1)]
    pub sim_seed: u64,
    /// Stop every stage and fail after this many seconds (watchdog).
    #[arg(long)]
    pub timeout: Option<f64>,
    /// Print a machine-readable summary (JSON) on stdout.
    #[arg(long)]
    pub json: bool,
}

/// `pssba stage NAME ...`: the arguments of every stage; which stage takes which, and which
/// it needs, is the stage table's (`pssba_system::stages::table`), checked before it runs.
#[derive(Debug, Args)]
pub struct StageCommand {
    /// The stage: record, adjust, smooth or ingest.
    #[arg(value_parser = parse_stage)]
    pub stage: Stage,
    /// iceoryx2 prefix of the run.
    #[arg(long)]
    pub prefix: String,
    /// The run's TOML config.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// record: the output MCAP file.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// record, smooth: frames come from an outside producer (`pssba run --input live`).
    #[arg(long)]
    pub live: bool,
    /// ingest, smooth, record: the file a restarted process of the stage resumes from
    /// (ingest: the count of frames sent; smooth: the windows published and the frames they
    /// made final; record: how far the recording got at its last flush, with a journal beside
    /// it, so that it ends the part it cut and goes on in a new part run.part2.mcap, ...).
    #[arg(long)]
    pub progress: Option<PathBuf>,
    /// ingest: the frame source, input:{JSON} (what `pssba run` names).
    #[arg(long)]
    pub source: Option<String>,
    /// ingest: publish rate (Hz).
    #[arg(long)]
    pub rate: Option<f64>,
}

impl StageCommand {
    /// The stage's arguments as the stage table knows them.
    pub fn into_args(self) -> (Stage, StageArgs) {
        let args = StageArgs {
            prefix: self.prefix,
            config: self.config,
            out: self.out,
            live: self.live,
            progress: self.progress,
            source: self.source,
            rate_hz: self.rate,
        };
        (self.stage, args)
    }
}

fn parse_stage(name: &str) -> Result<Stage, String> {
    Stage::from_name(name).ok_or_else(|| {
        let names: Vec<&str> = Stage::ALL.iter().map(|s| s.name()).collect();
        format!("no stage '{name}' (the stages: {})", names.join(", "))
    })
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
    /// The input: a dataset folder (frames/*.pcd, poses.txt, optional gt.txt), a KITTI
    /// odometry sequence (velodyne/*.bin, calib.txt, times.txt, KITTI poses), a ROS 1 .bag, a
    /// rosbag2 folder, an .mcap or .db3 file, or a `pssba run` recording; told apart by
    /// content.
    #[arg(value_name = "INPUT")]
    pub dir: PathBuf,
    #[command(flatten)]
    pub recording: RecordingArgs,
    /// Method; overrides the config file's `method`.
    #[arg(long, value_enum)]
    pub method: Option<MethodArg>,
    /// TOML config (see config/default.toml); missing keys take the defaults.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Where to write the optimised poses (TUM, same stamps as poses.txt; for a recording,
    /// the clouds' header stamps). Default: DIR/poses_<method>.txt, or beside a recording
    /// NAME: NAME_poses_<method>.txt.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also write the smoothed cloud (world frame) as binary PLY; with `--method balm`, the
    /// merged input cloud at BALM's poses; for the whole flight, the input at the final poses.
    #[arg(long)]
    pub map: Option<PathBuf>,
    /// Frames per sliding window of the whole-flight pipeline (as `pssba run` does, in one
    /// process). Input longer than one window runs that pipeline by default: sliding windows,
    /// places seen again found and the loop closed ([flight] in the config). Default: the
    /// config's [windows] window_frames.
    #[arg(long)]
    pub window_frames: Option<usize>,
    /// New frames per sliding window after the first (1 <= S < W). Default: the config's
    /// [windows] window_stride.
    #[arg(long)]
    pub window_stride: Option<usize>,
    /// Adjust all frames in one window, however many (the paper's setting; memory and time
    /// grow with the input). The default for input no longer than one window.
    #[arg(long)]
    pub one_window: bool,
    /// Print a machine-readable summary (JSON) on stdout.
    #[arg(long)]
    pub json: bool,
}

/// How frames and poses are read from an input (the Recording flags: a robot recording's).
#[derive(Debug, Clone, Args)]
pub struct RecordingArgs {
    /// Cloud topic (sensor_msgs/PointCloud2 or Livox CustomMsg). Default: the config's
    /// [recording] points_topic, else the only one.
    #[arg(long, help_heading = "Recording")]
    pub points_topic: Option<String>,
    /// Pose topic (nav_msgs/Odometry, geometry_msgs/PoseStamped or PoseWithCovarianceStamped),
    /// world from body. Default: the config's [recording] poses_topic, else the only one.
    #[arg(long, help_heading = "Recording")]
    pub poses_topic: Option<String>,
    /// body_from_lidar as tx,ty,tz,qx,qy,qz,qw (m, unit quaternion); overrides /tf_static.
    /// Default: the config's [recording] extrinsic, else /tf_static (or /tf) when it links the
    /// pose's frame to the clouds' frame, else identity (warned).
    #[arg(long, value_name = "TX,TY,TZ,QX,QY,QZ,QW", help_heading = "Recording")]
    pub extrinsic: Option<String>,
    /// A cloud between two poses further apart than this (s) gets no interpolated pose and is
    /// skipped (counted). Default: the config's [recording] max_pose_gap_s (0.5).
    #[arg(long, value_name = "S", help_heading = "Recording")]
    pub max_pose_gap: Option<f64>,
    /// Only clouds stamped from this many seconds after the recording's start.
    #[arg(
        long,
        value_name = "S",
        conflicts_with = "frames",
        help_heading = "Recording"
    )]
    pub start: Option<f64>,
    /// Only clouds stamped within this many seconds after --start (or the start).
    #[arg(
        long,
        value_name = "D",
        conflicts_with = "frames",
        help_heading = "Recording"
    )]
    pub duration: Option<f64>,
    /// Only these cloud messages: A..B (0-based, B excluded) on the cloud topic. With
    /// `--input live`: N, stop after N frames as if the end-of-stream marker had come.
    #[arg(long, value_name = "A..B|N", help_heading = "Recording")]
    pub frames: Option<String>,
    /// Each point's time within its frame: `auto` finds a field named offset_time (Livox
    /// CustomMsg), t (Ouster), time (Velodyne), timestamp (Livox driver2, Hesai), time_offset
    /// or time_stamp and tells its unit (s, ms, us, ns) and origin (after the header stamp, or
    /// absolute) from the first frame's values; FIELD or FIELD:UNIT names them; `none` ignores
    /// times (every point at its frame's stamp). `pssba inspect` shows what was found.
    /// Default: the config's [recording] point_time (auto).
    #[arg(
        long,
        value_name = "auto|none|FIELD[:UNIT]",
        help_heading = "Recording"
    )]
    pub point_time: Option<String>,
    /// Initial poses from this file instead of the input's own: a KITTI sequence's pose file
    /// (KITTI format: a 3x4 matrix per line, as kiss-icp writes them), or a dataset folder's
    /// (TUM). Default: the input's own (KITTI: poses.txt in the sequence folder).
    #[arg(long, value_name = "FILE", help_heading = "Input")]
    pub poses: Option<PathBuf>,
}

/// `pssba inspect`.
#[derive(Debug, Args)]
pub struct InspectArgs {
    /// TOML config; its [recording] table sets defaults of the recording flags.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The input: a dataset folder (frames/*.pcd, poses.txt, optional gt.txt), a KITTI
    /// odometry sequence (velodyne/*.bin, calib.txt, times.txt, KITTI poses), a ROS 1 .bag, a
    /// rosbag2 folder, an .mcap or .db3 file, or a `pssba run` recording; told apart by
    /// content.
    #[arg(value_name = "INPUT")]
    pub bag: PathBuf,
    #[command(flatten)]
    pub recording: RecordingArgs,
    /// Print JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// `pssba import`.
#[derive(Debug, Args)]
pub struct ImportArgs {
    /// TOML config; its [recording] table sets defaults of the recording flags.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The input: a dataset folder (frames/*.pcd, poses.txt, optional gt.txt), a KITTI
    /// odometry sequence (velodyne/*.bin, calib.txt, times.txt, KITTI poses), a ROS 1 .bag, a
    /// rosbag2 folder, an .mcap or .db3 file, or a `pssba run` recording; told apart by
    /// content.
    #[arg(value_name = "INPUT")]
    pub bag: PathBuf,
    /// Dataset folder to create (may exist, but must not hold frames/ or poses.txt).
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub recording: RecordingArgs,
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

/// Trajectory kinds as command-line values.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum TrajectoryArg {
    /// Horizontal circle around the scene's centre.
    Orbit,
    /// The orbit, climbing at 0.25 m/s.
    Helix,
    /// Three parallel rows joined by half-circle turns, swept back and forth.
    Lawnmower,
}

impl From<TrajectoryArg> for TrajectoryKind {
    fn from(value: TrajectoryArg) -> Self {
        match value {
            TrajectoryArg::Orbit => TrajectoryKind::Orbit,
            TrajectoryArg::Helix => TrajectoryKind::Helix,
            TrajectoryArg::Lawnmower => TrajectoryKind::Lawnmower,
        }
    }
}

/// Parses `--pose-noise TRANSLATION_M,ROTATION_DEG`.
pub fn parse_pose_noise(text: &str) -> Result<PoseNoise, String> {
    let usage = "expected TRANSLATION_M,ROTATION_DEG, two finite numbers >= 0, e.g. 0.2,1.0";
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let [t, r] = parts[..] else {
        return Err(format!("'{text}': {usage}"));
    };
    let number = |s: &str| {
        s.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v >= 0.0)
            .ok_or_else(|| format!("'{s}' in '{text}': {usage}"))
    };
    Ok(PoseNoise {
        translation_rms_m: number(t)?,
        rotation_rms_deg: number(r)?,
    })
}

/// `pssba simulate`.
///
/// Flies a UAV-like trajectory (1.5 m/s, 10 Hz, yaw along the path) through the scene and
/// ray-casts one Mid-360 frame per pose (FoV 360 x [-7, 52] deg, 0.1-70 m, 2 cm range noise,
/// non-repetitive pattern; each frame is taken at its pose, no motion within a frame).
/// Writes DIR/frames/*.pcd (sensor frame), DIR/gt.txt (true poses, TUM), DIR/poses.txt (gt
/// with seeded noise) and DIR/meta.json. Refuses to overwrite an existing dataset.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// A built-in scene (hangar, curved, truss, street) or the path of an STL mesh (binary or
    /// ASCII, metres, z up). An STL scene gets a ground plane (see --no-ground) and is flown
    /// on a loop around its bounding box: straights along its long side, half circles of
    /// radius 0.7 x half its short side + 5 m, widened until the loop keeps 2 m from the mesh
    /// with open sky above; at min z + clamp(a quarter of its height, 3, 5) m (the sensor
    /// looks only 7 deg down, so flying higher it would see little ground within 70 m).
    #[arg(long, value_name = "NAME|MESH.stl")]
    pub scene: String,
    /// Number of frames (10 Hz; 100 frames = 10 s of flight).
    #[arg(long)]
    pub frames: usize,
    /// Seed of the range noise and of the pose noise; the same seed gives identical output.
    #[arg(long)]
    pub seed: u64,
    /// Dataset folder to create (may exist, but must not hold frames/, poses.txt, gt.txt or
    /// meta.json).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Path shape, flown over the scene's default centre, radius and height. Default: the
    /// scene's own (lawnmower for street, orbit otherwise).
    #[arg(long, value_enum)]
    pub trajectory: Option<TrajectoryArg>,
    /// RMS of the Gaussian noise on the initial poses (poses.txt): translation in m and
    /// rotation in deg, per-axis sigma RMS/sqrt(3).
    #[arg(long, value_name = "T_M,R_DEG", default_value = "0.2,1.0", value_parser = parse_pose_noise)]
    pub pose_noise: PoseNoise,
    /// Rays fired per frame (20000 = the Mid-360's 200,000 points/s at 10 Hz); rays that hit
    /// nothing within 70 m give no point, so frames hold fewer points.
    #[arg(long, default_value_t = 20_000)]
    pub points_per_frame: usize,
    /// Do not add a ground plane under an STL scene (at its lowest z, 80 m beyond it).
    #[arg(long)]
    pub no_ground: bool,
    /// Frames taken at one instant each: every ray from the frame's pose, no point times.
    /// Default: the sensor moves during each frame (each ray from the true pose at its own
    /// time) and each frame's PCD holds every point's time after its stamp (field `time`, s).
    #[arg(long)]
    pub still_frames: bool,
    /// Flying speed along the path (m/s; a UAV flies 1-5). Default: the scene's (1.5).
    #[arg(long, value_name = "M_S")]
    pub speed: Option<f64>,
    /// Turn the sensor about its heading as a helmet wearer turns their head: 0.55 rad at
    /// 0.6 Hz, peaking at 119 deg/s.
    #[arg(long)]
    pub head_turns: bool,
}
