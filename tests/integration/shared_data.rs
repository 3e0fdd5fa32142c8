//! Tests on `../shared/data` skip cleanly, and say so, when the folder is absent.

use std::path::PathBuf;

/// `../shared/data/caric` next to the workspace, if present.
pub fn caric_dir() -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/caric");
    dir.is_dir().then_some(dir)
}

#[test]
fn caric_meshes_are_binary_stl_when_present() {
    let Some(dir) = caric_dir() else {
        eprintln!("SKIP: ../shared/data/caric not found (a fresh clone has no shared/ folder)");
        return;
    };
    for name in [
        "mbs.stl",
        "construction_crane_1.stl",
        "construction_crane_2.stl",
    ] {
        let bytes = std::fs::read(dir.join(name)).expect("readable mesh");
        assert!(bytes.len() > 84, "{name} too short");
        let triangles = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
        assert_eq!(
            bytes.len(),
            84 + 50 * triangles,
            "{name}: binary STL size must match its triangle count"
        );
    }
}

#[test]
fn simulate_flies_around_the_mbs_mesh_when_present() {
    let Some(dir) = caric_dir() else {
        eprintln!("SKIP: ../shared/data/caric absent");
        return;
    };
    let tmp = tempfile::tempdir().expect("tmp");
    let out = tmp.path().join("mbs");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_pssba"))
        .args(["-q", "simulate", "--frames", "2", "--seed", "1", "--scene"])
        .arg(dir.join("mbs.stl"))
        .arg("--out")
        .arg(&out)
        .output()
        .expect("pssba runs");
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    let dataset = pssba_io::Dataset::open(&out).expect("opens");
    for k in 0..dataset.len() {
        let points = dataset.load_frame(k).expect("frame").len();
        assert!(points > 3000, "frame {k}: {points} points");
    }
}
