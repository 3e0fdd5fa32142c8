//! Encode/decode round trips and the validation of payloads read from shared memory.

use nalgebra::{Isometry3, Matrix3, Point3, Vector3};
use proptest::prelude::*;
use pssba_core::factor::{FactorBlock, FactorPoint, KernelRejections, Surface};
use pssba_core::fit::Polynomial;
use pssba_core::geometry::Pose;
use pssba_core::lm::LmSettings;
use pssba_core::{ScaleReport, WorldSurface};
use pssba_msg::{
    FinalPose, MsgError, PoseMsg, WindowResult, decode_block, decode_result, encode_block,
    encode_result,
};

fn pose(k: usize) -> Pose {
    Pose::from_isometry(&Isometry3::new(
        Vector3::new(k as f64, 0.5, -0.25),
        Vector3::new(0.1, -0.2, 0.3 * k as f64),
    ))
}

fn block() -> (FactorBlock, Vec<Pose>, Vec<bool>, LmSettings) {
    let surfaces = (0..3)
        .map(|i| Surface {
            frame: i % 2,
            kernel_in_lidar: Vector3::new(1.0, 2.0, i as f64),
            tangent_from_lidar: pose(i).rotation.transpose() * Matrix3::identity(),
            polynomial: Polynomial {
                coefficients: [0.1, -0.2, 0.3, 0.0, 0.01, i as f64 * 1e-3],
            },
            gamma_m: 1.5,
        })
        .collect();
    // Grouped by surface, as the extraction makes them (the layout implies the surface).
    let points = (0..5)
        .map(|j| {
            FactorPoint::new(
                (j * 3 / 5) as u32,
                2,
                Vector3::new(0.1 * j as f64, 1.0 / 3.0, -2.0),
                0.5 + j as f64 * 0.1,
            )
        })
        .collect();
    let block = FactorBlock {
        gamma_m: 1.5,
        robust_scale_m: 0.15,
        surfaces,
        points,
        rejected: KernelRejections::default(),
    };
    let settings = LmSettings {
        max_iterations: 8,
        initial_lambda: 1e-4,
        prior_translation_m: f64::INFINITY,
        prior_rotation_rad: 0.02,
        motion_translation_m: 0.02,
        motion_rotation_rad: f64::INFINITY,
    };
    (
        block,
        (0..3).map(pose).collect(),
        vec![true, false, false],
        settings,
    )
}

#[test]
fn factor_block_round_trips_bit_exactly() -> Result<(), MsgError> {
    let (b, poses, fixed, settings) = block();
    let (header, words) = encode_block(7, 3, &b, &poses, &fixed, &settings);
    let decoded = decode_block(&header, &words)?;
    assert_eq!((decoded.window, decoded.scale), (7, 3));
    assert_eq!(decoded.block, b);
    assert_eq!(decoded.poses, poses);
    assert_eq!(decoded.fixed, fixed);
    assert_eq!(decoded.settings, settings);
    Ok(())
}

#[test]
fn ungrouped_points_arrive_grouped_by_surface_in_stable_order() -> Result<(), MsgError> {
    let (mut b, poses, fixed, settings) = block();
    b.points.reverse();
    let (header, words) = encode_block(0, 0, &b, &poses, &fixed, &settings);
    assert_eq!(words.len(), pssba_msg::block_len(3, 3, 5));
    let decoded = decode_block(&header, &words)?;
    let mut expected = b.points.clone();
    expected.sort_by_key(|p| p.surface);
    assert_eq!(decoded.block.points, expected);
    Ok(())
}

#[test]
fn corrupt_blocks_are_refused_with_the_field_named() {
    let (b, poses, fixed, settings) = block();
    let (header, words) = encode_block(0, 0, &b, &poses, &fixed, &settings);

    let mut h = header;
    h.point_count += 1;
    assert!(matches!(
        decode_block(&h, &words),
        Err(MsgError::LengthMismatch { .. })
    ));

    let mut h = header;
    h.surface_count = u64::MAX;
    assert!(matches!(
        decode_block(&h, &words),
        Err(MsgError::TooLarge { .. })
    ));

    let mut h = header;
    h.gamma_m = f64::NAN;
    let err = decode_block(&h, &words).expect_err("NaN gamma");
    assert!(err.to_string().contains("gamma_m"), "{err}");

    // A residual pointing at frame 99 of 3.
    let mut w = words.clone();
    let first_point = 3 * 13 + 3 * 21;
    w[first_point] = 99.0;
    let err = decode_block(&header, &w).expect_err("frame index out of range");
    assert!(err.to_string().contains("point frame"), "{err}");

    // Surface point counts that do not add up to the header's point count.
    let mut w = words.clone();
    w[3 * 13 + 20] += 1.0;
    let err = decode_block(&header, &w).expect_err("point counts must add up");
    assert!(err.to_string().contains("surface point count"), "{err}");

    // A non-rotation pose.
    let mut w = words.clone();
    w[0] = 2.0;
    assert!(matches!(
        decode_block(&header, &w),
        Err(MsgError::NotARotation { .. })
    ));

    // A point coordinate or a weight beyond f32 (held in f32, it would turn infinite).
    for (offset, field) in [(2, "point_in_lidar"), (4, "weight")] {
        let mut w = words.clone();
        w[first_point + offset] = 1e39;
        let err = decode_block(&header, &w).expect_err("beyond f32");
        assert!(err.to_string().contains(field), "{err}");
    }

    // An infinite point coordinate.
    let mut w = words;
    w[first_point + 1] = f64::INFINITY;
    assert!(matches!(
        decode_block(&header, &w),
        Err(MsgError::NotFinite { .. })
    ));
}

fn window_result() -> WindowResult {
    WindowResult {
        window: 2,
        converged: true,
        finals: (0..3)
            .map(|k| FinalPose {
                sequence: 10 + k,
                stamp_s: k as f64 * 0.1,
                world_from_lidar: pose(k as usize).to_isometry(),
            })
            .collect(),
        revised: vec![FinalPose {
            sequence: 4,
            stamp_s: 0.4,
            world_from_lidar: pose(2).to_isometry(),
        }],
        surfaces: vec![WorldSurface {
            frame: 11,
            kernel_in_world: Point3::new(1.0, 2.0, 3.0),
            tangent_from_world: pose(1).rotation,
            coefficients: [1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
            gamma_m: 0.4,
        }],
        map: vec![Point3::new(0.5, 0.25, 0.125); 4],
        scales: vec![ScaleReport {
            gamma_m: 3.0,
            cloud_points: 1000,
            kernels_used: 20,
            kernels_rejected: KernelRejections {
                no_normal: 1,
                too_few_points: 2,
                ill_conditioned: 3,
                too_rough: 4,
                single_frame: 5,
            },
            residuals: 300,
            cost_before: f64::NAN,
            cost_after: 1.5,
            iterations: 4,
            pose_change: 0.02,
            unconstrained_frames: 0,
            wall_time_s: 0.3,
            times: pssba_core::PhaseTimes {
                cloud_s: 0.1,
                normals_s: 0.05,
                extract_s: 0.1,
                solve_s: 0.05,
            },
        }],
        failure: None,
        frames_dropped: 3,
    }
}

#[test]
fn window_result_round_trips() -> Result<(), MsgError> {
    let result = window_result();
    let (header, words) = encode_result(&result);
    let decoded = decode_result(&header, &words)?;
    assert_eq!(decoded.window, 2);
    assert_eq!(decoded.finals.len(), 3);
    for (a, b) in decoded.finals.iter().zip(&result.finals) {
        assert_eq!(a.sequence, b.sequence);
        assert!(
            (a.world_from_lidar.to_homogeneous() - b.world_from_lidar.to_homogeneous()).norm()
                < 1e-12
        );
    }
    assert_eq!(decoded.revised.len(), 1);
    assert_eq!(decoded.revised[0].sequence, 4);
    assert_eq!(decoded.revised[0].stamp_s, 0.4);
    assert_eq!(decoded.surfaces, result.surfaces);
    assert_eq!(decoded.map, result.map);
    assert_eq!(
        decoded.scales[0].kernels_rejected,
        result.scales[0].kernels_rejected
    );
    assert!(decoded.scales[0].cost_before.is_nan());
    assert_eq!(decoded.failure, None);
    // A failed window carries its reason.
    let failed = WindowResult {
        failure: Some("scale 2: no poses from the adjust stage within 600 s".into()),
        ..result
    };
    let (header, words) = encode_result(&failed);
    assert_eq!(decode_result(&header, &words)?.failure, failed.failure);
    let mut bad = words.clone();
    *bad.last_mut().expect("error bytes") = 300.0;
    assert!(decode_result(&header, &bad).is_err(), "a byte above 255");
    Ok(())
}

#[test]
fn pose_message_checks_its_rotation() {
    let mut msg = PoseMsg::from_pose(&pose(1));
    assert!(msg.to_pose("test", 0).is_ok());
    msg.rotation[4] *= 1.01;
    assert!(matches!(
        msg.to_pose("test", 0),
        Err(MsgError::NotARotation { .. })
    ));
    msg = PoseMsg::from_pose(&pose(1));
    msg.translation_m[1] = f64::NAN;
    assert!(matches!(
        msg.to_pose("test", 0),
        Err(MsgError::NotFinite { .. })
    ));
}

proptest! {
    /// Whatever a hostile or broken process writes, decoding returns an error or a message;
    /// it never panics.
    #[test]
    fn decoding_garbage_never_panics(
        counts in proptest::array::uniform3(0u64..6),
        words in proptest::collection::vec(prop_oneof![
            -5.0f64..5.0, Just(f64::NAN), Just(f64::INFINITY), Just(0.0), Just(1.0), Just(2.0)
        ], 0..200),
        gamma in prop_oneof![Just(1.0f64), Just(-1.0), Just(f64::NAN)],
    ) {
        let (b, poses, fixed, settings) = block();
        let (mut header, _) = encode_block(0, 0, &b, &poses, &fixed, &settings);
        header.frame_count = counts[0];
        header.surface_count = counts[1];
        header.point_count = counts[2];
        header.gamma_m = gamma;
        let _ = decode_block(&header, &words);
        let (mut rh, _) = encode_result(&window_result());
        rh.final_count = counts[0];
        rh.surface_count = counts[1];
        rh.map_point_count = counts[2];
        let _ = decode_result(&rh, &words);
    }
}

proptest! {
    /// Whatever sequence of part headers arrives (a hostile or broken producer), reassembly
    /// returns errors or whole messages, never panics, and never holds more words than
    /// actually arrived.
    #[test]
    fn reassembling_garbage_parts_never_panics(
        parts in proptest::collection::vec(
            (0u64..3, 0u32..4, 0u32..4, 0u64..40, prop_oneof![0u64..40, Just(u64::MAX)], 0usize..12),
            0..30,
        ),
    ) {
        let mut reassembly = pssba_msg::Reassembly::default();
        let words: Vec<f64> = (0..12).map(f64::from).collect();
        let mut arrived = 0usize;
        for (message_id, index, count, offset_words, total_words, len) in parts {
            arrived += len;
            let header = pssba_msg::Parts { message_id, index, count, offset_words, total_words };
            if let Ok(Some(done)) = reassembly.push(header, &words[..len], 1 << 20) {
                prop_assert!(done.len() <= arrived);
                prop_assert_eq!(done.len() as u64, total_words);
            }
        }
    }
}
