//! Running sums of one quantity, for a scenario's metrics: mean, RMS and spread without keeping
//! the samples.

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
}
