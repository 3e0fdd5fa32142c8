//! STL meshes (binary and ASCII) as triangle soups, for the simulator's scenes (DESIGN.md
//! section 4: the CARIC meshes are binary STL).
//!
//! A file whose size is exactly `84 + 50 n` bytes for the triangle count `n` in its header
//! is binary (even if its header starts with `solid`, as some exporters write); otherwise a
//! file starting with `solid` is ASCII; anything else is a malformed binary file.

use std::path::Path;

use nalgebra::Point3;

use crate::IoError;

/// One triangle: three vertices (m, as stored; normals are ignored).
pub type StlTriangle = [Point3<f64>; 3];

/// Bytes of the binary header (80-byte comment + u32 count) and of one binary triangle.
const HEADER_BYTES: usize = 84;
const TRIANGLE_BYTES: usize = 50;

fn stl_err(path: &Path, message: String) -> IoError {
    IoError::Stl {
        path: path.to_path_buf(),
        message,
    }
}

/// Reads an STL file. Fails, naming the file and the fault, on an empty or truncated file,
/// a triangle count that disagrees with the file size, a non-finite vertex, malformed ASCII
/// (with its line number) or a mesh without triangles.
pub fn read_stl(path: impl AsRef<Path>) -> Result<Vec<StlTriangle>, IoError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    read_stl_from_bytes(&bytes, path)
}

/// [`read_stl`] on bytes already in memory; `path` names the source in errors.
pub fn read_stl_from_bytes(bytes: &[u8], path: &Path) -> Result<Vec<StlTriangle>, IoError> {
    if bytes.is_empty() {
        return Err(stl_err(path, "empty file".into()));
    }
    let count = bytes
        .get(80..HEADER_BYTES)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
    let binary_size = count.map(|n| HEADER_BYTES as u64 + TRIANGLE_BYTES as u64 * n as u64);
    let triangles = if binary_size == Some(bytes.len() as u64) {
        read_binary(bytes, path)?
    } else if bytes.trim_ascii_start().starts_with(b"solid") {
        read_ascii(bytes, path)?
    } else {
        let message = match (count, binary_size) {
            (Some(n), Some(size)) if size > bytes.len() as u64 => format!(
                "binary STL truncated: header says {n} triangles ({size} bytes) but the file has {} bytes",
                bytes.len()
            ),
            (Some(n), Some(size)) => format!(
                "bad triangle count: header says {n} triangles ({size} bytes) but the file has {} bytes",
                bytes.len()
            ),
            _ => format!(
                "binary STL truncated: {} bytes, the header alone needs {HEADER_BYTES}",
                bytes.len()
            ),
        };
        return Err(stl_err(path, message));
    };
    if triangles.is_empty() {
        return Err(stl_err(path, "no triangles (empty mesh)".into()));
    }
    Ok(triangles)
}

/// Checks that a vertex is finite.
fn finite(
    v: Point3<f64>,
    path: &Path,
    triangle: usize,
    where_: &str,
) -> Result<Point3<f64>, IoError> {
    if v.iter().all(|c| c.is_finite()) {
        return Ok(v);
    }
    let message = format!(
        "triangle {triangle}{where_}: vertex ({} {} {}) is not finite",
        v.x, v.y, v.z
    );
    Err(stl_err(path, message))
}

fn read_binary(bytes: &[u8], path: &Path) -> Result<Vec<StlTriangle>, IoError> {
    let f32_at = |at: usize| {
        f64::from(f32::from_le_bytes([
            bytes[at],
            bytes[at + 1],
            bytes[at + 2],
            bytes[at + 3],
        ]))
    };
    bytes[HEADER_BYTES..]
        .chunks_exact(TRIANGLE_BYTES)
        .enumerate()
        .map(|(k, _)| {
            let base = HEADER_BYTES + k * TRIANGLE_BYTES + 12;
            let vertex = |j: usize| {
                let at = base + 12 * j;
                finite(
                    Point3::new(f32_at(at), f32_at(at + 4), f32_at(at + 8)),
                    path,
                    k,
                    "",
                )
            };
            Ok([vertex(0)?, vertex(1)?, vertex(2)?])
        })
        .collect()
}

fn read_ascii(bytes: &[u8], path: &Path) -> Result<Vec<StlTriangle>, IoError> {
    let text = std::str::from_utf8(bytes).map_err(|e| {
        let message = format!(
            "starts with 'solid' but is not ASCII text ({e}) and its size does not fit a binary STL"
        );
        stl_err(path, message)
    })?;
    let at_line = |line: usize, message: String| stl_err(path, format!("line {line}: {message}"));
    let mut triangles = Vec::new();
    // The facet being read: its first line and the vertices so far.
    let mut facet: Option<(usize, Vec<Point3<f64>>)> = None;
    // Several `solid ... endsolid` blocks may follow each other.
    let mut in_solid = false;
    for (index, line) in text.lines().enumerate() {
        let number = index + 1;
        let mut tokens = line.split_whitespace();
        let Some(keyword) = tokens.next() else {
            continue;
        };
        if !in_solid && keyword != "solid" {
            return Err(at_line(
                number,
                format!("'{keyword}' outside solid ... endsolid"),
            ));
        }
        match (keyword, &mut facet) {
            ("solid", None) if !in_solid => in_solid = true,
            ("facet", None) => facet = Some((number, Vec::with_capacity(3))),
            ("outer" | "endloop", Some(_)) => {}
            ("vertex", Some((_, vertices))) => {
                let fields: Vec<&str> = tokens.collect();
                if fields.len() != 3 {
                    return Err(at_line(
                        number,
                        format!("vertex needs 3 numbers, found {}", fields.len()),
                    ));
                }
                let mut xyz = [0.0; 3];
                for (value, field) in xyz.iter_mut().zip(&fields) {
                    *value = field.parse().map_err(|_| {
                        at_line(
                            number,
                            format!("vertex coordinate '{field}' is not a number"),
                        )
                    })?;
                }
                let where_ = format!(" (line {number})");
                vertices.push(finite(Point3::from(xyz), path, triangles.len(), &where_)?);
            }
            ("endfacet", Some((start, vertices))) => {
                let [a, b, c] = vertices[..] else {
                    let found = vertices.len();
                    return Err(at_line(
                        *start,
                        format!("facet has {found} vertices, expected 3"),
                    ));
                };
                triangles.push([a, b, c]);
                facet = None;
            }
            ("endsolid", None) => in_solid = false,
            (other, _) => return Err(at_line(number, format!("unexpected '{other}'"))),
        }
    }
    if let Some((start, _)) = facet {
        return Err(stl_err(
            path,
            format!("ASCII STL truncated: facet opened at line {start} is not closed"),
        ));
    }
    if in_solid {
        return Err(stl_err(
            path,
            "ASCII STL truncated: no 'endsolid' line".into(),
        ));
    }
    Ok(triangles)
}
