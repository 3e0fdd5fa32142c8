//! Decoding PCD data sections into points.

use std::path::Path;

use nalgebra::Point3;

use super::header::{Field, Header, parse_header};
use super::{PcdEncoding, TimedPoints};
use crate::{IoError, lzf};

/// Reads the x, y, z coordinates of every point of a PCD file.
///
/// Points are returned in storage order (row-major for organised clouds).
/// NaN/infinite coordinates are returned as-is; the caller filters them.
pub fn read_pcd(path: impl AsRef<Path>) -> Result<Vec<Point3<f64>>, IoError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    read_pcd_from_bytes(&bytes, path)
}

/// Points a PCD file holds at most, reading only its header (at most the first 1 MiB) and its
/// size: its `POINTS`, NaN points included, but never more than its data section can hold (a
/// header claiming 10^9 points in a small file does not size anything for 10^9 points; the
/// full read then refuses the file).
pub fn pcd_point_count(path: impl AsRef<Path>) -> Result<usize, IoError> {
    use std::io::Read;
    let path = path.as_ref();
    let file = std::fs::File::open(path).map_err(|e| IoError::io(path, e))?;
    let file_bytes = file.metadata().map_err(|e| IoError::io(path, e))?.len();
    let mut head = Vec::new();
    file.take(1 << 20)
        .read_to_end(&mut head)
        .map_err(|e| IoError::io(path, e))?;
    let header = parse_header(&head, path)?;
    let data_bytes = file_bytes.saturating_sub(header.data_offset as u64);
    let values: usize = header.fields.iter().map(|f| f.count).sum();
    let point_bytes: usize = header.fields.iter().map(Field::bytes).sum();
    let most = match header.encoding {
        // At least one character and one separator per value.
        PcdEncoding::Ascii => data_bytes / (2 * values.max(1)) as u64,
        PcdEncoding::Binary => data_bytes / point_bytes.max(1) as u64,
        // LZF turns at most 3 bytes into 264 (a back-reference), plus 8 bytes of sizes.
        PcdEncoding::BinaryCompressed => data_bytes.saturating_mul(88) / point_bytes.max(1) as u64,
    };
    Ok(header
        .points
        .min(usize::try_from(most).unwrap_or(usize::MAX)))
}

/// Like [`read_pcd`] but decodes an in-memory file; `name_for_errors` is
/// only used in error messages.
pub fn read_pcd_from_bytes(
    bytes: &[u8],
    name_for_errors: impl AsRef<Path>,
) -> Result<Vec<Point3<f64>>, IoError> {
    let path = name_for_errors.as_ref();
    let header = parse_header(bytes, path)?;
    let values = decode(&header, &bytes[header.data_offset..], &header.xyz, path)?;
    Ok(values
        .chunks_exact(3)
        .map(|v| Point3::new(v[0], v[1], v[2]))
        .collect())
}

/// Like [`read_pcd`], with each point's time after the frame's stamp (s) from a `time`
/// field ([`super::TIME_FIELD`], `TYPE F`, `COUNT 1`) when the file has one.
pub fn read_pcd_with_times(path: impl AsRef<Path>) -> Result<TimedPoints, IoError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    read_pcd_with_times_from_bytes(&bytes, path)
}

/// [`read_pcd_with_times`] on an in-memory file.
pub fn read_pcd_with_times_from_bytes(
    bytes: &[u8],
    name_for_errors: impl AsRef<Path>,
) -> Result<TimedPoints, IoError> {
    let path = name_for_errors.as_ref();
    let header = parse_header(bytes, path)?;
    let Some((time, ty)) = header.time.clone() else {
        return Ok((read_pcd_from_bytes(bytes, path)?, None));
    };
    let field = &header.fields[time];
    if ty != "F" || field.count != 1 || ![4, 8].contains(&field.size) {
        return Err(IoError::PcdField {
            path: path.to_path_buf(),
            field: super::TIME_FIELD.to_string(),
            message: format!(
                "has TYPE {ty} SIZE {} COUNT {}, expected F 4 (or 8) 1: seconds after the \
                 frame's stamp",
                field.size, field.count
            ),
        });
    }
    let [x, y, z] = header.xyz;
    let values = decode(
        &header,
        &bytes[header.data_offset..],
        &[x, y, z, time],
        path,
    )?;
    let mut points = Vec::with_capacity(header.points);
    let mut times = Vec::with_capacity(header.points);
    for v in values.chunks_exact(4) {
        points.push(Point3::new(v[0], v[1], v[2]));
        times.push(v[3] as f32);
    }
    Ok((points, Some(times)))
}

/// The values of the `wanted` fields (indices into the header's fields, each `COUNT 1`) of
/// every point, point by point.
fn decode(
    header: &Header,
    data: &[u8],
    wanted: &[usize],
    path: &Path,
) -> Result<Vec<f64>, IoError> {
    match header.encoding {
        PcdEncoding::Ascii => decode_ascii(header, data, wanted, path),
        PcdEncoding::Binary => decode_binary(header, data, wanted, path),
        PcdEncoding::BinaryCompressed => decode_compressed(header, data, wanted, path),
    }
}

/// Byte offset of each field within one point's record.
fn prefix_sums(fields: &[Field], per: impl Fn(&Field) -> usize) -> Vec<usize> {
    let mut acc = 0;
    fields
        .iter()
        .map(|f| {
            let at = acc;
            acc += per(f);
            at
        })
        .collect()
}

/// Reads a little-endian f32 (size 4) or f64 (size 8) at `at`.
/// The caller guarantees `at + size <= bytes.len()`.
fn read_float(bytes: &[u8], at: usize, size: usize) -> f64 {
    if size == 4 {
        let mut b = [0u8; 4];
        b.copy_from_slice(&bytes[at..at + 4]);
        f64::from(f32::from_le_bytes(b))
    } else {
        let mut b = [0u8; 8];
        b.copy_from_slice(&bytes[at..at + 8]);
        f64::from_le_bytes(b)
    }
}

fn record_bytes(header: &Header) -> usize {
    header.fields.iter().map(Field::bytes).sum()
}

fn total_bytes(header: &Header, encoding: &'static str, path: &Path) -> Result<usize, IoError> {
    header
        .points
        .checked_mul(record_bytes(header))
        .ok_or_else(|| IoError::PcdData {
            path: path.to_path_buf(),
            encoding,
            message: format!("POINTS {} times the record size overflows", header.points),
        })
}

fn decode_binary(
    header: &Header,
    data: &[u8],
    wanted: &[usize],
    path: &Path,
) -> Result<Vec<f64>, IoError> {
    let need = total_bytes(header, "binary", path)?;
    if data.len() < need {
        return Err(IoError::PcdTruncated {
            path: path.to_path_buf(),
            encoding: "binary",
            expected: need,
            found: data.len(),
            unit: "bytes",
        });
    }
    let record = record_bytes(header);
    let offsets = prefix_sums(&header.fields, Field::bytes);
    let fields: Vec<(usize, usize)> = wanted
        .iter()
        .map(|&k| (offsets[k], header.fields[k].size))
        .collect();
    let mut values = Vec::with_capacity(header.points * fields.len());
    for i in 0..header.points {
        let base = i * record;
        values.extend(
            fields
                .iter()
                .map(|&(at, size)| read_float(data, base + at, size)),
        );
    }
    Ok(values)
}

fn decode_compressed(
    header: &Header,
    data: &[u8],
    wanted: &[usize],
    path: &Path,
) -> Result<Vec<f64>, IoError> {
    let truncated = |expected: usize| IoError::PcdTruncated {
        path: path.to_path_buf(),
        encoding: "binary_compressed",
        expected,
        found: data.len(),
        unit: "bytes",
    };
    if data.len() < 8 {
        return Err(truncated(8));
    }
    let word = |k: usize| u32::from_le_bytes([data[k], data[k + 1], data[k + 2], data[k + 3]]);
    let compressed = word(0) as usize;
    let uncompressed = word(4) as usize;
    let end = compressed.saturating_add(8);
    let payload = data.get(8..end).ok_or_else(|| truncated(end))?;
    let need = total_bytes(header, "binary_compressed", path)?;
    if uncompressed != need {
        return Err(IoError::PcdData {
            path: path.to_path_buf(),
            encoding: "binary_compressed",
            message: format!("uncompressed size {uncompressed} != POINTS*record size {need}"),
        });
    }
    let raw = lzf::decompress(payload, uncompressed).map_err(|cause| IoError::PcdLzf {
        path: path.to_path_buf(),
        cause,
    })?;
    // Column-major: all values of field 0, then all of field 1, ...
    let n = header.points;
    let columns = prefix_sums(&header.fields, |f| f.bytes() * n);
    let fields: Vec<(usize, usize)> = wanted
        .iter()
        .map(|&k| (columns[k], header.fields[k].size))
        .collect();
    let mut values = Vec::with_capacity(n * fields.len());
    for i in 0..n {
        values.extend(
            fields
                .iter()
                .map(|&(at, size)| read_float(&raw, at + i * size, size)),
        );
    }
    Ok(values)
}

fn decode_ascii(
    header: &Header,
    data: &[u8],
    fields: &[usize],
    path: &Path,
) -> Result<Vec<f64>, IoError> {
    let token_index = prefix_sums(&header.fields, |f| f.count);
    let per_point: usize = header.fields.iter().map(|f| f.count).sum();
    let wanted: Vec<(usize, usize, &str)> = fields
        .iter()
        .map(|&k| {
            (
                token_index[k],
                header.fields[k].size,
                header.fields[k].name.as_str(),
            )
        })
        .collect();
    let mut values = Vec::with_capacity(header.points.min(data.len() / 6 + 1) * wanted.len());
    let mut points = 0;
    for (idx, raw_line) in data.split(|&b| b == b'\n').enumerate() {
        let line = header.header_lines + idx + 1;
        let err = |message: String| IoError::PcdAscii {
            path: path.to_path_buf(),
            line,
            message,
        };
        let text = std::str::from_utf8(raw_line)
            .map_err(|_| err("line is not valid UTF-8 text".into()))?
            .trim();
        if text.is_empty() {
            continue;
        }
        if points == header.points {
            return Err(err(format!("more than POINTS = {} points", header.points)));
        }
        let mut point = [0.0; 4];
        let mut found = 0;
        for (t, token) in text.split_whitespace().enumerate() {
            found += 1;
            for (slot, &(at, size, name)) in point.iter_mut().zip(&wanted) {
                if t != at {
                    continue;
                }
                let parsed = if size == 4 {
                    token.parse::<f32>().map(f64::from).ok()
                } else {
                    token.parse::<f64>().ok()
                };
                *slot = parsed.ok_or_else(|| {
                    err(format!("field '{name}' value '{token}' is not a number"))
                })?;
            }
        }
        if found != per_point {
            return Err(err(format!("expected {per_point} values, found {found}")));
        }
        values.extend_from_slice(&point[..wanted.len()]);
        points += 1;
    }
    if points < header.points {
        return Err(IoError::PcdTruncated {
            path: path.to_path_buf(),
            encoding: "ascii",
            expected: header.points,
            found: points,
            unit: "points",
        });
    }
    Ok(values)
}
