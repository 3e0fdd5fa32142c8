//! Motion within a frame (DESIGN section 8): a point fired `tau` seconds after its frame's
//! stamp left the sensor at `R(tau) = R_k Exp(tau w)`, `t(tau) = t_k + tau R_k d`: frame `k`
//! turning at a constant body rate `w` and moving at a constant velocity `d` (in its own
//! axes), both from the poses of its neighbours `k - 1` and `k + 1` (central differences).
//! De-skewing brings the point into frame `k`'s lidar coordinates at the stamp:
//! `p' = R_k^T (R(tau) p + t(tau) - t_k) = Exp(tau w) p + tau d`.
//!
//! Why central differences, not DESIGN's model A (frame `k` to `k + 1`): the de-skew is
//! refreshed from the current poses between scales, not differentiated, so a pose error
//! feeds back through it. With model A an error that alternates from frame to frame comes
//! back at full size after each scale (frame `k`'s points are skewed by
//! `tau / dt (e_{k+1} - e_k)`, and the frame follows them); the central difference cancels
//! it and shrinks every other pattern by at least half per scale. A quadratic through the
//! three frames (which would follow a helmet's yaw acceleration) amplifies the noise of
//! unadjusted poses and ended 10x worse. Measured in BENCHMARK.md (issue 39).

//! Stamp convention: a frame's pose (input and output) is the sensor's pose at the frame's
//! stamp; point times are relative to that stamp (negative for points before it).

use crate::error::CoreError;
use crate::geometry::{Pose, exp_so3, log_so3};
use crate::parallel::{Parallelism, map_indexed};
use nalgebra::{Isometry3, Point3, Vector3};

/// Per-point times of a window's frames.
#[derive(Debug, Clone, Copy)]
pub struct PointTimes<'a> {
    /// Each frame's stamp (s): the instant its pose describes. Any origin; only differences
    /// between neighbouring frames are used.
    pub stamps_s: &'a [f64],
    /// Each point's time after its frame's stamp (s), one per point of the frame, in the
    /// same order.
    pub offsets_s: &'a [Vec<f32>],
}

/// [`PointTimes`] owned: the stamps and per-point times of frames handed over.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameTimes {
    /// Each frame's stamp (s).
    pub stamps_s: Vec<f64>,
    /// Each point's time after its frame's stamp (s).
    pub offsets_s: Vec<Vec<f32>>,
}

impl FrameTimes {
    /// Borrowed.
    pub fn view(&self) -> PointTimes<'_> {
        PointTimes {
            stamps_s: &self.stamps_s,
            offsets_s: &self.offsets_s,
        }
    }
}

impl PointTimes<'_> {
    /// True when some point was taken away from its frame's stamp.
    pub fn any_moving(&self) -> bool {
        self.offsets_s.iter().flatten().any(|&t| t != 0.0)
    }

    /// The times of the points `keep` keeps, frame by frame.
    pub(crate) fn filtered(
        &self,
        frames: &[Vec<Point3<f64>>],
        keep: impl Fn(&Point3<f64>) -> bool,
    ) -> Vec<Vec<f32>> {
        frames
            .iter()
            .zip(self.offsets_s)
            .map(|(f, t)| {
                f.iter()
                    .zip(t)
                    .filter(|(p, _)| keep(p))
                    .map(|(_, &t)| t)
                    .collect()
            })
            .collect()
    }

    /// One stamp and one time per point of every frame; finite stamps and times.
    pub(crate) fn check(&self, point_counts: &[usize]) -> Result<(), CoreError> {
        if self.stamps_s.len() != point_counts.len() || self.offsets_s.len() != point_counts.len() {
            return Err(CoreError::PointTimesFrames {
                frames: point_counts.len(),
                stamps: self.stamps_s.len(),
                time_lists: self.offsets_s.len(),
            });
        }
        for (frame, (&points, offsets)) in point_counts.iter().zip(self.offsets_s).enumerate() {
            if offsets.len() != points {
                return Err(CoreError::PointTimesCount {
                    frame,
                    points,
                    times: offsets.len(),
                });
            }
            if !self.stamps_s[frame].is_finite() || offsets.iter().any(|t| !t.is_finite()) {
                return Err(CoreError::NonFinitePointTime { frame });
            }
        }
        Ok(())
    }
}

/// The raw points of a window's frames with their times, kept for de-skewing at each scale.
#[derive(Debug, Clone)]
pub(crate) struct FrameMotion {
    raw: Vec<Vec<Vector3<f64>>>,
    offsets_s: Vec<Vec<f32>>,
    stamps_s: Vec<f64>,
}

/// Frame `k`'s motion over one second, `(w, d)`: its body angular rate (rad/s) and its
/// velocity in its own lidar axes (m/s), so a point at `tau` de-skews to
/// `Exp(tau w) p + tau d`. Central differences over the neighbours `k - 1` and `k + 1` where
/// both exist, one-sided at the window's ends; zero when the window has one frame or the
/// neighbours share the stamp.
fn motion_per_s(poses: &[Pose], stamps_s: &[f64], k: usize) -> (Vector3<f64>, Vector3<f64>) {
    let n = poses.len();
    let (before, after) = (k.saturating_sub(1), (k + 1).min(n.saturating_sub(1)));
    let dt_s = stamps_s[after] - stamps_s[before];
    if after == before || dt_s == 0.0 || !dt_s.is_finite() {
        return (Vector3::zeros(), Vector3::zeros());
    }
    let (a, b, here) = (&poses[before], &poses[after], &poses[k]);
    // Each step's rotation in its own start frame; frames a step apart differ little, so
    // their sum is frame k's rotation over the span to first order.
    let rotation_steps = log_so3(&(a.rotation.transpose() * here.rotation))
        + log_so3(&(here.rotation.transpose() * b.rotation));
    let w = rotation_steps / dt_s;
    let d = here.rotation.transpose() * (b.translation - a.translation) / dt_s;
    (w, d)
}

impl FrameMotion {
    /// Keeps the points and their times (one per point, checked by the caller).
    pub(crate) fn new(
        raw: Vec<Vec<Vector3<f64>>>,
        offsets_s: Vec<Vec<f32>>,
        stamps_s: Vec<f64>,
    ) -> Self {
        Self {
            raw,
            offsets_s,
            stamps_s,
        }
    }

    /// Every frame's points brought to its stamp along `poses` (central differences).
    pub(crate) fn deskewed(
        &self,
        poses: &[Pose],
        parallelism: Parallelism,
    ) -> Vec<Vec<Vector3<f64>>> {
        map_indexed(self.raw.len(), parallelism, |k| {
            let (w, d) = motion_per_s(poses, &self.stamps_s, k);
            self.raw[k]
                .iter()
                .zip(&self.offsets_s[k])
                .map(|(p, &tau)| {
                    let tau = f64::from(tau);
                    exp_so3(&(tau * w)) * p + tau * d
                })
                .collect()
        })
    }

    /// Points in each frame.
    pub(crate) fn point_counts(&self) -> Vec<usize> {
        self.raw.iter().map(Vec::len).collect()
    }

    /// Empties frame `k` (a sparse frame left out).
    pub(crate) fn clear_frame(&mut self, k: usize) {
        self.raw[k].clear();
        self.offsets_s[k].clear();
    }
}

/// Frame `k`'s points (times `offsets_s`) brought to its stamp, its motion from `poses` and
/// `stamps_s` of frames around it (`k` indexes into them; see [`FrameMotion::deskewed`]).
pub(crate) fn deskew_frame(
    points: &[Point3<f64>],
    offsets_s: &[f32],
    poses: &[Pose],
    stamps_s: &[f64],
    k: usize,
) -> Vec<Point3<f64>> {
    let (w, d) = motion_per_s(poses, stamps_s, k);
    points
        .iter()
        .zip(offsets_s)
        .map(|(p, &tau)| {
            let tau = f64::from(tau);
            Point3::from(exp_so3(&(tau * w)) * p.coords + tau * d)
        })
        .collect()
}

/// Every frame's points brought to its stamp along `world_from_lidar` (central differences): de-skew
/// from given poses (e.g. odometry), once. The adjustment itself de-skews again at every
/// scale when its [`crate::Window`] carries the times.
pub fn deskew_frames(
    frames: &[Vec<Point3<f64>>],
    times: PointTimes<'_>,
    world_from_lidar: &[Isometry3<f64>],
) -> Result<Vec<Vec<Point3<f64>>>, CoreError> {
    if frames.len() != world_from_lidar.len() {
        return Err(CoreError::CountMismatch {
            frames: frames.len(),
            poses: world_from_lidar.len(),
        });
    }
    let counts: Vec<usize> = frames.iter().map(Vec::len).collect();
    times.check(&counts)?;
    let poses: Vec<Pose> = world_from_lidar.iter().map(Pose::from_isometry).collect();
    if let Some(frame) = poses.iter().position(|p| !p.is_finite()) {
        return Err(CoreError::NonFinitePose { frame });
    }
    let motion = FrameMotion::new(
        frames
            .iter()
            .map(|f| f.iter().map(|p| p.coords).collect())
            .collect(),
        times.offsets_s.to_vec(),
        times.stamps_s.to_vec(),
    );
    Ok(motion
        .deskewed(&poses, Parallelism::Serial)
        .into_iter()
        .map(|f| f.into_iter().map(Point3::from).collect())
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn pose(x: f64, yaw: f64) -> Pose {
        Pose::from_isometry(&Isometry3::from_parts(
            Translation3::new(x, 0.5 * x, 0.1),
            UnitQuaternion::from_euler_angles(0.02, -0.01, yaw),
        ))
    }

    /// On a track of constant body rate and constant velocity, a world point seen at time
    /// tau lands, de-skewed, where frame k's pose at its stamp sees it (every frame: the
    /// central and the one-sided differences are both exact there).
    #[test]
    fn deskewed_points_match_the_continuous_motion() {
        let w_body = Vector3::new(0.1, -0.05, 1.2);
        let v_world = Vector3::new(3.0, -1.0, 0.2);
        let start = pose(0.4, 0.3);
        let at = |t: f64| Pose {
            rotation: start.rotation * exp_so3(&(t * w_body)),
            translation: start.translation + t * v_world,
        };
        let stamps_s = vec![10.0, 10.1, 10.2, 10.3];
        let poses: Vec<Pose> = stamps_s.iter().map(|&s| at(s - 10.0)).collect();
        let world = Vector3::new(4.0, -2.0, 1.5);
        let taus = [0.0f32, 0.03, -0.02, 0.099];
        let mut raw = Vec::new();
        let mut offsets = Vec::new();
        for &stamp in &stamps_s {
            let frame: Vec<Vector3<f64>> = taus
                .iter()
                .map(|&tau| {
                    let p = at(stamp - 10.0 + f64::from(tau));
                    p.rotation.transpose() * (world - p.translation)
                })
                .collect();
            raw.push(frame);
            offsets.push(taus.to_vec());
        }
        let motion = FrameMotion::new(raw, offsets, stamps_s);
        let out = motion.deskewed(&poses, Parallelism::Serial);
        for (k, frame) in out.iter().enumerate() {
            for p in frame {
                let back = poses[k].apply(p);
                assert!((back - world).norm() < 1e-5, "frame {k}: {back:?}");
            }
        }
    }

    #[test]
    fn zero_times_leave_points_unchanged() {
        let poses = vec![pose(0.0, 0.0), pose(1.0, 0.3)];
        let raw = vec![
            vec![Vector3::new(1.0, 2.0, 3.0)],
            vec![Vector3::new(-1.0, 0.5, 2.0)],
        ];
        let motion = FrameMotion::new(raw.clone(), vec![vec![0.0], vec![0.0]], vec![0.0, 0.1]);
        assert_eq!(motion.deskewed(&poses, Parallelism::Serial), raw);
    }

    #[test]
    fn bad_times_are_refused() {
        let offsets = vec![vec![0.0f32, f32::NAN]];
        let times = PointTimes {
            stamps_s: &[0.0],
            offsets_s: &offsets,
        };
        assert_eq!(
            times.check(&[2]),
            Err(CoreError::NonFinitePointTime { frame: 0 })
        );
        assert!(matches!(
            times.check(&[3]),
            Err(CoreError::PointTimesCount {
                frame: 0,
                points: 3,
                times: 2
            })
        ));
        assert!(matches!(
            times.check(&[2, 2]),
            Err(CoreError::PointTimesFrames { .. })
        ));
    }
}
