//! The recording format: MCAP with Foxglove schemas (zstd chunks of at most 1 MiB), written
//! through any `Write + Seek`. Topics:
//! - `/lidar/points` (foxglove.PointCloud, frame `lidar`): each input frame, x/y/z float32;
//! - `/tf` (foxglove.FrameTransform, `world` -> `lidar`): each final pose at its frame's stamp;
//! - `/pssba/poses/initial`, `/pssba/poses/optimized`, `/pssba/poses/ground_truth`
//!   (foxglove.PosesInFrame, frame `world`): every pose known so far in frame order, written
//!   after each window, so the last message of a topic is the whole trajectory;
//! - `/pssba/map` (foxglove.PointCloud, frame `world`): each window's smoothed cloud;
//! - `/pssba/surfaces` (JSON, schema [`SURFACES_SCHEMA`]): each window's fitted surfaces;
//! - `/pssba/diagnostics` (JSON, schema [`DIAGNOSTICS_SCHEMA`]): per-scale reports.

use crate::RecordingError;
use foxglove::Encode;
use foxglove::schemas::packed_element_field::NumericType;
use foxglove::schemas::{
    FrameTransform, PackedElementField, PointCloud, Pose, PosesInFrame, Quaternion, Timestamp,
    Vector3,
};
use nalgebra::{Isometry3, Point3};
use pssba_msg::WindowResult;
use std::collections::BTreeMap;
use std::io::{Seek, Write};

/// JSON schema of `/pssba/surfaces` messages.
pub const SURFACES_SCHEMA: &str = r#"{"title":"pssba.Surfaces","type":"object","properties":{
"window":{"type":"integer"},"surfaces":{"type":"array","items":{"type":"object","properties":{
"frame":{"type":"integer","description":"sequence of the frame whose point is the kernel"},
"kernel_in_world":{"type":"array","items":{"type":"number"},"description":"m"},
"tangent_from_world":{"type":"array","items":{"type":"number"},"description":"3x3 row-major; last row = normal"},
"coefficients":{"type":"array","items":{"type":"number"},"description":"z = a0 x^2 + a1 y^2 + a2 xy + a3 x + a4 y + a5 in tangent coordinates (m)"},
"gamma_m":{"type":"number"}}}}}}"#;

/// JSON schema of `/pssba/diagnostics` messages.
pub const DIAGNOSTICS_SCHEMA: &str = r#"{"title":"pssba.Diagnostics","type":"object","properties":{
"kind":{"type":"string","enum":["window","lm_solve"]},"window":{"type":"integer"},
"converged":{"type":"boolean"},"scales":{"type":"array","items":{"type":"object"},
"description":"pssba_core::ScaleReport per scale: gamma_m, cloud_points, kernels_used, kernels_rejected, residuals, cost_before, cost_after, iterations, pose_change, unconstrained_frames, wall_time_s"},
"scale":{"type":"integer"},"cost_before":{"type":"number"},"cost_after":{"type":"number"},
"iterations":{"type":"integer"},"residuals":{"type":"integer"},"solve_time_s":{"type":"number"}}}"#;

/// Topic names.
pub mod topics {
    /// Input clouds.
    pub const POINTS: &str = "/lidar/points";
    /// Final poses as transforms.
    pub const TF: &str = "/tf";
    /// Initial poses.
    pub const INITIAL: &str = "/pssba/poses/initial";
    /// Optimised poses.
    pub const OPTIMIZED: &str = "/pssba/poses/optimized";
    /// Ground truth.
    pub const GROUND_TRUTH: &str = "/pssba/poses/ground_truth";
    /// Smoothed map.
    pub const MAP: &str = "/pssba/map";
    /// Fitted surfaces.
    pub const SURFACES: &str = "/pssba/surfaces";
    /// Per-scale reports.
    pub const DIAGNOSTICS: &str = "/pssba/diagnostics";
}

/// Chunk size bound: what a crash can lose.
const CHUNK_BYTES: u64 = 1 << 20;

/// What the recorder knows of a frame: the trajectories it writes after each window are
/// made of these (kept by the record stage's journal for a restart, the record stage's `record_journal`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KnownFrame {
    /// Stamp (s).
    pub stamp_s: f64,
    /// Initial pose (world from lidar).
    pub initial: Isometry3<f64>,
    /// Ground truth, if the source has it.
    pub ground_truth: Option<Isometry3<f64>>,
    /// Final pose, once its window is done.
    pub optimized: Option<Isometry3<f64>>,
}

/// The file of part `part` (1, 2, ...) of a recording to `out`: `out` itself for the first,
/// `run.part2.mcap` beside `run.mcap` for the second (a restarted record stage goes on in a
/// new part), and so on.
pub fn part_path(out: &std::path::Path, part: u64) -> std::path::PathBuf {
    if part <= 1 {
        return out.to_path_buf();
    }
    match out.extension().and_then(|e| e.to_str()) {
        Some(ext) => out.with_extension(format!("part{part}.{ext}")),
        None => out.with_extension(format!("part{part}")),
    }
}

/// Every part of a recording to `out` that exists, in order (see [`part_path`]).
pub fn existing_parts(out: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut parts = vec![out.to_path_buf()];
    for part in 2.. {
        let path = part_path(out, part);
        if !path.exists() {
            break;
        }
        parts.push(path);
    }
    parts
}

/// Writes a run's MCAP file.
pub struct McapRecorder<W: Write + Seek> {
    writer: mcap::Writer<W>,
    channels: BTreeMap<&'static str, u16>,
    sequence: u32,
    frames: Vec<KnownFrame>,
}

impl<W: Write + Seek> std::fmt::Debug for McapRecorder<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapRecorder")
            .field("frames", &self.frames.len())
            .finish_non_exhaustive()
    }
}

fn stamp_ns(stamp_s: f64) -> u64 {
    if stamp_s.is_finite() && stamp_s > 0.0 {
        (stamp_s * 1e9) as u64
    } else {
        0
    }
}

fn timestamp(stamp_s: f64) -> Timestamp {
    let ns = stamp_ns(stamp_s);
    Timestamp::new_checked((ns / 1_000_000_000) as u32, (ns % 1_000_000_000) as u32)
        .unwrap_or(Timestamp::MAX)
}

fn pose(world_from_lidar: &Isometry3<f64>) -> Pose {
    let t = world_from_lidar.translation.vector;
    let q = world_from_lidar.rotation;
    Pose {
        position: Some(Vector3 {
            x: t.x,
            y: t.y,
            z: t.z,
        }),
        orientation: Some(Quaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        }),
    }
}

/// A float32 x/y/z cloud.
/// A `PointCloud` of float32 x, y, z, and with `times_s` (one per point) a float32 `time`
/// field: each point's time after the stamp (s), as the frames carried it.
fn point_cloud(
    stamp_s: f64,
    frame_id: &str,
    xyz: impl Iterator<Item = [f32; 3]>,
    times_s: Option<&[f32]>,
) -> PointCloud {
    let mut data = Vec::new();
    let mut times = times_s.map(|t| t.iter());
    for p in xyz {
        for v in p {
            data.extend_from_slice(&v.to_le_bytes());
        }
        if let Some(times) = &mut times {
            let t = times.next().copied().unwrap_or(0.0);
            data.extend_from_slice(&t.to_le_bytes());
        }
    }
    let field = |name: &str, offset| PackedElementField {
        name: name.into(),
        offset,
        r#type: NumericType::Float32 as i32,
    };
    let mut fields = vec![field("x", 0), field("y", 4), field("z", 8)];
    if times_s.is_some() {
        fields.push(field(TIME_FIELD, 12));
    }
    PointCloud {
        timestamp: Some(timestamp(stamp_s)),
        frame_id: frame_id.into(),
        pose: Some(pose(&Isometry3::identity())),
        point_stride: if times_s.is_some() { 16 } else { 12 },
        fields,
        data: data.into(),
    }
}

/// The field of a recorded frame's cloud that holds each point's time after the stamp (s).
pub const TIME_FIELD: &str = "time";

impl<W: Write + Seek> McapRecorder<W> {
    /// Starts a recording with all channels declared.
    pub fn new(out: W) -> crate::Result<Self> {
        Self::resume(out, Vec::new())
    }

    /// Starts a further part of a recording whose earlier parts hold `frames` (their
    /// trajectories go on from there; the frames' clouds and transforms are not repeated).
    pub fn resume(out: W, frames: Vec<KnownFrame>) -> crate::Result<Self> {
        let mut writer = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .compression_threads(0)
            .chunk_size(Some(CHUNK_BYTES))
            .profile("")
            .library("pssba-record")
            .create(out)?;
        let mut channels = BTreeMap::new();
        let mut protobuf =
            |writer: &mut mcap::Writer<W>, topic, schema: Option<foxglove::Schema>| {
                let schema = schema.ok_or(RecordingError::Encode {
                    topic,
                    message: "the foxglove crate has no schema for it".into(),
                })?;
                let id = writer.add_schema(&schema.name, &schema.encoding, &schema.data)?;
                let channel = writer.add_channel(id, topic, "protobuf", &BTreeMap::new())?;
                channels.insert(topic, channel);
                Ok::<(), RecordingError>(())
            };
        protobuf(&mut writer, topics::POINTS, PointCloud::get_schema())?;
        protobuf(&mut writer, topics::MAP, PointCloud::get_schema())?;
        protobuf(&mut writer, topics::TF, FrameTransform::get_schema())?;
        for topic in [topics::INITIAL, topics::OPTIMIZED, topics::GROUND_TRUTH] {
            protobuf(&mut writer, topic, PosesInFrame::get_schema())?;
        }
        for (topic, name, schema) in [
            (topics::SURFACES, "pssba.Surfaces", SURFACES_SCHEMA),
            (topics::DIAGNOSTICS, "pssba.Diagnostics", DIAGNOSTICS_SCHEMA),
        ] {
            let id = writer.add_schema(name, "jsonschema", schema.as_bytes())?;
            let channel = writer.add_channel(id, topic, "json", &BTreeMap::new())?;
            channels.insert(topic, channel);
        }
        Ok(Self {
            writer,
            channels,
            sequence: 0,
            frames,
        })
    }

    fn write_bytes(&mut self, topic: &'static str, stamp_s: f64, data: &[u8]) -> crate::Result<()> {
        let channel_id = *self.channels.get(topic).ok_or(RecordingError::Encode {
            topic,
            message: "undeclared topic".into(),
        })?;
        self.sequence += 1;
        let time = stamp_ns(stamp_s);
        self.writer.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id,
                sequence: self.sequence,
                log_time: time,
                publish_time: time,
            },
            data,
        )?;
        Ok(())
    }

    fn write<M: Encode>(
        &mut self,
        topic: &'static str,
        stamp_s: f64,
        message: &M,
    ) -> crate::Result<()> {
        let mut buf = Vec::with_capacity(message.encoded_len().unwrap_or(256));
        message
            .encode(&mut buf)
            .map_err(|e| RecordingError::Encode {
                topic,
                message: e.to_string(),
            })?;
        self.write_bytes(topic, stamp_s, &buf)
    }

    /// Records an input frame (points in the lidar frame).
    /// Records a frame's cloud (with each point's time after the stamp, when it has them).
    pub fn add_frame(
        &mut self,
        frame: KnownFrame,
        points: &[[f32; 3]],
        times_s: Option<&[f32]>,
    ) -> crate::Result<()> {
        if let Some(times_s) = times_s
            && times_s.len() != points.len()
        {
            return Err(RecordingError::PointTimes {
                points: points.len(),
                times: times_s.len(),
            });
        }
        self.frames.push(frame);
        let cloud = point_cloud(frame.stamp_s, "lidar", points.iter().copied(), times_s);
        self.write(topics::POINTS, frame.stamp_s, &cloud)
    }

    /// Records a finished window: transforms, trajectories, map, surfaces, diagnostics.
    pub fn add_window(&mut self, result: &WindowResult) -> crate::Result<()> {
        let mut latest_stamp = self.frames.last().map_or(0.0, |f| f.stamp_s);
        for f in &result.finals {
            let known = self
                .frames
                .get_mut(f.sequence as usize)
                .ok_or(RecordingError::UnknownFrame(f.sequence))?;
            known.optimized = Some(f.world_from_lidar);
            latest_stamp = f.stamp_s;
            let p = pose(&f.world_from_lidar);
            let tf = FrameTransform {
                timestamp: Some(timestamp(f.stamp_s)),
                parent_frame_id: "world".into(),
                child_frame_id: "lidar".into(),
                translation: p.position,
                rotation: p.orientation,
            };
            self.write(topics::TF, f.stamp_s, &tf)?;
        }
        // A loop closure's moved frames: /tf keeps what was published when they became final;
        // the trajectory below (the whole of it, every window) carries their new poses.
        for f in &result.revised {
            let known = self
                .frames
                .get_mut(f.sequence as usize)
                .ok_or(RecordingError::UnknownFrame(f.sequence))?;
            known.optimized = Some(f.world_from_lidar);
        }
        self.write_trajectories(latest_stamp)?;
        let map = point_cloud(
            latest_stamp,
            "world",
            result
                .map
                .iter()
                .map(|p: &Point3<f64>| [p.x as f32, p.y as f32, p.z as f32]),
            None,
        );
        self.write(topics::MAP, latest_stamp, &map)?;
        let surfaces = serde_json::json!({ "window": result.window, "surfaces": result.surfaces });
        self.write_bytes(
            topics::SURFACES,
            latest_stamp,
            &json_bytes(topics::SURFACES, &surfaces)?,
        )?;
        let diagnostics = serde_json::json!({
            "kind": "window",
            "window": result.window,
            "converged": result.converged,
            "failed": result.failure.is_some(),
            "error": result.failure,
            "final_frames": result.finals.iter().map(|f| f.sequence).collect::<Vec<_>>(),
            "frames_dropped": result.frames_dropped,
            "scales": result.scales,
        });
        self.write_bytes(
            topics::DIAGNOSTICS,
            latest_stamp,
            &json_bytes(topics::DIAGNOSTICS, &diagnostics)?,
        )
    }

    /// Records the end of the run: frames the smooth stage took, and how many it dropped.
    pub fn add_end_of_run(&mut self, frames_taken: u64, frames_dropped: u64) -> crate::Result<()> {
        let stamp = self.frames.last().map_or(0.0, |f| f.stamp_s);
        let message = serde_json::json!({
            "kind": "end_of_run",
            "frames_recorded": self.frames.len(),
            "frames_adjusted": frames_taken,
            "frames_dropped": frames_dropped,
        });
        self.write_bytes(
            topics::DIAGNOSTICS,
            stamp,
            &json_bytes(topics::DIAGNOSTICS, &message)?,
        )
    }

    /// Records one LM solve's report from the adjust stage.
    pub fn add_solve(&mut self, header: &pssba_msg::PoseSetHeader) -> crate::Result<()> {
        let stamp = self.frames.last().map_or(0.0, |f| f.stamp_s);
        let message = serde_json::json!({
            "kind": "lm_solve",
            "window": header.window,
            "scale": header.scale,
            "cost_before": header.cost_before,
            "cost_after": header.cost_after,
            "iterations": header.iterations,
            "residuals": header.residuals,
            "solve_time_s": header.solve_time_s,
        });
        self.write_bytes(
            topics::DIAGNOSTICS,
            stamp,
            &json_bytes(topics::DIAGNOSTICS, &message)?,
        )
    }

    fn write_trajectories(&mut self, stamp_s: f64) -> crate::Result<()> {
        let poses_in_world = |poses: Vec<Pose>| PosesInFrame {
            timestamp: Some(timestamp(stamp_s)),
            frame_id: "world".into(),
            poses,
        };
        let initial = poses_in_world(self.frames.iter().map(|f| pose(&f.initial)).collect());
        // Every frame with a final pose (in order: windows end in order; a frame dropped by
        // the smooth stage has none).
        let optimized = poses_in_world(
            self.frames
                .iter()
                .filter_map(|f| f.optimized.as_ref().map(pose))
                .collect(),
        );
        let ground_truth: Vec<Pose> = self
            .frames
            .iter()
            .map_while(|f| f.ground_truth.as_ref().map(pose))
            .collect();
        self.write(topics::INITIAL, stamp_s, &initial)?;
        self.write(topics::OPTIMIZED, stamp_s, &optimized)?;
        if !ground_truth.is_empty() {
            self.write(topics::GROUND_TRUTH, stamp_s, &poses_in_world(ground_truth))?;
        }
        Ok(())
    }

    /// Frames recorded.
    pub fn frames(&self) -> usize {
        self.frames.len()
    }

    /// Finishes the current chunk and writes everything out: the file then ends on a whole
    /// record, a point [`end_cut_file`] can end it at if a later write fails.
    pub fn flush(&mut self) -> crate::Result<()> {
        self.writer.flush()?;
        Ok(())
    }

    /// Copies a message of another recording in this format, its sequence and times kept
    /// (the summary rebuild of a cut part, `recover.rs`); `false` for a topic this format
    /// does not have.
    pub(crate) fn copy_message(&mut self, message: &mcap::Message<'_>) -> crate::Result<bool> {
        let Some(&channel_id) = self.channels.get(message.channel.topic.as_str()) else {
            return Ok(false);
        };
        self.writer.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id,
                sequence: message.sequence,
                log_time: message.log_time,
                publish_time: message.publish_time,
            },
            &message.data,
        )?;
        Ok(true)
    }

    /// Writes the summary and closes the file.
    pub fn finish(mut self) -> crate::Result<()> {
        self.writer.finish()?;
        Ok(())
    }
}

/// Ends an MCAP file whose writing failed (a full disk), keeping its first `clean_len` bytes:
/// the part up to the last [`McapRecorder::flush`], which ends on a whole record. A data-end
/// record, a footer without a summary section and the closing magic follow (50 bytes, in
/// the room the cut-off tail leaves), so MCAP readers read every message before the cut by
/// scanning the file.
pub fn end_cut_file(path: &std::path::Path, clean_len: u64) -> crate::Result<()> {
    use std::io::{Seek, SeekFrom};
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .open(path)
        .map_err(|e| io_error("opening to end it", path, e))?;
    file.set_len(clean_len)
        .and_then(|()| file.seek(SeekFrom::Start(clean_len)))
        .map_err(|e| io_error("cutting back to its last whole record", path, e))?;
    let mut tail = Vec::with_capacity(50);
    // Data End (opcode 0x0F): data_section_crc = 0, "not computed".
    tail.push(0x0F);
    tail.extend_from_slice(&4u64.to_le_bytes());
    tail.extend_from_slice(&0u32.to_le_bytes());
    // Footer (opcode 0x02): no summary section, no summary offsets, no summary CRC.
    tail.push(0x02);
    tail.extend_from_slice(&20u64.to_le_bytes());
    tail.extend_from_slice(&0u64.to_le_bytes());
    tail.extend_from_slice(&0u64.to_le_bytes());
    tail.extend_from_slice(&0u32.to_le_bytes());
    tail.extend_from_slice(mcap::MAGIC);
    file.write_all(&tail)
        .and_then(|()| file.sync_all())
        .map_err(|e| io_error("ending", path, e))
}

fn io_error(what: &'static str, path: &std::path::Path, source: std::io::Error) -> RecordingError {
    RecordingError::Io {
        what,
        path: path.to_path_buf(),
        source,
    }
}

fn json_bytes(topic: &'static str, value: &serde_json::Value) -> crate::Result<Vec<u8>> {
    serde_json::to_vec(value).map_err(|e| RecordingError::Encode {
        topic,
        message: e.to_string(),
    })
}
