//! Analytic surfaces to sample points from: each gives an area-proportional random point and
//! its outward unit normal.

use nalgebra::{Point3, Vector3};
use rand::Rng;
use std::f64::consts::TAU;

/// A closed-form surface of the synthetic scene.
#[derive(Debug, Clone, Copy)]
pub enum Shape {
    /// Sphere (centre, radius m).
    Sphere { centre: Point3<f64>, radius_m: f64 },
    /// Cylinder along `axis` (unit) from `base`, length and radius in m.
    Cylinder {
        base: Point3<f64>,
        axis: Vector3<f64>,
        length_m: f64,
        radius_m: f64,
    },
    /// Torus around the vertical axis through `centre`.
    Torus {
        centre: Point3<f64>,
        major_m: f64,
        minor_m: f64,
    },
    /// Paraboloid ground `z = curvature (x^2 + y^2)` over a disc of radius `extent_m`.
    Bowl { curvature: f64, extent_m: f64 },
}

/// Unit vector orthogonal to `v`.
fn orthogonal(v: &Vector3<f64>) -> Vector3<f64> {
    let helper = if v.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    v.cross(&helper).normalize()
}

impl Shape {
    /// Approximate area (m^2), to share points between shapes.
    pub fn area_m2(&self) -> f64 {
        match *self {
            Shape::Sphere { radius_m, .. } => 2.0 * TAU * radius_m * radius_m,
            Shape::Cylinder {
                length_m, radius_m, ..
            } => TAU * radius_m * length_m,
            Shape::Torus {
                major_m, minor_m, ..
            } => TAU * TAU * major_m * minor_m,
            Shape::Bowl { extent_m, .. } => 0.5 * TAU * extent_m * extent_m,
        }
    }

    /// A random point on the surface and the outward normal there.
    pub fn sample(&self, rng: &mut impl Rng) -> (Point3<f64>, Vector3<f64>) {
        match *self {
            Shape::Sphere { centre, radius_m } => {
                let z: f64 = rng.random_range(-1.0..1.0);
                let phi = rng.random_range(0.0..TAU);
                let r = (1.0 - z * z).sqrt();
                let n = Vector3::new(r * phi.cos(), r * phi.sin(), z);
                (centre + n * radius_m, n)
            }
            Shape::Cylinder {
                base,
                axis,
                length_m,
                radius_m,
            } => {
                let u = orthogonal(&axis);
                let v = axis.cross(&u);
                let phi = rng.random_range(0.0..TAU);
                let n = u * phi.cos() + v * phi.sin();
                (
                    base + axis * rng.random_range(0.0..length_m) + n * radius_m,
                    n,
                )
            }
            Shape::Torus {
                centre,
                major_m,
                minor_m,
            } => loop {
                // Rejection keeps the density uniform in area.
                let (u, v) = (rng.random_range(0.0..TAU), rng.random_range(0.0..TAU));
                let keep = (major_m + minor_m * v.cos()) / (major_m + minor_m);
                if rng.random_range(0.0..1.0) <= keep {
                    let radial = Vector3::new(u.cos(), u.sin(), 0.0);
                    let n = radial * v.cos() + Vector3::z() * v.sin();
                    break (centre + radial * major_m + n * minor_m, n);
                }
            },
            Shape::Bowl {
                curvature,
                extent_m,
            } => {
                let r = extent_m * rng.random_range(0.0f64..1.0).sqrt();
                let phi = rng.random_range(0.0..TAU);
                let (x, y) = (r * phi.cos(), r * phi.sin());
                let n = Vector3::new(-2.0 * curvature * x, -2.0 * curvature * y, 1.0).normalize();
                (Point3::new(x, y, curvature * (x * x + y * y)), n)
            }
        }
    }
}
