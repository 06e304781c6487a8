//! A declared system's step response, where its reference steps (a `between = "hold"` table
//! whose value changes): of the first step, measured until the next step or the run's end,
//!
//! - rise time: from the response's first 10 % of the step to its first 90 %, s;
//! - overshoot: its largest excursion past the new value, % of the step (0 if none);
//! - settling time: from the step until the response stays within 2 % of the step of the new
//!   value, s (absent where it never does);
//! - steady-state error: the new value less the response at the last loop measured.
//!
//! The step runs from the component's value at the step's loop to the reference's new value, not
//! from the reference's old value: a loop that had not settled is judged by what it travelled.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::model::mean::max_keeping_nan;
use crate::model::reference::{Between, Signal};

/// The band, as a share of the step, that the response settles within.
pub const SETTLING_BAND: f64 = 0.02;

/// One step's response as it is observed.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StepResponse {
    /// The step's time, s, and the reference's value from it on.
    at: f64,
    target: f64,
    /// The next step's time (the response is measured until it), or infinity.
    until: f64,
    /// How many steps the reference has (the metrics are of the first).
    steps: usize,
    /// The component's value at the step's loop.
    start: Option<f64>,
    rise_10: Option<f64>,
    rise_90: Option<f64>,
    /// The largest (response − new value) ÷ step seen.
    overshoot: f64,
    /// The first loop of the run of loops within the band that lasts to now.
    settled_at: Option<f64>,
    last: Option<(f64, f64)>,
}

impl StepResponse {
    /// The first step of `signal`, if it steps.
    pub fn of(signal: &Signal) -> Option<Self> {
        let Signal::Table { t, value, between: Between::Hold } = signal else { return None };
        let steps: Vec<usize> = (1..t.len()).filter(|&i| value[i] != value[i - 1]).collect();
        let &first = steps.first()?;
        Some(StepResponse {
            at: t[first],
            target: value[first],
            until: steps.get(1).map_or(f64::INFINITY, |&i| t[i]),
            steps: steps.len(),
            start: None,
            rise_10: None,
            rise_90: None,
            overshoot: 0.0,
            settled_at: None,
            last: None,
        })
    }

    /// The component's value `y` at simulation time `t`.
    pub fn observe(&mut self, t: f64, y: f64) {
        if t < self.at || t >= self.until {
            return;
        }
        let start = *self.start.get_or_insert(y);
        let step = self.target - start;
        self.last = Some((t, y));
        if step == 0.0 {
            return;
        }
        let travelled = (y - start) / step;
        if self.rise_10.is_none() && travelled >= 0.1 {
            self.rise_10 = Some(t);
        }
        if self.rise_90.is_none() && travelled >= 0.9 {
            self.rise_90 = Some(t);
        }
        self.overshoot = max_keeping_nan(self.overshoot, travelled - 1.0);
        if (y - self.target).abs() <= SETTLING_BAND * step.abs() {
            self.settled_at.get_or_insert(t);
        } else {
            self.settled_at = None;
        }
    }

    /// The metrics, keyed `<prefix>.rise_time_s` and so on; none before the step.
    pub fn write(&self, prefix: &str, m: &mut BTreeMap<String, f64>) {
        let (Some(start), Some((_, last))) = (self.start, self.last) else { return };
        m.insert(format!("{prefix}.steady_state_error"), self.target - last);
        if self.target == start {
            return;
        }
        if let (Some(t10), Some(t90)) = (self.rise_10, self.rise_90) {
            m.insert(format!("{prefix}.rise_time_s"), t90 - t10);
        }
        m.insert(format!("{prefix}.overshoot_pct"), 100.0 * self.overshoot.max(0.0));
        if let Some(settled) = self.settled_at {
            m.insert(format!("{prefix}.settling_time_s"), settled - self.at);
        }
    }

    /// What the metrics leave out: a response that never rose or settled, other steps.
    pub fn notes(&self, prefix: &str) -> Vec<String> {
        let (Some(start), Some((end, _))) = (self.start, self.last) else {
            return vec![format!("{prefix}: the reference steps at t = {} s, after the run's last loop", self.at)];
        };
        let mut notes = vec![];
        if self.target == start {
            notes.push(format!(
                "{prefix}: the step at t = {} s is already where the response is; no rise or settling",
                self.at
            ));
        } else {
            if self.rise_90.is_none() {
                notes.push(format!(
                    "{prefix}: the response never reached 90 % of the step by t = {end} s; no rise time"
                ));
            }
            if self.settled_at.is_none() {
                notes.push(format!(
                    "{prefix}: the response was not within {} % of the step by t = {end} s; no settling time",
                    100.0 * SETTLING_BAND
                ));
            }
        }
        if self.steps > 1 {
            notes.push(format!(
                "{prefix}: of the first of the reference's {} steps, at t = {} s, until the next at {} s",
                self.steps, self.at, self.until
            ));
        }
        notes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RATE: f64 = 10_000.0;

    /// The response `y(t − at)` to a hold table's step from 0 to 1 at `at`, sampled at RATE for
    /// `seconds`.
    fn respond(at: f64, seconds: f64, y: impl Fn(f64) -> f64) -> StepResponse {
        let signal = Signal::table(&[[0.0, 0.0], [at, 1.0]], Between::Hold).unwrap();
        let mut step = StepResponse::of(&signal).expect("a step");
        for k in 0..(seconds * RATE) as u64 {
            let t = k as f64 / RATE;
            step.observe(t, if t < at { 0.0 } else { y(t - at) });
        }
        step
    }

    fn metrics(step: &StepResponse) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        step.write("step", &mut m);
        m
    }

    /// y = 1 − e^(−t/τ): rise time τ ln 9, settling time τ ln 50, no overshoot, steady-state
    /// error e^(−T/τ) at the last loop T; each within a sample.
    #[test]
    fn a_first_order_response_has_the_analytic_rise_and_settling_times() {
        let tau = 0.1;
        let step = respond(0.5, 2.0, |t| 1.0 - (-t / tau).exp());
        let m = metrics(&step);
        let sample = 1.0 / RATE;
        assert!((m["step.rise_time_s"] - tau * 9f64.ln()).abs() <= sample, "{m:?}");
        assert!((m["step.settling_time_s"] - tau * 50f64.ln()).abs() <= sample, "{m:?}");
        assert_eq!(m["step.overshoot_pct"], 0.0);
        let last = 2.0 - sample - 0.5;
        assert!((m["step.steady_state_error"] - (-last / tau).exp()).abs() < 1e-12, "{m:?}");
        assert!(step.notes("step").is_empty(), "{:?}", step.notes("step"));
    }

    /// An underdamped second-order response peaks at e^(−ζπ/√(1−ζ²)) past the new value.
    #[test]
    fn a_second_order_response_has_the_analytic_overshoot() {
        let (zeta, wn) = (0.5f64, 10.0);
        let wd = wn * (1.0 - zeta * zeta).sqrt();
        let phi = (1.0 - zeta * zeta).sqrt().atan2(zeta);
        let y = |t: f64| 1.0 - (-zeta * wn * t).exp() * (wd * t + phi).sin() / (1.0 - zeta * zeta).sqrt();
        let m = metrics(&respond(0.2, 3.0, y));
        let analytic = 100.0 * (-zeta * std::f64::consts::PI / (1.0 - zeta * zeta).sqrt()).exp();
        assert!((m["step.overshoot_pct"] - analytic).abs() < 1e-4, "{} against {analytic}", m["step.overshoot_pct"]);
    }

    /// A response that never gets there: no rise or settling time, and notes that say so; a table
    /// of several steps says which one was measured.
    #[test]
    fn a_response_that_falls_short_says_what_it_lacks() {
        let step = respond(0.5, 1.0, |t| 0.5 * t);
        let m = metrics(&step);
        assert!(!m.contains_key("step.rise_time_s") && !m.contains_key("step.settling_time_s"), "{m:?}");
        let notes = step.notes("step");
        assert!(notes[0].starts_with("step: the response never reached 90 % of the step by t = 0.9999 s"), "{notes:?}");
        assert!(notes[1].contains("not within 2 % of the step"), "{notes:?}");
        let two = Signal::table(&[[0.0, 0.0], [1.0, 1.0], [2.0, 1.0], [3.0, 0.0]], Between::Hold).unwrap();
        let step = StepResponse::of(&two).unwrap();
        assert_eq!((step.at, step.until, step.steps), (1.0, 3.0, 2));
        assert!(StepResponse::of(&Signal::table(&[[0.0, 0.0], [1.0, 1.0]], Between::Linear).unwrap()).is_none());
    }
}
