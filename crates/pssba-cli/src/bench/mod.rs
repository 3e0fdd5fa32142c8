//! `pssba bench`: the paper's Table I protocol on simulated scenes (DESIGN.md sections 3-4).
//! `args` holds the flags, `scenes` picks the scenes, `run` measures one case, `table` averages
//! over seeds and renders the tables; this file runs the loop and writes the outputs.

mod args;
mod group;
mod run;
mod scenes;
mod table;

pub use args::BenchArgs;

use anyhow::Context;
use args::Sizes;
use pssba_config::Config;
use pssba_io::StampedPose;
use run::Measurement;
use std::path::Path;
use std::time::Instant;
use table::{Metric, Row};

/// Writes `DIR/<scene>-seed<N>/{gt,initial,<method>}.txt` (TUM).
fn write_poses(
    dir: &Path,
    scene: &str,
    seed: u64,
    data: &pssba_sim::SimulatedDataset,
    measurements: &[Measurement],
) -> anyhow::Result<()> {
    let folder = dir.join(format!("{scene}-seed{seed}"));
    std::fs::create_dir_all(&folder)
        .with_context(|| format!("{}: cannot create", folder.display()))?;
    let tum = |poses: &[nalgebra::Isometry3<f64>]| -> Vec<StampedPose> {
        data.stamps
            .iter()
            .zip(poses)
            .map(|(&stamp, &world_from_lidar)| StampedPose {
                stamp,
                world_from_lidar,
            })
            .collect()
    };
    pssba_io::write_tum(folder.join("gt.txt"), &tum(&data.ground_truth))?;
    for m in measurements.iter().filter(|m| m.error.is_none()) {
        pssba_io::write_tum(
            folder.join(format!("{}.txt", m.method.name())),
            &tum(&m.world_from_lidar),
        )?;
    }
    Ok(())
}

/// The header line naming the variant and sizes.
fn describe(args: &BenchArgs, sizes: &Sizes) -> String {
    let methods: Vec<&str> = args.methods().iter().map(|m| m.name()).collect();
    format!(
        "pssba bench{}: {} frames x {} rays per frame, seeds 1..={}, pose noise 0.2 m / 1 deg \
         RMS, methods {}, config {}",
        if args.quick { " (quick variant)" } else { "" },
        sizes.frames,
        sizes.points_per_frame,
        sizes.seeds,
        methods.join(", "),
        args.config
            .as_ref()
            .map_or_else(|| "defaults".to_owned(), |p| p.display().to_string())
    )
}

/// Runs the subcommand.
pub fn run(args: &BenchArgs) -> anyhow::Result<()> {
    let sizes = args.sizes()?;
    let settings = Config::load(args.config.as_deref())?;
    let scenes = scenes::resolve(args.scenes.as_deref(), args.caric.as_deref())?;
    let methods = args.methods();
    let header = describe(args, &sizes);
    tracing::info!("{header}");
    let started = Instant::now();
    let mut rows = Vec::new();
    let mut moved_scenes = Vec::new();
    for source in &scenes {
        let name = source.name();
        let mut scene = source
            .build()
            .with_context(|| format!("building scene {name}"))?;
        let group = group::group_path(&scene, sizes.frames)
            .with_context(|| format!("choosing the path of {name}"))?;
        if group.moved {
            let hits: Vec<String> = group
                .wall_hits_per_turn
                .iter()
                .map(|h| format!("{h:.0}"))
                .collect();
            tracing::info!(
                "{name}: the default path's first {} frames are a straight leg (APE undefined \
                 after SE(3) alignment); the group starts at turn {} of [{}] (wall hits per \
                 probed frame)",
                sizes.frames,
                group.chosen_turn + 1,
                hits.join(", ")
            );
            moved_scenes.push(name.to_owned());
        }
        scene.trajectory = group.trajectory;
        let mut per_seed: Vec<(u64, Vec<Measurement>)> = Vec::new();
        for seed in 1..=sizes.seeds {
            let sim_started = Instant::now();
            let data = run::simulate(&scene, sizes.frames, sizes.points_per_frame, seed)
                .with_context(|| format!("simulating {name} seed {seed}"))?;
            let points: usize = data.frames.iter().map(Vec::len).sum();
            tracing::info!(
                "{name} seed {seed}: simulated {} frames, {:.0} points per frame ({:.1} s)",
                data.frames.len(),
                points as f64 / data.frames.len() as f64,
                sim_started.elapsed().as_secs_f64()
            );
            let mut measurements = Vec::new();
            for &method in &methods {
                let m = run::measure(method, &data, &settings);
                match (&m.error, m.ape_m) {
                    (Some(error), _) => {
                        tracing::warn!("{name} seed {seed} {}: FAILED: {error}", method.name());
                    }
                    (None, Some(ape)) => tracing::info!(
                        "{name} seed {seed} {:<11}: APE {ape:.4} m, occupancy {:.0}, {}",
                        method.name(),
                        m.occupancy.unwrap_or(f64::NAN),
                        m.time_s
                            .map_or_else(|| "-".to_owned(), |t| format!("{t:.2} s"))
                    ),
                    (None, None) => {}
                }
                measurements.push(m);
            }
            if let Some(dir) = &args.write_poses {
                write_poses(dir, name, seed, &data, &measurements)?;
            }
            per_seed.push((seed, measurements));
        }
        for &method in &methods {
            let runs: Vec<(u64, &Measurement)> = per_seed
                .iter()
                .filter_map(|(seed, ms)| ms.iter().find(|m| m.method == method).map(|m| (*seed, m)))
                .collect();
            rows.push(Row::new(name, method, &runs));
        }
    }
    let total_s = started.elapsed().as_secs_f64();
    let header = describe(args, &sizes);
    let names: Vec<String> = scenes.iter().map(|s| s.name().to_owned()).collect();
    let path_note = (!moved_scenes.is_empty()).then(|| {
        format!(
            "Path: each scene's default trajectory, except {}: its first {} frames are a \
             straight leg (collinear positions: SE(3) alignment and APE undefined, evo refuses \
             too), so the group starts at the path's turn that sees the most wall (surfaces \
             over 30 deg from horizontal, probed with a few rays).",
            moved_scenes.join(", "),
            sizes.frames
        )
    });
    let output = Output {
        header,
        rows,
        scenes: names,
        path_note,
        total_s,
    };
    output.print();
    if let Some(path) = &args.json {
        output.write_json(path, args, &sizes, &moved_scenes)?;
    }
    if let Some(path) = &args.markdown {
        output.write_markdown(path)?;
    }
    Ok(())
}

/// Everything a finished bench prints and writes.
struct Output {
    header: String,
    rows: Vec<Row>,
    scenes: Vec<String>,
    path_note: Option<String>,
    total_s: f64,
}

impl Output {
    fn print(&self) {
        println!("{}", self.header);
        for metric in Metric::ALL {
            println!();
            print!("{}", table::text_table(&self.rows, &self.scenes, metric));
        }
        let failures = table::failure_notes(&self.rows);
        if !failures.is_empty() {
            println!("\n* = failed on some seeds (mean over the others):\n{failures}");
        }
        if let Some(note) = &self.path_note {
            println!("\n{note}");
        }
        println!(
            "\ntotal wall time {:.1} s (simulation included)",
            self.total_s
        );
    }

    fn write_json(
        &self,
        path: &Path,
        args: &BenchArgs,
        sizes: &Sizes,
        moved: &[String],
    ) -> anyhow::Result<()> {
        let doc = serde_json::json!({
            "quick": args.quick,
            "frames": sizes.frames,
            "points_per_frame": sizes.points_per_frame,
            "seeds": sizes.seeds,
            "pose_noise": { "translation_rms_m": 0.2, "rotation_rms_deg": 1.0 },
            "config": args.config.as_ref().map(|p| p.display().to_string()),
            "occupancy": {
                "voxel_m": run::VOXEL_M, "offsets": run::OFFSETS, "seed": run::OFFSET_SEED,
            },
            "group_starts_at_first_turn": moved,
            "total_wall_time_s": self.total_s,
            "rows": self.rows,
        });
        let text = serde_json::to_string_pretty(&doc)? + "\n";
        std::fs::write(path, text).with_context(|| format!("{}: cannot write", path.display()))?;
        eprintln!("wrote {}", path.display());
        Ok(())
    }

    fn write_markdown(&self, path: &Path) -> anyhow::Result<()> {
        let mut text = format!("{}.\n\n", self.header);
        for metric in Metric::ALL {
            text.push_str(&table::markdown_table(&self.rows, &self.scenes, metric));
            text.push('\n');
        }
        text.push_str(
            "In parentheses: the paper's Table I (our `hangar` is procedural, the paper's CARIC \
             hangar being unavailable; `crane` is CARIC's construction_crane_1; `curved` and \
             `truss` have no counterpart).\n",
        );
        let failures = table::failure_notes(&self.rows);
        if !failures.is_empty() {
            text.push_str("\n`*` = failed on some seeds (mean over the others):\n\n");
            text.push_str(&failures);
        }
        if let Some(note) = &self.path_note {
            text.push_str(&format!("\n{note}\n"));
        }
        text.push_str(&format!(
            "\nTotal wall time {:.1} s (simulation included).\n",
            self.total_s
        ));
        std::fs::write(path, text).with_context(|| format!("{}: cannot write", path.display()))?;
        eprintln!("wrote {}", path.display());
        Ok(())
    }
}
