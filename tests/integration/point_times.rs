//! Point times as the common drivers record them, read by `pssba inspect` and `pssba import`
//! from bags written by the independent `rosbags` package (tests/fixtures/bags/moving, see its
//! README: one bag per driver convention from one moving source folder, a wrong type, a NaN).

use crate::system::{pssba_watched, s, stderr};
use std::path::{Path, PathBuf};
use std::time::Duration;

fn moving() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/bags/moving")
}

fn pssba(args: &[&str]) -> std::process::Output {
    pssba_watched(args, Duration::from_secs(120))
}

/// A bag, the convention `pssba inspect` must report (field, unit, origin), and how far its
/// decoded times may be from the source's: the stored value's own rounding (README).
struct Convention {
    bag: &'static str,
    field: &'static str,
    unit: &'static str,
    origin: &'static str,
    tolerance_s: f64,
}

const CONVENTIONS: [Convention; 5] = [
    // u32 ns after the stamp: 0.5 ns, then the f32 the times travel in (3.7 ns at 0.1 s).
    Convention {
        bag: "ouster.bag",
        field: "t",
        unit: "Ns",
        origin: "HeaderStamp",
        tolerance_s: 1e-8,
    },
    // The source's own f32 s: exact.
    Convention {
        bag: "velodyne.bag",
        field: "time",
        unit: "S",
        origin: "HeaderStamp",
        tolerance_s: 0.0,
    },
    // f64 absolute s at 1.7e9 s: half of its 0.24 us step.
    Convention {
        bag: "hesai",
        field: "timestamp",
        unit: "S",
        origin: "Epoch",
        tolerance_s: 1.3e-7,
    },
    // f64 absolute ns at 1.7e18 ns: half of its 256 ns step.
    Convention {
        bag: "livox_driver2.bag",
        field: "timestamp",
        unit: "Ns",
        origin: "Epoch",
        tolerance_s: 1.4e-7,
    },
    // Livox CustomMsg u32 ns after the message's timebase.
    Convention {
        bag: "livox_custom",
        field: "offset_time",
        unit: "Ns",
        origin: "Timebase",
        tolerance_s: 1e-8,
    },
];

#[test]
fn every_driver_convention_is_detected_and_imported_to_the_source_times() {
    let source = pssba_io::Dataset::open(moving().join("source")).expect("source folder");
    let dir = tempfile::tempdir().expect("tempdir");
    for c in &CONVENTIONS {
        let bag = moving().join(c.bag);
        let out = pssba(&["inspect", s(&bag), "--json"]);
        assert!(out.status.success(), "{}: {}", c.bag, stderr(&out));
        let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
        assert_eq!(report["frames"]["frames"], source.len(), "{}", c.bag);
        let time = &report["frames"]["point_time"];
        assert_eq!(time["field"], c.field, "{}: {time}", c.bag);
        assert_eq!(time["unit"], c.unit, "{}: {time}", c.bag);
        assert_eq!(time["origin"], c.origin, "{}: {time}", c.bag);
        let (_, source_times) = source.load_frame_with_times(0).expect("frame 0");
        let last = source_times.expect("source times")[..]
            .iter()
            .copied()
            .fold(f32::MIN, f32::max);
        let reported = time["first_frame_s"][1].as_f64().expect("span");
        assert!(
            (reported - f64::from(last)).abs() <= c.tolerance_s + 1e-9,
            "{}: frame 0 ends at {reported} s, the source at {last} s",
            c.bag
        );

        let out_dir = dir.path().join(c.bag.replace('.', "_"));
        let out = pssba(&["-q", "import", s(&bag), "--out", s(&out_dir)]);
        assert!(out.status.success(), "{}: {}", c.bag, stderr(&out));
        let imported = pssba_io::Dataset::open(&out_dir).expect("imported dataset");
        assert_eq!(imported.len(), source.len(), "{}", c.bag);
        let mut worst_s = 0.0_f64;
        for k in 0..source.len() {
            let (points, times) = imported.load_frame_with_times(k).expect("imported frame");
            let (want_points, want_times) = source.load_frame_with_times(k).expect("source");
            assert_eq!(points, want_points, "{} frame {k}", c.bag);
            let (times, want_times) = (times.expect("times"), want_times.expect("times"));
            assert_eq!(times.len(), want_times.len(), "{} frame {k}", c.bag);
            for (t, want) in times.iter().zip(&want_times) {
                worst_s = worst_s.max((f64::from(*t) - f64::from(*want)).abs());
            }
        }
        assert!(
            worst_s <= c.tolerance_s,
            "{}: times up to {worst_s:e} s from the source's (allowed {:e})",
            c.bag,
            c.tolerance_s
        );
    }
}

/// Runs `pssba import` on a bag that must fail, and checks it leaves no frames behind.
fn failed_import(bag: &str, dir: &Path) -> String {
    let out_dir = dir.join(bag.replace('.', "_"));
    let out = pssba(&["-q", "import", s(&moving().join(bag)), "--out", s(&out_dir)]);
    let text = stderr(&out);
    assert!(!out.status.success(), "{bag} imported: {text}");
    assert!(
        !out_dir.join(pssba_io::FRAMES_DIR).exists(),
        "{bag}: a failed import left {}",
        out_dir.join(pssba_io::FRAMES_DIR).display()
    );
    text
}

#[test]
fn bad_point_times_are_refused_naming_the_message_and_field() {
    let dir = tempfile::tempdir().expect("tempdir");
    // A uint8 `time` (plausible ms values): not a type times are read from.
    let text = failed_import("bad_time_type.bag", dir.path());
    assert!(
        text.contains("bad_time_type.bag")
            && text.contains("field time has datatype uint8")
            && text.contains("--point-time none")
            && !text.contains("  float32"),
        "{text}"
    );
    // Frame 0 is fine (inspect reads it), message 1's point 5 is NaN: import names both.
    let inspect = pssba(&["inspect", s(&moving().join("nan_time.bag")), "--json"]);
    assert!(inspect.status.success(), "{}", stderr(&inspect));
    let text = failed_import("nan_time.bag", dir.path());
    assert!(
        text.contains("nan_time.bag")
            && text.contains("/velodyne_points")
            && text.contains("message 1")
            && text.contains("point 5's time is NaN"),
        "{text}"
    );
}
