//! Small statistics the benchmarks share: nearest-rank percentiles of raw samples, the median
//! and the coefficient of variation.

use qmarc_report::summary::Pct;

/// The nearest-rank `q` quantile (0 < q ≤ 1) of `sorted`, ascending and not empty.
pub fn nearest_rank<T: Copy>(sorted: &[T], q: f64) -> T {
    let n = sorted.len();
    sorted[((q * n as f64).ceil() as usize).clamp(1, n) - 1]
}

/// p50/p99/p99.9/max of `samples_ns` (nearest rank), in µs; sorts them.
pub fn percentiles_us(samples_ns: &mut [u64]) -> Pct {
    samples_ns.sort_unstable();
    let n = samples_ns.len();
    if n == 0 {
        return Pct::default();
    }
    let at = |q: f64| nearest_rank(samples_ns, q) as f64 / 1e3;
    Pct { p50: at(0.5), p99: at(0.99), p999: at(0.999), max: samples_ns[n - 1] as f64 / 1e3 }
}

/// The median of `v` (the mean of the middle two for an even count); 0 when empty.
pub fn median(v: &[f64]) -> f64 {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    s.sort_by(f64::total_cmp);
    match s.len() {
        0 => 0.0,
        n if n % 2 == 1 => s[n / 2],
        n => (s[n / 2 - 1] + s[n / 2]) / 2.0,
    }
}

/// Standard deviation over mean (population), 0 for fewer than two values or a zero mean.
pub fn cv(v: &[f64]) -> f64 {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    if v.len() < 2 || mean == 0.0 {
        return 0.0;
    }
    (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt() / mean
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank_percentiles() {
        let mut v: Vec<u64> = (1..=1000).map(|k| k * 1000).collect();
        v.reverse();
        let p = percentiles_us(&mut v);
        assert_eq!((p.p50, p.p99, p.p999, p.max), (500.0, 990.0, 999.0, 1000.0));
        assert_eq!(percentiles_us(&mut []).max, 0.0);
    }

    #[test]
    fn median_and_cv() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        assert_eq!(median(&[]), 0.0);
        assert_eq!(cv(&[2.0, 2.0, 2.0]), 0.0);
        assert!((cv(&[1.0, 3.0]) - 0.5).abs() < 1e-12);
    }
}
