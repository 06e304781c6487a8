//! Running sums of one quantity, for a scenario's metrics: mean, RMS and spread without keeping
//! the samples; and the largest value seen, which stays NaN once a NaN came.

/// The larger of `a` and `b`, NaN if either is: a maximum over a diverged run is not a number
/// (`f64::max` would drop the NaN and report the largest value before the divergence).
pub fn max_keeping_nan(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() { f64::NAN } else { a.max(b) }
}

#[derive(Debug, Default, Clone, Copy, serde::Serialize, serde::Deserialize)]
pub struct Mean {
    sum: f64,
    sum_sq: f64,
    pub n: u64,
}

impl Mean {
    pub fn add(&mut self, x: f64) {
        self.sum += x;
        self.sum_sq += x * x;
        self.n += 1;
    }

    pub fn mean(&self) -> Option<f64> {
        (self.n > 0).then(|| self.sum / self.n as f64)
    }

    pub fn rms(&self) -> Option<f64> {
        (self.n > 0).then(|| (self.sum_sq / self.n as f64).sqrt())
    }

    /// The standard deviation (of the population: divided by n).
    pub fn std(&self) -> Option<f64> {
        let mean = self.mean()?;
        Some((self.sum_sq / self.n as f64 - mean * mean).max(0.0).sqrt())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_rms_and_spread_of_known_samples() {
        let mut m = Mean::default();
        assert_eq!(m.mean(), None);
        for x in [1.0, -1.0, 3.0, 5.0] {
            m.add(x);
        }
        assert_eq!(m.mean(), Some(2.0));
        assert_eq!(m.rms(), Some(3.0));
        assert_eq!(m.std(), Some(5f64.sqrt()));
    }

    #[test]
    fn a_maximum_stays_nan_once_a_nan_came() {
        assert_eq!(max_keeping_nan(1.0, 2.0), 2.0);
        assert!(max_keeping_nan(f64::NAN, 2.0).is_nan());
        assert!([0.5, f64::NAN, 3.0].into_iter().fold(0.0, max_keeping_nan).is_nan());
        assert_eq!([0.5, f64::INFINITY, 3.0].into_iter().fold(0.0, max_keeping_nan), f64::INFINITY);
    }
}
