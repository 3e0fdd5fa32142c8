//! Reading a recording back: message counts per topic and the last trajectory of each poses
//! topic (used by the launcher's APE summary and by the replay tests).

use crate::RecordingError;
use crate::write::topics;
use foxglove::Decode;
use foxglove::schemas::packed_element_field::NumericType;
use foxglove::schemas::{PointCloud, PosesInFrame};
use nalgebra::{Isometry3, Point3, Quaternion, Translation3, UnitQuaternion};
use std::collections::BTreeMap;
use std::path::Path;

/// What a recording holds.
#[derive(Debug, Default, Clone)]
pub struct Recording {
    /// Messages per topic.
    pub counts: BTreeMap<String, usize>,
    /// Schema name per topic.
    pub schemas: BTreeMap<String, String>,
    /// Last `/pssba/poses/initial` message.
    pub initial: Vec<Isometry3<f64>>,
    /// Last `/pssba/poses/optimized` message.
    pub optimized: Vec<Isometry3<f64>>,
    /// Last `/pssba/poses/ground_truth` message (empty if none).
    pub ground_truth: Vec<Isometry3<f64>>,
    /// Every window's outcome, from `/pssba/diagnostics`, in order.
    pub windows: Vec<WindowRecord>,
    /// Frames the smooth stage dropped (live input, policy `drop`), from the end-of-run
    /// diagnostics; `None` if the run did not end normally.
    pub frames_dropped: Option<u64>,
}

/// One window as recorded in `/pssba/diagnostics`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WindowRecord {
    /// Window number.
    pub window: u64,
    /// Frames it made final (stream sequence numbers).
    pub final_frames: Vec<u64>,
    /// Why it failed, if it did (its final frames then kept their initial poses).
    pub error: Option<String>,
}

fn window_record(data: &[u8]) -> Option<WindowRecord> {
    let value: serde_json::Value = serde_json::from_slice(data).ok()?;
    if value["kind"] != "window" {
        return None;
    }
    Some(WindowRecord {
        window: value["window"].as_u64()?,
        final_frames: value["final_frames"]
            .as_array()
            .map(|a| a.iter().filter_map(serde_json::Value::as_u64).collect())
            .unwrap_or_default(),
        error: value["error"].as_str().map(str::to_owned),
    })
}

fn end_of_run_dropped(data: &[u8]) -> Option<u64> {
    let value: serde_json::Value = serde_json::from_slice(data).ok()?;
    (value["kind"] == "end_of_run").then(|| value["frames_dropped"].as_u64())?
}

/// The poses of a `PosesInFrame` message.
pub fn isometries(message: &PosesInFrame) -> Vec<Isometry3<f64>> {
    message
        .poses
        .iter()
        .map(|p| {
            let t = p.position.unwrap_or_default();
            let q = p.orientation.unwrap_or_default();
            Isometry3::from_parts(
                Translation3::new(t.x, t.y, t.z),
                UnitQuaternion::from_quaternion(Quaternion::new(q.w, q.x, q.y, q.z)),
            )
        })
        .collect()
}

/// Which bytes of a point hold x, y and z, and whether as f64.
fn layout(cloud: &PointCloud) -> Result<[(usize, bool); 3], String> {
    let stride = cloud.point_stride as usize;
    let mut out = [None; 3];
    for field in &cloud.fields {
        let slot = match field.name.as_str() {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            _ => continue,
        };
        let float64 = match NumericType::try_from(field.r#type) {
            Ok(NumericType::Float32) => false,
            Ok(NumericType::Float64) => true,
            _ => return Err(format!("field {} is not float32 or float64", field.name)),
        };
        let offset = field.offset as usize;
        if offset + if float64 { 8 } else { 4 } > stride {
            return Err(format!(
                "field {} does not fit in point_stride {stride}",
                field.name
            ));
        }
        out[slot] = Some((offset, float64));
    }
    match out {
        [Some(x), Some(y), Some(z)] => Ok([x, y, z]),
        _ => Err("a cloud without x, y and z fields".into()),
    }
}

/// The points of a `PointCloud` (x, y and z as float32 or float64, at any offsets within
/// `point_stride`), in the cloud's frame; the error says what does not fit.
pub fn cloud_points(cloud: &PointCloud) -> Result<Vec<Point3<f64>>, String> {
    let fields = layout(cloud)?;
    let stride = cloud.point_stride as usize;
    if stride == 0 || !cloud.data.len().is_multiple_of(stride) {
        return Err(format!(
            "{} data bytes are not a multiple of point_stride {stride}",
            cloud.data.len()
        ));
    }
    Ok(cloud
        .data
        .chunks_exact(stride)
        .map(|point| {
            let value = |(offset, float64): (usize, bool)| {
                if float64 {
                    let mut b = [0u8; 8];
                    b.copy_from_slice(&point[offset..offset + 8]);
                    f64::from_le_bytes(b)
                } else {
                    let mut b = [0u8; 4];
                    b.copy_from_slice(&point[offset..offset + 4]);
                    f64::from(f32::from_le_bytes(b))
                }
            };
            Point3::new(value(fields[0]), value(fields[1]), value(fields[2]))
        })
        .collect())
}

/// The points' times after the stamp (s) of a recorded frame's cloud: its float32 `time`
/// field ([`crate::TIME_FIELD`]), `None` without one; the error says what does not fit.
pub fn cloud_point_times(cloud: &PointCloud) -> Result<Option<Vec<f32>>, String> {
    let Some(field) = cloud.fields.iter().find(|f| f.name == crate::TIME_FIELD) else {
        return Ok(None);
    };
    if NumericType::try_from(field.r#type) != Ok(NumericType::Float32) {
        return Err(format!("field {} is not float32", field.name));
    }
    let (stride, offset) = (cloud.point_stride as usize, field.offset as usize);
    if offset + 4 > stride || !cloud.data.len().is_multiple_of(stride) {
        return Err(format!(
            "field {} at offset {offset} does not fit {} data bytes of point_stride {stride}",
            field.name,
            cloud.data.len()
        ));
    }
    Ok(Some(
        cloud
            .data
            .chunks_exact(stride)
            .map(|point| {
                let mut b = [0u8; 4];
                b.copy_from_slice(&point[offset..offset + 4]);
                f32::from_le_bytes(b)
            })
            .collect(),
    ))
}

/// Reads `path` completely, one message at a time.
pub fn read_recording(path: &Path) -> crate::Result<Recording> {
    let mut recording = Recording::default();
    // Record lengths bounded by the file's size: a corrupt length is an error, not a huge
    // allocation (crates/pssba-system/fuzz, target replay_mcap).
    let reader = pssba_bag::mcap_message_reader(path)
        .map_err(|e| RecordingError::read(path, e.to_string()))?;
    for message in reader {
        let message =
            message.map_err(|e| RecordingError::read(path, format!("bad record: {e}")))?;
        let topic = message.channel.topic.clone();
        *recording.counts.entry(topic.clone()).or_default() += 1;
        if let Some(schema) = &message.channel.schema {
            recording.schemas.insert(topic.clone(), schema.name.clone());
        }
        let slot = match topic.as_str() {
            topics::INITIAL => &mut recording.initial,
            topics::OPTIMIZED => &mut recording.optimized,
            topics::GROUND_TRUTH => &mut recording.ground_truth,
            topics::DIAGNOSTICS => {
                recording.windows.extend(window_record(&message.data));
                if let Some(dropped) = end_of_run_dropped(&message.data) {
                    recording.frames_dropped = Some(dropped);
                }
                continue;
            }
            _ => continue,
        };
        let poses = PosesInFrame::decode(&message.data[..])
            .map_err(|e| RecordingError::read(path, format!("decoding {topic}: {e}")))?;
        *slot = isometries(&poses);
    }
    Ok(recording)
}

/// Reads every part of a recording to `out` ([`crate::existing_parts`]: a record
/// stage restarted after a crash goes on in a new part) as one: message counts add up, windows
/// follow one another, and each trajectory is the last one written in any part (a later part
/// goes on from the whole run's frames).
pub fn read_recording_parts(out: &Path) -> crate::Result<Recording> {
    let mut whole = Recording::default();
    for path in crate::existing_parts(out) {
        let part = read_recording(&path)?;
        for (topic, count) in part.counts {
            *whole.counts.entry(topic).or_default() += count;
        }
        whole.schemas.extend(part.schemas);
        for (slot, poses) in [
            (&mut whole.initial, part.initial),
            (&mut whole.optimized, part.optimized),
            (&mut whole.ground_truth, part.ground_truth),
        ] {
            if !poses.is_empty() {
                *slot = poses;
            }
        }
        whole.windows.extend(part.windows);
        whole.frames_dropped = part.frames_dropped.or(whole.frames_dropped);
    }
    Ok(whole)
}
