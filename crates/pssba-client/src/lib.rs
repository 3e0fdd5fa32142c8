//! The public interface of a live PSS-BA instance (`pssba run --input live --instance NAME`),
//! specified in docs/interface.md: everything a drone's own process needs to feed frames in and
//! read results out, over iceoryx2 shared memory, with no dependency on the algorithm.
//!
//! - [`FrameProducer`]: publish frames (stamp, initial world_from_lidar, lidar-frame points).
//! - [`outputs::FinalPoseSubscriber`]: each frame's final pose as it becomes final.
//! - [`windows::WindowSubscriber`]: each window's summary, smoothed map chunk and surfaces.
//!
//! Examples: `examples/replay_folder.rs` (a producer replaying a dataset folder at sensor
//! rate) and `examples/write_tum.rs` (a consumer writing final poses as TUM).

pub mod error;
pub mod frames;
pub mod instance;
pub mod outputs;
pub mod services;
pub mod types;
pub mod windows;

pub use error::MsgError;
pub use frames::{FrameConsumer, FrameError, FrameProducer, ReceivedFrame};
pub use outputs::{FinalPose, FinalPoseMsg};
pub use services::ServiceError;
pub use types::{FRAME_LAYOUT_VERSION, FrameHeader, IsometryMsg, PointXyz};
