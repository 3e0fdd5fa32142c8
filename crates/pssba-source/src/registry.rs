//! The one table of input sources, and how an input is matched to one: by content, in table
//! order (a `pssba run` recording is an MCAP file too, so it comes before the MCAP reader).

use crate::{FrameSource, Result, SimSpec, SourceError};
use std::path::{Path, PathBuf};

/// How an input is read, beyond its path: the recording flags and config keys, and a pose
/// file for inputs that keep poses apart from their frames (KITTI).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OpenOptions {
    /// Topics, extrinsic, pose gap and the part to read of a robot recording (ignored by
    /// the other sources).
    pub recording: pssba_bag::RecordingOptions,
    /// Initial poses from this file instead of the input's own (`--poses`; KITTI).
    pub poses: Option<PathBuf>,
}

/// One kind of input source.
#[derive(Clone, Copy)]
pub struct SourceKind {
    /// Its name ("dataset folder").
    pub name: &'static str,
    /// What it looks for in an input, said when nothing matches.
    pub looks_for: &'static str,
    /// True when `path` is this kind of input (a cheap look at its content).
    pub detect: fn(&Path) -> bool,
    /// Opens it.
    pub open: fn(&Path, &OpenOptions) -> Result<Box<dyn FrameSource>>,
}

impl std::fmt::Debug for SourceKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SourceKind")
            .field("name", &self.name)
            .finish_non_exhaustive()
    }
}

/// Every input source, in the order they are tried.
pub const SOURCES: &[SourceKind] = &[
    crate::dataset::KIND,
    crate::kitti::KIND,
    crate::pssba_run::KIND,
    crate::ros::ROS1_BAG,
    crate::ros::ROSBAG2_FOLDER,
    crate::ros::MCAP_FILE,
    crate::ros::SQLITE_FILE,
];

/// The source that reads `path`; the error says what each source looked for.
pub fn detect(path: &Path) -> Result<&'static SourceKind> {
    if !path.exists() {
        return Err(SourceError::NotFound {
            path: path.to_path_buf(),
        });
    }
    SOURCES
        .iter()
        .find(|kind| (kind.detect)(path))
        .ok_or_else(|| SourceError::NotRecognised {
            path: path.to_path_buf(),
            looked_for: SOURCES
                .iter()
                .map(|k| format!("  - {}: {}", k.name, k.looks_for))
                .collect::<Vec<_>>()
                .join("\n"),
        })
}

/// Opens `path` with the source that recognises it.
pub fn open(path: &Path, options: &OpenOptions) -> Result<Box<dyn FrameSource>> {
    let kind = detect(path)?;
    tracing::debug!("{}: read as a {}", path.display(), kind.name);
    (kind.open)(path, options)
}

/// An input as one value: what the command line named, carried to the ingest stage.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, rename_all = "snake_case")]
// Parsed once per run: the size of the recording options does not matter.
#[allow(clippy::large_enum_variant)]
pub enum InputSpec {
    /// A file or folder, read by the source that recognises it.
    Path {
        /// The input.
        path: PathBuf,
        /// How to read it.
        #[serde(default)]
        options: OpenOptions,
    },
    /// The built-in simulated scene.
    Simulated(SimSpec),
}

impl InputSpec {
    /// Opens the input.
    pub fn open(&self) -> Result<Box<dyn FrameSource>> {
        match self {
            InputSpec::Path { path, options } => open(path, options),
            InputSpec::Simulated(spec) => Ok(Box::new(crate::simulated::Simulated::new(spec)?)),
        }
    }

    /// Checks what can be checked before any process starts, without reading points.
    pub fn check(&self) -> Result<()> {
        match self {
            InputSpec::Path { path, options } => open(path, options).map(drop),
            InputSpec::Simulated(spec) => spec.check(),
        }
    }

    /// What the input is, for logs, before it is opened.
    pub fn describe(&self) -> String {
        match self {
            InputSpec::Path { path, .. } => path.display().to_string(),
            InputSpec::Simulated(spec) => spec.describe(),
        }
    }
}
