//! Writing x/y/z-only PCD files.

use std::fmt::Write as _;
use std::path::Path;

use nalgebra::Point3;

use super::{PcdEncoding, PcdPrecision};
use crate::{IoError, lzf};

/// Writes `points` as a PCD v0.7 file with fields x y z stored as f32
/// (`SIZE 4`, about 7 significant digits; see [`PcdPrecision::F32`]).
///
/// Use [`write_pcd_with_precision`] to store f64 instead.
pub fn write_pcd(
    path: impl AsRef<Path>,
    points: &[Point3<f64>],
    encoding: PcdEncoding,
) -> Result<(), IoError> {
    write_pcd_with_precision(path, points, encoding, PcdPrecision::F32)
}

/// Writes `points` as a PCD v0.7 file with fields x y z of the given
/// precision. With [`PcdPrecision::F32`], values beyond the f32 range
/// become infinite. NaN/infinite coordinates are written unchanged.
pub fn write_pcd_with_precision(
    path: impl AsRef<Path>,
    points: &[Point3<f64>],
    encoding: PcdEncoding,
    precision: PcdPrecision,
) -> Result<(), IoError> {
    let path = path.as_ref();
    let bytes = pcd_to_bytes(points, encoding, precision, path)?;
    std::fs::write(path, bytes).map_err(|e| IoError::io(path, e))
}

/// Encodes `points` as the bytes of a PCD file (see
/// [`write_pcd_with_precision`]). Fails only if a binary_compressed section
/// would exceed 4 GiB; `name_for_errors` is used in that message.
pub fn pcd_to_bytes(
    points: &[Point3<f64>],
    encoding: PcdEncoding,
    precision: PcdPrecision,
    name_for_errors: impl AsRef<Path>,
) -> Result<Vec<u8>, IoError> {
    pcd_to_bytes_with_times(points, None, encoding, precision, name_for_errors)
}

/// [`pcd_to_bytes`] with a fourth field `time` ([`super::TIME_FIELD`], f32 s after the
/// frame's stamp) when `times_s` is given: one time per point (the caller checks the count;
/// missing times are written as 0).
pub fn pcd_to_bytes_with_times(
    points: &[Point3<f64>],
    times_s: Option<&[f32]>,
    encoding: PcdEncoding,
    precision: PcdPrecision,
    name_for_errors: impl AsRef<Path>,
) -> Result<Vec<u8>, IoError> {
    let n = points.len();
    let s = precision.size();
    let time_at = |i: usize| times_s.and_then(|t| t.get(i)).copied().unwrap_or(0.0);
    let (fields, sizes, types, counts) = match times_s {
        Some(_) => ("x y z time", format!("{s} {s} {s} 4"), "F F F F", "1 1 1 1"),
        None => ("x y z", format!("{s} {s} {s}"), "F F F", "1 1 1"),
    };
    let mut out = format!(
        "# .PCD v0.7 - Point Cloud Data file format\n\
         VERSION 0.7\nFIELDS {fields}\nSIZE {sizes}\nTYPE {types}\nCOUNT {counts}\n\
         WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {encoding}\n"
    )
    .into_bytes();
    match encoding {
        PcdEncoding::Ascii => {
            let mut text = String::with_capacity(n * 4 * 12);
            for (i, p) in points.iter().enumerate() {
                let [x, y, z] = [p.x, p.y, p.z].map(|v| format_value(v, precision));
                // Writing to a String cannot fail.
                let _ = match times_s {
                    Some(_) => writeln!(text, "{x} {y} {z} {}", time_at(i)),
                    None => writeln!(text, "{x} {y} {z}"),
                };
            }
            out.extend_from_slice(text.as_bytes());
        }
        PcdEncoding::Binary => {
            out.reserve(n * (3 * s + 4));
            for (i, p) in points.iter().enumerate() {
                for v in [p.x, p.y, p.z] {
                    push_value(&mut out, v, precision);
                }
                if times_s.is_some() {
                    out.extend_from_slice(&time_at(i).to_le_bytes());
                }
            }
        }
        PcdEncoding::BinaryCompressed => {
            let mut raw = Vec::with_capacity(n * (3 * s + 4));
            for axis in 0..3 {
                for p in points {
                    push_value(&mut raw, p.coords[axis], precision);
                }
            }
            if times_s.is_some() {
                for i in 0..n {
                    raw.extend_from_slice(&time_at(i).to_le_bytes());
                }
            }
            let packed = lzf::compress(&raw);
            let too_big = |what: &str, len: usize| IoError::PcdData {
                path: name_for_errors.as_ref().to_path_buf(),
                encoding: "binary_compressed",
                message: format!("{what} size {len} bytes does not fit in 32 bits"),
            };
            let c = u32::try_from(packed.len()).map_err(|_| too_big("compressed", packed.len()))?;
            let u = u32::try_from(raw.len()).map_err(|_| too_big("uncompressed", raw.len()))?;
            out.extend_from_slice(&c.to_le_bytes());
            out.extend_from_slice(&u.to_le_bytes());
            out.extend_from_slice(&packed);
        }
    }
    Ok(out)
}

fn push_value(out: &mut Vec<u8>, v: f64, precision: PcdPrecision) {
    match precision {
        PcdPrecision::F32 => out.extend_from_slice(&(v as f32).to_le_bytes()),
        PcdPrecision::F64 => out.extend_from_slice(&v.to_le_bytes()),
    }
}

/// Shortest text that parses back to the same f32/f64; NaN as `nan`.
fn format_value(v: f64, precision: PcdPrecision) -> String {
    if v.is_nan() {
        return "nan".to_string();
    }
    match precision {
        PcdPrecision::F32 => format!("{}", v as f32),
        PcdPrecision::F64 => format!("{v}"),
    }
}
