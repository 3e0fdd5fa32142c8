//! The wire protocol of PSS-BA (docs/interface.md for the public part, DESIGN.md section 6):
//! every `#[repr(C)]` type that lives in iceoryx2 shared memory, every service's name, limits
//! and builder, and the codecs and validation of everything read. Nothing read from shared
//! memory is trusted: any process of the same user can open a service.
//!
//! - [`public`]: what outside processes send and read (frames in; final poses, window
//!   summaries, map chunks, surfaces out). `pssba-client` is the port layer over it.
//! - [`internal`]: the services between the system's own stages (factor blocks, pose sets,
//!   window results, rewinds, the recorder's confirmations) and which stage subscribes to
//!   which.
//! - [`node`]: nodes, instance prefixes, service names and the settings shared by every port.
//! - [`codec`]: the word layouts of factor blocks and window results, and messages of any size
//!   over fixed-size samples. The conversions to and from pssba-core's types (block and result
//!   codecs, `PoseMsg::to_pose`) need the `core` feature; without it this crate has no
//!   algorithm dependency.
//!
//! Poses: public messages carry [`IsometryMsg`] (quaternion and translation, the exact bits of
//! the producer's `Isometry3`); internal ones carry [`PoseMsg`] (rotation matrix and
//! translation, the exact bits of the core's `Pose`). Each encoding keeps its side's bits: the
//! system equals the in-process run to 1e-9 only because no pose is converted in transit.

pub mod codec;
pub mod error;
pub mod instance;
pub mod internal;
pub mod node;
pub mod public;

pub use codec::parts::{HasParts, Reassembly};
pub use error::{MsgError, ServiceError};
pub use internal::services::Stage;
pub use internal::types::{
    BlockHeader, Parts, PoseMsg, PoseSetHeader, RecordedAck, ResultHeader, block_kind, result_kind,
};
pub use public::frame::{FrameError, ReceivedFrame, check_frame};
pub use public::types::{
    ChunkHeader, FRAME_LAYOUT_VERSION, FinalPose, FinalPoseMsg, FrameHeader, IsometryMsg, PointXyz,
    SurfaceMsg, WindowSummaryMsg,
};

#[cfg(feature = "core")]
pub use codec::block::{
    BlockMessage, block_header, block_len, block_words, decode_block, encode_block,
};
#[cfg(feature = "core")]
pub use codec::result::{WindowResult, decode_result, encode_result};
