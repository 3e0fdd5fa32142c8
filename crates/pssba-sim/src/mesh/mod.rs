//! Triangle meshes for ray-cast scenes (DESIGN.md section 4): an indexed vertex/triangle
//! buffer plus the shared builders ([`primitives`]) the procedural scenes are made of.

mod primitives;

use nalgebra::{Point3, Vector3};

/// An indexed triangle mesh in world coordinates (m). Orientation of the triangles does not
/// matter: rays hit both faces.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriangleMesh {
    /// Vertex positions (m).
    pub vertices: Vec<Point3<f64>>,
    /// Triangles as indices into `vertices`.
    pub triangles: Vec<[u32; 3]>,
}

/// An axis-aligned box (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Smallest corner.
    pub min: Point3<f64>,
    /// Largest corner.
    pub max: Point3<f64>,
}

impl Aabb {
    /// Centre of the box.
    pub fn centre(&self) -> Point3<f64> {
        nalgebra::center(&self.min, &self.max)
    }

    /// Edge lengths (m).
    pub fn extent(&self) -> Vector3<f64> {
        self.max - self.min
    }
}

impl TriangleMesh {
    /// An empty mesh.
    pub fn new() -> Self {
        Self::default()
    }

    /// A mesh from a triangle soup (e.g. an STL file): three fresh vertices per triangle.
    pub fn from_triangles(triangles: &[[Point3<f64>; 3]]) -> Self {
        let mut mesh = Self::new();
        for t in triangles {
            mesh.push_triangle(t[0], t[1], t[2]);
        }
        mesh
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.triangles.len()
    }

    /// True if the mesh has no triangle.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// Adds a vertex and returns its index.
    pub fn push_vertex(&mut self, p: Point3<f64>) -> u32 {
        let index = u32::try_from(self.vertices.len()).unwrap_or(u32::MAX);
        self.vertices.push(p);
        index
    }

    /// Adds one triangle with its own three vertices.
    pub fn push_triangle(&mut self, a: Point3<f64>, b: Point3<f64>, c: Point3<f64>) {
        let (ia, ib, ic) = (
            self.push_vertex(a),
            self.push_vertex(b),
            self.push_vertex(c),
        );
        self.triangles.push([ia, ib, ic]);
    }

    /// Adds the quad `a b c d` (in order around its edge) as two triangles.
    pub fn push_quad(&mut self, a: Point3<f64>, b: Point3<f64>, c: Point3<f64>, d: Point3<f64>) {
        let [ia, ib, ic, id] = [a, b, c, d].map(|p| self.push_vertex(p));
        self.triangles.push([ia, ib, ic]);
        self.triangles.push([ia, ic, id]);
    }

    /// Appends all triangles of `other`.
    pub fn append(&mut self, other: &TriangleMesh) {
        let offset = u32::try_from(self.vertices.len()).unwrap_or(u32::MAX);
        self.vertices.extend_from_slice(&other.vertices);
        self.triangles.extend(
            other
                .triangles
                .iter()
                .map(|t| t.map(|i| i.saturating_add(offset))),
        );
    }

    /// A surface sampled on a `nu x nv` grid of `(u, v)` in `[0, 1]^2`, `point(u, v)` giving
    /// the position: the common builder of spheres, tori, vaults and heightfields.
    pub fn push_grid(
        &mut self,
        nu: usize,
        nv: usize,
        mut point: impl FnMut(f64, f64) -> Point3<f64>,
    ) {
        let (nu, nv) = (nu.max(1), nv.max(1));
        let first = self.vertices.len();
        for i in 0..=nu {
            for j in 0..=nv {
                self.vertices
                    .push(point(i as f64 / nu as f64, j as f64 / nv as f64));
            }
        }
        let index =
            |i: usize, j: usize| u32::try_from(first + i * (nv + 1) + j).unwrap_or(u32::MAX);
        for i in 0..nu {
            for j in 0..nv {
                let (a, b) = (index(i, j), index(i + 1, j));
                let (c, d) = (index(i + 1, j + 1), index(i, j + 1));
                self.triangles.push([a, b, c]);
                self.triangles.push([a, c, d]);
            }
        }
    }

    /// Bounding box of the vertices, `None` for an empty mesh.
    pub fn bounding_box(&self) -> Option<Aabb> {
        let first = *self.vertices.first()?;
        let mut aabb = Aabb {
            min: first,
            max: first,
        };
        for v in &self.vertices {
            aabb.min = aabb.min.inf(v);
            aabb.max = aabb.max.sup(v);
        }
        Some(aabb)
    }

    /// Total surface area (m^2).
    pub fn area_m2(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.vertices[i as usize]);
                0.5 * (b - a).cross(&(c - a)).norm()
            })
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_and_append_keep_indices_valid() {
        let mut mesh = TriangleMesh::new();
        mesh.push_grid(3, 2, |u, v| Point3::new(u, v, 0.0));
        assert_eq!(mesh.len(), 12);
        assert!((mesh.area_m2() - 1.0).abs() < 1e-12);
        let mut both = mesh.clone();
        both.append(&mesh);
        assert_eq!(both.len(), 24);
        assert!(
            both.triangles
                .iter()
                .flatten()
                .all(|&i| (i as usize) < both.vertices.len())
        );
        assert!((both.area_m2() - 2.0).abs() < 1e-12);
    }
}
