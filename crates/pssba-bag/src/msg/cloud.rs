//! Point-cloud messages: `sensor_msgs/PointCloud2` and the Livox drivers' `CustomMsg`.

use nalgebra::Point3;

use super::cursor::{Cursor, DecodeError, Header, decode_err};
use super::point_time::{KNOWN_TIME_FIELDS, PointTimeChoice, RawTimes};

/// One decoded cloud: finite points in the message's frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Cloud {
    /// The message header (stamp and frame).
    pub header: Header,
    /// Finite points, in message order (m).
    pub points: Vec<Point3<f64>>,
    /// Points dropped because a coordinate was NaN or infinite.
    pub non_finite: usize,
    /// The points' times as stored, when the message has a time field and times are asked
    /// for.
    pub times: Option<RawTimes>,
}

/// `sensor_msgs/PointField` datatype codes of the types read.
const INT32: u8 = 5;
const UINT32: u8 = 6;
const FLOAT32: u8 = 7;
const FLOAT64: u8 = 8;

/// The name of a `sensor_msgs/PointField` datatype code.
fn datatype_name(code: u8) -> &'static str {
    match code {
        1 => "int8",
        2 => "uint8",
        3 => "int16",
        4 => "uint16",
        INT32 => "int32",
        UINT32 => "uint32",
        FLOAT32 => "float32",
        FLOAT64 => "float64",
        _ => "unknown",
    }
}

/// A point-time field inside a point.
#[derive(Debug, Clone)]
struct TimeField {
    name: String,
    offset: usize,
    datatype: u8,
}

impl TimeField {
    fn size(&self) -> usize {
        if self.datatype == FLOAT64 { 8 } else { 4 }
    }

    fn read(&self, point: &[u8], big_endian: bool) -> f64 {
        let mut b = [0u8; 4];
        if self.datatype == FLOAT64 {
            let mut b8 = [0u8; 8];
            b8.copy_from_slice(&point[self.offset..self.offset + 8]);
            return if big_endian {
                f64::from_be_bytes(b8)
            } else {
                f64::from_le_bytes(b8)
            };
        }
        b.copy_from_slice(&point[self.offset..self.offset + 4]);
        let bits = if big_endian {
            u32::from_be_bytes(b)
        } else {
            u32::from_le_bytes(b)
        };
        match self.datatype {
            FLOAT32 => f64::from(f32::from_bits(bits)),
            INT32 => f64::from(bits as i32),
            _ => f64::from(bits),
        }
    }
}

/// The field to read times from: the one named, or the first known name present.
fn choose_time_field(
    fields: &[(String, usize, u8)],
    choice: &PointTimeChoice,
) -> Result<Option<TimeField>, DecodeError> {
    let found = match choice {
        PointTimeChoice::Ignore => return Ok(None),
        PointTimeChoice::Auto => KNOWN_TIME_FIELDS
            .iter()
            .find_map(|name| fields.iter().find(|f| f.0 == *name)),
        PointTimeChoice::Field { name, .. } => {
            let field = fields.iter().find(|f| f.0 == *name);
            if field.is_none() {
                let names: Vec<&str> = fields.iter().map(|f| f.0.as_str()).collect();
                return Err(decode_err(format!(
                    "no field {name} for --point-time; the fields are: {}",
                    names.join(", ")
                )));
            }
            field
        }
    };
    let Some((name, offset, datatype)) = found else {
        return Ok(None);
    };
    if ![INT32, UINT32, FLOAT32, FLOAT64].contains(datatype) {
        return Err(decode_err(format!(
            "the point time field {name} has datatype {} ({datatype}); times are read from \
             float32, float64, uint32 or int32 (ignore them with --point-time none)",
            datatype_name(*datatype)
        )));
    }
    Ok(Some(TimeField {
        name: name.clone(),
        offset: *offset,
        datatype: *datatype,
    }))
}

/// Where one coordinate sits inside a point.
#[derive(Debug, Clone, Copy)]
struct Coordinate {
    offset: usize,
    float64: bool,
}

impl Coordinate {
    fn size(self) -> usize {
        if self.float64 { 8 } else { 4 }
    }

    fn read(self, point: &[u8], big_endian: bool) -> f64 {
        let bytes = &point[self.offset..self.offset + self.size()];
        if self.float64 {
            let mut b = [0u8; 8];
            b.copy_from_slice(bytes);
            if big_endian {
                f64::from_be_bytes(b)
            } else {
                f64::from_le_bytes(b)
            }
        } else {
            let mut b = [0u8; 4];
            b.copy_from_slice(bytes);
            f64::from(if big_endian {
                f32::from_be_bytes(b)
            } else {
                f32::from_le_bytes(b)
            })
        }
    }
}

/// Decodes a `sensor_msgs/PointCloud2`: x, y, z as FLOAT32 or FLOAT64 at any offsets and
/// `point_step`, organized (height > 1) or not, `is_bigendian` honoured; points with a
/// non-finite coordinate are dropped and counted; the time field `times` asks for is read
/// (see [`super::point_time`]); other fields are ignored.
pub fn decode_point_cloud2(
    cursor: &mut Cursor<'_>,
    times: &PointTimeChoice,
) -> Result<Cloud, DecodeError> {
    let header = cursor.header()?;
    let height = cursor.u32("height")? as usize;
    let width = cursor.u32("width")? as usize;
    // A PointField is at least a name length, offset, datatype and count: 13 bytes.
    let field_count = cursor.sequence_len(13, "fields")?;
    let (mut x, mut y, mut z) = (None, None, None);
    let mut fields = Vec::with_capacity(field_count);
    for _ in 0..field_count {
        let name = cursor.string("fields[].name")?;
        let offset = cursor.u32("fields[].offset")? as usize;
        let datatype = cursor.u8("fields[].datatype")?;
        let _count = cursor.u32("fields[].count")?;
        fields.push((name.clone(), offset, datatype));
        let slot = match name.as_str() {
            "x" => &mut x,
            "y" => &mut y,
            "z" => &mut z,
            _ => continue,
        };
        let float64 = match datatype {
            FLOAT32 => false,
            FLOAT64 => true,
            other => {
                return Err(decode_err(format!(
                    "field {name} has datatype {other}; only FLOAT32 (7) and FLOAT64 (8) \
                     coordinates are read"
                )));
            }
        };
        *slot = Some(Coordinate { offset, float64 });
    }
    let (Some(x), Some(y), Some(z)) = (x, y, z) else {
        let missing: Vec<&str> = [("x", x), ("y", y), ("z", z)]
            .iter()
            .filter(|(_, c)| c.is_none())
            .map(|(n, _)| *n)
            .collect();
        return Err(decode_err(format!(
            "the fields lack {}: a cloud needs x, y and z",
            missing.join(", ")
        )));
    };
    let big_endian = cursor.bool("is_bigendian")?;
    let point_step = cursor.u32("point_step")? as usize;
    let row_step = cursor.u32("row_step")? as usize;
    let data_len = cursor.sequence_len(1, "data")?;
    let data = cursor.take(data_len, "data")?;
    let time_field = choose_time_field(&fields, times)?;
    let time_span = time_field
        .iter()
        .map(|t| (t.name.as_str(), t.offset, t.size()));
    let xyz_spans = [("x", x), ("y", y), ("z", z)].map(|(n, c)| (n, c.offset, c.size()));
    for (name, offset, size) in xyz_spans.into_iter().chain(time_span) {
        if offset.saturating_add(size) > point_step {
            return Err(decode_err(format!(
                "field {name} at offset {offset} ({size} bytes) does not fit in point_step \
                 {point_step}"
            )));
        }
    }
    let row_bytes = width.checked_mul(point_step);
    if row_bytes.is_none_or(|b| b > row_step) {
        return Err(decode_err(format!(
            "row_step {row_step} is less than width {width} x point_step {point_step}"
        )));
    }
    if row_step.checked_mul(height) != Some(data.len()) {
        return Err(decode_err(format!(
            "row_step {row_step} x height {height} disagrees with the {} data bytes",
            data.len()
        )));
    }
    let mut points = Vec::with_capacity(width * height);
    let mut time_values = Vec::with_capacity(if time_field.is_some() {
        width * height
    } else {
        0
    });
    let mut non_finite = 0;
    for row in data.chunks_exact(row_step.max(1)).take(height) {
        for point in row[..width * point_step].chunks_exact(point_step.max(1)) {
            let p = Point3::new(
                x.read(point, big_endian),
                y.read(point, big_endian),
                z.read(point, big_endian),
            );
            if p.iter().all(|v| v.is_finite()) {
                points.push(p);
                if let Some(t) = &time_field {
                    time_values.push(t.read(point, big_endian));
                }
            } else {
                non_finite += 1;
            }
        }
    }
    Ok(Cloud {
        header,
        points,
        non_finite,
        times: time_field.map(|t| RawTimes {
            field: t.name,
            datatype: datatype_name(t.datatype),
            values: time_values,
            base_ns: 0,
        }),
    })
}

/// Bytes of one `CustomPoint` in ROS 1 (CDR may add up to 3 bytes of padding before the next).
const LIVOX_POINT_BYTES: usize = 4 + 3 * 4 + 3;

/// Decodes `livox_ros_driver/CustomMsg` (ROS 1) or `livox_ros_driver2/msg/CustomMsg` (ROS 2):
/// the Mid-360's native message that FAST-LIO reads. x, y, z are kept, and `offset_time`
/// (ns after `timebase`) unless `times` is [`PointTimeChoice::Ignore`].
pub fn decode_livox(
    cursor: &mut Cursor<'_>,
    times: &PointTimeChoice,
) -> Result<Cloud, DecodeError> {
    let header = cursor.header()?;
    let timebase_ns = cursor.u64("timebase")?;
    let keep_times = match times {
        PointTimeChoice::Ignore => false,
        PointTimeChoice::Auto => true,
        PointTimeChoice::Field { name, .. } if name == "offset_time" => true,
        PointTimeChoice::Field { name, .. } => {
            return Err(decode_err(format!(
                "no field {name} for --point-time: a Livox CustomMsg's point times are \
                 offset_time"
            )));
        }
    };
    let point_num = cursor.u32("point_num")? as usize;
    let _lidar_id = cursor.u8("lidar_id")?;
    cursor.take(3, "rsvd")?;
    let count = cursor.sequence_len(LIVOX_POINT_BYTES, "points")?;
    if count != point_num {
        return Err(decode_err(format!(
            "point_num is {point_num} but the points sequence holds {count}"
        )));
    }
    let mut points = Vec::with_capacity(count);
    let mut offsets = Vec::with_capacity(if keep_times { count } else { 0 });
    let mut non_finite = 0;
    for _ in 0..count {
        let offset_time = cursor.u32("points[].offset_time")?;
        let p = Point3::new(
            f64::from(cursor.f32("points[].x")?),
            f64::from(cursor.f32("points[].y")?),
            f64::from(cursor.f32("points[].z")?),
        );
        cursor.take(3, "points[].reflectivity, tag, line")?;
        if p.iter().all(|v| v.is_finite()) {
            points.push(p);
            if keep_times {
                offsets.push(f64::from(offset_time));
            }
        } else {
            non_finite += 1;
        }
    }
    // A timebase that does not fit i64 ns (past the year 2262) is read as the header stamp.
    let base_ns = i64::try_from(timebase_ns)
        .ok()
        .filter(|&b| b != 0)
        .unwrap_or(header.stamp_ns);
    Ok(Cloud {
        header,
        points,
        non_finite,
        times: keep_times.then(|| RawTimes {
            field: "offset_time".into(),
            datatype: "uint32",
            values: offsets,
            base_ns,
        }),
    })
}

/// A cloud message's header and its number of points (finite or not), read without the points:
/// enough to plan frames and size buffers before any cloud is decoded.
pub fn peek_cloud(cursor: &mut Cursor<'_>, livox: bool) -> Result<(Header, usize), DecodeError> {
    let header = cursor.header()?;
    let points = if livox {
        cursor.u64("timebase")?;
        cursor.u32("point_num")? as usize
    } else {
        let height = cursor.u32("height")? as usize;
        let width = cursor.u32("width")? as usize;
        height.saturating_mul(width)
    };
    Ok((header, points))
}
