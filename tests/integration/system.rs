//! The process system end to end: `pssba run` spawns the real stage processes over iceoryx2;
//! the MCAP it writes is read back with the mcap crate. Every run is bounded by the launcher's
//! `--timeout` and by a watchdog here; nothing asserts on wall time.

use nalgebra::Isometry3;
use pssba_recording::{Recording, read_recording};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::mpsc;
use std::time::Duration;

/// Runs `pssba ARGS`, killing it if it outlives `limit` (a hung system fails the test).
pub(crate) fn pssba_watched(args: &[&str], limit: Duration) -> Output {
    let child = Command::new(env!("CARGO_BIN_EXE_pssba"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("pssba starts");
    let pid = child.id();
    let (done, wait) = mpsc::channel();
    let waiter = std::thread::spawn(move || {
        let out = child.wait_with_output().expect("pssba output");
        let _ = done.send(());
        out
    });
    if wait.recv_timeout(limit).is_err() {
        let _ = Command::new("kill").arg("-9").arg(pid.to_string()).status();
        panic!("watchdog: pssba {args:?} still running after {limit:?}");
    }
    waiter.join().expect("waiter thread")
}

pub(crate) fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

pub(crate) fn s(path: &Path) -> &str {
    path.to_str().expect("utf-8 path")
}

/// `pssba -q run SOURCE.. --config CONFIG --out MCAP --timeout 300 EXTRA..` under a watchdog.
fn pssba_run(source: &[&str], config: &Path, mcap: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["-q", "run"];
    args.extend_from_slice(source);
    args.extend_from_slice(&["--config", s(config), "--out", s(mcap), "--timeout", "300"]);
    args.extend_from_slice(extra);
    pssba_watched(&args, Duration::from_secs(400))
}

/// A simulated dataset folder (written by the in-process demo).
fn dataset(root: &Path, frames: usize, points: usize) -> PathBuf {
    let dir = root.join("scene");
    let out = pssba_watched(
        &[
            "-q",
            "demo",
            "--frames",
            &frames.to_string(),
            "--points",
            &points.to_string(),
            "--seed",
            "2",
            "--write-dataset",
            s(&dir),
        ],
        Duration::from_secs(300),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    dir
}

fn config(root: &Path, window_frames: usize, window_stride: usize) -> PathBuf {
    config_with(root, window_frames, window_stride, 5, "")
}

/// A run config with `max_scales` and extra `[system]` lines.
fn config_with(
    root: &Path,
    window_frames: usize,
    window_stride: usize,
    max_scales: usize,
    system_extra: &str,
) -> PathBuf {
    let path = root.join("run.toml");
    let text = format!(
        "max_scales = {max_scales}\n[system]\nwindow_frames = {window_frames}\n\
         window_stride = {window_stride}\n{system_extra}"
    );
    std::fs::write(&path, text).expect("config written");
    path
}

/// A dataset folder's frames as `pssba adjust` loads them: points, initial poses, stamps, and
/// each point's time (frames without a time field at their stamp) when any frame has them.
struct Loaded {
    frames: Vec<Vec<nalgebra::Point3<f64>>>,
    initial: Vec<Isometry3<f64>>,
    stamps_s: Vec<f64>,
    offsets_s: Option<Vec<Vec<f32>>>,
}

impl Loaded {
    fn times(&self) -> Option<pssba_core::PointTimes<'_>> {
        self.offsets_s
            .as_deref()
            .map(|offsets_s| pssba_core::PointTimes {
                stamps_s: &self.stamps_s,
                offsets_s,
            })
    }
}

fn load(dir: &Path) -> Loaded {
    let data = pssba_io::Dataset::open(dir).expect("dataset");
    let (frames, times): (Vec<_>, Vec<_>) = (0..data.len())
        .map(|k| data.load_frame_with_times(k).expect("frame"))
        .unzip();
    let offsets_s = times.iter().any(Option::is_some).then(|| {
        frames
            .iter()
            .zip(times)
            .map(|(f, t)| t.unwrap_or_else(|| vec![0.0; f.len()]))
            .collect()
    });
    Loaded {
        frames,
        initial: data.initial.iter().map(|p| p.world_from_lidar).collect(),
        stamps_s: data.initial.iter().map(|p| p.stamp).collect(),
        offsets_s,
    }
}

fn read_poses(path: &Path) -> Vec<Isometry3<f64>> {
    pssba_io::read_tum(path)
        .expect("TUM")
        .iter()
        .map(|p| p.world_from_lidar)
        .collect()
}

/// `pssba simulate --scene SCENE --frames N --seed 3 EXTRA..` into `root/SCENE`: frames
/// taken while moving, each point with its time, unless EXTRA asks for `--still-frames`.
fn simulate(root: &Path, scene: &str, frames: usize, extra: &[&str]) -> PathBuf {
    let dir = root.join(scene);
    let frames = frames.to_string();
    let mut args = vec![
        "-q", "simulate", "--scene", scene, "--frames", &frames, "--seed", "3",
    ];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--out", s(&dir)]);
    let out = pssba_watched(&args, Duration::from_secs(300));
    assert!(out.status.success(), "{scene}: {}", stderr(&out));
    dir
}

/// `pssba run --dataset DIR` with `config` equals the in-process whole-flight library
/// (to 1e-9) and `pssba adjust DIR --window-frames W --window-stride S` (to the TUM file's 9
/// decimals). Returns the recording.
fn assert_run_equals_library(dir: &Path, config: &Path, root: &Path) -> Recording {
    let mcap = root.join("run.mcap");
    let out = pssba_run(&["--dataset", s(dir)], config, &mcap, &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let recording = read_recording(&mcap).expect("MCAP readable");
    let run_config = pssba_system::Config::load(Some(config)).expect("config");
    let loaded = load(dir);
    let library = pssba_core::adjust_flight(
        &loaded.frames,
        &loaded.initial,
        loaded.times(),
        &run_config.algorithm,
        run_config.windows.spec(),
        run_config.flight.settings(),
        pssba_core::Parallelism::Rayon,
    )
    .expect("library run");
    assert!(library.failures.is_empty(), "{:?}", library.failures);
    let difference = max_pose_difference(&recording.optimized, &library.world_from_lidar);
    assert!(
        difference < 1e-9,
        "system vs in-process sliding windows: max difference {difference:e}"
    );
    let windows = library.windows.len();
    assert_eq!(recording.windows.len(), windows);
    assert!(recording.windows.iter().all(|w| w.error.is_none()));
    let poses_path = root.join("adjusted.txt");
    let w = run_config.windows.window_frames.to_string();
    let st = run_config.windows.window_stride.to_string();
    let out = pssba_watched(
        &[
            "-q",
            "adjust",
            s(dir),
            "--config",
            s(config),
            "--window-frames",
            &w,
            "--window-stride",
            &st,
            "--out",
            s(&poses_path),
        ],
        Duration::from_secs(300),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let difference = max_pose_difference(&recording.optimized, &read_poses(&poses_path));
    assert!(
        difference < 5e-9,
        "system vs pssba adjust --window-frames: max difference {difference:e}"
    );
    recording
}

#[test]
fn sliding_windows_through_the_processes_equal_the_library() {
    let tmp = tempfile::tempdir().expect("tmp");
    let dir = dataset(tmp.path(), 30, 3000);
    // Windows end at 12, 20, 28 and 30; tiny samples split every block and result in parts.
    let config = config_with(tmp.path(), 12, 8, 5, "sample_words = 1024\n");
    let recording = assert_run_equals_library(&dir, &config, tmp.path());
    assert_eq!(recording.windows.len(), 4);
    assert_eq!(recording.optimized.len(), 30);
}

#[test]
fn frames_of_150k_points_go_through_the_processes_as_through_pssba_adjust() {
    // A denser sensor than the Mid-360: 150,000 rays per frame (more than the 65,536 the
    // frames service once held), so factor blocks and results span several samples.
    let tmp = tempfile::tempdir().expect("tmp");
    let dir = simulate(
        tmp.path(),
        "hangar",
        12,
        &["--points-per-frame", "150000", "--still-frames"],
    );
    let largest = pssba_io::Dataset::open(&dir)
        .expect("dataset")
        .largest_frame_points()
        .expect("headers");
    assert!(largest > 100_000, "largest frame {largest}");
    let config = config_with(tmp.path(), 100, 80, 3, "");
    assert_run_equals_library(&dir, &config, tmp.path());
}

#[test]
fn every_builtin_scene_at_full_size_goes_through_the_processes_as_through_pssba_adjust() {
    // 100 frames x 20,000 rays each; 3 scales keep the test short (equality does not depend
    // on the number of scales).
    for scene in ["hangar", "curved", "truss", "street"] {
        let tmp = tempfile::tempdir().expect("tmp");
        let dir = simulate(tmp.path(), scene, 100, &[]);
        let config = config_with(tmp.path(), 100, 80, 3, "");
        let recording = assert_run_equals_library(&dir, &config, tmp.path());
        assert_eq!(recording.optimized.len(), 100, "{scene}");
    }
}

/// A folder whose frames 6 and 7 hold 5 points each: the window in which they are new has
/// nothing to adjust and fails.
fn dataset_with_a_failing_window(root: &Path) -> PathBuf {
    let dir = dataset(root, 12, 2000);
    for k in [6, 7] {
        let path = dir.join("frames").join(format!("{k:06}.pcd"));
        let points: Vec<_> = (0..5)
            .map(|i| nalgebra::Point3::new(1.0 + i as f64, 2.0, 3.0))
            .collect();
        std::fs::remove_file(&path).expect("remove");
        pssba_io::write_pcd(&path, &points, pssba_io::PcdEncoding::Binary).expect("write");
    }
    dir
}

#[test]
fn a_failed_window_fails_the_run_and_says_which_frames_kept_their_poses() {
    let tmp = tempfile::tempdir().expect("tmp");
    let dir = dataset_with_a_failing_window(tmp.path());
    let config = config_with(tmp.path(), 4, 2, 3, "");
    let mcap = tmp.path().join("run.mcap");
    let out = pssba_run(&["--dataset", s(&dir)], &config, &mcap, &[]);
    assert!(!out.status.success(), "a failed window must fail the run");
    let err = stderr(&out);
    assert!(err.contains("windows failed"), "{err}");
    assert!(
        err.contains("window 2 (frames 6..=7 kept their initial poses)"),
        "{err}"
    );
    // Nothing is lost: every frame has its one final pose in the recording.
    let recording = read_recording(&mcap).expect("MCAP readable");
    assert_eq!(recording.optimized.len(), 12);
    assert!(recording.windows.iter().any(|w| w.error.is_some()));
    // The same in one process.
    let out = pssba_watched(
        &[
            "-q",
            "adjust",
            s(&dir),
            "--config",
            s(&config),
            "--window-frames",
            "4",
            "--window-stride",
            "2",
        ],
        Duration::from_secs(300),
    );
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("window 2 (frames 6..8 kept their initial poses)"),
        "{}",
        stderr(&out)
    );

    // Asked to keep going: exit 0, with the failure still reported.
    let config = config_with(tmp.path(), 4, 2, 3, "allow_failed_windows = true\n");
    let out = pssba_run(&["--dataset", s(&dir)], &config, &mcap, &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("windows failed"), "{}", stderr(&out));
}

fn max_pose_difference(a: &[Isometry3<f64>], b: &[Isometry3<f64>]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x.to_homogeneous() - y.to_homogeneous()).abs().max())
        .fold(0.0, f64::max)
}

#[test]
fn one_window_through_the_processes_equals_pssba_adjust() {
    let tmp = tempfile::tempdir().expect("tmp");
    let dir = dataset(tmp.path(), 10, 3000);
    let config = config(tmp.path(), 1000, 1);
    let mcap = tmp.path().join("run.mcap");
    let out = pssba_run(&["--dataset", s(&dir)], &config, &mcap, &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let poses_path = tmp.path().join("adjusted.txt");
    let out = pssba_watched(
        &[
            "-q",
            "adjust",
            s(&dir),
            "--config",
            s(&config),
            "--out",
            s(&poses_path),
        ],
        Duration::from_secs(300),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let in_process: Vec<Isometry3<f64>> = pssba_io::read_tum(&poses_path)
        .expect("TUM")
        .iter()
        .map(|p| p.world_from_lidar)
        .collect();
    let recording = read_recording(&mcap).expect("MCAP readable");
    // The TUM file holds 9 decimals: equal up to that rounding.
    let difference = max_pose_difference(&recording.optimized, &in_process);
    assert!(
        difference < 5e-9,
        "system vs pssba adjust: max difference {difference:e}"
    );
    // Full precision: the library's in-process run (what `pssba adjust` calls).
    let data = pssba_io::Dataset::open(&dir).expect("dataset");
    let frames: Vec<_> = (0..data.len())
        .map(|k| data.load_frame(k).expect("frame"))
        .collect();
    let initial_poses: Vec<_> = data.initial.iter().map(|p| p.world_from_lidar).collect();
    let run_config = pssba_system::Config::load(Some(&config)).expect("config");
    let library =
        pssba_core::adjust(&frames, &initial_poses, &run_config.algorithm).expect("adjust");
    let difference = max_pose_difference(&recording.optimized, &library.world_from_lidar);
    assert!(
        difference < 1e-9,
        "system vs in-process library: max difference {difference:e}"
    );
    let initial: Vec<Isometry3<f64>> = pssba_io::read_tum(dir.join("poses.txt"))
        .expect("TUM")
        .iter()
        .map(|p| p.world_from_lidar)
        .collect();
    assert!(max_pose_difference(&recording.initial, &initial) < 1e-8);
}

fn assert_topics(recording: &Recording, frames: usize, windows: usize) {
    let count = |topic: &str| recording.counts.get(topic).copied().unwrap_or(0);
    assert_eq!(count("/lidar/points"), frames);
    assert_eq!(count("/tf"), frames, "one final transform per frame");
    for topic in [
        "/pssba/map",
        "/pssba/surfaces",
        "/pssba/poses/optimized",
        "/pssba/poses/initial",
    ] {
        assert_eq!(count(topic), windows, "{topic}");
    }
    assert_eq!(count("/pssba/poses/ground_truth"), windows);
    assert!(
        count("/pssba/diagnostics") > windows,
        "window reports plus LM solves"
    );
    let schema = |topic: &str| recording.schemas.get(topic).map(String::as_str);
    assert_eq!(schema("/lidar/points"), Some("foxglove.PointCloud"));
    assert_eq!(schema("/pssba/map"), Some("foxglove.PointCloud"));
    assert_eq!(schema("/tf"), Some("foxglove.FrameTransform"));
    assert_eq!(
        schema("/pssba/poses/optimized"),
        Some("foxglove.PosesInFrame")
    );
    assert_eq!(schema("/pssba/surfaces"), Some("pssba.Surfaces"));
    assert_eq!(schema("/pssba/diagnostics"), Some("pssba.Diagnostics"));
}

#[test]
fn sliding_windows_record_every_topic_and_improve_the_trajectory() {
    let tmp = tempfile::tempdir().expect("tmp");
    let config = config(tmp.path(), 12, 8);
    let mcap = tmp.path().join("out").join("run.mcap");
    let out = pssba_run(
        &["--sim-frames", "30", "--sim-points", "3000"],
        &config,
        &mcap,
        &["--json"],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON summary");
    let recording = read_recording(&mcap).expect("MCAP readable");
    // Windows end at 12, 20, 28 and 30 (the end of the stream).
    assert_topics(&recording, 30, 4);
    assert_eq!(
        recording.optimized.len(),
        30,
        "every frame has exactly one final pose"
    );
    assert_eq!(recording.ground_truth.len(), 30);
    let before = pssba_eval::ape_translation_paired(&recording.ground_truth, &recording.initial)
        .expect("APE");
    let after = pssba_eval::ape_translation_paired(&recording.ground_truth, &recording.optimized)
        .expect("APE");
    assert!(
        after.rmse_m < 0.25 * before.rmse_m,
        "APE {} -> {}",
        before.rmse_m,
        after.rmse_m
    );
    // Continuity across window boundaries: no frame far off the aligned trajectory.
    assert!(
        after.max_m < 0.05,
        "largest per-frame error {} m",
        after.max_m
    );
    assert_eq!(summary["frames"], 30);
}

#[test]
fn a_dying_stage_stops_the_run_and_names_the_stage() {
    let tmp = tempfile::tempdir().expect("tmp");
    let dir = dataset(tmp.path(), 8, 2000);
    // Frame 5's data is cut short (its header is fine, so the run starts): ingest fails
    // after publishing frames 0-4.
    std::fs::write(
        dir.join("frames").join("000005.pcd"),
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1000\n\
         HEIGHT 1\nPOINTS 1000\nDATA ascii\n1 2 3\n",
    )
    .expect("write");
    let config = config(tmp.path(), 4, 2);
    let mcap = tmp.path().join("run.mcap");
    let out = pssba_run(&["--dataset", s(&dir)], &config, &mcap, &[]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(err.contains("stage ingest failed"), "{err}");
    assert!(err.contains("000005.pcd"), "{err}");
    // The recorder was stopped, not killed: its MCAP is finished and holds what arrived.
    let recording = read_recording(&mcap).expect("finished MCAP");
    let points = recording.counts.get("/lidar/points").copied().unwrap_or(0);
    assert!((1..=5).contains(&points), "{points} frames recorded");
}

#[test]
fn bad_run_arguments_are_refused_before_any_stage_starts() {
    let tmp = tempfile::tempdir().expect("tmp");
    let missing = tmp.path().join("nowhere");
    let out = pssba_watched(&["run", "--dataset", s(&missing)], Duration::from_secs(60));
    assert!(!out.status.success());
    assert!(stderr(&out).contains("nowhere"), "{}", stderr(&out));
    // A frame whose header is broken is found before any stage starts, and named.
    let dir = dataset(tmp.path(), 4, 500);
    let broken = dir.join("frames").join("000002.pcd");
    std::fs::write(&broken, "VERSION 0.7\nFIELDS x y\n").expect("write");
    let out = pssba_watched(&["run", "--dataset", s(&dir)], Duration::from_secs(60));
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(err.contains("000002.pcd"), "{err}");
    assert!(
        !err.contains("stage"),
        "refused before any stage started: {err}"
    );
    let bad = tmp.path().join("bad.toml");
    std::fs::write(&bad, "[system]\nwindow_stride = 0\n").expect("write");
    let out = pssba_watched(&["run", "--config", s(&bad)], Duration::from_secs(60));
    assert!(!out.status.success());
    assert!(stderr(&out).contains("window_stride"), "{}", stderr(&out));
}

/// A flight whose frames were taken while moving goes through the processes with its point
/// times (frames layout version 2): the recording keeps every point's time bit for bit, and
/// replaying the recording (`--input run.mcap`) adjusts its frames with those times as well
/// as the first run did.
#[test]
fn a_moving_flight_keeps_its_point_times_through_the_processes_and_a_replay() {
    let tmp = tempfile::tempdir().expect("tmp");
    let dir = simulate(tmp.path(), "curved", 24, &["--points-per-frame", "3000"]);
    let loaded = load(&dir);
    let source_times = loaded.offsets_s.as_ref().expect("simulated times");
    assert!(source_times.iter().flatten().any(|&t| t > 0.05));
    let config = config_with(tmp.path(), 12, 8, 3, "");
    let first = tmp.path().join("first.mcap");
    let out = pssba_run(&["--dataset", s(&dir)], &config, &first, &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let source = pssba_source::open(&first, &pssba_source::OpenOptions::default()).expect("input");
    let mut recorded = 0;
    for (k, frame) in source.frames_from(0).expect("frames").enumerate() {
        let frame = frame.expect("frame");
        assert_eq!(
            frame.point_times_s.as_ref(),
            Some(&source_times[k]),
            "frame {k}"
        );
        recorded += 1;
    }
    assert_eq!(recorded, 24);
    let replay = tmp.path().join("replay.mcap");
    let out = pssba_run(&["--input", s(&first)], &config, &replay, &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let (a, b) = (
        read_recording(&first).expect("first"),
        read_recording(&replay).expect("replay"),
    );
    assert_eq!((a.optimized.len(), b.optimized.len()), (24, 24));
    // A replay does not repeat a run's poses bit for bit (a still flight's differ by about
    // 1 mm after 3 scales too: the recording's stamps are whole nanoseconds), so its
    // accuracy is what is compared.
    let ape_m = |r: &Recording| {
        pssba_eval::ape_translation_paired(&r.ground_truth, &r.optimized)
            .expect("APE")
            .rmse_m
    };
    let (first_m, replay_m) = (ape_m(&a), ape_m(&b));
    eprintln!("APE: first run {first_m:.4} m, replay {replay_m:.4} m");
    assert!(
        replay_m < 1.5 * first_m + 1e-3,
        "replay {replay_m} m vs first run {first_m} m"
    );
}
