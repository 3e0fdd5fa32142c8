//! One type for every container: a ROS 1 `.bag`, a rosbag2 folder (`metadata.yaml` with
//! `.mcap` or `.db3` files), a bare `.mcap` or a bare `.db3`.

use std::collections::{BTreeMap, HashMap};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::error::BagError;
use crate::mcap_file::{self, McapFile};
use crate::msg::Wire;
use crate::ros1::{self, Ros1Bag};
use crate::sqlite::{self, SqliteBag};

/// A topic of a recording.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicInfo {
    /// Topic name.
    pub name: String,
    /// ROS type as the recording spells it (`sensor_msgs/PointCloud2`,
    /// `sensor_msgs/msg/PointCloud2`); an encoding that cannot be decoded here is appended
    /// in brackets.
    pub type_name: String,
    /// How its messages are serialized.
    pub wire: Wire,
    /// Messages on it.
    pub count: u64,
}

/// One message as stored: its topic, log time and serialized bytes.
#[derive(Debug, Clone)]
pub struct RawMessage {
    /// Topic.
    pub topic: Arc<str>,
    /// When the recorder logged it (ns since the epoch).
    pub log_time_ns: i64,
    /// Serialized message.
    pub data: Vec<u8>,
}

/// A stored message with its 0-based index on its topic.
#[derive(Debug, Clone)]
pub struct IndexedMessage {
    /// The message.
    pub message: RawMessage,
    /// Its index on its topic (in reading order).
    pub index: u64,
}

/// The container formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Container {
    /// ROS 1 bag v2.0.
    Ros1,
    /// A rosbag2 folder with MCAP storage.
    Rosbag2Mcap,
    /// A rosbag2 folder with sqlite3 storage.
    Rosbag2Sqlite,
    /// A bare MCAP file.
    Mcap,
    /// A bare rosbag2 sqlite3 file.
    Sqlite,
}

impl Container {
    /// Human-readable name.
    pub fn describe(self) -> &'static str {
        match self {
            Container::Ros1 => "ROS 1 bag",
            Container::Rosbag2Mcap => "rosbag2 folder (MCAP)",
            Container::Rosbag2Sqlite => "rosbag2 folder (sqlite3)",
            Container::Mcap => "MCAP file",
            Container::Sqlite => "rosbag2 sqlite3 file",
        }
    }
}

impl Container {
    /// The container at `path`, told by content (a file's first bytes; a folder's
    /// `metadata.yaml` and its first storage file), without opening it; `None` when it is
    /// none of these (or cannot be read: [`Bag::open`] then says why).
    pub fn detect(path: &Path) -> Option<Container> {
        if path.is_dir() {
            let first = rosbag2_files(path).ok()?.into_iter().next()?;
            return match Self::detect_file(&first)? {
                Container::Mcap => Some(Container::Rosbag2Mcap),
                Container::Sqlite => Some(Container::Rosbag2Sqlite),
                _ => None,
            };
        }
        Self::detect_file(path)
    }

    fn detect_file(path: &Path) -> Option<Container> {
        let mut head = [0u8; 16];
        let n = std::fs::File::open(path)
            .and_then(|mut f| f.read(&mut head))
            .ok()?;
        let head = &head[..n];
        [
            (ros1::MAGIC, Container::Ros1),
            (mcap_file::MAGIC, Container::Mcap),
            (sqlite::MAGIC, Container::Sqlite),
        ]
        .into_iter()
        .find_map(|(magic, container)| head.starts_with(magic).then_some(container))
    }
}

#[derive(Debug)]
enum Part {
    Ros1(Ros1Bag),
    Mcap(McapFile),
    Sqlite(SqliteBag),
}

impl Part {
    fn open(path: &Path) -> Result<Part, BagError> {
        let mut head = [0u8; 16];
        let n = std::fs::File::open(path)
            .and_then(|mut f| f.read(&mut head))
            .map_err(|e| BagError::io(path, e))?;
        let head = &head[..n];
        if head.starts_with(ros1::MAGIC) {
            Ok(Part::Ros1(Ros1Bag::open(path)?))
        } else if head.starts_with(mcap_file::MAGIC) {
            Ok(Part::Mcap(McapFile::open(path)?))
        } else if head.starts_with(sqlite::MAGIC) {
            Ok(Part::Sqlite(SqliteBag::open(path)?))
        } else if [ros1::MAGIC, mcap_file::MAGIC, sqlite::MAGIC]
            .iter()
            .any(|m| m.len() > head.len() && m.starts_with(head))
        {
            Err(BagError::format(
                path,
                format!("truncated: the file has only {n} bytes"),
            ))
        } else {
            Err(BagError::format(
                path,
                "not a recording: expected a ROS 1 bag, an MCAP file or a rosbag2 sqlite3 file",
            ))
        }
    }

    fn topics(&self) -> &[TopicInfo] {
        match self {
            Part::Ros1(b) => &b.topics,
            Part::Mcap(b) => &b.topics,
            Part::Sqlite(b) => &b.topics,
        }
    }

    fn time_range_ns(&self) -> Option<(i64, i64)> {
        match self {
            Part::Ros1(b) => b.time_range_ns,
            Part::Mcap(b) => b.time_range_ns,
            Part::Sqlite(b) => b.time_range_ns,
        }
    }

    fn messages(
        &self,
        wanted: &[String],
    ) -> Result<Box<dyn Iterator<Item = Result<RawMessage, BagError>> + Send>, BagError> {
        Ok(match self {
            Part::Ros1(b) => Box::new(b.messages(wanted)?),
            Part::Mcap(b) => Box::new(b.messages(wanted)?),
            Part::Sqlite(b) => Box::new(b.messages(wanted)?),
        })
    }
}

/// An opened recording: its topics, counts and time range, read without the data.
#[derive(Debug)]
pub struct Bag {
    path: PathBuf,
    container: Container,
    parts: Vec<(PathBuf, Part)>,
    topics: Vec<TopicInfo>,
    time_range_ns: Option<(i64, i64)>,
}

/// The storage files a rosbag2 `metadata.yaml` lists under `relative_file_paths`, in order
/// (block list `- a.mcap` or flow list `[a.mcap, b.mcap]`).
fn rosbag2_files(dir: &Path) -> Result<Vec<PathBuf>, BagError> {
    let meta = dir.join("metadata.yaml");
    let text = std::fs::read_to_string(&meta).map_err(|e| BagError::io(&meta, e))?;
    let mut files = Vec::new();
    let mut lines = text.lines().peekable();
    while let Some(line) = lines.next() {
        let Some(rest) = line.trim().strip_prefix("relative_file_paths:") else {
            continue;
        };
        let rest = rest.trim();
        if let Some(list) = rest.strip_prefix('[') {
            let list = list.trim_end_matches(']');
            files.extend(
                list.split(',')
                    .map(str::trim)
                    .filter(|s| !s.is_empty())
                    .map(String::from),
            );
        } else {
            while let Some(item) = lines.peek().and_then(|l| l.trim().strip_prefix("- ")) {
                files.push(item.trim().to_string());
                lines.next();
            }
        }
        break;
    }
    if files.is_empty() {
        return Err(BagError::format(
            &meta,
            "no relative_file_paths: cannot tell the storage files",
        ));
    }
    files
        .into_iter()
        .map(|f| {
            let f = f.trim_matches(|c| c == '"' || c == '\'');
            let path = dir.join(f);
            if f.ends_with(".zstd") {
                return Err(BagError::format(
                    &path,
                    "a compressed rosbag2 file: decompress it first (`ros2 bag decompress`)",
                ));
            }
            // A relative path may be stored with or without the folder's own name.
            if path.exists() {
                return Ok(path);
            }
            let name = Path::new(f).file_name().map(|n| dir.join(n));
            name.filter(|p| p.exists()).ok_or_else(|| {
                BagError::format(&meta, format!("lists '{f}', which is not in the folder"))
            })
        })
        .collect()
}

impl Bag {
    /// Opens a `.bag`, a rosbag2 folder, a `.mcap` or a `.db3`, by content (not by name).
    pub fn open(path: impl AsRef<Path>) -> Result<Bag, BagError> {
        let path = path.as_ref();
        let files = if path.is_dir() {
            rosbag2_files(path)?
        } else if path.is_file() {
            vec![path.to_path_buf()]
        } else {
            return Err(BagError::io(
                path,
                std::io::Error::new(std::io::ErrorKind::NotFound, "no such file or folder"),
            ));
        };
        let parts: Vec<(PathBuf, Part)> = files
            .into_iter()
            .map(|f| Part::open(&f).map(|p| (f, p)))
            .collect::<Result<_, _>>()?;
        let container = match (path.is_dir(), &parts[0].1) {
            (_, Part::Ros1(_)) => Container::Ros1,
            (true, Part::Mcap(_)) => Container::Rosbag2Mcap,
            (true, Part::Sqlite(_)) => Container::Rosbag2Sqlite,
            (false, Part::Mcap(_)) => Container::Mcap,
            (false, Part::Sqlite(_)) => Container::Sqlite,
        };
        let mut merged: BTreeMap<String, TopicInfo> = BTreeMap::new();
        let mut range: Option<(i64, i64)> = None;
        for (_, part) in &parts {
            for topic in part.topics() {
                merged
                    .entry(topic.name.clone())
                    .and_modify(|t| t.count += topic.count)
                    .or_insert_with(|| topic.clone());
            }
            if let Some((a, b)) = part.time_range_ns() {
                range = Some(range.map_or((a, b), |(x, y)| (x.min(a), y.max(b))));
            }
        }
        Ok(Bag {
            path: path.to_path_buf(),
            container,
            parts,
            topics: merged.into_values().collect(),
            time_range_ns: range,
        })
    }

    /// The path it was opened from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Its container format.
    pub fn container(&self) -> Container {
        self.container
    }

    /// Topics, sorted by name.
    pub fn topics(&self) -> &[TopicInfo] {
        &self.topics
    }

    /// A topic by name.
    pub fn topic(&self, name: &str) -> Option<&TopicInfo> {
        self.topics.iter().find(|t| t.name == name)
    }

    /// First and last message time (ns), when the recording has messages.
    pub fn time_range_ns(&self) -> Option<(i64, i64)> {
        self.time_range_ns
    }

    /// Total bytes of its storage files.
    pub fn size_bytes(&self) -> u64 {
        self.parts
            .iter()
            .filter_map(|(p, _)| std::fs::metadata(p).ok())
            .map(|m| m.len())
            .sum()
    }

    /// Streams the messages of the wanted topics (storage file by storage file, each in its
    /// own order: file order for ROS 1 and MCAP, time order for sqlite3), each with its index
    /// on its topic.
    pub fn messages(&self, wanted: &[String]) -> Result<Messages, BagError> {
        let mut parts = Vec::new();
        for (_, part) in &self.parts {
            parts.push(part.messages(wanted)?);
        }
        Ok(Messages {
            inner: Box::new(parts.into_iter().flatten()),
            counts: HashMap::new(),
        })
    }
}

/// Messages with their per-topic index.
pub struct Messages {
    inner: Box<dyn Iterator<Item = Result<RawMessage, BagError>> + Send>,
    counts: HashMap<Arc<str>, u64>,
}

impl std::fmt::Debug for Messages {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Messages").finish_non_exhaustive()
    }
}

impl Iterator for Messages {
    type Item = Result<IndexedMessage, BagError>;

    fn next(&mut self) -> Option<Self::Item> {
        let message = match self.inner.next()? {
            Ok(m) => m,
            Err(e) => return Some(Err(e)),
        };
        let count = self.counts.entry(message.topic.clone()).or_default();
        let index = *count;
        *count += 1;
        Some(Ok(IndexedMessage { message, index }))
    }
}
