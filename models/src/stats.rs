//! Order statistics shared by the stages, the report sections and the studies: one
//! median, so that every published median means the same thing.

/// Median of the finite values (the mean of the two middle values for an even count);
/// NaN when there is none.
pub fn finite_median(values: impl IntoIterator<Item = f64>) -> f64 {
    let mut finite: Vec<f64> = values.into_iter().filter(|v| v.is_finite()).collect();
    if finite.is_empty() {
        return f64::NAN;
    }
    finite.sort_by(f64::total_cmp);
    let mid = finite.len() / 2;
    if finite.len() % 2 == 1 {
        finite[mid]
    } else {
        0.5 * (finite[mid - 1] + finite[mid])
    }
}

/// The `q` quantile of `values` by nearest rank (the 90th percentiles); sorts `values`;
/// NaN when empty.
pub fn nearest_rank_quantile(values: &mut [f64], q: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.sort_by(f64::total_cmp);
    let rank = ((q * values.len() as f64).ceil() as usize).clamp(1, values.len());
    values[rank - 1]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn odd_even_empty_and_non_finite() {
        assert_eq!(finite_median([3.0, 1.0, 2.0]), 2.0);
        assert_eq!(finite_median([4.0, 1.0, 3.0, 2.0]), 2.5);
        assert_eq!(finite_median([f64::NAN, 5.0, f64::INFINITY, 1.0]), 3.0);
        assert!(finite_median([f64::NAN]).is_nan() && finite_median(Vec::new()).is_nan());
    }

    #[test]
    fn nearest_rank_quantiles() {
        let mut v = [4.0, 1.0, 3.0, 2.0];
        assert_eq!(nearest_rank_quantile(&mut v, 0.5), 2.0);
        assert_eq!(nearest_rank_quantile(&mut v, 0.9), 4.0);
        assert_eq!(nearest_rank_quantile(&mut v, 0.0), 1.0);
        assert!(nearest_rank_quantile(&mut [], 0.5).is_nan());
    }
}
