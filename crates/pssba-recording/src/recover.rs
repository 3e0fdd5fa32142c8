//! A full summary section for a part that has none: one the recorder ended after a crash
//! ([`crate::end_cut_file`]: data end and footer only) or one torn by a recorder that was not
//! restarted. Readers that seek through the summary (chunk indexes, statistics, as the
//! Foxglove app and `mcap info` do) then work on it, as `mcap recover` would make them.
//!
//! The part's messages are copied, sequence and times kept, into a new file in this format
//! (every schema and channel declared, as a recorder declares them), which then replaces it.
//! Run it only when no stage writes the recording any more.

use crate::write::McapRecorder;
use crate::{RecordingError, existing_parts};
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

/// Bytes of a footer record with its opcode and length, and the closing magic.
const FOOTER_AND_MAGIC: u64 = 1 + 8 + 20 + 8;

/// Whether `path` ends on a footer that points to a summary section.
pub fn has_summary(path: &Path) -> crate::Result<bool> {
    let io = |e| RecordingError::Io {
        what: "reading the footer of",
        path: path.to_path_buf(),
        source: e,
    };
    let mut file = std::fs::File::open(path).map_err(io)?;
    let len = file.metadata().map_err(io)?.len();
    if len < FOOTER_AND_MAGIC {
        return Ok(false);
    }
    let mut tail = [0u8; FOOTER_AND_MAGIC as usize];
    file.seek(SeekFrom::Start(len - FOOTER_AND_MAGIC))
        .and_then(|_| file.read_exact(&mut tail))
        .map_err(io)?;
    let footer_opcode = tail[0];
    let magic_ok = &tail[tail.len() - 8..] == mcap::MAGIC;
    let summary_start = u64::from_le_bytes(tail[9..17].try_into().unwrap_or_default());
    Ok(footer_opcode == 0x02 && magic_ok && summary_start != 0)
}

/// What [`add_summary`] did to a part.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Summarized {
    /// The part had a summary already; left as it was.
    AlreadyWhole,
    /// The part was rewritten with a summary: `messages` copied; `torn` if its end did not
    /// read (a recorder killed mid-write), the messages before that kept.
    Rewritten { messages: u64, torn: bool },
}

/// Gives the part at `path` a summary section if it has none. On an error (a full disk) the
/// part is left as it was.
pub fn add_summary(path: &Path) -> crate::Result<Summarized> {
    if has_summary(path)? {
        return Ok(Summarized::AlreadyWhole);
    }
    let staged = path.with_extension("summarizing.mcap");
    let copied = copy_into(path, &staged);
    if copied.is_err() {
        let _ = std::fs::remove_file(&staged);
    }
    copied
}

fn copy_into(path: &Path, staged: &Path) -> crate::Result<Summarized> {
    let io = |what, e| RecordingError::Io {
        what,
        path: staged.to_path_buf(),
        source: e,
    };
    let file = std::fs::File::create(staged).map_err(|e| io("creating", e))?;
    let mut recorder = McapRecorder::new(std::io::BufWriter::new(file))?;
    let reader = pssba_bag::mcap_message_reader(path)
        .map_err(|e| RecordingError::read(path, e.to_string()))?;
    let (mut messages, mut torn) = (0u64, false);
    for message in reader {
        let Ok(message) = message else {
            torn = true;
            break;
        };
        if !recorder.copy_message(&message)? {
            return Err(RecordingError::read(
                path,
                format!(
                    "topic {} is not one of a pssba run recording's",
                    message.channel.topic
                ),
            ));
        }
        messages += 1;
    }
    recorder.finish()?;
    std::fs::File::open(staged)
        .and_then(|f| f.sync_all())
        .map_err(|e| io("syncing", e))?;
    std::fs::rename(staged, path).map_err(|e| io("moving into place", e))?;
    Ok(Summarized::Rewritten { messages, torn })
}

/// [`add_summary`] for every part of the recording to `out`; returns the parts rewritten.
pub fn add_summaries(out: &Path) -> crate::Result<Vec<(std::path::PathBuf, Summarized)>> {
    let mut rewritten = Vec::new();
    for part in existing_parts(out).into_iter().filter(|p| p.exists()) {
        let done = add_summary(&part)?;
        if done != Summarized::AlreadyWhole {
            rewritten.push((part, done));
        }
    }
    Ok(rewritten)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::write::{KnownFrame, end_cut_file};
    use nalgebra::Isometry3;

    fn frame(k: u32) -> KnownFrame {
        KnownFrame {
            stamp_s: 1.0 + f64::from(k) * 0.1,
            initial: Isometry3::translation(f64::from(k), 0.0, 0.0),
            ground_truth: None,
            optimized: None,
        }
    }

    /// (topic, sequence, log time, data) of every message, read by scanning.
    fn messages(path: &Path) -> Vec<(String, u32, u64, Vec<u8>)> {
        pssba_bag::mcap_message_reader(path)
            .expect("reader")
            .map(|m| {
                let m = m.expect("message");
                (
                    m.channel.topic.clone(),
                    m.sequence,
                    m.log_time,
                    m.data.to_vec(),
                )
            })
            .collect()
    }

    #[test]
    fn a_cut_part_gets_a_summary_that_indexed_readers_use() {
        let dir = tempfile::tempdir().expect("tmp");
        let path = dir.path().join("run.mcap");
        let file = std::fs::File::create(&path).expect("create");
        let mut recorder = McapRecorder::new(std::io::BufWriter::new(file)).expect("recorder");
        let points = vec![[1.0f32, 2.0, 3.0]; 5000];
        for k in 0..6 {
            recorder.add_frame(frame(k), &points, None).expect("frame");
        }
        recorder.flush().expect("flush");
        let clean_len = std::fs::metadata(&path).expect("len").len();
        drop(recorder);
        end_cut_file(&path, clean_len).expect("ended");
        assert!(!has_summary(&path).expect("footer"));
        let cut = std::fs::read(&path).expect("read");
        assert!(
            mcap::Summary::read(&cut).expect("footer").is_none(),
            "no summary yet"
        );
        let before = messages(&path);
        assert_eq!(before.len(), 6);

        assert_eq!(
            add_summary(&path).expect("summary"),
            Summarized::Rewritten {
                messages: 6,
                torn: false
            }
        );
        assert!(has_summary(&path).expect("footer"));
        assert_eq!(messages(&path), before, "every message kept, in order");
        let bytes = std::fs::read(&path).expect("read");
        let summary = mcap::Summary::read(&bytes)
            .expect("summary")
            .expect("present");
        let stats = summary.stats.clone().expect("statistics");
        assert_eq!(stats.message_count, 6);
        assert!(!summary.chunk_indexes.is_empty());
        assert_eq!(summary.channels.len(), 8, "every channel of the format");
        let mut indexed = 0;
        for index in &summary.chunk_indexes {
            indexed += summary.stream_chunk(&bytes, index).expect("chunk").count();
        }
        assert_eq!(indexed, 6, "the messages, found through the chunk indexes");
        assert_eq!(add_summary(&path).expect("again"), Summarized::AlreadyWhole);
    }

    #[test]
    fn a_torn_part_keeps_the_messages_before_the_tear() {
        let dir = tempfile::tempdir().expect("tmp");
        let path = dir.path().join("run.mcap");
        let file = std::fs::File::create(&path).expect("create");
        let mut recorder = McapRecorder::new(std::io::BufWriter::new(file)).expect("recorder");
        let points = vec![[1.0f32, 2.0, 3.0]; 5000];
        for k in 0..3 {
            recorder.add_frame(frame(k), &points, None).expect("frame");
        }
        recorder.flush().expect("flush");
        let clean_len = std::fs::metadata(&path).expect("len").len();
        drop(recorder);
        // A half-written record after the last flush, no footer: a killed recorder.
        let mut bytes = std::fs::read(&path).expect("read");
        bytes.truncate(clean_len as usize);
        bytes.extend_from_slice(&[0x06, 0xff, 0xff, 0, 0, 0, 0, 0, 0, 1, 2, 3]);
        std::fs::write(&path, &bytes).expect("write");

        let done = add_summary(&path).expect("summary");
        assert_eq!(
            done,
            Summarized::Rewritten {
                messages: 3,
                torn: true
            }
        );
        let bytes = std::fs::read(&path).expect("read");
        let summary = mcap::Summary::read(&bytes)
            .expect("summary")
            .expect("present");
        assert_eq!(summary.stats.expect("statistics").message_count, 3);
    }
}
