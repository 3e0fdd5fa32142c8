//! Summary statistics of per-pose errors, with evo's (numpy's) conventions.

/// Statistics of a non-empty error sample `e_1..e_n`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ErrorStats {
    /// `sqrt((1/n) Σ e_i²)`.
    pub rmse: f64,
    /// `(1/n) Σ e_i`.
    pub mean: f64,
    /// Middle value; mean of the two middle values for even `n` (`np.median`).
    pub median: f64,
    /// Largest error.
    pub max: f64,
    /// Smallest error.
    pub min: f64,
    /// Population standard deviation `sqrt((1/n) Σ (e_i − mean)²)` (`np.std`, ddof 0).
    pub std: f64,
}

impl ErrorStats {
    /// Computes the statistics; `None` for an empty sample.
    pub(crate) fn from_errors(errors: &[f64]) -> Option<Self> {
        let n = errors.len() as f64;
        let mut sorted = errors.to_vec();
        sorted.sort_by(f64::total_cmp);
        let (&min, &max) = (sorted.first()?, sorted.last()?);
        let mid = sorted.len() / 2;
        let median = if sorted.len() % 2 == 1 {
            sorted[mid]
        } else {
            0.5 * (sorted[mid - 1] + sorted[mid])
        };
        let mean = errors.iter().sum::<f64>() / n;
        let rmse = (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
        let std = (errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n).sqrt();
        Some(Self {
            rmse,
            mean,
            median,
            max,
            min,
            std,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_checked_values() {
        let s = ErrorStats::from_errors(&[3.0, 1.0, 4.0, 0.0]).expect("non-empty");
        assert_eq!(s.min, 0.0);
        assert_eq!(s.max, 4.0);
        assert_eq!(s.median, 2.0);
        assert_eq!(s.mean, 2.0);
        assert!((s.rmse - (26.0f64 / 4.0).sqrt()).abs() < 1e-15);
        assert!((s.std - (10.0f64 / 4.0).sqrt()).abs() < 1e-15);
        assert_eq!(ErrorStats::from_errors(&[5.0]).map(|s| s.median), Some(5.0));
        assert!(ErrorStats::from_errors(&[]).is_none());
    }
}
