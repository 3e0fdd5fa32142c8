//! Dataset folder: write, open, load.

#![allow(clippy::unwrap_used)]

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use pssba_io::{Dataset, IoError, PcdEncoding, StampedPose, write_pcd, write_tum};

fn frames(n: usize) -> Vec<Vec<Point3<f64>>> {
    (0..n)
        .map(|k| {
            (0..100 + k)
                .map(|i| Point3::new(i as f64 * 0.5, k as f64, -1.25))
                .collect()
        })
        .collect()
}

fn poses(n: usize, shift: f64) -> Vec<StampedPose> {
    (0..n)
        .map(|k| {
            let rot = UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.0, 0.1 * k as f64));
            let t = Translation3::new(k as f64 + shift, 0.5, 0.0);
            StampedPose::new(0.1 * k as f64, Isometry3::from_parts(t, rot))
        })
        .collect()
}

fn close(a: &[StampedPose], b: &[StampedPose]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(p, q)| {
            let d = p.world_from_lidar.inverse() * q.world_from_lidar;
            (p.stamp - q.stamp).abs() < 1e-9
                && d.translation.vector.norm() < 1e-8
                && d.rotation.angle() < 1e-8
        })
}

#[test]
fn write_open_load() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("ds");
    let (f, init, gt) = (frames(4), poses(4, 0.0), poses(4, 0.01));
    for (k, enc) in [
        PcdEncoding::Ascii,
        PcdEncoding::Binary,
        PcdEncoding::BinaryCompressed,
    ]
    .into_iter()
    .enumerate()
    {
        let root = root.join(k.to_string());
        let gt_arg = (k != 1).then_some(gt.as_slice());
        let written = Dataset::write(&root, &f, &init, gt_arg, enc).unwrap();
        std::fs::write(root.join("meta.json"), "{ not even json").unwrap();
        let ds = Dataset::open(&root).unwrap();
        assert_eq!(ds, written);
        assert_eq!(ds.len(), 4);
        assert_eq!(ds.frame_paths[2], root.join("frames/000002.pcd"));
        assert!(close(&ds.initial, &init));
        assert_eq!(ds.ground_truth.is_some(), k != 1);
        if let Some(g) = &ds.ground_truth {
            assert!(close(g, &gt));
        }
        for (i, frame) in f.iter().enumerate() {
            assert_eq!(&ds.load_frame(i).unwrap(), frame, "{enc}");
        }
        let e = ds.load_frame(4).unwrap_err();
        assert!(
            matches!(
                e,
                IoError::FrameIndex {
                    index: 4,
                    count: 4,
                    ..
                }
            ),
            "{e}"
        );
        // Refuses to overwrite.
        let msg = Dataset::write(&root, &f, &init, None, enc)
            .unwrap_err()
            .to_string();
        assert!(msg.contains("already exists"), "{msg}");
    }
}

#[test]
fn frames_sorted_by_name_and_non_pcd_ignored() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    std::fs::create_dir(root.join("frames")).unwrap();
    for (name, z) in [("b.pcd", 2.0), ("a.pcd", 1.0), ("c.PCD", 3.0)] {
        let pts = [Point3::new(0.0, 0.0, z)];
        write_pcd(root.join("frames").join(name), &pts, PcdEncoding::Binary).unwrap();
    }
    std::fs::write(root.join("frames/notes.txt"), "x").unwrap();
    write_tum(root.join("poses.txt"), &poses(3, 0.0)).unwrap();
    let ds = Dataset::open(root).unwrap();
    let zs: Vec<f64> = (0..3).map(|k| ds.load_frame(k).unwrap()[0].z).collect();
    assert_eq!(zs, [1.0, 2.0, 3.0]);
    assert!(ds.ground_truth.is_none());
}

#[track_caller]
fn open_err(root: &std::path::Path, wanted: &str) {
    let msg = Dataset::open(root).unwrap_err().to_string();
    assert!(msg.contains(wanted), "{msg:?} lacks {wanted:?}");
    assert!(msg.contains(&root.display().to_string()), "{msg}");
}

#[test]
fn open_errors() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    open_err(root, "dataset: missing folder frames/");
    std::fs::create_dir(root.join("frames")).unwrap();
    open_err(root, "frames: dataset: no .pcd files");
    write_pcd(root.join("frames/000000.pcd"), &[], PcdEncoding::Binary).unwrap();
    write_pcd(root.join("frames/000001.pcd"), &[], PcdEncoding::Binary).unwrap();
    open_err(root, "dataset: missing poses.txt");
    write_tum(root.join("poses.txt"), &poses(3, 0.0)).unwrap();
    open_err(
        root,
        "poses.txt: dataset: has 3 poses but frames/ has 2 .pcd files",
    );
    write_tum(root.join("poses.txt"), &poses(2, 0.0)).unwrap();
    std::fs::write(root.join("gt.txt"), "0 1 2 3 0 0 0 1\n").unwrap();
    open_err(
        root,
        "gt.txt: dataset: has 1 poses but frames/ has 2 .pcd files",
    );
    std::fs::write(root.join("gt.txt"), "0 1 2 3 0 0 0 1\n0 1 2\n").unwrap();
    open_err(root, "gt.txt: line 2: expected 8 numbers");
    std::fs::remove_file(root.join("gt.txt")).unwrap();
    assert_eq!(Dataset::open(root).unwrap().len(), 2);
}

#[test]
fn write_rejects_bad_input_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("ds");
    let enc = PcdEncoding::Binary;
    let msg = Dataset::write(&root, &frames(3), &poses(2, 0.0), None, enc)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("poses.txt: 2 poses given for 3 frames"),
        "{msg}"
    );
    let gt = poses(4, 0.0);
    let msg = Dataset::write(&root, &frames(3), &poses(3, 0.0), Some(&gt), enc)
        .unwrap_err()
        .to_string();
    assert!(msg.contains("gt.txt: 4 poses given for 3 frames"), "{msg}");
    let mut bad = poses(3, 0.0);
    bad[1].stamp = f64::NAN;
    let msg = Dataset::write(&root, &frames(3), &bad, None, enc)
        .unwrap_err()
        .to_string();
    assert!(msg.contains("poses.txt: pose 1"), "{msg}");
    assert!(Dataset::write(&root, &[], &[], None, enc).is_err());
    assert!(!root.exists());
}
