//! The TUM trajectory parser on any text: an error naming the line, never a panic; every pose
//! accepted is finite.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    if let Ok(poses) = pssba_io::parse_tum(&text, "fuzz.txt") {
        for pose in poses {
            assert!(pose.stamp.is_finite());
            assert!(pose.world_from_lidar.translation.vector.iter().all(|v| v.is_finite()));
        }
    }
});
