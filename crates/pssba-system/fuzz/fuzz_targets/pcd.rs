//! The PCD reader (ascii, binary, binary_compressed) on any bytes: an error, never a panic,
//! and allocation bounded by the input (a header may claim any size).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(points) = pssba_io::read_pcd_from_bytes(data, "fuzz.pcd") {
        assert!(points.len() <= data.len(), "more points than bytes");
    }
});
