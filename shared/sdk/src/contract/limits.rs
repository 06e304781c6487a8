//! What the monitor has seen of the scenario's error against its `[limits]` over the whole run:
//! plain numbers, judged into a verdict when the summary is written
//! (`crate::launcher::verdict`). Kept in the monitor's report, so a restarted monitor goes on
//! from it.

use serde::{Deserialize, Serialize};

/// The one rule for an error against a limit or a band, for the verdict and each fault's report
/// alike: beyond when greater (an error equal to the limit is within it) or not a number.
pub fn beyond(error: f64, limit: f64) -> bool {
    error.is_nan() || error > limit
}

/// The error over every loop recorded, in simulation time.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct LimitsWatch {
    /// Loops whose true state was recorded and judged.
    pub loops: u64,
    /// The largest finite error, and when.
    pub worst: Option<f64>,
    pub worst_at_s: Option<f64>,
    /// The first loop beyond the limit.
    pub exceeded_at_s: Option<f64>,
    /// Beyond the limit since then, without a loop back within it (None: within it now).
    pub beyond_since_s: Option<f64>,
    /// The first loop at or past the scenario's point of no return.
    pub no_return_at_s: Option<f64>,
    /// The first loop whose error was not a number (the simulation diverged).
    pub not_finite_at_s: Option<f64>,
}

impl LimitsWatch {
    /// Takes the error of the loop at simulation time `t`, against `limit` and the point of no
    /// return `lost_beyond`, if there is one.
    pub fn observe(&mut self, t: f64, error: f64, limit: f64, lost_beyond: Option<f64>) {
        self.loops += 1;
        if !error.is_finite() {
            self.not_finite_at_s.get_or_insert(t);
            return;
        }
        if self.worst.is_none_or(|worst| error > worst) {
            self.worst = Some(error);
            self.worst_at_s = Some(t);
        }
        if beyond(error, limit) {
            self.exceeded_at_s.get_or_insert(t);
            self.beyond_since_s.get_or_insert(t);
        } else {
            self.beyond_since_s = None;
        }
        if lost_beyond.is_some_and(|beyond| error >= beyond) {
            self.no_return_at_s.get_or_insert(t);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_error_equal_to_the_limit_is_within_it_and_nan_is_beyond() {
        assert!(!beyond(0.3, 0.3));
        assert!(beyond(0.300_000_000_000_000_04, 0.3));
        assert!(beyond(f64::NAN, 0.3));
        assert!(beyond(f64::INFINITY, 0.3));
        let mut watch = LimitsWatch::default();
        watch.observe(0.0, 0.3, 0.3, None);
        assert_eq!((watch.exceeded_at_s, watch.beyond_since_s), (None, None));
        watch.observe(0.001, 0.31, 0.3, None);
        assert_eq!(watch.exceeded_at_s, Some(0.001));
    }
}
