//! An MCAP file as ROS 2 writes it (message encoding `cdr`, schemas `ros2msg`), or any other
//! MCAP: topics and counts come from its summary section when it has one (read from the end
//! of the file, without the data), else from one streaming pass; messages are streamed with
//! `mcap::io::MessageReader`, one chunk in memory at a time.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::bag::{RawMessage, TopicInfo};
use crate::error::BagError;
use crate::msg::Wire;

/// The first bytes of every MCAP file.
pub const MAGIC: &[u8] = b"\x89MCAP0\r\n";

/// Footer record (opcode, length, 20-byte body) plus the closing magic.
const FOOTER_BYTES: u64 = 1 + 8 + 20 + 8;

/// The summary section is read whole; it may not claim more than this.
const MAX_SUMMARY_BYTES: u64 = 256 << 20;

/// A record larger than the file is corrupt, except inside a compressed chunk; this much is
/// always allowed (a LiDAR message is far smaller).
const MIN_RECORD_LIMIT_BYTES: u64 = 256 << 20;

/// Streams an MCAP file's messages with lengths bounded by the file's size (or
/// [`MIN_RECORD_LIMIT_BYTES`]): a corrupt record length is an error, not a huge allocation.
pub fn message_reader(
    path: &Path,
) -> Result<crate::mcap_stream::MessageReader<BufReader<File>>, BagError> {
    let file = File::open(path).map_err(|e| BagError::io(path, e))?;
    let len = file.metadata().map_err(|e| BagError::io(path, e))?.len();
    let limit = usize::try_from(len.max(MIN_RECORD_LIMIT_BYTES)).unwrap_or(usize::MAX);
    let options = mcap::sans_io::LinearReaderOptions::default().with_record_length_limit(limit);
    Ok(crate::mcap_stream::MessageReader::new(
        BufReader::new(file),
        options,
    ))
}

/// An opened MCAP file.
#[derive(Debug, Clone)]
pub struct McapFile {
    path: PathBuf,
    /// Topics with types and counts, sorted by name.
    pub topics: Vec<TopicInfo>,
    /// First and last message log time (ns).
    pub time_range_ns: Option<(i64, i64)>,
}

/// The wire format of a channel's messages, if this crate can decode them.
fn wire_of(message_encoding: &str) -> Option<Wire> {
    match message_encoding {
        "cdr" => Some(Wire::Cdr),
        "ros1" => Some(Wire::Ros1),
        _ => None,
    }
}

#[derive(Default)]
struct Tally {
    /// topic -> (type, encoding, count)
    topics: BTreeMap<String, (String, String, u64)>,
    range: Option<(i64, i64)>,
}

impl Tally {
    fn add(&mut self, topic: &str, type_name: &str, encoding: &str, count: u64) {
        let entry = self
            .topics
            .entry(topic.to_string())
            .or_insert_with(|| (type_name.to_string(), encoding.to_string(), 0));
        entry.2 += count;
    }

    fn time(&mut self, start: i64, end: i64) {
        self.range = Some(match self.range {
            None => (start, end),
            Some((a, b)) => (a.min(start), b.max(end)),
        });
    }

    fn into_topics(self) -> Vec<TopicInfo> {
        self.topics
            .into_iter()
            .map(|(name, (type_name, encoding, count))| TopicInfo {
                name,
                // A channel whose encoding is not decoded here keeps its type for listing,
                // marked so that it is never picked.
                type_name: if wire_of(&encoding).is_some() {
                    type_name
                } else {
                    format!("{type_name} [{encoding}]")
                },
                wire: wire_of(&encoding).unwrap_or(Wire::Cdr),
                count,
            })
            .collect()
    }
}

impl McapFile {
    /// Reads the summary (or, without one, counts the messages in one pass).
    pub fn open(path: &Path) -> Result<McapFile, BagError> {
        let mut file = File::open(path).map_err(|e| BagError::io(path, e))?;
        let len = file.metadata().map_err(|e| BagError::io(path, e))?.len();
        let mut magic = [0u8; 8];
        if file.read_exact(&mut magic).is_err() || magic != MAGIC {
            return Err(BagError::format(path, "not an MCAP file (bad magic)"));
        }
        let tally = match read_summary(&mut file, len) {
            Some(tally) => tally,
            None => count_by_streaming(path)?,
        };
        Ok(McapFile {
            path: path.to_path_buf(),
            time_range_ns: tally.range,
            topics: tally.into_topics(),
        })
    }

    /// Streams the messages of the wanted topics in file order.
    pub fn messages(&self, wanted: &[String]) -> Result<McapMessages, BagError> {
        Ok(McapMessages {
            path: self.path.clone(),
            reader: message_reader(&self.path)?,
            wanted: wanted.iter().map(|w| Arc::from(w.as_str())).collect(),
            failed: false,
        })
    }
}

/// Schemas, channels and statistics from the summary section; `None` when the file has no
/// usable summary (then the caller counts by streaming).
fn read_summary(file: &mut File, len: u64) -> Option<Tally> {
    if len < 2 * MAGIC.len() as u64 + FOOTER_BYTES {
        return None;
    }
    let footer_at = len - FOOTER_BYTES;
    file.seek(SeekFrom::Start(footer_at)).ok()?;
    let mut footer = [0u8; FOOTER_BYTES as usize];
    file.read_exact(&mut footer).ok()?;
    if footer[0] != 0x02 || &footer[29..] != MAGIC {
        return None;
    }
    let summary_start = u64::from_le_bytes(footer[9..17].try_into().ok()?);
    if summary_start == 0
        || summary_start >= footer_at
        || footer_at - summary_start > MAX_SUMMARY_BYTES
    {
        return None;
    }
    file.seek(SeekFrom::Start(summary_start)).ok()?;
    let mut summary = vec![0u8; (footer_at - summary_start) as usize];
    file.read_exact(&mut summary).ok()?;
    if has_malformed_attachment(&summary) {
        // The mcap crate's parser would panic on it; streaming reports the error.
        return None;
    }
    let mut schemas = BTreeMap::new();
    let mut channels = BTreeMap::new();
    let mut statistics = None;
    for record in mcap::read::LinearReader::sans_magic(&summary) {
        match record.ok()? {
            mcap::records::Record::Schema { header, .. } => {
                schemas.insert(header.id, header.name);
            }
            mcap::records::Record::Channel(c) => {
                channels.insert(c.id, c);
            }
            mcap::records::Record::Statistics(s) => statistics = Some(s),
            _ => {}
        }
    }
    let statistics = statistics?;
    let mut tally = Tally::default();
    for (id, channel) in &channels {
        let type_name = schemas.get(&channel.schema_id).cloned().unwrap_or_default();
        let count = statistics
            .channel_message_counts
            .get(id)
            .copied()
            .unwrap_or(0);
        tally.add(&channel.topic, &type_name, &channel.message_encoding, count);
    }
    if statistics.message_count > 0 {
        tally.time(
            statistics.message_start_time as i64,
            statistics.message_end_time as i64,
        );
    }
    Some(tally)
}

/// True if a record of `section` (records back to back, no magic) is an attachment too short
/// for its CRC ([`crate::mcap_stream`]).
fn has_malformed_attachment(section: &[u8]) -> bool {
    let mut at = 0usize;
    while let Some(head) = section.get(at..at + 9) {
        let opcode = head[0];
        let len = u64::from_le_bytes(head[1..9].try_into().unwrap_or([0; 8]));
        let Some(end) = usize::try_from(len)
            .ok()
            .and_then(|l| (at + 9).checked_add(l))
        else {
            return false;
        };
        let Some(body) = section.get(at + 9..end) else {
            return false;
        };
        if opcode == mcap::records::op::ATTACHMENT
            && crate::mcap_stream::attachment_header_len(body).is_some_and(|h| body.len() < h + 4)
        {
            return true;
        }
        at = end;
    }
    false
}

fn count_by_streaming(path: &Path) -> Result<Tally, BagError> {
    let mut tally = Tally::default();
    for message in message_reader(path)? {
        let message = message.map_err(|e| BagError::format(path, e.to_string()))?;
        let channel = &message.channel;
        let type_name = channel
            .schema
            .as_ref()
            .map(|s| s.name.clone())
            .unwrap_or_default();
        tally.add(&channel.topic, &type_name, &channel.message_encoding, 1);
        tally.time(message.log_time as i64, message.log_time as i64);
    }
    Ok(tally)
}

/// The messages of some topics.
pub struct McapMessages {
    path: PathBuf,
    reader: crate::mcap_stream::MessageReader<BufReader<File>>,
    wanted: Vec<Arc<str>>,
    failed: bool,
}

impl std::fmt::Debug for McapMessages {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapMessages")
            .field("path", &self.path)
            .finish_non_exhaustive()
    }
}

impl Iterator for McapMessages {
    type Item = Result<RawMessage, BagError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        for message in self.reader.by_ref() {
            let message = match message {
                Ok(m) => m,
                Err(e) => {
                    self.failed = true;
                    return Some(Err(BagError::format(&self.path, e.to_string())));
                }
            };
            let Some(topic) = self.wanted.iter().find(|w| ***w == *message.channel.topic) else {
                continue;
            };
            return Some(Ok(RawMessage {
                topic: topic.clone(),
                log_time_ns: message.log_time as i64,
                data: message.data.into_owned(),
            }));
        }
        None
    }
}
