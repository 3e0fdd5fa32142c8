//! The public interface of a live PSS-BA instance (`pssba run --input live --instance NAME`),
//! specified in docs/interface.md: everything a drone's own process needs to feed frames in and
//! read results out, over iceoryx2 shared memory, with no dependency on the algorithm. A thin
//! layer of ports over the wire protocol in `pssba-msg` (its public part, re-exported here).
//!
//! - [`FrameProducer`]: publish frames (stamp, initial world_from_lidar, lidar-frame points).
//! - [`outputs::FinalPoseSubscriber`]: each frame's final pose as it becomes final.
//! - [`windows::WindowSubscriber`]: each window's summary, smoothed map chunk and surfaces.
//!
//! Examples: `examples/replay_folder.rs` (a producer replaying a dataset folder at sensor
//! rate) and `examples/write_tum.rs` (a consumer writing final poses as TUM).

pub mod frames;
pub mod outputs;
pub mod windows;

/// Instance names and their iceoryx2 prefixes.
pub use pssba_msg::instance;
/// The `#[repr(C)]` types of the public services.
pub use pssba_msg::public::types;

/// Nodes and the public services: [`services::create_node`] under an instance's prefix, the
/// service names, limits and builders.
pub mod services {
    pub use pssba_msg::node::*;
    pub use pssba_msg::public::services::*;
}

pub use frames::{FrameConsumer, FrameError, FrameProducer, ReceivedFrame};
pub use outputs::{FinalPose, FinalPoseMsg};
pub use pssba_msg::{
    FRAME_LAYOUT_VERSION, FrameHeader, IsometryMsg, MsgError, PointXyz, ServiceError,
};
