//! Where frames come from (kiss-icp's datasets shape): every input is a [`FrameSource`], an
//! iterator of frames with stamps and initial poses, its length and largest frame when known
//! up front, and a way to start again from frame N (a restarted stage, a rewind). One file per
//! source; [`open`] picks the source by the input's content through the [`registry`], and
//! when nothing matches it says what each source looked for.
//!
//! Adding a source: one file with a [`SourceKind`] (what it looks for, how to detect and
//! open it) and one line in [`registry::SOURCES`]. `docs/architecture.md` has the recipe.

mod dataset;
mod error;
mod kitti;
mod pssba_run;
pub mod registry;
mod ros;
mod simulated;

pub use error::SourceError;
pub use pssba_run::{RecordedRun, is_pssba_recording};
pub use registry::{InputSpec, OpenOptions, SourceKind, detect, open};
pub use simulated::{SimSpec, simulated_frames};

use nalgebra::{Isometry3, Point3};

/// Results of this crate.
pub type Result<T, E = SourceError> = std::result::Result<T, E>;

/// One frame of an input.
#[derive(Debug, Clone)]
pub struct Frame {
    /// Stamp (s).
    pub stamp_s: f64,
    /// Points in the lidar frame (m).
    pub points: Vec<Point3<f64>>,
    /// Initial pose.
    pub world_from_lidar: Isometry3<f64>,
    /// Ground truth, when known.
    pub ground_truth: Option<Isometry3<f64>>,
    /// Each point's time after `stamp_s` (s), one per point, when the input has point times
    /// (a frame's pose is the sensor's pose at its stamp).
    pub point_times_s: Option<Vec<f32>>,
}

/// Frames read one at a time.
pub type Frames = Box<dyn Iterator<Item = Result<Frame>> + Send>;

/// An opened input.
pub trait FrameSource: std::fmt::Debug + Send {
    /// Which source this is (a [`SourceKind::name`]).
    fn kind(&self) -> &'static str;

    /// What it is, for logs and summaries.
    fn describe(&self) -> String;

    /// Frames, when known up front.
    fn len(&self) -> Option<usize>;

    /// True when it is known to hold no frame.
    fn is_empty(&self) -> bool {
        self.len() == Some(0)
    }

    /// Points of the largest frame (non-finite points included), when known before the first
    /// frame: it sizes the shared-memory frames service.
    fn max_points(&self) -> Option<usize>;

    /// The frames from index `first` on; `len` still counts every frame. Frames skipped are
    /// not decoded where the source can avoid it.
    fn frames_from(&self, first: usize) -> Result<Frames>;

    /// Where the frames came from, for `pssba import`'s `meta.json`.
    fn metadata(&self) -> serde_json::Value {
        serde_json::json!({ "source": self.describe(), "kind": self.kind() })
    }

    /// Every frame, in memory (logs progress about every 10 %).
    fn read_all(&self) -> Result<Vec<Frame>> {
        let total = self.len().unwrap_or(0);
        let step = (total / 10).max(1);
        let mut frames = Vec::with_capacity(total);
        for (k, frame) in self.frames_from(0)?.enumerate() {
            frames.push(frame?);
            if (k + 1) % step == 0 || k + 1 == total {
                tracing::info!("read {}/{total} frames", k + 1);
            }
        }
        Ok(frames)
    }
}
