//! The public services of an instance (docs/interface.md): their names, subscriber limits,
//! queue lengths and the one builder of each. Outside processes may open every one of them.

use crate::error::ServiceError;
use crate::lossless_service;
use crate::node::service_name;
use crate::public::types::{
    ChunkHeader, FinalPoseMsg, FrameHeader, PointXyz, SurfaceMsg, WindowSummaryMsg,
};
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;

/// Service name suffixes of the public services (the full name is `pssba/<instance>/<suffix>`).
pub mod names {
    /// Frames in.
    pub const FRAMES: &str = "frames";
    /// Frame consumers report ready here (an event service).
    pub const FRAMES_READY: &str = "frames/ready";
    /// Final poses out.
    pub const FINAL_POSES: &str = "final_poses";
    /// Final poses a loop closure moved after they were published, out (same layout).
    pub const REVISED_POSES: &str = "revised_poses";
    /// Window summaries out.
    pub const WINDOWS: &str = "windows";
    /// Map chunks out.
    pub const MAP: &str = "map";
    /// Surfaces out.
    pub const SURFACES: &str = "surfaces";
}

/// Frames a subscriber may hold queued before the publisher waits (backpressure).
pub const FRAME_BUFFER: usize = 8;

/// Consumers of frames: the system's smooth and record stages ([`ready_id::SYSTEM`]).
pub const FRAME_SUBSCRIBERS: usize = 2;

/// Ready ids of the system's frame consumers.
pub mod ready_id {
    /// The smooth stage.
    pub const SMOOTH: usize = 1;
    /// The record stage.
    pub const RECORD: usize = 2;
    /// Every consumer the system starts.
    pub const SYSTEM: [usize; 2] = [SMOOTH, RECORD];
    // The frames service admits exactly the consumers the producer waits for.
    const _: () = assert!(SYSTEM.len() == super::FRAME_SUBSCRIBERS);
}

/// Most outside subscribers of the final poses at once.
pub const FINAL_POSE_SUBSCRIBERS: usize = 8;
/// Final poses a late subscriber receives first (and each subscriber's queue length).
pub const FINAL_POSE_HISTORY: usize = 4096;
/// Most map points in one sample (192 KiB).
pub const MAP_CHUNK_POINTS: usize = 16_384;
/// Most surfaces in one sample (160 KiB).
pub const SURFACE_CHUNK: usize = 1024;
/// Most outside subscribers of each window service at once.
pub const WINDOW_SUBSCRIBERS: usize = 4;
/// Window summaries a late subscriber receives first (and each subscriber's queue).
pub const SUMMARY_HISTORY: usize = 64;
/// Map or surface samples each subscriber may hold unread before the oldest is overwritten
/// (also what a late subscriber receives first).
pub const CHUNK_QUEUE: usize = 32;

/// The frames service.
pub type FramesService = PortFactory<ipc::Service, [PointXyz], FrameHeader>;
/// The final poses' service.
pub type FinalPosesService = PortFactory<ipc::Service, FinalPoseMsg, ()>;
/// The window summaries' service.
pub type SummaryService = PortFactory<ipc::Service, WindowSummaryMsg, ()>;
/// A chunk service (map points or surfaces).
pub type ChunkService<T> = PortFactory<ipc::Service, [T], ChunkHeader>;
/// The map chunks' service.
pub type MapService = ChunkService<PointXyz>;
/// The surfaces' service.
pub type SurfacesService = ChunkService<SurfaceMsg>;

/// Opens or creates the frames service.
pub fn frames_service(node: &Node<ipc::Service>) -> Result<FramesService, ServiceError> {
    lossless_service!(
        node,
        names::FRAMES,
        [PointXyz],
        FrameHeader,
        FRAME_SUBSCRIBERS,
        FRAME_BUFFER
    )
}

/// Opens or creates `pssba/<instance>/final_poses` with the settings of docs/interface.md.
pub fn final_poses_service(node: &Node<ipc::Service>) -> Result<FinalPosesService, ServiceError> {
    pose_service(node, names::FINAL_POSES)
}

/// Opens or creates `pssba/<instance>/revised_poses`: the settings and layout of
/// `final_poses`.
pub fn revised_poses_service(node: &Node<ipc::Service>) -> Result<FinalPosesService, ServiceError> {
    pose_service(node, names::REVISED_POSES)
}

/// A service of [`FinalPoseMsg`] named `suffix`.
fn pose_service(
    node: &Node<ipc::Service>,
    suffix: &str,
) -> Result<FinalPosesService, ServiceError> {
    let name = service_name(node, suffix)?;
    node.service_builder(&name)
        .publish_subscribe::<FinalPoseMsg>()
        .max_publishers(1)
        .max_subscribers(FINAL_POSE_SUBSCRIBERS)
        .history_size(FINAL_POSE_HISTORY)
        .subscriber_max_buffer_size(FINAL_POSE_HISTORY)
        .subscriber_max_borrowed_samples(8)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| ServiceError::ipc(name.as_str(), e))
}

/// Opens or creates `pssba/<instance>/windows`.
pub fn summary_service(node: &Node<ipc::Service>) -> Result<SummaryService, ServiceError> {
    let name = service_name(node, names::WINDOWS)?;
    node.service_builder(&name)
        .publish_subscribe::<WindowSummaryMsg>()
        .max_publishers(1)
        .max_subscribers(WINDOW_SUBSCRIBERS)
        .history_size(SUMMARY_HISTORY)
        .subscriber_max_buffer_size(SUMMARY_HISTORY)
        .subscriber_max_borrowed_samples(4)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| ServiceError::ipc(name.as_str(), e))
}

/// Opens or creates a chunk service (`map` or `surfaces`).
pub fn chunk_service<T>(
    node: &Node<ipc::Service>,
    suffix: &str,
) -> Result<ChunkService<T>, ServiceError>
where
    T: std::fmt::Debug + ZeroCopySend + 'static,
{
    let name = service_name(node, suffix)?;
    node.service_builder(&name)
        .publish_subscribe::<[T]>()
        .user_header::<ChunkHeader>()
        .max_publishers(1)
        .max_subscribers(WINDOW_SUBSCRIBERS)
        .history_size(CHUNK_QUEUE)
        .subscriber_max_buffer_size(CHUNK_QUEUE)
        .subscriber_max_borrowed_samples(4)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| ServiceError::ipc(name.as_str(), e))
}
