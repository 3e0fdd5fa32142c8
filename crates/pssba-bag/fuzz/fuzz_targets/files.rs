//! A whole recording file on arbitrary bytes (detected by content: ROS 1 bag, MCAP, sqlite3):
//! open it, stream every message of every topic, and plan and read its frames. The bytes go
//! through a file because the readers stream from files.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pssba_bag::{Bag, Recording, RecordingOptions};

fuzz_target!(|data: &[u8]| {
    let path = std::env::temp_dir().join(format!("pssba-bag-fuzz-{}", std::process::id()));
    if std::fs::write(&path, data).is_err() {
        return;
    }
    if let Ok(bag) = Bag::open(&path) {
        let topics: Vec<String> = bag.topics().iter().map(|t| t.name.clone()).collect();
        if let Ok(messages) = bag.messages(&topics) {
            for message in messages {
                if message.is_err() {
                    break;
                }
            }
        }
    }
    if let Ok(recording) = Recording::open(&path, &RecordingOptions::default()) {
        if let Ok(frames) = recording.frames() {
            for frame in frames {
                if frame.is_err() {
                    break;
                }
            }
        }
    }
    let _ = std::fs::remove_file(&path);
});
