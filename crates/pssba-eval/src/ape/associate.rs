//! Nearest-timestamp association of a reference and an estimated trajectory,
//! reproducing evo's `sync.associate_trajectories` (`SyncMethod.nearest_time`,
//! no time offset) as used by `evo_ape` (evo 1.38.1, `evo/core/sync.py`).

/// Associates reference (`gt_stamps`) and estimate (`est_stamps`) timestamps
/// by nearest time, exactly as evo's `associate_trajectories(ref, est,
/// max_diff=max_diff_s)` does. Returns `(gt_index, est_index)` pairs.
///
/// evo's rules, mirrored here:
/// * The trajectory with **fewer** poses is the "short" one (the estimate on
///   a tie). Every short stamp `s` is matched to its nearest long stamp `l`
///   if `|s - l| <= max_diff_s`; pairs come out in short-index order.
/// * Each short pose is used at most once, but two short poses may pick the
///   same long pose if they are closer together than `max_diff_s`. evo does
///   not deduplicate, so neither does this function; with stamps spaced by
///   more than `2 * max_diff_s` the result is one-to-one.
/// * If the long stamps are non-decreasing, a binary search is used: short
///   stamps outside `[long[0] - max_diff, long[n-1] + max_diff]` are skipped;
///   otherwise `i = #{l <= s}` (numpy `searchsorted(side="right")`, clamped
///   to `n-1`), `ub = long[i] - s`, `lb = s - long[i-1]` (∞ for `i = 0`), and
///   the upper neighbour wins if `ub <= max_diff && ub < lb`, else the lower
///   one if `lb <= max_diff && lb <= ub` (ties go to the earlier stamp).
/// * If the long stamps are not sorted, a linear search picks the first index
///   of the minimal `|long[j] - s|` (numpy `argmin`), kept if `<= max_diff`.
///
/// Non-finite stamps never produce a pair (a NaN short stamp is skipped; in
/// the unsorted path any NaN difference suppresses the match, like numpy's
/// NaN-propagating `argmin`). A NaN or negative `max_diff_s` yields no pairs.
/// [`crate::ape::ape_translation`] rejects such inputs before associating.
pub fn associate(gt_stamps: &[f64], est_stamps: &[f64], max_diff_s: f64) -> Vec<(usize, usize)> {
    if est_stamps.len() > gt_stamps.len() {
        // Reference is the short trajectory: pairs are (short=gt, long=est).
        matching_time_indices(gt_stamps, est_stamps, max_diff_s)
    } else {
        matching_time_indices(est_stamps, gt_stamps, max_diff_s)
            .into_iter()
            .map(|(est, gt)| (gt, est))
            .collect()
    }
}

/// evo's `matching_time_indices(stamps_1=short, stamps_2=long, max_diff)`:
/// returns `(short_index, long_index)` pairs.
fn matching_time_indices(short: &[f64], long: &[f64], max_diff: f64) -> Vec<(usize, usize)> {
    let (Some(&first), Some(&last)) = (long.first(), long.last()) else {
        return Vec::new();
    };
    // np.all(np.diff(long) >= 0); a NaN difference counts as unsorted.
    let sorted = long.windows(2).all(|w| w[1] - w[0] >= 0.0);
    let mut pairs = Vec::with_capacity(short.len());
    for (i_short, &s) in short.iter().enumerate() {
        let best = if sorted {
            if s.is_nan() || s < first - max_diff || s > last + max_diff {
                continue;
            }
            nearest_sorted(long, s, max_diff)
        } else {
            nearest_linear(long, s, max_diff)
        };
        if let Some(i_long) = best {
            pairs.push((i_short, i_long));
        }
    }
    pairs
}

/// Binary-search branch of evo's matcher for a non-decreasing `long`.
fn nearest_sorted(long: &[f64], s: f64, max_diff: f64) -> Option<usize> {
    // searchsorted(side="right"), clamped to the last index.
    let idx = long.partition_point(|&l| l <= s).min(long.len() - 1);
    let diff_ub = long[idx] - s;
    let diff_lb = match idx.checked_sub(1) {
        Some(prev) => s - long[prev],
        None => f64::INFINITY,
    };
    if diff_ub <= max_diff && diff_ub < diff_lb {
        Some(idx)
    } else if diff_lb <= max_diff && diff_lb <= diff_ub {
        idx.checked_sub(1)
    } else {
        None
    }
}

/// Linear-search branch of evo's matcher (first minimum, NaN wins like numpy).
fn nearest_linear(long: &[f64], s: f64, max_diff: f64) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for (j, &l) in long.iter().enumerate() {
        let d = (l - s).abs();
        if d.is_nan() {
            // numpy.argmin returns the first NaN, and NaN <= max_diff is false.
            return None;
        }
        if best.is_none_or(|(_, bd)| d < bd) {
            best = Some((j, d));
        }
    }
    best.filter(|&(_, d)| d <= max_diff).map(|(j, _)| j)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_lengths_match_each_estimate_to_nearest_reference() {
        let gt = [0.0, 0.1, 0.2, 0.3];
        let est = [0.004, 0.095, 0.25, 0.3];
        // 0.25 is 0.05 away from both neighbours: no match.
        assert_eq!(associate(&gt, &est, 0.01), vec![(0, 0), (1, 1), (3, 3)]);
    }

    #[test]
    fn shorter_reference_is_the_short_side() {
        // gt shorter: every gt stamp looks for its nearest estimate.
        let gt = [0.0, 1.0];
        let est = [0.0, 0.005, 0.5, 1.0];
        assert_eq!(associate(&gt, &est, 0.01), vec![(0, 0), (1, 3)]);
    }

    #[test]
    fn dense_short_stamps_may_share_a_long_stamp_like_evo() {
        let gt = [0.0, 1.0, 2.0];
        let est = [0.0, 0.004];
        assert_eq!(associate(&gt, &est, 0.01), vec![(0, 0), (0, 1)]);
    }

    #[test]
    fn tie_goes_to_the_earlier_stamp() {
        let gt = [0.0, 0.5, 0.75, 1.0];
        let est = [0.625, 2.0, 3.0];
        assert_eq!(associate(&gt, &est, 0.2), vec![(1, 0)]);
    }

    #[test]
    fn unsorted_long_side_uses_linear_search() {
        let gt = [0.3, 0.1, 0.2, 0.0];
        let est = [0.0, 0.201];
        assert_eq!(associate(&gt, &est, 0.01), vec![(3, 0), (2, 1)]);
    }

    #[test]
    fn out_of_range_and_empty_inputs() {
        assert!(associate(&[], &[], 0.01).is_empty());
        assert!(associate(&[1.0, 2.0], &[], 0.01).is_empty());
        assert!(associate(&[1.0, 2.0], &[5.0], 0.01).is_empty());
        assert!(associate(&[1.0, 2.0], &[2.0], f64::NAN).is_empty());
        assert!(associate(&[1.0, f64::NAN], &[1.0], 0.01).is_empty());
        assert_eq!(associate(&[1.0, 2.0], &[2.009], 0.01), vec![(1, 0)]);
    }
}
