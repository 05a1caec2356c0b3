//! [`Histogram`]: latency figures in fixed memory, 1 µs bins as cyclictest keeps them.

/// Counts of durations in 1 µs bins up to a bound, an overflow count and the exact maximum.
/// Recording never allocates: the bins are allocated once by [`Histogram::new`].
#[derive(Debug, Clone, PartialEq)]
pub struct Histogram {
    bins: Vec<u64>,
    overflow: u64,
    count: u64,
    max_ns: u64,
}

/// Nearest-rank percentiles of a [`Histogram`], in µs.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Percentiles {
    /// Median.
    pub p50_us: f64,
    /// 99th percentile.
    pub p99_us: f64,
    /// 99.9th percentile.
    pub p999_us: f64,
    /// Largest value recorded (exact, not binned).
    pub max_us: f64,
}

impl Histogram {
    /// A histogram with bins 0‥`bound_us` µs (one per µs) and an overflow count above.
    pub fn new(bound_us: usize) -> Histogram {
        Histogram { bins: vec![0; bound_us + 1], overflow: 0, count: 0, max_ns: 0 }
    }

    /// Records a duration in ns (truncated to whole µs, as cyclictest does).
    #[inline]
    pub fn record_ns(&mut self, ns: u64) {
        let us = (ns / crate::NS_PER_US) as usize;
        match self.bins.get_mut(us) {
            Some(bin) => *bin += 1,
            None => self.overflow += 1,
        }
        self.count += 1;
        self.max_ns = self.max_ns.max(ns);
    }

    /// How many values were recorded.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// How many values were above the last bin.
    pub fn overflow(&self) -> u64 {
        self.overflow
    }

    /// How many values were strictly above `us` µs (whole µs after truncation).
    pub fn count_above_us(&self, us: usize) -> u64 {
        let in_bins: u64 = self.bins.iter().skip(us + 1).sum();
        in_bins + self.overflow
    }

    /// The largest value recorded, in ns.
    pub fn max_ns(&self) -> u64 {
        self.max_ns
    }

    /// The nearest-rank `p`-quantile (0 < p ≤ 1) in µs; a rank in the overflow reports the
    /// maximum. 0 when empty.
    pub fn quantile_us(&self, p: f64) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        let rank = ((p * self.count as f64).ceil() as u64).clamp(1, self.count);
        let mut seen = 0;
        for (us, n) in self.bins.iter().enumerate() {
            seen += n;
            if seen >= rank {
                return us as f64;
            }
        }
        self.max_ns as f64 / crate::NS_PER_US as f64
    }

    /// p50, p99, p99.9 and the maximum.
    pub fn percentiles(&self) -> Percentiles {
        Percentiles {
            p50_us: self.quantile_us(0.5),
            p99_us: self.quantile_us(0.99),
            p999_us: self.quantile_us(0.999),
            max_us: self.max_ns as f64 / crate::NS_PER_US as f64,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(values_us: &[u64], bound: usize, expected: (f64, f64, f64, f64)) {
        let mut h = Histogram::new(bound);
        for v in values_us {
            h.record_ns(v * 1_000 + 999);
        }
        let p = h.percentiles();
        let max = values_us.iter().max().map_or(0.0, |m| *m as f64 + 0.999);
        assert_eq!(
            (p.p50_us, p.p99_us, p.p999_us, p.max_us),
            (expected.0, expected.1, expected.2, max)
        );
        assert_eq!(max, expected.3);
    }

    #[test]
    fn nearest_rank_percentiles() {
        check(&[], 10, (0.0, 0.0, 0.0, 0.0));
        check(&[5], 10, (5.0, 5.0, 5.0, 5.999));
        let hundred: Vec<u64> = (1..=100).collect();
        check(&hundred, 200, (50.0, 99.0, 100.0, 100.999));
    }

    #[test]
    fn overflow_reports_the_maximum() {
        let mut h = Histogram::new(10);
        for v in [1, 2, 3_000_000] {
            h.record_ns(v * 1_000);
        }
        assert_eq!(h.overflow(), 1);
        assert_eq!(h.quantile_us(1.0), 3_000_000.0);
        assert_eq!(h.count_above_us(1), 2);
        assert_eq!(h.count_above_us(2), 1);
    }
}
