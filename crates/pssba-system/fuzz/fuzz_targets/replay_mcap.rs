//! The readers of our own recordings on any bytes: the replay of a `pssba run` MCAP file
//! (`pssba run --input RUN.mcap`: both passes, every frame) and the summary reader of
//! `pssba run`. Both read from a path, so the input goes through a scratch file.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::PathBuf;
use std::sync::OnceLock;

fn scratch() -> &'static PathBuf {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| {
        // In memory when the machine has /dev/shm: the file is written for every input.
        let shm = std::path::Path::new("/dev/shm");
        let dir = if shm.is_dir() { shm.to_path_buf() } else { std::env::temp_dir() };
        dir.join(format!("pssba-fuzz-{}.mcap", std::process::id()))
    })
}

fuzz_target!(|data: &[u8]| {
    let path = scratch();
    if std::fs::write(path, data).is_err() {
        return;
    }
    if let Ok(run) = pssba_source::RecordedRun::open(path)
        && let Ok(frames) = run.frames()
    {
        for frame in frames {
            if frame.is_err() {
                break;
            }
        }
    }
    let _ = pssba_recording::read_recording(path);
});
