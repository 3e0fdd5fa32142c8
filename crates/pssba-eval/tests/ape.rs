//! Behavioural tests of the APE pipeline.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use proptest::prelude::*;
use pssba_eval::{EvalError, ape_translation, umeyama_se3};

fn helix(n: usize) -> Vec<(f64, Isometry3<f64>)> {
    (0..n)
        .map(|i| {
            let a = 0.3 * i as f64;
            let p = Vector3::new(4.0 * a.cos(), 4.0 * a.sin(), 0.2 * i as f64);
            (
                100.0 + 0.1 * i as f64,
                Isometry3::translation(p.x, p.y, p.z),
            )
        })
        .collect()
}

fn moved(traj: &[(f64, Isometry3<f64>)], m: &Isometry3<f64>) -> Vec<(f64, Isometry3<f64>)> {
    traj.iter().map(|(t, pose)| (*t, m * pose)).collect()
}

fn some_motion() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(3.0, -7.0, 1.5),
        UnitQuaternion::from_scaled_axis(Vector3::new(0.4, -1.1, 2.0)),
    )
}

#[test]
fn identical_trajectories_have_zero_error() {
    let gt = helix(20);
    let res = ape_translation(&gt, &gt, 0.01).expect("APE");
    assert_eq!(res.matched, 20);
    assert!(res.rmse_m < 1e-12 && res.max_m < 1e-12, "{res:?}");
    assert!(res.alignment.translation.vector.norm() < 1e-12);
    assert!(res.alignment.rotation.angle() < 1e-12);
}

#[test]
fn rigidly_moved_copy_is_aligned_back() {
    let gt = helix(25);
    let m = some_motion();
    let est = moved(&gt, &m);
    let res = ape_translation(&gt, &est, 0.01).expect("APE");
    assert!(res.rmse_m < 1e-10, "rmse {}", res.rmse_m);
    // The alignment undoes the motion: T ≈ M⁻¹.
    let residual = res.alignment * m;
    assert!(residual.translation.vector.norm() < 1e-10);
    assert!(residual.rotation.angle() < 1e-10);
}

#[test]
fn scaled_square_hand_checked() {
    // Reference: square corners (±1, ±1, 0). Estimate: the same square scaled
    // by 1.1 about its centre, then moved rigidly. Scale cannot be removed by
    // SE(3); by symmetry the best alignment is the inverse motion and every
    // corner is 0.1·√2 off, so rmse = mean = max = min = 0.1·√2, std = 0.
    let corners = [(1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)];
    let gt: Vec<_> = corners
        .iter()
        .enumerate()
        .map(|(i, &(x, y))| (i as f64, Isometry3::translation(x, y, 0.0)))
        .collect();
    let m = some_motion();
    let est: Vec<_> = corners
        .iter()
        .enumerate()
        // Stamps 4 ms late: still associated with max_diff = 0.01 s.
        .map(|(i, &(x, y))| {
            (
                i as f64 + 0.004,
                m * Isometry3::translation(1.1 * x, 1.1 * y, 0.0),
            )
        })
        .collect();
    let res = ape_translation(&gt, &est, 0.01).expect("APE");
    let expected = 0.1 * 2f64.sqrt();
    assert_eq!(res.matched, 4);
    for v in [res.rmse_m, res.mean_m, res.median_m, res.max_m, res.min_m] {
        assert!((v - expected).abs() < 1e-12, "{v} vs {expected}");
    }
    assert!(res.std_m < 1e-12);
}

#[test]
fn saddle_offsets_hand_checked() {
    // Corners lifted by ±d in a saddle pattern: Σ x·z = Σ y·z = 0, so the
    // alignment is the identity and every error is exactly d.
    let d = 0.25;
    let pts = [
        (1.0, 1.0, d),
        (-1.0, -1.0, d),
        (1.0, -1.0, -d),
        (-1.0, 1.0, -d),
    ];
    let gt: Vec<_> = pts
        .iter()
        .enumerate()
        .map(|(i, p)| (i as f64, Isometry3::translation(p.0, p.1, 0.0)))
        .collect();
    let est: Vec<_> = pts
        .iter()
        .enumerate()
        .map(|(i, p)| (i as f64, Isometry3::translation(p.0, p.1, p.2)))
        .collect();
    let res = ape_translation(&gt, &est, 0.01).expect("APE");
    assert!(
        (res.rmse_m - d).abs() < 1e-12 && res.std_m < 1e-12,
        "{res:?}"
    );
    assert!(res.alignment.rotation.angle() < 1e-12);
}

#[test]
fn unmatched_poses_are_ignored() {
    let gt = helix(10);
    let mut est = moved(&gt, &some_motion());
    est[4].0 += 0.02; // beyond max_diff: dropped
    est.push((500.0, Isometry3::translation(99.0, 99.0, 99.0))); // matches nothing
    let res = ape_translation(&gt, &est, 0.01).expect("APE");
    assert_eq!(res.matched, 9);
    assert!(res.rmse_m < 1e-10);
}

#[test]
fn umeyama_recovers_motion_of_planar_set() {
    // Planar source (rank-2 covariance): the reflection correction must pick
    // the proper rotation.
    let src: Vec<Vector3<f64>> = [(0.0, 0.0), (2.0, 0.0), (0.0, 1.0), (3.0, 2.0), (-1.0, 4.0)]
        .iter()
        .map(|&(x, y)| Vector3::new(x, y, 0.0))
        .collect();
    let m = some_motion();
    let dst: Vec<Vector3<f64>> = src.iter().map(|p| (m * Point3::from(*p)).coords).collect();
    let t = umeyama_se3(&src, &dst).expect("align");
    assert!((t.translation.vector - m.translation.vector).norm() < 1e-12);
    assert!(t.rotation.angle_to(&m.rotation) < 1e-12);
}

#[test]
fn umeyama_rejects_bad_input() {
    let v = |x: f64, y: f64, z: f64| Vector3::new(x, y, z);
    let two = [v(0.0, 0.0, 0.0), v(1.0, 0.0, 0.0)];
    assert_eq!(
        umeyama_se3(&two, &two),
        Err(EvalError::TooFewPoints {
            got: 2,
            required: 3
        })
    );
    let line: Vec<_> = (0..10)
        .map(|i| v(i as f64, 2.0 * i as f64, -(i as f64)))
        .collect();
    assert!(matches!(
        umeyama_se3(&line, &line),
        Err(EvalError::DegenerateAlignment { .. })
    ));
    // Exactly collinear with large coordinates: evo's absolute test alone
    // would accept this, the relative test rejects it.
    let far: Vec<_> = (0..10)
        .map(|i| v(1e4 + 0.1 * i as f64, 3e4, -5e3))
        .collect();
    assert!(matches!(
        umeyama_se3(&far, &far),
        Err(EvalError::DegenerateAlignment { .. })
    ));
    let same = [v(1.0, 2.0, 3.0); 5];
    assert!(matches!(
        umeyama_se3(&same, &same),
        Err(EvalError::DegenerateAlignment { .. })
    ));
    let tri = [v(0.0, 0.0, 0.0), v(1.0, 0.0, 0.0), v(0.0, 1.0, 0.0)];
    assert!(matches!(
        umeyama_se3(&tri, &tri[..2]),
        Err(EvalError::LengthMismatch { .. })
    ));
    let nan = [v(0.0, 0.0, 0.0), v(1.0, f64::NAN, 0.0), v(0.0, 1.0, 0.0)];
    assert_eq!(
        umeyama_se3(&tri, &nan),
        Err(EvalError::NonFinite {
            what: "destination point",
            index: 1
        })
    );
}

#[test]
fn ape_errors() {
    let gt = helix(10);
    let far: Vec<_> = gt.iter().map(|(t, p)| (t + 50.0, *p)).collect();
    assert!(matches!(
        ape_translation(&gt, &far, 0.01),
        Err(EvalError::NoMatches { .. })
    ));
    assert_eq!(
        ape_translation(&gt, &gt[..2], 0.01),
        Err(EvalError::TooFewMatches {
            matched: 2,
            required: 3
        })
    );
    assert!(matches!(
        ape_translation(&gt, &gt, -1.0),
        Err(EvalError::InvalidMaxDiff { .. })
    ));
    assert!(matches!(
        ape_translation(&gt, &gt, f64::NAN),
        Err(EvalError::InvalidMaxDiff { .. })
    ));
    let mut bad = gt.clone();
    bad[3].0 = f64::INFINITY;
    assert_eq!(
        ape_translation(&gt, &bad, 0.01),
        Err(EvalError::NonFinite {
            what: "estimate timestamp",
            index: 3
        })
    );
    let mut bad = gt.clone();
    bad[5].1.translation.vector.y = f64::NAN;
    assert_eq!(
        ape_translation(&bad, &gt, 0.01),
        Err(EvalError::NonFinite {
            what: "reference pose",
            index: 5
        })
    );
    // Error messages name the values.
    let msg = EvalError::TooFewMatches {
        matched: 2,
        required: 3,
    }
    .to_string();
    assert!(msg.contains('2') && msg.contains('3'), "{msg}");
}

fn vec3(range: f64) -> impl Strategy<Value = Vector3<f64>> {
    (-range..range, -range..range, -range..range).prop_map(|(x, y, z)| Vector3::new(x, y, z))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    /// Moving the estimate rigidly does not change the aligned APE, and the
    /// aligned rmse never exceeds the unaligned one.
    #[test]
    fn aligned_rmse_is_invariant_to_rigid_motion_of_estimate(
        pts in prop::collection::vec((vec3(10.0), vec3(1.0)), 4..40),
        noise_scale in 0.01f64..1.0,
        axis_angle in vec3(3.0),
        shift in vec3(100.0),
    ) {
        let gt: Vec<_> = pts
            .iter()
            .enumerate()
            .map(|(i, (p, _))| (i as f64, Isometry3::translation(p.x, p.y, p.z)))
            .collect();
        let est: Vec<_> = pts
            .iter()
            .enumerate()
            .map(|(i, (p, n))| {
                let q = p + n * noise_scale;
                (i as f64, Isometry3::translation(q.x, q.y, q.z))
            })
            .collect();
        let m = Isometry3::from_parts(
            Translation3::from(shift),
            UnitQuaternion::from_scaled_axis(axis_angle),
        );
        // Random point sets are non-degenerate with probability one; skip the
        // (practically impossible) degenerate draws rather than fail.
        let Ok(base) = ape_translation(&gt, &est, 0.01) else { return Ok(()); };
        let moved = ape_translation(&gt, &moved(&est, &m), 0.01)
            .map_err(|e| TestCaseError::fail(e.to_string()))?;
        let tol = 1e-9 * base.rmse_m.max(1e-3);
        prop_assert!((base.rmse_m - moved.rmse_m).abs() < tol,
            "{} vs {}", base.rmse_m, moved.rmse_m);
        prop_assert_eq!(base.matched, moved.matched);
        let unaligned = (pts.iter().map(|(_, n)| (n * noise_scale).norm_squared()).sum::<f64>()
            / pts.len() as f64).sqrt();
        prop_assert!(base.rmse_m <= unaligned * (1.0 + 1e-12) + 1e-15);
    }
}
