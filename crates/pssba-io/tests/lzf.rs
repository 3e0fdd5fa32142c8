//! LZF codec: hand-computed vectors, corrupt input, round trips.

#![allow(clippy::unwrap_used)]

use pssba_io::lzf::{LzfError, MAX_OFFSET, compress, decompress};

#[test]
fn decodes_hand_computed_vectors() {
    // literal "abc", then copy 6 bytes from 3 back.
    let v = [0x02, b'a', b'b', b'c', 0x80, 0x02];
    assert_eq!(decompress(&v, 9).unwrap(), b"abcabcabc");
    // literal "x", then long copy: 7 + 5 + 2 = 14 bytes from 1 back.
    let v = [0x00, b'x', 0xE0, 0x05, 0x00];
    assert_eq!(decompress(&v, 15).unwrap(), vec![b'x'; 15]);
}

#[test]
fn compresses_repetitive_data() {
    let data: Vec<u8> = (0..10_000u32).map(|k| (k % 7) as u8).collect();
    let c = compress(&data);
    assert!(c.len() < data.len() / 20, "{}", c.len());
    assert_eq!(decompress(&c, data.len()).unwrap(), data);
}

#[test]
fn longest_offset_and_match() {
    let mut x = 12345u32;
    let mut data: Vec<u8> = (0..MAX_OFFSET)
        .map(|_| {
            x = x.wrapping_mul(1_103_515_245).wrapping_add(12345);
            (x >> 16) as u8
        })
        .collect();
    data.extend_from_within(0..600);
    let c = compress(&data);
    assert!(c.len() < MAX_OFFSET + MAX_OFFSET / 32 + 20, "{}", c.len());
    assert_eq!(decompress(&c, data.len()).unwrap(), data);
}

#[test]
fn empty_round_trip() {
    assert!(compress(&[]).is_empty());
    assert_eq!(decompress(&[], 0).unwrap(), Vec::<u8>::new());
}

#[test]
fn corrupt_inputs_are_errors() {
    // literal run claims 4 bytes, only 2 present
    assert!(matches!(
        decompress(&[0x03, 1, 2], 4),
        Err(LzfError::Truncated { .. })
    ));
    // back-reference missing its offset byte
    assert!(matches!(
        decompress(&[0x00, 1, 0x20], 4),
        Err(LzfError::Truncated { .. })
    ));
    // long back-reference missing both bytes
    assert!(matches!(
        decompress(&[0x00, 1, 0xE0], 40),
        Err(LzfError::Truncated { .. })
    ));
    // reference into an empty output (found by proptest)
    assert!(matches!(
        decompress(&[32, 0, 0], 0),
        Err(LzfError::BadOffset {
            distance: 1,
            available: 0,
            ..
        })
    ));
    // reference before the start of the output
    assert!(matches!(
        decompress(&[0x00, 1, 0x20, 0x05], 4),
        Err(LzfError::BadOffset { .. })
    ));
    // decodes to more than expected
    assert!(matches!(
        decompress(&[0x02, 1, 2, 3], 2),
        Err(LzfError::SizeMismatch { overflow: true, .. })
    ));
    // decodes to less than expected
    assert!(matches!(
        decompress(&[0x02, 1, 2, 3], 5),
        Err(LzfError::SizeMismatch {
            overflow: false,
            ..
        })
    ));
}

proptest::proptest! {
    #[test]
    fn round_trip(data in proptest::collection::vec(0u8..4, 0..3000)) {
        let c = compress(&data);
        proptest::prop_assert!(c.len() <= data.len() + data.len() / 32 + 1);
        proptest::prop_assert_eq!(decompress(&c, data.len()).unwrap(), data);
    }

    #[test]
    fn round_trip_any_bytes(data in proptest::collection::vec(proptest::num::u8::ANY, 0..2000)) {
        let c = compress(&data);
        proptest::prop_assert_eq!(decompress(&c, data.len()).unwrap(), data);
    }

    #[test]
    fn garbage_never_panics(data in proptest::collection::vec(proptest::num::u8::ANY, 0..200), n in 0usize..5000) {
        let _ = decompress(&data, n);
    }
}
