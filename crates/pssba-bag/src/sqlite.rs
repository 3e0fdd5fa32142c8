//! A rosbag2 sqlite3 storage file (`.db3`, the default on Humble): table `topics` (id, name,
//! type, serialization_format) and table `messages` (id, topic_id, timestamp, data). Messages
//! are read in pages of [`PAGE`] rows ordered by (timestamp, id), so memory stays bounded.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use rusqlite::{Connection, OpenFlags};

use crate::bag::{RawMessage, TopicInfo};
use crate::error::BagError;
use crate::msg::Wire;

/// Rows fetched per query.
const PAGE: usize = 64;

/// The first bytes of every sqlite3 database.
pub const MAGIC: &[u8] = b"SQLite format 3\0";

/// An opened `.db3` file.
#[derive(Debug)]
pub struct SqliteBag {
    path: PathBuf,
    /// topic id -> topic name
    names: HashMap<i64, Arc<str>>,
    /// Topics with types and counts, sorted by name.
    pub topics: Vec<TopicInfo>,
    /// First and last message time (ns).
    pub time_range_ns: Option<(i64, i64)>,
}

fn open_db(path: &Path) -> Result<Connection, BagError> {
    Connection::open_with_flags(
        path,
        OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )
    .map_err(|e| BagError::format(path, format!("cannot open as sqlite3: {e}")))
}

impl SqliteBag {
    /// Reads the topic table and per-topic counts and time range.
    pub fn open(path: &Path) -> Result<SqliteBag, BagError> {
        let db = open_db(path)?;
        let fail =
            |e: rusqlite::Error| BagError::format(path, format!("not a rosbag2 sqlite3 file: {e}"));
        let mut topics_query = db
            .prepare("SELECT id, name, type, serialization_format FROM topics")
            .map_err(fail)?;
        let rows = topics_query
            .query_map([], |r| {
                Ok((
                    r.get::<_, i64>(0)?,
                    r.get::<_, String>(1)?,
                    r.get::<_, String>(2)?,
                    r.get::<_, String>(3)?,
                ))
            })
            .map_err(fail)?;
        let mut by_id = BTreeMap::new();
        for row in rows {
            let (id, name, type_name, format) = row.map_err(fail)?;
            by_id.insert(id, (name, type_name, format));
        }
        let mut counts_query = db
            .prepare("SELECT topic_id, COUNT(*), MIN(timestamp), MAX(timestamp) FROM messages GROUP BY topic_id")
            .map_err(fail)?;
        let rows = counts_query
            .query_map([], |r| {
                Ok((
                    r.get::<_, i64>(0)?,
                    r.get::<_, i64>(1)?,
                    r.get::<_, i64>(2)?,
                    r.get::<_, i64>(3)?,
                ))
            })
            .map_err(fail)?;
        let mut counts = HashMap::new();
        let mut range: Option<(i64, i64)> = None;
        for row in rows {
            let (id, count, first, last) = row.map_err(fail)?;
            counts.insert(id, count.max(0) as u64);
            range = Some(match range {
                None => (first, last),
                Some((a, b)) => (a.min(first), b.max(last)),
            });
        }
        let mut topics: Vec<TopicInfo> = by_id
            .iter()
            .map(|(id, (name, type_name, format))| TopicInfo {
                name: name.clone(),
                type_name: if format == "cdr" {
                    type_name.clone()
                } else {
                    format!("{type_name} [{format}]")
                },
                wire: Wire::Cdr,
                count: counts.get(id).copied().unwrap_or(0),
            })
            .collect();
        topics.sort_by(|a, b| a.name.cmp(&b.name));
        Ok(SqliteBag {
            path: path.to_path_buf(),
            names: by_id
                .into_iter()
                .map(|(id, (name, _, _))| (id, Arc::from(name.as_str())))
                .collect(),
            topics,
            time_range_ns: range,
        })
    }

    /// Streams the messages of the wanted topics, ordered by time.
    pub fn messages(&self, wanted: &[String]) -> Result<SqliteMessages, BagError> {
        let ids: Vec<i64> = self
            .names
            .iter()
            .filter(|(_, name)| wanted.iter().any(|w| **w == ***name))
            .map(|(id, _)| *id)
            .collect();
        Ok(SqliteMessages {
            path: self.path.clone(),
            db: open_db(&self.path)?,
            names: self.names.clone(),
            ids_sql: ids.iter().map(i64::to_string).collect::<Vec<_>>().join(","),
            after: None,
            page: VecDeque::new(),
            done: ids.is_empty(),
        })
    }
}

/// The messages of some topics, a page at a time.
pub struct SqliteMessages {
    path: PathBuf,
    db: Connection,
    names: HashMap<i64, Arc<str>>,
    ids_sql: String,
    /// The (timestamp, id) of the last row returned.
    after: Option<(i64, i64)>,
    page: VecDeque<(i64, i64, i64, Vec<u8>)>,
    done: bool,
}

impl std::fmt::Debug for SqliteMessages {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SqliteMessages")
            .field("path", &self.path)
            .finish_non_exhaustive()
    }
}

impl SqliteMessages {
    fn fetch(&mut self) -> Result<(), rusqlite::Error> {
        let (t, id) = self.after.unwrap_or((i64::MIN, i64::MIN));
        let sql = format!(
            "SELECT timestamp, id, topic_id, data FROM messages \
             WHERE topic_id IN ({}) AND (timestamp > ?1 OR (timestamp = ?1 AND id > ?2)) \
             ORDER BY timestamp, id LIMIT {PAGE}",
            self.ids_sql
        );
        let mut query = self.db.prepare_cached(&sql)?;
        let rows = query.query_map([t, id], |r| {
            Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get::<_, Vec<u8>>(3)?))
        })?;
        for row in rows {
            self.page.push_back(row?);
        }
        Ok(())
    }
}

impl Iterator for SqliteMessages {
    type Item = Result<RawMessage, BagError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        if self.page.is_empty() {
            if let Err(e) = self.fetch() {
                self.done = true;
                return Some(Err(BagError::format(
                    &self.path,
                    format!("reading messages: {e}"),
                )));
            }
            if self.page.is_empty() {
                self.done = true;
                return None;
            }
        }
        let (stamp, id, topic_id, data) = self.page.pop_front()?;
        self.after = Some((stamp, id));
        let topic = self.names.get(&topic_id).cloned()?;
        Some(Ok(RawMessage {
            topic,
            log_time_ns: stamp,
            data,
        }))
    }
}
