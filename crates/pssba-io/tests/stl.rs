//! STL reading: binary and ASCII files written here, and every malformed case names the file
//! and the fault.

use std::path::{Path, PathBuf};

use nalgebra::Point3;
use pssba_io::{StlTriangle, read_stl};

fn tris() -> Vec<StlTriangle> {
    vec![
        [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
        ],
        [
            Point3::new(0.5, -2.25, 3.0),
            Point3::new(-1.0, 4.0, 0.125),
            Point3::new(7.0, 8.0, 9.5),
        ],
    ]
}

/// A binary STL with `header` text, the given triangles and the stored count.
fn binary(header: &str, triangles: &[StlTriangle], count: u32) -> Vec<u8> {
    let mut bytes = vec![0u8; 80];
    bytes[..header.len()].copy_from_slice(header.as_bytes());
    bytes.extend(count.to_le_bytes());
    for t in triangles {
        bytes.extend([0f32; 3].iter().flat_map(|v| v.to_le_bytes()));
        for v in t {
            bytes.extend(v.iter().flat_map(|&c| (c as f32).to_le_bytes()));
        }
        bytes.extend([0u8; 2]);
    }
    bytes
}

fn ascii(triangles: &[StlTriangle]) -> String {
    let mut text = String::from("solid test\n");
    for t in triangles {
        text.push_str("  facet normal 0 0 1\n    outer loop\n");
        for v in t {
            text.push_str(&format!("      vertex {} {} {:e}\n", v.x, v.y, v.z));
        }
        text.push_str("    endloop\n  endfacet\n");
    }
    text.push_str("endsolid test\n");
    text
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("write");
    path
}

/// The error message of reading `bytes` as `name`; asserts it names the file.
fn error(name: &str, bytes: &[u8]) -> String {
    let dir = tempfile::tempdir().expect("tmp");
    let path = write(dir.path(), name, bytes);
    let message = read_stl(&path).expect_err("must fail").to_string();
    assert!(message.contains(name), "{message}");
    message
}

#[test]
fn binary_and_ascii_read_back_the_triangles() {
    let dir = tempfile::tempdir().expect("tmp");
    let b = write(dir.path(), "b.stl", &binary("binary", &tris(), 2));
    assert_eq!(read_stl(&b).expect("binary"), tris());
    // Some exporters start binary headers with "solid": the size decides.
    let s = write(dir.path(), "s.stl", &binary("solid but binary", &tris(), 2));
    assert_eq!(read_stl(&s).expect("binary with solid header"), tris());
    let a = write(dir.path(), "a.stl", ascii(&tris()).as_bytes());
    assert_eq!(read_stl(&a).expect("ascii"), tris());
    let two_solids = format!("{}{}", ascii(&tris()[..1]), ascii(&tris()[1..]));
    let m = write(dir.path(), "m.stl", two_solids.as_bytes());
    assert_eq!(read_stl(&m).expect("two solids"), tris());
}

#[test]
fn empty_truncated_and_miscounted_binaries_are_named() {
    assert!(error("empty.stl", b"").contains("empty file"));
    assert!(error("short.stl", &[7u8; 40]).contains("header alone needs 84"));
    let mut bytes = binary("x", &tris(), 2);
    bytes.truncate(bytes.len() - 10);
    let message = error("cut.stl", &bytes);
    assert!(
        message.contains("truncated") && message.contains("2 triangles"),
        "{message}"
    );
    let mut bytes = binary("x", &tris(), 2);
    bytes.extend([0u8; 7]);
    assert!(error("long.stl", &bytes).contains("bad triangle count"));
    assert!(error("none.stl", &binary("x", &[], 0)).contains("no triangles"));
}

#[test]
fn non_finite_vertices_are_rejected() {
    let mut bad = tris();
    bad[1][2].y = f64::NAN;
    let message = error("nan.stl", &binary("x", &bad, 2));
    assert!(
        message.contains("triangle 1") && message.contains("not finite"),
        "{message}"
    );
    let text = ascii(&tris()).replace("vertex 7 8", "vertex 7 inf");
    let message = error("inf.stl", text.as_bytes());
    assert!(
        message.contains("line 13") && message.contains("not finite"),
        "{message}"
    );
}

#[test]
fn malformed_ascii_names_the_line() {
    let text = ascii(&tris()).replace("vertex 1 0", "vertex one 0");
    let message = error("word.stl", text.as_bytes());
    assert!(
        message.contains("line 5") && message.contains("'one'"),
        "{message}"
    );
    let text = ascii(&tris()).replace("vertex 0 1 0e0\n", "");
    let message = error("two.stl", text.as_bytes());
    assert!(
        message.contains("line 2") && message.contains("2 vertices"),
        "{message}"
    );
    let text = ascii(&tris()).replace("vertex 0 1 0e0", "vertex 0 1");
    assert!(error("short_vertex.stl", text.as_bytes()).contains("3 numbers, found 2"));
    let full = ascii(&tris());
    let cut = &full[..full.find("endloop").expect("endloop")];
    assert!(error("cut.stl", cut.as_bytes()).contains("facet opened at line 2"));
    let no_end = full.replace("endsolid test\n", "");
    assert!(error("noend.stl", no_end.as_bytes()).contains("no 'endsolid'"));
    assert!(error("zero.stl", b"solid x\nendsolid x\n").contains("no triangles"));
    let message = error("junk.stl", b"solid x\n  bogus 1 2\nendsolid\n");
    assert!(
        message.contains("line 2") && message.contains("'bogus'"),
        "{message}"
    );
}
