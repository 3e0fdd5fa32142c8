//! `curved`: domes, cylinders, tori, a sphere and a saddle-roofed hall on an undulating
//! ground: the curved, irregular surfaces PSS-BA's polynomial kernels are meant for. The ring
//! 9-17 m from the origin is kept free up to 8 m for the default orbit; a far ring of silos
//! closes the view, a shallow shell canopy spans the middle.

use crate::{TrajectorySpec, TriangleMesh};
use nalgebra::Point3;

/// Height (m) of the ground at `(x, y)`: gentle waves of +-0.3 m.
pub fn ground_z(x: f64, y: f64) -> f64 {
    0.3 * (x / 9.0).sin() * (y / 11.0).cos()
}

/// A hall with a hyperbolic-paraboloid (saddle) roof: walls of `half_m` half-width around
/// `(cx, cy)`, eaves at `eaves_m`, roof `z = eaves + k (x'^2 - y'^2) + rise`.
fn saddle_hall(mesh: &mut TriangleMesh, cx: f64, cy: f64, half_m: f64, eaves_m: f64) {
    let k = 1.5 / (half_m * half_m);
    let roof = move |x: f64, y: f64| eaves_m + 1.5 + k * ((x - cx).powi(2) - (y - cy).powi(2));
    mesh.push_heightfield(
        [cx - half_m, cy - half_m],
        [cx + half_m, cy + half_m],
        0.5,
        roof,
    );
    // Walls up to the roof edge, one strip per side.
    for (a, b) in [
        ([-1.0, -1.0], [1.0, -1.0]),
        ([1.0, -1.0], [1.0, 1.0]),
        ([1.0, 1.0], [-1.0, 1.0]),
        ([-1.0, 1.0], [-1.0, -1.0]),
    ] {
        mesh.push_grid(16, 1, |s, h| {
            let x = cx + half_m * (a[0] + s * (b[0] - a[0]));
            let y = cy + half_m * (a[1] + s * (b[1] - a[1]));
            Point3::new(x, y, h * roof(x, y) - 0.2)
        });
    }
}

/// The curved scene and its default orbit: 13 m around the origin at 4.5 m.
pub fn build() -> (TriangleMesh, TrajectorySpec) {
    let mut mesh = TriangleMesh::new();
    mesh.push_heightfield([-55.0, -55.0], [55.0, 55.0], 1.5, ground_z);
    let on_ground = |x: f64, y: f64, z: f64| Point3::new(x, y, z + ground_z(x, y) - 0.1);

    // Centre (within 8 m): a dome, a tank, a lying pipe and a small torus.
    mesh.push_dome(on_ground(0.0, 0.0, 0.0), 5.0);
    mesh.push_cylinder(on_ground(4.0, 4.5, 0.0), on_ground(4.0, 4.5, 9.0), 1.5);
    mesh.push_cylinder(on_ground(-6.5, 1.0, 1.0), on_ground(-3.5, 6.5, 1.0), 1.0);
    mesh.push_torus(on_ground(2.5, -5.0, 0.7), 2.0, 0.7);
    mesh.push_sphere(on_ground(-4.0, -4.5, 1.6), 1.6);

    // Outer ring (beyond 18 m): larger and taller curved bodies.
    mesh.push_dome(on_ground(-24.0, 10.0, 0.0), 7.0);
    mesh.push_dome(on_ground(10.0, 24.0, 0.0), 4.0);
    for (x, y, r, h) in [
        (5.0, -22.0, 3.0, 14.0),
        (-13.0, -20.0, 2.5, 11.0),
        (21.0, 14.0, 1.2, 18.0),
    ] {
        mesh.push_cylinder(on_ground(x, y, 0.0), on_ground(x, y, h), r);
    }
    mesh.push_cylinder(on_ground(16.0, -17.0, 1.5), on_ground(27.0, -6.0, 1.5), 1.4);
    mesh.push_torus(on_ground(-6.0, 24.0, 1.5), 5.0, 1.5);
    mesh.push_torus(on_ground(-22.0, -12.0, 6.0), 3.0, 0.5);
    mesh.push_cylinder(
        on_ground(-22.0, -12.0, 0.0),
        on_ground(-22.0, -12.0, 5.5),
        0.3,
    );
    mesh.push_sphere(on_ground(-20.0, -3.0, 3.0), 3.0);
    saddle_hall(&mut mesh, 25.0, 3.0, 5.0, 6.0);
    // Far ring (34 m): silos with domed tops, tall enough for the upper half of the FoV.
    for (angle_deg, height_m) in [
        (45.0f64, 18.0),
        (135.0, 22.0),
        (-45.0, 16.0),
        (-100.0, 20.0),
        (180.0, 24.0),
        (80.0, 17.0),
    ] {
        let a = angle_deg.to_radians();
        let (x, y) = (34.0 * a.cos(), 34.0 * a.sin());
        mesh.push_cylinder(on_ground(x, y, 0.0), on_ground(x, y, height_m), 4.0);
        mesh.push_dome(on_ground(x, y, height_m), 4.0);
    }
    // A shell canopy over the middle: a spherical cap (sphere radius 60 m) 22 m high at its
    // crown and 26 m in radius, on six columns.
    mesh.push_grid(24, 96, |u, v| {
        let (r, a) = (26.0 * u, std::f64::consts::TAU * v);
        Point3::new(
            r * a.cos(),
            r * a.sin(),
            22.0 - (60.0 - (3600.0 - r * r).sqrt()),
        )
    });
    for k in 0..6 {
        let a = std::f64::consts::TAU * (k as f64 + 0.5) / 6.0;
        let (x, y) = (25.0 * a.cos(), 25.0 * a.sin());
        mesh.push_cylinder(on_ground(x, y, 0.0), Point3::new(x, y, 17.0), 0.5);
    }
    // A vaulted shed: a half cylinder lying along y.
    mesh.push_grid(24, 16, |u, v| {
        let a = std::f64::consts::PI * u;
        Point3::new(4.0 + 3.5 * a.cos(), -40.0 + 14.0 * v, 3.5 * a.sin())
    });
    (
        mesh,
        TrajectorySpec::orbit(Point3::new(0.0, 0.0, 4.5), 13.0),
    )
}
