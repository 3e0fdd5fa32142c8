//! Frames and initial poses from a recording, the way a LIO stack records them.
//!
//! - Each message on the cloud topic is a frame, stamped with its header stamp.
//! - The pose topic (Odometry, PoseStamped) gives `world_from_body`; a frame's pose is the pose
//!   at its stamp, exact or interpolated ([`Trajectory::at`]); a frame outside the pose range
//!   or across a gap larger than [`RecordingOptions::max_pose_gap_s`] is skipped and counted.
//! - `body_from_lidar` comes from `--extrinsic`, else from `/tf_static` (or `/tf`) when it links
//!   the body frame (or, for PoseStamped, any frame) to the cloud's frame, else identity with a
//!   warning. `world_from_lidar = world_from_body * body_from_lidar`.
//! - A cloud whose frame is the pose topic's parent frame (FAST-LIO's `/cloud_registered`) is
//!   already in the world frame: it is taken back into the sensor frame with
//!   `lidar_from_world`.
//!
//! - Point times (a Livox `offset_time`, a PointCloud2 `t`, `time`, `timestamp` field): each
//!   point's time after its frame's header stamp, the unit and origin told from the first
//!   frame's values ([`msg::point_time`]), or as [`RecordingOptions::point_time`] says. Clouds
//!   in the world frame are taken as already de-skewed: their times are not read.
//!
//! [`Recording::open`] makes one pass over the pose, tf and cloud topics (clouds are peeked
//! at, not decoded, but the first, whose times tell their convention) and plans every frame;
//! [`Recording::frames`] then streams the frames, decoding one cloud at a time.

use std::collections::HashMap;
use std::ops::Range;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Point3};

use crate::bag::{Bag, Messages, TopicInfo};
use crate::error::BagError;
use crate::msg::{self, Kind, PointTimeChoice, PointTimeConvention};
use crate::trajectory::{NoPose, Trajectory};

/// Topics searched for the extrinsic.
pub const TF_TOPICS: [&str; 2] = ["/tf_static", "/tf"];

/// Default of [`RecordingOptions::max_pose_gap_s`].
pub const DEFAULT_MAX_POSE_GAP_S: f64 = 0.5;

/// How to turn a recording into frames.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordingOptions {
    /// The cloud topic; `None` picks the only cloud topic.
    pub points_topic: Option<String>,
    /// The pose topic; `None` picks the only pose topic.
    pub poses_topic: Option<String>,
    /// `body_from_lidar`, overriding `/tf_static`.
    pub extrinsic: Option<Isometry3<f64>>,
    /// A frame between two poses further apart than this (s) is skipped.
    pub max_pose_gap_s: f64,
    /// Keep frames stamped at or after the recording's start + this (s).
    pub start_s: Option<f64>,
    /// Keep frames stamped before the start (+ `start_s`) + this (s).
    pub duration_s: Option<f64>,
    /// Keep these cloud messages (0-based on the cloud topic).
    pub frames: Option<Range<usize>>,
    /// Which field gives each point's time (`--point-time`).
    #[serde(default)]
    pub point_time: PointTimeChoice,
}

impl Default for RecordingOptions {
    fn default() -> Self {
        RecordingOptions {
            points_topic: None,
            poses_topic: None,
            extrinsic: None,
            max_pose_gap_s: DEFAULT_MAX_POSE_GAP_S,
            start_s: None,
            duration_s: None,
            frames: None,
            point_time: PointTimeChoice::Auto,
        }
    }
}

/// Where `body_from_lidar` came from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ExtrinsicSource {
    /// `--extrinsic` or configuration.
    Given,
    /// A chain of transforms in `/tf_static` or `/tf` from `body` to `lidar`.
    Tf {
        /// Body frame.
        body: String,
        /// Cloud frame.
        lidar: String,
    },
    /// The clouds are in the body frame.
    SameFrame,
    /// Nothing links the frames: identity (warned).
    AssumedIdentity,
}

/// Frames left out, by reason.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct Skipped {
    /// Outside `--start/--duration` or `--frames`.
    pub not_selected: usize,
    /// Stamped before the first or after the last pose.
    pub outside_pose_range: usize,
    /// Between two poses further apart than the allowed gap.
    pub pose_gap: usize,
    /// Stamped at or before the previous frame.
    pub out_of_order: usize,
}

impl Skipped {
    /// All frames skipped.
    pub fn total(&self) -> usize {
        self.not_selected + self.outside_pose_range + self.pose_gap + self.out_of_order
    }
}

/// A frame planned from the cloud topic's index, before its points are read.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedFrame {
    /// Index of its message on the cloud topic.
    pub message_index: u64,
    /// Header stamp (ns).
    pub stamp_ns: i64,
    /// Its initial pose.
    pub world_from_lidar: Isometry3<f64>,
    /// Points in the message (finite or not).
    pub points: usize,
}

/// A recording with its topics chosen and every frame planned.
#[derive(Debug)]
pub struct Recording {
    bag: Bag,
    /// The cloud topic.
    pub points_topic: TopicInfo,
    points_kind: Kind,
    /// The pose topic.
    pub poses_topic: TopicInfo,
    /// The world frame (the pose topic's parent).
    pub world_frame: String,
    /// The body frame (the pose topic's child), when it names one.
    pub body_frame: Option<String>,
    /// The clouds' frame.
    pub cloud_frame: String,
    /// True when the clouds are in the world frame and are taken back to the sensor frame.
    pub clouds_in_world: bool,
    /// `body_from_lidar`.
    pub extrinsic: Isometry3<f64>,
    /// Where it came from.
    pub extrinsic_source: ExtrinsicSource,
    /// The frames, in stamp order.
    pub frames: Vec<PlannedFrame>,
    /// Frames left out.
    pub skipped: Skipped,
    /// Poses on the pose topic.
    pub pose_count: usize,
    /// The largest pose gap a frame's pose was interpolated across (s), as given.
    pub max_pose_gap_s: f64,
    /// How the clouds' point times read, when they have them (and they are asked for).
    pub point_time: Option<PointTimeConvention>,
    point_time_choice: PointTimeChoice,
}

fn kind_list(topics: &[&TopicInfo]) -> String {
    topics
        .iter()
        .map(|t| format!("{} ({}, {} messages)", t.name, t.type_name, t.count))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Picks the topic named, or the only topic of a fitting kind.
fn choose_topic(
    bag: &Bag,
    named: Option<&str>,
    fits: fn(Kind) -> bool,
    what: &str,
    flag: &str,
) -> Result<(TopicInfo, Kind), BagError> {
    let fitting: Vec<&TopicInfo> = bag
        .topics()
        .iter()
        .filter(|t| Kind::of(&t.type_name).is_some_and(fits))
        .collect();
    let fail = |m: String| BagError::recording(bag.path(), m);
    if let Some(name) = named {
        let Some(topic) = bag.topic(name) else {
            let all: Vec<&TopicInfo> = bag.topics().iter().collect();
            return Err(fail(format!(
                "no topic {name}; the recording has: {}",
                kind_list(&all)
            )));
        };
        let kind = Kind::of(&topic.type_name)
            .filter(|k| fits(*k))
            .ok_or_else(|| {
                fail(format!(
                    "{flag} {name} is {}, not a {what} type; {what} topics: {}",
                    topic.type_name,
                    if fitting.is_empty() {
                        "none".to_string()
                    } else {
                        kind_list(&fitting)
                    }
                ))
            })?;
        return Ok((topic.clone(), kind));
    }
    match fitting[..] {
        [only] => {
            tracing::info!(
                "{what} topic: {} ({}, {} messages)",
                only.name,
                only.type_name,
                only.count
            );
            let kind = Kind::of(&only.type_name).filter(|k| fits(*k));
            Ok((
                only.clone(),
                kind.ok_or_else(|| fail("unreachable: fitting topic".into()))?,
            ))
        }
        [] => {
            let all: Vec<&TopicInfo> = bag.topics().iter().collect();
            Err(fail(format!(
                "no {what} topic (sensor_msgs/PointCloud2 or Livox CustomMsg for clouds; \
                 nav_msgs/Odometry, geometry_msgs/PoseStamped or PoseWithCovarianceStamped for \
                 poses); the recording has: {}",
                kind_list(&all)
            )))
        }
        _ => Err(fail(format!(
            "several {what} topics, choose one with {flag}: {}",
            kind_list(&fitting)
        ))),
    }
}

fn message_error(path: &Path, topic: &TopicInfo, index: u64, source: msg::DecodeError) -> BagError {
    BagError::Message {
        path: path.to_path_buf(),
        topic: topic.name.clone(),
        type_name: topic.type_name.clone(),
        index,
        cause: source,
    }
}

/// A tree of static transforms: child -> (parent, parent_from_child).
#[derive(Debug, Default)]
struct TfTree(HashMap<String, (String, Isometry3<f64>)>);

impl TfTree {
    /// `root_from_frame` and the root's name.
    fn to_root(&self, frame: &str) -> (String, Isometry3<f64>) {
        let mut name = frame.to_string();
        let mut root_from_frame = Isometry3::identity();
        for _ in 0..64 {
            match self.0.get(&name) {
                Some((parent, parent_from_child)) => {
                    root_from_frame = parent_from_child * root_from_frame;
                    name = parent.clone();
                }
                None => break,
            }
        }
        (name, root_from_frame)
    }

    /// `a_from_b`, when both frames hang in the same tree.
    fn between(&self, a: &str, b: &str) -> Option<Isometry3<f64>> {
        let (root_a, root_from_a) = self.to_root(a);
        let (root_b, root_from_b) = self.to_root(b);
        (root_a == root_b && (self.0.contains_key(a) || self.0.contains_key(b)))
            .then(|| root_from_a.inverse() * root_from_b)
    }
}

/// What the planning pass collects.
struct Scan {
    poses: Vec<(i64, Isometry3<f64>)>,
    world_frame: Option<String>,
    body_frame: Option<String>,
    tf: TfTree,
    clouds: Vec<(u64, i64, usize)>,
    cloud_frame: Option<String>,
    point_time: Option<PointTimeConvention>,
}

impl Recording {
    /// Opens a recording, chooses its topics and plans its frames (one pass, no cloud decoded).
    pub fn open(path: impl AsRef<Path>, options: &RecordingOptions) -> Result<Recording, BagError> {
        let bag = Bag::open(path)?;
        let path = bag.path().to_path_buf();
        let fail = |m: String| BagError::recording(&path, m);
        if options.max_pose_gap_s.is_nan() || options.max_pose_gap_s <= 0.0 {
            return Err(fail(format!(
                "max_pose_gap_s is {}, must be > 0",
                options.max_pose_gap_s
            )));
        }
        let (points_topic, points_kind) = choose_topic(
            &bag,
            options.points_topic.as_deref(),
            Kind::is_cloud,
            "point cloud",
            "--points-topic",
        )?;
        let (poses_topic, poses_kind) = choose_topic(
            &bag,
            options.poses_topic.as_deref(),
            Kind::is_pose,
            "pose",
            "--poses-topic",
        )?;
        let scan = scan(
            &bag,
            (&points_topic, points_kind),
            (&poses_topic, poses_kind),
            &options.point_time,
        )?;
        let Some(cloud_frame) = scan.cloud_frame.clone() else {
            return Err(fail(format!("{} has no messages", points_topic.name)));
        };
        let world_frame = scan.world_frame.clone().unwrap_or_default();
        if scan.poses.is_empty() {
            return Err(fail(format!("{} has no messages", poses_topic.name)));
        }
        let clouds_in_world = cloud_frame == world_frame;
        let (extrinsic, extrinsic_source) =
            extrinsic(options, &scan, &cloud_frame, clouds_in_world);
        if extrinsic_source == ExtrinsicSource::AssumedIdentity {
            tracing::warn!(
                "{}: nothing links the pose frame {} to the cloud frame {cloud_frame} \
                 (no /tf_static, no --extrinsic): assuming an identity extrinsic",
                path.display(),
                scan.body_frame.as_deref().unwrap_or("(unnamed)")
            );
        }
        let trajectory = Trajectory::new(scan.poses.clone());
        let bag_start = bag.time_range_ns().map_or(0, |r| r.0);
        let (frames, skipped) =
            plan_frames(&scan.clouds, &trajectory, &extrinsic, options, bag_start);
        if frames.is_empty() {
            let span = |r: Option<(i64, i64)>| {
                r.map_or("nothing".into(), |(a, b)| {
                    format!("{:.3}..{:.3} s", a as f64 * 1e-9, b as f64 * 1e-9)
                })
            };
            let cloud_range = scan
                .clouds
                .iter()
                .map(|c| c.1)
                .min()
                .zip(scan.clouds.iter().map(|c| c.1).max());
            return Err(fail(format!(
                "no frame has a pose: {} clouds on {} span {}, {} poses on {} span {} \
                 (skipped: {} not selected, {} outside the pose range, {} across a pose gap \
                 over {} s, {} out of order)",
                scan.clouds.len(),
                points_topic.name,
                span(cloud_range),
                trajectory.len(),
                poses_topic.name,
                span(trajectory.range_ns()),
                skipped.not_selected,
                skipped.outside_pose_range,
                skipped.pose_gap,
                options.max_pose_gap_s,
                skipped.out_of_order
            )));
        }
        let unplanned = skipped.total() - skipped.not_selected;
        if unplanned > 0 {
            tracing::warn!(
                "{}: {unplanned} of {} clouds on {} have no pose and are skipped: {} outside \
                 the pose range, {} across a pose gap over {} s, {} out of order",
                path.display(),
                scan.clouds.len(),
                points_topic.name,
                skipped.outside_pose_range,
                skipped.pose_gap,
                options.max_pose_gap_s,
                skipped.out_of_order
            );
        }
        let point_time = scan.point_time.filter(|_| !clouds_in_world);
        if let Some(convention) = &point_time {
            tracing::info!("point times: {}", convention.describe());
        }
        Ok(Recording {
            point_time,
            point_time_choice: options.point_time.clone(),
            pose_count: scan.poses.len(),
            max_pose_gap_s: options.max_pose_gap_s,
            body_frame: scan.body_frame,
            bag,
            points_topic,
            points_kind,
            poses_topic,
            world_frame,
            cloud_frame,
            clouds_in_world,
            extrinsic,
            extrinsic_source,
            frames,
            skipped,
        })
    }

    /// The underlying recording.
    pub fn bag(&self) -> &Bag {
        &self.bag
    }

    /// The recording's path.
    pub fn path(&self) -> &Path {
        self.bag.path()
    }

    /// Points of the largest planned frame (before non-finite points are dropped).
    pub fn max_points(&self) -> usize {
        self.frames.iter().map(|f| f.points).max().unwrap_or(0)
    }

    /// Streams the planned frames, decoding one cloud at a time.
    pub fn frames(&self) -> Result<FrameStream, BagError> {
        Ok(FrameStream {
            path: self.path().to_path_buf(),
            topic: self.points_topic.clone(),
            kind: self.points_kind,
            clouds_in_world: self.clouds_in_world,
            point_time: self.point_time.clone(),
            point_time_choice: if self.point_time.is_some() {
                self.point_time_choice.clone()
            } else {
                PointTimeChoice::Ignore
            },
            planned: self.frames.clone(),
            messages: self
                .bag
                .messages(std::slice::from_ref(&self.points_topic.name))?,
            next: 0,
        })
    }
}

/// One pass over the pose, tf and cloud topics.
fn scan(
    bag: &Bag,
    (points_topic, points_kind): (&TopicInfo, Kind),
    (poses_topic, poses_kind): (&TopicInfo, Kind),
    point_time: &PointTimeChoice,
) -> Result<Scan, BagError> {
    let mut wanted = vec![points_topic.name.clone(), poses_topic.name.clone()];
    let tf_topics: Vec<&TopicInfo> = TF_TOPICS
        .iter()
        .filter_map(|t| bag.topic(t))
        .filter(|t| Kind::of(&t.type_name) == Some(Kind::Tf))
        .collect();
    wanted.extend(tf_topics.iter().map(|t| t.name.clone()));
    let mut scan = Scan {
        poses: Vec::new(),
        world_frame: None,
        body_frame: None,
        tf: TfTree::default(),
        clouds: Vec::new(),
        cloud_frame: None,
        point_time: None,
    };
    let total = points_topic.count + poses_topic.count;
    let mut seen = 0u64;
    let mut last_log = std::time::Instant::now();
    for message in bag.messages(&wanted)? {
        let message = message?;
        let (topic, index, data) = (
            &*message.message.topic,
            message.index,
            &message.message.data,
        );
        if topic == points_topic.name {
            let (header, points) = msg::peek_cloud(points_kind, data, points_topic.wire)
                .map_err(|e| message_error(bag.path(), points_topic, index, e))?;
            if scan.cloud_frame.is_none() {
                scan.cloud_frame = Some(header.frame_id.clone());
                scan.point_time =
                    first_point_times(data, points_kind, points_topic.wire, point_time)
                        .map_err(|e| message_error(bag.path(), points_topic, index, e))?;
            } else if scan.cloud_frame.as_deref() != Some(header.frame_id.as_str()) {
                return Err(message_error(
                    bag.path(),
                    points_topic,
                    index,
                    msg::DecodeError(format!(
                        "frame_id '{}' differs from the first cloud's '{}'",
                        header.frame_id,
                        scan.cloud_frame.as_deref().unwrap_or_default()
                    )),
                ));
            }
            scan.clouds.push((index, header.stamp_ns, points));
        } else if topic == poses_topic.name {
            let pose = msg::decode_pose(poses_kind, data, poses_topic.wire)
                .map_err(|e| message_error(bag.path(), poses_topic, index, e))?;
            scan.world_frame.get_or_insert(pose.header.frame_id.clone());
            if let Some(child) = &pose.child_frame_id {
                scan.body_frame.get_or_insert(child.clone());
            }
            scan.poses
                .push((pose.header.stamp_ns, pose.parent_from_child));
        } else if let Some(tf_topic) = tf_topics.iter().find(|t| t.name == topic) {
            let transforms = msg::decode_tf(data, tf_topic.wire)
                .map_err(|e| message_error(bag.path(), tf_topic, index, e))?;
            for t in transforms {
                if let Some(child) = t.child_frame_id {
                    scan.tf
                        .0
                        .entry(child)
                        .or_insert((t.header.frame_id, t.parent_from_child));
                }
            }
            continue;
        }
        seen += 1;
        // Progress on long reads only: every 2 s.
        if last_log.elapsed().as_secs_f64() > 2.0 {
            last_log = std::time::Instant::now();
            tracing::info!("{}: indexed {seen}/{total} messages", bag.path().display());
        }
    }
    Ok(scan)
}

/// The convention of the first cloud's point times, if it has any.
fn first_point_times(
    data: &[u8],
    kind: Kind,
    wire: msg::Wire,
    choice: &PointTimeChoice,
) -> Result<Option<PointTimeConvention>, msg::DecodeError> {
    let cloud = msg::decode_cloud(kind, data, wire, choice)?;
    let unit = match choice {
        PointTimeChoice::Field { unit, .. } => *unit,
        _ => None,
    };
    cloud
        .times
        .map(|raw| PointTimeConvention::detect(&raw, cloud.header.stamp_ns, unit))
        .transpose()
}

fn extrinsic(
    options: &RecordingOptions,
    scan: &Scan,
    cloud_frame: &str,
    clouds_in_world: bool,
) -> (Isometry3<f64>, ExtrinsicSource) {
    if let Some(given) = options.extrinsic {
        return (given, ExtrinsicSource::Given);
    }
    match &scan.body_frame {
        Some(body) if body == cloud_frame => (Isometry3::identity(), ExtrinsicSource::SameFrame),
        Some(body) if !clouds_in_world => match scan.tf.between(body, cloud_frame) {
            Some(t) => (
                t,
                ExtrinsicSource::Tf {
                    body: body.clone(),
                    lidar: cloud_frame.to_string(),
                },
            ),
            None => (Isometry3::identity(), ExtrinsicSource::AssumedIdentity),
        },
        // A pose without a child frame: a transform whose child is the cloud frame, from
        // whatever parent, is taken as body_from_lidar.
        None if !clouds_in_world => match scan.tf.0.get(cloud_frame) {
            Some((parent, t)) => (
                *t,
                ExtrinsicSource::Tf {
                    body: parent.clone(),
                    lidar: cloud_frame.to_string(),
                },
            ),
            None => (Isometry3::identity(), ExtrinsicSource::AssumedIdentity),
        },
        // World-frame clouds: the sensor frame is the body's, moved by the tf extrinsic if any.
        _ => {
            let lidar = scan
                .tf
                .0
                .iter()
                .find(|(_, (parent, _))| Some(parent) == scan.body_frame.as_ref());
            match lidar {
                Some((child, (parent, t))) => (
                    *t,
                    ExtrinsicSource::Tf {
                        body: parent.clone(),
                        lidar: child.clone(),
                    },
                ),
                None => (Isometry3::identity(), ExtrinsicSource::AssumedIdentity),
            }
        }
    }
}

/// Applies the selection and the pose lookup to every cloud.
fn plan_frames(
    clouds: &[(u64, i64, usize)],
    trajectory: &Trajectory,
    body_from_lidar: &Isometry3<f64>,
    options: &RecordingOptions,
    bag_start_ns: i64,
) -> (Vec<PlannedFrame>, Skipped) {
    let seconds = |s: f64| (s * 1e9).round() as i64;
    let from = bag_start_ns + options.start_s.map_or(0, seconds);
    let until = options.duration_s.map(|d| from + seconds(d));
    let max_gap_ns = seconds(options.max_pose_gap_s);
    let mut skipped = Skipped::default();
    let mut frames: Vec<PlannedFrame> = Vec::new();
    for &(index, stamp_ns, points) in clouds {
        let in_frames = options
            .frames
            .as_ref()
            .is_none_or(|r| r.contains(&(index as usize)));
        let in_time = stamp_ns >= from && until.is_none_or(|u| stamp_ns < u);
        if !in_frames || (options.start_s.is_some() || options.duration_s.is_some()) && !in_time {
            skipped.not_selected += 1;
            continue;
        }
        if frames.last().is_some_and(|f| f.stamp_ns >= stamp_ns) {
            skipped.out_of_order += 1;
            continue;
        }
        match trajectory.at(stamp_ns, max_gap_ns) {
            Ok(world_from_body) => frames.push(PlannedFrame {
                message_index: index,
                stamp_ns,
                world_from_lidar: world_from_body * body_from_lidar,
                points,
            }),
            Err(NoPose::OutsideRange) => skipped.outside_pose_range += 1,
            Err(NoPose::Gap) => skipped.pose_gap += 1,
        }
    }
    (frames, skipped)
}

/// One frame read from a recording.
#[derive(Debug, Clone, PartialEq)]
pub struct BagFrame {
    /// Index of its message on the cloud topic.
    pub message_index: u64,
    /// Header stamp (ns).
    pub stamp_ns: i64,
    /// Finite points in the sensor frame (m).
    pub points: Vec<Point3<f64>>,
    /// Initial pose.
    pub world_from_lidar: Isometry3<f64>,
    /// Points dropped as non-finite.
    pub non_finite: usize,
    /// Each point's time after the stamp (s), when the recording has point times.
    pub point_times_s: Option<Vec<f32>>,
}

impl BagFrame {
    /// The stamp in seconds.
    pub fn stamp_s(&self) -> f64 {
        stamp_s(self.stamp_ns)
    }
}

/// Nanoseconds to seconds.
pub fn stamp_s(stamp_ns: i64) -> f64 {
    stamp_ns.div_euclid(1_000_000_000) as f64 + stamp_ns.rem_euclid(1_000_000_000) as f64 * 1e-9
}

/// The planned frames, decoded one at a time.
pub struct FrameStream {
    path: PathBuf,
    topic: TopicInfo,
    kind: Kind,
    clouds_in_world: bool,
    point_time: Option<PointTimeConvention>,
    point_time_choice: PointTimeChoice,
    planned: Vec<PlannedFrame>,
    messages: Messages,
    next: usize,
}

impl std::fmt::Debug for FrameStream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FrameStream")
            .field("next", &self.next)
            .finish_non_exhaustive()
    }
}

impl FrameStream {
    /// A cloud's point times after its stamp, when the recording has them; a cloud without
    /// the first cloud's time field is an error.
    fn point_times(&self, cloud: &msg::Cloud) -> Result<Option<Vec<f32>>, msg::DecodeError> {
        let Some(convention) = &self.point_time else {
            return Ok(None);
        };
        let Some(raw) = &cloud.times else {
            return Err(msg::cursor::decode_err(format!(
                "no point time field {}, which the first cloud had",
                convention.field
            )));
        };
        convention.offsets_s(raw, cloud.header.stamp_ns).map(Some)
    }

    /// Frames in the stream.
    pub fn len(&self) -> usize {
        self.planned.len()
    }

    /// True without frames.
    pub fn is_empty(&self) -> bool {
        self.planned.is_empty()
    }
}

impl Iterator for FrameStream {
    type Item = Result<BagFrame, BagError>;

    fn next(&mut self) -> Option<Self::Item> {
        let planned = self.planned.get(self.next)?.clone();
        for message in self.messages.by_ref() {
            let message = match message {
                Ok(m) => m,
                Err(e) => return Some(Err(e)),
            };
            if message.index != planned.message_index {
                continue;
            }
            self.next += 1;
            let topic = &self.topic;
            let data = &message.message.data;
            let decoded = msg::decode_cloud(self.kind, data, topic.wire, &self.point_time_choice)
                .and_then(|cloud| {
                    let times = self.point_times(&cloud)?;
                    Ok((cloud, times))
                });
            let (cloud, point_times_s) = match decoded {
                Ok(c) => c,
                Err(e) => return Some(Err(message_error(&self.path, topic, message.index, e))),
            };
            let mut points = cloud.points;
            if self.clouds_in_world {
                let lidar_from_world = planned.world_from_lidar.inverse();
                for p in &mut points {
                    *p = lidar_from_world * *p;
                }
            }
            return Some(Ok(BagFrame {
                message_index: planned.message_index,
                stamp_ns: planned.stamp_ns,
                points,
                world_from_lidar: planned.world_from_lidar,
                non_finite: cloud.non_finite,
                point_times_s,
            }));
        }
        self.next = self.planned.len();
        Some(Err(BagError::recording(
            &self.path,
            format!(
                "{} ended before message {} (read while planning): the recording changed?",
                self.topic.name, planned.message_index
            ),
        )))
    }
}
