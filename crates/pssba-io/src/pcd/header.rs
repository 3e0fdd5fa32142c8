//! Parsing and validation of the PCD text header.

use std::path::Path;

use super::PcdEncoding;
use crate::IoError;

/// One entry of FIELDS with its SIZE, TYPE and COUNT.
#[derive(Debug, Clone)]
pub(crate) struct Field {
    pub name: String,
    pub size: usize,
    pub count: usize,
}

impl Field {
    /// Bytes one point uses for this field.
    pub fn bytes(&self) -> usize {
        self.size * self.count
    }
}

/// A validated PCD header.
#[derive(Debug, Clone)]
pub(crate) struct Header {
    pub fields: Vec<Field>,
    pub points: usize,
    pub encoding: PcdEncoding,
    /// Indices into `fields` of x, y and z.
    pub xyz: [usize; 3],
    /// Index into `fields` of `time` (see [`super::TIME_FIELD`]) and its TYPE, if present.
    pub time: Option<(usize, String)>,
    /// Byte offset of the data section.
    pub data_offset: usize,
    /// Number of lines up to and including the DATA line.
    pub header_lines: usize,
}

#[derive(Default)]
struct Raw {
    fields: Option<Vec<String>>,
    size: Option<Vec<String>>,
    ty: Option<Vec<String>>,
    count: Option<Vec<String>>,
    width: Option<usize>,
    height: Option<usize>,
    points: Option<usize>,
}

fn header_err(path: &Path, message: String) -> IoError {
    IoError::PcdHeader {
        path: path.to_path_buf(),
        message,
    }
}

fn parse_usize(path: &Path, key: &str, value: &str) -> Result<usize, IoError> {
    value.parse().map_err(|_| {
        header_err(
            path,
            format!("{key} value '{value}' is not a non-negative integer"),
        )
    })
}

fn single<'a>(path: &Path, key: &str, values: &[&'a str]) -> Result<&'a str, IoError> {
    match values {
        [v] => Ok(v),
        _ => Err(header_err(
            path,
            format!("{key} expects one value, found '{}'", values.join(" ")),
        )),
    }
}

/// Parses the header at the start of `bytes`.
pub(crate) fn parse_header(bytes: &[u8], path: &Path) -> Result<Header, IoError> {
    let mut raw = Raw::default();
    let mut pos = 0;
    let mut line_no = 0;
    while pos < bytes.len() {
        let end = bytes[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |k| pos + k);
        let line_bytes = &bytes[pos..end];
        pos = (end + 1).min(bytes.len());
        line_no += 1;
        let line = std::str::from_utf8(line_bytes)
            .map_err(|_| header_err(path, format!("line {line_no} is not text")))?
            .trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut words = line.split_whitespace();
        let key = words.next().unwrap_or_default().to_ascii_uppercase();
        let values: Vec<&str> = words.collect();
        let owned = || values.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        match key.as_str() {
            "FIELDS" => raw.fields = Some(owned()),
            "SIZE" => raw.size = Some(owned()),
            "TYPE" => raw.ty = Some(owned()),
            "COUNT" => raw.count = Some(owned()),
            "WIDTH" => {
                raw.width = Some(parse_usize(path, "WIDTH", single(path, "WIDTH", &values)?)?)
            }
            "HEIGHT" => {
                raw.height = Some(parse_usize(
                    path,
                    "HEIGHT",
                    single(path, "HEIGHT", &values)?,
                )?)
            }
            "POINTS" => {
                raw.points = Some(parse_usize(
                    path,
                    "POINTS",
                    single(path, "POINTS", &values)?,
                )?)
            }
            "DATA" => {
                let kind = single(path, "DATA", &values)?;
                let encoding = match kind.to_ascii_lowercase().as_str() {
                    "ascii" => PcdEncoding::Ascii,
                    "binary" => PcdEncoding::Binary,
                    "binary_compressed" => PcdEncoding::BinaryCompressed,
                    _ => {
                        return Err(IoError::PcdUnsupportedData {
                            path: path.to_path_buf(),
                            kind: kind.to_string(),
                        });
                    }
                };
                return validate(raw, encoding, pos, line_no, path);
            }
            // VERSION, VIEWPOINT and unknown keys are ignored, as PCL does.
            _ => {}
        }
    }
    Err(header_err(
        path,
        format!("missing DATA line (header ends after {line_no} lines)"),
    ))
}

fn require<T>(value: Option<T>, key: &str, path: &Path) -> Result<T, IoError> {
    value.ok_or_else(|| header_err(path, format!("missing {key} line")))
}

fn validate(
    raw: Raw,
    encoding: PcdEncoding,
    data_offset: usize,
    header_lines: usize,
    path: &Path,
) -> Result<Header, IoError> {
    let names = require(raw.fields, "FIELDS", path)?;
    let sizes = require(raw.size, "SIZE", path)?;
    let types = require(raw.ty, "TYPE", path)?;
    let counts = raw
        .count
        .unwrap_or_else(|| vec!["1".to_string(); names.len()]);
    let width = require(raw.width, "WIDTH", path)?;
    let height = require(raw.height, "HEIGHT", path)?;
    let points = require(raw.points, "POINTS", path)?;
    if names.is_empty() {
        return Err(header_err(path, "FIELDS is empty".into()));
    }
    for (key, list) in [("SIZE", &sizes), ("TYPE", &types), ("COUNT", &counts)] {
        if list.len() != names.len() {
            let msg = format!(
                "{key} has {} entries ('{}') but FIELDS has {}",
                list.len(),
                list.join(" "),
                names.len()
            );
            return Err(header_err(path, msg));
        }
    }
    if width.checked_mul(height) != Some(points) {
        return Err(IoError::PcdPointCount {
            path: path.to_path_buf(),
            points,
            width,
            height,
        });
    }
    let mut fields = Vec::with_capacity(names.len());
    let mut types_ok = Vec::with_capacity(names.len());
    for (((name, size), ty), count) in names.iter().zip(&sizes).zip(&types).zip(&counts) {
        let size = parse_usize(path, "SIZE", size)?;
        if ![1, 2, 4, 8].contains(&size) {
            let msg = format!("SIZE of field '{name}' is {size}, expected 1, 2, 4 or 8");
            return Err(header_err(path, msg));
        }
        if !["I", "U", "F"].contains(&ty.as_str()) {
            let msg = format!("TYPE of field '{name}' is '{ty}', expected I, U or F");
            return Err(header_err(path, msg));
        }
        let count = parse_usize(path, "COUNT", count)?;
        if count == 0 {
            return Err(header_err(path, format!("COUNT of field '{name}' is 0")));
        }
        types_ok.push(ty.as_str());
        fields.push(Field {
            name: name.clone(),
            size,
            count,
        });
    }
    let mut xyz = [0; 3];
    for (slot, axis) in xyz.iter_mut().zip(["x", "y", "z"]) {
        let mut found = fields.iter().enumerate().filter(|(_, f)| f.name == axis);
        let (k, f) = found
            .next()
            .ok_or_else(|| header_err(path, format!("FIELDS has no '{axis}'")))?;
        if found.next().is_some() {
            return Err(header_err(
                path,
                format!("FIELDS has '{axis}' more than once"),
            ));
        }
        let field_err = |message: String| IoError::PcdField {
            path: path.to_path_buf(),
            field: axis.to_string(),
            message,
        };
        if types_ok[k] != "F" {
            return Err(field_err(format!("has TYPE {}, expected F", types_ok[k])));
        }
        if f.size != 4 && f.size != 8 {
            return Err(field_err(format!("has SIZE {}, expected 4 or 8", f.size)));
        }
        if f.count != 1 {
            return Err(field_err(format!("has COUNT {}, expected 1", f.count)));
        }
        *slot = k;
    }
    let time = fields
        .iter()
        .position(|f| f.name == super::TIME_FIELD)
        .map(|k| (k, types_ok[k].to_string()));
    Ok(Header {
        fields,
        points,
        encoding,
        xyz,
        time,
        data_offset,
        header_lines,
    })
}
