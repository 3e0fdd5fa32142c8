//! Which stretch of a scene's path a benchmark group flies.
//!
//! A group on a straight leg has collinear positions, for which the SE(3) alignment (hence
//! APE) is undefined; such a group starts at one of the path's turns instead. Of the turns,
//! it takes the one whose frames see the most wall: a probe casts a few rays from poses along
//! each candidate group and counts hits on surfaces steeper than [`WALL_MIN_TILT_DEG`]. Ground
//! and flat roofs fix only height, roll and pitch; position along the path and yaw need walls
//! (measured on the CARIC crane: about 100 wall hits per frame leave them unobservable, 0.2 m
//! APE for every method, while the other turn of the same loop gives 0.03 m). The rule is
//! the same for every scene and every method.

use nalgebra::{Point3, Vector3};
use pssba_sim::{Mid360, Raycaster, Scene, TrajectoryKind, TrajectorySpec};

/// Below this spread (m, RMS) of the positions across the flight direction, a group counts
/// as a straight leg.
const STRAIGHT_SPREAD_M: f64 = 0.05;
/// A surface counts as wall when its normal is at least this far from vertical (deg).
pub const WALL_MIN_TILT_DEG: f64 = 30.0;
/// Poses probed per candidate group, evenly spread over it.
const PROBE_POSES: usize = 10;
/// Rays cast per probed pose (the first rays of the Mid-360 pattern at that frame).
const PROBE_RAYS: usize = 4000;

/// The path of a group and how it was chosen.
#[derive(Debug, Clone)]
pub struct GroupPath {
    /// The path to fly.
    pub trajectory: TrajectorySpec,
    /// The default path's group was a straight leg, so the group starts at a turn.
    pub moved: bool,
    /// Wall hits per probed frame of each candidate turn, in path order (empty if not moved).
    pub wall_hits_per_turn: Vec<f64>,
    /// Index of the chosen turn in `wall_hits_per_turn`.
    pub chosen_turn: usize,
}

/// RMS spread (m) of `positions` across their main direction: the square root of the
/// second-largest eigenvalue of their covariance. Zero for collinear positions, for which an
/// SE(3) alignment (hence APE) is undefined: evo refuses them as well.
pub fn cross_spread_m(positions: &[Point3<f64>]) -> f64 {
    let n = positions.len().max(1) as f64;
    let mean = positions.iter().map(|p| p.coords).sum::<Vector3<f64>>() / n;
    let covariance = positions
        .iter()
        .map(|p| (p.coords - mean) * (p.coords - mean).transpose())
        .sum::<nalgebra::Matrix3<f64>>()
        / n;
    let mut eigenvalues: Vec<f64> = covariance.symmetric_eigenvalues().iter().copied().collect();
    eigenvalues.sort_by(|a, b| b.total_cmp(a));
    eigenvalues[1].max(0.0).sqrt()
}

/// Starts (metres along the path, `start_along_m`) of the turns a group may begin at: both
/// half circles of an orbit or helix; the turn after each row of the lawnmower's first sweep.
pub fn turn_starts_m(path: &TrajectorySpec) -> Vec<f64> {
    use std::f64::consts::PI;
    let r = path.radius_m;
    match path.kind {
        // `start_along_m` is measured from the loop's point furthest along its axis; the
        // right half circle begins a quarter circle before it, the left one after the top
        // straight.
        TrajectoryKind::Orbit | TrajectoryKind::Helix => {
            vec![
                -0.5 * PI * r,
                0.5 * PI * r + 2.0 * path.straight_half_m.max(0.0),
            ]
        }
        TrajectoryKind::Lawnmower => {
            let leg_m = 2.0 * r + PI * 0.5 * path.lane_spacing_m;
            (0..path.lanes.max(2) - 1)
                .map(|k| k as f64 * leg_m + 2.0 * r)
                .collect()
        }
    }
}

/// Mean number of probe rays per frame that hit a wall within the sensor's range.
pub fn wall_hits_per_frame(
    caster: &Raycaster,
    path: &TrajectorySpec,
    frames: usize,
    sensor: &Mid360,
) -> f64 {
    let poses = path.world_from_lidar(frames, sensor.frame_rate_hz);
    let min_tilt_cos = WALL_MIN_TILT_DEG.to_radians().cos();
    let probes = PROBE_POSES.min(poses.len());
    let mut hits = 0usize;
    for k in 0..probes {
        let frame = k * poses.len() / probes;
        let pose = &poses[frame];
        let origin = Point3::from(pose.translation.vector);
        let dirs = sensor.frame_directions(frame);
        for dir in dirs.iter().take(PROBE_RAYS) {
            let world_dir = pose.rotation * dir;
            if let Some((range_m, normal)) =
                caster.cast_with_normal(&origin, &world_dir, sensor.max_range_m)
                && range_m >= sensor.min_range_m
                && normal.z.abs() < min_tilt_cos
            {
                hits += 1;
            }
        }
    }
    hits as f64 / probes.max(1) as f64
}

/// The path a group of `frames` frames flies in `scene` (see the module doc).
pub fn group_path(scene: &Scene, frames: usize) -> anyhow::Result<GroupPath> {
    let default = scene.trajectory;
    let sensor = Mid360::default();
    let positions: Vec<Point3<f64>> = default
        .world_from_lidar(frames, sensor.frame_rate_hz)
        .iter()
        .map(|p| Point3::from(p.translation.vector))
        .collect();
    if cross_spread_m(&positions) >= STRAIGHT_SPREAD_M {
        return Ok(GroupPath {
            trajectory: default,
            moved: false,
            wall_hits_per_turn: Vec::new(),
            chosen_turn: 0,
        });
    }
    let caster = Raycaster::new(&scene.mesh)?;
    let candidates: Vec<TrajectorySpec> = turn_starts_m(&default)
        .into_iter()
        .map(|start_along_m| TrajectorySpec {
            start_along_m,
            ..default
        })
        .collect();
    let wall_hits_per_turn: Vec<f64> = candidates
        .iter()
        .map(|path| wall_hits_per_frame(&caster, path, frames, &sensor))
        .collect();
    // The first of equals, so the choice is deterministic.
    let chosen_turn = (0..candidates.len()).fold(0, |best, k| {
        if wall_hits_per_turn[k] > wall_hits_per_turn[best] {
            k
        } else {
            best
        }
    });
    Ok(GroupPath {
        trajectory: candidates[chosen_turn],
        moved: true,
        wall_hits_per_turn,
        chosen_turn,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_circle_is_not_straight_and_a_line_is() {
        let circle: Vec<Point3<f64>> = (0..50)
            .map(|k| {
                let a = k as f64 * 0.1;
                Point3::new(5.0 * a.cos(), 5.0 * a.sin(), 2.0)
            })
            .collect();
        assert!(cross_spread_m(&circle) > 1.0);
        let line: Vec<Point3<f64>> = (0..50).map(|k| Point3::new(k as f64, 2.0, 1.0)).collect();
        assert!(cross_spread_m(&line) < 1e-9);
    }

    #[test]
    fn turn_starts_begin_the_half_circles() {
        let path = TrajectorySpec {
            straight_half_m: 10.0,
            ..TrajectorySpec::orbit(Point3::new(0.0, 0.0, 3.0), 4.0)
        };
        // At a turn's start the heading is along the straights (x) and the path bends.
        for start_along_m in turn_starts_m(&path) {
            let turn = TrajectorySpec {
                start_along_m,
                ..path
            };
            let poses = turn.world_from_lidar(60, 10.0);
            let first = poses[0].translation.vector;
            assert!((first.x.abs() - 10.0).abs() < 1e-6, "{first}");
            let positions: Vec<Point3<f64>> = poses
                .iter()
                .map(|p| Point3::from(p.translation.vector))
                .collect();
            assert!(cross_spread_m(&positions) > 0.5);
        }
    }
}
