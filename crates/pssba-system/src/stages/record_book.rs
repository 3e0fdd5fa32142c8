//! The record stage's bookkeeping around the MCAP writer: each frame, window, LM report and the
//! end of the run is written once, in order, across the parts a restarted stage goes on in;
//! after every flush the journal records how far the part got ([`crate::resume::record_journal`]) and
//! the smooth stage is told which windows are on disk ([`RecordedAck`]), so it can forget them.

use crate::Error;
use crate::error::{Context, bail};
use crate::resume::record_journal::{Committed, RecordJournal, Restored};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;
use nalgebra::Isometry3;
use pssba_msg::{PoseSetHeader, RecordedAck, WindowResult};
use pssba_recording::{KnownFrame, McapRecorder};
use std::collections::{BTreeMap, HashSet};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// The recording being written.
pub struct Book {
    /// The part being written.
    path: PathBuf,
    recorder: McapRecorder<BufWriter<File>>,
    journal: Option<RecordJournal>,
    /// Where the part stood at its last flush.
    committed: Committed,
    /// Windows recorded: the next one expected.
    windows: u64,
    end_of_run: bool,
    solves: HashSet<u64>,
    /// Results not recorded yet, by window: windows are recorded in order, each once all its
    /// frames are (after a restart, a window sent again may come after a later one, and the
    /// frames after a rewind).
    waiting: BTreeMap<u64, WindowResult>,
    /// The end of the run, once it came and until every window before it is recorded.
    end_pending: Option<EndOfRun>,
    acks: Publisher<ipc::Service, RecordedAck, ()>,
    acked: Option<(u64, bool)>,
}

/// The smooth stage's end-of-run message.
#[derive(Debug, Clone, Copy)]
pub struct EndOfRun {
    /// Windows in the run.
    pub windows: u64,
    /// Frames the smooth stage took.
    pub frames_taken: u64,
    /// Frames it dropped (live input, policy `drop`).
    pub frames_dropped: u64,
}

impl std::fmt::Debug for Book {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Book")
            .field("path", &self.path)
            .field("committed", &self.committed)
            .field("windows", &self.windows)
            .finish_non_exhaustive()
    }
}

impl Book {
    /// Starts the recording: part 1 on a first start; after a restart, the part the crash cut
    /// is ended at its last flush ([`pssba_recording::end_cut_file`]) and a new part begins.
    pub fn open(
        out: &Path,
        journal: Option<RecordJournal>,
        restored: Option<Restored>,
        acks: Publisher<ipc::Service, RecordedAck, ()>,
    ) -> crate::Result<Self> {
        let restored = restored.unwrap_or_default();
        let mut committed = restored.committed;
        let part = if committed.clean_len == 0 {
            // Nothing of that part was committed: it is written again.
            committed.part.max(1)
        } else {
            let cut = pssba_recording::part_path(out, committed.part);
            let len = std::fs::metadata(&cut)
                .with_context(|| format!("reading the length of {}", cut.display()))?
                .len();
            if len < committed.clean_len {
                bail!(
                    Data,
                    "{} has {len} bytes; its last flush was at {}",
                    cut.display(),
                    committed.clean_len
                );
            }
            pssba_recording::end_cut_file(&cut, committed.clean_len)?;
            tracing::warn!(
                "restarted: ended {} after its {} bytes up to the last flush ({} frames, {} \
                 windows recorded so far)",
                cut.display(),
                committed.clean_len,
                restored.frames.len(),
                committed.windows
            );
            committed.part + 1
        };
        let path = pssba_recording::part_path(out, part);
        let file = File::create(&path).with_context(|| format!("creating {}", path.display()))?;
        let recorder = McapRecorder::resume(BufWriter::new(file), restored.frames)?;
        committed = Committed {
            part,
            clean_len: 0,
            ..committed
        };
        Ok(Self {
            path,
            recorder,
            journal,
            windows: committed.windows,
            end_of_run: committed.end_of_run,
            committed,
            solves: restored.solves,
            waiting: BTreeMap::new(),
            end_pending: None,
            acks,
            acked: None,
        })
    }

    /// The part being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Frames recorded, in every part.
    pub fn frames(&self) -> u64 {
        self.recorder.frames() as u64
    }

    /// Windows recorded, in every part.
    pub fn windows(&self) -> u64 {
        self.windows
    }

    /// True once the end of the run is recorded (all windows before it are).
    pub fn run_ended(&self) -> bool {
        self.end_of_run
    }

    /// Records a frame (its sequence is [`Self::frames`]) with its points' times, if any.
    pub fn frame(
        &mut self,
        stamp_s: f64,
        points: &[[f32; 3]],
        times_s: Option<&[f32]>,
        initial: Isometry3<f64>,
        ground_truth: Option<Isometry3<f64>>,
    ) -> crate::Result<()> {
        let frame = KnownFrame {
            stamp_s,
            initial,
            ground_truth,
            optimized: None,
        };
        self.recorder.add_frame(frame, points, times_s)?;
        if let Some(journal) = &mut self.journal {
            journal.frame(&frame);
        }
        self.record_waiting()
    }

    /// Records a window once (a window already recorded or waiting, sent again, is skipped),
    /// in window order, as soon as all its frames are recorded.
    pub fn window(&mut self, result: WindowResult) -> crate::Result<()> {
        if result.window < self.windows || self.waiting.contains_key(&result.window) {
            tracing::debug!(window = result.window, "skipped a window recorded already");
            return Ok(());
        }
        self.waiting.insert(result.window, result);
        self.record_waiting()
    }

    /// Records the end of the run once every window before it is.
    pub fn end_of_run(&mut self, end: EndOfRun) -> crate::Result<()> {
        if !self.end_of_run {
            self.end_pending = Some(end);
        }
        self.record_waiting()
    }

    /// Records an LM report once (a restarted adjust stage may answer a block twice).
    pub fn solve(&mut self, header: &PoseSetHeader) -> crate::Result<()> {
        if self.solves.insert(header.block_id) {
            self.recorder.add_solve(header)?;
            if let Some(journal) = &mut self.journal {
                journal.solve(header.block_id);
            }
        }
        Ok(())
    }

    fn record_waiting(&mut self) -> crate::Result<()> {
        let frames = self.frames();
        while let Some(next) = self.waiting.first_entry() {
            let result = next.get();
            if result.window != self.windows || result.finals.iter().any(|f| f.sequence >= frames) {
                break;
            }
            let result = next.remove();
            self.recorder.add_window(&result)?;
            if let Some(journal) = &mut self.journal {
                for f in result.finals.iter().chain(&result.revised) {
                    journal.final_pose(f.sequence, &f.world_from_lidar);
                }
            }
            self.windows = result.window + 1;
        }
        if let Some(end) = self.end_pending
            && end.windows <= self.windows
        {
            self.end_pending = None;
            self.recorder
                .add_end_of_run(end.frames_taken, end.frames_dropped)?;
            self.end_of_run = true;
        }
        Ok(())
    }

    /// What the recording still waits for after the end of the run has come (`None` if
    /// nothing, or if the end has not come): a window not received, or a frame a window needs.
    pub fn waiting_for(&self) -> Option<String> {
        let end = self.end_pending?;
        match self.waiting.first_key_value() {
            Some((&window, result)) if window == self.windows => {
                let frame = result
                    .finals
                    .iter()
                    .find(|f| f.sequence >= self.frames())
                    .map_or(0, |f| f.sequence);
                Some(format!(
                    "window {window} has a final pose for frame {frame}, but only {} frames \
                     arrived",
                    self.frames()
                ))
            }
            _ => Some(format!(
                "window {} of the run's {} never arrived",
                self.windows, end.windows
            )),
        }
    }

    /// Writes everything out so the part ends on a whole record, notes that point in the
    /// journal, and tells the smooth stage which windows are on disk.
    pub fn flush(&mut self) -> crate::Result<()> {
        self.recorder.flush()?;
        let clean_len = std::fs::metadata(&self.path).map_or(self.committed.clean_len, |m| m.len());
        self.committed = Committed {
            clean_len,
            windows: self.windows,
            end_of_run: self.end_of_run,
            ..self.committed
        };
        if let Some(journal) = &mut self.journal {
            journal.commit(self.committed)?;
        }
        let now = (self.windows, self.end_of_run);
        if self.acked != Some(now) {
            self.ack(false)?;
        }
        Ok(())
    }

    /// Tells the smooth stage what is on disk; `replay` asks it to send the windows after that
    /// again (a restarted stage).
    pub fn ack(&mut self, replay: bool) -> crate::Result<()> {
        let ack = RecordedAck {
            next_window: self.windows,
            end_of_run: u32::from(self.end_of_run),
            replay: u32::from(replay),
        };
        self.acks
            .send_copy(ack)
            .map_err(Error::ipc("telling the smooth stage what is recorded"))?;
        self.acked = Some((self.windows, self.end_of_run));
        Ok(())
    }

    /// Finishes the part (summary, footer). If that fails (a full disk), the part is cut back
    /// to its last flush and ended there; the error says how far it got.
    pub fn finish(self, earlier: Option<&crate::Error>) -> crate::Result<()> {
        let frames = self.frames();
        let clean_len = self.committed.clean_len;
        let path = self.path;
        let Err(finishing) = self.recorder.finish() else {
            tracing::info!("wrote {} ({frames} frames in all parts)", path.display());
            return Ok(());
        };
        // A full disk fails the write that stopped the loop and the summary alike.
        let cause = earlier.map_or(String::new(), |error| format!("{error:#}; then "));
        let ended = match pssba_recording::end_cut_file(&path, clean_len) {
            Ok(()) => format!(
                "it is ended after its first {clean_len} bytes (the last flush) and readable \
                 up to there"
            ),
            Err(error) => format!("it could not be ended either ({error:#})"),
        };
        bail!(
            Run,
            "recording to {} failed with {frames} frames taken: {cause}finishing the file \
             failed too ({finishing:#}); {ended}",
            path.display()
        );
    }
}
