//! `truss`: a construction site around a tower crane (the paper's Crane scene): a lattice mast
//! and jib of thin square tubes (0.3 m chords, 0.2 m braces), building frames of columns,
//! floor slabs and concrete cores, site containers, a fence and a ground.

use crate::{TrajectorySpec, TriangleMesh};
use nalgebra::{Point3, Vector3};

/// Half widths (m) of the main chords and of the braces.
const CHORD_HALF_M: f64 = 0.15;
const BRACE_HALF_M: f64 = 0.1;

/// A straight lattice girder: `corners` chords running from each corner offset at `start`
/// along `along`, with a ring of braces and one diagonal per face every `bay_m`.
fn lattice(
    mesh: &mut TriangleMesh,
    start: Point3<f64>,
    along: Vector3<f64>,
    corners: &[Vector3<f64>],
    bay_m: f64,
) {
    let length = along.norm();
    let bays = (length / bay_m).round().max(1.0) as usize;
    let step = along / bays as f64;
    for c in corners {
        mesh.push_tube(start + c, start + c + along, CHORD_HALF_M);
    }
    for b in 0..=bays {
        let base = start + step * b as f64;
        for (i, c) in corners.iter().enumerate() {
            let next = corners[(i + 1) % corners.len()];
            mesh.push_tube(base + c, base + next, BRACE_HALF_M);
            if b < bays {
                // Diagonals alternate direction bay by bay, as in a Warren truss.
                let (from, to) = if b % 2 == 0 { (c, &next) } else { (&next, c) };
                mesh.push_tube(base + from, base + step + to, BRACE_HALF_M);
            }
        }
    }
}

/// The tower crane with its foot at `at`: a 36 m mast, a 40 m jib along +x, a 12 m
/// counter-jib with its counterweight, and the cab.
fn crane(mesh: &mut TriangleMesh, at: Point3<f64>) {
    let h = 1.2;
    let square = [
        Vector3::new(-h, -h, 0.0),
        Vector3::new(h, -h, 0.0),
        Vector3::new(h, h, 0.0),
        Vector3::new(-h, h, 0.0),
    ];
    mesh.push_box(
        at + Vector3::new(-3.0, -3.0, -0.5),
        at + Vector3::new(3.0, 3.0, 1.0),
    );
    lattice(
        mesh,
        at + Vector3::z(),
        Vector3::new(0.0, 0.0, 35.0),
        &square,
        3.0,
    );
    let top = at + Vector3::new(0.0, 0.0, 36.0);
    let triangle = [
        Vector3::new(0.0, -1.0, 0.0),
        Vector3::new(0.0, 1.0, 0.0),
        Vector3::new(0.0, 0.0, 2.0),
    ];
    lattice(
        mesh,
        top + Vector3::new(h, 0.0, 0.0),
        Vector3::new(40.0, 0.0, 0.0),
        &triangle,
        2.5,
    );
    lattice(
        mesh,
        top - Vector3::new(h, 0.0, 0.0),
        Vector3::new(-12.0, 0.0, 0.0),
        &triangle,
        2.5,
    );
    mesh.push_box(
        top + Vector3::new(-13.0, -1.5, -2.5),
        top + Vector3::new(-9.0, 1.5, 0.0),
    );
    mesh.push_box(
        top + Vector3::new(-h, h, -2.0),
        top + Vector3::new(h, h + 2.2, 0.5),
    );
    // The apex tower and its ties.
    let apex = top + Vector3::new(0.0, 0.0, 7.0);
    for c in &square {
        mesh.push_tube(top + c, apex, CHORD_HALF_M);
    }
    mesh.push_tube(apex, top + Vector3::new(30.0, 0.0, 2.0), 0.05);
    mesh.push_tube(apex, top + Vector3::new(-12.0, 0.0, 2.0), 0.05);
}

/// A building under construction: a grid of columns, `floors` floor slabs (the top one half
/// poured) and a concrete core (lift shaft) rising two storeys above them.
fn building_frame(mesh: &mut TriangleMesh, min: Point3<f64>, bays: (usize, usize), floors: usize) {
    let (bay_m, storey_m) = (6.0, 3.5);
    for i in 0..=bays.0 {
        for j in 0..=bays.1 {
            let foot = min + Vector3::new(i as f64 * bay_m, j as f64 * bay_m, 0.0);
            mesh.push_tube(
                foot,
                foot + Vector3::new(0.0, 0.0, floors as f64 * storey_m),
                0.2,
            );
        }
    }
    let size = Vector3::new(bays.0 as f64 * bay_m, bays.1 as f64 * bay_m, 0.0);
    for floor in 1..=floors {
        let z = floor as f64 * storey_m;
        let x_end = if floor == floors { 0.5 } else { 1.0 };
        mesh.push_box(
            min + Vector3::new(-0.3, -0.3, z - 0.3),
            min + Vector3::new(size.x * x_end + 0.3, size.y + 0.3, z),
        );
    }
    let core = min + Vector3::new(bay_m, bay_m, 0.0);
    let top = (floors + 2) as f64 * storey_m;
    mesh.push_box(core, core + Vector3::new(4.0, 5.0, top));
}

/// The truss scene and its default orbit: 9 m around the mast at 10 m.
pub fn build() -> (TriangleMesh, TrajectorySpec) {
    let mut mesh = TriangleMesh::new();
    mesh.push_heightfield([-60.0, -60.0], [60.0, 60.0], 5.0, |_, _| 0.0);
    crane(&mut mesh, Point3::origin());
    building_frame(&mut mesh, Point3::new(14.0, -9.0, 0.0), (3, 3), 6);
    building_frame(&mut mesh, Point3::new(-26.0, 6.0, 0.0), (2, 2), 4);
    building_frame(&mut mesh, Point3::new(-12.0, -34.0, 0.0), (4, 2), 5);
    building_frame(&mut mesh, Point3::new(-4.0, 16.0, 0.0), (3, 1), 7);
    for (x, y, along_x) in [
        (-16.0, -14.0, true),
        (-9.0, -16.0, false),
        (5.0, 17.0, true),
        (-20.0, -4.0, false),
    ] {
        let half = if along_x {
            Vector3::new(3.0, 1.2, 1.3)
        } else {
            Vector3::new(1.2, 3.0, 1.3)
        };
        let centre = Point3::new(x, y, 1.3);
        mesh.push_box(centre - half, centre + half);
    }
    // A site fence of posts and rails along the north edge.
    for k in 0..20 {
        let x = -30.0 + 3.0 * k as f64;
        mesh.push_tube(Point3::new(x, 28.0, 0.0), Point3::new(x, 28.0, 2.0), 0.05);
        mesh.push_tube(
            Point3::new(x, 28.0, 1.8),
            Point3::new(x + 3.0, 28.0, 1.8),
            0.04,
        );
    }
    (
        mesh,
        TrajectorySpec::orbit(Point3::new(0.0, 0.0, 10.0), 9.0),
    )
}
