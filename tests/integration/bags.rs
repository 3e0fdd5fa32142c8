//! Robot recordings in: `pssba adjust BAG`, `pssba import`, `pssba inspect` and
//! `pssba run --input` on bags written by the independent `rosbags` package
//! (tests/fixtures/bags, see its README), compared with the same frames as a dataset folder.

use crate::system::{pssba_watched, s, stderr};
use nalgebra::Isometry3;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Bag stamps are the source folder's TUM stamps plus this.
const STAMP_OFFSET_S: f64 = 1_700_000_000.0;

/// The main fixtures: each holds the 20 frames of `source/`.
const BAGS: [&str; 4] = [
    "ros1_lz4.bag",
    "ros1_bz2_livox.bag",
    "ros2_mcap",
    "ros2_sqlite3",
];

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/bags")
}

fn pssba(args: &[&str]) -> std::process::Output {
    pssba_watched(args, Duration::from_secs(300))
}

fn poses(path: &Path) -> Vec<Isometry3<f64>> {
    pssba_io::read_tum(path)
        .expect("TUM")
        .iter()
        .map(|p| p.world_from_lidar)
        .collect()
}

fn ape_m(est: &[Isometry3<f64>]) -> f64 {
    let gt = poses(&fixtures().join("source/gt.txt"));
    pssba_eval::ape_translation_paired(&gt, est)
        .expect("APE")
        .rmse_m
}

#[test]
fn adjust_on_each_bag_reaches_the_accuracy_of_the_source_folder() {
    let dir = tempfile::tempdir().expect("tempdir");
    // The source folder is copied: adjust writes its poses beside the input.
    let folder_out = dir.path().join("folder.txt");
    let out = pssba(&[
        "-q",
        "adjust",
        s(&fixtures().join("source")),
        "--out",
        s(&folder_out),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let folder_ape = ape_m(&poses(&folder_out));
    assert!(
        folder_ape < 0.01,
        "the source folder itself: {folder_ape} m"
    );
    for bag in BAGS {
        let est = dir.path().join(format!("{bag}.txt"));
        let out = pssba(&["-q", "adjust", s(&fixtures().join(bag)), "--out", s(&est)]);
        assert!(out.status.success(), "{bag}: {}", stderr(&out));
        let stamped = pssba_io::read_tum(&est).expect("TUM");
        assert_eq!(stamped.len(), 20, "{bag}");
        for (k, p) in stamped.iter().enumerate() {
            // The clouds' header stamps (f64 seconds since the epoch: ~0.2 us resolution).
            assert!(
                (p.stamp - (STAMP_OFFSET_S + k as f64 * 0.1)).abs() < 1e-6,
                "{bag} stamp {k}"
            );
        }
        let bag_ape = ape_m(&poses(&est));
        eprintln!("{bag}: APE {bag_ape:.4} m, source folder {folder_ape:.4} m");
        // Odometry bags start from interpolated poses (up to 5 cm from poses.txt), so their
        // APE is compared with a margin; PoseStamped bags hold poses.txt itself.
        assert!(
            bag_ape <= 1.25 * folder_ape + 0.001,
            "{bag}: {bag_ape} m vs folder {folder_ape} m"
        );
    }
}

#[test]
fn import_round_trips_the_frames_exactly_and_names_its_sources() {
    let dir = tempfile::tempdir().expect("tempdir");
    let source = pssba_io::Dataset::open(fixtures().join("source")).expect("source");
    for bag in BAGS {
        let out_dir = dir.path().join(bag);
        let out = pssba(&[
            "-q",
            "import",
            s(&fixtures().join(bag)),
            "--out",
            s(&out_dir),
        ]);
        assert!(out.status.success(), "{bag}: {}", stderr(&out));
        let imported = pssba_io::Dataset::open(&out_dir).expect("imported dataset");
        assert_eq!(imported.len(), source.len(), "{bag}");
        for k in 0..source.len() {
            assert_eq!(
                imported.load_frame(k).expect("frame"),
                source.load_frame(k).expect("frame"),
                "{bag} frame {k}"
            );
        }
        let meta: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out_dir.join("meta.json")).expect("meta"))
                .expect("json");
        assert_eq!(meta["frames"], 20, "{bag}");
        assert!(
            meta["points_topic"]["name"]
                .as_str()
                .is_some_and(|t| t.starts_with('/')),
            "{meta}"
        );
        assert_eq!(meta["skipped"]["outside_pose_range"], 0);
        // Importing again into the same folder is refused, naming what exists.
        let again = pssba(&[
            "-q",
            "import",
            s(&fixtures().join(bag)),
            "--out",
            s(&out_dir),
        ]);
        assert!(!again.status.success() && stderr(&again).contains("already exists"));
    }
    // PoseStamped bags carry poses.txt exactly.
    let imported = pssba_io::read_tum(dir.path().join("ros2_mcap/poses.txt")).expect("poses");
    for (a, b) in imported.iter().zip(&source.initial) {
        assert!(
            (a.world_from_lidar.translation.vector - b.world_from_lidar.translation.vector).norm()
                < 1e-9
        );
    }
}

#[test]
fn inspect_lists_topics_and_what_would_be_read() {
    let out = pssba(&["inspect", s(&fixtures().join("ros2_sqlite3")), "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    assert_eq!(report["container"], "rosbag2 folder (sqlite3)");
    let topics = report["topics"].as_array().expect("topics");
    assert_eq!(topics.len(), 3);
    assert_eq!(report["frames"]["points_topic"], "/livox/lidar");
    assert_eq!(report["frames"]["poses_topic"], "/Odometry");
    assert_eq!(report["frames"]["frames"], 20);
    let extrinsic = report["frames"]["extrinsic"].as_array().expect("extrinsic");
    assert!((extrinsic[0].as_f64().expect("tx") - 0.10).abs() < 1e-12);
    // The Livox points' offset_time (written as i x 10 ns after the timebase = the stamp).
    let time = &report["frames"]["point_time"];
    assert_eq!(time["field"], "offset_time", "{time}");
    assert_eq!(
        (time["unit"].as_str(), time["origin"].as_str()),
        (Some("Ns"), Some("Timebase"))
    );
    let last_s = time["first_frame_s"][1].as_f64().expect("span");
    let last_index = (last_s / 10e-9).round();
    assert!(
        (860.0..900.0).contains(&last_index) && (last_s - last_index * 10e-9).abs() < 1e-10,
        "{last_s}"
    );
    // Ignored on request; a field the clouds lack is an error naming the message and field.
    let none = pssba(&[
        "inspect",
        s(&fixtures().join("ros2_sqlite3")),
        "--json",
        "--point-time",
        "none",
    ]);
    let report: serde_json::Value = serde_json::from_slice(&none.stdout).expect("json");
    assert!(report["frames"]["point_time"].is_null(), "{report}");
    let wrong = pssba(&[
        "-q",
        "adjust",
        s(&fixtures().join("ros1_lz4.bag")),
        "--point-time",
        "t:ns",
    ]);
    let text = stderr(&wrong);
    assert!(
        !wrong.status.success() && text.contains("message 0") && text.contains("no field t"),
        "{text}"
    );
    // A recording that cannot give frames still lists its topics, and says why.
    let out = pssba(&["inspect", s(&fixtures().join("small/no_overlap.bag"))]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && text.contains("/points") && text.contains("no frame has a pose"),
        "{text}"
    );
}

#[test]
fn options_select_topics_frames_and_extrinsic() {
    let dir = tempfile::tempdir().expect("tempdir");
    let bag = fixtures().join("ros1_lz4.bag");
    // --frames picks part of the recording; --extrinsic overrides /tf_static.
    let out_dir = dir.path().join("part");
    let identity = "0,0,0,0,0,0,1";
    let out = pssba(&[
        "-q",
        "import",
        s(&bag),
        "--out",
        s(&out_dir),
        "--frames",
        "4..9",
        "--extrinsic",
        identity,
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out_dir.join("meta.json")).expect("meta"))
            .expect("json");
    assert_eq!(meta["frames"], 5);
    assert_eq!(meta["skipped"]["not_selected"], 15);
    assert_eq!(
        meta["body_from_lidar"]["translation_m"],
        serde_json::json!([0.0, 0.0, 0.0])
    );
    // Wrong topic type, and a bad extrinsic: clear errors naming what is wrong.
    let out = pssba(&["-q", "adjust", s(&bag), "--points-topic", "/Odometry"]);
    assert!(
        !out.status.success()
            && stderr(&out).contains("--points-topic /Odometry is nav_msgs/Odometry"),
        "{}",
        stderr(&out)
    );
    let out = pssba(&["-q", "adjust", s(&bag), "--extrinsic", "1,2,3"]);
    assert!(
        !out.status.success() && stderr(&out).contains("expected 7 numbers"),
        "{}",
        stderr(&out)
    );
    let out = pssba(&["-q", "adjust", s(&fixtures().join("small/nan_pose.bag"))]);
    assert!(
        !out.status.success()
            && stderr(&out).contains("topic /pose (geometry_msgs/PoseStamped), message 1"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn run_replays_a_bag_and_then_its_own_recording() {
    let dir = tempfile::tempdir().expect("tempdir");
    let config = dir.path().join("run.toml");
    std::fs::write(&config, "[system]\nwindow_frames = 12\nwindow_stride = 8\n").expect("config");
    let first = dir.path().join("bag.mcap");
    let bag = fixtures().join("ros1_bz2_livox.bag");
    let out = pssba(&[
        "-q",
        "run",
        "--input",
        s(&bag),
        "--config",
        s(&config),
        "--out",
        s(&first),
        "--timeout",
        "240",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let recording = pssba_recording::read_recording(&first).expect("recording");
    assert_eq!(recording.counts.get("/lidar/points"), Some(&20));
    assert_eq!(recording.optimized.len(), 20);
    let run_ape = ape_m(&recording.optimized);
    assert!(run_ape < 0.02, "run --input BAG: APE {run_ape} m");
    // The recording is valid input: replayed, it gives the same clouds and initial poses.
    let second = dir.path().join("replay.mcap");
    let out = pssba(&[
        "-q",
        "run",
        "--input",
        s(&first),
        "--config",
        s(&config),
        "--out",
        s(&second),
        "--timeout",
        "240",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let replay = pssba_recording::read_recording(&second).expect("replay");
    assert_eq!(replay.counts.get("/lidar/points"), Some(&20));
    assert_eq!(replay.initial.len(), recording.initial.len());
    for (a, b) in replay.initial.iter().zip(&recording.initial) {
        // Equal up to the quaternion's renormalisation when read back (1 ulp).
        assert!(
            (a.to_homogeneous() - b.to_homogeneous()).amax() < 1e-12,
            "{a} vs {b}"
        );
    }
    let replay_ape = ape_m(&replay.optimized);
    assert!(
        replay_ape <= 1.25 * run_ape + 0.001,
        "replay APE {replay_ape} m vs {run_ape} m"
    );
}
