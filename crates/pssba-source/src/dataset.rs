//! The dataset folder (DESIGN.md section 5): `frames/*.pcd`, `poses.txt`, optional `gt.txt`.

use crate::registry::{OpenOptions, SourceKind};
use crate::{Frame, FrameSource, Frames, Result};
use pssba_io::Dataset;
use rayon::prelude::*;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

/// The registry entry.
pub const KIND: SourceKind = SourceKind {
    name: "dataset folder",
    looks_for: "a folder with frames/*.pcd and poses.txt (TUM), optionally gt.txt",
    detect: |path| path.join(pssba_io::FRAMES_DIR).is_dir(),
    open: |path, options| Ok(Box::new(DatasetSource::open(path, options)?)),
};

/// An opened dataset folder; its frame headers are read at opening (not the points), so its
/// largest frame is known before the first frame is sent.
#[derive(Debug)]
pub struct DatasetSource {
    dataset: Arc<Dataset>,
    max_points: usize,
    /// `--point-time none`: the PCDs' `time` fields are not read.
    ignore_times: bool,
}

impl DatasetSource {
    fn open(dir: &Path, options: &OpenOptions) -> Result<Self> {
        let mut dataset = Dataset::open(dir)?;
        if let Some(poses) = &options.poses {
            let initial = pssba_io::read_tum(poses)?;
            if initial.len() != dataset.len() {
                return Err(crate::SourceError::invalid(
                    poses,
                    format!(
                        "has {} poses but {} has {} frames",
                        initial.len(),
                        dir.display(),
                        dataset.len()
                    ),
                ));
            }
            dataset.initial = initial;
        }
        let max_points = dataset.largest_frame_points()?;
        let ignore_times = options.recording.point_time == pssba_bag::msg::PointTimeChoice::Ignore;
        Ok(Self {
            dataset: Arc::new(dataset),
            max_points,
            ignore_times,
        })
    }

    fn frame(dataset: &Dataset, k: usize, ignore_times: bool) -> Result<Frame> {
        let (points, point_times_s) = if ignore_times {
            (dataset.load_frame(k)?, None)
        } else {
            dataset.load_frame_with_times(k)?
        };
        Ok(Frame {
            stamp_s: dataset.initial[k].stamp,
            points,
            world_from_lidar: dataset.initial[k].world_from_lidar,
            ground_truth: dataset.ground_truth.as_ref().map(|g| g[k].world_from_lidar),
            point_times_s,
        })
    }
}

impl FrameSource for DatasetSource {
    fn kind(&self) -> &'static str {
        KIND.name
    }

    fn describe(&self) -> String {
        self.dataset.dir.display().to_string()
    }

    fn len(&self) -> Option<usize> {
        Some(self.dataset.len())
    }

    fn max_points(&self) -> Option<usize> {
        Some(self.max_points)
    }

    fn frames_from(&self, first: usize) -> Result<Frames> {
        let dataset = Arc::clone(&self.dataset);
        let len = dataset.len();
        let ignore_times = self.ignore_times;
        Ok(Box::new(
            (first.min(len)..len).map(move |k| Self::frame(&dataset, k, ignore_times)),
        ))
    }

    /// Every frame, read in parallel.
    fn read_all(&self) -> Result<Vec<Frame>> {
        let total = self.dataset.len();
        let done = AtomicUsize::new(0);
        let step = (total / 10).max(1);
        (0..total)
            .into_par_iter()
            .map(|k| {
                let frame = Self::frame(&self.dataset, k, self.ignore_times)?;
                let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                if n.is_multiple_of(step) || n == total {
                    tracing::info!("loaded {n}/{total} frames");
                }
                Ok(frame)
            })
            .collect()
    }
}
