//! Messages and services of the PSS-BA process system (DESIGN.md section 6).
//!
//! Each service carries a `#[repr(C)]` user header and a slice payload (`[PointXyz]` frames,
//! `[f64]` factor blocks and window results with documented word layouts, `[PoseMsg]` pose
//! sets). [`services`] builds every service from one function; [`block`] and [`result`]
//! encode and validate the word payloads. Nothing read from shared memory is trusted: any
//! process of the same user can open a service.

pub mod block;
pub mod error;
pub mod parts;
pub mod result;
pub mod services;
pub mod types;
pub mod words;

pub use pssba_client::{frames, outputs};

pub use block::{BlockMessage, block_header, block_len, block_words, decode_block, encode_block};
pub use error::MsgError;
pub use frames::{FrameConsumer, FrameError, FrameProducer, ReceivedFrame};
pub use parts::{HasParts, Reassembly};
pub use result::{FinalPose, WindowResult, decode_result, encode_result};
pub use services::ServiceError;
pub use types::{
    BlockHeader, FRAME_LAYOUT_VERSION, FrameHeader, IsometryMsg, Parts, PointXyz, PoseMsg,
    PoseSetHeader, RecordedAck, ResultHeader,
};
