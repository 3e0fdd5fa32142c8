//! `hangar`: a barrel-vault hangar (the paper's Hangar scene, unavailable as a mesh) with an
//! aircraft-like body inside. The vault's curved sides come down to the floor, the back wall
//! is closed, the front has a wide door opening.

use crate::{TrajectorySpec, TriangleMesh};
use nalgebra::{Point3, UnitQuaternion, Vector3};
use std::f64::consts::PI;

/// Half length (along x), half span (along y) and crown height of the vault (m).
const HALF_LENGTH_M: f64 = 28.0;
const HALF_SPAN_M: f64 = 20.0;
const CROWN_M: f64 = 15.0;

/// Point of the vault's (elliptic) cross-section at angle `a` (0 = floor at +y, pi = -y).
fn arch(a: f64) -> (f64, f64) {
    (HALF_SPAN_M * a.cos(), CROWN_M * a.sin())
}

/// An end wall at `x` filling the arch, as a fan from the floor centre; with `door_half_m`
/// a central opening that wide and 70 % of the crown high is left out.
fn end_wall(mesh: &mut TriangleMesh, x: f64, door_half_m: Option<f64>) {
    let steps = 48;
    let door_top = 0.7 * CROWN_M;
    for k in 0..steps {
        let (y0, z0) = arch(PI * k as f64 / steps as f64);
        let (y1, z1) = arch(PI * (k + 1) as f64 / steps as f64);
        match door_half_m {
            None => mesh.push_triangle(
                Point3::new(x, 0.0, 0.0),
                Point3::new(x, y0, z0),
                Point3::new(x, y1, z1),
            ),
            // With a door: fill between the arch and the door's outline (a box of
            // half-width `d`, height `door_top`), radially from the floor centre.
            Some(d) => {
                let inner = |y: f64, z: f64| {
                    let s = (d / y.abs().max(1e-9)).min(door_top / z.max(1e-9));
                    Point3::new(x, y * s.min(1.0), z * s.min(1.0))
                };
                mesh.push_quad(
                    inner(y0, z0),
                    Point3::new(x, y0, z0),
                    Point3::new(x, y1, z1),
                    inner(y1, z1),
                );
            }
        }
    }
}

/// The aircraft: fuselage cylinder with a dome nose and a cone tail, swept wings, tailplane
/// and fin, standing on the floor on three gear legs. Nose points to -x, centred at `at`.
fn aircraft(mesh: &mut TriangleMesh, at: Point3<f64>) {
    let body_r = 1.8;
    let (nose_x, tail_x) = (at.x - 11.0, at.x + 11.0);
    let axis_z = at.z;
    mesh.push_cylinder(
        Point3::new(nose_x, at.y, axis_z),
        Point3::new(tail_x, at.y, axis_z),
        body_r,
    );
    mesh.push_sphere(Point3::new(nose_x, at.y, axis_z), body_r);
    mesh.push_cone(
        Point3::new(tail_x, at.y, axis_z),
        Point3::new(tail_x + 5.0, at.y, axis_z + 1.0),
        body_r,
        Vector3::x_axis(),
    );
    for side in [-1.0, 1.0] {
        let sweep = UnitQuaternion::from_euler_angles(0.0, 0.0, side * 0.35);
        let wing_centre = Point3::new(at.x + 2.5, at.y + side * 7.5, axis_z - 0.8);
        mesh.push_oriented_box(wing_centre, Vector3::new(1.8, 6.5, 0.2), sweep);
        let tailplane = Point3::new(tail_x + 2.5, at.y + side * 3.0, axis_z + 0.6);
        mesh.push_oriented_box(tailplane, Vector3::new(0.9, 2.4, 0.12), sweep);
    }
    mesh.push_oriented_box(
        Point3::new(tail_x + 2.6, at.y, axis_z + 3.2),
        Vector3::new(1.4, 0.15, 2.2),
        UnitQuaternion::from_euler_angles(0.0, -0.35, 0.0),
    );
    for (dx, dy) in [(-8.0, 0.0), (3.0, -2.5), (3.0, 2.5)] {
        let top = Point3::new(at.x + dx, at.y + dy, axis_z - body_r + 0.2);
        mesh.push_cylinder(Point3::new(top.x, top.y, 0.0), top, 0.25);
    }
}

/// The hangar mesh and its default flight: an orbit of 10 m around the aircraft at 8.5 m,
/// above the wings and below the vault.
pub fn build() -> (TriangleMesh, TrajectorySpec) {
    let mut mesh = TriangleMesh::new();
    mesh.push_heightfield(
        [-HALF_LENGTH_M, -HALF_SPAN_M],
        [HALF_LENGTH_M, HALF_SPAN_M],
        4.0,
        |_, _| 0.0,
    );
    mesh.push_grid(40, 64, |u, v| {
        let (y, z) = arch(PI * v);
        Point3::new(-HALF_LENGTH_M + 2.0 * HALF_LENGTH_M * u, y, z)
    });
    // Ribs under the vault every 7 m: the regular structure of a real hangar.
    for k in -3..=3 {
        let x = 7.0 * k as f64;
        for s in 0..24 {
            let (y0, z0) = arch(PI * s as f64 / 24.0);
            let (y1, z1) = arch(PI * (s + 1) as f64 / 24.0);
            let inset = 0.93;
            mesh.push_tube(
                Point3::new(x, inset * y0, inset * z0),
                Point3::new(x, inset * y1, inset * z1),
                0.2,
            );
        }
    }
    end_wall(&mut mesh, HALF_LENGTH_M, None);
    end_wall(&mut mesh, -HALF_LENGTH_M, Some(12.0));
    aircraft(&mut mesh, Point3::new(0.0, 0.0, 3.0));
    for (x, y, size) in [
        (-18.0, 14.0, 1.2),
        (16.0, -13.0, 1.6),
        (20.0, 12.0, 1.0),
        (-20.0, -12.0, 2.0),
    ] {
        mesh.push_box(
            Point3::new(x - size, y - size, 0.0),
            Point3::new(x + size, y + size, size * 1.5),
        );
    }
    let trajectory = TrajectorySpec::orbit(Point3::new(0.0, 0.0, 8.5), 10.0);
    (mesh, trajectory)
}
