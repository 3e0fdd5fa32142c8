//! `pssba simulate`: writes a dataset folder that `Dataset::open` reads back, deterministic
//! per seed, and bad input is a clear error with a non-zero exit.

use std::path::Path;
use std::process::{Command, Output};

fn pssba(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pssba"))
        .args(args)
        .output()
        .expect("pssba runs")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// `pssba simulate` of 3 frames of `scene` into `dir` with `seed`; asserts success.
fn simulate(scene: &str, dir: &Path, seed: &str, extra: &[&str]) {
    let out_dir = dir.to_str().expect("utf-8");
    let mut args = vec![
        "simulate", "--scene", scene, "--frames", "3", "--seed", seed,
    ];
    args.extend(["--out", out_dir]);
    args.extend(extra);
    let out = pssba(&args);
    assert!(out.status.success(), "{}", stderr(&out));
}

#[test]
fn simulate_writes_a_dataset_that_opens() {
    let tmp = tempfile::tempdir().expect("tmp");
    let dir = tmp.path().join("street");
    simulate("street", &dir, "5", &["--points-per-frame", "5000"]);
    let dataset = pssba_io::Dataset::open(&dir).expect("opens");
    assert_eq!(dataset.len(), 3);
    let gt = dataset.ground_truth.as_ref().expect("gt.txt");
    for (k, (initial, truth)) in dataset.initial.iter().zip(gt).enumerate() {
        assert!((initial.stamp - 0.1 * k as f64).abs() < 1e-9);
        let offset =
            initial.world_from_lidar.translation.vector - truth.world_from_lidar.translation.vector;
        assert!(
            offset.norm() > 1e-6 && offset.norm() < 1.5,
            "noise {}",
            offset.norm()
        );
    }
    let points = dataset.load_frame(2).expect("frame");
    assert!(
        points.len() > 1500 && points.len() <= 5000,
        "{}",
        points.len()
    );
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("meta.json")).expect("meta"))
            .expect("json");
    assert_eq!(meta["scene"]["name"], "street");
    assert_eq!(meta["trajectory"]["kind"], "lawnmower");
    assert_eq!(meta["seed"], 5);
    assert_eq!(meta["pose_noise"]["translation_rms_m"], 0.2);

    // Same seed: byte-identical files; another seed: different frames and poses.
    let again = tmp.path().join("again");
    simulate("street", &again, "5", &["--points-per-frame", "5000"]);
    let other = tmp.path().join("other");
    simulate("street", &other, "6", &["--points-per-frame", "5000"]);
    for file in ["frames/000001.pcd", "poses.txt", "gt.txt", "meta.json"] {
        let read = |d: &Path| std::fs::read(d.join(file)).expect("file");
        assert_eq!(read(&dir), read(&again), "{file} differs for the same seed");
        if file != "gt.txt" && file != "meta.json" {
            assert_ne!(read(&dir), read(&other), "{file} equal for another seed");
        }
    }

    // The folder is never overwritten.
    let out = pssba(&[
        "simulate",
        "--scene",
        "street",
        "--frames",
        "3",
        "--seed",
        "5",
        "--out",
        dir.to_str().expect("utf-8"),
    ]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("refusing to overwrite"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn simulate_reads_an_ascii_stl_scene_and_a_trajectory_override() {
    let tmp = tempfile::tempdir().expect("tmp");
    // A 10 m cube as ASCII STL (12 facets).
    let corner = |i: u8| {
        [
            (i & 1) as f64 * 10.0,
            ((i >> 1) & 1) as f64 * 10.0,
            ((i >> 2) & 1) as f64 * 10.0,
        ]
    };
    let faces = [
        [0, 1, 3, 2],
        [4, 6, 7, 5],
        [0, 4, 5, 1],
        [2, 3, 7, 6],
        [0, 2, 6, 4],
        [1, 5, 7, 3],
    ];
    let mut text = String::from("solid cube\n");
    for f in faces {
        for tri in [[f[0], f[1], f[2]], [f[0], f[2], f[3]]] {
            text.push_str("facet normal 0 0 0\nouter loop\n");
            for i in tri {
                let [x, y, z] = corner(i);
                text.push_str(&format!("vertex {x} {y} {z}\n"));
            }
            text.push_str("endloop\nendfacet\n");
        }
    }
    text.push_str("endsolid cube\n");
    let stl = tmp.path().join("cube.stl");
    std::fs::write(&stl, text).expect("write");
    let dir = tmp.path().join("cube");
    simulate(
        stl.to_str().expect("utf-8"),
        &dir,
        "1",
        &["--trajectory", "helix"],
    );
    let dataset = pssba_io::Dataset::open(&dir).expect("opens");
    assert!(dataset.load_frame(0).expect("frame").len() > 1000);
    let meta = std::fs::read_to_string(dir.join("meta.json")).expect("meta");
    assert!(
        meta.contains("\"helix\"") && meta.contains("\"stl\""),
        "{meta}"
    );
}

#[test]
fn simulate_rejects_bad_input_clearly() {
    let tmp = tempfile::tempdir().expect("tmp");
    let out_dir = tmp.path().join("x");
    let out_dir = out_dir.to_str().expect("utf-8");
    let bad_stl = tmp.path().join("bad.stl");
    std::fs::write(&bad_stl, [1u8; 30]).expect("write");
    let bad_stl = bad_stl.to_str().expect("utf-8");
    let cases: [(&[&str], &str); 6] = [
        (
            &["--scene", "hangar", "--frames", "0"],
            "--frames must be at least 1",
        ),
        (
            &["--scene", "atlantis", "--frames", "2"],
            "hangar, curved, truss, street",
        ),
        (
            &["--scene", "/nonexistent/mesh.stl", "--frames", "2"],
            "/nonexistent/mesh.stl",
        ),
        (
            &["--scene", bad_stl, "--frames", "2"],
            "bad.stl: STL: binary STL truncated",
        ),
        (
            &["--scene", "hangar", "--frames", "2", "--pose-noise", "0.2"],
            "TRANSLATION_M,ROTATION_DEG",
        ),
        (
            &[
                "--scene",
                "hangar",
                "--frames",
                "2",
                "--trajectory",
                "spiral",
            ],
            "lawnmower",
        ),
    ];
    for (args, expected) in cases {
        let mut all = vec!["simulate", "--seed", "1", "--out", out_dir];
        all.extend(args);
        let out = pssba(&all);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(
            stderr(&out).contains(expected),
            "{args:?}: {}",
            stderr(&out)
        );
        assert!(!stderr(&out).contains("panicked"), "{}", stderr(&out));
    }
    let help = String::from_utf8_lossy(&pssba(&["simulate", "--help"]).stdout).into_owned();
    for flag in [
        "--scene",
        "--frames",
        "--seed",
        "--out",
        "--trajectory",
        "--pose-noise",
        "--points-per-frame",
        "--no-ground",
    ] {
        assert!(help.contains(flag), "{flag} missing from --help");
    }
}
