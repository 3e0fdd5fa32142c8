//! `pssba bench` flags.

use super::run::BenchMethod;
use clap::Args;
use std::path::PathBuf;

/// `pssba bench`: the paper's Table I protocol (DESIGN.md section 4) on simulated scenes.
///
/// For every scene and seed: simulate a group of frames along the scene's default trajectory
/// (Mid-360-like sensor, 2 cm range noise), perturb the poses by 0.2 m / 1 deg RMS (seeded),
/// then run Initial, BALM, Point2Plane, PSS-BA(FS) and PSS-BA on the same frames and initial
/// poses. Reports APE (translation RMSE after SE(3) alignment vs ground truth), occupied 0.1 m
/// voxels of the merged cloud (mean over 8 seeded grid offsets; fewer = sharper) and the
/// method's wall time (simulation excluded), each averaged over seeds. Every method runs with
/// one config for all scenes and seeds (the defaults, or --config): no per-scene tuning.
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// The quick variant (a few minutes on 2 cores): 30 frames of 8000 rays, 1 seed, every
    /// available scene. --frames, --points-per-frame and --seeds still override it.
    #[arg(long)]
    pub quick: bool,
    /// Comma-separated scenes: hangar, curved, truss, street (built-in), mbs, crane (CARIC
    /// meshes, see --caric). Default: the four built-ins plus mbs and crane when the CARIC
    /// folder is found.
    #[arg(long, value_delimiter = ',', value_name = "NAME,...")]
    pub scenes: Option<Vec<String>>,
    /// Run seeds 1..=N per scene (each seed: its own range noise and pose noise).
    #[arg(long, value_name = "N")]
    pub seeds: Option<u64>,
    /// Comma-separated methods to run: initial, balm, point2plane, pss-ba-fs, pss-ba.
    /// Default: all five. The tables show "-" for the others (and the PSS-BA/BALM time ratio
    /// needs both).
    #[arg(long, value_delimiter = ',', value_name = "NAME,...", value_enum)]
    pub methods: Option<Vec<BenchMethod>>,
    /// Frames per group (10 Hz). Default 100 (quick: 30).
    #[arg(long, value_name = "N")]
    pub frames: Option<usize>,
    /// Rays per frame. Default 20000, the Mid-360's 200,000 points/s at 10 Hz (quick: 8000).
    #[arg(long, value_name = "N")]
    pub points_per_frame: Option<usize>,
    /// TOML config applied to every scene and seed: the PSS-BA keys of config/default.toml
    /// (its `method` is ignored: each row sets its own) plus an optional [balm] table.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Folder holding mbs.stl and construction_crane_1.stl. Default: ../shared/data/caric
    /// relative to the current directory, else next to the executable's or the source
    /// workspace.
    #[arg(long, value_name = "DIR")]
    pub caric: Option<PathBuf>,
    /// Write the per-scene, per-method means as JSON:
    /// {"rows": [{"scene", "method", "ape_m", "occupancy", "time_s", ...}], ...}.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Write the tables as markdown, with the paper's Table I numbers beside ours.
    #[arg(long, value_name = "FILE")]
    pub markdown: Option<PathBuf>,
    /// Write TUM trajectories per scene and seed: DIR/<scene>-seed<N>/gt.txt, initial.txt and
    /// <method>.txt (e.g. for `evo_ape tum gt.txt pss-ba.txt -a`).
    #[arg(long, value_name = "DIR")]
    pub write_poses: Option<PathBuf>,
}

/// The effective sizes after applying --quick and the overrides.
#[derive(Debug, Clone, Copy)]
pub struct Sizes {
    /// Frames per group.
    pub frames: usize,
    /// Rays per frame.
    pub points_per_frame: usize,
    /// Seeds 1..=seeds.
    pub seeds: u64,
}

impl BenchArgs {
    /// The methods to run, in the tables' order, each once.
    pub fn methods(&self) -> Vec<BenchMethod> {
        BenchMethod::ALL
            .into_iter()
            .filter(|m| {
                self.methods
                    .as_ref()
                    .is_none_or(|chosen| chosen.contains(m))
            })
            .collect()
    }

    /// Frames, rays and seeds, validated.
    pub fn sizes(&self) -> anyhow::Result<Sizes> {
        let (frames, points_per_frame) = if self.quick {
            (30, 8000)
        } else {
            (100, 20_000)
        };
        let sizes = Sizes {
            frames: self.frames.unwrap_or(frames),
            points_per_frame: self.points_per_frame.unwrap_or(points_per_frame),
            seeds: self.seeds.unwrap_or(1),
        };
        if sizes.frames < 2 {
            anyhow::bail!("--frames must be at least 2 (got {})", sizes.frames);
        }
        if sizes.points_per_frame == 0 {
            anyhow::bail!("--points-per-frame must be at least 1 (got 0)");
        }
        if sizes.seeds == 0 {
            anyhow::bail!("--seeds must be at least 1 (got 0)");
        }
        Ok(sizes)
    }
}
