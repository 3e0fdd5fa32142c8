//! The readers against bags written by an independent writer (the `rosbags` Python package,
//! `tools/make_bag_fixtures.py`, fixtures in `tests/fixtures/bags/`, described in its README).

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Point3};
use pssba_bag::{Bag, BagError, Container, ExtrinsicSource, Recording, RecordingOptions};

/// Every bag stamp is this many ns after the source folder's TUM stamp.
const STAMP_OFFSET_NS: i64 = 1_700_000_000_000_000_000;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/bags")
}

fn source() -> pssba_io::Dataset {
    pssba_io::Dataset::open(fixtures().join("source")).expect("source folder")
}

fn source_frame(k: usize) -> Vec<Point3<f64>> {
    source().load_frame(k).expect("source frame")
}

fn expected_odometry_poses() -> Vec<Isometry3<f64>> {
    pssba_io::read_tum(fixtures().join("expected_odometry_world_from_lidar.txt"))
        .expect("expected poses")
        .into_iter()
        .map(|p| p.world_from_lidar)
        .collect()
}

fn assert_pose_near(a: &Isometry3<f64>, b: &Isometry3<f64>, what: &str) {
    let t = (a.translation.vector - b.translation.vector).norm();
    let r = a.rotation.angle_to(&b.rotation);
    assert!(t < 1e-8 && r < 1e-8, "{what}: {t} m, {r} rad apart");
}

/// Reads every frame and checks stamps, points (exactly, NaN dropped) and poses.
fn check_recording(
    path: &Path,
    expected_poses: &[Isometry3<f64>],
    non_finite_per_frame: Option<usize>,
) {
    let recording = Recording::open(path, &RecordingOptions::default()).expect("opens");
    assert_eq!(recording.frames.len(), 20, "{}", path.display());
    assert_eq!(recording.skipped.total(), 0);
    let frames: Vec<_> = recording
        .frames()
        .expect("stream")
        .collect::<Result<_, _>>()
        .expect("frames");
    assert_eq!(frames.len(), 20);
    for (k, frame) in frames.iter().enumerate() {
        assert_eq!(frame.stamp_ns, STAMP_OFFSET_NS + k as i64 * 100_000_000);
        assert_eq!(
            frame.points,
            source_frame(k),
            "frame {k} of {}",
            path.display()
        );
        if let Some(n) = non_finite_per_frame {
            assert_eq!(frame.non_finite, n);
        }
        assert_pose_near(
            &frame.world_from_lidar,
            &expected_poses[k],
            &format!("pose {k}"),
        );
    }
}

#[test]
fn ros1_lz4_pointcloud2_with_odometry_and_tf_static_extrinsic() {
    let path = fixtures().join("ros1_lz4.bag");
    let bag = Bag::open(&path).expect("opens");
    assert_eq!(bag.container(), Container::Ros1);
    let counts: Vec<(&str, u64)> = bag
        .topics()
        .iter()
        .map(|t| (t.name.as_str(), t.count))
        .collect();
    assert_eq!(
        counts,
        [("/Odometry", 49), ("/points_raw", 20), ("/tf_static", 1)]
    );
    let recording = Recording::open(&path, &RecordingOptions::default()).expect("opens");
    assert_eq!(
        recording.extrinsic_source,
        ExtrinsicSource::Tf {
            body: "body".into(),
            lidar: "livox_frame".into()
        }
    );
    let t = recording.extrinsic.translation.vector;
    assert!((t - nalgebra::Vector3::new(0.10, -0.05, 0.20)).norm() < 1e-12);
    check_recording(&path, &expected_odometry_poses(), Some(3));
}

#[test]
fn ros1_bz2_livox_custom_msg_with_pose_stamped() {
    let path = fixtures().join("ros1_bz2_livox.bag");
    let initial: Vec<_> = source()
        .initial
        .iter()
        .map(|p| p.world_from_lidar)
        .collect();
    check_recording(&path, &initial, Some(0));
    let recording = Recording::open(&path, &RecordingOptions::default()).expect("opens");
    assert_eq!(recording.extrinsic_source, ExtrinsicSource::AssumedIdentity);
}

#[test]
fn rosbag2_mcap_folder_organized_float64() {
    let path = fixtures().join("ros2_mcap");
    assert_eq!(
        Bag::open(&path).expect("opens").container(),
        Container::Rosbag2Mcap
    );
    let initial: Vec<_> = source()
        .initial
        .iter()
        .map(|p| p.world_from_lidar)
        .collect();
    check_recording(&path, &initial, None);
    // The same file, bare.
    let bare = path.join("ros2_mcap.mcap");
    assert_eq!(
        Bag::open(&bare).expect("opens").container(),
        Container::Mcap
    );
    check_recording(&bare, &initial, None);
}

#[test]
fn rosbag2_sqlite3_livox2_with_odometry_and_tf_static() {
    let path = fixtures().join("ros2_sqlite3");
    assert_eq!(
        Bag::open(&path).expect("opens").container(),
        Container::Rosbag2Sqlite
    );
    check_recording(&path, &expected_odometry_poses(), Some(0));
}

#[test]
fn big_endian_cloud_and_bare_mcap_small_bags() {
    let initial: Vec<_> = source()
        .initial
        .iter()
        .map(|p| p.world_from_lidar)
        .collect();
    for name in ["bigendian.bag", "ros2.mcap"] {
        let path = fixtures().join("small").join(name);
        let recording = Recording::open(&path, &RecordingOptions::default()).expect("opens");
        let frames: Vec<_> = recording
            .frames()
            .expect("stream")
            .collect::<Result<_, _>>()
            .expect("frames");
        assert_eq!(frames.len(), 3, "{name}");
        for (k, frame) in frames.iter().enumerate() {
            assert_eq!(frame.points, source_frame(k)[..60], "{name} frame {k}");
            assert_pose_near(&frame.world_from_lidar, &initial[k], name);
        }
    }
}

/// The error text of reading every frame of a recording.
fn error_of(path: &Path, options: &RecordingOptions) -> String {
    let result = Recording::open(path, options).and_then(|r| {
        r.frames()?
            .collect::<Result<Vec<_>, BagError>>()
            .map(|_| ())
    });
    format!("{}", result.expect_err("must fail"))
}

#[test]
fn bad_recordings_name_file_topic_and_message() {
    let small = fixtures().join("small");
    let defaults = RecordingOptions::default();
    let no_z = error_of(&small.join("no_z.bag"), &defaults);
    assert!(
        no_z.contains(
            "no_z.bag: topic /points (sensor_msgs/PointCloud2), message 0: the fields lack z"
        ),
        "{no_z}"
    );
    let row = error_of(&small.join("bad_row_step.bag"), &defaults);
    assert!(
        row.contains("message 0: row_step") && row.contains("disagrees with the"),
        "{row}"
    );
    let nan = error_of(&small.join("nan_pose.bag"), &defaults);
    assert!(
        nan.contains("topic /pose (geometry_msgs/PoseStamped), message 1: pose: x is NaN"),
        "{nan}"
    );
    let overlap = error_of(&small.join("no_overlap.bag"), &defaults);
    assert!(
        overlap.contains("no frame has a pose") && overlap.contains("3 outside the pose range"),
        "{overlap}"
    );
    let wrong_type = RecordingOptions {
        points_topic: Some("/pose".into()),
        ..RecordingOptions::default()
    };
    let wrong = error_of(&small.join("bigendian.bag"), &wrong_type);
    assert!(
        wrong.contains("--points-topic /pose is geometry_msgs/PoseStamped, not a point cloud type"),
        "{wrong}"
    );
    let missing = RecordingOptions {
        poses_topic: Some("/odom".into()),
        ..RecordingOptions::default()
    };
    let none = error_of(&small.join("bigendian.bag"), &missing);
    assert!(
        none.contains("no topic /odom; the recording has: /points"),
        "{none}"
    );
}

#[test]
fn truncated_and_unknown_compression_bags_are_clear_errors() {
    let dir = tempfile::tempdir().expect("tempdir");
    let bytes = std::fs::read(fixtures().join("ros1_lz4.bag")).expect("read");
    for cut in [10, 5000, bytes.len() / 2, bytes.len() - 100] {
        let path = dir.path().join(format!("cut_{cut}.bag"));
        std::fs::write(&path, &bytes[..cut]).expect("write");
        let error = error_of(&path, &RecordingOptions::default());
        assert!(
            error.contains(&format!("cut_{cut}.bag")) && error.contains("truncated"),
            "{error}"
        );
    }
    let needle = b"compression=lz4";
    let mut patched = bytes.clone();
    let mut n = 0;
    for k in 0..patched.len() - needle.len() {
        if &patched[k..k + needle.len()] == needle {
            patched[k + 12..k + 15].copy_from_slice(b"xz9");
            n += 1;
        }
    }
    assert!(n > 0);
    let path = dir.path().join("xz.bag");
    std::fs::write(&path, &patched).expect("write");
    let error = error_of(&path, &RecordingOptions::default());
    assert!(
        error.contains("compression 'xz9'; supported: none, bz2, lz4"),
        "{error}"
    );
}

#[test]
fn frame_selection_by_time_and_by_index() {
    let path = fixtures().join("ros1_bz2_livox.bag");
    let by_index = RecordingOptions {
        frames: Some(5..9),
        ..RecordingOptions::default()
    };
    let r = Recording::open(&path, &by_index).expect("opens");
    let indices: Vec<u64> = r.frames.iter().map(|f| f.message_index).collect();
    assert_eq!(indices, [5, 6, 7, 8]);
    assert_eq!(r.skipped.not_selected, 16);
    // The bag starts at the first message (the first cloud and pose, at offset + 0 s).
    let by_time = RecordingOptions {
        start_s: Some(0.45),
        duration_s: Some(0.3),
        ..RecordingOptions::default()
    };
    let r = Recording::open(&path, &by_time).expect("opens");
    let indices: Vec<u64> = r.frames.iter().map(|f| f.message_index).collect();
    assert_eq!(indices, [5, 6, 7]);
}

#[test]
fn a_pose_gap_larger_than_allowed_skips_frames() {
    // Odometry at 25 Hz: gaps of 40 ms; an allowed gap of 30 ms keeps only exact matches.
    let path = fixtures().join("ros1_lz4.bag");
    let tight = RecordingOptions {
        max_pose_gap_s: 0.03,
        ..RecordingOptions::default()
    };
    let r = Recording::open(&path, &tight).expect("opens");
    assert_eq!(r.frames.len(), 10);
    assert_eq!(r.skipped.pose_gap, 10);
}

#[test]
fn clouds_in_the_world_frame_are_taken_back_into_the_sensor_frame() {
    // As FAST-LIO's /cloud_registered: frame_id is the pose topic's parent (camera_init).
    let path = fixtures().join("small/cloud_registered.bag");
    let recording = Recording::open(&path, &RecordingOptions::default()).expect("opens");
    assert!(recording.clouds_in_world);
    let frames: Vec<_> = recording
        .frames()
        .expect("stream")
        .collect::<Result<_, _>>()
        .expect("frames");
    assert_eq!(frames.len(), 3);
    for (k, frame) in frames.iter().enumerate() {
        let source = &source_frame(k)[..60];
        assert_eq!(frame.points.len(), source.len());
        // The world coordinates were stored as f32 (~1 um at 13 m).
        let worst = frame
            .points
            .iter()
            .zip(source)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(worst < 1e-5, "frame {k}: {worst} m");
    }
}

/// Inputs the fuzzers found crashing (fixed since): each must give an error, not a panic or
/// an abort. tests/fixtures/fuzz_findings/NAME says in its name what it exercised.
#[test]
fn fuzz_findings_are_clear_errors() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/fuzz_findings");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).expect("findings folder") {
        let path = entry.expect("entry").path();
        let result = Bag::open(&path).and_then(|bag| {
            let topics: Vec<String> = bag.topics().iter().map(|t| t.name.clone()).collect();
            bag.messages(&topics)?
                .collect::<Result<Vec<_>, _>>()
                .map(|_| ())
        });
        assert!(result.is_err(), "{}", path.display());
        n += 1;
    }
    assert!(n > 0);
}
