//! `pssba run --input live`: frames from a process outside the system, here
//! `tools/pssba_live.py publish` on the PyPI package iceoryx2 0.10.0 (another language, written
//! from docs/interface.md).
//!
//! Needs a Python with `iceoryx2==0.10.0`: `PSSBA_PYTHON` names it (`.ci/run` makes a venv),
//! else `python3` if it imports iceoryx2. Without one the tests skip, saying so, unless
//! `PSSBA_REQUIRE_LIVE_TESTS` is set (CI sets it, so there they cannot skip).

use crate::system::{pssba_watched, s, stderr};
use std::os::unix::process::ExitStatusExt;
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

/// A 30-frame moving flight (each point with its time, so the producer sends layout version 2)
/// and a config with `system_keys` added to its [system] table.
fn setup_with(root: &Path, system_keys: &str) -> (PathBuf, PathBuf) {
    let dir = root.join("scene");
    let out = pssba_watched(
        &[
            "-q",
            "simulate",
            "--scene",
            "curved",
            "--frames",
            "30",
            "--points-per-frame",
            "2000",
            "--seed",
            "2",
            "--out",
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

/// Fails the test with `who`'s stderr unless the process succeeded.
fn assert_success(who: &str, output: &std::process::Output) {
    assert!(
        output.status.success(),
        "{who}: {}",
        String::from_utf8_lossy(&output.stderr)
    );
}

/// `pssba run --dataset DIR` with `config`, recorded to `out`: what a live run of the same
/// folder must equal.
fn replay_dataset(dir: &Path, config: &Path, out: &Path) -> pssba_recording::Recording {
    let run = pssba_watched(
        &[
            "-q",
            "run",
            "--dataset",
            s(dir),
            "--config",
            s(config),
            "--out",
            s(out),
            "--timeout",
            "240",
        ],
        Duration::from_secs(300),
    );
    assert!(run.status.success(), "{}", stderr(&run));
    pssba_recording::read_recording(out).expect("replay recording")
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
    assert_success("publisher", &publish);
    assert_success("poses", &poses);
    assert!(live.status.success(), "live run: {}", stderr(&live));

    let live = pssba_recording::read_recording(&live_mcap).expect("live recording");
    let replay = replay_dataset(&dir, &config, &root.path().join("replay.mcap"));
    // Every frame arrived once, with its pose, and got one final pose.
    assert_eq!(live.counts.get("/lidar/points"), Some(&30));
    assert_eq!(live.optimized.len(), 30);
    // The same bits in (tools/pssba_live.py normalises quaternions as pssba's TUM reader
    // does, and sends each point's time), so the same poses out: the live run equals the
    // replay of the folder, which de-skews with the times.
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
    // 15 of the 30 frames at 10 Hz, then the producer SIGKILLs itself: no marker.
    let publisher = Command::new(&python)
        .arg(tool())
        .args(["publish", s(&dir), "--instance", &instance])
        .args(["--rate", "10", "--timeout", "120", "--die-after", "15"])
        .stderr(Stdio::null())
        .status()
        .expect("python runs");
    assert_eq!(
        publisher.signal(),
        Some(9),
        "the producer was to die after 15 frames"
    );
    let live = live.wait_with_output().expect("pssba output");
    let log = stderr(&live);
    assert!(live.status.success(), "{log}");
    let recording = pssba_recording::read_recording(&mcap).expect("recording");
    let frames = recording.counts.get("/lidar/points").copied().unwrap_or(0);
    // At most the 15 sent (a frame in flight may die with its producer's shared memory).
    assert!((1..=15).contains(&frames), "{frames} frames recorded");
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
    // How many frames survive depends on the machine's load: on a busy CI machine all but
    // the first may be dropped, and a window left with one frame cannot be adjusted. That
    // is a failed window, not what this test is about, so failed windows are allowed here.
    let (dir, config) = setup_with(
        root.path(),
        "live_overflow = \"drop\"\nlive_backlog_frames = 1\nallow_failed_windows = true\n",
    );
    let instance = format!("test-{}-c", std::process::id());
    let mcap = root.path().join("live.mcap");
    let live = start_live_with(&instance, &config, &mcap, &["--json"]);
    let final_tum = root.path().join("final.tum");
    let (publish, poses) = publish_and_listen(&python, &instance, &dir, &final_tum);
    let live = live.wait_with_output().expect("pssba output");
    assert_success("publish", &publish);
    assert_success("poses", &poses);
    assert!(live.status.success(), "{}", stderr(&live));
    let recording = pssba_recording::read_recording(&mcap).expect("recording");
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
    assert_success("publish", &publish);
    assert!(live.status.success(), "{}", stderr(&live));
    let recording = pssba_recording::read_recording(&mcap).expect("recording");
    assert_eq!(recording.counts.get("/lidar/points"), Some(&20));
    assert_eq!(recording.optimized.len(), 20);
    assert_eq!(recording.frames_dropped, Some(0));
}

#[test]
fn a_rust_client_feeds_frames_and_reads_window_summaries_maps_and_surfaces() {
    use pssba_client::windows::{SurfaceMsg, WindowSubscriber, WindowSummaryMsg};
    use pssba_client::{FrameProducer, PointXyz, frames::ready_id, instance, services};
    let root = tempfile::tempdir().expect("tempdir");
    let (dir, config) = setup(root.path());
    let name = format!("test-{}-e", std::process::id());
    let mcap = root.path().join("live.mcap");
    let live = start_live(&name, &config, &mcap);

    // This test process is both the producer (pssba-client, no Python) and a subscriber.
    let node = services::create_node(&instance::prefix(&name), "test_client").expect("node");
    let windows = WindowSubscriber::create(&node).expect("window subscriber");
    let dataset = pssba_io::Dataset::open(&dir).expect("dataset");
    let timeout = Duration::from_secs(60);
    let mut producer = FrameProducer::create(&node, 4000, timeout).expect("producer");
    producer
        .wait_for_consumers(&node, &ready_id::SYSTEM, timeout)
        .expect("the system's consumers");
    for k in 0..dataset.len() {
        let points: Vec<PointXyz> = dataset
            .load_frame(k)
            .expect("frame")
            .iter()
            .map(|p| PointXyz {
                xyz_m: [p.x as f32, p.y as f32, p.z as f32],
            })
            .collect();
        let pose = dataset.initial[k].world_from_lidar;
        producer
            .send(
                dataset.initial[k].stamp,
                &pose,
                None,
                points.len(),
                |i| points[i],
                None,
            )
            .expect("send");
    }
    producer.end_stream().expect("end of stream");

    let mut summaries: Vec<WindowSummaryMsg> = Vec::new();
    let mut map_points: Vec<u64> = Vec::new();
    let mut surfaces: Vec<Vec<SurfaceMsg>> = Vec::new();
    let started = std::time::Instant::now();
    loop {
        windows
            .receive_map(|header, points| {
                let w = header.window as usize;
                map_points.resize(map_points.len().max(w + 1), 0);
                map_points[w] += points.len() as u64;
                assert!(points.iter().all(|p| p.xyz_m.iter().all(|v| v.is_finite())));
            })
            .expect("map");
        windows
            .receive_surfaces(|header, chunk| {
                let w = header.window as usize;
                surfaces.resize(surfaces.len().max(w + 1), Vec::new());
                surfaces[w].extend_from_slice(chunk);
            })
            .expect("surfaces");
        let summary = windows.receive_summary().expect("summary");
        match summary {
            Some(s) if s.end_of_stream != 0 => {
                assert_eq!(s.window as usize, summaries.len());
                break;
            }
            Some(s) => summaries.push(s),
            None => {
                assert!(
                    started.elapsed() < Duration::from_secs(200),
                    "no end of stream"
                );
                windows.wait(Duration::from_millis(200)).expect("wait");
            }
        }
    }
    producer.linger(&node, Duration::from_secs(30));
    let live = live.wait_with_output().expect("pssba output");
    assert!(live.status.success(), "{}", stderr(&live));
    let recording = pssba_recording::read_recording(&mcap).expect("recording");
    // One summary per recorded window; together they make every frame final, in order.
    assert_eq!(summaries.len(), recording.windows.len());
    assert!(summaries.len() >= 3, "{} windows", summaries.len());
    let mut next = 0;
    for (k, s) in summaries.iter().enumerate() {
        assert_eq!(s.window, k as u64);
        assert_eq!(s.first_sequence, next, "window {k}");
        assert_eq!(
            s.final_count as usize,
            recording.windows[k].final_frames.len()
        );
        next += s.final_count;
        assert_eq!(s.failed, 0);
        assert!(s.scales_run >= 1 && s.last_gamma_m > 0.0);
        // The whole map chunk and every surface arrived.
        assert!(s.map_points > 0);
        assert_eq!(map_points.get(k), Some(&s.map_points), "window {k} map");
        assert_eq!(surfaces[k].len() as u64, s.surfaces, "window {k} surfaces");
        for surface in &surfaces[k] {
            // Surfaces name frames of this window's span, with a rotation as their frame.
            assert!(surface.frame_sequence < next);
            let r = nalgebra::Matrix3::from_row_slice(&surface.tangent_from_world);
            assert!((r * r.transpose() - nalgebra::Matrix3::identity()).amax() < 1e-9);
            assert!(surface.gamma_m > 0.0);
        }
    }
    assert_eq!(next, 30);
    assert_eq!(
        recording.counts.get("/pssba/map").copied(),
        Some(summaries.len())
    );
}

#[test]
fn with_live_producer_lost_wait_a_new_producer_continues_the_run() {
    let Some(python) = python() else { return };
    let root = tempfile::tempdir().expect("tempdir");
    let (dir, config) = setup_with(root.path(), "live_producer_lost = \"wait\"\n");
    let instance = format!("test-{}-f", std::process::id());
    let mcap = root.path().join("live.mcap");
    let live = start_live(&instance, &config, &mcap);
    // The first producer dies after 15 frames, without its marker.
    let first = Command::new(&python)
        .arg(tool())
        .args(["publish", s(&dir), "--instance", &instance])
        .args(["--rate", "10", "--timeout", "120", "--die-after", "15"])
        .stderr(Stdio::null())
        .status()
        .expect("python runs");
    assert_eq!(
        first.signal(),
        Some(9),
        "the first producer was to die after 15 frames"
    );
    std::thread::sleep(Duration::from_millis(1500));
    // A new producer (a restarted odometry) sends the whole folder and the marker.
    let second = Command::new(&python)
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
    assert_success("second producer", &second);
    let live = live.wait_with_output().expect("pssba output");
    assert!(live.status.success(), "{}", stderr(&live));
    let recording = pssba_recording::read_recording(&mcap).expect("recording");
    let frames = recording.counts.get("/lidar/points").copied().unwrap_or(0);
    let first_frames = frames - 30;
    assert!((1..=15).contains(&first_frames), "{frames} frames recorded");
    // Every frame of both producers is recorded once and is final.
    assert_eq!(recording.optimized.len(), frames);
    // The second producer's frames made new windows of their own: the same poses as a replay
    // of the folder alone.
    let replay = replay_dataset(&dir, &config, &root.path().join("replay.mcap"));
    for (k, (a, b)) in recording.optimized[first_frames..]
        .iter()
        .zip(&replay.optimized)
        .enumerate()
    {
        let difference = (a.to_homogeneous() - b.to_homogeneous()).amax();
        assert!(
            difference < 1e-9,
            "second producer's frame {k}: {difference}"
        );
    }
    // Windows are numbered across producers and name the frames by the run's numbering.
    let named: Vec<u64> = recording
        .windows
        .iter()
        .flat_map(|w| w.final_frames.clone())
        .collect();
    assert_eq!(named, (0..frames as u64).collect::<Vec<_>>());
}
