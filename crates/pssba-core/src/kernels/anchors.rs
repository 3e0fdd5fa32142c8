//! The frames a kernel's surface is anchored to (DESIGN step 6, "anchor offset"). The paper
//! attaches each kernel's surface to the kernel point's own frame. In a long window that sees
//! a place again and again (an orbit, a revisit) one anchor per kernel means fewer anchors
//! per frame as the window grows (1 / frames): measured on a 1000-frame hangar orbit, 7.6 mm
//! APE against 3.7 mm for its first 100 frames, with residuals to spare. So the window is cut
//! into groups of consecutive frames, and a kernel gets one surface per group that sees it,
//! each anchored to the group's frame with the most points at the kernel: every frame then
//! anchors about as many surfaces as in a window of one group's length.

use crate::kernels::frame_set::FrameSet;

/// Least number of a frame's points at a kernel for the surface to be moved onto them (the
/// anchor offset); fewer, and the anchor would be a guess.
pub const MIN_ANCHOR_POINTS: usize = 3;

/// Frame groups of a window of `frames` frames: one per `frames_per_group` frames, rounded
/// up (a window of at most `frames_per_group` frames: one group, the paper's anchoring).
pub fn frame_groups(frames: usize, frames_per_group: usize) -> usize {
    frames.div_ceil(frames_per_group.max(1)).max(1)
}

/// The group of `frame` among `groups` groups of a window of `frames` frames (runs of
/// consecutive frames of equal length, give or take one).
pub fn group_of(frame: u32, frames: usize, groups: usize) -> usize {
    (frame as usize * groups.max(1) / frames.max(1)).min(groups.max(1) - 1)
}

/// Per-thread buffers of [`anchor_frames`], kept empty between calls.
#[derive(Debug, Default)]
pub struct AnchorScratch {
    /// Points per frame.
    counts: Vec<u32>,
    /// Frames with a point.
    seen: FrameSet,
}

/// Anchor frames of a kernel with several groups: for each group in order, the frame of the
/// group with the most of `point_frames` (the frames of the kernel's neighbours, one entry per
/// point; each below `frames`), ties to the lower frame, if it has at least
/// [`MIN_ANCHOR_POINTS`].
pub fn anchor_frames(
    point_frames: impl Iterator<Item = u32>,
    frames: usize,
    groups: usize,
    scratch: &mut AnchorScratch,
) -> Vec<u32> {
    if scratch.counts.len() < frames {
        scratch.counts.resize(frames, 0);
    }
    scratch.seen.reserve_frames(frames);
    for frame in point_frames {
        scratch.counts[frame as usize] += 1;
        scratch.seen.insert(frame as usize);
    }
    // Per group: (points, frame) of its best frame so far.
    let mut best: Vec<(u32, u32)> = vec![(0, 0); groups.max(1)];
    let counts = &mut scratch.counts;
    scratch.seen.drain_ascending(|frame| {
        let count = std::mem::take(&mut counts[frame]);
        let slot = &mut best[group_of(frame as u32, frames, groups)];
        // Frames come in ascending order: a strictly larger count wins, ties keep the lower.
        if count > slot.0 {
            *slot = (count, frame as u32);
        }
    });
    best.into_iter()
        .filter(|&(count, _)| count as usize >= MIN_ANCHOR_POINTS)
        .map(|(_, frame)| frame)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn groups_cut_the_window_into_runs() {
        assert_eq!(frame_groups(1, 100), 1);
        assert_eq!(frame_groups(100, 100), 1);
        assert_eq!(frame_groups(101, 100), 2);
        assert_eq!(frame_groups(1000, 100), 10);
        assert_eq!(frame_groups(0, 100), 1);
        assert_eq!(frame_groups(5, 0), 5);
        // 1000 frames in 10 groups: runs of 100.
        assert_eq!(group_of(0, 1000, 10), 0);
        assert_eq!(group_of(99, 1000, 10), 0);
        assert_eq!(group_of(100, 1000, 10), 1);
        assert_eq!(group_of(999, 1000, 10), 9);
        // 101 frames in 2 groups: 51 and 50.
        assert_eq!(group_of(50, 101, 2), 0);
        assert_eq!(group_of(51, 101, 2), 1);
        // Every frame in range, runs non-decreasing, every group used.
        for (frames, groups) in [(7, 3), (101, 2), (1000, 10), (5, 5)] {
            let g: Vec<usize> = (0..frames as u32)
                .map(|f| group_of(f, frames, groups))
                .collect();
            assert!(g.windows(2).all(|w| w[0] <= w[1] && w[1] <= w[0] + 1));
            assert_eq!((g[0], g[frames - 1]), (0, groups - 1));
        }
    }

    #[test]
    fn each_group_anchors_to_its_best_seen_frame() {
        let mut scratch = AnchorScratch::default();
        // 10 frames in 2 groups (0-4, 5-9). Group 0: frame 1 has 4 points, frame 3 has 4
        // (tie: the lower frame), frame 0 has 2. Group 1: frame 7 has 5, frame 9 has 6.
        let frames = [
            1, 3, 9, 1, 7, 3, 0, 9, 1, 7, 3, 9, 7, 1, 0, 3, 9, 7, 9, 7, 9,
        ];
        let got = anchor_frames(frames.iter().copied(), 10, 2, &mut scratch);
        assert_eq!(got, vec![1, 9]);
        // A group whose best frame has too few points gets no anchor.
        let got = anchor_frames([2, 2, 6, 6, 6].into_iter(), 10, 2, &mut scratch);
        assert_eq!(got, vec![6]);
        assert!(anchor_frames(std::iter::empty(), 10, 2, &mut scratch).is_empty());
    }
}
