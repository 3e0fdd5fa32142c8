//! End to end on the plane-rich room: 20 frames, 2 cm range noise, poses perturbed by
//! 0.2 m / 1 deg RMS. BALM must bring the APE (after SE(3) alignment) below 2 cm.

use crate::common::room::{room_trajectory, scan_room};
use pssba_balm::{BalmConfig, Parallelism, adjust};
use pssba_eval::ape_translation_paired;
use pssba_sim::perturb_poses;

#[test]
fn room_ape_drops_below_two_centimetres() {
    let truth = room_trajectory(20);
    let frames = scan_room(&truth, 6000, 0.02, 1);
    let initial = perturb_poses(&truth, 0.2, 1.0, 1);
    let result = adjust(
        &frames,
        &initial,
        &BalmConfig::default(),
        Parallelism::Rayon,
    )
    .expect("balm runs");
    let ape_initial = ape_translation_paired(&truth, &initial)
        .expect("ape")
        .rmse_m;
    let ape = ape_translation_paired(&truth, &result.world_from_lidar)
        .expect("ape")
        .rmse_m;
    let first = &result.outer[0];
    assert!(
        first.plane_voxels > 50,
        "{} plane voxels",
        first.plane_voxels
    );
    assert!(ape_initial > 0.1, "initial APE {ape_initial}");
    assert!(
        ape < 0.02,
        "APE {ape_initial} -> {ape}; reports {:#?}",
        result.outer
    );
    // Frame 0 is the gauge.
    assert_eq!(result.world_from_lidar[0], initial[0]);
    // Every outer iteration lowers (or keeps) its own cost, and the final RMS distance is at
    // the noise level.
    for outer in &result.outer {
        assert!(outer.cost_after <= outer.cost_before);
    }
    let last = result.outer.last().expect("an outer iteration");
    assert!(
        last.rms_distance_m() < 0.03,
        "rms {}",
        last.rms_distance_m()
    );
    assert!(
        result
            .world_from_lidar
            .iter()
            .all(|p| p.to_homogeneous().iter().all(|v| v.is_finite()))
    );
}
