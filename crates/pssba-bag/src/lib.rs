//! Robot recordings in: the frames and initial poses of a LiDAR flight, read from what a LIO
//! stack and a LiDAR driver record. Pure Rust, no ROS install.
//!
//! - Containers ([`Bag`]): ROS 1 bag v2.0 (uncompressed, bz2 and lz4 chunks), rosbag2 folders
//!   (`metadata.yaml` with MCAP or sqlite3 `.db3` storage), bare `.mcap` and `.db3` files.
//!   Read by streaming: one chunk (ROS 1, MCAP) or one page of rows (sqlite3) in memory.
//! - Messages ([`msg`]): `sensor_msgs/PointCloud2`, `livox_ros_driver/CustomMsg` and
//!   `livox_ros_driver2/CustomMsg`, `nav_msgs/Odometry`, `geometry_msgs/PoseStamped` and
//!   `PoseWithCovarianceStamped`, `tf2_msgs/TFMessage`, in ROS 1 or CDR serialization.
//! - Frames ([`Recording`]): each cloud message a frame at its header stamp, its initial pose
//!   from the pose topic (exact or interpolated), the lidar extrinsic from `/tf_static`.
//!
//! Every error is a [`BagError`] naming the file and, for a message, its topic and index.

pub mod bag;
mod error;
mod mcap_file;
pub mod mcap_stream;
pub mod msg;
pub mod recording;
mod ros1;
mod sqlite;
pub mod trajectory;

pub use bag::{Bag, Container, IndexedMessage, RawMessage, TopicInfo};
pub use error::BagError;
pub use mcap_file::message_reader as mcap_message_reader;
pub use recording::{
    BagFrame, ExtrinsicSource, FrameStream, PlannedFrame, Recording, RecordingOptions, Skipped,
    stamp_s,
};
pub use trajectory::Trajectory;
