//! The flight out: `pssba run` writes RUN.tum, RUN.ply and RUN.pcd beside its recording, and
//! `pssba export` writes the same from any recording. Checked against the recording read back
//! by the project's readers (the final poses of `/pssba/poses/optimized`, the frames of
//! `/lidar/points` through `pssba-source`), not against the exporter's own code.

use crate::system::{pssba_watched, s, stderr};
use nalgebra::Isometry3;
use std::collections::HashSet;
use std::path::Path;
use std::time::Duration;

const VOXEL_M: f64 = 0.25;

fn voxel_key(p: &nalgebra::Point3<f64>, voxel_m: f64) -> [i64; 3] {
    [p.x, p.y, p.z].map(|v| (v / voxel_m).floor() as i64)
}

/// The voxels the map of the run recorded to `mcap` must fill: every frame's points (read as
/// an input by pssba-source, de-skewed along the final poses when they have times) through its
/// final pose; and how many frames had times.
fn expected_voxels(
    mcap: &Path,
    finals: &[Isometry3<f64>],
    voxel_m: f64,
) -> (HashSet<[i64; 3]>, usize) {
    let source = pssba_source::open(mcap, &pssba_source::OpenOptions::default()).expect("input");
    let frames: Vec<_> = (source.frames_from(0).expect("frames"))
        .map(|f| f.expect("frame"))
        .collect();
    let stamps_s: Vec<f64> = frames.iter().map(|f| f.stamp_s).collect();
    let mut voxels = HashSet::new();
    let mut timed = 0;
    for (k, (frame, world_from_lidar)) in frames.iter().zip(finals).enumerate() {
        let points = match &frame.point_times_s {
            Some(times) => {
                timed += 1;
                pssba_core::deskew_frame_along(&frame.points, times, finals, &stamps_s, k)
                    .expect("de-skew")
            }
            None => frame.points.clone(),
        };
        for p in &points {
            voxels.insert(voxel_key(&(world_from_lidar * p), voxel_m));
        }
    }
    (voxels, timed)
}

fn same_pose(a: &Isometry3<f64>, b: &Isometry3<f64>) -> bool {
    (a.translation.vector - b.translation.vector).norm() < 1e-8
        && a.rotation.angle_to(&b.rotation) < 1e-8
}

#[test]
fn a_run_writes_its_trajectory_and_map_and_export_writes_the_same() {
    let tmp = tempfile::tempdir().expect("tmp");
    let config = tmp.path().join("run.toml");
    std::fs::write(
        &config,
        format!("max_scales = 5\n[windows]\nwindow_frames = 12\nwindow_stride = 8\n[output]\nmap_voxel_m = {VOXEL_M}\n"),
    )
    .expect("config");
    // A moving flight: every point with its time.
    let dataset = tmp.path().join("flight");
    let out = pssba_watched(
        &[
            "-q",
            "simulate",
            "--scene",
            "curved",
            "--frames",
            "20",
            "--points-per-frame",
            "2000",
            "--seed",
            "5",
            "--out",
            s(&dataset),
        ],
        Duration::from_secs(300),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let mcap = tmp.path().join("run.mcap");
    let args = [
        "-q",
        "run",
        "--dataset",
        s(&dataset),
        "--config",
        s(&config),
    ];
    let mut run_args = args.to_vec();
    run_args.extend(["--out", s(&mcap), "--timeout", "300"]);
    let out = pssba_watched(&run_args, Duration::from_secs(400));
    assert!(out.status.success(), "{}", stderr(&out));

    // The trajectory: the recorded final poses, stamped as the frames.
    let recording = pssba_recording::read_recording_parts(&mcap).expect("recording");
    assert_eq!(recording.optimized.len(), 20);
    let tum = pssba_io::read_tum(tmp.path().join("run.tum")).expect("run.tum");
    assert_eq!(tum.len(), recording.optimized.len());
    for (k, (line, recorded)) in tum.iter().zip(&recording.optimized).enumerate() {
        assert!(same_pose(&line.world_from_lidar, recorded), "pose {k}");
    }
    let source = pssba_source::open(&mcap, &pssba_source::OpenOptions::default()).expect("input");
    let stamps: Vec<f64> = source
        .frames_from(0)
        .expect("frames")
        .map(|f| f.expect("frame").stamp_s)
        .collect();
    assert_eq!(stamps.len(), tum.len());
    assert!(
        tum.iter()
            .zip(&stamps)
            .all(|(l, s)| (l.stamp - s).abs() < 1e-6)
    );

    // The map: one point per voxel the frames fill, inside that voxel; PLY and PCD alike.
    // The simulated frames move: the map is de-skewed along the final poses.
    let (expected, timed) = expected_voxels(&mcap, &recording.optimized, VOXEL_M);
    assert_eq!(timed, 20, "frames with point times");
    let ply = pssba_io::read_ply(tmp.path().join("run.ply")).expect("run.ply");
    let pcd = pssba_io::read_pcd(tmp.path().join("run.pcd")).expect("run.pcd");
    assert!(expected.len() > 1000, "{} voxels", expected.len());
    assert_eq!(ply.len(), expected.len());
    assert_eq!(ply, pcd);
    let inside = |p: &nalgebra::Point3<f64>| {
        [-1e-4, 0.0, 1e-4]
            .iter()
            .any(|d| expected.contains(&voxel_key(&(p + nalgebra::Vector3::repeat(*d)), VOXEL_M)))
    };
    assert!(
        ply.iter().all(inside),
        "every map point lies in a voxel the frames fill"
    );

    // `pssba export` writes the same files; a coarser voxel gives fewer points.
    let (poses, map) = (tmp.path().join("e.tum"), tmp.path().join("e.pcd"));
    let out = pssba_watched(
        &[
            "-q",
            "export",
            s(&mcap),
            "--poses",
            s(&poses),
            "--map",
            s(&map),
            "--config",
            s(&config),
        ],
        Duration::from_secs(120),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let read = |p: &Path| std::fs::read(p).expect("file");
    assert_eq!(read(&poses), read(&tmp.path().join("run.tum")));
    assert_eq!(read(&map), read(&tmp.path().join("run.pcd")));
    let coarse = tmp.path().join("coarse.ply");
    let out = pssba_watched(
        &[
            "-q",
            "export",
            s(&mcap),
            "--map",
            s(&coarse),
            "--map-voxel",
            "1.0",
        ],
        Duration::from_secs(120),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let coarse = pssba_io::read_ply(&coarse).expect("coarse map");
    assert_eq!(
        coarse.len(),
        expected_voxels(&mcap, &recording.optimized, 1.0).0.len()
    );
    assert!(coarse.len() < ply.len());
}

#[test]
fn export_names_what_it_cannot_do() {
    let tmp = tempfile::tempdir().expect("tmp");
    let missing = tmp.path().join("none.mcap");
    let poses = tmp.path().join("p.tum");
    let cases: [(Vec<&str>, &str); 4] = [
        (vec![s(&missing)], "nothing to export"),
        (vec![s(&missing), "--map", "map.xyz"], "--map map.xyz"),
        (vec![s(&missing), "--poses", s(&poses)], "none.mcap"),
        (
            vec![s(&missing), "--map", "m.ply", "--map-voxel", "0"],
            "voxel size 0",
        ),
    ];
    for (extra, want) in cases {
        let mut args = vec!["export"];
        args.extend(extra.iter().copied());
        let out = pssba_watched(&args, Duration::from_secs(60));
        assert!(!out.status.success(), "{args:?} must fail");
        assert!(stderr(&out).contains(want), "{args:?}: {}", stderr(&out));
    }
    assert!(
        !poses.exists(),
        "nothing is written when the recording is missing"
    );
}
