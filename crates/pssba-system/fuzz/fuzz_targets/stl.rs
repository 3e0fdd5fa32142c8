//! The STL reader (ascii and binary) on any bytes: an error, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = pssba_io::read_stl_from_bytes(data, std::path::Path::new("fuzz.stl"));
});
