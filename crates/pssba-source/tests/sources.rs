//! The registry and the sources, through the public interface.

use pssba_source::{InputSpec, OpenOptions, SimSpec, SourceError};
use std::path::Path;

/// Inputs the fuzzers (crates/pssba-system/fuzz) once crashed on: each is now a clear error
/// from both readers of our recordings.
#[test]
fn fuzz_findings_are_clear_errors() {
    let dir =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/system_fuzz_findings");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).expect("findings folder") {
        let path = entry.expect("entry").path();
        let summary = pssba_recording::read_recording(&path);
        assert!(summary.is_err(), "{}", path.display());
        let replay = pssba_source::RecordedRun::open(&path).and_then(|run| {
            run.frames()?.collect::<pssba_source::Result<Vec<_>>>()?;
            Ok(())
        });
        assert!(replay.is_err(), "{}", path.display());
        n += 1;
    }
    assert!(n > 0);
}

#[test]
fn a_simulated_source_knows_its_size_up_front() {
    let spec = InputSpec::Simulated(SimSpec {
        frames: 3,
        points_per_frame: 500,
        seed: 1,
    });
    let source = spec.open().expect("opens");
    assert_eq!(source.len(), Some(3));
    let max = source.max_points().expect("known");
    let frames = source.read_all().expect("frames");
    assert_eq!(frames.iter().map(|f| f.points.len()).max(), Some(max));
    // Starting again from frame 2 gives frame 2.
    let again: Vec<_> = source.frames_from(2).expect("from 2").collect();
    assert_eq!(again.len(), 1);
    let frame = again[0].as_ref().expect("frame");
    assert_eq!(frame.points, frames[2].points);
}

#[test]
fn a_missing_input_is_said_once() {
    let error = pssba_source::open(Path::new("/nonexistent"), &OpenOptions::default())
        .expect_err("missing");
    assert!(matches!(error, SourceError::NotFound { .. }));
    assert_eq!(error.to_string(), "/nonexistent: no such file or folder");
}

#[test]
fn an_unknown_input_lists_what_each_source_looked_for() {
    let dir = tempfile::tempdir().expect("tempdir");
    let error = pssba_source::open(dir.path(), &OpenOptions::default()).expect_err("unknown");
    let text = error.to_string();
    for kind in pssba_source::registry::SOURCES {
        assert!(
            text.contains(kind.name) && text.contains(kind.looks_for),
            "{text}"
        );
    }
    let file = dir.path().join("notes.txt");
    std::fs::write(&file, "not a recording").expect("write");
    let text = pssba_source::open(&file, &OpenOptions::default())
        .expect_err("unknown")
        .to_string();
    assert!(text.contains("KITTI odometry sequence"), "{text}");
}

#[test]
fn a_dataset_folder_is_recognised_and_read_from_any_frame() {
    let dir = tempfile::tempdir().expect("tempdir");
    let frames = pssba_source::simulated_frames(&SimSpec {
        frames: 4,
        points_per_frame: 200,
        seed: 2,
    });
    let poses: Vec<_> = frames
        .iter()
        .map(|f| pssba_io::StampedPose::new(f.stamp_s, f.world_from_lidar))
        .collect();
    let points: Vec<_> = frames.iter().map(|f| f.points.clone()).collect();
    pssba_io::Dataset::write(
        dir.path(),
        &points,
        &poses,
        None,
        pssba_io::PcdEncoding::Binary,
    )
    .expect("dataset");
    let kind = pssba_source::detect(dir.path()).expect("recognised");
    assert_eq!(kind.name, "dataset folder");
    let source = pssba_source::open(dir.path(), &OpenOptions::default()).expect("opens");
    assert_eq!((source.len(), source.max_points()), (Some(4), Some(200)));
    let all = source.read_all().expect("all");
    let from_3: Vec<_> = source
        .frames_from(3)
        .expect("from 3")
        .collect::<pssba_source::Result<_>>()
        .expect("frames");
    assert_eq!(from_3.len(), 1);
    assert_eq!(from_3[0].points, all[3].points);
    assert_eq!(from_3[0].world_from_lidar, all[3].world_from_lidar);
}
