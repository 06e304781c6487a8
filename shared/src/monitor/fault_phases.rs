//! The run split at one fault into before, during and after (`contract::report::FaultPhases`):
//! loops, loops without a command, misses, end-to-end latency and the scenario's error in each.
//! Fed by the fault's tracker, which knows when the fault began and when the loop was whole
//! again; serialisable, so that a restarted monitor goes on from the last one's.

use serde::{Deserialize, Serialize};

use crate::contract::report::{FaultPhases, PhaseStats};
use crate::monitor::distribution::Distribution;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    Before,
    During,
    After,
}

/// What is known of one loop for the split.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct LoopFacts {
    /// Its state was recorded.
    pub state: bool,
    /// Its command reached the plant (the loop has a record).
    pub commanded: bool,
    /// That command came in time.
    pub in_time: bool,
    pub end_to_end_ns: Option<u64>,
    /// The scenario's error measure of its state.
    pub error: Option<f64>,
}

#[derive(Default, Serialize, Deserialize)]
struct Tally {
    loops: u64,
    without_command: u64,
    misses: u64,
    end_to_end: Distribution,
    error_max: Option<f64>,
    error_sum_sq: f64,
    errors: u64,
}

impl Tally {
    fn add(&mut self, facts: &LoopFacts) {
        if !facts.state {
            return;
        }
        self.loops += 1;
        self.without_command += u64::from(!facts.commanded);
        self.misses += u64::from(!(facts.commanded && facts.in_time));
        if let Some(ns) = facts.end_to_end_ns {
            self.end_to_end.record(ns);
        }
        if let Some(e) = facts.error {
            // NaN (a diverged state) is the largest error of all.
            self.error_max =
                Some(self.error_max.map_or(e, |m: f64| if e.is_nan() || m.is_nan() { f64::NAN } else { m.max(e) }));
            self.error_sum_sq += e * e;
            self.errors += 1;
        }
    }

    fn stats(&self, from_k: u64, to_k: u64) -> PhaseStats {
        PhaseStats {
            from_k,
            to_k,
            loops: self.loops,
            without_command: self.without_command,
            misses: self.misses,
            end_to_end_ns: self.end_to_end.stats(),
            error_max: self.error_max,
            error_rms: (self.errors > 0).then(|| (self.error_sum_sq / self.errors as f64).sqrt()),
        }
    }
}

/// The three tallies of one fault.
#[derive(Default, Serialize, Deserialize)]
pub struct PhaseTally {
    before: Tally,
    during: Tally,
    after: Tally,
}

impl PhaseTally {
    pub fn add(&mut self, phase: Phase, facts: &LoopFacts) {
        match phase {
            Phase::Before => self.before.add(facts),
            Phase::During => self.during.add(facts),
            Phase::After => self.after.add(facts),
        }
    }

    /// The split of a run of `loops` loops at a fault injected at loop `from`, whose loop was
    /// whole again at `back` (None: never).
    pub fn finish(&self, from: u64, back: Option<u64>, loops: u64) -> FaultPhases {
        let from = from.min(loops);
        let back = back.unwrap_or(loops).clamp(from, loops);
        FaultPhases {
            before: self.before.stats(0, from),
            during: self.during.stats(from, back),
            after: self.after.stats(back, loops),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_loop_counts_in_its_phase_and_the_spans_cover_the_run() {
        let mut tally = PhaseTally::default();
        let ok = LoopFacts { state: true, commanded: true, in_time: true, end_to_end_ns: Some(100), error: Some(0.0) };
        let none = LoopFacts { commanded: false, in_time: false, end_to_end_ns: None, error: Some(2.0), ..ok };
        let late = LoopFacts { in_time: false, end_to_end_ns: Some(5000), error: Some(1.0), ..ok };
        tally.add(Phase::Before, &ok);
        tally.add(Phase::During, &none);
        tally.add(Phase::During, &late);
        tally.add(Phase::After, &ok);
        tally.add(Phase::After, &LoopFacts::default());
        let phases = tally.finish(1, Some(3), 5);
        assert_eq!((phases.before.from_k, phases.before.to_k, phases.during.to_k, phases.after.to_k), (0, 1, 3, 5));
        assert_eq!((phases.during.loops, phases.during.without_command, phases.during.misses), (2, 1, 2));
        assert_eq!(phases.during.end_to_end_ns.count, 1);
        assert_eq!(phases.during.error_max, Some(2.0));
        assert_eq!(phases.during.error_rms, Some(2.5f64.sqrt()));
        assert_eq!((phases.after.loops, phases.after.misses), (1, 0), "a loop without a state is not counted");
        let never = tally.finish(1, None, 5);
        assert_eq!((never.during.to_k, never.after.from_k, never.after.to_k), (5, 5, 5));
    }
}
