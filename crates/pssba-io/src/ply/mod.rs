//! PLY point clouds (vertices only): writers for inspecting clouds in
//! viewers such as CloudCompare or MeshLab, and a minimal reader.

mod read;

use std::fmt::Write as _;
use std::path::Path;

use nalgebra::Point3;

use crate::IoError;

pub use read::{read_ply, read_ply_from_bytes};

fn header(format: &str, n: usize) -> String {
    format!(
        "ply\nformat {format} 1.0\ncomment written by pssba-io\nelement vertex {n}\n\
         property float x\nproperty float y\nproperty float z\nend_header\n"
    )
}

/// Writes `points` as a `binary_little_endian` PLY with `float` (f32)
/// x, y, z vertex properties.
pub fn write_ply(path: impl AsRef<Path>, points: &[Point3<f64>]) -> Result<(), IoError> {
    let path = path.as_ref();
    let mut out = header("binary_little_endian", points.len()).into_bytes();
    out.reserve(points.len() * 12);
    for p in points {
        for v in [p.x, p.y, p.z] {
            out.extend_from_slice(&(v as f32).to_le_bytes());
        }
    }
    std::fs::write(path, out).map_err(|e| IoError::io(path, e))
}

/// Writes `points` as an `ascii` PLY with `float` (f32) x, y, z vertex
/// properties.
pub fn write_ply_ascii(path: impl AsRef<Path>, points: &[Point3<f64>]) -> Result<(), IoError> {
    let path = path.as_ref();
    let mut out = header("ascii", points.len());
    for p in points {
        let [x, y, z] = [p.x, p.y, p.z].map(|v| v as f32);
        // Writing to a String cannot fail.
        let _ = writeln!(out, "{x} {y} {z}");
    }
    std::fs::write(path, out).map_err(|e| IoError::io(path, e))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn cloud() -> Vec<Point3<f64>> {
        (0..50)
            .map(|k| {
                let k = k as f64;
                Point3::new(k * 0.25, -k * 1.5, 100.0 + k.sin())
            })
            .collect()
    }

    fn assert_close(a: &[Point3<f64>], b: &[Point3<f64>]) {
        assert_eq!(a.len(), b.len());
        for (p, q) in a.iter().zip(b) {
            assert!(
                (p - q).norm() < 1e-4 * (1.0 + p.coords.norm()),
                "{p} vs {q}"
            );
        }
    }

    #[test]
    fn binary_and_ascii_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let pts = cloud();
        let bin = dir.path().join("a.ply");
        write_ply(&bin, &pts).unwrap();
        assert_close(&pts, &read_ply(&bin).unwrap());
        let asc = dir.path().join("b.ply");
        write_ply_ascii(&asc, &pts).unwrap();
        assert_close(&pts, &read_ply(&asc).unwrap());
        let empty = dir.path().join("c.ply");
        write_ply(&empty, &[]).unwrap();
        assert!(read_ply(&empty).unwrap().is_empty());
    }

    #[test]
    fn reads_other_property_layouts() {
        let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 2\n\
            property uchar red\nproperty double x\nproperty double y\nproperty int z\n\
            element face 0\nproperty list uchar int vertex_indices\nend_header\n"
            .to_vec();
        for (r, x, y, z) in [(7u8, 1.5f64, -2.0f64, 3i32), (8, 4.0, 5.0, -6)] {
            bytes.push(r);
            bytes.extend_from_slice(&x.to_le_bytes());
            bytes.extend_from_slice(&y.to_le_bytes());
            bytes.extend_from_slice(&z.to_le_bytes());
        }
        let pts = read_ply_from_bytes(&bytes, "v.ply").unwrap();
        assert_eq!(
            pts,
            vec![Point3::new(1.5, -2.0, 3.0), Point3::new(4.0, 5.0, -6.0)]
        );
    }

    #[test]
    fn malformed_files_are_errors() {
        let cases: [(&[u8], &str); 5] = [
            (b"PLY\n", "v.ply: PLY: not a PLY file"),
            (b"ply\nformat binary_big_endian 1.0\nend_header\n", "unsupported format"),
            (b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n", "v.ply: PLY: expected 2 vertices"),
            (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n", "no vertex property 'z'"),
            (b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n\0\0", "truncated"),
        ];
        for (bytes, expected) in cases {
            let msg = read_ply_from_bytes(bytes, "v.ply").unwrap_err().to_string();
            assert!(msg.contains(expected), "{msg:?} lacks {expected:?}");
        }
    }
}
