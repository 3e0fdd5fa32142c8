//! The frames protocol, for any producer and consumer of the frames service (the ingest stage,
//! the smooth and record stages, and a user's own process):
//!
//! - **Start-up handshake.** A subscriber attaches to the producer's queue only when it first
//!   looks for samples; until then iceoryx2 drops what does not fit the queue. So a consumer
//!   waits for the producer, attaches, then reports ready with its id on the
//!   [`FRAMES_READY`] event service; the producer ([`FrameProducer::wait_for_consumers`]) sends
//!   nothing before every expected consumer has reported (its listener exists before its
//!   publisher, so no report is missed).
//! - **Sequence.** Frames carry 0, 1, 2, ... in order; the end-of-stream marker is a header
//!   with `end_stream = 1`, no points, and `sequence` = the number of frames sent. A consumer
//!   refuses a gap, a repeat, anything after the marker, a non-finite stamp and a pose that is
//!   not a rotation ([`FrameConsumer::receive`]).
//! - **Every send is notified** on the frames event service, so consumers block on a listener
//!   instead of polling.
//! - **A resumed producer** (the system's ingest stage restarted after a crash,
//!   [`FrameProducer::start_at`]) continues the sequence where its predecessor's last completed
//!   send ended; the frame whose send the crash cut may come again, and a consumer that
//!   follows it ([`FrameConsumer::follow_resumed_producer`]) skips sequence numbers it already
//!   has. Frames already in a consumer's queue outlive their producer (iceoryx2 keeps a gone
//!   publisher's connection while it holds data), so nothing sent is lost.

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::PortFactory;
use nalgebra::Isometry3;
use pssba_msg::ServiceError;
use pssba_msg::node::{EventService, event_service, woken};
use pssba_msg::public::frame::{check_point_times, packed_time_slot};
use pssba_msg::public::services::{FramesService, frames_service, names};
use pssba_msg::public::types::{
    FRAME_LAYOUT_VERSION, FRAME_LAYOUT_VERSION_STILL, FrameHeader, IsometryMsg, PointXyz,
    timed_payload_len,
};
use std::cell::Cell;
use std::collections::BTreeSet;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

pub use pssba_msg::public::frame::{FrameError, ReceivedFrame, check_frame};
pub use pssba_msg::public::services::names::FRAMES_READY;
pub use pssba_msg::public::services::ready_id;

fn transport(what: &str) -> impl FnOnce(String) -> FrameError + '_ {
    move |reason| FrameError::Transport(format!("{what}: {reason}"))
}

fn event(node: &Node<ipc::Service>, name: &str) -> Result<EventService, ServiceError> {
    event_service(node, name)
}

fn now_unix_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// The producer side: sizes the frames service, waits for consumers, sends frames in order
/// and the end-of-stream marker.
#[derive(Debug)]
pub struct FrameProducer {
    ready: Listener<ipc::Service>,
    service: FramesService,
    publisher: Publisher<ipc::Service, [PointXyz], FrameHeader>,
    notifier: Notifier<ipc::Service>,
    capacity: usize,
    next_sequence: u64,
}

impl FrameProducer {
    /// Opens the frames service on `node` with samples of up to `capacity` points (with
    /// their times: a third more room) and iceoryx2 backpressure that gives up after
    /// `backpressure_timeout`.
    pub fn create(
        node: &Node<ipc::Service>,
        capacity: usize,
        backpressure_timeout: Duration,
    ) -> Result<Self, FrameError> {
        // Before the publisher exists, so no consumer's ready report is missed.
        let ready = event(node, FRAMES_READY)?
            .listener_builder()
            .create()
            .map_err(|e| transport("ready listener")(format!("{e:?}")))?;
        let service = frames_service(node)?;
        let capacity = capacity.max(1);
        let publisher = pssba_msg::node::publisher(
            &service,
            timed_payload_len(capacity),
            backpressure_timeout,
        )?;
        let notifier = event(node, names::FRAMES)?
            .notifier_builder()
            .create()
            .map_err(|e| transport("frames notifier")(format!("{e:?}")))?;
        Ok(Self {
            ready,
            service,
            publisher,
            notifier,
            capacity,
            next_sequence: 0,
        })
    }

    /// Largest frame (points) a sample holds.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Frames sent so far.
    pub fn sent(&self) -> u64 {
        self.next_sequence
    }

    /// Resumes a stream after a crashed producer of the same stream: the first frame sent is
    /// `sequence` (the frames its predecessor had sent). Consumers must follow it with
    /// [`FrameConsumer::follow_resumed_producer`]; a new live producer starts at 0 instead.
    pub fn start_at(&mut self, sequence: u64) {
        self.next_sequence = sequence;
    }

    /// Waits until every consumer in `ids` has reported ready (or `timeout`, or a signal).
    pub fn wait_for_consumers(
        &self,
        node: &Node<ipc::Service>,
        ids: &[usize],
        timeout: Duration,
    ) -> Result<(), FrameError> {
        let started = Instant::now();
        let mut seen = BTreeSet::new();
        while !ids.iter().all(|id| seen.contains(id)) {
            if started.elapsed() > timeout {
                return Err(FrameError::Transport(format!(
                    "frame consumers not ready after {:.0} s (ready: {seen:?} of {ids:?})",
                    timeout.as_secs_f64()
                )));
            }
            if node.wait(Duration::ZERO).is_err() {
                return Err(FrameError::Transport(
                    "interrupted while waiting for the frame consumers".into(),
                ));
            }
            woken(self.ready.timed_wait(
                |event| {
                    seen.insert(event.id.as_value());
                },
                Duration::from_millis(100),
            ))
            .map_err(|e| transport("waiting for consumers")(format!("{e:?}")))?;
        }
        Ok(())
    }

    /// Sends the next frame: `points(i)` gives point `i` of `len` (lidar frame, m), written
    /// straight into the loaned sample; `times_s`, when given, each point's time after
    /// `stamp_s` (s; `len` of them, finite, within 1 s). Returns its sequence number.
    pub fn send(
        &mut self,
        stamp_s: f64,
        world_from_lidar: &Isometry3<f64>,
        ground_truth: Option<&Isometry3<f64>>,
        len: usize,
        mut points: impl FnMut(usize) -> PointXyz,
        times_s: Option<&[f32]>,
    ) -> Result<u64, FrameError> {
        let sequence = self.next_sequence;
        if let Some(times_s) = times_s {
            if times_s.len() != len {
                return Err(FrameError::Sequence(format!(
                    "frame {sequence} has {len} points and {} point times",
                    times_s.len()
                )));
            }
            check_point_times(sequence, times_s)?;
        }
        let timed_points = match times_s {
            Some(_) => u32::try_from(len).map_err(|_| {
                FrameError::Sequence(format!("frame {sequence}: {len} points with times"))
            })?,
            None => 0,
        };
        if len > self.capacity {
            return Err(FrameError::Sequence(format!(
                "frame {sequence} has {len} points; the frames service holds at most {}",
                self.capacity
            )));
        }
        if !stamp_s.is_finite() {
            return Err(FrameError::Sequence(format!(
                "frame {sequence}: stamp {stamp_s} is not finite"
            )));
        }
        let header = FrameHeader {
            sequence,
            stamp_s,
            world_from_lidar: IsometryMsg::from_isometry(world_from_lidar),
            ground_truth: ground_truth
                .map(IsometryMsg::from_isometry)
                .unwrap_or_default(),
            has_ground_truth: u32::from(ground_truth.is_some()),
            end_of_stream: 0,
            sent_unix_ns: 0,
            layout_version: FRAME_LAYOUT_VERSION,
            timed_points,
        };
        match times_s {
            Some(times_s) => self.publish(header, timed_payload_len(len), |i| {
                if i < len {
                    points(i)
                } else {
                    packed_time_slot(times_s, i - len)
                }
            })?,
            None => self.publish(header, len, points)?,
        }
        self.next_sequence += 1;
        Ok(sequence)
    }

    /// Sends the end-of-stream marker.
    pub fn end_stream(&mut self) -> Result<(), FrameError> {
        let header = FrameHeader {
            sequence: self.next_sequence,
            end_of_stream: 1,
            ..FrameHeader::default()
        };
        self.publish(header, 0, |_| PointXyz::default())
    }

    fn publish(
        &self,
        header: FrameHeader,
        len: usize,
        points: impl FnMut(usize) -> PointXyz,
    ) -> Result<(), FrameError> {
        let sample = self
            .publisher
            .loan_slice_uninit(len)
            .map_err(|e| transport("loaning a frame sample")(format!("{e:?}")))?;
        let mut sample = sample.write_from_fn(points);
        // Stamped right before the send: the latency measured is the transport's alone.
        *sample.user_header_mut() = FrameHeader {
            sent_unix_ns: now_unix_ns(),
            layout_version: FRAME_LAYOUT_VERSION,
            ..header
        };
        sample
            .send()
            .map_err(|e| transport("sending a frame")(format!("{e:?}")))?;
        self.notifier
            .notify()
            .map_err(|e| transport("notifying a frame")(format!("{e:?}")))?;
        Ok(())
    }

    /// True while a consumer is subscribed to the frames service.
    pub fn has_consumers(&self) -> bool {
        self.service.dynamic_config().number_of_subscribers() > 0
    }

    /// Stays until every consumer has detached (or `timeout`): the samples in flight live in
    /// this process's shared memory. Checks every 10 ms (shutdown only).
    pub fn linger(&self, node: &Node<ipc::Service>, timeout: Duration) {
        let started = Instant::now();
        while self.service.dynamic_config().number_of_subscribers() > 0 {
            if started.elapsed() > timeout || node.wait(Duration::from_millis(10)).is_err() {
                return;
            }
        }
    }
}

/// The consumer side: attaches and reports ready, then receives validated frames in order.
#[derive(Debug)]
pub struct FrameConsumer {
    service: FramesService,
    subscriber: Subscriber<ipc::Service, [PointXyz], FrameHeader>,
    listener: Listener<ipc::Service>,
    ready: Notifier<ipc::Service>,
    id: usize,
    /// Cells, so a WaitSet can hold [`Self::listener`] while frames are received.
    /// Frames received from every producer so far.
    next_sequence: Cell<u64>,
    /// Frames received from earlier producers: the current producer's sequence 0 is this
    /// stream number ([`Self::rejoin`]).
    offset: Cell<u64>,
    ended: Cell<bool>,
    /// The publisher this consumer attached to last.
    producer: Cell<Option<u128>>,
    /// Following a resumed producer: repeated sequence numbers are skipped.
    resumed: Cell<bool>,
    /// Frames skipped as repeats of frames already received.
    repeats: Cell<u64>,
    /// Restarted at a sequence number ([`Self::resync_at`]): everything before that number
    /// arrives is skipped.
    syncing: Cell<bool>,
}

impl FrameConsumer {
    /// Subscribes, waits for the producer (at most `timeout`), attaches to its queue and
    /// reports ready as `id`.
    pub fn connect(
        node: &Node<ipc::Service>,
        id: usize,
        timeout: Duration,
    ) -> Result<Self, FrameError> {
        let service = frames_service(node)?;
        let subscriber = service
            .subscriber_builder()
            .create()
            .map_err(|e| transport("frames subscriber")(format!("{e:?}")))?;
        let listener = event(node, names::FRAMES)?
            .listener_builder()
            .create()
            .map_err(|e| transport("frames listener")(format!("{e:?}")))?;
        let ready = event(node, FRAMES_READY)?
            .notifier_builder()
            .create()
            .map_err(|e| transport("ready notifier")(format!("{e:?}")))?;
        let started = Instant::now();
        while service.dynamic_config().number_of_publishers() == 0 {
            if started.elapsed() > timeout {
                return Err(FrameError::Transport(format!(
                    "no frame producer appeared within {:.0} s",
                    timeout.as_secs_f64()
                )));
            }
            if node.wait(Duration::from_millis(10)).is_err() {
                return Err(FrameError::Transport(
                    "interrupted while waiting for the frame producer".into(),
                ));
            }
        }
        let consumer = Self {
            service,
            subscriber,
            listener,
            ready,
            id,
            next_sequence: Cell::new(0),
            offset: Cell::new(0),
            ended: Cell::new(false),
            producer: Cell::new(None),
            resumed: Cell::new(false),
            repeats: Cell::new(0),
            syncing: Cell::new(false),
        };
        consumer.attach()?;
        Ok(consumer)
    }

    /// The id of the connected publisher (the frames service admits one), if any.
    fn publisher_id(&self) -> Option<u128> {
        let mut id = None;
        self.service.dynamic_config().list_publishers(|details| {
            id = Some(details.publisher_id.value());
            CallbackProgression::Stop
        });
        id
    }

    /// Attaches to the producer's queue, then reports ready.
    fn attach(&self) -> Result<(), FrameError> {
        self.producer.set(self.publisher_id());
        self.subscriber
            .has_samples()
            .map_err(|e| transport("attaching to the frame producer")(format!("{e:?}")))?;
        self.ready
            .notify_with_custom_event_id(EventId::new(self.id))
            .map_err(|e| transport("reporting ready")(format!("{e:?}")))?;
        Ok(())
    }

    /// After a producer vanished ([`Self::end_without_marker`]): if a new producer has
    /// appeared, attaches to it, reports ready again and reopens the stream, returning true.
    /// The new producer starts at sequence 0; its frames continue this consumer's numbering
    /// ([`ReceivedFrame::sequence`] = frames received from earlier producers + its sequence).
    pub fn rejoin(&self) -> Result<bool, FrameError> {
        if !self.ended.get() || !self.producer_present() {
            return Ok(false);
        }
        self.attach()?;
        self.offset.set(self.next_sequence.get());
        self.ended.set(false);
        Ok(true)
    }

    /// For the system's own stream: if the producer this consumer attached to has been
    /// replaced by a new one (a restarted ingest stage, which resumes the sequence with
    /// [`FrameProducer::start_at`]), attaches to it and reports ready again, returning true.
    /// Frames the old producer left in the queue are still received first; from here on a
    /// repeated sequence number (the frame whose send a crash cut) is skipped, not refused.
    /// Call it before each [`Self::receive`]: the new producer sends nothing until every
    /// consumer has reported ready.
    pub fn follow_resumed_producer(&self) -> Result<bool, FrameError> {
        if self.ended.get() {
            return Ok(false);
        }
        match self.publisher_id() {
            Some(id) if Some(id) != self.producer.get() => {
                self.attach()?;
                self.resumed.set(true);
                Ok(true)
            }
            _ => Ok(false),
        }
    }

    /// For the system's own stream, whose producer may rewind (the ingest stage sends frames
    /// again for a restarted smooth stage): frames and end markers this consumer already has
    /// are skipped, not refused. A gap is still an error.
    pub fn skip_repeats(&self) {
        self.resumed.set(true);
    }

    /// For a consumer restarted mid-stream (the smooth stage after a crash): the stream goes
    /// on for it at `sequence` (frames before it were final already), which the producer is
    /// asked to send again. Until frame `sequence` (or the end marker at `sequence`) arrives,
    /// what arrives is skipped; after it, repeats are skipped as with [`Self::skip_repeats`].
    pub fn resync_at(&self, sequence: u64) {
        self.next_sequence.set(sequence);
        self.offset.set(0);
        self.syncing.set(true);
        self.resumed.set(true);
    }

    /// Frames skipped as repeats after a resumed producer.
    pub fn repeats(&self) -> u64 {
        self.repeats.get()
    }

    /// The listener woken by each frame (to attach to a WaitSet).
    pub fn listener(&self) -> &Listener<ipc::Service> {
        &self.listener
    }

    /// Frames received so far.
    pub fn received(&self) -> u64 {
        self.next_sequence.get()
    }

    /// True once the end-of-stream marker has arrived.
    pub fn ended(&self) -> bool {
        self.ended.get()
    }

    /// True while a producer is connected.
    pub fn producer_present(&self) -> bool {
        self.service.dynamic_config().number_of_publishers() > 0
    }

    /// For live input, where the producer is a process outside the system: true when no
    /// producer is connected any more, after removing the resources of dead nodes (so a
    /// producer killed without its end-of-stream marker is noticed through iceoryx2's
    /// dead-node detection). Call it after draining and only when the stream has not ended.
    /// A producer other than the one this consumer attached to counts as gone too: a new
    /// producer may take a vanished one's place before this consumer looks, and it sends
    /// nothing until this consumer reports ready again ([`Self::rejoin`]).
    pub fn producer_gone(&self, node: &Node<ipc::Service>) -> bool {
        if self.producer_present() {
            node.try_cleanup_dead_nodes();
        }
        match self.publisher_id() {
            None => true,
            Some(id) => self.producer.get() != Some(id),
        }
    }

    /// Ends the stream without its marker (a live producer that vanished): what was received
    /// stands, nothing more is accepted.
    pub fn end_without_marker(&self) {
        self.ended.set(true);
    }

    /// Blocks until a frame is notified or `timeout` passes.
    pub fn wait(&self, timeout: Duration) -> Result<(), FrameError> {
        woken(self.listener.timed_wait(|_| {}, timeout))
            .map_err(|e| transport("waiting for frames")(format!("{e:?}")))
    }

    /// Takes every frame waiting, validated, in order, calling `on_frame` for each; marks the
    /// end of the stream when its marker arrives. A frame that breaks the rules is an error.
    pub fn receive<E>(
        &self,
        mut on_frame: impl FnMut(ReceivedFrame<'_>) -> Result<(), E>,
    ) -> Result<(), E>
    where
        E: From<FrameError>,
    {
        while let Some(sample) = self
            .subscriber
            .receive()
            .map_err(|e| transport("receiving frames")(format!("{e:?}")))?
        {
            let header = *sample.user_header();
            let version = header.layout_version;
            if version != FRAME_LAYOUT_VERSION && version != FRAME_LAYOUT_VERSION_STILL {
                return Err(FrameError::Sequence(format!(
                    "frame {}: layout version {version} where this system reads versions \
                     {FRAME_LAYOUT_VERSION_STILL} and {FRAME_LAYOUT_VERSION} (docs/interface.md)",
                    header.sequence
                ))
                .into());
            }
            let expected = self.next_sequence.get() - self.offset.get();
            if self.syncing.get() {
                if header.sequence != expected {
                    // Sent before the producer rewound to `expected`: it comes again.
                    self.repeats.set(self.repeats.get() + 1);
                    continue;
                }
                self.syncing.set(false);
            }
            let repeat = if header.end_of_stream == 0 {
                header.sequence < expected
            } else {
                self.ended.get()
            };
            if self.resumed.get() && repeat {
                self.repeats.set(self.repeats.get() + 1);
                continue;
            }
            if self.ended.get() {
                return Err(FrameError::Sequence(format!(
                    "frame {} arrived after the end of the stream",
                    header.sequence
                ))
                .into());
            }
            if header.end_of_stream != 0 {
                if header.sequence != expected {
                    return Err(FrameError::Sequence(format!(
                        "end of stream after {} frames, but {expected} were received",
                        header.sequence,
                    ))
                    .into());
                }
                self.ended.set(true);
                continue;
            }
            let mut frame = check_frame(&header, expected, sample.payload())?;
            frame.sequence += self.offset.get();
            self.next_sequence.set(self.next_sequence.get() + 1);
            on_frame(frame)?;
        }
        Ok(())
    }
}
