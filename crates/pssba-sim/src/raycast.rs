//! Ray casting against a triangle mesh through parry's BVH (DESIGN.md section 4: the
//! simulated sensor sees the first surface along each ray).

use crate::TriangleMesh;
use nalgebra::{Point3, Vector3};
use parry3d_f64::query::{Ray, RayCast};
use parry3d_f64::shape::TriMesh;
use rayon::prelude::*;

/// Why a mesh cannot be ray-cast.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RaycastError {
    /// The mesh has no triangle.
    #[error("the mesh has no triangles")]
    EmptyMesh,
    /// A triangle refers to a vertex past the end of the vertex buffer.
    #[error("triangle {triangle} refers to a missing vertex")]
    BadIndex {
        /// 0-based triangle.
        triangle: usize,
    },
    /// A vertex is NaN or infinite.
    #[error("vertex {vertex} is not finite")]
    NonFiniteVertex {
        /// 0-based vertex.
        vertex: usize,
    },
}

/// A mesh prepared for ray casting (a BVH over its triangles).
#[derive(Debug, Clone)]
pub struct Raycaster {
    trimesh: TriMesh,
}

impl Raycaster {
    /// Builds the BVH. Fails on an empty mesh, an out-of-range index or a non-finite vertex.
    pub fn new(mesh: &TriangleMesh) -> Result<Self, RaycastError> {
        if mesh.is_empty() {
            return Err(RaycastError::EmptyMesh);
        }
        if let Some(vertex) = mesh
            .vertices
            .iter()
            .position(|v| !v.coords.iter().all(|c| c.is_finite()))
        {
            return Err(RaycastError::NonFiniteVertex { vertex });
        }
        let count = mesh.vertices.len();
        if let Some(triangle) = mesh
            .triangles
            .iter()
            .position(|t| t.iter().any(|&i| i as usize >= count))
        {
            return Err(RaycastError::BadIndex { triangle });
        }
        let trimesh = TriMesh::new(mesh.vertices.clone(), mesh.triangles.clone())
            .map_err(|_| RaycastError::EmptyMesh)?;
        Ok(Self { trimesh })
    }

    /// Distance (m) along the unit direction `dir` from `origin` to the first surface, if one
    /// lies within `max_range_m`. Both faces of a triangle count.
    pub fn cast(&self, origin: &Point3<f64>, dir: &Vector3<f64>, max_range_m: f64) -> Option<f64> {
        self.trimesh
            .cast_local_ray(&Ray::new(*origin, *dir), max_range_m, false)
    }

    /// [`Raycaster::cast`] with the unit normal of the surface hit (its sign is arbitrary).
    pub fn cast_with_normal(
        &self,
        origin: &Point3<f64>,
        dir: &Vector3<f64>,
        max_range_m: f64,
    ) -> Option<(f64, Vector3<f64>)> {
        self.trimesh
            .cast_local_ray_and_get_normal(&Ray::new(*origin, *dir), max_range_m, false)
            .map(|hit| (hit.time_of_impact, hit.normal))
    }

    /// [`Raycaster::cast`] for many unit directions from one origin, in order; rayon-parallel
    /// when `parallel` (the result is identical to the serial one).
    pub fn cast_all(
        &self,
        origin: &Point3<f64>,
        dirs: &[Vector3<f64>],
        max_range_m: f64,
        parallel: bool,
    ) -> Vec<Option<f64>> {
        let one = |dir: &Vector3<f64>| self.cast(origin, dir, max_range_m);
        if parallel {
            dirs.par_iter().with_min_len(256).map(one).collect()
        } else {
            dirs.iter().map(one).collect()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_box() -> Raycaster {
        let mut mesh = TriangleMesh::new();
        mesh.push_box(Point3::new(-0.5, -0.5, -0.5), Point3::new(0.5, 0.5, 0.5));
        Raycaster::new(&mesh).expect("box")
    }

    #[test]
    fn box_and_plane_give_the_analytic_distance() {
        let caster = unit_box();
        let from_outside = caster.cast(&Point3::new(-3.0, 0.1, 0.2), &Vector3::x(), 70.0);
        assert!((from_outside.expect("hit") - 2.5).abs() < 1e-12);
        let (range_m, normal) = caster
            .cast_with_normal(&Point3::new(-3.0, 0.1, 0.2), &Vector3::x(), 70.0)
            .expect("hit");
        assert!((range_m - 2.5).abs() < 1e-12);
        assert!((normal.x.abs() - 1.0).abs() < 1e-12, "{normal}");
        // From inside, the far face at 0.5 m, along a diagonal through a face.
        let dir = Vector3::new(1.0, 0.5, 0.0).normalize();
        let inside = caster.cast(&Point3::origin(), &dir, 70.0).expect("hit");
        assert!((inside - 0.5 / dir.x).abs() < 1e-12);
        assert_eq!(
            caster.cast(&Point3::new(-3.0, 0.0, 0.0), &-Vector3::x(), 70.0),
            None
        );
        assert_eq!(
            caster.cast(&Point3::new(-3.0, 0.0, 0.0), &Vector3::x(), 2.0),
            None
        );

        let mut plane = TriangleMesh::new();
        plane.push_heightfield([-50.0, -50.0], [50.0, 50.0], 5.0, |_, _| 0.0);
        let plane = Raycaster::new(&plane).expect("plane");
        let elevation = (-20f64).to_radians();
        let dir = Vector3::new(elevation.cos(), 0.3 * elevation.cos(), elevation.sin()).normalize();
        let range = plane
            .cast(&Point3::new(1.0, 2.0, 3.0), &dir, 70.0)
            .expect("hit");
        assert!((range - 3.0 / -dir.z).abs() < 1e-9, "{range}");
    }

    #[test]
    fn parallel_equals_serial() {
        let caster = unit_box();
        let dirs: Vec<_> = (0..5000)
            .map(|k| {
                let a = k as f64 * 0.37;
                Vector3::new(a.cos(), a.sin(), (k as f64 * 0.011).sin()).normalize()
            })
            .collect();
        let origin = Point3::new(0.1, -0.2, 0.05);
        assert_eq!(
            caster.cast_all(&origin, &dirs, 70.0, true),
            caster.cast_all(&origin, &dirs, 70.0, false)
        );
    }

    #[test]
    fn bad_meshes_are_errors() {
        assert_eq!(
            Raycaster::new(&TriangleMesh::new()).err(),
            Some(RaycastError::EmptyMesh)
        );
        let mut mesh = TriangleMesh::new();
        mesh.push_triangle(
            Point3::origin(),
            Point3::new(f64::NAN, 0.0, 0.0),
            Point3::origin(),
        );
        assert_eq!(
            Raycaster::new(&mesh).err(),
            Some(RaycastError::NonFiniteVertex { vertex: 1 })
        );
    }
}
