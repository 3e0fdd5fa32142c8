//! Outputs at the final poses: world surfaces and the smoothed cloud (paper "Points Smoothing":
//! each point replaced by `(x, y, f(x, y))` in its kernel's tangent frame).

use crate::cloud::ScaleCloud;
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
/// are left out.
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
    let kernels: Vec<[f64; 3]> = surfaces
        .iter()
        .map(|s| s.kernel_in_world.coords.into())
        .collect();
    let tree = ImmutableKdTree::new_from_slice(&kernels);
    let projected = map_indexed(cloud.len(), parallelism, |i| {
        let world = poses[cloud.frame_of[i] as usize].apply(&cloud.lidar(i));
        let nearest = tree.nearest_one::<SquaredEuclidean>(&world.into());
        let surface = &surfaces[nearest.item as usize];
        if nearest.distance > surface.gamma_m * surface.gamma_m {
            return None;
        }
        let s = surface.tangent_from_world * (world - surface.kernel_in_world.coords);
        let poly = crate::fit::Polynomial {
            coefficients: surface.coefficients,
        };
        let z = poly.height(s.x, s.y);
        ((z - s.z).abs() <= 3.0 * block.robust_scale_m).then(|| {
            let smoothed = surface.tangent_from_world.transpose() * Vector3::new(s.x, s.y, z);
            Point3::from(smoothed + surface.kernel_in_world.coords)
        })
    });
    projected.into_iter().flatten().collect()
}
