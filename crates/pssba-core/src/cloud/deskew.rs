//! Motion within a frame (DESIGN section 8). A point fired `tau` seconds after its frame's
//! stamp left the sensor at `T(tau) = T_k Exp(xi(tau))`, with the body twist integrated to
//! second order, `xi(tau) = tau xi_k + tau^2 / 2 a_k`. De-skewing brings the point into frame
//! `k`'s lidar coordinates at the stamp: `p' = T_k^-1 T(tau) p = Exp(xi(tau)) p` (SE(3)).
//!
//! - The twist of each step `j -> j+1` is `Log(T_j^-1 T_{j+1}) / dt` (SE(3) log, in `j`'s
//!   axes): exact for a screw motion, so an orbit's curving path (centripetal 2 m/s^2 at
//!   5 m/s, 10 mm over a 0.1 s frame) is followed, where a straight chord was not.
//! - The rate at stamp `k`, `xi_k`, is the mean of the steps either side (central
//!   difference); one-sided at the window's ends; zero with one frame.
//! - The change of rate `a_k` is the difference of the neighbouring stamps' central rates,
//!   `(xi_{k+1} - xi_k) / dt` for points after the stamp and `(xi_k - xi_{k-1}) / dt` for
//!   points before it (none at the window's first frame): it follows a helmet's yaw
//!   acceleration (7.8 rad/s^2 is 2.2 deg at the end of a 0.1 s frame when the rate is
//!   held constant).
//!
//! Why these stencils: the de-skew is refreshed from the current poses between scales, not
//! differentiated, so a pose error feeds back through it. Frame `k`'s points move by about
//! `tau` times the stencil applied to the pose errors. An error that alternates from frame to
//! frame cancels in every stencil above (central rates and differences of central rates two
//! steps apart); a one-sided step (DESIGN's model A, `k -> k+1`) brings it back at full size
//! after each scale, and a second difference through `k-1, k, k+1` doubles it (both
//! measured, BENCHMARK.md, issue 39). Per refresh this model brings back at most 0.4x of
//! any other pattern. Wider stencils that would follow the jerk too (a cubic in time), or a
//! centred change, bring back more, and ended worse on the bench (BENCHMARK.md).

//! Stamp convention: a frame's pose (input and output) is the sensor's pose at the frame's
//! stamp; point times are relative to that stamp (negative for points before it).

use crate::error::CoreError;
use crate::geometry::{Pose, exp_se3_apply, log_se3};
use crate::parallel::{Parallelism, map_indexed};
use nalgebra::{Isometry3, Point3, Vector3, Vector6};

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

/// The body twist per second `[w (rad/s); v (m/s)]` of the step from frame `j` to `j + 1`,
/// in `j`'s axes (SE(3) log); `None` past the window or when the stamps do not advance.
fn step_twist(poses: &[Pose], stamps_s: &[f64], j: usize) -> Option<Vector6<f64>> {
    let (a, b) = (poses.get(j)?, poses.get(j + 1)?);
    let dt_s = stamps_s[j + 1] - stamps_s[j];
    if dt_s <= 0.0 || !dt_s.is_finite() {
        return None;
    }
    let rotation = a.rotation.transpose() * b.rotation;
    let translation = a.rotation.transpose() * (b.translation - a.translation);
    let (phi, rho) = log_se3(&rotation, &translation);
    Some(Vector6::new(phi.x, phi.y, phi.z, rho.x, rho.y, rho.z) / dt_s)
}

/// The body twist per second at stamp `k`: the mean of the steps either side (one-sided at
/// the window's ends, zero when neither exists).
fn central_twist(poses: &[Pose], stamps_s: &[f64], k: usize) -> Vector6<f64> {
    let before = k
        .checked_sub(1)
        .and_then(|j| step_twist(poses, stamps_s, j));
    match (before, step_twist(poses, stamps_s, k)) {
        (Some(a), Some(b)) => 0.5 * (a + b),
        (Some(one), None) | (None, Some(one)) => one,
        (None, None) => Vector6::zeros(),
    }
}

/// Frame `k`'s motion around its stamp: the twist per second there and its change per
/// second towards the previous and the next stamp (see the module notes).
#[derive(Debug, Clone, Copy)]
struct FrameSkew {
    rate: Vector6<f64>,
    change_before: Vector6<f64>,
    change_after: Vector6<f64>,
}

impl FrameSkew {
    fn of_frame(poses: &[Pose], stamps_s: &[f64], k: usize) -> Self {
        let central = |j: usize| central_twist(poses, stamps_s, j);
        let rate = central(k);
        let change = |from: usize, to: usize| -> Vector6<f64> {
            let dt_s = stamps_s[to] - stamps_s[from];
            if dt_s <= 0.0 || !dt_s.is_finite() {
                return Vector6::zeros();
            }
            (central(to) - central(from)) / dt_s
        };
        // The first frame's rate is its one step's, already the mean rate over its own span
        // (for points after its stamp): a change would only add error there.
        let (change_before, change_after) = match (k.checked_sub(1), k + 1 < poses.len()) {
            (Some(before), true) => (change(before, k), change(k, k + 1)),
            (Some(before), false) => (change(before, k), Vector6::zeros()),
            (None, _) => (Vector6::zeros(), Vector6::zeros()),
        };
        Self {
            rate,
            change_before,
            change_after,
        }
    }

    /// The point `p`, fired `tau_s` after the stamp, in the lidar axes at the stamp.
    #[inline]
    fn apply(&self, tau_s: f32, p: &Vector3<f64>) -> Vector3<f64> {
        let tau = f64::from(tau_s);
        let change = if tau >= 0.0 {
            &self.change_after
        } else {
            &self.change_before
        };
        let xi = tau * self.rate + (0.5 * tau * tau) * change;
        exp_se3_apply(
            &xi.fixed_rows::<3>(0).into(),
            &xi.fixed_rows::<3>(3).into(),
            p,
        )
    }
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

    /// Every frame's points brought to its stamp along `poses` (see the module notes).
    pub(crate) fn deskewed(
        &self,
        poses: &[Pose],
        parallelism: Parallelism,
    ) -> Vec<Vec<Vector3<f64>>> {
        map_indexed(self.raw.len(), parallelism, |k| {
            let skew = FrameSkew::of_frame(poses, &self.stamps_s, k);
            self.raw[k]
                .iter()
                .zip(&self.offsets_s[k])
                .map(|(p, &tau)| skew.apply(tau, p))
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
    let skew = FrameSkew::of_frame(poses, stamps_s, k);
    points
        .iter()
        .zip(offsets_s)
        .map(|(p, &tau)| Point3::from(skew.apply(tau, &p.coords)))
        .collect()
}

/// Every frame's points brought to its stamp along `world_from_lidar` (see the module notes): de-skew
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

/// Frame `k`'s points (fired `offsets_s` after its stamp) brought to its stamp along a
/// trajectory (`world_from_lidar` at `stamps_s`, all frames): only frames `k - 2 ..= k + 2`
/// are read, so a long flight's frames can be de-skewed one by one in O(1) each.
pub fn deskew_frame_along(
    points: &[Point3<f64>],
    offsets_s: &[f32],
    world_from_lidar: &[Isometry3<f64>],
    stamps_s: &[f64],
    k: usize,
) -> Result<Vec<Point3<f64>>, CoreError> {
    let n = world_from_lidar.len();
    if stamps_s.len() != n || k >= n {
        return Err(CoreError::CountMismatch {
            frames: stamps_s.len().max(k + 1),
            poses: n,
        });
    }
    if offsets_s.len() != points.len() {
        return Err(CoreError::PointTimesCount {
            frame: k,
            points: points.len(),
            times: offsets_s.len(),
        });
    }
    let start = k.saturating_sub(2);
    let end = (k + 3).min(n);
    let stamps = &stamps_s[start..end];
    if offsets_s.iter().any(|t| !t.is_finite()) || stamps.iter().any(|s| !s.is_finite()) {
        return Err(CoreError::NonFinitePointTime { frame: k });
    }
    let poses: Vec<Pose> = world_from_lidar[start..end]
        .iter()
        .map(Pose::from_isometry)
        .collect();
    if let Some(frame) = poses.iter().position(|p| !p.is_finite()) {
        return Err(CoreError::NonFinitePose {
            frame: start + frame,
        });
    }
    Ok(deskew_frame(points, offsets_s, &poses, stamps, k - start))
}

/// Every frame's points in the world frame at `world_from_lidar`, de-skewed along those poses
/// first when `times` are given (one frame at a time: memory is the output's), non-finite
/// points left out: a flight's map from its final poses.
pub fn world_cloud(
    frames: &[Vec<Point3<f64>>],
    times: Option<PointTimes<'_>>,
    world_from_lidar: &[Isometry3<f64>],
) -> Result<Vec<Point3<f64>>, CoreError> {
    if frames.len() != world_from_lidar.len() {
        return Err(CoreError::CountMismatch {
            frames: frames.len(),
            poses: world_from_lidar.len(),
        });
    }
    let poses: Vec<Pose> = world_from_lidar.iter().map(Pose::from_isometry).collect();
    if let Some(times) = &times {
        let counts: Vec<usize> = frames.iter().map(Vec::len).collect();
        times.check(&counts)?;
        if let Some(frame) = poses.iter().position(|p| !p.is_finite()) {
            return Err(CoreError::NonFinitePose { frame });
        }
    }
    let mut cloud = Vec::with_capacity(frames.iter().map(Vec::len).sum());
    for (k, (frame, pose)) in frames.iter().zip(world_from_lidar).enumerate() {
        let deskewed;
        let points = match &times {
            Some(t) => {
                deskewed = deskew_frame(frame, &t.offsets_s[k], &poses, t.stamps_s, k);
                &deskewed
            }
            None => frame,
        };
        cloud.extend(
            points
                .iter()
                .map(|p| pose * p)
                .filter(|p| p.iter().all(|v| v.is_finite())),
        );
    }
    Ok(cloud)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::exp_so3;
    use nalgebra::{Translation3, UnitQuaternion};

    fn pose(x: f64, yaw: f64) -> Pose {
        Pose::from_isometry(&Isometry3::from_parts(
            Translation3::new(x, 0.5 * x, 0.1),
            UnitQuaternion::from_euler_angles(0.02, -0.01, yaw),
        ))
    }

    /// Frames at `stamps_s` along the continuous track `at`, each seeing `world` at `taus`.
    fn frames_along(
        at: &dyn Fn(f64) -> Pose,
        stamps_s: &[f64],
        world: &Vector3<f64>,
        taus: &[f32],
    ) -> FrameMotion {
        let raw = stamps_s
            .iter()
            .map(|&stamp| {
                taus.iter()
                    .map(|&tau| {
                        let p = at(stamp + f64::from(tau));
                        p.rotation.transpose() * (world - p.translation)
                    })
                    .collect()
            })
            .collect();
        let offsets = vec![taus.to_vec(); stamps_s.len()];
        FrameMotion::new(raw, offsets, stamps_s.to_vec())
    }

    /// On a screw motion (constant body twist: an orbit, or a straight line), a world point
    /// seen at time tau lands, de-skewed, where frame k's pose at its stamp sees it: every
    /// frame, since the central and the one-sided steps are both exact there.
    #[test]
    fn a_screw_motion_is_followed_exactly() {
        let (w, v) = (Vector3::new(0.1, -0.05, 0.4), Vector3::new(5.0, -0.3, 0.2));
        let start = pose(0.4, 0.3);
        let at = |t: f64| {
            let (phi, rho) = (t * w, t * v);
            Pose {
                rotation: start.rotation * exp_so3(&phi),
                translation: start.translation
                    + start.rotation * crate::geometry::left_jacobian_so3_times(&phi, &rho),
            }
        };
        let stamps_s = [0.0, 0.1, 0.2, 0.3];
        let poses: Vec<Pose> = stamps_s.iter().map(|&s| at(s)).collect();
        let world = Vector3::new(4.0, -2.0, 1.5);
        let motion = frames_along(&at, &stamps_s, &world, &[0.0, 0.03, -0.02, 0.099]);
        for (k, frame) in motion
            .deskewed(&poses, Parallelism::Serial)
            .iter()
            .enumerate()
        {
            for p in frame {
                let back = poses[k].apply(p);
                assert!((back - world).norm() < 1e-9, "frame {k}: {back:?}");
            }
        }
        // The flight's map from these poses: every point on the world point with the times,
        // up to 0.5 m off without them (5 m/s for 99 ms).
        let frames: Vec<Vec<Point3<f64>>> = (motion.raw.iter())
            .map(|f| f.iter().map(|p| Point3::from(*p)).collect())
            .collect();
        let isometries: Vec<_> = poses.iter().map(Pose::to_isometry).collect();
        let times = PointTimes {
            stamps_s: &stamps_s,
            offsets_s: &motion.offsets_s,
        };
        let map = world_cloud(&frames, Some(times), &isometries).expect("map");
        assert_eq!(map.len(), 16);
        let worst = |map: &[Point3<f64>]| {
            map.iter()
                .map(|p| (p.coords - world).norm())
                .fold(0.0, f64::max)
        };
        assert!(worst(&map) < 1e-9, "{}", worst(&map));
        let skewed = world_cloud(&frames, None, &isometries).expect("map");
        assert!(worst(&skewed) > 0.4, "{}", worst(&skewed));
        let short = PointTimes {
            stamps_s: &stamps_s,
            offsets_s: &motion.offsets_s[..3],
        };
        assert!(world_cloud(&frames, Some(short), &isometries).is_err());
        // One frame at a time, from its neighbours only: the same points.
        let mut one_by_one = Vec::new();
        for (k, frame) in frames.iter().enumerate() {
            let points = deskew_frame_along(frame, &motion.offsets_s[k], &isometries, &stamps_s, k)
                .expect("frame");
            one_by_one.extend(points.iter().map(|p| isometries[k] * p));
        }
        assert_eq!(one_by_one, map);
        assert!(deskew_frame_along(&frames[0], &[0.0], &isometries, &stamps_s, 0).is_err());
        assert!(
            deskew_frame_along(&frames[0], &motion.offsets_s[0], &isometries, &stamps_s, 9)
                .is_err()
        );
    }

    /// A yaw accelerating at 8 rad/s^2 (a helmet's head turn): frames whose neighbours all
    /// have central rates are de-skewed exactly, before and after the stamp; holding the
    /// rate constant would leave 2.2 deg (39 cm at 10 m) by the frame's end.
    #[test]
    fn an_accelerating_turn_is_followed_exactly_inside_the_window() {
        let (rate, accel) = (1.5, 8.0);
        let start = pose(0.0, 0.2);
        let at = |t: f64| Pose {
            rotation: start.rotation
                * exp_so3(&Vector3::new(0.0, 0.0, rate * t + 0.5 * accel * t * t)),
            translation: start.translation,
        };
        let stamps_s = [0.0, 0.1, 0.2, 0.3, 0.4, 0.5];
        let poses: Vec<Pose> = stamps_s.iter().map(|&s| at(s)).collect();
        let world = Vector3::new(10.0, 0.5, 1.0);
        let motion = frames_along(&at, &stamps_s, &world, &[0.0, 0.05, -0.04, 0.099]);
        {
            let out = motion.deskewed(&poses, Parallelism::Serial);
            for k in 2..=3 {
                for p in &out[k] {
                    let back = poses[k].apply(p);
                    assert!((back - world).norm() < 1e-9, "frame {k}: {back:?}");
                }
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
