//! A system declared in the launch file (issue 31). This branch holds only the metrics and the
//! reference; the declared system itself (system, plant, sensors, estimator) is merged in.

pub mod metrics;
pub mod reference;
