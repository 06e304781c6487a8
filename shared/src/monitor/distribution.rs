//! A latency distribution: an HDR histogram with exact extremes and mean, summarised as [`Stats`].

use hdrhistogram::Histogram;

use crate::contract::report::Stats;

/// Histogram range: 1 ns to 60 s at 3 significant digits.
const HISTOGRAM_MAX_NS: u64 = 60_000_000_000;

/// An empty histogram with the monitor's range and precision.
pub fn histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, HISTOGRAM_MAX_NS, 3).expect("valid histogram bounds")
}

/// An HDR histogram with exact extremes and mean.
pub struct Distribution {
    histogram: Histogram<u64>,
    min: u64,
    max: u64,
    sum: u128,
}

impl Default for Distribution {
    fn default() -> Self {
        Self { histogram: histogram(), min: u64::MAX, max: 0, sum: 0 }
    }
}

impl Distribution {
    pub fn record(&mut self, ns: u64) {
        self.histogram.saturating_record(ns);
        self.min = self.min.min(ns);
        self.max = self.max.max(ns);
        self.sum += u128::from(ns);
    }

    /// The value at quantile `q` as HDR reports it (a bucket's highest equivalent value).
    pub fn quantile(&self, q: f64) -> Option<u64> {
        (!self.histogram.is_empty()).then(|| self.histogram.value_at_quantile(q))
    }

    /// The largest value recorded (exact).
    pub fn max(&self) -> Option<u64> {
        (!self.histogram.is_empty()).then_some(self.max)
    }

    pub fn stats(&self) -> Stats {
        let count = self.histogram.len();
        if count == 0 {
            return Stats::default();
        }
        // HDR reports a bucket's highest equivalent value; keep it inside the exact extremes.
        let q = |q: f64| Some(self.histogram.value_at_quantile(q).clamp(self.min, self.max));
        Stats {
            count,
            min: Some(self.min),
            p50: q(0.50),
            p90: q(0.90),
            p99: q(0.99),
            p999: q(0.999),
            max: Some(self.max),
            mean: Some(self.sum as f64 / count as f64),
        }
    }
}
