//! Per-cycle latency of the hard loop: a fixed log-linear histogram (no allocation per
//! record), percentiles and deadline misses.
//!
//! Buckets: values below 16 ns have one bucket each; above, every power of two
//! `[2^k, 2^(k+1))` is split into 16 equal sub-buckets, so a bucket is at most 1/16 (6.25 %)
//! of its value wide, up to 2^40 ns (18 min). A percentile is reported as the upper edge of
//! its bucket (a bound, never an underestimate), clamped to the largest value recorded.
//!
//! ```
//! use handeye_daemon::timing::LatencyHistogram;
//! let mut h = LatencyHistogram::new(1_000_000);
//! for us in 1..=100u64 { h.record_ns(us * 1000); }
//! assert_eq!(h.count(), 100);
//! let p50 = h.percentile_ns(50.0);
//! assert!(p50 >= 50_000 && p50 <= 50_000 * 17 / 16, "{p50}");
//! assert_eq!(h.deadline_misses(), 0);
//! h.record_ns(2_000_000);
//! assert_eq!(h.deadline_misses(), 1);
//! ```

const SUB_BITS: u32 = 4;
const SUB: u64 = 1 << SUB_BITS;
const MAX_EXP: u32 = 40;
const BUCKETS: usize = (SUB as usize) + ((MAX_EXP - SUB_BITS) as usize) * (SUB as usize) + 1;

/// A fixed-size latency histogram in nanoseconds.
#[derive(Debug, Clone)]
pub struct LatencyHistogram {
    counts: [u64; BUCKETS],
    count: u64,
    sum_ns: u128,
    max_ns: u64,
    min_ns: u64,
    deadline_ns: u64,
    misses: u64,
}

fn bucket_of(ns: u64) -> usize {
    if ns < SUB {
        return ns as usize;
    }
    let exp = 63 - ns.leading_zeros(); // >= SUB_BITS
    if exp >= MAX_EXP {
        return BUCKETS - 1;
    }
    let sub = (ns >> (exp - SUB_BITS)) & (SUB - 1);
    (SUB as usize) + ((exp - SUB_BITS) as usize) * (SUB as usize) + sub as usize
}

/// Upper edge (exclusive) of bucket `b`, ns.
fn bucket_upper(b: usize) -> u64 {
    if b < SUB as usize {
        return b as u64 + 1;
    }
    if b >= BUCKETS - 1 {
        return u64::MAX;
    }
    let k = b - SUB as usize;
    let exp = (k / SUB as usize) as u32 + SUB_BITS;
    let sub = (k % SUB as usize) as u64;
    (SUB + sub + 1) << (exp - SUB_BITS)
}

impl LatencyHistogram {
    /// An empty histogram; a value above `deadline_ns` counts as a deadline miss.
    pub fn new(deadline_ns: u64) -> Self {
        Self { counts: [0; BUCKETS], count: 0, sum_ns: 0, max_ns: 0, min_ns: u64::MAX, deadline_ns, misses: 0 }
    }

    /// Records one value. Constant time, no allocation.
    pub fn record_ns(&mut self, ns: u64) {
        self.counts[bucket_of(ns)] += 1;
        self.count += 1;
        self.sum_ns += u128::from(ns);
        self.max_ns = self.max_ns.max(ns);
        self.min_ns = self.min_ns.min(ns);
        if ns > self.deadline_ns {
            self.misses += 1;
        }
    }

    pub fn count(&self) -> u64 {
        self.count
    }

    pub fn deadline_ns(&self) -> u64 {
        self.deadline_ns
    }

    /// Values above the deadline so far.
    pub fn deadline_misses(&self) -> u64 {
        self.misses
    }

    pub fn max_ns(&self) -> u64 {
        self.max_ns
    }

    pub fn mean_ns(&self) -> f64 {
        if self.count == 0 { 0.0 } else { self.sum_ns as f64 / self.count as f64 }
    }

    /// The `p`-th percentile (0..=100): the upper edge of the bucket holding it, never more
    /// than the largest value seen; 0 when empty.
    pub fn percentile_ns(&self, p: f64) -> u64 {
        if self.count == 0 {
            return 0;
        }
        let p = if p.is_finite() { p.clamp(0.0, 100.0) } else { 100.0 };
        let rank = ((p / 100.0) * self.count as f64).ceil().max(1.0) as u64;
        let mut seen = 0;
        for (b, &c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return bucket_upper(b).saturating_sub(1).min(self.max_ns).max(self.min_ns);
            }
        }
        self.max_ns
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buckets_are_ordered_and_narrow() {
        let mut last = 0;
        for ns in [0u64, 1, 15, 16, 17, 31, 32, 100, 1000, 12_345, 1 << 20, (1 << 39) + 5] {
            let b = bucket_of(ns);
            assert!(b >= last, "{ns}");
            last = b;
            let upper = bucket_upper(b);
            assert!(ns < upper, "{ns} !< {upper}");
            assert!((upper - ns) as f64 <= (ns as f64 / 16.0).max(1.0) + 1.0, "{ns}: upper {upper}");
        }
        assert_eq!(bucket_of(u64::MAX), BUCKETS - 1);
    }

    #[test]
    fn percentiles_bound_the_true_value_within_a_bucket() {
        let mut h = LatencyHistogram::new(u64::MAX);
        // 990 fast cycles of 80 µs and 10 slow ones of 3 ms: p50 ~80 µs, p99 ~80 µs, p99.9 3 ms.
        for _ in 0..990 {
            h.record_ns(80_000);
        }
        for _ in 0..10 {
            h.record_ns(3_000_000);
        }
        let p50 = h.percentile_ns(50.0);
        assert!((80_000..=85_000).contains(&p50), "{p50}");
        assert!((80_000..=85_000).contains(&h.percentile_ns(99.0)));
        assert_eq!(h.percentile_ns(99.9), 3_000_000);
        assert_eq!(h.percentile_ns(100.0), 3_000_000);
        assert!((h.mean_ns() - (990.0 * 80_000.0 + 10.0 * 3e6) / 1000.0).abs() < 1.0);
    }

    #[test]
    fn deadline_misses_count_values_over_the_deadline() {
        let mut h = LatencyHistogram::new(1000);
        for ns in [999, 1000, 1001, 5000] {
            h.record_ns(ns);
        }
        assert_eq!(h.deadline_misses(), 2);
        assert_eq!(LatencyHistogram::new(1).percentile_ns(50.0), 0);
    }
}
