//! Absolute Pose Error (translation part) after SE(3) Umeyama alignment,
//! matching `evo_ape tum GT EST -a` (evo 1.38.1).
//!
//! Pipeline, as in evo: associate poses by nearest timestamp
//! ([`associate`]), align the matched estimate positions onto the matched
//! reference positions ([`umeyama_se3`]), then take statistics of the
//! per-pose errors `e_i = ‖T·p_est,i − p_gt,i‖`.

mod associate;
mod stats;
mod umeyama;

pub use associate::associate;
pub use umeyama::{MIN_POINTS, umeyama_se3};

use nalgebra::{Isometry3, Vector3};

use crate::EvalError;
use stats::ErrorStats;

/// evo's default `--t_max_diff` for association, seconds.
pub const DEFAULT_MAX_DIFF_S: f64 = 0.01;

/// Result of [`ape_translation`]. All distances in metres.
#[derive(Debug, Clone, PartialEq)]
pub struct ApeResult {
    /// Root mean square of the errors, `sqrt((1/n) Σ e_i²)` (evo's `rmse`).
    pub rmse_m: f64,
    /// Mean error `(1/n) Σ e_i`.
    pub mean_m: f64,
    /// Median error (mean of the two middle values for even `n`).
    pub median_m: f64,
    /// Largest error.
    pub max_m: f64,
    /// Smallest error.
    pub min_m: f64,
    /// Population standard deviation of the errors (ddof 0, like evo).
    pub std_m: f64,
    /// Number of associated pose pairs `n` the statistics are taken over.
    pub matched: usize,
    /// `T` with `p_gt ≈ T · p_est`: the motion applied to the estimate.
    pub alignment: Isometry3<f64>,
    /// Associated `(gt_index, est_index)` pairs, in evo's order.
    pub pairs: Vec<(usize, usize)>,
    /// Per-pair error `e_i`, parallel to `pairs`.
    pub errors_m: Vec<f64>,
}

/// Translation APE of `est` against `gt` after SE(3) alignment, as
/// `evo_ape tum GT EST -a --t_max_diff max_diff_s` computes it.
///
/// Both trajectories are `(timestamp_s, world_from_body)` lists. Poses are
/// associated with [`associate`]; the rigid `T` minimising
/// `Σ‖T·p_est − p_gt‖²` over the matched positions is found with
/// [`umeyama_se3`] (evo transforms the estimate, never the reference), and
/// the statistics are taken over `e_i = ‖T·p_est,i − p_gt,i‖`. Orientations
/// are only validated, not used.
///
/// # Errors
/// [`EvalError::InvalidMaxDiff`] for a negative/non-finite tolerance,
/// [`EvalError::NonFinite`] for a NaN/∞ stamp or pose,
/// [`EvalError::NoMatches`] if nothing associates,
/// [`EvalError::TooFewMatches`] for fewer than [`MIN_POINTS`] pairs, and
/// [`EvalError::DegenerateAlignment`] / [`EvalError::SvdFailed`] from the
/// alignment.
pub fn ape_translation(
    gt: &[(f64, Isometry3<f64>)],
    est: &[(f64, Isometry3<f64>)],
    max_diff_s: f64,
) -> Result<ApeResult, EvalError> {
    if !(max_diff_s.is_finite() && max_diff_s >= 0.0) {
        return Err(EvalError::InvalidMaxDiff { max_diff_s });
    }
    check_trajectory(gt, "reference timestamp", "reference pose")?;
    check_trajectory(est, "estimate timestamp", "estimate pose")?;

    let gt_stamps: Vec<f64> = gt.iter().map(|(t, _)| *t).collect();
    let est_stamps: Vec<f64> = est.iter().map(|(t, _)| *t).collect();
    let pairs = associate(&gt_stamps, &est_stamps, max_diff_s);
    if pairs.is_empty() {
        return Err(EvalError::NoMatches {
            gt_len: gt.len(),
            est_len: est.len(),
            max_diff_s,
        });
    }
    if pairs.len() < MIN_POINTS {
        return Err(EvalError::TooFewMatches {
            matched: pairs.len(),
            required: MIN_POINTS,
        });
    }

    let position = |pose: &Isometry3<f64>| pose.translation.vector;
    let p_gt: Vec<Vector3<f64>> = pairs.iter().map(|&(g, _)| position(&gt[g].1)).collect();
    let p_est: Vec<Vector3<f64>> = pairs.iter().map(|&(_, e)| position(&est[e].1)).collect();
    let alignment = umeyama_se3(&p_est, &p_gt)?;

    let errors_m: Vec<f64> = p_est
        .iter()
        .zip(&p_gt)
        .map(|(pe, pg)| (alignment.rotation * pe + alignment.translation.vector - pg).norm())
        .collect();
    // `pairs` is non-empty here, so the statistics always exist.
    let s = ErrorStats::from_errors(&errors_m).ok_or(EvalError::NoMatches {
        gt_len: gt.len(),
        est_len: est.len(),
        max_diff_s,
    })?;
    Ok(ApeResult {
        rmse_m: s.rmse,
        mean_m: s.mean,
        median_m: s.median,
        max_m: s.max,
        min_m: s.min,
        std_m: s.std,
        matched: pairs.len(),
        alignment,
        pairs,
        errors_m,
    })
}

/// Rejects the first non-finite timestamp or pose component.
fn check_trajectory(
    traj: &[(f64, Isometry3<f64>)],
    stamp_what: &'static str,
    pose_what: &'static str,
) -> Result<(), EvalError> {
    for (index, (t, pose)) in traj.iter().enumerate() {
        if !t.is_finite() {
            return Err(EvalError::NonFinite {
                what: stamp_what,
                index,
            });
        }
        let finite = pose.translation.vector.iter().all(|c| c.is_finite())
            && pose.rotation.coords.iter().all(|c| c.is_finite());
        if !finite {
            return Err(EvalError::NonFinite {
                what: pose_what,
                index,
            });
        }
    }
    Ok(())
}

/// [`ape_translation`] for two pose sequences already in one-to-one order (pose `k` of `est`
/// estimates pose `k` of `gt`), as the synthetic windows produce them.
pub fn ape_translation_paired(
    gt: &[Isometry3<f64>],
    est: &[Isometry3<f64>],
) -> Result<ApeResult, EvalError> {
    let stamped = |poses: &[Isometry3<f64>]| -> Vec<(f64, Isometry3<f64>)> {
        poses
            .iter()
            .enumerate()
            .map(|(k, pose)| (k as f64, *pose))
            .collect()
    };
    ape_translation(&stamped(gt), &stamped(est), DEFAULT_MAX_DIFF_S)
}
