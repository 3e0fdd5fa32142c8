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

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use pssba_msg::ServiceError;
use pssba_msg::node::{event_service, woken};
use pssba_msg::public::services::{chunk_service, names, summary_service};
use pssba_msg::public::types::PointXyz;

pub use pssba_msg::public::services::names::SURFACES;
pub use pssba_msg::public::services::{
    CHUNK_QUEUE, MAP_CHUNK_POINTS, SUMMARY_HISTORY, SURFACE_CHUNK, WINDOW_SUBSCRIBERS,
};
pub use pssba_msg::public::types::{ChunkHeader, SurfaceMsg, WindowSummaryMsg, checked};

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
            notifier: event_service(node, names::WINDOWS)?
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
            listener: event_service(node, names::WINDOWS)?
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
        woken(self.listener.timed_wait(|_| {}, timeout))
            .map_err(|e| ServiceError::ipc("waiting for windows", e))
    }
}
