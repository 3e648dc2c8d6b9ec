//! Order statistics and subsampling with one stated semantics for the whole project.
//!
//! * [`quantile`] of a set of values is the linear interpolation between order statistics
//!   (Hyndman and Fan's type 7, the default of R and NumPy): with the `n` finite values sorted
//!   as `x[0] <= ... <= x[n-1]`, `h = q (n - 1)`, the quantile is
//!   `x[floor h] + (h - floor h) (x[floor h + 1] - x[floor h])`. `q` is clamped to `[0, 1]`.
//! * Non-finite values (NaN, infinities) are ignored: they are failed measurements, not
//!   extreme ones. With no finite value the result is NaN, so a report shows "no data" rather
//!   than a number.
//! * [`median`] is the 0.5 quantile (the mean of the two middle values for an even count).
//! * [`strided_indices`] picks at most `k` of `n` items, evenly spread and deterministic
//!   (`floor(i n / k)`), so that a subsample is reproducible and covers the whole range.

/// The `q` quantile of the finite values (type 7, see the module docs); NaN when none.
pub fn quantile(values: &[f64], q: f64) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    quantile_sorted(&v, q)
}

/// The `q` quantile of values already sorted ascending and all finite; NaN when empty.
pub fn quantile_sorted(sorted: &[f64], q: f64) -> f64 {
    let n = sorted.len();
    if n == 0 {
        return f64::NAN;
    }
    let h = if q.is_nan() { 0.5 } else { q.clamp(0.0, 1.0) } * (n - 1) as f64;
    let i = h.floor() as usize;
    let j = (i + 1).min(n - 1);
    sorted[i] + (h - i as f64) * (sorted[j] - sorted[i])
}

/// The median of the finite values; NaN when none.
pub fn median(values: &[f64]) -> f64 {
    quantile(values, 0.5)
}

/// The median of the finite values; `None` when none (a figure of nothing is absent, not NaN).
pub fn median_finite(values: &[f64]) -> Option<f64> {
    Some(median(values)).filter(|m| m.is_finite())
}

/// At most `k` indices into `0..n`, evenly strided and increasing: all of them when `n <= k`.
pub fn strided_indices(n: usize, k: usize) -> Vec<usize> {
    if n <= k {
        return (0..n).collect();
    }
    (0..k)
        .map(|i| ((i as u128 * n as u128) / k as u128) as usize)
        .collect()
}

/// At most `k` items of `items`, evenly strided (see [`strided_indices`]).
pub fn strided_subsample<T: Clone>(items: &[T], k: usize) -> Vec<T> {
    strided_indices(items.len(), k)
        .into_iter()
        .filter_map(|i| items.get(i).cloned())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_interpolate_and_ignore_non_finite() {
        let v = [3.0, f64::NAN, 1.0, 2.0, f64::INFINITY, 4.0];
        assert_eq!(median(&v), 2.5);
        assert_eq!(quantile(&v, 0.0), 1.0);
        assert_eq!(quantile(&v, 1.0), 4.0);
        assert_eq!(quantile(&v, 2.0), 4.0);
        assert!((quantile(&v, 0.9) - 3.7).abs() < 1e-12);
        assert_eq!(median(&[5.0]), 5.0);
        assert!(median(&[]).is_nan());
        assert!(median(&[f64::NAN]).is_nan());
    }

    #[test]
    fn strides_cover_the_range_without_repeats() {
        assert_eq!(strided_indices(3, 5), vec![0, 1, 2]);
        let s = strided_indices(1000, 7);
        assert_eq!(s.len(), 7);
        assert!(s.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(s[0], 0);
        // The last index lies within one stride of the end.
        assert!(*s.last().unwrap_or(&0) + 1000 / 7 + 1 >= 1000);
        assert_eq!(strided_subsample(&[1, 2, 3, 4], 2), vec![1, 3]);
    }

    proptest::proptest! {
        #[test]
        fn quantile_is_monotone_and_within_range(
            v in proptest::collection::vec(-1e6f64..1e6, 1..50),
            a in 0.0f64..1.0,
            b in 0.0f64..1.0,
        ) {
            let (lo, hi) = if a <= b { (a, b) } else { (b, a) };
            let (qa, qb) = (quantile(&v, lo), quantile(&v, hi));
            proptest::prop_assert!(qa <= qb);
            let min = v.iter().copied().fold(f64::INFINITY, f64::min);
            let max = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            proptest::prop_assert!(qa >= min && qb <= max);
        }
    }
}
