//! The revised poses over real iceoryx2 shared memory: a final pose that a loop closure moved
//! comes again on `revised_poses` (same layout as `final_poses`, `window` the closing window),
//! apart from the first publication, which `final_poses` subscribers see unchanged.

use nalgebra::{Isometry3, Vector3};
use pssba_client::outputs::{FinalPose, FinalPosePublisher, FinalPoseSubscriber};
use pssba_client::services::create_node;

struct Prefix(String);

impl Drop for Prefix {
    fn drop(&mut self) {
        if let Ok(entries) = std::fs::read_dir("/dev/shm") {
            for entry in entries.flatten() {
                if entry.file_name().to_string_lossy().starts_with(&self.0) {
                    let _ = std::fs::remove_file(entry.path());
                }
            }
        }
    }
}

fn final_pose(sequence: u64, x_m: f64) -> FinalPose {
    FinalPose {
        sequence,
        stamp_s: sequence as f64 * 0.1,
        world_from_lidar: Isometry3::new(Vector3::new(x_m, 0.0, 1.0), Vector3::zeros()),
    }
}

#[test]
fn moved_poses_come_again_on_their_own_service() -> Result<(), Box<dyn std::error::Error>> {
    let prefix = Prefix(format!("pssba-test-{}-revised-", std::process::id()));
    let smooth = create_node(&prefix.0, "smooth")?;
    let outside = create_node(&prefix.0, "outside")?;
    let mut finals = FinalPosePublisher::create(&smooth)?;
    let mut revised = FinalPosePublisher::create_revised(&smooth)?;
    let first = FinalPoseSubscriber::create(&outside)?;
    let again = FinalPoseSubscriber::create_revised(&outside)?;
    finals.publish(0, false, &[final_pose(0, 0.0), final_pose(1, 1.0)])?;
    finals.publish(1, false, &[final_pose(2, 2.0)])?;
    revised.publish(1, false, &[final_pose(1, 1.25)])?;
    finals.end_stream()?;
    revised.end_stream()?;
    let mut seen = Vec::new();
    while let Some(m) = first.receive()? {
        let x_m = if m.end_of_stream == 1 {
            None
        } else {
            Some(
                m.world_from_lidar
                    .to_isometry("test", m.sequence)?
                    .translation
                    .x,
            )
        };
        seen.push((m.sequence, m.end_of_stream, x_m));
    }
    // The first publication is untouched by the revision; the end marker counts it once.
    assert_eq!(
        seen,
        vec![
            (0, 0, Some(0.0)),
            (1, 0, Some(1.0)),
            (2, 0, Some(2.0)),
            (3, 1, None)
        ]
    );
    let m = again.receive()?.expect("the revised pose");
    assert_eq!((m.sequence, m.window, m.end_of_stream), (1, 1, 0));
    assert_eq!(
        m.world_from_lidar.to_isometry("test", 0)?.translation.x,
        1.25
    );
    let end = again.receive()?.expect("the end marker");
    assert_eq!((end.end_of_stream, end.sequence), (1, 1));
    assert!(again.receive()?.is_none());
    Ok(())
}
