//! Point-cloud messages: `sensor_msgs/PointCloud2` and the Livox drivers' `CustomMsg`.

use nalgebra::Point3;

use super::cursor::{Cursor, DecodeError, Header, decode_err};

/// One decoded cloud: finite points in the message's frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Cloud {
    /// The message header (stamp and frame).
    pub header: Header,
    /// Finite points, in message order (m).
    pub points: Vec<Point3<f64>>,
    /// Points dropped because a coordinate was NaN or infinite.
    pub non_finite: usize,
}

/// `sensor_msgs/PointField` datatype codes of the two float types.
const FLOAT32: u8 = 7;
const FLOAT64: u8 = 8;

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
/// non-finite coordinate are dropped and counted; other fields are ignored.
pub fn decode_point_cloud2(cursor: &mut Cursor<'_>) -> Result<Cloud, DecodeError> {
    let header = cursor.header()?;
    let height = cursor.u32("height")? as usize;
    let width = cursor.u32("width")? as usize;
    // A PointField is at least a name length, offset, datatype and count: 13 bytes.
    let field_count = cursor.sequence_len(13, "fields")?;
    let (mut x, mut y, mut z) = (None, None, None);
    for _ in 0..field_count {
        let name = cursor.string("fields[].name")?;
        let offset = cursor.u32("fields[].offset")? as usize;
        let datatype = cursor.u8("fields[].datatype")?;
        let _count = cursor.u32("fields[].count")?;
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
    for (name, c) in [("x", x), ("y", y), ("z", z)] {
        if c.offset + c.size() > point_step {
            return Err(decode_err(format!(
                "field {name} at offset {} ({} bytes) does not fit in point_step {point_step}",
                c.offset,
                c.size()
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
            } else {
                non_finite += 1;
            }
        }
    }
    Ok(Cloud {
        header,
        points,
        non_finite,
    })
}

/// Bytes of one `CustomPoint` in ROS 1 (CDR may add up to 3 bytes of padding before the next).
const LIVOX_POINT_BYTES: usize = 4 + 3 * 4 + 3;

/// Decodes `livox_ros_driver/CustomMsg` (ROS 1) or `livox_ros_driver2/msg/CustomMsg` (ROS 2):
/// the Mid-360's native message that FAST-LIO reads. Only x, y, z are kept.
pub fn decode_livox(cursor: &mut Cursor<'_>) -> Result<Cloud, DecodeError> {
    let header = cursor.header()?;
    let _timebase_ns = cursor.u64("timebase")?;
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
    let mut non_finite = 0;
    for _ in 0..count {
        let _offset_time = cursor.u32("points[].offset_time")?;
        let p = Point3::new(
            f64::from(cursor.f32("points[].x")?),
            f64::from(cursor.f32("points[].y")?),
            f64::from(cursor.f32("points[].z")?),
        );
        cursor.take(3, "points[].reflectivity, tag, line")?;
        if p.iter().all(|v| v.is_finite()) {
            points.push(p);
        } else {
            non_finite += 1;
        }
    }
    Ok(Cloud {
        header,
        points,
        non_finite,
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
