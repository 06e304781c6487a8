//! A latency distribution: an HDR histogram with exact extremes and mean, summarised as [`Stats`].

use hdrhistogram::Histogram;

use crate::contract::report::Stats;

/// Histogram range: 1 ns to 60 s at 3 significant digits.
const HISTOGRAM_MAX_NS: u64 = 60_000_000_000;

/// An empty histogram with the monitor's range and precision.
pub fn histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, HISTOGRAM_MAX_NS, 3).expect("valid histogram bounds")
}

/// An HDR histogram with exact extremes and mean. Serialisable, so that a restarted monitor
/// goes on from the last one's (the histogram in HdrHistogram's V2 format).
#[derive(serde::Serialize, serde::Deserialize)]
pub struct Distribution {
    #[serde(with = "v2")]
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

/// A histogram as HdrHistogram's V2 bytes (compact: runs of empty buckets take a byte or two).
mod v2 {
    use hdrhistogram::Histogram;
    use hdrhistogram::serialization::{Deserializer as V2Reader, Serializer as _, V2Serializer};
    use serde::{Deserialize, Deserializer, Serializer, de::Error as _, ser::Error as _};

    pub fn serialize<S: Serializer>(histogram: &Histogram<u64>, serializer: S) -> Result<S::Ok, S::Error> {
        let mut bytes = vec![];
        V2Serializer::new().serialize(histogram, &mut bytes).map_err(|e| S::Error::custom(format!("{e:?}")))?;
        serializer.serialize_bytes(&bytes)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<Histogram<u64>, D::Error> {
        let bytes = serde_bytes::ByteBuf::deserialize(deserializer)?;
        V2Reader::new().deserialize(&mut &bytes[..]).map_err(|e| D::Error::custom(format!("{e:?}")))
    }
}
