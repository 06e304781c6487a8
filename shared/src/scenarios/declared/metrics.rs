//! A declared system's metrics and error measure: the generic ones, which need no scenario
//! knowledge. Placeholder (helper D replaces this file with per-component final, max |x|, RMS,
//! tracking against a `[reference]` and the `[limits]` verdict): no metrics yet, and the error
//! is the state's Euclidean norm.

use std::collections::BTreeMap;
use std::sync::Arc;

use super::system::System;
use crate::model::scenario::{ErrorMeasure, Metrics, Row};

/// The run's metrics of `system`.
pub fn generic(_system: &System) -> Box<dyn Metrics> {
    Box::new(NoMetrics)
}

/// How fault reports judge `system`: the norm of its declared state (outputs left out).
pub fn error_measure(system: &System) -> ErrorMeasure {
    let n = system.vectors.state.len();
    ErrorMeasure {
        name: "|x| (state norm)",
        of_state: Arc::new(move |_t, x: &[f64]| x[..n].iter().map(|v| v * v).sum::<f64>().sqrt()),
        recovery_band: 0.05,
        limit: 1e6,
        limit_key: "limits",
        lost_beyond: None,
    }
}

struct NoMetrics;

impl Metrics for NoMetrics {
    fn observe(&mut self, _row: &Row) {}
    fn finish(&self) -> BTreeMap<String, f64> {
        BTreeMap::new()
    }
}
