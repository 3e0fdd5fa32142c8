//! The smooth stage keeps each window result it publishes until the record stage confirms it
//! is on disk ([`RecordedAck`], sent after every flush of the recording). A restarted record
//! stage loses what was in its queue and what it had not flushed; it asks for the windows
//! after the last one on disk, and they are sent again under their message ids. Only the
//! unconfirmed windows are kept, so memory stays bounded by how far the recorder lags.

use crate::Error;
use crate::transport::shm;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use pssba_msg::internal::services;
use pssba_msg::{RecordedAck, ResultHeader};
use std::collections::VecDeque;

/// One published result message.
#[derive(Debug)]
struct Kept {
    window: u64,
    header: ResultHeader,
    words: Vec<f64>,
    message_id: u64,
}

/// Results not yet confirmed by the recorder.
#[derive(Debug)]
pub struct Retained {
    acks: Subscriber<ipc::Service, RecordedAck, ()>,
    kept: VecDeque<Kept>,
    /// The end-of-run message, once published and until it is confirmed.
    end: Option<Kept>,
}

impl Retained {
    /// Subscribes to the recorder's confirmations.
    pub fn create(node: &Node<ipc::Service>) -> crate::Result<Self> {
        let acks = services::recorded_service(node)?
            .subscriber_builder()
            .create()
            .map_err(Error::ipc("subscribing to the recorder's confirmations"))?;
        Ok(Self {
            acks,
            kept: VecDeque::new(),
            end: None,
        })
    }

    /// Keeps a published window result.
    pub fn keep(&mut self, window: u64, header: ResultHeader, words: Vec<f64>, message_id: u64) {
        self.kept.push_back(Kept {
            window,
            header,
            words,
            message_id,
        });
    }

    /// Keeps the published end-of-run message.
    pub fn keep_end(&mut self, header: ResultHeader, message_id: u64) {
        self.end = Some(Kept {
            window: header.window,
            header,
            words: Vec::new(),
            message_id,
        });
    }

    /// Windows kept.
    pub fn len(&self) -> usize {
        self.kept.len()
    }

    /// True if nothing is kept.
    pub fn is_empty(&self) -> bool {
        self.kept.is_empty() && self.end.is_none()
    }

    /// Reads the recorder's confirmations: forgets what is on disk, and sends again what a
    /// restarted recorder asks for.
    pub fn serve(
        &mut self,
        results: &Publisher<ipc::Service, [f64], ResultHeader>,
        notifier: &Notifier<ipc::Service>,
        sample_words: usize,
    ) -> crate::Result<()> {
        while let Some(sample) = self
            .acks
            .receive()
            .map_err(Error::ipc("receiving the recorder's confirmations"))?
        {
            let ack = *sample;
            while self
                .kept
                .front()
                .is_some_and(|k| k.window < ack.next_window)
            {
                self.kept.pop_front();
            }
            if ack.end_of_run != 0 {
                self.end = None;
            }
            if ack.replay == 0 {
                continue;
            }
            tracing::warn!(
                "a restarted record stage has windows 0..{}: sending {} kept windows{} again",
                ack.next_window,
                self.kept.len(),
                if self.end.is_some() {
                    " and the end of the run"
                } else {
                    ""
                }
            );
            for kept in self.kept.iter().chain(&self.end) {
                shm::publish_parts(
                    results,
                    notifier,
                    kept.header,
                    kept.message_id,
                    kept.words.len(),
                    sample_words,
                    kept.words.iter().copied(),
                )?;
            }
        }
        Ok(())
    }
}
