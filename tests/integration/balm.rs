//! `pssba adjust --method balm` and `pssba demo --method balm`: the BALM baseline writes poses
//! and the merged map, reports its outer iterations, and reads its `[balm]` config table.

use crate::cli::{json, pssba, small_dataset, stderr};
use std::path::Path;

#[test]
fn adjust_with_balm_writes_poses_map_and_report() {
    let tmp = tempfile::tempdir().expect("tmp");
    let dir = small_dataset(tmp.path());
    let map = tmp.path().join("balm_map.ply");
    let out = pssba(&[
        "adjust",
        dir.to_str().expect("utf-8"),
        "--method",
        "balm",
        "--map",
        map.to_str().expect("utf-8"),
        "--json",
    ]);
    let summary = json(&out);
    assert!(stderr(&out).contains("planes"), "outer report on stderr");
    assert_eq!(summary["method"], "balm");
    let outer = summary["outer"].as_array().expect("outer reports");
    assert!(!outer.is_empty());
    assert!(outer[0]["plane_voxels"].as_u64().expect("count") > 0);
    let ape = summary["ape"]["optimized_m"].as_f64().expect("ape");
    assert!(ape.is_finite() && ape < 0.5, "APE {ape}");

    // Default output name, same stamps as poses.txt.
    let stamps = |p: &Path| -> Vec<String> {
        std::fs::read_to_string(p)
            .expect("tum")
            .lines()
            .map(|l| l.split_whitespace().next().unwrap_or("").to_owned())
            .collect()
    };
    assert_eq!(
        stamps(&dir.join("poses_balm.txt")),
        stamps(&dir.join("poses.txt"))
    );
    // 10 frames x 4000 points, merged, binary PLY.
    assert!(std::fs::metadata(&map).expect("map written").len() > 40_000 * 12);
}

#[test]
fn balm_table_of_the_config_is_read_and_validated() {
    let tmp = tempfile::tempdir().expect("tmp");
    let demo = |config: &Path| {
        pssba(&[
            "demo",
            "--frames",
            "4",
            "--points",
            "2000",
            "--method",
            "balm",
            "--config",
            config.to_str().expect("utf-8"),
            "--json",
        ])
    };
    let good = tmp.path().join("good.toml");
    std::fs::write(&good, "gamma0_m = 3.0\n[balm]\nmax_outer_iterations = 1\n").expect("write");
    let summary = json(&demo(&good));
    assert_eq!(summary["outer"].as_array().expect("outer").len(), 1);

    let bad = tmp.path().join("bad.toml");
    std::fs::write(&bad, "[balm]\nvoxel_size_m = -1.0\n").expect("write");
    let out = demo(&bad);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("voxel_size_m"), "{}", stderr(&out));

    let typo = tmp.path().join("typo.toml");
    std::fs::write(&typo, "[balm]\nvoxel_size = 1.0\n").expect("write");
    let out = demo(&typo);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("voxel_size"), "{}", stderr(&out));
}
