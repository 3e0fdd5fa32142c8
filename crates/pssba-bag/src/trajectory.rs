//! A stamped trajectory and pose lookup at a cloud's stamp: the exact pose, or linear
//! translation + slerp rotation between the two bracketing poses.

use nalgebra::{Isometry3, Translation3};

/// Why a stamp gets no pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoPose {
    /// Before the first or after the last pose.
    OutsideRange,
    /// The bracketing poses are further apart than the allowed gap.
    Gap,
}

/// Poses sorted by stamp (ns), one per stamp.
#[derive(Debug, Clone, Default)]
pub struct Trajectory {
    stamps_ns: Vec<i64>,
    poses: Vec<Isometry3<f64>>,
}

impl Trajectory {
    /// Sorts the poses by stamp; of several poses with one stamp, the last given is kept.
    pub fn new(mut stamped: Vec<(i64, Isometry3<f64>)>) -> Trajectory {
        stamped.sort_by_key(|(t, _)| *t);
        let mut trajectory = Trajectory::default();
        for (t, pose) in stamped {
            if trajectory.stamps_ns.last() == Some(&t) {
                if let Some(last) = trajectory.poses.last_mut() {
                    *last = pose;
                }
                continue;
            }
            trajectory.stamps_ns.push(t);
            trajectory.poses.push(pose);
        }
        trajectory
    }

    /// Number of distinct stamps.
    pub fn len(&self) -> usize {
        self.stamps_ns.len()
    }

    /// True without poses.
    pub fn is_empty(&self) -> bool {
        self.stamps_ns.is_empty()
    }

    /// First and last stamp (ns).
    pub fn range_ns(&self) -> Option<(i64, i64)> {
        Some((*self.stamps_ns.first()?, *self.stamps_ns.last()?))
    }

    /// The pose at `stamp_ns`: exact, or interpolated across a gap of at most `max_gap_ns`.
    pub fn at(&self, stamp_ns: i64, max_gap_ns: i64) -> Result<Isometry3<f64>, NoPose> {
        let after = self.stamps_ns.partition_point(|&t| t < stamp_ns);
        if after < self.stamps_ns.len() && self.stamps_ns[after] == stamp_ns {
            return Ok(self.poses[after]);
        }
        if after == 0 || after == self.stamps_ns.len() {
            return Err(NoPose::OutsideRange);
        }
        let (t0, t1) = (self.stamps_ns[after - 1], self.stamps_ns[after]);
        if t1 - t0 > max_gap_ns {
            return Err(NoPose::Gap);
        }
        let s = (stamp_ns - t0) as f64 / (t1 - t0) as f64;
        Ok(interpolate(&self.poses[after - 1], &self.poses[after], s))
    }
}

/// `a` at `s = 0`, `b` at `s = 1`: translation linear, rotation by slerp.
pub fn interpolate(a: &Isometry3<f64>, b: &Isometry3<f64>, s: f64) -> Isometry3<f64> {
    let translation = a.translation.vector.lerp(&b.translation.vector, s);
    let rotation = a.rotation.slerp(&b.rotation, s);
    Isometry3::from_parts(Translation3::from(translation), rotation)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{UnitQuaternion, Vector3};

    fn pose(x: f64, yaw: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(x, 0.0, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
        )
    }

    #[test]
    fn exact_interpolated_outside_and_gap() {
        let t = Trajectory::new(vec![
            (200, pose(2.0, 0.2)),
            (0, pose(0.0, 0.0)),
            (1000, pose(3.0, 0.0)),
        ]);
        assert_eq!(t.at(200, 100).expect("exact"), pose(2.0, 0.2));
        let mid = t.at(50, 500).expect("interpolated");
        assert!((mid.translation.x - 0.5).abs() < 1e-12);
        assert!((mid.rotation.angle() - 0.05).abs() < 1e-12);
        assert_eq!(t.at(-1, 500), Err(NoPose::OutsideRange));
        assert_eq!(t.at(1001, 500), Err(NoPose::OutsideRange));
        assert_eq!(t.at(500, 500), Err(NoPose::Gap));
    }

    #[test]
    fn a_repeated_stamp_keeps_the_last_pose() {
        let t = Trajectory::new(vec![(5, pose(1.0, 0.0)), (5, pose(2.0, 0.0))]);
        assert_eq!(t.len(), 1);
        assert_eq!(t.at(5, 0).expect("exact").translation.x, 2.0);
    }
}
