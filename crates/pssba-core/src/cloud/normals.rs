//! PCA normals (DESIGN step 2): the eigenvector of the smallest eigenvalue of the neighbours'
//! covariance, oriented towards the sensor origin of the frame the point came from.

use crate::cloud::eigen3::smallest_eigenpair;
use crate::cloud::neighbour_grid::nearest_within;
use crate::parallel::{Parallelism, map_indexed};
use nalgebra::{Matrix3, SymmetricEigen, Vector3};

/// Unit normal of a neighbourhood, or `None` when it has fewer than 3 points or no single
/// smallest direction (a point or a line). The tests' entry to [`pca_normal_of`].
#[cfg(test)]
pub fn pca_normal(points: &[Vector3<f64>]) -> Option<Vector3<f64>> {
    pca_normal_of(points.len(), |i| points[i])
}

/// [`pca_normal`] of the `count` points `point(0)`, `point(1)`, ... (read twice, in order;
/// no list is gathered).
fn pca_normal_of(count: usize, point: impl Fn(usize) -> Vector3<f64>) -> Option<Vector3<f64>> {
    if count < 3 {
        return None;
    }
    let mean = (0..count).map(&point).sum::<Vector3<f64>>() / count as f64;
    let covariance = (0..count)
        .map(|i| {
            let d = point(i) - mean;
            d * d.transpose()
        })
        .sum::<Matrix3<f64>>();
    let (smallest, middle, normal) = match smallest_eigenpair(&covariance) {
        Some(([smallest, middle, _], normal)) => (smallest, middle, normal),
        // The smallest eigenvalue is not clearly simple: the iterative solver decides.
        None => {
            let eigen = SymmetricEigen::new(covariance);
            let mut order = [0usize, 1, 2];
            order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
            let normal = eigen.eigenvectors.column(order[0]).into_owned();
            (
                eigen.eigenvalues[order[0]],
                eigen.eigenvalues[order[1]],
                normal,
            )
        }
    };
    // A line or a spot (two vanishing eigenvalues) has no normal; NaN has none either.
    let spread = middle.is_finite() && middle > 1e-12;
    if !spread || smallest.is_nan() || smallest < -1e-12 {
        return None;
    }
    normal
        .iter()
        .all(|v| v.is_finite())
        .then(|| normal.normalize())
}

/// Flips `normal` so it points towards `sensor_origin` from `point`.
#[inline]
pub fn orient_towards(
    normal: Vector3<f64>,
    point: &Vector3<f64>,
    sensor_origin: &Vector3<f64>,
) -> Vector3<f64> {
    if normal.dot(&(sensor_origin - point)) < 0.0 {
        -normal
    } else {
        normal
    }
}

/// For each query point, its nearest points (at most `k`, within a radius), nearest first:
/// query `q`'s are `items[starts[q]..starts[q + 1]]`. Kept by a cloud so its normals can be
/// recomputed over the same neighbourhoods after the points moved a little.
#[derive(Debug, Clone, Default)]
pub struct NeighbourLists {
    starts: Vec<u32>,
    items: Vec<u32>,
}

impl NeighbourLists {
    /// For each point of `points`, its `k` nearest points of `points` (itself included)
    /// within `max_radius_m`, by a uniform grid (see [`crate::cloud::neighbour_grid`]).
    ///
    /// # Panics
    /// If the lists hold more than `u32::MAX` items in all.
    pub fn nearest(
        points: &[[f64; 3]],
        k: usize,
        max_radius_m: f64,
        parallelism: Parallelism,
    ) -> Self {
        let per_query = nearest_within(points, k.max(3), max_radius_m, parallelism);
        let mut starts = Vec::with_capacity(per_query.len() + 1);
        starts.push(0u32);
        let mut items = Vec::with_capacity(per_query.iter().map(Vec::len).sum());
        for list in per_query {
            items.extend(list);
            starts.push(u32::try_from(items.len()).expect("fewer than 2^32 neighbours"));
        }
        Self { starts, items }
    }

    /// Number of lists (queries).
    pub fn len(&self) -> usize {
        self.starts.len().saturating_sub(1)
    }

    /// Query `q`'s neighbours, nearest first (as of when the lists were made).
    pub fn of(&self, q: usize) -> &[u32] {
        &self.items[self.starts[q] as usize..self.starts[q + 1] as usize]
    }
}

/// Unoriented PCA normal of each list of `lists` over the current positions `points` of its
/// items; `None` where PCA fails.
pub fn normals_over(
    points: &[[f64; 3]],
    lists: &NeighbourLists,
    parallelism: Parallelism,
) -> Vec<Option<Vector3<f64>>> {
    map_indexed(lists.len(), parallelism, |q| {
        let neighbours = lists.of(q);
        pca_normal_of(neighbours.len(), |i| {
            Vector3::from(points[neighbours[i] as usize])
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_normal_is_oriented_to_sensor() {
        let pts: Vec<_> = (0..25)
            .map(|i| Vector3::new((i % 5) as f64, (i / 5) as f64, 2.0))
            .collect();
        let n = pca_normal(&pts).unwrap();
        assert!((n.z.abs() - 1.0).abs() < 1e-12);
        let up = orient_towards(n, &pts[0], &Vector3::new(0.0, 0.0, 10.0));
        assert!((up - Vector3::z()).norm() < 1e-12);
    }

    #[test]
    fn line_has_no_normal() {
        let pts: Vec<_> = (0..10).map(|i| Vector3::new(i as f64, 0.0, 0.0)).collect();
        assert!(pca_normal(&pts).is_none());
    }

    #[test]
    fn serial_and_parallel_normals_agree() {
        let pts: Vec<[f64; 3]> = (0..400)
            .map(|i| {
                let (a, b) = ((i % 20) as f64 * 0.1, (i / 20) as f64 * 0.1);
                [a, b, (a * a - b) * 0.3]
            })
            .collect();
        let normals = |parallelism| {
            let lists = NeighbourLists::nearest(&pts, 8, 1.0, parallelism);
            normals_over(&pts, &lists, parallelism)
        };
        let (serial, parallel) = (normals(Parallelism::Serial), normals(Parallelism::Rayon));
        assert_eq!(serial, parallel);
        assert!(serial.iter().all(|n| n.is_some()));
    }
}
