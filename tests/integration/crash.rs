//! The crash matrix: in a multi-window `pssba run`, one stage is SIGKILLed at a seeded random
//! point (the Nth factor block sent, or the Nth frame sent, counted in the run's own debug log
//! as it happens), and the run must still end well: exit 0, every frame recorded once, one
//! final pose per frame, APE within 1.5x of an undisturbed run, and a recording the mcap
//! crate reads. `PSSBA_CRASH_SEED` picks other points (the seed is printed).

use crate::system::{s, stderr};
use pssba_recording::existing_parts;
use pssba_recording::read_recording_parts as read_recording;
use std::collections::BTreeSet;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

const FRAMES: usize = 120;

/// W = 40, S = 30 over 120 frames: four windows, 4 scales each; `system_extra` adds
/// `[system]` lines.
fn config(root: &Path, name: &str, system_extra: &str) -> std::path::PathBuf {
    let path = root.join(format!("{name}.toml"));
    std::fs::write(
        &path,
        format!(
            "max_scales = 4\n[system]\nwindow_frames = 40\nwindow_stride = 30\n\
             restart_backoff_s = 0.1\n{system_extra}"
        ),
    )
    .expect("config written");
    path
}

/// splitmix64: a seeded point that does not depend on any crate.
fn splitmix(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The pid of `pssba stage STAGE --prefix PREFIX`, from /proc.
fn stage_pid(stage: &str, prefix: &str) -> Option<u32> {
    let wanted = format!("stage\0{stage}\0--prefix\0{prefix}\0");
    std::fs::read_dir("/proc")
        .ok()?
        .flatten()
        .find_map(|entry| {
            let pid: u32 = entry.file_name().to_str()?.parse().ok()?;
            let cmdline = std::fs::read(entry.path().join("cmdline")).ok()?;
            String::from_utf8_lossy(&cmdline)
                .contains(&wanted)
                .then_some(pid)
        })
}

/// What one run did.
struct Run {
    out: Output,
    /// The stage's pid that was killed, if it was.
    killed: Option<u32>,
}

/// `pssba -v run` on the built-in scene; when `kill` is `(stage, marker, n)`, SIGKILLs the
/// stage as the nth log line containing `marker` appears.
fn run(root: &Path, name: &str, kill: Option<(&str, &str, usize)>, system_extra: &str) -> Run {
    let mcap = root.join(format!("{name}.mcap"));
    let mut child = Command::new(env!("CARGO_BIN_EXE_pssba"))
        .args(["-v", "run", "--sim-frames", &FRAMES.to_string()])
        .args(["--sim-points", "3000", "--sim-seed", "4"])
        .args([
            "--config",
            s(&config(root, name, system_extra)),
            "--out",
            s(&mcap),
        ])
        .args(["--timeout", "300", "--json"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("pssba starts");
    let stderr_pipe = child.stderr.take().expect("stderr");
    let (lines_tx, lines) = mpsc::channel::<String>();
    let reader = std::thread::spawn(move || {
        for line in BufReader::new(stderr_pipe).lines().map_while(Result::ok) {
            let _ = lines_tx.send(line);
        }
    });
    let started = Instant::now();
    let mut log = Vec::new();
    let mut prefix = None;
    let mut seen = 0;
    let mut killed = None;
    while let Ok(line) = lines.recv_timeout(Duration::from_secs(400)) {
        if let Some(rest) = line.split("with prefix ").nth(1) {
            prefix = Some(rest.trim().to_string());
        }
        if let (Some((stage, marker, n)), None, Some(prefix)) = (kill, killed, &prefix)
            && line.contains(marker)
        {
            seen += 1;
            if seen == n {
                let pid = stage_pid(stage, prefix).expect("the stage is running");
                let status = Command::new("kill").args(["-9", &pid.to_string()]).status();
                assert!(status.is_ok_and(|s| s.success()), "kill -9 {pid}");
                killed = Some(pid);
            }
        }
        log.push(line);
        assert!(
            started.elapsed() < Duration::from_secs(400),
            "watchdog: the run is still going"
        );
    }
    reader.join().expect("reader");
    let mut out = child.wait_with_output().expect("pssba output");
    out.stderr = log.join("\n").into_bytes();
    Run { out, killed }
}

/// Every message's log time on `topic` in every part of the recording, with the mcap crate's
/// reader (each part must read to its end).
fn log_times(mcap: &Path, topic: &str) -> Vec<u64> {
    existing_parts(mcap)
        .iter()
        .flat_map(|part| {
            pssba_bag::mcap_message_reader(part)
                .expect("MCAP opens")
                .map(|m| m.expect("every record reads"))
                .filter(|m| m.channel.topic == topic)
                .map(|m| m.log_time)
                .collect::<Vec<_>>()
        })
        .collect()
}

fn ape_m(mcap: &Path) -> f64 {
    let recording = read_recording(mcap).expect("the mcap crate reads the recording");
    assert_eq!(
        recording.optimized.len(),
        FRAMES,
        "one final pose per frame"
    );
    pssba_eval::ape_translation_paired(&recording.ground_truth, &recording.optimized)
        .expect("APE")
        .rmse_m
}

/// Every frame recorded once, with one final transform each.
fn assert_every_frame_once(mcap: &Path) {
    for topic in ["/lidar/points", "/tf"] {
        let times = log_times(mcap, topic);
        let distinct: BTreeSet<u64> = times.iter().copied().collect();
        assert_eq!(times.len(), FRAMES, "{topic}: {} messages", times.len());
        assert_eq!(distinct.len(), FRAMES, "{topic}: a frame recorded twice");
    }
}

#[test]
fn a_killed_stage_is_restarted_and_the_run_loses_nothing() {
    let tmp = tempfile::tempdir().expect("tmp");
    let seed: u64 = std::env::var("PSSBA_CRASH_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(14);
    eprintln!("crash seed {seed} (PSSBA_CRASH_SEED)");
    let mut state = seed;

    let calm = run(tmp.path(), "calm", None, "");
    assert!(calm.out.status.success(), "{}", stderr(&calm.out));
    let calm_ape = ape_m(&tmp.path().join("calm.mcap"));
    let blocks = stderr(&calm.out).matches("factor block sent").count();
    assert!(blocks >= 12, "{blocks} blocks in a 4-window run");

    // (stage, log line counted, the nth such line: seeded, within the run)
    let cases = [
        (
            "adjust",
            "factor block sent",
            2 + (splitmix(&mut state) % (blocks as u64 - 4)) as usize,
        ),
        (
            "ingest",
            "frame sent",
            5 + (splitmix(&mut state) % (FRAMES as u64 - 15)) as usize,
        ),
        // After the end of the stream, while it waits for the consumers to finish: the
        // restarted ingest stage must not wait for frame consumers that have every frame.
        ("ingest", "end-of-stream marker sent", 1),
        (
            "smooth",
            "factor block sent",
            2 + (splitmix(&mut state) % (blocks as u64 - 4)) as usize,
        ),
        (
            "record",
            "frame sent",
            5 + (splitmix(&mut state) % (FRAMES as u64 - 15)) as usize,
        ),
        // Later, while windows are published: the smooth stage sends the lost ones again.
        (
            "record",
            "factor block sent",
            2 + (splitmix(&mut state) % (blocks as u64 - 4)) as usize,
        ),
    ];
    for (stage, marker, n) in cases {
        let name = format!("kill-{stage}-{n}");
        let run = run(tmp.path(), &name, Some((stage, marker, n)), "");
        let err = stderr(&run.out);
        assert!(
            run.killed.is_some(),
            "{stage} was never killed (at {marker} #{n})"
        );
        assert!(
            run.out.status.success(),
            "{stage} killed at {marker} #{n}: {err}"
        );
        assert!(err.contains(&format!("stage {stage} restarted")), "{err}");
        let mcap = tmp.path().join(format!("{name}.mcap"));
        let parts = existing_parts(&mcap).len();
        if stage == "record" {
            assert!(parts >= 2, "a restarted recorder goes on in a new part");
            // The part the crash cut was ended at its last flush; at the end of the run it is
            // given a full summary section, and the trajectory beside the recording covers
            // every part.
            for part in existing_parts(&mcap) {
                assert!(
                    pssba_recording::has_summary(&part).expect("footer"),
                    "{} has a summary section",
                    part.display()
                );
            }
            let tum = pssba_io::read_tum(mcap.with_extension("tum")).expect("trajectory");
            assert_eq!(tum.len(), FRAMES);
        } else {
            assert_eq!(parts, 1);
        }
        assert_every_frame_once(&mcap);
        let ape = ape_m(&mcap);
        // Stronger than the APE bound: a restarted stage goes on exactly where its
        // predecessor was, so every final pose is the undisturbed run's.
        let calm_poses = read_recording(&tmp.path().join("calm.mcap"))
            .expect("calm")
            .optimized;
        let poses = read_recording(&mcap).expect("recording").optimized;
        let largest = poses
            .iter()
            .zip(&calm_poses)
            .map(|(a, b)| (a.translation.vector - b.translation.vector).norm())
            .fold(0.0, f64::max);
        assert!(largest < 1e-6, "{stage}: a final pose moved {largest} m");
        eprintln!(
            "{stage} killed at {marker} #{n}: APE {ape:.5} m (undisturbed {calm_ape:.5} m), \
             {parts} part(s)"
        );
        assert!(ape <= 1.5 * calm_ape, "APE {ape} vs {calm_ape} undisturbed");
        let summary: serde_json::Value =
            serde_json::from_slice(&run.out.stdout).expect("JSON summary");
        assert_eq!(summary["frames"], FRAMES);
    }
}

#[test]
fn a_stage_killed_past_max_restarts_stops_the_run_and_names_it() {
    let tmp = tempfile::tempdir().expect("tmp");
    for stage in ["record", "adjust"] {
        let why = "not restarted again after 0 restarts";
        let extra = "max_restarts = 0\n";
        let run = run(tmp.path(), stage, Some((stage, "frame sent", 50)), extra);
        let err = stderr(&run.out);
        assert!(run.killed.is_some(), "{stage} was never killed");
        assert!(!run.out.status.success(), "{err}");
        assert!(
            err.contains(&format!(
                "stage {stage} failed (signal: 9 (SIGKILL)); {why}"
            )),
            "{err}"
        );
    }
}

/// A 3 MB tmpfs at `dir` (needs root; `None` when it cannot be mounted).
fn small_disk(dir: &Path) -> Option<()> {
    let mounted = Command::new("mount")
        .args(["-t", "tmpfs", "-o", "size=3m", "tmpfs", s(dir)])
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|status| status.success());
    mounted.then_some(())
}

#[test]
fn a_full_disk_fails_the_run_clearly_and_leaves_a_readable_recording() {
    let tmp = tempfile::tempdir().expect("tmp");
    let disk = tmp.path().join("disk");
    std::fs::create_dir(&disk).expect("mount point");
    if small_disk(&disk).is_none() {
        eprintln!("SKIPPED: cannot mount a 3 MB tmpfs here (needs root)");
        return;
    }
    let mcap = disk.join("full.mcap");
    let out = crate::system::pssba_watched(
        &["-q", "run", "--out", s(&mcap), "--timeout", "300"],
        Duration::from_secs(400),
    );
    let err = stderr(&out);
    let listed = pssba_bag::mcap_message_reader(&mcap)
        .expect("MCAP opens")
        .map(|m| m.map(|m| m.channel.topic.clone()))
        .collect::<Result<Vec<_>, _>>();
    let _ = Command::new("umount").arg(s(&disk)).status();
    assert!(!out.status.success(), "a full disk must fail the run");
    assert!(err.contains("No space left on device"), "{err}");
    assert!(
        err.contains(s(&mcap)) && err.contains("readable up to there"),
        "{err}"
    );
    assert!(err.contains("stage record failed"), "{err}");
    // Every record before the cut reads, with the mcap crate's reader.
    let topics = listed.expect("every message before the cut reads");
    let frames = topics.iter().filter(|t| *t == "/lidar/points").count();
    assert!(frames >= 10, "{frames} frames readable");
}
