//! `pssba run --input live`: frames from a process outside the system, here
//! `tools/pssba_live.py publish` on the PyPI package iceoryx2 0.10.0 (another language, written
//! from docs/interface.md).
//!
//! Needs a Python with `iceoryx2==0.10.0`: `PSSBA_PYTHON` names it (`.ci/run` makes a venv),
//! else `python3` if it imports iceoryx2. Without one the tests skip, saying so, unless
//! `PSSBA_REQUIRE_LIVE_TESTS` is set (CI sets it, so there they cannot skip).

use crate::system::{pssba_watched, s, stderr};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

/// The Python to run tools/pssba_live.py with, or `None` (the test skips) when none has
/// iceoryx2 and CI does not require it.
fn python() -> Option<String> {
    let candidates = std::env::var("PSSBA_PYTHON")
        .into_iter()
        .chain(["python3".to_string()]);
    for python in candidates {
        let ok = Command::new(&python)
            .args(["-c", "import iceoryx2"])
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        if ok {
            return Some(python);
        }
    }
    assert!(
        std::env::var_os("PSSBA_REQUIRE_LIVE_TESTS").is_none(),
        "PSSBA_REQUIRE_LIVE_TESTS is set but no Python with iceoryx2 was found (PSSBA_PYTHON)"
    );
    eprintln!("SKIPPED: no Python with the iceoryx2 package (set PSSBA_PYTHON); CI runs this test");
    None
}

fn tool() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tools/pssba_live.py")
}

/// Starts `pssba run --input live --instance NAME` in the background.
fn start_live(instance: &str, config: &Path, out: &Path) -> Child {
    start_live_with(instance, config, out, &[])
}

/// Same, with more arguments.
fn start_live_with(instance: &str, config: &Path, out: &Path, extra: &[&str]) -> Child {
    Command::new(env!("CARGO_BIN_EXE_pssba"))
        .args(["-q", "run", "--input", "live", "--instance", instance])
        .args(["--config", s(config), "--out", s(out), "--timeout", "240"])
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("pssba starts")
}

fn setup(root: &Path) -> (PathBuf, PathBuf) {
    setup_with(root, "")
}

/// The 30-frame scene and a config with `system_keys` added to its [system] table.
fn setup_with(root: &Path, system_keys: &str) -> (PathBuf, PathBuf) {
    let dir = root.join("scene");
    let out = pssba_watched(
        &[
            "-q",
            "demo",
            "--frames",
            "30",
            "--points",
            "2000",
            "--seed",
            "2",
            "--write-dataset",
            s(&dir),
        ],
        Duration::from_secs(300),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let config = root.join("run.toml");
    std::fs::write(
        &config,
        format!("max_scales = 5\n[system]\nwindow_frames = 12\nwindow_stride = 8\n{system_keys}"),
    )
    .expect("config");
    (dir, config)
}

#[test]
fn a_python_producer_feeds_a_live_run_like_a_dataset_replay() {
    let Some(python) = python() else { return };
    let root = tempfile::tempdir().expect("tempdir");
    let (dir, config) = setup(root.path());
    let instance = format!("test-{}-a", std::process::id());
    let live_mcap = root.path().join("live.mcap");
    let live = start_live(&instance, &config, &live_mcap);
    // An outside subscriber of the final poses, started before the frames flow.
    let final_tum = root.path().join("final.tum");
    let poses = Command::new(&python)
        .arg(tool())
        .args([
            "poses",
            "--instance",
            &instance,
            "--out",
            s(&final_tum),
            "--timeout",
            "120",
        ])
        .stderr(Stdio::piped())
        .spawn()
        .expect("python runs");
    let publish = Command::new(&python)
        .arg(tool())
        .args([
            "publish",
            s(&dir),
            "--instance",
            &instance,
            "--timeout",
            "120",
        ])
        .output()
        .expect("python runs");
    let live = live.wait_with_output().expect("pssba output");
    let poses = poses.wait_with_output().expect("poses output");
    assert!(
        publish.status.success(),
        "publisher: {}",
        String::from_utf8_lossy(&publish.stderr)
    );
    assert!(
        poses.status.success(),
        "poses: {}",
        String::from_utf8_lossy(&poses.stderr)
    );
    assert!(live.status.success(), "live run: {}", stderr(&live));

    let replay_mcap = root.path().join("replay.mcap");
    let out = pssba_watched(
        &[
            "-q",
            "run",
            "--dataset",
            s(&dir),
            "--config",
            s(&config),
            "--out",
            s(&replay_mcap),
            "--timeout",
            "240",
        ],
        Duration::from_secs(300),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let live = pssba_system::mcap_read::read_recording(&live_mcap).expect("live recording");
    let replay = pssba_system::mcap_read::read_recording(&replay_mcap).expect("replay recording");
    // Every frame arrived once, with its pose, and got one final pose.
    assert_eq!(live.counts.get("/lidar/points"), Some(&30));
    assert_eq!(live.optimized.len(), 30);
    // The same bits in (tools/pssba_live.py normalises quaternions as pssba's TUM reader
    // does), so the same poses out: the live run equals the replay of the folder.
    assert_eq!(live.initial, replay.initial);
    assert_eq!(live.optimized.len(), replay.optimized.len());
    for (k, (a, b)) in live.optimized.iter().zip(&replay.optimized).enumerate() {
        let difference = (a.to_homogeneous() - b.to_homogeneous()).amax();
        assert!(difference < 1e-9, "final pose {k}: {a} vs {b}");
    }
    // The outside subscriber got one final pose per frame, with the frame's stamp, equal to
    // the replay's (the TUM file holds 12 decimals).
    let dataset = pssba_io::Dataset::open(&dir).expect("dataset");
    let received = pssba_io::read_tum(&final_tum).expect("final poses TUM");
    assert_eq!(received.len(), 30);
    for (k, (got, want)) in received.iter().zip(&replay.optimized).enumerate() {
        assert_eq!(got.stamp, dataset.initial[k].stamp, "stamp of frame {k}");
        let difference = (got.world_from_lidar.to_homogeneous() - want.to_homogeneous()).amax();
        assert!(
            difference < 1e-9,
            "outside subscriber, frame {k}: {difference}"
        );
    }
}

#[test]
fn a_producer_killed_mid_stream_leaves_a_finished_run() {
    let Some(python) = python() else { return };
    let root = tempfile::tempdir().expect("tempdir");
    let (dir, config) = setup(root.path());
    let instance = format!("test-{}-b", std::process::id());
    let mcap = root.path().join("live.mcap");
    let live = start_live(&instance, &config, &mcap);
    let mut publisher = Command::new(&python)
        .arg(tool())
        .args([
            "publish",
            s(&dir),
            "--instance",
            &instance,
            "--rate",
            "10",
            "--timeout",
            "120",
        ])
        .stderr(Stdio::null())
        .spawn()
        .expect("python runs");
    // About 15 of the 30 frames at 10 Hz (after the handshake), then SIGKILL: no marker.
    std::thread::sleep(Duration::from_millis(2500));
    publisher.kill().expect("kill");
    publisher.wait().expect("reaped");
    let live = live.wait_with_output().expect("pssba output");
    let log = stderr(&live);
    assert!(live.status.success(), "{log}");
    let recording = pssba_system::mcap_read::read_recording(&mcap).expect("recording");
    let frames = recording.counts.get("/lidar/points").copied().unwrap_or(0);
    assert!((2..30).contains(&frames), "{frames} frames recorded");
    // Every frame received is recorded once and is final.
    assert_eq!(recording.optimized.len(), frames);
}

/// Runs `publish` of the 30-frame scene (as fast as it can) into `instance`, with a `poses`
/// subscriber; returns (publisher, poses subscriber) outputs.
fn publish_and_listen(
    python: &str,
    instance: &str,
    dir: &Path,
    final_tum: &Path,
) -> (std::process::Output, std::process::Output) {
    let poses = Command::new(python)
        .arg(tool())
        .args(["poses", "--instance", instance, "--out", s(final_tum)])
        .args(["--timeout", "120"])
        .stderr(Stdio::piped())
        .spawn()
        .expect("python runs");
    let publish = Command::new(python)
        .arg(tool())
        .args([
            "publish",
            s(dir),
            "--instance",
            instance,
            "--timeout",
            "120",
        ])
        .output()
        .expect("python runs");
    (publish, poses.wait_with_output().expect("poses output"))
}

#[test]
fn a_full_backlog_drops_frames_counts_them_and_never_stalls_the_producer() {
    let Some(python) = python() else { return };
    let root = tempfile::tempdir().expect("tempdir");
    // One frame may wait while a window is solved: a producer at full speed overflows it.
    let (dir, config) = setup_with(
        root.path(),
        "live_overflow = \"drop\"\nlive_backlog_frames = 1\n",
    );
    let instance = format!("test-{}-c", std::process::id());
    let mcap = root.path().join("live.mcap");
    let live = start_live_with(&instance, &config, &mcap, &["--json"]);
    let final_tum = root.path().join("final.tum");
    let (publish, poses) = publish_and_listen(&python, &instance, &dir, &final_tum);
    let live = live.wait_with_output().expect("pssba output");
    assert!(
        publish.status.success(),
        "{}",
        String::from_utf8_lossy(&publish.stderr)
    );
    assert!(
        poses.status.success(),
        "{}",
        String::from_utf8_lossy(&poses.stderr)
    );
    assert!(live.status.success(), "{}", stderr(&live));
    let recording = pssba_system::mcap_read::read_recording(&mcap).expect("recording");
    // Every frame the producer sent is recorded (the recorder is lossless) ...
    assert_eq!(recording.counts.get("/lidar/points"), Some(&30));
    // ... some were dropped by the smooth stage, counted, and have no final pose.
    let dropped = recording.frames_dropped.expect("end-of-run diagnostics") as usize;
    assert!((1..30).contains(&dropped), "{dropped} dropped");
    assert_eq!(recording.optimized.len(), 30 - dropped);
    let summary: serde_json::Value =
        serde_json::from_slice(&live.stdout).expect("the --json summary");
    assert_eq!(summary["frames_dropped"].as_u64(), Some(dropped as u64));
    // The outside subscriber got one final pose per frame kept, stamps increasing, and the
    // frames kept are the ones the windows name.
    let received = pssba_io::read_tum(&final_tum).expect("final poses TUM");
    assert_eq!(received.len(), 30 - dropped);
    assert!(received.windows(2).all(|w| w[0].stamp < w[1].stamp));
    let named: usize = recording.windows.iter().map(|w| w.final_frames.len()).sum();
    assert_eq!(named, 30 - dropped);
}

#[test]
fn frames_n_stops_a_live_run_after_n_frames() {
    let Some(python) = python() else { return };
    let root = tempfile::tempdir().expect("tempdir");
    let (dir, config) = setup_with(root.path(), "live_overflow = \"block\"\n");
    let instance = format!("test-{}-d", std::process::id());
    let mcap = root.path().join("live.mcap");
    let live = start_live_with(&instance, &config, &mcap, &["--frames", "20"]);
    let final_tum = root.path().join("final.tum");
    let (publish, _poses) = publish_and_listen(&python, &instance, &dir, &final_tum);
    let live = live.wait_with_output().expect("pssba output");
    assert!(
        publish.status.success(),
        "{}",
        String::from_utf8_lossy(&publish.stderr)
    );
    assert!(live.status.success(), "{}", stderr(&live));
    let recording = pssba_system::mcap_read::read_recording(&mcap).expect("recording");
    assert_eq!(recording.counts.get("/lidar/points"), Some(&20));
    assert_eq!(recording.optimized.len(), 20);
    assert_eq!(recording.frames_dropped, Some(0));
}
