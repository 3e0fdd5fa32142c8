//! Shared mesh builders of the procedural scenes: boxes, tubes, cylinders, cones, spheres,
//! domes, tori and heightfield patches. Curved surfaces are tessellated so that facets are
//! about [`FACET_M`] wide, well below what a 20,000-ray frame resolves at 10 m.

use super::TriangleMesh;
use nalgebra::{Point3, Rotation3, Unit, UnitQuaternion, Vector3};
use std::f64::consts::{FRAC_PI_2, TAU};

/// Target facet size (m) of curved surfaces.
pub const FACET_M: f64 = 0.4;

/// Segments around a circle of radius `radius_m` (at least 8).
fn segments(radius_m: f64) -> usize {
    ((TAU * radius_m / FACET_M).ceil() as usize).clamp(8, 256)
}

/// Two unit vectors completing `axis` to an orthonormal frame.
fn frame_around(axis: &Unit<Vector3<f64>>) -> (Vector3<f64>, Vector3<f64>) {
    let helper = if axis.z.abs() < 0.9 {
        Vector3::z()
    } else {
        Vector3::x()
    };
    let u = axis.cross(&helper).normalize();
    (u, axis.cross(&u))
}

impl TriangleMesh {
    /// A closed box with the given orientation, centre and half extents (m).
    pub fn push_oriented_box(
        &mut self,
        centre: Point3<f64>,
        half_extents_m: Vector3<f64>,
        rotation: UnitQuaternion<f64>,
    ) {
        let corner = |sx: f64, sy: f64, sz: f64| {
            centre + rotation * half_extents_m.component_mul(&Vector3::new(sx, sy, sz))
        };
        let c = [
            corner(-1., -1., -1.),
            corner(1., -1., -1.),
            corner(1., 1., -1.),
            corner(-1., 1., -1.),
            corner(-1., -1., 1.),
            corner(1., -1., 1.),
            corner(1., 1., 1.),
            corner(-1., 1., 1.),
        ];
        for [a, b, cc, d] in [
            [0, 3, 2, 1],
            [4, 5, 6, 7],
            [0, 1, 5, 4],
            [1, 2, 6, 5],
            [2, 3, 7, 6],
            [3, 0, 4, 7],
        ] {
            self.push_quad(c[a], c[b], c[cc], c[d]);
        }
    }

    /// A closed axis-aligned box between two corners (m).
    pub fn push_box(&mut self, min: Point3<f64>, max: Point3<f64>) {
        let half = (max - min) * 0.5;
        self.push_oriented_box(min + half, half, UnitQuaternion::identity());
    }

    /// A closed square tube of side `2 half_width_m` from `a` to `b` (lattice members).
    pub fn push_tube(&mut self, a: Point3<f64>, b: Point3<f64>, half_width_m: f64) {
        let along = b - a;
        let rotation = UnitQuaternion::rotation_between(&Vector3::z(), &along)
            .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), TAU / 2.0));
        let half = Vector3::new(half_width_m, half_width_m, 0.5 * along.norm());
        self.push_oriented_box(nalgebra::center(&a, &b), half, rotation);
    }

    /// A cylinder of radius `radius_m` from `base` to `top`, with end caps.
    pub fn push_cylinder(&mut self, base: Point3<f64>, top: Point3<f64>, radius_m: f64) {
        let axis = Unit::new_normalize(top - base);
        let (u, v) = frame_around(&axis);
        let ring = |angle: f64| (u * angle.cos() + v * angle.sin()) * radius_m;
        self.push_grid(segments(radius_m), 1, |s, h| {
            base + (top - base) * h + ring(s * TAU)
        });
        for centre in [base, top] {
            self.push_cone(centre, centre, radius_m, axis);
        }
    }

    /// A cone (or, with `apex == base`, a flat disc) of base radius `radius_m` around `axis`.
    pub fn push_cone(
        &mut self,
        base: Point3<f64>,
        apex: Point3<f64>,
        radius_m: f64,
        axis: Unit<Vector3<f64>>,
    ) {
        let (u, v) = frame_around(&axis);
        let n = segments(radius_m);
        let tip = self.push_vertex(apex);
        let first = self.vertices.len();
        for k in 0..n {
            let angle = k as f64 / n as f64 * TAU;
            self.push_vertex(base + (u * angle.cos() + v * angle.sin()) * radius_m);
        }
        let rim = |k: usize| u32::try_from(first + k % n).unwrap_or(u32::MAX);
        self.triangles
            .extend((0..n).map(|k| [tip, rim(k), rim(k + 1)]));
    }

    /// A sphere of radius `radius_m`.
    pub fn push_sphere(&mut self, centre: Point3<f64>, radius_m: f64) {
        self.push_spherical_cap(centre, radius_m, -FRAC_PI_2);
    }

    /// The upper half of a sphere, closed by its base disc (a dome on the ground).
    pub fn push_dome(&mut self, centre: Point3<f64>, radius_m: f64) {
        self.push_spherical_cap(centre, radius_m, 0.0);
        self.push_cone(centre, centre, radius_m, Vector3::z_axis());
    }

    /// The part of a sphere above latitude `lowest_rad`.
    fn push_spherical_cap(&mut self, centre: Point3<f64>, radius_m: f64, lowest_rad: f64) {
        let around = segments(radius_m);
        let rings = (around / 2).max(4);
        self.push_grid(around, rings, |s, t| {
            let lat = lowest_rad + t * (FRAC_PI_2 - lowest_rad);
            let lon = s * TAU;
            centre
                + Vector3::new(lat.cos() * lon.cos(), lat.cos() * lon.sin(), lat.sin()) * radius_m
        });
    }

    /// A torus around the vertical axis through `centre` (major and minor radius, m).
    pub fn push_torus(&mut self, centre: Point3<f64>, major_m: f64, minor_m: f64) {
        self.push_grid(segments(major_m), segments(minor_m), |s, t| {
            let (u, v) = (s * TAU, t * TAU);
            let radial = Vector3::new(u.cos(), u.sin(), 0.0);
            centre + radial * (major_m + minor_m * v.cos()) + Vector3::z() * (minor_m * v.sin())
        });
    }

    /// A heightfield patch `z = height(x, y)` over `[min.x, max.x] x [min.y, max.y]`, with
    /// cells about `cell_m` wide.
    pub fn push_heightfield(
        &mut self,
        min: [f64; 2],
        max: [f64; 2],
        cell_m: f64,
        height: impl Fn(f64, f64) -> f64,
    ) {
        let cells = |lo: f64, hi: f64| (((hi - lo) / cell_m).ceil() as usize).clamp(1, 1024);
        self.push_grid(cells(min[0], max[0]), cells(min[1], max[1]), |s, t| {
            let x = min[0] + s * (max[0] - min[0]);
            let y = min[1] + t * (max[1] - min[1]);
            Point3::new(x, y, height(x, y))
        });
    }

    /// Rotates every vertex by `yaw_rad` about the vertical axis through `pivot`.
    pub fn rotate_about_z(&mut self, pivot: Point3<f64>, yaw_rad: f64) {
        let rotation = Rotation3::from_axis_angle(&Vector3::z_axis(), yaw_rad);
        for v in &mut self.vertices {
            *v = pivot + rotation * (*v - pivot);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn areas_match_the_analytic_shapes() {
        let area = |build: &dyn Fn(&mut TriangleMesh)| {
            let mut m = TriangleMesh::new();
            build(&mut m);
            m.area_m2()
        };
        let boxed = area(&|m| m.push_box(Point3::origin(), Point3::new(1.0, 2.0, 3.0)));
        assert!((boxed - 22.0).abs() < 1e-9);
        let tube = area(&|m| m.push_tube(Point3::origin(), Point3::new(3.0, 4.0, 0.0), 0.1));
        assert!((tube - (4.0 * 0.2 * 5.0 + 2.0 * 0.04)).abs() < 1e-9);
        let sphere = area(&|m| m.push_sphere(Point3::origin(), 2.0));
        assert!((sphere / (4.0 * PI * 4.0) - 1.0).abs() < 0.01, "{sphere}");
        let torus = area(&|m| m.push_torus(Point3::origin(), 3.0, 1.0));
        assert!(
            (torus / (4.0 * PI * PI * 3.0) - 1.0).abs() < 0.01,
            "{torus}"
        );
        let cylinder = area(&|m| m.push_cylinder(Point3::origin(), Point3::new(0., 0., 2.), 1.0));
        // 16 segments: the inscribed caps lose 2.6 % of their area.
        assert!(
            (cylinder / (2.0 * PI * 2.0 + 2.0 * PI) - 1.0).abs() < 0.02,
            "{cylinder}"
        );
    }
}
