//! ROS 1 bag format 2.0 (<http://wiki.ros.org/Bags/Format/2.0>), streamed chunk by chunk.
//!
//! A bag is `#ROSBAG V2.0\n`, a bag header record (where the index starts, how many
//! connections and chunks), the chunks (each a compressed run of connection and message
//! records, followed by index records), then the index: one connection record per connection
//! and one chunk-info record per chunk (message counts per connection and time range).
//!
//! Opening reads the bag header and the index only. Reading messages walks the chunks in file
//! order and holds one decompressed chunk at a time. Every length is checked against what is
//! left of the file or chunk before anything is allocated.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::bag::{RawMessage, TopicInfo};
use crate::error::BagError;
use crate::msg::Wire;

/// The first bytes of every ROS 1 bag.
pub const MAGIC: &[u8] = b"#ROSBAG V2.0\n";

/// Record op codes.
mod op {
    pub const MESSAGE_DATA: u8 = 0x02;
    pub const BAG_HEADER: u8 = 0x03;
    pub const INDEX_DATA: u8 = 0x04;
    pub const CHUNK: u8 = 0x05;
    pub const CHUNK_INFO: u8 = 0x06;
    pub const CONNECTION: u8 = 0x07;
}

/// A decompressed chunk may not claim more than this (a corrupt size must not allocate 4 GiB).
const MAX_CHUNK_BYTES: usize = 1 << 30;

/// One record: its header fields and its data.
#[derive(Debug)]
struct Record {
    fields: Vec<(String, Vec<u8>)>,
    data: Vec<u8>,
}

impl Record {
    fn field(&self, name: &str) -> Option<&[u8]> {
        self.fields
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_slice())
    }

    fn op(&self) -> Result<u8, String> {
        match self.field("op") {
            Some([op]) => Ok(*op),
            _ => Err("a record without a one-byte op field".into()),
        }
    }

    fn u32(&self, name: &str) -> Result<u32, String> {
        match self.field(name) {
            Some(v) if v.len() == 4 => Ok(u32::from_le_bytes([v[0], v[1], v[2], v[3]])),
            _ => Err(format!("record field '{name}' missing or not 4 bytes")),
        }
    }

    fn u64(&self, name: &str) -> Result<u64, String> {
        match self.field(name) {
            Some(v) if v.len() == 8 => {
                let mut b = [0u8; 8];
                b.copy_from_slice(v);
                Ok(u64::from_le_bytes(b))
            }
            _ => Err(format!("record field '{name}' missing or not 8 bytes")),
        }
    }

    /// A ROS 1 time field (u32 seconds, u32 nanoseconds) in nanoseconds.
    fn time_ns(&self, name: &str) -> Result<i64, String> {
        let raw = self.u64(name)?;
        Ok(time_ns(raw))
    }

    fn text(&self, name: &str) -> Result<String, String> {
        let v = self
            .field(name)
            .ok_or_else(|| format!("record field '{name}' missing"))?;
        String::from_utf8(v.to_vec()).map_err(|_| format!("record field '{name}' is not UTF-8"))
    }
}

/// A ROS 1 `time` packed as u64 (seconds in the low word) in nanoseconds.
fn time_ns(raw: u64) -> i64 {
    let sec = (raw & 0xffff_ffff) as i64;
    let nsec = (raw >> 32) as i64;
    sec * 1_000_000_000 + nsec
}

/// Parses `name=value` fields, each preceded by its u32 length.
fn parse_fields(mut bytes: &[u8]) -> Result<Vec<(String, Vec<u8>)>, String> {
    let mut fields = Vec::new();
    while !bytes.is_empty() {
        let (len, rest) = split_u32(bytes).ok_or("a record header ends inside a field length")?;
        let len = len as usize;
        if len > rest.len() {
            return Err(format!(
                "a header field claims {len} bytes, {} are left",
                rest.len()
            ));
        }
        let (field, rest) = rest.split_at(len);
        let eq = field
            .iter()
            .position(|&b| b == b'=')
            .ok_or("a header field without '='")?;
        let name = String::from_utf8_lossy(&field[..eq]).into_owned();
        fields.push((name, field[eq + 1..].to_vec()));
        bytes = rest;
    }
    Ok(fields)
}

fn split_u32(bytes: &[u8]) -> Option<(u32, &[u8])> {
    let (head, rest) = bytes.split_first_chunk::<4>()?;
    Some((u32::from_le_bytes(*head), rest))
}

/// Parses the record at the start of `bytes` (a decompressed chunk); returns it and its size.
fn parse_record(bytes: &[u8]) -> Result<(Record, usize), String> {
    let (header_len, rest) = split_u32(bytes).ok_or("truncated record header length")?;
    let header_len = header_len as usize;
    if header_len > rest.len() {
        return Err(format!(
            "record header of {header_len} bytes, {} left",
            rest.len()
        ));
    }
    let (header, rest) = rest.split_at(header_len);
    let (data_len, rest) = split_u32(rest).ok_or("truncated record data length")?;
    let data_len = data_len as usize;
    if data_len > rest.len() {
        return Err(format!(
            "record data of {data_len} bytes, {} left",
            rest.len()
        ));
    }
    let record = Record {
        fields: parse_fields(header)?,
        data: rest[..data_len].to_vec(),
    };
    Ok((record, 8 + header_len + data_len))
}

/// Reads a record's header or data length and checks it against the file's size.
fn read_len(
    file: &mut BufReader<File>,
    pos: &mut u64,
    file_len: u64,
    at: u64,
    what: &str,
) -> Result<usize, String> {
    let mut b = [0u8; 4];
    file.read_exact(&mut b)
        .map_err(|_| format!("truncated: the record at byte {at} ends inside its {what} length"))?;
    *pos += 4;
    let len = u64::from(u32::from_le_bytes(b));
    if *pos + len > file_len {
        return Err(format!(
            "truncated: the record at byte {at} claims a {what} of {len} bytes, the file ends {} \
             bytes later",
            file_len.saturating_sub(*pos)
        ));
    }
    Ok(len as usize)
}

/// Reads the record at the file's current position (`pos`); lengths are checked against the
/// file's size. Returns `None` at the end of the file.
fn read_record(
    file: &mut BufReader<File>,
    pos: &mut u64,
    file_len: u64,
) -> Result<Option<Record>, String> {
    if *pos >= file_len {
        return Ok(None);
    }
    let at = *pos;
    let header_len = read_len(file, pos, file_len, at, "header")?;
    let mut header = vec![0u8; header_len];
    file.read_exact(&mut header).map_err(|e| e.to_string())?;
    *pos += header_len as u64;
    let data_len = read_len(file, pos, file_len, at, "data")?;
    let mut data = vec![0u8; data_len];
    file.read_exact(&mut data).map_err(|e| e.to_string())?;
    *pos += data_len as u64;
    let fields = parse_fields(&header).map_err(|e| format!("record at byte {at}: {e}"))?;
    Ok(Some(Record { fields, data }))
}

/// A connection: which topic and type its messages have.
#[derive(Debug, Clone)]
struct Connection {
    topic: Arc<str>,
    type_name: String,
}

fn parse_connection(record: &Record) -> Result<(u32, Connection), String> {
    let id = record.u32("conn")?;
    let topic = record.text("topic")?;
    let fields = parse_fields(&record.data).map_err(|e| format!("connection {id}: {e}"))?;
    let type_name = fields
        .iter()
        .find(|(n, _)| n == "type")
        .map(|(_, v)| String::from_utf8_lossy(v).into_owned())
        .ok_or_else(|| format!("connection {id} ({topic}) has no type"))?;
    Ok((
        id,
        Connection {
            topic: topic.into(),
            type_name,
        },
    ))
}

/// An opened ROS 1 bag: its index.
#[derive(Debug, Clone)]
pub struct Ros1Bag {
    path: PathBuf,
    file_len: u64,
    /// First byte after the bag header record.
    data_start: u64,
    /// Where the index starts (the chunks end).
    index_pos: u64,
    connections: HashMap<u32, Connection>,
    /// Topics with types and message counts, sorted by name.
    pub topics: Vec<TopicInfo>,
    /// First and last message time (ns), if any message.
    pub time_range_ns: Option<(i64, i64)>,
}

impl Ros1Bag {
    /// Reads the bag header and the index.
    pub fn open(path: &Path) -> Result<Ros1Bag, BagError> {
        let fail = |m: String| BagError::format(path, m);
        let file = File::open(path).map_err(|e| BagError::io(path, e))?;
        let file_len = file.metadata().map_err(|e| BagError::io(path, e))?.len();
        let mut file = BufReader::new(file);
        let mut magic = [0u8; 13];
        if file.read_exact(&mut magic).is_err() || magic != MAGIC {
            return Err(fail(
                "not a ROS 1 bag: it does not start with '#ROSBAG V2.0'".into(),
            ));
        }
        let mut pos = MAGIC.len() as u64;
        let header = read_record(&mut file, &mut pos, file_len)
            .map_err(&fail)?
            .ok_or_else(|| fail("truncated: no bag header record".into()))?;
        if header.op().map_err(&fail)? != op::BAG_HEADER {
            return Err(fail("the first record is not a bag header".into()));
        }
        let index_pos = header.u64("index_pos").map_err(&fail)?;
        let conn_count = header.u32("conn_count").map_err(&fail)?;
        let chunk_count = header.u32("chunk_count").map_err(&fail)?;
        if index_pos == 0 {
            return Err(fail(
                "the bag has no index (its recording did not finish): run `rosbag reindex` on it"
                    .into(),
            ));
        }
        if index_pos >= file_len {
            return Err(fail(format!(
                "truncated: the index should start at byte {index_pos} but the file has {file_len} bytes"
            )));
        }
        let data_start = pos;
        file.seek(SeekFrom::Start(index_pos))
            .map_err(|e| BagError::io(path, e))?;
        pos = index_pos;
        let mut connections = HashMap::new();
        let mut counts: HashMap<u32, u64> = HashMap::new();
        let mut range: Option<(i64, i64)> = None;
        let (mut seen_conns, mut seen_chunks) = (0, 0);
        while let Some(record) = read_record(&mut file, &mut pos, file_len).map_err(&fail)? {
            match record.op().map_err(&fail)? {
                op::CONNECTION => {
                    let (id, conn) = parse_connection(&record).map_err(&fail)?;
                    connections.insert(id, conn);
                    seen_conns += 1;
                }
                op::CHUNK_INFO => {
                    let start = record.time_ns("start_time").map_err(&fail)?;
                    let end = record.time_ns("end_time").map_err(&fail)?;
                    for pair in record.data.chunks_exact(8) {
                        let conn = u32::from_le_bytes([pair[0], pair[1], pair[2], pair[3]]);
                        let n = u32::from_le_bytes([pair[4], pair[5], pair[6], pair[7]]);
                        *counts.entry(conn).or_default() += u64::from(n);
                    }
                    range = Some(match range {
                        None => (start, end),
                        Some((a, b)) => (a.min(start), b.max(end)),
                    });
                    seen_chunks += 1;
                }
                _ => {}
            }
        }
        if seen_conns != conn_count || seen_chunks != chunk_count {
            return Err(fail(format!(
                "truncated index: the bag header announces {conn_count} connections and \
                 {chunk_count} chunks, the index holds {seen_conns} and {seen_chunks}"
            )));
        }
        let mut by_topic: BTreeMap<&str, TopicInfo> = BTreeMap::new();
        for (id, conn) in &connections {
            let info = by_topic.entry(&conn.topic).or_insert_with(|| TopicInfo {
                name: conn.topic.to_string(),
                type_name: conn.type_name.clone(),
                wire: Wire::Ros1,
                count: 0,
            });
            info.count += counts.get(id).copied().unwrap_or(0);
        }
        let topics = by_topic.into_values().collect();
        Ok(Ros1Bag {
            path: path.to_path_buf(),
            file_len,
            data_start,
            index_pos,
            connections,
            topics,
            time_range_ns: range,
        })
    }

    /// Streams the messages of the wanted topics in file order.
    pub fn messages(&self, wanted: &[String]) -> Result<Ros1Messages, BagError> {
        let mut file =
            BufReader::new(File::open(&self.path).map_err(|e| BagError::io(&self.path, e))?);
        file.seek(SeekFrom::Start(self.data_start))
            .map_err(|e| BagError::io(&self.path, e))?;
        let wanted: HashMap<u32, Arc<str>> = self
            .connections
            .iter()
            .filter(|(_, c)| wanted.iter().any(|w| **w == *c.topic))
            .map(|(id, c)| (*id, c.topic.clone()))
            .collect();
        Ok(Ros1Messages {
            path: self.path.clone(),
            file,
            pos: self.data_start,
            end: self.index_pos.min(self.file_len),
            wanted,
            chunk: Vec::new(),
            chunk_at: 0,
            chunk_pos: 0,
            failed: false,
        })
    }
}

/// The messages of some topics, chunk by chunk.
#[derive(Debug)]
pub struct Ros1Messages {
    path: PathBuf,
    file: BufReader<File>,
    pos: u64,
    end: u64,
    wanted: HashMap<u32, Arc<str>>,
    /// The current decompressed chunk and the offset of the next record in it.
    chunk: Vec<u8>,
    chunk_pos: usize,
    /// File offset of the current chunk (for errors).
    chunk_at: u64,
    failed: bool,
}

/// Decompresses one chunk record's data.
fn decompress(record: &Record) -> Result<Vec<u8>, String> {
    let compression = record.text("compression")?;
    let size = record.u32("size")? as usize;
    if size > MAX_CHUNK_BYTES {
        return Err(format!(
            "a chunk claims {size} uncompressed bytes (limit {MAX_CHUNK_BYTES})"
        ));
    }
    let mut out = Vec::with_capacity(size);
    let limit = size as u64 + 1;
    match compression.as_str() {
        "none" => return Ok(record.data.clone()),
        "bz2" => {
            bzip2::read::BzDecoder::new(record.data.as_slice())
                .take(limit)
                .read_to_end(&mut out)
                .map_err(|e| format!("bz2 chunk: {e}"))?;
        }
        "lz4" => {
            lz4::Decoder::new(record.data.as_slice())
                .map_err(|e| format!("lz4 chunk: {e}"))?
                .take(limit)
                .read_to_end(&mut out)
                .map_err(|e| format!("lz4 chunk: {e}"))?;
        }
        other => {
            return Err(format!(
                "a chunk uses compression '{other}'; supported: none, bz2, lz4"
            ));
        }
    }
    if out.len() != size {
        return Err(format!(
            "a {compression} chunk decompresses to {} bytes, its header says {size}",
            out.len()
        ));
    }
    Ok(out)
}

impl Ros1Messages {
    fn message(&self, record: &Record) -> Result<Option<RawMessage>, String> {
        let conn = record.u32("conn")?;
        let Some(topic) = self.wanted.get(&conn) else {
            return Ok(None);
        };
        Ok(Some(RawMessage {
            topic: topic.clone(),
            log_time_ns: record.time_ns("time")?,
            data: record.data.clone(),
        }))
    }

    fn next_inner(&mut self) -> Result<Option<RawMessage>, BagError> {
        loop {
            if self.chunk_pos < self.chunk.len() {
                let at = self.chunk_at;
                let (record, size) = parse_record(&self.chunk[self.chunk_pos..]).map_err(|e| {
                    BagError::format(&self.path, format!("chunk at byte {at}: {e}"))
                })?;
                self.chunk_pos += size;
                let op = record.op().map_err(|e| {
                    BagError::format(&self.path, format!("chunk at byte {at}: {e}"))
                })?;
                if op == op::MESSAGE_DATA {
                    let message = self.message(&record).map_err(|e| {
                        BagError::format(&self.path, format!("chunk at byte {at}: {e}"))
                    })?;
                    if message.is_some() {
                        return Ok(message);
                    }
                }
                continue;
            }
            if self.pos >= self.end {
                return Ok(None);
            }
            let at = self.pos;
            let fail = |m: String| BagError::format(&self.path, m);
            let record = read_record(&mut self.file, &mut self.pos, self.end)
                .map_err(fail)?
                .ok_or_else(|| BagError::format(&self.path, "truncated chunk section"))?;
            match record.op().map_err(fail)? {
                op::CHUNK => {
                    self.chunk = decompress(&record).map_err(|e| {
                        BagError::format(&self.path, format!("chunk at byte {at}: {e}"))
                    })?;
                    self.chunk_pos = 0;
                    self.chunk_at = at;
                }
                op::MESSAGE_DATA => {
                    let message = self.message(&record).map_err(fail)?;
                    if message.is_some() {
                        return Ok(message);
                    }
                }
                op::INDEX_DATA | op::CONNECTION | op::CHUNK_INFO => {}
                other => {
                    return Err(fail(format!("unknown record op {other:#04x} at byte {at}")));
                }
            }
        }
    }
}

impl Iterator for Ros1Messages {
    type Item = Result<RawMessage, BagError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        let next = self.next_inner().transpose();
        if matches!(next, Some(Err(_))) {
            self.failed = true;
        }
        next
    }
}
