//! Outputs at the final poses: world surfaces and the smoothed cloud (paper "Points Smoothing":
//! each point replaced by `(x, y, f(x, y))` in its kernel's tangent frame).

use crate::cloud::scale_cloud::ScaleCloud;
use crate::factor::FactorBlock;
use crate::geometry::Pose;
use crate::parallel::{Parallelism, map_indexed};
use crate::result::WorldSurface;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Point3, Vector3};

/// The block's surfaces moved with their frames to `poses`.
pub fn world_surfaces(block: &FactorBlock, poses: &[Pose]) -> Vec<WorldSurface> {
    block
        .surfaces
        .iter()
        .map(|s| {
            let pose = &poses[s.frame];
            WorldSurface {
                frame: s.frame,
                kernel_in_world: Point3::from(pose.apply(&s.kernel_in_lidar)),
                tangent_from_world: s.tangent_from_lidar * pose.rotation.transpose(),
                coefficients: s.polynomial.coefficients,
                gamma_m: s.gamma_m,
            }
        })
        .collect()
}

/// Each downsampled point projected onto the surface of its nearest kernel, when that kernel
/// lies within gamma and the point is within three robust scales of the surface; other points
/// are left out. Output in cloud order.
///
/// The cloud's points are taken voxel by voxel (its downsampling voxels, at the final poses):
/// a kernel within gamma of a point lies within gamma plus the voxel's spread of the voxel's
/// centroid, so one kd-tree query per voxel gives every candidate its points need.
pub fn smoothed_cloud(
    cloud: &ScaleCloud,
    block: &FactorBlock,
    poses: &[Pose],
    parallelism: Parallelism,
) -> Vec<Point3<f64>> {
    let surfaces = world_surfaces(block, poses);
    if surfaces.is_empty() {
        return Vec::new();
    }
    let tree = kernel_tree(&surfaces);
    let max_gamma_m = surfaces.iter().map(|s| s.gamma_m).fold(0.0, f64::max);
    let voxels = cloud.index.centroids().len();
    let by_voxel = map_indexed(voxels, parallelism, |v| {
        let world: Vec<Vector3<f64>> = cloud
            .index
            .points_of(v)
            .map(|i| poses[cloud.frame_of[i] as usize].apply(&cloud.lidar(i)))
            .collect();
        let centroid = world.iter().sum::<Vector3<f64>>() / world.len().max(1) as f64;
        let spread_m = world
            .iter()
            .map(|w| (w - centroid).norm())
            .fold(0.0, f64::max);
        let reach_m = (max_gamma_m + spread_m) * (1.0 + 1e-9) + 1e-12;
        let candidates = by_distance_from(
            &surfaces,
            &centroid,
            tree.within_unsorted::<SquaredEuclidean>(&centroid.into(), reach_m * reach_m)
                .iter()
                .map(|n| n.item as usize),
        );
        world
            .iter()
            .filter_map(|w| {
                let (distance_sq, nearest) =
                    nearest_candidate(&surfaces, &candidates, &centroid, w)?;
                project(&surfaces[nearest], distance_sq, w, block.robust_scale_m)
            })
            .collect::<Vec<_>>()
    });
    by_voxel.into_iter().flatten().collect()
}

/// The candidate kernels with their distance (m) from `centroid`, nearest first (ties by
/// index).
fn by_distance_from(
    surfaces: &[WorldSurface],
    centroid: &Vector3<f64>,
    candidates: impl Iterator<Item = usize>,
) -> Vec<(f64, usize)> {
    let mut sorted: Vec<(f64, usize)> = candidates
        .map(|k| ((surfaces[k].kernel_in_world.coords - centroid).norm(), k))
        .collect();
    sorted.sort_unstable_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
    sorted
}

/// The candidate nearest `w` (squared distance, surface index; the lower index on a tie).
/// Candidates come nearest `centroid` first, so the scan stops once even the triangle
/// inequality's bound `|k - w| >= |k - c| - |w - c|` exceeds the best distance: a 1000-frame
/// window has ten kernels per place (one per group of frames) and ten times the points, and
/// comparing every point with every candidate made the outputs grow with the square of the
/// window.
fn nearest_candidate(
    surfaces: &[WorldSurface],
    candidates: &[(f64, usize)],
    centroid: &Vector3<f64>,
    w: &Vector3<f64>,
) -> Option<(f64, usize)> {
    let from_centroid_m = (w - centroid).norm();
    let mut best: Option<(f64, usize)> = None;
    for &(kernel_from_centroid_m, k) in candidates {
        if let Some((best_sq, _)) = best {
            // The margin covers rounding: the bound must never cut a true minimum.
            let bound_m = kernel_from_centroid_m - from_centroid_m;
            if bound_m > best_sq.sqrt() * (1.0 + 1e-9) + 1e-12 {
                break;
            }
        }
        let distance_sq = (surfaces[k].kernel_in_world.coords - w).norm_squared();
        let better = best.is_none_or(|(best_sq, best_k)| {
            distance_sq.total_cmp(&best_sq).then(k.cmp(&best_k)).is_lt()
        });
        if better {
            best = Some((distance_sq, k));
        }
    }
    best
}

/// kd-tree over the kernel points (items: surface indices).
fn kernel_tree(surfaces: &[WorldSurface]) -> ImmutableKdTree<f64, 3> {
    let kernels: Vec<[f64; 3]> = surfaces
        .iter()
        .map(|s| s.kernel_in_world.coords.into())
        .collect();
    ImmutableKdTree::new_from_slice(&kernels)
}

/// `world` projected onto `surface` (its kernel `distance_sq` m^2 away), if the kernel is
/// within gamma and the point within three robust scales of the surface.
fn project(
    surface: &WorldSurface,
    distance_sq: f64,
    world: &Vector3<f64>,
    robust_scale_m: f64,
) -> Option<Point3<f64>> {
    if distance_sq > surface.gamma_m * surface.gamma_m {
        return None;
    }
    let s = surface.tangent_from_world * (world - surface.kernel_in_world.coords);
    let poly = crate::kernels::fit::Polynomial {
        coefficients: surface.coefficients,
    };
    let z = poly.height(s.x, s.y);
    ((z - s.z).abs() <= 3.0 * robust_scale_m).then(|| {
        let smoothed = surface.tangent_from_world.transpose() * Vector3::new(s.x, s.y, z);
        Point3::from(smoothed + surface.kernel_in_world.coords)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::PssBaConfig;
    use crate::kernels::fit::SurfaceModel;
    use crate::kernels::smoothing::extract_block;
    use pssba_sim::{SceneSpec, curved_window, perturb_poses};

    /// The plain way: a kd-tree nearest-kernel query for every point.
    fn smoothed_cloud_per_point(
        cloud: &ScaleCloud,
        block: &FactorBlock,
        poses: &[Pose],
    ) -> Vec<Point3<f64>> {
        let surfaces = world_surfaces(block, poses);
        if surfaces.is_empty() {
            return Vec::new();
        }
        let tree = kernel_tree(&surfaces);
        (0..cloud.len())
            .filter_map(|i| {
                let world = poses[cloud.frame_of[i] as usize].apply(&cloud.lidar(i));
                let nearest = tree.nearest_one::<SquaredEuclidean>(&world.into());
                project(
                    &surfaces[nearest.item as usize],
                    nearest.distance,
                    &world,
                    block.robust_scale_m,
                )
            })
            .collect()
    }

    #[test]
    fn voxel_candidates_give_the_per_point_nearest_kernel() {
        let window = curved_window(&SceneSpec {
            frames: 4,
            points_per_frame: 3000,
            seed: 5,
            ..SceneSpec::default()
        });
        let frames: Vec<Vec<Vector3<f64>>> = (window.frames.iter())
            .map(|f| f.iter().map(|p| p.coords).collect())
            .collect();
        let poses: Vec<Pose> = perturb_poses(&window.ground_truth, 0.05, 0.3, 9)
            .iter()
            .map(Pose::from_isometry)
            .collect();
        // Final poses away from the cloud's: the voxels' points move apart.
        let moved: Vec<Pose> = perturb_poses(&window.ground_truth, 0.1, 0.5, 10)
            .iter()
            .map(Pose::from_isometry)
            .collect();
        let config = PssBaConfig::default();
        for gamma_m in [1.5, 0.4] {
            let cloud = ScaleCloud::build(
                &frames,
                &poses,
                config.downsample_m(gamma_m),
                config.normal_neighbours,
                Parallelism::Serial,
            );
            let block = extract_block(
                &cloud,
                &poses,
                gamma_m,
                SurfaceModel::Quadratic,
                &config,
                Parallelism::Serial,
            );
            for at in [&poses, &moved] {
                let expected = smoothed_cloud_per_point(&cloud, &block, at);
                assert!(
                    expected.len() > cloud.len() / 10,
                    "{} of {}",
                    expected.len(),
                    cloud.len()
                );
                assert_eq!(
                    smoothed_cloud(&cloud, &block, at, Parallelism::Serial),
                    expected
                );
            }
        }
    }
}
