//! The fault ledger: each fault of the launch file beside what the launcher saw of it (injected,
//! detected and by what, continued, resumed, restarted). It says which faults are due, which
//! injected faults of a process are still undetected or unresumed, and records what was seen;
//! the summary gets the record at the end. Times are passed in, never read here.

use crate::config::faults::{FaultKind, FaultSpec};
use crate::contract::role::Role;
use crate::launcher::inject::{self, DetectedBy, FaultSeen};
use crate::monitor::injections::{Injection, Injections};

pub(super) struct FaultLedger<'a> {
    specs: &'a [FaultSpec],
    /// What was seen of `specs[i]`, at `i`.
    seen: Vec<FaultSeen>,
    /// Real time: the loop each kill and stop took effect at, for the monitor.
    landed: Injections,
}

impl<'a> FaultLedger<'a> {
    pub(super) fn new(specs: &'a [FaultSpec]) -> Self {
        Self { specs, seen: vec![FaultSeen::default(); specs.len()], landed: Injections::new() }
    }

    pub(super) fn spec(&self, i: usize) -> &'a FaultSpec {
        &self.specs[i]
    }

    /// Real time: the faults injected from outside that are due at `now_ns` (tick 0 at
    /// `start_ns`) and not injected yet.
    pub(super) fn due_by_time(&self, start_ns: u64, now_ns: u64) -> Vec<usize> {
        inject::due_by_time(self.specs, &self.seen, start_ns, now_ns)
    }

    /// Lockstep: the faults injected from outside at loop `k`, not injected yet.
    pub(super) fn due_at_loop(&self, rate_hz: f64, k: u64) -> Vec<usize> {
        inject::due_at_loop(self.specs, &self.seen, rate_hz, k)
    }

    /// Fault `i` was injected at `ns` (or found its process not running then).
    pub(super) fn injected(&mut self, i: usize, ns: u64) {
        self.seen[i].injected_ns = Some(ns);
    }

    /// Real time: fault `i` took effect as `injection` says. Returns every injection so far.
    pub(super) fn landed(&mut self, i: usize, injection: Injection) -> &Injections {
        self.landed.insert(i, injection);
        &self.landed
    }

    /// Fault `i`, a stop, is to be continued at `at_ns`.
    pub(super) fn continue_at(&mut self, i: usize, at_ns: Option<u64>) {
        self.seen[i].continue_at_ns = at_ns;
    }

    /// The stops that are over at `now_ns`, taken off the wait; each is
    /// [`continued`](Self::continued) once its SIGCONT is sent.
    pub(super) fn take_continues_due(&mut self, now_ns: u64) -> Vec<usize> {
        let due: Vec<usize> =
            (0..self.seen.len()).filter(|&i| self.seen[i].continue_at_ns.is_some_and(|at| now_ns >= at)).collect();
        for &i in &due {
            self.seen[i].continue_at_ns = None;
        }
        due
    }

    /// The run is over: every stop not continued yet is taken off the wait, to be continued now,
    /// before its time (a stop may last longer than the run).
    pub(super) fn take_continues_at_run_end(&mut self) -> Vec<usize> {
        let left: Vec<usize> = (0..self.seen.len()).filter(|&i| self.seen[i].continue_at_ns.is_some()).collect();
        for &i in &left {
            self.seen[i].continue_at_ns = None;
            self.seen[i].continued_at_run_end = true;
        }
        left
    }

    /// Since when `role` has been stopped by a fault not continued yet, if it is: (the fault, ns).
    pub(super) fn stopped_since(&self, role: Role) -> Option<(usize, u64)> {
        self.injected_on(role, FaultKind::Stop)
            .into_iter()
            .find(|&i| self.seen[i].continue_at_ns.is_some())
            .and_then(|i| Some((i, self.seen[i].injected_ns?)))
    }

    /// A cut of the link is in effect: a stage across it waits on it.
    pub(super) fn cut_open(&self) -> bool {
        self.injected_on(Role::Bridge, FaultKind::Cut).into_iter().any(|i| self.seen[i].continued_ns.is_none())
    }

    /// Fault `i`'s process was sent SIGCONT at `ns`.
    pub(super) fn continued(&mut self, i: usize, ns: u64) {
        self.seen[i].continued_ns = Some(ns);
    }

    /// `by` noticed something wrong with `role` at `ns`: the injected faults on it of the kind
    /// `by` notices that are still undetected count as detected. Returns them.
    pub(super) fn detect(&mut self, role: Role, by: DetectedBy, ns: u64) -> Vec<usize> {
        self.detect_kind(role, noticed_kind(by), by, ns, ns)
    }

    /// The monitor saw `role` stall at `ns`, its input waiting since `since_ns`: its injected
    /// stops still undetected that were on when the wait began count as detected (a stall that
    /// began after a stop's SIGCONT is not that stop's). Returns them.
    pub(super) fn detect_stall(&mut self, role: Role, since_ns: u64, ns: u64) -> Vec<usize> {
        self.detect_kind(role, FaultKind::Stop, DetectedBy::InputDeadline, since_ns, ns)
    }

    /// The stage across the link stalled at `ns`, its input waiting since `since_ns`: the
    /// injected cuts still undetected that were on when the wait began count as detected.
    /// Returns them.
    pub(super) fn detect_cut(&mut self, since_ns: u64, ns: u64) -> Vec<usize> {
        self.detect_kind(Role::Bridge, FaultKind::Cut, DetectedBy::InputDeadline, since_ns, ns)
    }

    /// `by` noticed what began at `began_ns` at `ns`.
    fn detect_kind(&mut self, role: Role, kind: FaultKind, by: DetectedBy, began_ns: u64, ns: u64) -> Vec<usize> {
        let found: Vec<usize> =
            self.injected_on(role, kind).into_iter().filter(|&i| detectable(&self.seen[i], by, began_ns)).collect();
        for &i in &found {
            self.seen[i].detected_ns = Some(ns);
            self.seen[i].detected_by = Some(by);
        }
        found
    }

    /// `role` handles its input again at `ns`: its detected stops not resumed yet are resumed.
    pub(super) fn resume(&mut self, role: Role, ns: u64) {
        self.resume_kind(role, FaultKind::Stop, ns);
    }

    /// The stage across the link handles its input again at `ns`: the detected cuts not
    /// resumed yet are resumed.
    pub(super) fn resume_cut(&mut self, ns: u64) {
        self.resume_kind(Role::Bridge, FaultKind::Cut, ns);
    }

    fn resume_kind(&mut self, role: Role, kind: FaultKind, ns: u64) {
        for i in self.injected_on(role, kind) {
            let seen = &mut self.seen[i];
            if seen.resumed_ns.is_none() && seen.detected_ns.is_some() {
                seen.resumed_ns = Some(ns);
            }
        }
    }

    /// A restarted `role` is ready at `ns`: its kills not restarted yet are restarted.
    pub(super) fn restarted(&mut self, role: Role, ns: u64) {
        for i in self.injected_on(role, FaultKind::Kill) {
            self.seen[i].restarted_ns.get_or_insert(ns);
        }
    }

    /// What was seen of each fault, in the launch file's order (`RunLog::faults`).
    pub(super) fn seen(&self) -> &[FaultSeen] {
        &self.seen
    }

    /// The faults on `role` of `kind` that were injected, newest first.
    fn injected_on(&self, role: Role, kind: FaultKind) -> Vec<usize> {
        inject::injected(self.specs, &self.seen, role, kind)
    }
}

/// The kind of fault that `by` notices: a process that exited was killed, the rest were stopped.
fn noticed_kind(by: DetectedBy) -> FaultKind {
    match by {
        DetectedBy::ProcessExited => FaultKind::Kill,
        DetectedBy::InputDeadline | DetectedBy::MonitorHeartbeat | DetectedBy::LinkLease => FaultKind::Stop,
    }
}

/// Whether `by` may still detect a fault, in what began at `began_ns`: only once; a silence (the
/// monitor's heartbeat, the link's lease) only while the stop lasts, since after the SIGCONT it
/// is not the stop's; a stall (seen after the fact) only if it began before the SIGCONT.
fn detectable(seen: &FaultSeen, by: DetectedBy, began_ns: u64) -> bool {
    seen.detected_ns.is_none()
        && match by {
            DetectedBy::ProcessExited => true,
            DetectedBy::InputDeadline => seen.continued_ns.is_none_or(|continued| began_ns <= continued),
            DetectedBy::MonitorHeartbeat | DetectedBy::LinkLease => seen.continued_ns.is_none(),
        }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::faults::parse_fault;

    fn specs(texts: &[&str]) -> Vec<FaultSpec> {
        texts.iter().map(|t| parse_fault(t).unwrap()).collect()
    }

    #[test]
    fn a_death_detects_the_injected_kills_of_its_process_once() {
        let f = specs(&["kill sensors at 1s", "kill plant at 1s", "stop sensors at 2s for 1s"]);
        let mut ledger = FaultLedger::new(&f);
        assert!(ledger.detect(Role::Sensors, DetectedBy::ProcessExited, 5).is_empty(), "nothing injected yet");
        ledger.injected(0, 10);
        ledger.injected(1, 10);
        ledger.injected(2, 20);
        assert_eq!(ledger.detect(Role::Sensors, DetectedBy::ProcessExited, 30), [0], "not the plant's, not a stop");
        assert!(ledger.detect(Role::Sensors, DetectedBy::ProcessExited, 40).is_empty(), "detected once");
        let seen = ledger.seen();
        assert_eq!((seen[0].detected_ns, seen[0].detected_by), (Some(30), Some(DetectedBy::ProcessExited)));
        assert_eq!((seen[1].detected_ns, seen[2].detected_ns), (None, None));
    }

    #[test]
    fn a_stall_detects_a_stop_and_its_end_resumes_it() {
        let f = specs(&["stop controller at 1s for 100ms", "kill controller at 3s"]);
        let mut ledger = FaultLedger::new(&f);
        ledger.injected(0, 100);
        ledger.resume(Role::Controller, 150);
        assert_eq!(ledger.seen[0].resumed_ns, None, "not resumed before it was detected");
        assert_eq!(ledger.detect_stall(Role::Controller, 120, 200), [0]);
        ledger.resume(Role::Controller, 300);
        ledger.resume(Role::Controller, 400);
        let seen = ledger.seen();
        assert_eq!((seen[0].detected_by, seen[0].resumed_ns), (Some(DetectedBy::InputDeadline), Some(300)));
        assert_eq!(seen[1], FaultSeen::default(), "the kill was not injected");
    }

    #[test]
    fn a_fault_of_another_process_is_not_matched() {
        let f = specs(&["stop estimator at 1s for 100ms", "kill estimator at 2s"]);
        let mut ledger = FaultLedger::new(&f);
        ledger.injected(0, 10);
        ledger.injected(1, 20);
        assert!(ledger.detect_stall(Role::Sensors, 15, 30).is_empty());
        assert!(ledger.detect(Role::Controller, DetectedBy::ProcessExited, 30).is_empty());
        ledger.restarted(Role::Plant, 40);
        ledger.resume(Role::Sensors, 40);
        assert!(ledger.seen().iter().all(|s| s.detected_ns.is_none() && s.restarted_ns.is_none()));
    }

    #[test]
    fn two_faults_of_one_process_are_each_detected_and_restarted_once() {
        let f = specs(&["kill plant at 1s", "kill plant at 2s"]);
        let mut ledger = FaultLedger::new(&f);
        ledger.injected(0, 1_000);
        assert_eq!(ledger.detect(Role::Plant, DetectedBy::ProcessExited, 1_001), [0]);
        ledger.restarted(Role::Plant, 1_100);
        ledger.injected(1, 2_000);
        assert_eq!(ledger.detect(Role::Plant, DetectedBy::ProcessExited, 2_002), [1]);
        ledger.restarted(Role::Plant, 2_200);
        let seen = ledger.seen();
        assert_eq!([seen[0].detected_ns, seen[1].detected_ns], [Some(1_001), Some(2_002)]);
        assert_eq!([seen[0].restarted_ns, seen[1].restarted_ns], [Some(1_100), Some(2_200)], "the first keeps its own");
    }

    #[test]
    fn a_silence_detects_a_stop_only_before_its_continue() {
        let f = specs(&["stop monitor at 1s for 200ms", "stop bridge at 1s for 200ms"]);
        let mut ledger = FaultLedger::new(&f);
        for i in [0, 1] {
            ledger.injected(i, 100);
            ledger.continue_at(i, Some(200));
        }
        assert!(ledger.take_continues_due(199).is_empty());
        assert_eq!(ledger.take_continues_due(200), [0, 1]);
        assert!(ledger.take_continues_due(300).is_empty(), "continued once");
        ledger.continued(1, 250);
        assert!(ledger.detect(Role::Bridge, DetectedBy::LinkLease, 260).is_empty(), "a silence after the SIGCONT");
        assert_eq!(ledger.detect(Role::Monitor, DetectedBy::MonitorHeartbeat, 240), [0]);
        // The monitor's input deadline reports a stall it saw while stopped, after the fact.
        let mut late = FaultLedger::new(&f);
        late.injected(1, 100);
        late.continued(1, 300);
        assert_eq!(late.detect_stall(Role::Bridge, 290, 310), [1]);
    }

    #[test]
    fn a_stall_that_began_after_a_stops_continue_is_not_that_stops() {
        let f = specs(&["stop estimator at 1s for 300ms"]);
        let mut ledger = FaultLedger::new(&f);
        ledger.injected(0, 1_000);
        ledger.continued(0, 1_300);
        assert!(ledger.detect_stall(Role::Estimator, 30_000, 30_050).is_empty(), "a stall 29 s later");
        assert_eq!(ledger.seen()[0].detected_ns, None, "the stop stays undetected");
        assert_eq!(ledger.detect_stall(Role::Estimator, 1_290, 1_340), [0], "one that began during it");
    }

    #[test]
    fn the_runs_end_continues_every_stop_still_on_and_says_so() {
        let f = specs(&["stop plant at 100ms for 100s", "stop sensors at 100ms for 10ms", "kill estimator at 1s"]);
        let mut ledger = FaultLedger::new(&f);
        assert_eq!(ledger.stopped_since(Role::Plant), None);
        for i in [0, 1] {
            ledger.injected(i, 100);
            ledger.continue_at(i, Some(if i == 0 { 100_100 } else { 110 }));
        }
        assert_eq!(ledger.stopped_since(Role::Plant), Some((0, 100)));
        assert_eq!(ledger.take_continues_due(120), [1], "the short stop is over in its time");
        assert_eq!(ledger.take_continues_at_run_end(), [0], "the long one is cut short");
        assert!(ledger.take_continues_at_run_end().is_empty() && ledger.take_continues_due(200_000).is_empty());
        assert_eq!(ledger.stopped_since(Role::Plant), None);
        let seen = ledger.seen();
        assert_eq!([seen[0].continued_at_run_end, seen[1].continued_at_run_end], [true, false]);
    }

    #[test]
    fn a_cut_is_detected_and_resumed_by_the_stage_across_the_link_not_as_a_stop() {
        let f = specs(&["stop bridge at 1s for 200ms", "cut bridge at 2s for 300ms"]);
        let mut ledger = FaultLedger::new(&f);
        assert!(ledger.detect_cut(40, 50).is_empty(), "not cut yet");
        ledger.injected(0, 100);
        ledger.injected(1, 200);
        assert_eq!(ledger.detect_cut(240, 250), [1], "the cut, not the stop");
        assert!(ledger.detect_cut(240, 260).is_empty(), "detected once");
        ledger.resume_cut(600);
        ledger.resume(Role::Bridge, 700);
        let seen = ledger.seen();
        assert_eq!((seen[1].detected_ns, seen[1].resumed_ns), (Some(250), Some(600)));
        assert_eq!((seen[0].detected_ns, seen[0].resumed_ns), (None, None));
    }
}
