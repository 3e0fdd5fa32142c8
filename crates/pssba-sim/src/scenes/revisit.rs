//! `revisit`: a structured place at the origin and a flat runway leading away from it, for
//! flights that leave a place and come back (the whole-flight pipeline, issue 38). Curved
//! bodies (a dome, tanks, a torus, a sphere, a vaulted shed) stand within 9 m of the origin;
//! the ground is flat everywhere else, so away from the place a frame constrains only height,
//! roll and pitch and the odometry's drift in x, y and yaw is all there is.
//!
//! The default flight is a stadium loop: its left half circle (radius 11 m) wraps around the
//! place, its straights run `excursion_m` along +x over open ground. It starts at the left
//! half circle, so one loop and a half circle visit the place twice.

use crate::{Scene, TrajectorySpec, TriangleMesh};
use nalgebra::Point3;

/// Radius (m) of the loop's half circles; the place fits inside the left one.
pub const REVISIT_TURN_RADIUS_M: f64 = 11.0;
/// Flight height (m).
const FLIGHT_HEIGHT_M: f64 = 3.5;

/// The place: curved bodies on flat ground, all within 9 m of the origin.
fn push_place(mesh: &mut TriangleMesh) {
    mesh.push_dome(Point3::new(0.0, 0.0, -0.1), 4.0);
    mesh.push_cylinder(Point3::new(4.5, 4.0, 0.0), Point3::new(4.5, 4.0, 8.0), 1.5);
    mesh.push_cylinder(
        Point3::new(-6.5, -1.5, 0.0),
        Point3::new(-6.5, -1.5, 5.0),
        1.0,
    );
    mesh.push_torus(Point3::new(3.0, -5.0, 0.7), 2.0, 0.7);
    mesh.push_sphere(Point3::new(-4.5, 4.0, 1.5), 1.5);
    mesh.push_cylinder(
        Point3::new(-7.0, 0.0, 1.0),
        Point3::new(-5.5, 5.5, 1.0),
        0.8,
    );
    // A vaulted shed lying along y, west of the place.
    mesh.push_grid(20, 12, |u, v| {
        let a = std::f64::consts::PI * u;
        Point3::new(-3.0 + 2.5 * a.cos(), -7.0 + 3.0 * v, 2.5 * a.sin())
    });
}

/// The revisit scene with straights of `excursion_m` (m, at least 10) over open ground.
pub fn revisit_scene(excursion_m: f64) -> Scene {
    let excursion_m = excursion_m.max(10.0);
    let mut mesh = TriangleMesh::new();
    push_place(&mut mesh);
    let reach_m = 60.0;
    mesh.push_heightfield(
        [-reach_m, -reach_m],
        [excursion_m + reach_m, reach_m],
        10.0,
        |_, _| 0.0,
    );
    let half_m = 0.5 * excursion_m;
    let trajectory = TrajectorySpec {
        straight_half_m: half_m,
        // From the loop's easternmost point: the rest of the right half circle and the top
        // straight, then the left half circle starts.
        start_along_m: 0.5 * std::f64::consts::PI * REVISIT_TURN_RADIUS_M + 2.0 * half_m,
        ..TrajectorySpec::orbit(
            Point3::new(half_m, 0.0, FLIGHT_HEIGHT_M),
            REVISIT_TURN_RADIUS_M,
        )
    };
    Scene {
        name: "revisit".to_owned(),
        mesh,
        trajectory,
    }
}

/// Frames (at `frame_rate_hz`) of a flight that visits the place, flies the loop and comes
/// back around the place once more: one loop plus one half circle.
pub fn revisit_frames(scene: &Scene, frame_rate_hz: f64) -> usize {
    let t = &scene.trajectory;
    let metres = 4.0 * t.straight_half_m + 3.0 * std::f64::consts::PI * t.radius_m;
    (metres / t.speed_m_s * frame_rate_hz).ceil() as usize
}

/// Rows of the survey flight, and their spacing (m).
pub const SURVEY_ROWS: usize = 4;
pub const SURVEY_ROW_SPACING_M: f64 = 10.0;

/// The revisit scene flown as a lawnmower survey: [`SURVEY_ROWS`] rows of 80 m along x,
/// [`SURVEY_ROW_SPACING_M`] apart, south of the place (the first row's west end 20 m from
/// it), flown there and back over and over: every row after the first pass is seen again.
pub fn survey_scene(speed_m_s: f64) -> Scene {
    let mut scene = revisit_scene(100.0);
    let t = &mut scene.trajectory;
    t.kind = crate::TrajectoryKind::Lawnmower;
    t.speed_m_s = speed_m_s;
    t.centre = Point3::new(20.0, -24.0, t.centre.z);
    t.radius_m = 40.0;
    t.lane_spacing_m = SURVEY_ROW_SPACING_M;
    t.lanes = SURVEY_ROWS;
    t.start_along_m = 0.0;
    scene.name = "survey".to_owned();
    scene
}

/// Frames (at `frame_rate_hz`) of a survey that flies the rows there and back once (every
/// row but the last twice).
pub fn survey_frames(scene: &Scene, frame_rate_hz: f64) -> usize {
    let t = &scene.trajectory;
    let turn_m = std::f64::consts::PI * 0.5 * t.lane_spacing_m;
    let legs = 2 * t.lanes.max(1) - 1;
    let metres = legs as f64 * (2.0 * t.radius_m + turn_m) - turn_m;
    (metres / t.speed_m_s * frame_rate_hz).floor() as usize
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Raycaster, path_is_free};

    #[test]
    fn the_flight_circles_the_place_twice_in_free_space() {
        let scene = revisit_scene(60.0);
        let frames = revisit_frames(&scene, 10.0);
        let poses = scene.trajectory.world_from_lidar(frames, 10.0);
        let positions: Vec<_> = poses
            .iter()
            .map(|p| Point3::from(p.translation.vector))
            .collect();
        let caster = Raycaster::new(&scene.mesh).expect("mesh");
        assert!(path_is_free(&caster, &positions, true));
        let near_place = |p: &Point3<f64>| p.coords.xy().norm() < 12.0;
        assert!(near_place(&positions[0]) && near_place(&positions[frames - 1]));
        let far = positions.iter().map(|p| p.x).fold(0.0, f64::max);
        assert!(far > 60.0 + REVISIT_TURN_RADIUS_M - 0.5, "{far}");
        // Two separate visits: near, far, near again.
        let mut visits = 0;
        let mut inside = false;
        for p in &positions {
            let now = near_place(p);
            visits += usize::from(now && !inside);
            inside = now;
        }
        assert_eq!(visits, 2);
    }
}
