//! What the dashboard shows of the loop, gathered by the recorder between two statuses: each
//! latency of the last second of loops (sorted once per status for exact percentiles: at 1 kHz a
//! thousand numbers a row) and a few points of the scenario's key signals.

use std::collections::VecDeque;

use crate::config::schema::Component;
use crate::contract::protocol::{LiveLatency, LiveStatus, SignalPoint};
use crate::contract::report::HOPS;
use crate::model::layout::VectorLayout;
use crate::monitor::join::LoopParts;
use crate::monitor::stats::{Distribution, LoopStats};

/// Points of the key signals per second of simulation time.
const POINTS_PER_SECOND: f64 = 100.0;
/// Most values a latency's window keeps (a second at 10 kHz).
const MAX_WINDOW: usize = 10_000;

/// Where a key signal's true value is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Truth {
    State(usize),
    Command(usize),
}

/// A signal the dashboard plots: its true value, and the estimate of it if the estimator has one
/// of the same name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KeySignal {
    pub name: &'static str,
    pub unit: &'static str,
    pub truth: Truth,
    pub estimate: Option<usize>,
}

/// The scenario's key signals, from its layout alone: the first two state components the
/// estimator estimates (by name; the first state components when fewer are), and the first
/// command.
pub fn key_signals(layout: &VectorLayout) -> Vec<KeySignal> {
    let estimate_of = |c: &Component| layout.estimate.iter().position(|e| e.name == c.name);
    let estimated = layout.state.iter().enumerate().filter(|(_, c)| estimate_of(c).is_some());
    let others = layout.state.iter().enumerate().filter(|(_, c)| estimate_of(c).is_none());
    let mut signals: Vec<KeySignal> = estimated
        .chain(others)
        .take(2)
        .map(|(i, c)| KeySignal { name: c.name, unit: c.unit, truth: Truth::State(i), estimate: estimate_of(c) })
        .collect();
    if let Some(c) = layout.input.first() {
        signals.push(KeySignal { name: c.name, unit: c.unit, truth: Truth::Command(0), estimate: None });
    }
    signals
}

/// One latency over the last second of loops, and since the previous status.
struct Window {
    /// The newest values, at most a second of loops.
    recent: VecDeque<u64>,
    capacity: usize,
    /// Values since the previous status: how many, and the largest.
    fresh: u64,
    fresh_max: Option<u64>,
}

impl Window {
    fn new(capacity: usize) -> Self {
        Self { recent: VecDeque::with_capacity(capacity), capacity, fresh: 0, fresh_max: None }
    }

    fn push(&mut self, ns: u64) {
        if self.recent.len() == self.capacity {
            self.recent.pop_front();
        }
        self.recent.push_back(ns);
        self.fresh += 1;
        self.fresh_max = self.fresh_max.max(Some(ns));
    }

    /// The numbers for a status, with the run's maximum so far; then starts the next period.
    fn take(&mut self, run: &Distribution) -> LiveLatency {
        let mut values: Vec<u64> = self.recent.iter().copied().collect();
        values.sort_unstable();
        // The nearest-rank quantile: the smallest value with at least q of them at or below it.
        let at = |q: f64| values.get(((q * values.len() as f64).ceil() as usize).saturating_sub(1)).copied();
        LiveLatency {
            count: std::mem::take(&mut self.fresh),
            latest_max: self.fresh_max.take(),
            p50: at(0.5),
            p99: at(0.99),
            max: at(1.0),
            run_max: run.max(),
        }
    }
}

/// Collects what the next [`LiveStatus`] reports.
pub struct Live {
    signals: Vec<KeySignal>,
    /// One point every this many loops.
    every: u64,
    end_to_end: Window,
    hops: [Window; HOPS.len()],
    tick_period_error: Window,
    points: Vec<SignalPoint>,
}

impl Live {
    pub fn new(layout: &VectorLayout, rate_hz: f64) -> Self {
        // A second of loops, within what a status may sort cheaply.
        let window = || Window::new((rate_hz.round() as usize).clamp(1, MAX_WINDOW));
        Self {
            signals: key_signals(layout),
            every: (rate_hz / POINTS_PER_SECOND).round().max(1.0) as u64,
            end_to_end: window(),
            hops: std::array::from_fn(|_| window()),
            tick_period_error: window(),
            points: vec![],
        }
    }

    /// Takes loop `k` at simulation time `t`, after `stats` observed it.
    pub fn observe(&mut self, k: u64, t: f64, parts: &LoopParts, stats: &LoopStats) {
        if let Some(state) = &parts.state
            && state.timing.period_ns > 0
        {
            self.tick_period_error.push(stats.tick_period_error(state.timing.period_ns));
        }
        if let (Some(e2e), Some(hops)) = (parts.end_to_end_ns(), parts.hops_ns()) {
            self.end_to_end.push(e2e);
            for (window, ns) in self.hops.iter_mut().zip(hops) {
                window.push(ns);
            }
        }
        if k.is_multiple_of(self.every) {
            let finite = |v: Option<f64>| v.filter(|v| v.is_finite());
            let values = self
                .signals
                .iter()
                .map(|s| {
                    let truth = match s.truth {
                        Truth::State(i) => parts.state.as_ref().map(|m| m.x[i]),
                        Truth::Command(i) => parts.command.as_ref().map(|m| m.u[i]),
                    };
                    let estimate = s.estimate.and_then(|i| parts.estimate.as_ref().map(|m| m.x[i]));
                    [finite(truth), finite(estimate)]
                })
                .collect();
            self.points.push(SignalPoint { t, values });
        }
    }

    /// Everything since the last call.
    pub fn take(&mut self, stats: &LoopStats) -> LiveStatus {
        LiveStatus {
            end_to_end: self.end_to_end.take(&stats.end_to_end),
            hops: self.hops.iter_mut().zip(&stats.hops).map(|(w, run)| w.take(run)).collect(),
            tick_period_error: self.tick_period_error.take(&stats.plant_tick_jitter),
            points: std::mem::take(&mut self.points),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn key_signals_prefer_estimated_states_then_the_first_command() {
        let c = Component::new;
        let layout = VectorLayout {
            state: vec![c("p_x", "m"), c("p_y", "m"), c("mass", "kg")],
            estimate: vec![c("xi", "1"), c("mass", "kg")],
            input: vec![c("thrust", "N"), c("tau_x", "N·m")],
            ..Default::default()
        };
        let signal = |name, unit, truth, estimate| KeySignal { name, unit, truth, estimate };
        assert_eq!(
            key_signals(&layout),
            [
                signal("mass", "kg", Truth::State(2), Some(1)),
                signal("p_x", "m", Truth::State(0), None),
                signal("thrust", "N", Truth::Command(0), None)
            ]
        );
        let example = key_signals(&VectorLayout::example());
        assert_eq!(
            example.iter().map(|s| (s.name, s.estimate)).collect::<Vec<_>>(),
            [("theta", Some(0)), ("omega", None), ("u", None)]
        );
    }

    #[test]
    fn a_window_keeps_the_newest_values_and_counts_those_since_the_last_status() {
        let mut run = Distribution::default();
        let mut window = Window::new(200);
        for ns in (1..=250).rev() {
            run.record(ns * 10);
            window.push(ns * 10);
        }
        // It holds 200 down to 1 (×10): nearest-rank percentiles of those.
        let all = LiveLatency {
            count: 250,
            latest_max: Some(2500),
            p50: Some(1000),
            p99: Some(1980),
            max: Some(2000),
            run_max: Some(2500),
        };
        assert_eq!(window.take(&run), all);
        assert_eq!(window.take(&run), LiveLatency { count: 0, latest_max: None, ..all.clone() });
        window.push(5);
        let newest =
            LiveLatency { count: 1, latest_max: Some(5), p50: Some(990), p99: Some(1970), max: Some(1990), ..all };
        assert_eq!(window.take(&run), newest);
    }
}
