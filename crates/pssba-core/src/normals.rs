//! PCA normals (DESIGN step 2): the eigenvector of the smallest eigenvalue of the neighbours'
//! covariance, oriented towards the sensor origin of the frame the point came from.
//! Neighbourhoods are the cells of a voxel grid whose edge follows gamma: measured on a
//! 30 x 20k window, a k-nearest search per point took 80% of the run time.

use crate::cloud::voxel_key;
use crate::parallel::{Parallelism, map_indexed};
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use rustc_hash::FxHashMap;

/// Unit normal of a neighbourhood, or `None` when it has fewer than 3 points or no single
/// smallest direction (a point or a line).
pub fn pca_normal(points: &[Vector3<f64>]) -> Option<Vector3<f64>> {
    if points.len() < 3 {
        return None;
    }
    let mean = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
    let covariance = points
        .iter()
        .map(|p| {
            let d = p - mean;
            d * d.transpose()
        })
        .sum::<Matrix3<f64>>();
    let eigen = SymmetricEigen::new(covariance);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
    let (smallest, middle) = (eigen.eigenvalues[order[0]], eigen.eigenvalues[order[1]]);
    // A line (two vanishing eigenvalues) has no normal.
    if !(middle > 1e-12) || !(smallest >= 0.0 || smallest > -1e-12) {
        return None;
    }
    let normal = eigen.eigenvectors.column(order[0]).into_owned();
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

/// Normals of every point from PCA over a cell of a voxel grid of edge `cell_m` (all frames'
/// points in the cell, so one pass over the cloud instead of a k-nearest search per point),
/// oriented towards `sensor_origin_of[i]`. `None` where the cell has fewer than
/// `min_points` points or no single smallest direction.
pub fn cell_normals(
    points_world: &[[f64; 3]],
    sensor_origin_of: impl Fn(usize) -> Vector3<f64> + Sync + Send,
    cell_m: f64,
    min_points: usize,
    parallelism: Parallelism,
) -> Vec<Option<Vector3<f64>>> {
    let mut cell_of = Vec::with_capacity(points_world.len());
    let mut index: FxHashMap<(i64, i64, i64), usize> = FxHashMap::default();
    let mut members: Vec<Vec<Vector3<f64>>> = Vec::new();
    for p in points_world {
        let p = Vector3::from(*p);
        let slot = *index.entry(voxel_key(&p, cell_m)).or_insert_with(|| {
            members.push(Vec::new());
            members.len() - 1
        });
        members[slot].push(p);
        cell_of.push(slot);
    }
    let normals = map_indexed(members.len(), parallelism, |c| {
        if members[c].len() < min_points.max(3) {
            None
        } else {
            pca_normal(&members[c])
        }
    });
    map_indexed(points_world.len(), parallelism, |i| {
        normals[cell_of[i]]
            .map(|n| orient_towards(n, &Vector3::from(points_world[i]), &sensor_origin_of(i)))
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
    fn serial_and_parallel_cell_normals_agree() {
        let pts: Vec<[f64; 3]> = (0..400)
            .map(|i| {
                let (a, b) = ((i % 20) as f64 * 0.1, (i / 20) as f64 * 0.1);
                [a, b, (a * a - b) * 0.3]
            })
            .collect();
        let origin = |_| Vector3::new(0.0, 0.0, 5.0);
        let serial = cell_normals(&pts, origin, 0.5, 5, Parallelism::Serial);
        let parallel = cell_normals(&pts, origin, 0.5, 5, Parallelism::Rayon);
        assert_eq!(serial, parallel);
        assert!(serial.iter().all(|n| n.is_some_and(|n| n.z > 0.0)));
    }
}
