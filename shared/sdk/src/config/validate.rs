//! Checks of single numbers in a scenario's sections, shared by every scenario: each fails with
//! one line naming the dotted key, where its value came from, and what is allowed.

use std::fmt::Display;
use std::ops::RangeInclusive;

use crate::config::launch::{LaunchConfig, LaunchError};

/// An error unless `value` is finite and positive.
pub fn positive(c: &LaunchConfig, key: &str, value: f64) -> Result<(), LaunchError> {
    positive_as(c, key, value, "number")
}

/// An error unless `value` is finite and positive, saying what it is ("must be a positive angle").
pub fn positive_as(c: &LaunchConfig, key: &str, value: f64, what: &str) -> Result<(), LaunchError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(c.error(key, format!("must be a positive {what}, got {value}")))
    }
}

/// An error unless `value` is finite and not negative.
pub fn not_negative(c: &LaunchConfig, key: &str, value: f64) -> Result<(), LaunchError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(c.error(key, format!("must be 0 or a positive number, got {value}")))
    }
}

/// An error unless `value` is within ±`bound` (`units` says in what: "SI units").
pub fn within(c: &LaunchConfig, key: &str, value: f64, bound: f64, units: &str) -> Result<(), LaunchError> {
    if value.abs() <= bound {
        Ok(())
    } else {
        Err(c.error(key, format!("must be within ±{bound} ({units}), got {value}")))
    }
}

/// The largest magnitude of a vehicle's positions, velocities, forces and times (SI units): far
/// beyond any flight, and small enough that the models' products stay finite.
pub const MAX_SI: f64 = 1e4;

/// An error unless `value` is within ±[`MAX_SI`].
pub fn within_si(c: &LaunchConfig, key: &str, value: f64) -> Result<(), LaunchError> {
    within(c, key, value, MAX_SI, "SI units")
}

/// An error unless `period` (s) lies from one loop period to the run's duration, or is 0 where
/// `zero_is_every_tick` (0: every tick).
pub fn period_within_run(
    c: &LaunchConfig,
    key: &str,
    period: f64,
    zero_is_every_tick: bool,
) -> Result<(), LaunchError> {
    if zero_is_every_tick && period == 0.0 {
        return Ok(());
    }
    let dt = c.dt();
    if period.is_finite() && period >= dt * (1.0 - 1e-9) && period <= c.duration_s.max(dt) {
        return Ok(());
    }
    let zero = if zero_is_every_tick { "0 (every tick) or " } else { "" };
    Err(c.error(key, format!("must be {zero}from one loop period ({dt} s) to the run's duration, got {period}")))
}

/// Every element of `values` checked by `check` under `key.i` (the index as `--set` names it).
pub fn each(
    c: &LaunchConfig,
    key: &str,
    values: &[f64],
    check: impl Fn(&LaunchConfig, &str, f64) -> Result<(), LaunchError>,
) -> Result<(), LaunchError> {
    values.iter().enumerate().try_for_each(|(i, v)| check(c, &format!("{key}.{i}"), *v))
}

/// An error unless `value` is in `range`; `what` names the unit ("integration steps per loop").
pub fn in_range<T: PartialOrd + Display>(
    c: &LaunchConfig,
    key: &str,
    value: T,
    range: RangeInclusive<T>,
    what: &str,
) -> Result<(), LaunchError> {
    if range.contains(&value) {
        Ok(())
    } else {
        Err(c.error(key, format!("must be {} to {} {what}, got {value}", range.start(), range.end())))
    }
}
