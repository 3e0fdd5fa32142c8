//! UAV-like ground-truth trajectories (DESIGN.md section 4): orbit, helix and lawnmower at a
//! constant speed (default 1.5 m/s), one pose per frame at the sensor's frame rate. The
//! sensor's x axis points along the horizontal velocity (yaw along the path), z stays up
//! apart from a gentle roll/pitch sway of at most 2 deg, as a multirotor's attitude wanders.

use nalgebra::{Isometry3, Point3, Rotation2, Translation3, UnitQuaternion, Vector2};
use std::f64::consts::PI;

/// The path shapes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrajectoryKind {
    /// A horizontal loop around `centre`, counter-clockwise: a circle of `radius_m`, or with
    /// `straight_half_m > 0` a stadium (two straights of `2 straight_half_m` along
    /// `axis_yaw_rad` joined by half circles of `radius_m`) to hug elongated models.
    Orbit,
    /// The orbit climbing at `climb_m_s`, centred in height on `centre.z`.
    Helix,
    /// `lanes` (at least 2) rows along x of length `2 radius_m`, `lane_spacing_m` apart,
    /// joined by half-circle turns; after the last row it sweeps back over the rows.
    Lawnmower,
}

impl TrajectoryKind {
    /// Every kind, in the order names are listed.
    pub const ALL: [TrajectoryKind; 3] = [Self::Orbit, Self::Helix, Self::Lawnmower];

    /// The lower-case name used on the command line and in meta.json.
    pub fn name(self) -> &'static str {
        match self {
            Self::Orbit => "orbit",
            Self::Helix => "helix",
            Self::Lawnmower => "lawnmower",
        }
    }

    /// The kind called `name`, if any.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }
}

/// Where and how the sensor flies.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrajectorySpec {
    /// Path shape.
    pub kind: TrajectoryKind,
    /// Centre of the orbit or of the lawnmower area; `z` is the mean flight height (m).
    pub centre: Point3<f64>,
    /// Orbit radius, or half the length of a lawnmower row (m).
    pub radius_m: f64,
    /// Half length of the orbit's straight sides (m); 0 for a circle.
    pub straight_half_m: f64,
    /// Direction (rad from +x) of the orbit's straight sides and of the lawnmower rows.
    pub axis_yaw_rad: f64,
    /// Speed along the path (m/s).
    pub speed_m_s: f64,
    /// Vertical speed of the helix (m/s), part of `speed_m_s`.
    pub climb_m_s: f64,
    /// Distance between lawnmower rows (m).
    pub lane_spacing_m: f64,
    /// Number of lawnmower rows.
    pub lanes: usize,
    /// Where on the orbit the flight starts: metres along it from its point furthest along
    /// `axis_yaw_rad` (for a circle, `radius_m` x the start angle from that axis). For the
    /// lawnmower: metres along the legs from the start of the first row (negative: 0).
    pub start_along_m: f64,
    /// Head turns (a helmet's wearer looking around): yaw swings by this amplitude (rad)
    /// about the heading, `yaw_sway_rad * sin(2 pi yaw_sway_hz t)`; the peak yaw rate is
    /// `2 pi yaw_sway_hz yaw_sway_rad` (0.5 rad at 0.6 Hz: 108 deg/s). 0: none.
    pub yaw_sway_rad: f64,
    /// Frequency of the head turns (Hz).
    pub yaw_sway_hz: f64,
}

impl TrajectorySpec {
    /// An orbit of `radius_m` around `centre` at 1.5 m/s (helix climb 0.25 m/s, lawnmower
    /// 3 rows 3 m apart when the kind is changed).
    pub fn orbit(centre: Point3<f64>, radius_m: f64) -> Self {
        Self {
            kind: TrajectoryKind::Orbit,
            centre,
            radius_m,
            straight_half_m: 0.0,
            axis_yaw_rad: 0.0,
            speed_m_s: 1.5,
            climb_m_s: 0.25,
            lane_spacing_m: 3.0,
            lanes: 3,
            start_along_m: 0.0,
            yaw_sway_rad: 0.0,
            yaw_sway_hz: 0.0,
        }
    }

    /// The same geometry flown as `kind`.
    pub fn with_kind(self, kind: TrajectoryKind) -> Self {
        Self { kind, ..self }
    }

    /// Position (m) and horizontal unit heading at time `t_s` of a flight lasting `total_s`.
    fn state(&self, t_s: f64, total_s: f64) -> (Point3<f64>, Vector2<f64>) {
        let c = self.centre;
        let (local, heading, z) = match self.kind {
            TrajectoryKind::Orbit | TrajectoryKind::Helix => {
                let (horizontal, z) = if self.kind == TrajectoryKind::Helix {
                    let climb = self.climb_m_s.clamp(0.0, self.speed_m_s);
                    let horizontal = (self.speed_m_s.powi(2) - climb.powi(2)).sqrt();
                    (horizontal, c.z + climb * (t_s - 0.5 * total_s))
                } else {
                    (self.speed_m_s, c.z)
                };
                let (xy, heading) = self.stadium(horizontal * t_s);
                (xy, heading, z)
            }
            TrajectoryKind::Lawnmower => {
                let (xy, heading) =
                    self.lawnmower(self.speed_m_s * t_s + self.start_along_m.max(0.0));
                (xy, heading, c.z)
            }
        };
        let rotation = Rotation2::new(self.axis_yaw_rad);
        let xy = rotation * local;
        (Point3::new(c.x + xy.x, c.y + xy.y, z), rotation * heading)
    }

    /// Orbit position (relative to the centre, before `axis_yaw_rad`) and heading after
    /// `s_m` metres: right half circle, top straight, left half circle, bottom straight.
    fn stadium(&self, s_m: f64) -> (Vector2<f64>, Vector2<f64>) {
        let (r, half) = (self.radius_m.max(1e-3), self.straight_half_m.max(0.0));
        let perimeter_m = 4.0 * half + 2.0 * PI * r;
        let mut s = (s_m + self.start_along_m + 0.5 * PI * r).rem_euclid(perimeter_m);
        let arc = |centre_x: f64, phi: f64| {
            let position = Vector2::new(centre_x + r * phi.cos(), r * phi.sin());
            (position, Vector2::new(-phi.sin(), phi.cos()))
        };
        if s < PI * r {
            return arc(half, -0.5 * PI + s / r);
        }
        s -= PI * r;
        if s < 2.0 * half {
            return (Vector2::new(half - s, r), -Vector2::x());
        }
        s -= 2.0 * half;
        if s < PI * r {
            return arc(-half, 0.5 * PI + s / r);
        }
        s -= PI * r;
        (Vector2::new(-half + s, -r), Vector2::x())
    }

    /// Lawnmower position (relative to the centre, before `axis_yaw_rad`) and heading after
    /// `s_m` metres. Legs (a row, then a half-circle
    /// turn of diameter `lane_spacing_m` to the next row) visit the rows 0, 1, .., n-1, n-2,
    /// .., 0, 1, ..; speed and heading stay continuous.
    fn lawnmower(&self, s_m: f64) -> (Vector2<f64>, Vector2<f64>) {
        let lanes = self.lanes.max(2);
        let (r, turn_r) = (self.radius_m.max(1e-3), 0.5 * self.lane_spacing_m.max(1e-3));
        let leg_m = 2.0 * r + PI * turn_r;
        let leg = (s_m / leg_m).floor().max(0.0) as usize;
        let s = s_m - leg as f64 * leg_m;
        let period = 2 * (lanes - 1);
        let lane_of = |m: usize| {
            let phase = m % period;
            if phase < lanes { phase } else { period - phase }
        };
        let (lane, next) = (lane_of(leg), lane_of(leg + 1));
        let dir = if leg.is_multiple_of(2) { 1.0 } else { -1.0 };
        let side = if next > lane { 1.0 } else { -1.0 };
        let y0 = -0.5 * (lanes - 1) as f64 * self.lane_spacing_m;
        let y = y0 + lane as f64 * self.lane_spacing_m;
        if s <= 2.0 * r {
            let x = -dir * r + dir * s;
            return (Vector2::new(x, y), Vector2::new(dir, 0.0));
        }
        let phi = (s - 2.0 * r) / turn_r;
        let pivot = Vector2::new(dir * r, y + side * turn_r);
        let position = pivot + turn_r * Vector2::new(dir * phi.sin(), -side * phi.cos());
        (position, Vector2::new(dir * phi.cos(), side * phi.sin()))
    }

    /// Ground-truth `world_from_lidar` poses of `frames` frames at `frame_rate_hz`: frame `k`
    /// at `k / frame_rate_hz` (its stamp).
    pub fn world_from_lidar(&self, frames: usize, frame_rate_hz: f64) -> Vec<Isometry3<f64>> {
        let total_s = Self::duration_s(frames, frame_rate_hz);
        (0..frames)
            .map(|k| self.pose_at(k as f64 / frame_rate_hz, total_s))
            .collect()
    }

    /// The flight time (s) that [`Self::world_from_lidar`] gives `frames` frames: the helix
    /// climbs over it. Pass it to [`Self::pose_at`].
    pub fn duration_s(frames: usize, frame_rate_hz: f64) -> f64 {
        frames.saturating_sub(1) as f64 / frame_rate_hz
    }

    /// True `world_from_lidar` at any time `t_s` of a flight lasting `total_s`; smooth in
    /// time, so a ray fired between two frame stamps leaves from where the sensor was then.
    pub fn pose_at(&self, t_s: f64, total_s: f64) -> Isometry3<f64> {
        let (position, heading) = self.state(t_s, total_s);
        let turn = self.yaw_sway_rad * (2.0 * PI * self.yaw_sway_hz * t_s).sin();
        let yaw = heading.y.atan2(heading.x) + turn;
        let sway = 2f64.to_radians();
        let roll = sway * (0.9 * t_s).sin();
        let pitch = sway * (0.6 * t_s + 1.0).sin();
        let rotation = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
        Isometry3::from_parts(Translation3::from(position.coords), rotation)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// Velocity (m/s) between two poses `dt_s` apart.
    fn velocity_m_s(a: &Isometry3<f64>, b: &Isometry3<f64>, dt_s: f64) -> Vector3<f64> {
        (b.translation.vector - a.translation.vector) / dt_s
    }

    #[test]
    fn speed_is_within_1_to_2_m_s_and_yaw_follows_the_velocity() {
        let circle = TrajectorySpec::orbit(Point3::new(1.0, -2.0, 5.0), 8.0);
        let stadium = TrajectorySpec {
            straight_half_m: 12.0,
            axis_yaw_rad: 2.0,
            ..circle
        };
        for (base, kind) in [circle, stadium]
            .into_iter()
            .flat_map(|b| TrajectoryKind::ALL.map(|k| (b, k)))
        {
            let poses = base.with_kind(kind).world_from_lidar(800, 10.0);
            for pair in poses.windows(2) {
                let v = velocity_m_s(&pair[0], &pair[1], 0.1);
                assert!(
                    (1.0..=2.0).contains(&v.norm()),
                    "{kind:?}: {} m/s",
                    v.norm()
                );
                let heading = pair[0].rotation * Vector3::x();
                let mid_heading =
                    (pair[0].rotation * Vector3::x() + pair[1].rotation * Vector3::x()).xy();
                assert!(
                    mid_heading.angle(&v.xy()) < 0.02,
                    "{kind:?}: heading off the velocity"
                );
                assert!(heading.xy().angle(&v.xy()) < 0.1);
                let up = pair[0].rotation * Vector3::z();
                assert!(up.z > 2.9f64.to_radians().cos());
            }
        }
    }

    #[test]
    fn poses_at_any_time_meet_the_frame_poses_and_head_turns_reach_their_rate() {
        let spec = TrajectorySpec {
            yaw_sway_rad: 0.55,
            yaw_sway_hz: 0.6,
            ..TrajectorySpec::orbit(Point3::new(0.0, 0.0, 4.0), 10.0)
                .with_kind(TrajectoryKind::Helix)
        };
        let poses = spec.world_from_lidar(50, 10.0);
        let total_s = TrajectorySpec::duration_s(50, 10.0);
        for (k, pose) in poses.iter().enumerate() {
            assert_eq!(*pose, spec.pose_at(k as f64 / 10.0, total_s));
        }
        let dt = 1e-3;
        let peak_deg_s = (0..2000)
            .map(|i| {
                let t = i as f64 * dt;
                let (a, b) = (spec.pose_at(t, total_s), spec.pose_at(t + dt, total_s));
                (a.rotation.inverse() * b.rotation).angle().to_degrees() / dt
            })
            .fold(0.0, f64::max);
        assert!((110.0..135.0).contains(&peak_deg_s), "{peak_deg_s}");
    }

    #[test]
    fn lawnmower_covers_its_rows_and_helix_climbs() {
        let spec = TrajectorySpec::orbit(Point3::new(0.0, 0.0, 4.0), 10.0);
        let mower = spec
            .with_kind(TrajectoryKind::Lawnmower)
            .world_from_lidar(1000, 10.0);
        let ys: Vec<f64> = mower.iter().map(|p| p.translation.y).collect();
        assert!(
            ys.iter().any(|&y| (y + 3.0).abs() < 1e-9)
                && ys.iter().any(|&y| (y - 3.0).abs() < 1e-9)
        );
        assert!(mower.iter().all(|p| p.translation.x.abs() <= 11.5 + 1e-9));
        let helix = spec
            .with_kind(TrajectoryKind::Helix)
            .world_from_lidar(101, 10.0);
        let (first, last) = (helix[0].translation.z, helix[100].translation.z);
        assert!((first - 2.75).abs() < 1e-9 && (last - 5.25).abs() < 1e-9);
    }
}
