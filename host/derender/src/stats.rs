//! Robust statistics: median, median absolute deviation, trimmed mean.

use serde::Serialize;

/// Robust summary of a set of values.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RobustStats {
    /// Number of values.
    pub count: usize,
    /// Median.
    pub median: f64,
    /// Mean after discarding the lowest and highest [`TRIM_FRACTION`] each.
    pub trimmed_mean: f64,
    /// Median absolute deviation scaled to a normal standard deviation (× 1.4826).
    pub mad_sigma: f64,
    /// Interquartile range.
    pub iqr: f64,
    /// 5th percentile.
    pub p05: f64,
    /// 95th percentile.
    pub p95: f64,
}

/// Fraction trimmed from each end by [`RobustStats::trimmed_mean`].
pub const TRIM_FRACTION: f64 = 0.1;

/// Percentile of sorted values by linear interpolation (`q` in `[0, 1]`).
pub fn percentile_sorted(sorted: &[f64], q: f64) -> f64 {
    skinbrdf_core::stats::quantile_sorted(sorted, q)
}

impl RobustStats {
    /// Summarises the finite values of `values` (non-finite ones are ignored); `None` if none.
    pub fn of(values: &[f64]) -> Option<Self> {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let median = percentile_sorted(&v, 0.5);
        let k = (v.len() as f64 * TRIM_FRACTION).floor() as usize;
        let core = &v[k..v.len() - k];
        let trimmed_mean = core.iter().sum::<f64>() / core.len() as f64;
        let mut dev: Vec<f64> = v.iter().map(|x| (x - median).abs()).collect();
        dev.sort_by(f64::total_cmp);
        Some(Self {
            count: v.len(),
            median,
            trimmed_mean,
            mad_sigma: 1.4826 * percentile_sorted(&dev, 0.5),
            iqr: percentile_sorted(&v, 0.75) - percentile_sorted(&v, 0.25),
            p05: percentile_sorted(&v, 0.05),
            p95: percentile_sorted(&v, 0.95),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outliers_do_not_move_the_robust_centre() {
        let mut v: Vec<f64> = (0..100).map(|i| 1.0 + 0.001 * (i as f64 - 50.0)).collect();
        v.extend([1e6, -1e6, f64::NAN]);
        let s = RobustStats::of(&v).unwrap();
        assert_eq!(s.count, 102);
        assert!((s.median - 1.0).abs() < 1e-3);
        assert!((s.trimmed_mean - 1.0).abs() < 1e-3);
        assert!(s.mad_sigma < 0.05);
        assert!(RobustStats::of(&[f64::NAN]).is_none());
    }
}
