//! `street`: a straight street along x (the paper's Street scene): building blocks of varied
//! height on both sides, kerbs, parked cars, lamp poles, trees (cone or sphere crowns) and
//! clutter (bins, benches). The corridor |y| < 6 m above 3 m is free for the lawnmower.

use crate::{TrajectoryKind, TrajectorySpec, TriangleMesh};
use nalgebra::{Point3, Vector3};

/// Building blocks (x start, x length, height) of the +y side; the -y side derives its own.
const BLOCKS: [(f64, f64, f64); 8] = [
    (-70.0, 14.0, 12.0),
    (-52.0, 18.0, 24.0),
    (-30.0, 12.0, 9.0),
    (-14.0, 16.0, 30.0),
    (6.0, 12.0, 15.0),
    (22.0, 20.0, 21.0),
    (46.0, 10.0, 8.0),
    (60.0, 14.0, 18.0),
];

/// A low box standing on the ground.
fn block(mesh: &mut TriangleMesh, centre_xy: (f64, f64), half: Vector3<f64>) {
    let c = Point3::new(centre_xy.0, centre_xy.1, half.z);
    mesh.push_box(c - half, c + half);
}

/// A tree at `(x, y)`: trunk plus a cone (`conifer`) or sphere crown.
fn tree(mesh: &mut TriangleMesh, x: f64, y: f64, conifer: bool) {
    mesh.push_cylinder(Point3::new(x, y, 0.0), Point3::new(x, y, 2.5), 0.2);
    if conifer {
        mesh.push_cone(
            Point3::new(x, y, 2.0),
            Point3::new(x, y, 7.0),
            1.6,
            Vector3::z_axis(),
        );
    } else {
        mesh.push_sphere(Point3::new(x, y, 4.0), 1.7);
    }
}

/// The street scene and its default flight: a 3-row lawnmower at 5 m over the street,
/// rows 50 m long and 3 m apart.
pub fn build() -> (TriangleMesh, TrajectorySpec) {
    let mut mesh = TriangleMesh::new();
    mesh.push_heightfield([-80.0, -40.0], [80.0, 40.0], 5.0, |_, _| 0.0);
    for side in [-1.0, 1.0] {
        for (k, &(x0, length, height)) in BLOCKS.iter().enumerate() {
            // The other side of the street is shifted by half a block and varies in height.
            let shift = if side > 0.0 { 0.0 } else { 5.0 };
            let height = if side > 0.0 {
                height
            } else {
                8.0 + (height * 7.0) % 20.0
            };
            let y0 = side * 11.0;
            let depth = 12.0 + 2.0 * (k % 3) as f64;
            let (ya, yb) = if side > 0.0 {
                (y0, y0 + depth)
            } else {
                (y0 - depth, y0)
            };
            mesh.push_box(
                Point3::new(x0 + shift, ya, 0.0),
                Point3::new(x0 + shift + length, yb, height),
            );
        }
        // Kerb along the street.
        mesh.push_box(
            Point3::new(-80.0, side * 6.0 - 0.2, 0.0),
            Point3::new(80.0, side * 6.0 + 0.2, 0.15),
        );
        for k in 0..14 {
            let x = -65.0 + 10.0 * k as f64;
            let pole_x = x + 0.5 * side;
            mesh.push_cylinder(
                Point3::new(pole_x, side * 7.0, 0.0),
                Point3::new(pole_x, side * 7.0, 7.0),
                0.12,
            );
            mesh.push_tube(
                Point3::new(pole_x, side * 7.0, 6.9),
                Point3::new(pole_x, side * 5.8, 6.9),
                0.06,
            );
            tree(
                &mut mesh,
                x + 5.0,
                side * 8.8,
                (k + (side > 0.0) as usize).is_multiple_of(3),
            );
            // Parked cars on the street edge, with gaps.
            if k % 4 != 1 {
                let car_x = x + 2.0 + side;
                block(&mut mesh, (car_x, side * 4.8), Vector3::new(2.2, 0.9, 0.75));
                block(
                    &mut mesh,
                    (car_x - 0.3, side * 4.8),
                    Vector3::new(1.1, 0.8, 1.3),
                );
            }
            // Clutter on the pavement: bins and benches.
            let clutter = if k % 2 == 0 {
                Vector3::new(0.3, 0.3, 0.5)
            } else {
                Vector3::new(0.9, 0.3, 0.25)
            };
            block(&mut mesh, (x + 8.0, side * 9.5), clutter);
        }
    }
    let trajectory = TrajectorySpec {
        kind: TrajectoryKind::Lawnmower,
        lanes: 3,
        lane_spacing_m: 3.0,
        ..TrajectorySpec::orbit(Point3::new(0.0, 0.0, 5.0), 25.0)
    };
    (mesh, trajectory)
}
