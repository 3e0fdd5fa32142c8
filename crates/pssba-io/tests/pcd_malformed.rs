//! Malformed PCD files give errors that name the file.

#![allow(clippy::unwrap_used)]

mod common;

use common::{F, build, header, sample};
use pssba_io::{IoError, PcdEncoding, read_pcd, read_pcd_from_bytes};

const XYZ: [F; 3] = [F("x", 4, 'F', 1), F("y", 4, 'F', 1), F("z", 4, 'F', 1)];

fn xyz_file(enc: PcdEncoding, n: usize) -> Vec<u8> {
    build(&XYZ, &sample(&XYZ, n).0, enc)
}

#[track_caller]
fn expect_err(bytes: &[u8], wanted: &[&str]) -> IoError {
    let err = read_pcd_from_bytes(bytes, "dir/frame.pcd").expect_err("should fail");
    let msg = err.to_string();
    assert!(msg.starts_with("dir/frame.pcd: "), "{msg}");
    for w in wanted {
        assert!(msg.contains(w), "{msg:?} lacks {w:?}");
    }
    err
}

fn replace(bytes: &[u8], from: &str, to: &str) -> Vec<u8> {
    let (from, to) = (from.as_bytes(), to.as_bytes());
    let at = bytes
        .windows(from.len())
        .position(|w| w == from)
        .expect("pattern");
    [&bytes[..at], to, &bytes[at + from.len()..]].concat()
}

#[test]
fn header_errors() {
    let good = xyz_file(PcdEncoding::Ascii, 3);
    let no_data = replace(&good, "DATA ascii\n", "");
    expect_err(&no_data, &["PCD header: missing DATA line"]);
    let e = expect_err(
        &replace(&good, "TYPE F F F", "TYPE I F F"),
        &["field 'x' has TYPE I, expected F"],
    );
    assert!(matches!(e, IoError::PcdField { .. }));
    expect_err(
        &replace(&good, "SIZE 4 4 4", "SIZE 4 4 2"),
        &["field 'z' has SIZE 2, expected 4 or 8"],
    );
    expect_err(
        &replace(&good, "COUNT 1 1 1", "COUNT 1 2 1"),
        &["field 'y' has COUNT 2, expected 1"],
    );
    expect_err(
        &replace(&good, "FIELDS x y z", "FIELDS x y w"),
        &["PCD header: FIELDS has no 'z'"],
    );
    expect_err(
        &replace(&good, "FIELDS x y z", "FIELDS x y x"),
        &["FIELDS has 'x' more than once"],
    );
    expect_err(
        &replace(&good, "SIZE 4 4 4", "SIZE 4 4"),
        &["SIZE has 2 entries ('4 4') but FIELDS has 3"],
    );
    expect_err(
        &replace(&good, "TYPE F F F", "TYPE F F Q"),
        &["TYPE of field 'z' is 'Q'"],
    );
    expect_err(
        &replace(&good, "SIZE 4 4 4", "SIZE 4 4 x"),
        &["SIZE value 'x' is not a non-negative integer"],
    );
    expect_err(
        &replace(&good, "WIDTH 3", "WIDTH -3"),
        &["WIDTH value '-3'"],
    );
    expect_err(&replace(&good, "HEIGHT 1\n", ""), &["missing HEIGHT line"]);
    expect_err(
        &replace(&good, "DATA ascii", "DATA binary_lz4"),
        &["unsupported DATA kind 'binary_lz4'"],
    );
    let e = expect_err(
        &replace(&good, "POINTS 3", "POINTS 4"),
        &["POINTS 4 != WIDTH*HEIGHT (3*1)"],
    );
    assert!(matches!(
        e,
        IoError::PcdPointCount {
            points: 4,
            width: 3,
            height: 1,
            ..
        }
    ));
}

#[test]
fn ascii_errors_name_the_line() {
    let good = xyz_file(PcdEncoding::Ascii, 3);
    let header_lines = header(&XYZ, 3, "ascii").lines().count();
    let bad = replace(&good, "100.125", "1OO.125");
    let line = format!(
        "line {}: PCD ascii data: field 'y' value '1OO.125' is not a number",
        header_lines + 2
    );
    expect_err(&bad, &[&line]);
    let short = replace(&good, " 100.125", "");
    expect_err(
        &short,
        &[
            &format!("line {}", header_lines + 2),
            "expected 3 values, found 2",
        ],
    );
    let last_line = good[..good.len() - 1]
        .iter()
        .rposition(|&b| b == b'\n')
        .unwrap();
    let fewer = &good[..last_line + 1];
    expect_err(
        fewer,
        &["PCD ascii data truncated: expected 3 points, found 2"],
    );
    let more = [&good[..], b"1 2 3\n"].concat();
    expect_err(&more, &["more than POINTS = 3 points"]);
}

#[test]
fn binary_errors() {
    let good = xyz_file(PcdEncoding::Binary, 5);
    expect_err(
        &good[..good.len() - 1],
        &["PCD binary data truncated: expected 60 bytes, found 59"],
    );
    let huge = replace(&good, "WIDTH 5", "WIDTH 100000000000");
    let huge = replace(&huge, "POINTS 5", "POINTS 100000000000");
    expect_err(&huge, &["binary data truncated"]);
}

#[test]
fn compressed_errors() {
    let good = xyz_file(PcdEncoding::BinaryCompressed, 50);
    let header_len = header(&XYZ, 50, "binary_compressed").len();
    let compressed =
        u32::from_le_bytes(good[header_len..header_len + 4].try_into().unwrap()) as usize;
    assert_eq!(good.len(), header_len + 8 + compressed);
    // Payload cut short.
    expect_err(
        &good[..good.len() - 3],
        &["PCD binary_compressed data truncated: expected"],
    );
    // Size words cut short.
    expect_err(&good[..header_len + 5], &["expected 8 bytes, found 5"]);
    // Uncompressed size disagreeing with POINTS.
    let mut bad = good.clone();
    bad[header_len + 4] ^= 1;
    expect_err(&bad, &["uncompressed size", "!= POINTS*record size 600"]);
    // Corrupt LZF: a back-reference before the start of the output.
    let mut bad = good.clone();
    bad[header_len + 8] = 0x3f;
    bad[header_len + 9] = 0xff;
    let e = expect_err(&bad, &["PCD binary_compressed: LZF decompression failed"]);
    assert!(matches!(e, IoError::PcdLzf { .. }));
    // Corrupt LZF: random garbage never panics.
    for seed in 0..200u32 {
        let mut bad = good.clone();
        let k = header_len + 8 + (seed as usize * 7919) % compressed;
        bad[k] = bad[k].wrapping_add(1 + (seed % 255) as u8);
        let _ = read_pcd_from_bytes(&bad, "x.pcd");
    }
}

#[test]
fn missing_file_names_path() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("missing.pcd");
    let msg = read_pcd(&path).unwrap_err().to_string();
    assert!(msg.starts_with(&path.display().to_string()), "{msg}");
}

/// Sizing from headers only: a true file gives its POINTS, a header that claims far more
/// points than the file can hold is bounded by the file's size.
#[test]
fn point_count_from_the_header_is_bounded_by_the_file_size() {
    let dir = tempfile::tempdir().unwrap();
    for enc in [
        PcdEncoding::Ascii,
        PcdEncoding::Binary,
        PcdEncoding::BinaryCompressed,
    ] {
        let path = dir.path().join(format!("{}.pcd", enc.as_str()));
        std::fs::write(&path, xyz_file(enc, 500)).unwrap();
        assert_eq!(pssba_io::pcd_point_count(&path).unwrap(), 500, "{enc:?}");
        let lying = replace(
            &replace(&xyz_file(enc, 500), "POINTS 500", "POINTS 1000000000"),
            "WIDTH 500",
            "WIDTH 1000000000",
        );
        std::fs::write(&path, &lying).unwrap();
        let bounded = pssba_io::pcd_point_count(&path).unwrap();
        assert!(bounded < 1_000_000, "{enc:?}: {bounded}");
        assert!(
            read_pcd(&path).is_err(),
            "{enc:?}: the full read refuses it"
        );
    }
}
