//! A minimal PLY reader: x, y, z of the `vertex` element, which must be the
//! first element; `ascii` or `binary_little_endian`; scalar properties only.

use std::path::Path;

use nalgebra::Point3;

use crate::IoError;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Scalar {
    I(usize),
    U(usize),
    F(usize),
}

impl Scalar {
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Scalar::I(1),
            "uchar" | "uint8" => Scalar::U(1),
            "short" | "int16" => Scalar::I(2),
            "ushort" | "uint16" => Scalar::U(2),
            "int" | "int32" => Scalar::I(4),
            "uint" | "uint32" => Scalar::U(4),
            "float" | "float32" => Scalar::F(4),
            "double" | "float64" => Scalar::F(8),
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I(s) | Scalar::U(s) | Scalar::F(s) => s,
        }
    }

    /// Decodes a little-endian value; `b` has exactly `self.size()` bytes.
    fn decode(self, b: &[u8]) -> f64 {
        let mut w = [0u8; 8];
        w[..b.len()].copy_from_slice(b);
        match self {
            Scalar::F(4) => f64::from(f32::from_le_bytes([w[0], w[1], w[2], w[3]])),
            Scalar::F(_) => f64::from_le_bytes(w),
            Scalar::U(_) => u64::from_le_bytes(w) as f64,
            Scalar::I(s) => {
                let shift = 64 - 8 * s as u32;
                ((u64::from_le_bytes(w) << shift) as i64 >> shift) as f64
            }
        }
    }
}

/// Reads the vertex positions of a PLY file.
pub fn read_ply(path: impl AsRef<Path>) -> Result<Vec<Point3<f64>>, IoError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    read_ply_from_bytes(&bytes, path)
}

/// Like [`read_ply`] for an in-memory file; `name_for_errors` is used in messages.
pub fn read_ply_from_bytes(
    bytes: &[u8],
    name_for_errors: impl AsRef<Path>,
) -> Result<Vec<Point3<f64>>, IoError> {
    let path = name_for_errors.as_ref();
    let err = |message: String| IoError::Ply {
        path: path.to_path_buf(),
        message,
    };
    let mut lines = bytes.split(|&b| b == b'\n');
    let mut offset = 0;
    let mut next_line = || -> Option<String> {
        let line = lines.next()?;
        offset += line.len() + 1;
        Some(String::from_utf8_lossy(line).trim().to_string())
    };
    if next_line().as_deref() != Some("ply") {
        return Err(err("not a PLY file (first line is not 'ply')".into()));
    }
    let mut binary = None;
    let mut vertices: Option<usize> = None;
    let mut in_vertex = false;
    let mut props: Vec<(String, Scalar)> = Vec::new();
    loop {
        let line = next_line().ok_or_else(|| err("missing end_header".into()))?;
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["end_header"] => break,
            ["format", "ascii", _] => binary = Some(false),
            ["format", "binary_little_endian", _] => binary = Some(true),
            ["format", ..] => return Err(err(format!("unsupported format '{line}'"))),
            ["element", name, count] => {
                in_vertex = vertices.is_none() && *name == "vertex";
                if vertices.is_none() && !in_vertex {
                    return Err(err(format!("first element is '{name}', expected 'vertex'")));
                }
                if in_vertex {
                    let n = count
                        .parse()
                        .map_err(|_| err(format!("bad vertex count '{count}'")))?;
                    vertices = Some(n);
                }
            }
            ["property", ty, name] if in_vertex => {
                let s = Scalar::parse(ty)
                    .ok_or_else(|| err(format!("unsupported property type '{ty}'")))?;
                props.push((name.to_string(), s));
            }
            ["property", ..] if in_vertex => {
                return Err(err(format!("unsupported vertex property '{line}'")));
            }
            _ => {} // comments, obj_info, properties of later elements
        }
    }
    let binary = binary.ok_or_else(|| err("missing format line".into()))?;
    let n = vertices.ok_or_else(|| err("no vertex element".into()))?;
    let mut xyz = [0; 3];
    for (slot, axis) in xyz.iter_mut().zip(["x", "y", "z"]) {
        *slot = props
            .iter()
            .position(|(name, _)| name == axis)
            .ok_or_else(|| err(format!("no vertex property '{axis}'")))?;
    }
    let data = bytes.get(offset.min(bytes.len())..).unwrap_or_default();
    if binary {
        let record: usize = props.iter().map(|(_, s)| s.size()).sum();
        let need = n.saturating_mul(record);
        if data.len() < need {
            let found = data.len();
            return Err(err(format!(
                "binary data truncated: expected {need} bytes, found {found}"
            )));
        }
        let mut starts = Vec::with_capacity(props.len());
        let mut acc = 0;
        for (_, s) in &props {
            starts.push(acc);
            acc += s.size();
        }
        let value = |i: usize, k: usize| {
            let (at, s) = (i * record + starts[k], props[k].1);
            s.decode(&data[at..at + s.size()])
        };
        return Ok((0..n)
            .map(|i| Point3::new(value(i, xyz[0]), value(i, xyz[1]), value(i, xyz[2])))
            .collect());
    }
    let text = String::from_utf8_lossy(data);
    let mut points = Vec::with_capacity(n.min(data.len() / 6 + 1));
    for line in text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .take(n)
    {
        let words: Vec<&str> = line.split_whitespace().collect();
        if words.len() != props.len() {
            let msg = format!(
                "vertex line '{line}' has {} values, expected {}",
                words.len(),
                props.len()
            );
            return Err(err(msg));
        }
        let mut p = [0.0; 3];
        for (slot, &k) in p.iter_mut().zip(&xyz) {
            *slot = words[k]
                .parse()
                .map_err(|_| err(format!("'{}' is not a number", words[k])))?;
        }
        points.push(Point3::from(p));
    }
    if points.len() < n {
        return Err(err(format!(
            "expected {n} vertices, found {}",
            points.len()
        )));
    }
    Ok(points)
}
