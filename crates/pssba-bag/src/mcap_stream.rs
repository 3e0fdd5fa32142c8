//! Streams an MCAP file's messages, as `mcap::io::MessageReader` does (the same linear reader,
//! chunk decompression and schema/channel bookkeeping of the mcap crate), with one check in
//! front of the crate's record parser: mcap 0.26 panics on an attachment record too short to
//! hold its CRC after its header (`read.rs` slices `body[header_len..body.len() - 4]`
//! unchecked). Found by the `replay_mcap` fuzzer (crates/pssba-system/fuzz); such a record is
//! now an error, like any other malformed record.

use mcap::records::{Record, op};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use mcap::{McapError, Message};
use std::borrow::Cow;
use std::io::Read;

/// Messages of an MCAP file in file order (see the module documentation).
pub struct MessageReader<R: Read> {
    source: R,
    reader: LinearReader,
    channels: mcap::read::ChannelAccumulator<'static>,
    done: bool,
}

impl<R: Read> std::fmt::Debug for MessageReader<R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MessageReader")
            .field("done", &self.done)
            .finish_non_exhaustive()
    }
}

impl<R: Read> MessageReader<R> {
    /// Reads `source` with `options` (chunks are always opened).
    pub fn new(source: R, options: LinearReaderOptions) -> Self {
        Self {
            source,
            reader: LinearReader::new_with_options(options.with_emit_chunks(false)),
            channels: mcap::read::ChannelAccumulator::default(),
            done: false,
        }
    }

    fn next_inner(&mut self) -> Option<Result<Message<'static>, McapError>> {
        loop {
            let event = match self.reader.next_event()? {
                Ok(event) => event,
                Err(error) => return Some(Err(error)),
            };
            let (opcode, data) = match event {
                LinearReadEvent::ReadRequest(need) => {
                    let read = loop {
                        match self.source.read(self.reader.insert(need)) {
                            Ok(n) => break n,
                            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                            Err(e) => return Some(Err(e.into())),
                        }
                    };
                    self.reader.notify_read(read);
                    continue;
                }
                LinearReadEvent::Record { opcode, data } => (opcode, data),
            };
            if opcode == op::ATTACHMENT
                && let Some(header_len) = attachment_header_len(data)
                && data.len() < header_len + 4
            {
                return Some(Err(McapError::BadAttachmentLength {
                    header: header_len as u64,
                    available: data.len() as u64,
                }));
            }
            let record = match mcap::parse_record(opcode, data) {
                Ok(record) => record,
                Err(error) => return Some(Err(error)),
            };
            // The summary's schemas and channels repeat the data section's: a copy that
            // conflicts with its original is an error (the crate's own reader skips them).
            match record {
                Record::Schema { header, data } => {
                    let data = Cow::Owned(data.into_owned());
                    if let Err(error) = self.channels.add_schema(header, data) {
                        return Some(Err(error));
                    }
                }
                Record::Channel(channel) => {
                    if let Err(error) = self.channels.add_channel(channel) {
                        return Some(Err(error));
                    }
                }
                Record::Message { header, data } => {
                    let Some(channel) = self.channels.get(header.channel_id) else {
                        return Some(Err(McapError::UnknownChannel(
                            header.sequence,
                            header.channel_id,
                        )));
                    };
                    return Some(Ok(Message {
                        channel,
                        sequence: header.sequence,
                        log_time: header.log_time,
                        publish_time: header.publish_time,
                        data: Cow::Owned(data.into_owned()),
                    }));
                }
                _ => {}
            }
        }
    }
}

impl<R: Read> Iterator for MessageReader<R> {
    type Item = Result<Message<'static>, McapError>;

    /// The next message; after the first error, nothing more.
    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let item = self.next_inner();
        if !matches!(item, Some(Ok(_))) {
            self.done = true;
        }
        item
    }
}

/// Length of an attachment record's header up to and including its data length field (log
/// time, create time, name, media type, data length), if the body holds that much.
pub(crate) fn attachment_header_len(body: &[u8]) -> Option<usize> {
    let u32_at = |at: usize| -> Option<usize> {
        let bytes = body.get(at..at + 4)?;
        Some(u32::from_le_bytes(bytes.try_into().ok()?) as usize)
    };
    let name_len = u32_at(16)?;
    let media_at = 20usize.checked_add(name_len)?;
    let media_len = u32_at(media_at)?;
    let header_len = media_at.checked_add(4 + media_len + 8)?;
    (header_len <= body.len()).then_some(header_len)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An attachment record body: header, `data_len` bytes claimed, `data` and no CRC.
    fn attachment(name: &str, data: &[u8], crc: bool) -> Vec<u8> {
        let mut body = Vec::new();
        body.extend_from_slice(&1u64.to_le_bytes());
        body.extend_from_slice(&2u64.to_le_bytes());
        body.extend_from_slice(&(name.len() as u32).to_le_bytes());
        body.extend_from_slice(name.as_bytes());
        body.extend_from_slice(&0u32.to_le_bytes());
        body.extend_from_slice(&(data.len() as u64).to_le_bytes());
        body.extend_from_slice(data);
        if crc {
            body.extend_from_slice(&0u32.to_le_bytes());
        }
        body
    }

    #[test]
    fn an_attachment_without_room_for_its_crc_is_an_error_not_a_panic() {
        let mut file = mcap::MAGIC.to_vec();
        // Header record: empty profile and library.
        file.push(op::HEADER);
        file.extend_from_slice(&8u64.to_le_bytes());
        file.extend_from_slice(&[0u8; 8]);
        let body = attachment("a", &[], false);
        file.push(op::ATTACHMENT);
        file.extend_from_slice(&(body.len() as u64).to_le_bytes());
        file.extend_from_slice(&body);
        let items: Vec<_> =
            MessageReader::new(std::io::Cursor::new(file), LinearReaderOptions::default())
                .collect();
        assert_eq!(items.len(), 1, "one error, then nothing");
        let error = items[0].as_ref().expect_err("malformed attachment");
        assert!(
            matches!(error, McapError::BadAttachmentLength { .. }),
            "{error}"
        );
    }

    #[test]
    fn the_header_length_of_a_well_formed_attachment_is_found() {
        let body = attachment("name", b"xyz", true);
        assert_eq!(attachment_header_len(&body), Some(8 + 8 + 4 + 4 + 4 + 8));
        assert_eq!(attachment_header_len(&body[..10]), None);
    }
}
