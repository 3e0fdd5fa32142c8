//! What a restarted record stage needs to go on in a new part of its recording (README, "When
//! a stage dies"), kept in two files beside the output:
//! - a journal, `<out>.record-journal`: append-only, one fixed-size entry per frame recorded
//!   (stamp, initial pose, ground truth), per final pose and per LM report, so the new part's
//!   trajectories go on from the whole run and nothing is recorded twice;
//! - a progress file ([`ProgressFile`]), `<out>.record-progress`, rewritten after each flush
//!   of the MCAP file: the part being written, its length up to the last flush (it ends on a
//!   whole record there), the journal's length, and how many frames and windows those hold.
//!
//! The progress file is written last, so it always names a consistent point: whatever the
//! MCAP part or the journal hold beyond it is cut off on restart and sent again (the ingest
//! stage rewinds, the smooth stage replays the windows it kept).

use crate::error::{Context, bail};
use crate::resume::progress::ProgressFile;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use pssba_recording::KnownFrame;
use std::collections::HashSet;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

/// Words per journal entry.
const ENTRY_WORDS: usize = 18;
const ENTRY_BYTES: u64 = (ENTRY_WORDS * 8) as u64;

mod tag {
    pub const FRAME: u64 = 1;
    pub const FINAL: u64 = 2;
    pub const SOLVE: u64 = 3;
}

/// Words of the progress file.
const PROGRESS_WORDS: usize = 6;

/// Where a recording stood at its last flush.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Committed {
    /// Part being written (1, 2, ...; [`pssba_recording::part_path`]).
    pub part: u64,
    /// Its length at the last flush (bytes; it ends on a whole record there).
    pub clean_len: u64,
    /// Windows recorded (0..windows).
    pub windows: u64,
    /// True once the end-of-run marker is recorded.
    pub end_of_run: bool,
}

/// What the stage's predecessors recorded, read back on restart.
#[derive(Debug, Clone, Default)]
pub struct Restored {
    /// Where the last predecessor stood.
    pub committed: Committed,
    /// Every frame recorded, with its final pose if its window was recorded.
    pub frames: Vec<KnownFrame>,
    /// LM reports recorded (by block id).
    pub solves: HashSet<u64>,
}

/// The open journal and progress file.
#[derive(Debug)]
pub struct RecordJournal {
    progress: ProgressFile,
    journal: std::fs::File,
    journal_path: PathBuf,
    /// Bytes of the journal written.
    journal_len: u64,
    /// Entries since the last commit.
    pending: Vec<u8>,
    frames: u64,
}

/// The journal beside a progress file.
pub fn journal_path(progress: &Path) -> PathBuf {
    progress.with_extension("record-journal")
}

impl RecordJournal {
    /// Opens the files; returns what earlier incarnations of the stage recorded, or `None` on
    /// the stage's first start (no progress stored yet).
    pub fn open(progress_path: &Path) -> crate::Result<(Self, Option<Restored>)> {
        let (progress, stored) =
            ProgressFile::open(progress_path, pssba_msg::Stage::Record.name())?;
        let journal_path = journal_path(progress_path);
        let journal = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&journal_path)
            .with_context(|| format!("opening the record journal {}", journal_path.display()))?;
        let mut this = Self {
            progress,
            journal,
            journal_path,
            journal_len: 0,
            pending: Vec::new(),
            frames: 0,
        };
        let Some(words) = stored else {
            this.journal.set_len(0)?;
            return Ok((this, None));
        };
        let restored = this.restore(&words).with_context(|| {
            format!(
                "restoring the record stage's state from {} and {}",
                progress_path.display(),
                this.journal_path.display()
            )
        })?;
        Ok((this, Some(restored)))
    }

    fn restore(&mut self, words: &[u64]) -> crate::Result<Restored> {
        let &[part, clean_len, journal_len, frames, windows, end_of_run] = words else {
            bail!(
                Data,
                "the progress file holds {} words, not {PROGRESS_WORDS}",
                words.len()
            );
        };
        if !journal_len.is_multiple_of(ENTRY_BYTES) {
            bail!(
                Data,
                "a journal length of {journal_len} bytes is not whole entries"
            );
        }
        let on_disk = self.journal.metadata()?.len();
        if on_disk < journal_len {
            bail!(
                Data,
                "the journal has {on_disk} bytes; the progress file counts {journal_len}"
            );
        }
        let mut bytes = vec![0u8; journal_len as usize];
        self.journal.read_exact_at(&mut bytes, 0)?;
        // What was written after the last commit is recorded again.
        self.journal.set_len(journal_len)?;
        self.journal_len = journal_len;
        let mut restored = Restored {
            committed: Committed {
                part,
                clean_len,
                windows,
                end_of_run: end_of_run != 0,
            },
            ..Restored::default()
        };
        for (k, entry) in bytes.chunks_exact(ENTRY_BYTES as usize).enumerate() {
            let w: Vec<u64> = entry
                .chunks_exact(8)
                .map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")))
                .collect();
            let f = |i: usize| f64::from_bits(w[i]);
            let sequence = w[1];
            match w[0] {
                tag::FRAME => {
                    if sequence != restored.frames.len() as u64 {
                        bail!(
                            Data,
                            "entry {k}: frame {sequence} after {} frames",
                            restored.frames.len()
                        );
                    }
                    restored.frames.push(KnownFrame {
                        stamp_s: f(2),
                        initial: isometry(&w[3..10]),
                        ground_truth: (w[10] != 0).then(|| isometry(&w[11..18])),
                        optimized: None,
                    });
                }
                tag::FINAL => {
                    let Some(frame) = restored.frames.get_mut(sequence as usize) else {
                        bail!(
                            Data,
                            "entry {k}: a final pose of frame {sequence}, not recorded"
                        );
                    };
                    frame.optimized = Some(isometry(&w[2..9]));
                }
                tag::SOLVE => {
                    restored.solves.insert(sequence);
                }
                other => bail!(Data, "entry {k}: unknown kind {other}"),
            }
        }
        if restored.frames.len() as u64 != frames {
            bail!(
                Data,
                "the journal holds {} frames; the progress file counts {frames}",
                restored.frames.len()
            );
        }
        self.frames = frames;
        Ok(restored)
    }

    fn push(&mut self, words: [u64; ENTRY_WORDS]) {
        self.pending
            .extend(words.iter().flat_map(|w| w.to_le_bytes()));
    }

    /// Notes a recorded frame (its sequence is the count of frames before it).
    pub fn frame(&mut self, frame: &KnownFrame) {
        let mut w = [0u64; ENTRY_WORDS];
        w[0] = tag::FRAME;
        w[1] = self.frames;
        w[2] = frame.stamp_s.to_bits();
        w[3..10].copy_from_slice(&pose_words(&frame.initial));
        if let Some(truth) = &frame.ground_truth {
            w[10] = 1;
            w[11..18].copy_from_slice(&pose_words(truth));
        }
        self.frames += 1;
        self.push(w);
    }

    /// Notes a recorded final pose.
    pub fn final_pose(&mut self, sequence: u64, world_from_lidar: &Isometry3<f64>) {
        let mut w = [0u64; ENTRY_WORDS];
        w[0] = tag::FINAL;
        w[1] = sequence;
        w[2..9].copy_from_slice(&pose_words(world_from_lidar));
        self.push(w);
    }

    /// Notes a recorded LM report.
    pub fn solve(&mut self, block_id: u64) {
        let mut w = [0u64; ENTRY_WORDS];
        w[0] = tag::SOLVE;
        w[1] = block_id;
        self.push(w);
    }

    /// After a flush of the MCAP part: appends the entries noted since the last commit, then
    /// records `at` as the point a restart goes on from.
    pub fn commit(&mut self, at: Committed) -> crate::Result<()> {
        if !self.pending.is_empty() {
            self.journal
                .write_all_at(&self.pending, self.journal_len)
                .with_context(|| format!("appending to {}", self.journal_path.display()))?;
            self.journal_len += self.pending.len() as u64;
            self.pending.clear();
        }
        self.progress.store(&[
            at.part,
            at.clean_len,
            self.journal_len,
            self.frames,
            at.windows,
            u64::from(at.end_of_run),
        ])
    }
}

/// A pose as 7 words (translation, then quaternion i, j, k, w), bit for bit.
fn pose_words(pose: &Isometry3<f64>) -> [u64; 7] {
    let t = pose.translation.vector;
    let q = pose.rotation.quaternion().coords;
    [t.x, t.y, t.z, q.x, q.y, q.z, q.w].map(f64::to_bits)
}

/// The inverse of [`pose_words`]; the quaternion is taken as stored (not re-normalised), so
/// the trajectories go on bit for bit.
fn isometry(words: &[u64]) -> Isometry3<f64> {
    let v: Vec<f64> = words.iter().map(|&w| f64::from_bits(w)).collect();
    Isometry3::from_parts(
        Translation3::new(v[0], v[1], v[2]),
        UnitQuaternion::new_unchecked(Quaternion::new(v[6], v[3], v[4], v[5])),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn frame(k: u64, truth: bool) -> KnownFrame {
        let pose = Isometry3::new(
            Vector3::new(k as f64, 0.1, -0.3),
            Vector3::new(0.01 * k as f64, 0.2, 0.3),
        );
        KnownFrame {
            stamp_s: 0.1 * k as f64,
            initial: pose,
            ground_truth: truth.then(|| pose.inverse()),
            optimized: None,
        }
    }

    #[test]
    fn a_restart_gets_back_exactly_what_was_committed_and_not_what_came_after() {
        let dir = tempfile::tempdir().expect("tmp");
        let path = dir.path().join("run.record-progress");
        let (mut journal, restored) = RecordJournal::open(&path).expect("new");
        assert!(restored.is_none());
        let frames: Vec<KnownFrame> = (0..3).map(|k| frame(k, k != 1)).collect();
        for f in &frames {
            journal.frame(f);
        }
        let optimized = frames[1].initial * frames[2].initial;
        journal.final_pose(1, &optimized);
        journal.solve(77);
        let at = Committed {
            part: 2,
            clean_len: 1234,
            windows: 1,
            end_of_run: false,
        };
        journal.commit(at).expect("commit");
        // Noted but never committed (the crash came before the flush): not restored.
        journal.frame(&frame(3, true));
        journal.final_pose(0, &optimized);
        drop(journal);

        let (mut journal, restored) = RecordJournal::open(&path).expect("reopen");
        let restored = restored.expect("state");
        assert_eq!(restored.committed, at);
        assert_eq!(restored.frames.len(), 3);
        assert_eq!(restored.frames[0], frames[0]);
        assert_eq!(restored.frames[1].ground_truth, None);
        assert_eq!(restored.frames[1].optimized, Some(optimized));
        assert_eq!(restored.frames[2].optimized, None);
        assert!(restored.solves.contains(&77));
        // It goes on numbering after the restored frames.
        journal.frame(&frame(3, false));
        journal
            .commit(Committed { windows: 2, ..at })
            .expect("commit");
        drop(journal);
        let (_, restored) = RecordJournal::open(&path).expect("reopen");
        assert_eq!(restored.expect("state").frames.len(), 4);
    }

    #[test]
    fn a_journal_shorter_than_its_progress_file_says_is_a_clear_error() {
        let dir = tempfile::tempdir().expect("tmp");
        let path = dir.path().join("run.record-progress");
        let (mut journal, _) = RecordJournal::open(&path).expect("new");
        journal.frame(&frame(0, true));
        journal.commit(Committed::default()).expect("commit");
        drop(journal);
        std::fs::write(journal_path(&path), [0u8; 10]).expect("cut");
        let error = RecordJournal::open(&path).expect_err("short journal");
        let text = format!("{error:#}");
        assert!(
            text.contains("record-journal") && text.contains("10 bytes"),
            "{text}"
        );
    }
}
