//! Behavioural tests of the voxel-occupancy metric.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use proptest::prelude::*;
use pssba_eval::{
    EvalError, count_voxels, occupancy_averaged, occupancy_of_frames, occupied_voxels,
    sub_voxel_offsets,
};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

const VOXEL: f64 = 0.1;

/// 1 m × 1 m plane at height `z`, 50 × 50 points, with per-point heights
/// from `z_of(index)`.
fn plane(z_of: impl Fn(usize) -> f64) -> Vec<Point3<f64>> {
    (0..2500)
        .map(|i| {
            let (ix, iy) = (i % 50, i / 50);
            Point3::new(0.01 + 0.02 * ix as f64, 0.01 + 0.02 * iy as f64, z_of(i))
        })
        .collect()
}

#[test]
fn hand_counted_voxels() {
    let pts = [
        Point3::new(0.05, 0.05, 0.05),
        Point3::new(0.06, 0.01, 0.09), // same voxel as the first
        Point3::new(0.15, 0.05, 0.05),
        Point3::new(-0.01, 0.0, 0.0),
        Point3::new(f64::NAN, 0.0, 0.0),
        Point3::new(0.0, f64::INFINITY, 0.0),
    ];
    let zero = Vector3::zeros();
    assert_eq!(occupied_voxels(pts.iter().copied(), VOXEL, zero), 3);
    let c = count_voxels(pts.iter().copied(), VOXEL, zero).expect("count");
    assert_eq!((c.occupied, c.skipped_points), (3, 2));
    // Shifting the grid by 0.06 moves every x index up by one: still 3 voxels.
    assert_eq!(
        occupied_voxels(pts.iter().copied(), VOXEL, Vector3::new(0.06, 0.0, 0.0)),
        3
    );
    assert_eq!(occupied_voxels(std::iter::empty(), VOXEL, zero), 0);
    // Invalid parameters: 0 from the infallible variant, an error from the other.
    assert_eq!(occupied_voxels(pts.iter().copied(), 0.0, zero), 0);
    assert_eq!(
        count_voxels(pts.iter().copied(), -1.0, zero),
        Err(EvalError::InvalidVoxelSize { voxel_m: -1.0 })
    );
    // Indices beyond i64 are skipped, not wrapped or saturated.
    let huge = [Point3::new(1e300, 0.0, 0.0), Point3::new(0.0, 0.0, 0.0)];
    let c = count_voxels(huge.iter().copied(), 1e-10, zero).expect("count");
    assert_eq!((c.occupied, c.skipped_points), (1, 1));
}

#[test]
fn plane_on_voxel_boundary_doubles_count_at_zero_offset() {
    // A surface at z = 0 (a grid plane) with ±0.1 mm noise straddles two
    // voxel layers at offset 0, but fits in one layer once the grid is
    // shifted by half a voxel: the count depends on the grid phase.
    let pts = plane(|i| if i % 2 == 0 { 1e-4 } else { -1e-4 });
    let at_zero = occupied_voxels(pts.iter().copied(), VOXEL, Vector3::zeros());
    let half_z = occupied_voxels(pts.iter().copied(), VOXEL, Vector3::new(0.0, 0.0, 0.05));
    let half_xyz = occupied_voxels(pts.iter().copied(), VOXEL, Vector3::repeat(0.05));
    assert_eq!((at_zero, half_z), (200, 100));
    assert_eq!(half_xyz, 121); // 11 × 11 columns, one layer
    // Averaging over offsets exposes and damps this phase sensitivity.
    let avg = occupancy_averaged(&pts, VOXEL, 16, 7).expect("occupancy");
    assert_eq!(avg.per_offset[0], 200);
    assert!(
        avg.per_offset[1..].iter().all(|n| (100..=121).contains(n)),
        "{:?}",
        avg.per_offset
    );
    assert_eq!(
        (avg.min, avg.max),
        (*avg.per_offset[1..].iter().min().expect("n"), 200)
    );
    assert!(avg.mean_voxels > avg.min as f64 && avg.mean_voxels < 200.0);
}

#[test]
fn blurred_copy_occupies_more_voxels_than_sharp_copy() {
    let sharp = plane(|_| 0.033);
    let mut rng = StdRng::seed_from_u64(1);
    let blurred: Vec<_> = sharp
        .iter()
        .map(|p| Point3::new(p.x, p.y, p.z + rng.random_range(-0.15..0.15)))
        .collect();
    let s = occupancy_averaged(&sharp, VOXEL, 8, 3).expect("sharp");
    let b = occupancy_averaged(&blurred, VOXEL, 8, 3).expect("blurred");
    assert!(
        b.mean_voxels > 2.0 * s.mean_voxels,
        "{} vs {}",
        b.mean_voxels,
        s.mean_voxels
    );
    assert!(b.min > s.max);
}

#[test]
fn offsets_are_deterministic_and_sub_voxel() {
    let pts = plane(|i| (i % 7) as f64 * 0.013);
    let a = occupancy_averaged(&pts, VOXEL, 10, 42).expect("a");
    let b = occupancy_averaged(&pts, VOXEL, 10, 42).expect("b");
    assert_eq!(a, b);
    let c = occupancy_averaged(&pts, VOXEL, 10, 43).expect("c");
    assert_ne!(a.offsets_m, c.offsets_m);
    assert_eq!(a.offsets_m[0], [0.0; 3]);
    assert_eq!(
        (a.per_offset.len(), a.offsets_m.len(), a.voxel_m),
        (10, 10, VOXEL)
    );
    assert!(
        a.offsets_m
            .iter()
            .flatten()
            .all(|&o| (0.0..VOXEL).contains(&o))
    );
    let mean = a.per_offset.iter().sum::<usize>() as f64 / 10.0;
    assert_eq!(a.mean_voxels, mean);
    let offsets = sub_voxel_offsets(VOXEL, 10, 42).expect("offsets");
    assert!(
        offsets
            .iter()
            .zip(&a.offsets_m)
            .all(|(o, m)| [o.x, o.y, o.z] == *m)
    );
}

#[test]
fn frames_variant_matches_merged_cloud() {
    let frame_a = plane(|i| 0.001 * (i % 13) as f64);
    let frame_b: Vec<_> = frame_a
        .iter()
        .map(|p| Point3::new(p.y, p.x, -p.z))
        .collect();
    let poses = [
        Isometry3::identity(),
        Isometry3::from_parts(
            Translation3::new(0.37, -0.2, 0.05),
            UnitQuaternion::from_scaled_axis(Vector3::new(0.1, 0.2, 0.7)),
        ),
    ];
    let frames = vec![frame_a, frame_b];
    let merged: Vec<_> = frames
        .iter()
        .zip(&poses)
        .flat_map(|(f, t)| f.iter().map(move |p| t * p))
        .collect();
    let from_frames = occupancy_of_frames(&frames, &poses, VOXEL, 6, 9).expect("frames");
    let from_merged = occupancy_averaged(&merged, VOXEL, 6, 9).expect("merged");
    assert_eq!(from_frames, from_merged);
}

#[test]
fn occupancy_errors() {
    let pts = plane(|_| 0.0);
    for v in [0.0, -0.1, f64::NAN, f64::INFINITY] {
        assert!(matches!(
            occupancy_averaged(&pts, v, 4, 0),
            Err(EvalError::InvalidVoxelSize { .. })
        ));
    }
    assert_eq!(
        occupancy_averaged(&pts, VOXEL, 0, 0),
        Err(EvalError::InvalidOffsetCount { n_offsets: 0 })
    );
    let frames = vec![pts.clone(), pts];
    assert!(matches!(
        occupancy_of_frames(&frames, &[Isometry3::identity()], VOXEL, 4, 0),
        Err(EvalError::LengthMismatch {
            left: 2,
            right: 1,
            ..
        })
    ));
    let bad = [
        Isometry3::identity(),
        Isometry3::translation(f64::NAN, 0.0, 0.0),
    ];
    assert_eq!(
        occupancy_of_frames(&frames, &bad, VOXEL, 4, 0),
        Err(EvalError::NonFinite {
            what: "world_from_lidar pose",
            index: 1
        })
    );
    let msg = EvalError::InvalidVoxelSize { voxel_m: -0.1 }.to_string();
    assert!(msg.contains("-0.1"), "{msg}");
}

fn point(range: f64) -> impl Strategy<Value = Point3<f64>> {
    (-range..range, -range..range, -range..range).prop_map(|(x, y, z)| Point3::new(x, y, z))
}

proptest! {
    /// 1 ≤ N ≤ #points for non-empty input, and adding points never lowers N.
    #[test]
    fn count_is_bounded_and_monotone(
        pts in prop::collection::vec(point(5.0), 1..200),
        extra in prop::collection::vec(point(5.0), 0..50),
        voxel in 0.05f64..2.0,
        offset in point(1.0),
    ) {
        let o = offset.coords;
        let n = occupied_voxels(pts.iter().copied(), voxel, o);
        prop_assert!(n >= 1 && n <= pts.len());
        let n_more = occupied_voxels(pts.iter().chain(&extra).copied(), voxel, o);
        prop_assert!(n_more >= n && n_more <= n + extra.len());
    }
}
