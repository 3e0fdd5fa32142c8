//! `pssba bench`: a tiny quick run writes JSON with every method for the scene (or the ones
//! `--methods` names), PSS-BA beats the initial poses, and an unknown scene or method is a
//! clear error listing the valid names.

use std::process::{Command, Output};

fn pssba(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pssba"))
        .args(args)
        .output()
        .expect("pssba runs")
}

#[test]
fn bench_quick_curved_writes_json_with_every_method() {
    let tmp = tempfile::tempdir().expect("tmp");
    let json = tmp.path().join("bench.json");
    let markdown = tmp.path().join("bench.md");
    let out = pssba(&[
        "bench",
        "--quick",
        "--scenes",
        "curved",
        "--frames",
        "10",
        "--points-per-frame",
        "6000",
        "--json",
        json.to_str().expect("utf-8"),
        "--markdown",
        markdown.to_str().expect("utf-8"),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("quick variant"), "{stdout}");
    assert!(stdout.contains("PSS-BA(FS)"), "{stdout}");

    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("json written"))
            .expect("valid");
    let rows = doc["rows"].as_array().expect("rows");
    let ape = |method: &str| -> Option<f64> {
        let row = rows
            .iter()
            .find(|r| r["scene"] == "curved" && r["method"] == method)
            .unwrap_or_else(|| panic!("no row for {method}"));
        row["ape_m"].as_f64()
    };
    for method in ["initial", "balm", "point2plane", "pss-ba-fs", "pss-ba"] {
        let _ = ape(method);
    }
    assert_eq!(rows.len(), 5);
    let initial = ape("initial").expect("initial APE");
    let pss_ba = ape("pss-ba").expect("pss-ba APE");
    assert!(initial.is_finite() && pss_ba.is_finite());
    assert!(pss_ba < initial, "pss-ba {pss_ba} vs initial {initial}");
    let md = std::fs::read_to_string(&markdown).expect("markdown written");
    assert!(md.contains("| PSS-BA |"), "{md}");
}

#[test]
fn bench_unknown_scene_lists_valid_names() {
    let out = pssba(&["bench", "--quick", "--scenes", "curved,moon"]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("unknown scene 'moon'"), "{stderr}");
    for name in ["hangar", "curved", "truss", "street", "mbs", "crane"] {
        assert!(stderr.contains(name), "{name} missing from: {stderr}");
    }
}

#[test]
fn bench_methods_runs_only_the_chosen_rows() {
    let tmp = tempfile::tempdir().expect("tmp");
    let json = tmp.path().join("bench.json");
    let out = pssba(&[
        "bench",
        "--quick",
        "--scenes",
        "curved",
        "--frames",
        "10",
        "--points-per-frame",
        "4000",
        "--methods",
        "pss-ba,initial",
        "--json",
        json.to_str().expect("utf-8"),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("json written"))
            .expect("valid");
    let methods: Vec<&str> = doc["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .map(|r| r["method"].as_str().expect("method"))
        .collect();
    // In the tables' order whatever the order given.
    assert_eq!(methods, ["initial", "pss-ba"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("methods initial, pss-ba"), "{stdout}");

    let out = pssba(&["bench", "--quick", "--methods", "pss-ba,slam"]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("slam") && stderr.contains("pss-ba-fs"),
        "{stderr}"
    );
}
