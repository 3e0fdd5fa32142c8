//! What a restarted smooth stage needs to go on where its predecessor crashed (README, "When
//! a stage dies"), kept in its progress file ([`crate::resume::progress`]).

use crate::resume::progress::ProgressFile;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use std::path::Path;

/// What a restarted smooth stage needs, stored after every published window: its incarnation
/// (message ids of each incarnation start at `incarnation << 40`, so an answer to a dead
/// incarnation's block never matches a new block), the windows published, the frames they
/// made final, and the final poses of the last `W - S` of those, which anchor the next
/// window. A restarted stage asks the ingest stage for the frames from the first anchor on
/// again ([`crate::stages::intake`]) and resumes the sliding windows with the anchors
/// ([`pssba_core::SlidingWindows::resume`]): the next windows are the ones the crashed stage would have
/// run, with the same results.
#[derive(Debug)]
pub struct SmoothProgress {
    file: Option<ProgressFile>,
    /// 0 for the first start, then one more for each restart.
    pub incarnation: u64,
}

/// Where a restarted smooth stage goes on.
#[derive(Debug, Clone, PartialEq)]
pub struct Resume {
    /// Windows published.
    pub windows_done: u64,
    /// Frames they made final.
    pub frames_final: u64,
    /// Final poses of frames `frames_final - anchors.len() .. frames_final`.
    pub anchors: Vec<Isometry3<f64>>,
}

impl Resume {
    /// The first frame the restarted stage needs (the first anchor).
    pub fn first_frame(&self) -> u64 {
        self.frames_final - self.anchors.len() as u64
    }

    fn words(&self, incarnation: u64) -> Vec<u64> {
        let mut words = vec![
            incarnation,
            self.windows_done,
            self.frames_final,
            self.anchors.len() as u64,
        ];
        for pose in &self.anchors {
            let (t, q) = (pose.translation.vector, pose.rotation.quaternion());
            words.extend([t.x, t.y, t.z, q.i, q.j, q.k, q.w].map(f64::to_bits));
        }
        words
    }

    fn from_words(words: &[u64]) -> crate::Result<(u64, Self)> {
        let bad = || {
            crate::Error::Data(format!(
                "the smooth progress file is damaged ({} words)",
                words.len()
            ))
        };
        let [incarnation, windows_done, frames_final, count] = *words.get(..4).ok_or_else(bad)?
        else {
            return Err(bad());
        };
        let poses = words.get(4..).ok_or_else(bad)?;
        if poses.len() as u64 != 7 * count || count > frames_final {
            return Err(bad());
        }
        let anchors = poses
            .chunks_exact(7)
            .map(|w| {
                let v = w.iter().map(|&b| f64::from_bits(b)).collect::<Vec<_>>();
                Isometry3::from_parts(
                    Translation3::new(v[0], v[1], v[2]),
                    // Unchecked: the stored quaternion is restored bit for bit (normalising again could
                    // change its last bits, and the next window would start elsewhere).
                    UnitQuaternion::new_unchecked(Quaternion::new(v[6], v[3], v[4], v[5])),
                )
            })
            .collect();
        let resume = Self {
            windows_done,
            frames_final,
            anchors,
        };
        Ok((incarnation, resume))
    }
}

impl SmoothProgress {
    /// Opens the file; returns the progress and, on a restart, where the stream goes on.
    pub fn open(path: Option<&Path>) -> crate::Result<(Self, Option<Resume>)> {
        let Some(path) = path else {
            return Ok((
                Self {
                    file: None,
                    incarnation: 0,
                },
                None,
            ));
        };
        let (file, stored) = ProgressFile::open(path, pssba_msg::Stage::Smooth.name())?;
        let (incarnation, resume) = match stored {
            Some(words) => {
                let (last, resume) = Resume::from_words(&words)?;
                (last + 1, Some(resume))
            }
            None => (0, None),
        };
        let progress = Self {
            file: Some(file),
            incarnation,
        };
        let start = resume.clone().unwrap_or(Resume {
            windows_done: 0,
            frames_final: 0,
            anchors: Vec::new(),
        });
        progress.store(&start)?;
        Ok((progress, resume))
    }

    /// The first message id of this incarnation.
    pub fn first_message_id(&self) -> u64 {
        self.incarnation << 40
    }

    /// Stores where a successor would go on.
    pub fn store(&self, resume: &Resume) -> crate::Result<()> {
        match &self.file {
            Some(file) => file.store(&resume.words(self.incarnation)),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn a_restart_reads_back_the_windows_frames_and_anchors_and_counts_incarnations() {
        let dir = tempfile::tempdir().expect("tmp");
        let path = dir.path().join("run.smooth-progress");
        let (first, resume) = SmoothProgress::open(Some(&path)).expect("new");
        assert_eq!((first.incarnation, resume), (0, None));
        let anchor = Isometry3::new(Vector3::new(1.0, -2.0, 3.5), Vector3::new(0.1, 0.2, -0.3));
        let stored = Resume {
            windows_done: 3,
            frames_final: 260,
            anchors: vec![anchor, Isometry3::identity()],
        };
        first.store(&stored).expect("store");
        let (second, resume) = SmoothProgress::open(Some(&path)).expect("reopen");
        assert_eq!(second.incarnation, 1);
        assert_ne!(second.first_message_id(), first.first_message_id());
        let resume = resume.expect("a restart");
        assert_eq!((resume.windows_done, resume.frames_final), (3, 260));
        assert_eq!(resume.first_frame(), 258);
        assert!((resume.anchors[0].to_homogeneous() - anchor.to_homogeneous()).norm() < 1e-15);
        let (third, _) = SmoothProgress::open(Some(&path)).expect("again");
        assert_eq!(third.incarnation, 2);
    }
}
