//! The command-line tool end to end: demo writes a dataset, adjust improves it, eval agrees,
//! bad input gives clear errors.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub(crate) fn pssba(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pssba"))
        .args(args)
        .output()
        .expect("pssba runs")
}

pub(crate) fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

pub(crate) fn json(out: &Output) -> serde_json::Value {
    assert!(out.status.success(), "failed: {}", stderr(out));
    serde_json::from_slice(&out.stdout).expect("stdout is JSON")
}

/// A small simulated dataset folder written by `pssba demo --write-dataset`.
pub(crate) fn small_dataset(root: &Path) -> PathBuf {
    let dir = root.join("scene");
    let out = pssba(&[
        "-q",
        "demo",
        "--frames",
        "10",
        "--points",
        "4000",
        "--seed",
        "3",
        "--write-dataset",
        dir.to_str().expect("utf-8"),
        "--json",
    ]);
    let summary = json(&out);
    let ape = &summary["ape"];
    assert!(
        ape["optimized_m"].as_f64().expect("number") < ape["initial_m"].as_f64().expect("number")
    );
    dir
}

#[test]
fn adjust_improves_a_simulated_dataset_and_writes_outputs() {
    let tmp = tempfile::tempdir().expect("tmp");
    let dir = small_dataset(tmp.path());
    let poses = tmp.path().join("optimized.txt");
    let map = tmp.path().join("map.ply");
    let out = pssba(&[
        "adjust",
        dir.to_str().expect("utf-8"),
        "--out",
        poses.to_str().expect("utf-8"),
        "--map",
        map.to_str().expect("utf-8"),
        "--json",
    ]);
    let summary = json(&out);
    assert!(
        stderr(&out).contains("gamma_m"),
        "per-scale report on stderr"
    );
    let initial = summary["ape"]["initial_m"].as_f64().expect("ape");
    let optimized = summary["ape"]["optimized_m"].as_f64().expect("ape");
    assert!(
        initial > 0.1 && optimized < 0.05,
        "APE {initial} -> {optimized}"
    );
    assert!(summary["scales"].as_array().expect("scales").len() >= 2);

    // Same stamps, in order, as poses.txt.
    let stamps = |p: &Path| -> Vec<String> {
        std::fs::read_to_string(p)
            .expect("tum")
            .lines()
            .map(|l| l.split_whitespace().next().unwrap_or("").to_owned())
            .collect()
    };
    assert_eq!(stamps(&poses), stamps(&dir.join("poses.txt")));
    assert!(std::fs::metadata(&map).expect("map written").len() > 1000);

    // `eval ape` on the written poses agrees with the summary.
    let ape = json(&pssba(&[
        "eval",
        "ape",
        dir.join("gt.txt").to_str().expect("utf-8"),
        poses.to_str().expect("utf-8"),
        "--json",
    ]));
    assert!((ape["rmse_m"].as_f64().expect("rmse") - optimized).abs() < 1e-6);

    // The adjusted map is sharper than the initial one.
    let occupancy = |p: &Path| -> f64 {
        let v = json(&pssba(&[
            "eval",
            "occupancy",
            dir.to_str().expect("utf-8"),
            "--poses",
            p.to_str().expect("utf-8"),
            "--json",
        ]));
        v["mean_voxels"].as_f64().expect("mean")
    };
    let (before, after) = (occupancy(&dir.join("poses.txt")), occupancy(&poses));
    assert!(after < before, "occupancy {before} -> {after}");
}

#[test]
fn eval_ape_matches_the_evo_fixture() {
    let fixture =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../pssba-eval/tests/fixtures/ape");
    let expected: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(fixture.join("expected.json")).expect("fixture"),
    )
    .expect("json");
    let out = json(&pssba(&[
        "eval",
        "ape",
        fixture.join("gt.txt").to_str().expect("utf-8"),
        fixture.join("est.txt").to_str().expect("utf-8"),
        "--json",
    ]));
    let (got, want) = (
        out["rmse_m"].as_f64().expect("rmse"),
        expected["rmse_m"].as_f64().expect("rmse"),
    );
    assert!((got - want).abs() < 1e-9 * want, "{got} vs evo {want}");
    assert_eq!(out["matched"], expected["matched"]);
}

#[test]
fn missing_folder_is_a_clear_error() {
    let out = pssba(&["adjust", "/nonexistent/pssba-folder"]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("/nonexistent/pssba-folder"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn malformed_pose_file_names_file_and_line() {
    let tmp = tempfile::tempdir().expect("tmp");
    let dir = small_dataset(tmp.path());
    let poses = dir.join("poses.txt");
    let mut text = std::fs::read_to_string(&poses).expect("poses");
    text.push_str("0.95 1 2 three 0 0 0 1\n");
    std::fs::write(&poses, text).expect("write");
    let out = pssba(&["adjust", dir.to_str().expect("utf-8")]);
    assert!(!out.status.success());
    let message = stderr(&out);
    assert!(
        message.contains("poses.txt") && message.contains("line 11"),
        "{message}"
    );
}

#[test]
fn bad_config_names_the_field() {
    let tmp = tempfile::tempdir().expect("tmp");
    let config = tmp.path().join("bad.toml");
    std::fs::write(&config, "gamma_shrink = 0.5\n").expect("write");
    let out = pssba(&[
        "demo",
        "--frames",
        "3",
        "--points",
        "100",
        "--config",
        config.to_str().expect("utf-8"),
    ]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("gamma_shrink"), "{}", stderr(&out));
}

#[test]
fn help_explains_every_subcommand() {
    let out = pssba(&["--help"]);
    let text = String::from_utf8_lossy(&out.stdout);
    for word in ["adjust", "eval", "demo"] {
        assert!(text.contains(word), "{text}");
    }
    let adjust = String::from_utf8_lossy(&pssba(&["adjust", "--help"]).stdout).into_owned();
    assert!(
        adjust.contains("--method") && adjust.contains("pss-ba-fs"),
        "{adjust}"
    );
}
