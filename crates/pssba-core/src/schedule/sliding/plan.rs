//! The window plan of a frame stream (DESIGN section 6). Window 0 holds frames `[0, W)` with
//! frame 0 as the gauge. Every later window ends `S` frames further on and starts `W` frames
//! before its end, so its first `W - S` frames are already final and held fixed: they anchor
//! the new frames to the trajectory so far. At the end of the stream one last window takes
//! what is left, with the same `W - S` anchors. Every frame is final in exactly one window:
//! the one in which it was free.

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// One window to run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WindowPlan {
    /// First frame (stream index).
    pub first: usize,
    /// One past the last frame.
    pub end: usize,
    /// Per window frame: held fixed (already final, or the gauge of window 0).
    pub fixed: Vec<bool>,
}

/// The next window, given `finalised` frames already final, `available` frames received and
/// whether the stream has ended; `None` when more frames are needed (or none are left).
pub fn next_window(
    window_frames: usize,
    window_stride: usize,
    finalised: usize,
    available: usize,
    end_of_stream: bool,
) -> Option<WindowPlan> {
    if finalised >= available {
        return None;
    }
    let wanted_end = if finalised == 0 {
        window_frames
    } else {
        finalised + window_stride
    };
    let end = if available >= wanted_end {
        wanted_end
    } else if end_of_stream {
        available
    } else {
        return None;
    };
    // Every later window keeps the same W - S anchors, the last (shorter) one too: widening
    // it back to W frames would re-fit up to W - 1 final frames to place a few new ones (the
    // README's main job: a 100-frame window, 1.3 s, for its last 20 frames).
    let first = finalised.saturating_sub(window_frames.saturating_sub(window_stride));
    let fixed = (first..end)
        .map(|k| {
            if finalised == 0 {
                k == 0
            } else {
                k < finalised
            }
        })
        .collect();
    Some(WindowPlan { first, end, fixed })
}

/// The correction `final * initial^-1` averaged over the anchor frames (rotations by their
/// chordal mean), applied to the new frames' initial poses so they start where the anchors
/// moved: odometry drift and the gauge chosen by earlier windows carry over instead of being
/// re-learned from scratch. Identity without anchors.
pub fn anchor_correction(anchors: &[(Isometry3<f64>, Isometry3<f64>)]) -> Isometry3<f64> {
    if anchors.is_empty() {
        return Isometry3::identity();
    }
    let mut rotation_sum = Matrix3::zeros();
    let mut translation_sum = Vector3::zeros();
    for (initial, final_pose) in anchors {
        let correction = final_pose * initial.inverse();
        rotation_sum += correction.rotation.to_rotation_matrix().matrix();
        translation_sum += correction.translation.vector;
    }
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&rotation_sum));
    Isometry3::from_parts(
        Translation3::from(translation_sum / anchors.len() as f64),
        rotation,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every frame is free in exactly one window, whatever the arrival pattern.
    #[test]
    fn every_frame_is_final_once() {
        for (w, s, total) in [
            (10, 8, 37),
            (10, 9, 30),
            (5, 1, 12),
            (100, 80, 50),
            (4, 3, 4),
        ] {
            let mut finalised = 0;
            let mut free_count = vec![0; total];
            for available in 1..=total {
                let end = available == total;
                while let Some(plan) = next_window(w, s, finalised, available, end) {
                    assert!(plan.end - plan.first <= w);
                    for (i, &fixed) in plan.fixed.iter().enumerate() {
                        let k = plan.first + i;
                        assert_eq!(
                            fixed,
                            if finalised == 0 {
                                k == 0
                            } else {
                                k < finalised
                            }
                        );
                        if !fixed || k == 0 {
                            free_count[k] += 1;
                        }
                    }
                    // Later windows keep the overlap as anchors, the last one too.
                    if finalised > 0 {
                        assert!(plan.first < finalised);
                        let anchors = plan.fixed.iter().filter(|&&f| f).count();
                        assert_eq!(anchors, (w - s).min(finalised), "{w} {s} {total}");
                    }
                    finalised = plan.end;
                }
            }
            assert!(
                free_count.iter().all(|&c| c == 1),
                "{w} {s} {total}: {free_count:?}"
            );
        }
    }

    #[test]
    fn one_window_when_it_holds_everything() {
        let plan = next_window(100, 80, 0, 60, true).expect("a window");
        assert_eq!((plan.first, plan.end), (0, 60));
        assert_eq!(plan.fixed.iter().filter(|&&f| f).count(), 1);
        assert_eq!(next_window(100, 80, 0, 60, false), None);
    }

    #[test]
    fn correction_recovers_a_common_motion() {
        let motion = Isometry3::new(
            Vector3::new(0.3, -0.1, 0.2),
            Vector3::new(0.01, 0.02, -0.03),
        );
        let anchors: Vec<_> = (0..5)
            .map(|k| {
                let initial = Isometry3::new(
                    Vector3::new(k as f64, 2.0, 0.5),
                    Vector3::new(0.0, 0.0, 0.1 * k as f64),
                );
                (initial, motion * initial)
            })
            .collect();
        let correction = anchor_correction(&anchors);
        assert!((correction.to_homogeneous() - motion.to_homogeneous()).norm() < 1e-12);
    }
}
