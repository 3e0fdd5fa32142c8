//! Each window's result for outside subscribers (docs/interface.md):
//! - `pssba/<instance>/windows`: one [`WindowSummaryMsg`] per window;
//! - `pssba/<instance>/map`: the window's smoothed map chunk (world frame, f32), in samples of
//!   at most [`MAP_CHUNK_POINTS`] points, each with a [`ChunkHeader`];
//! - `pssba/<instance>/surfaces`: the window's surfaces ([`SurfaceMsg`]), in samples of at most
//!   [`SURFACE_CHUNK`] surfaces.
//!
//! All three overwrite a slow subscriber's oldest samples (safe overflow), so no subscriber ever
//! stalls the pipeline; `part`/`parts` tell a subscriber whether it got a window's map whole.
//! The summary is published last, so a subscriber that sees it has been offered every chunk.
#![allow(unsafe_code)] // `derive(ZeroCopySend)` emits the `unsafe impl` marker; nothing else.

use crate::services::{self, ServiceError, names};
use crate::types::PointXyz;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;

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
/// The surfaces' service (suffix).
pub const SURFACES: &str = "surfaces";

/// One finished window (`pssba/<instance>/windows`, fixed-size payload), 80 bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pssba::WindowSummaryMsg")]
pub struct WindowSummaryMsg {
    /// Window index (0, 1, 2, ...).
    pub window: u64,
    /// Sequence number of the first frame this window made final.
    pub first_sequence: u64,
    /// Frames it made final (their poses are on `final_poses`).
    pub final_count: u64,
    /// Points of its smoothed map chunk (on `map`).
    pub map_points: u64,
    /// Its surfaces (on `surfaces`).
    pub surfaces: u64,
    /// Frames the system has dropped so far (overflow policy `drop`).
    pub frames_dropped: u64,
    /// Kernel scale of its last scale (m).
    pub last_gamma_m: f64,
    /// Largest pose change of its last scale (the convergence measure).
    pub last_pose_change: f64,
    /// Scales it ran.
    pub scales_run: u32,
    /// 1 if its schedule converged.
    pub converged: u32,
    /// 1 if its adjustment failed (its frames kept their anchor-corrected initial poses).
    pub failed: u32,
    /// 1 on the end-of-stream marker (`window` = windows published; nothing else set).
    pub end_of_stream: u32,
}

/// Where a map or surface sample sits in its window's chunk (user header), 32 bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("pssba::ChunkHeader")]
pub struct ChunkHeader {
    /// Window index.
    pub window: u64,
    /// Index of this sample's first item within the window's chunk.
    pub first_item: u64,
    /// Items in the window's whole chunk.
    pub total_items: u64,
    /// This sample's number, 0-based.
    pub part: u32,
    /// Samples of the window's chunk.
    pub parts: u32,
}

/// One surface of a window, in the world frame (`pssba/<instance>/surfaces`), 160 bytes: the
/// paper's local polynomial z = f(x, y) in its kernel's tangent frame.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pssba::SurfaceMsg")]
pub struct SurfaceMsg {
    /// Sequence number of the frame whose point is the kernel.
    pub frame_sequence: u64,
    /// The kernel point in the world (m).
    pub kernel_in_world_m: [f64; 3],
    /// Rotation tangent-from-world, row-major (the tangent frame's z is the surface normal).
    pub tangent_from_world: [f64; 9],
    /// Coefficients of f(x, y) = c0 + c1 x + c2 y + c3 x^2 + c4 x y + c5 y^2 (x, y, f in m,
    /// relative to the kernel point).
    pub coefficients: [f64; 6],
    /// Kernel radius gamma (m) of the scale.
    pub gamma_m: f64,
}

type SummaryService = PortFactory<ipc::Service, WindowSummaryMsg, ()>;
type ChunkService<T> = PortFactory<ipc::Service, [T], ChunkHeader>;

fn summary_service(node: &Node<ipc::Service>) -> Result<SummaryService, ServiceError> {
    let name = services::service_name(node, names::WINDOWS)?;
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

fn chunk_service<T>(
    node: &Node<ipc::Service>,
    suffix: &str,
) -> Result<ChunkService<T>, ServiceError>
where
    T: std::fmt::Debug + ZeroCopySend + 'static,
{
    let name = services::service_name(node, suffix)?;
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

/// Publishes each window's summary, map chunk and surfaces (the smooth stage).
#[derive(Debug)]
pub struct WindowPublisher {
    summaries: Publisher<ipc::Service, WindowSummaryMsg, ()>,
    map: Publisher<ipc::Service, [PointXyz], ChunkHeader>,
    surfaces: Publisher<ipc::Service, [SurfaceMsg], ChunkHeader>,
    notifier: Notifier<ipc::Service>,
    windows: u64,
}

fn chunk_publisher<T>(
    node: &Node<ipc::Service>,
    suffix: &str,
    max_len: usize,
) -> Result<Publisher<ipc::Service, [T], ChunkHeader>, ServiceError>
where
    T: std::fmt::Debug + ZeroCopySend + 'static,
{
    chunk_service::<T>(node, suffix)?
        .publisher_builder()
        .initial_max_slice_len(max_len)
        .allocation_strategy(AllocationStrategy::Static)
        .create()
        .map_err(|e| ServiceError::ipc(format!("{suffix} publisher"), e))
}

impl WindowPublisher {
    /// Creates the three services and their publishers.
    pub fn create(node: &Node<ipc::Service>) -> Result<Self, ServiceError> {
        Ok(Self {
            summaries: summary_service(node)?
                .publisher_builder()
                .create()
                .map_err(|e| ServiceError::ipc("window summary publisher", e))?,
            map: chunk_publisher(node, names::MAP, MAP_CHUNK_POINTS)?,
            surfaces: chunk_publisher(node, SURFACES, SURFACE_CHUNK)?,
            notifier: services::event_service(node, names::WINDOWS)?
                .notifier_builder()
                .create()
                .map_err(|e| ServiceError::ipc("window notifier", e))?,
            windows: 0,
        })
    }

    /// Publishes one window: its map chunk and surfaces, then its summary, then notifies
    /// `pssba/<instance>/windows/event`.
    pub fn publish(
        &mut self,
        summary: WindowSummaryMsg,
        map: &[PointXyz],
        surfaces: &[SurfaceMsg],
    ) -> Result<(), ServiceError> {
        send_chunks(&self.map, summary.window, map, MAP_CHUNK_POINTS)?;
        send_chunks(&self.surfaces, summary.window, surfaces, SURFACE_CHUNK)?;
        self.send_summary(WindowSummaryMsg {
            map_points: map.len() as u64,
            surfaces: surfaces.len() as u64,
            ..summary
        })?;
        self.windows += 1;
        Ok(())
    }

    /// Publishes the end-of-stream marker.
    pub fn end_stream(&mut self) -> Result<(), ServiceError> {
        self.send_summary(WindowSummaryMsg {
            window: self.windows,
            end_of_stream: 1,
            ..WindowSummaryMsg::default()
        })
    }

    fn send_summary(&self, summary: WindowSummaryMsg) -> Result<(), ServiceError> {
        self.summaries
            .send_copy(summary)
            .map_err(|e| ServiceError::ipc("sending a window summary", e))?;
        self.notifier
            .notify()
            .map_err(|e| ServiceError::ipc("notifying a window", e))?;
        Ok(())
    }
}

fn send_chunks<T>(
    publisher: &Publisher<ipc::Service, [T], ChunkHeader>,
    window: u64,
    items: &[T],
    chunk: usize,
) -> Result<(), ServiceError>
where
    T: std::fmt::Debug + ZeroCopySend + Copy + 'static,
{
    let parts = items.len().div_ceil(chunk);
    for (part, slice) in items.chunks(chunk).enumerate() {
        let sample = publisher
            .loan_slice_uninit(slice.len())
            .map_err(|e| ServiceError::ipc("loaning a chunk sample", e))?;
        let mut sample = sample.write_from_slice(slice);
        *sample.user_header_mut() = ChunkHeader {
            window,
            first_item: (part * chunk) as u64,
            total_items: items.len() as u64,
            part: part as u32,
            parts: parts as u32,
        };
        sample
            .send()
            .map_err(|e| ServiceError::ipc("sending a chunk", e))?;
    }
    Ok(())
}

/// An outside subscriber of window summaries, map chunks and surfaces.
#[derive(Debug)]
pub struct WindowSubscriber {
    summaries: Subscriber<ipc::Service, WindowSummaryMsg, ()>,
    map: Subscriber<ipc::Service, [PointXyz], ChunkHeader>,
    surfaces: Subscriber<ipc::Service, [SurfaceMsg], ChunkHeader>,
    listener: Listener<ipc::Service>,
}

fn chunk_subscriber<T>(
    node: &Node<ipc::Service>,
    suffix: &str,
) -> Result<Subscriber<ipc::Service, [T], ChunkHeader>, ServiceError>
where
    T: std::fmt::Debug + ZeroCopySend + 'static,
{
    chunk_service::<T>(node, suffix)?
        .subscriber_builder()
        .create()
        .map_err(|e| ServiceError::ipc(format!("{suffix} subscriber"), e))
}

/// What a chunk sample holds, checked: `first_item + len <= total_items`, `part < parts`.
pub fn checked(header: &ChunkHeader, len: usize) -> Result<ChunkHeader, ServiceError> {
    let fits = header
        .first_item
        .checked_add(len as u64)
        .is_some_and(|end| end <= header.total_items)
        && header.part < header.parts;
    if fits {
        Ok(*header)
    } else {
        Err(ServiceError {
            what: format!("window {} chunk", header.window),
            reason: format!(
                "inconsistent header: part {} of {}, items {}+{len} of {}",
                header.part, header.parts, header.first_item, header.total_items
            ),
        })
    }
}

/// Calls `on_chunk` for every sample waiting on `subscriber`, its header checked first.
fn receive_chunks<T>(
    subscriber: &Subscriber<ipc::Service, [T], ChunkHeader>,
    what: &str,
    mut on_chunk: impl FnMut(ChunkHeader, &[T]),
) -> Result<(), ServiceError>
where
    T: std::fmt::Debug + ZeroCopySend + 'static,
{
    while let Some(sample) = subscriber
        .receive()
        .map_err(|e| ServiceError::ipc(what, e))?
    {
        on_chunk(
            checked(sample.user_header(), sample.payload().len())?,
            sample.payload(),
        );
    }
    Ok(())
}

impl WindowSubscriber {
    /// Subscribes on `node` (whose prefix names the instance).
    pub fn create(node: &Node<ipc::Service>) -> Result<Self, ServiceError> {
        Ok(Self {
            summaries: summary_service(node)?
                .subscriber_builder()
                .create()
                .map_err(|e| ServiceError::ipc("window summary subscriber", e))?,
            map: chunk_subscriber(node, names::MAP)?,
            surfaces: chunk_subscriber(node, SURFACES)?,
            listener: services::event_service(node, names::WINDOWS)?
                .listener_builder()
                .create()
                .map_err(|e| ServiceError::ipc("window listener", e))?,
        })
    }

    /// The next window summary waiting (or the end-of-stream marker), if any.
    pub fn receive_summary(&self) -> Result<Option<WindowSummaryMsg>, ServiceError> {
        let sample = self
            .summaries
            .receive()
            .map_err(|e| ServiceError::ipc("receiving a window summary", e))?;
        Ok(sample.map(|s| *s.payload()))
    }

    /// Calls `on_chunk` for every map sample waiting (points in the world frame, m).
    pub fn receive_map(
        &self,
        on_chunk: impl FnMut(ChunkHeader, &[PointXyz]),
    ) -> Result<(), ServiceError> {
        receive_chunks(&self.map, "receiving a map chunk", on_chunk)
    }

    /// Calls `on_chunk` for every surface sample waiting.
    pub fn receive_surfaces(
        &self,
        on_chunk: impl FnMut(ChunkHeader, &[SurfaceMsg]),
    ) -> Result<(), ServiceError> {
        receive_chunks(&self.surfaces, "receiving surfaces", on_chunk)
    }

    /// Blocks until a window is notified or `timeout` passes.
    pub fn wait(&self, timeout: std::time::Duration) -> Result<(), ServiceError> {
        crate::error::woken(self.listener.timed_wait(|_| {}, timeout))
            .map_err(|e| ServiceError::ipc("waiting for windows", e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::mem::{align_of, offset_of, size_of};

    /// The layouts docs/interface.md promises to other languages.
    #[test]
    fn layouts_match_the_contract() {
        assert_eq!(size_of::<WindowSummaryMsg>(), 80);
        assert_eq!(offset_of!(WindowSummaryMsg, last_gamma_m), 48);
        assert_eq!(offset_of!(WindowSummaryMsg, scales_run), 64);
        assert_eq!(offset_of!(WindowSummaryMsg, end_of_stream), 76);
        assert_eq!(size_of::<ChunkHeader>(), 32);
        assert_eq!(offset_of!(ChunkHeader, parts), 28);
        assert_eq!(size_of::<SurfaceMsg>(), 160);
        assert_eq!(offset_of!(SurfaceMsg, tangent_from_world), 32);
        assert_eq!(offset_of!(SurfaceMsg, coefficients), 104);
        assert_eq!(offset_of!(SurfaceMsg, gamma_m), 152);
        assert_eq!(align_of::<SurfaceMsg>(), 8);
    }

    #[test]
    fn inconsistent_chunk_headers_are_refused() {
        let good = ChunkHeader {
            window: 1,
            first_item: 10,
            total_items: 20,
            part: 1,
            parts: 2,
        };
        assert!(checked(&good, 10).is_ok());
        assert!(checked(&good, 11).is_err());
        assert!(checked(&ChunkHeader { part: 2, ..good }, 5).is_err());
        let overflow = ChunkHeader {
            first_item: u64::MAX,
            ..good
        };
        assert!(checked(&overflow, 1).is_err());
    }
}
