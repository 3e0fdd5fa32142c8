//! Serial and rayon runs give bit-identical results: per-root voxelisation collects in key
//! order, and cost/Hessian sums add a fixed number of parts in a fixed order.

use crate::common::in_pool;
use crate::common::room::{room_trajectory, scan_room};
use pssba_balm::lm::variable_layout;
use pssba_balm::normal_equations::accumulate;
use pssba_balm::voxel::voxelise;
use pssba_balm::{BalmConfig, Parallelism, adjust};
use pssba_core::geometry::Pose;
use pssba_sim::perturb_poses;

#[test]
fn serial_and_rayon_agree_bit_for_bit() {
    let truth = room_trajectory(6);
    let frames = scan_room(&truth, 3000, 0.02, 4);
    let initial = perturb_poses(&truth, 0.2, 1.0, 4);
    let config = BalmConfig {
        max_outer_iterations: 2,
        ..BalmConfig::default()
    };

    let lidar: Vec<Vec<_>> = frames
        .iter()
        .map(|f| f.iter().map(|p| p.coords).collect())
        .collect();
    let poses: Vec<Pose> = initial.iter().map(Pose::from_isometry).collect();
    let serial_voxels = voxelise(&lidar, &poses, &config, Parallelism::Serial);
    let rayon_voxels = in_pool(|| voxelise(&lidar, &poses, &config, Parallelism::Rayon));
    assert_eq!(serial_voxels, rayon_voxels);
    assert!(!serial_voxels.planes.is_empty());

    let fixed: Vec<bool> = (0..poses.len()).map(|k| k == 0).collect();
    let (layout, dim) = variable_layout(&fixed);
    let serial_eq = accumulate(
        &serial_voxels.planes,
        &poses,
        &layout,
        dim,
        Parallelism::Serial,
    );
    let rayon_eq = in_pool(|| {
        accumulate(
            &rayon_voxels.planes,
            &poses,
            &layout,
            dim,
            Parallelism::Rayon,
        )
    });
    assert_eq!(serial_eq, rayon_eq);

    let serial = adjust(&frames, &initial, &config, Parallelism::Serial).expect("serial");
    let rayon = in_pool(|| adjust(&frames, &initial, &config, Parallelism::Rayon)).expect("rayon");
    assert_eq!(serial.world_from_lidar, rayon.world_from_lidar);
    let costs = |r: &pssba_balm::BalmResult| -> Vec<(f64, f64, usize)> {
        r.outer
            .iter()
            .map(|o| (o.cost_before, o.cost_after, o.plane_voxels))
            .collect()
    };
    assert_eq!(costs(&serial), costs(&rayon));
}
