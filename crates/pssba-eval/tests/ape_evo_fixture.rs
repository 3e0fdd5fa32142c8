//! Cross-check of `ape_translation` against evo (see fixtures/ape/README.md).

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use pssba_eval::{DEFAULT_MAX_DIFF_S, ape_translation};

fn fixture_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/ape")
}

/// Minimal TUM parser: `stamp tx ty tz qx qy qz qw`, `#` comments.
fn read_tum(path: &Path) -> Vec<(f64, Isometry3<f64>)> {
    let text = std::fs::read_to_string(path).expect("read TUM file");
    text.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(|line| {
            let v: Vec<f64> = line
                .split_whitespace()
                .map(|s| s.parse().expect("float"))
                .collect();
            assert_eq!(v.len(), 8, "TUM line needs 8 values: {line}");
            let q = UnitQuaternion::from_quaternion(Quaternion::new(v[7], v[4], v[5], v[6]));
            (
                v[0],
                Isometry3::from_parts(Translation3::new(v[1], v[2], v[3]), q),
            )
        })
        .collect()
}

/// Pulls `"key": <number>` out of the flat fixture JSON (no serde needed).
fn json_number(json: &str, key: &str) -> f64 {
    let pat = format!("\"{key}\":");
    let start = json.find(&pat).expect("key present") + pat.len();
    let rest = &json[start..];
    let end = rest.find([',', '}', '\n']).expect("value end");
    rest[..end].trim().parse().expect("number")
}

#[test]
fn matches_evo_ape_on_fixture() {
    let dir = fixture_dir();
    let gt = read_tum(&dir.join("gt.txt"));
    let est = read_tum(&dir.join("est.txt"));
    let json = std::fs::read_to_string(dir.join("expected.json")).expect("read expected.json");

    let res = ape_translation(&gt, &est, DEFAULT_MAX_DIFF_S).expect("APE");

    assert_eq!(res.matched as f64, json_number(&json, "matched"));
    assert_eq!(res.matched, res.errors_m.len());
    for (key, ours) in [
        ("rmse_m", res.rmse_m),
        ("mean_m", res.mean_m),
        ("median_m", res.median_m),
        ("max_m", res.max_m),
        ("min_m", res.min_m),
        ("std_m", res.std_m),
    ] {
        let evo = json_number(&json, key);
        let rel = ((ours - evo) / evo).abs();
        println!("{key}: ours {ours:.17} evo {evo:.17} rel {rel:e}");
        assert!(
            rel < 1e-9,
            "{key}: ours {ours:.17} evo {evo:.17} rel {rel:e}"
        );
    }
    // The extra estimate pose (index 13, 1001.25 s) must not be used.
    assert!(res.pairs.iter().all(|&(_, e)| e != 13));
}
