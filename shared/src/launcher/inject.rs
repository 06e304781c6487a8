//! Fault injection from outside: which kill and stop faults are due (at their time in real time,
//! at their loop while the lockstep plant holds), the signal each sends, and what was seen of
//! each fault. The supervisor sends the signals. A `cut` is this machine's bridge's own (by loop
//! index), but in real time the launcher notes it as injected at its time and mended at its end,
//! so that its detection and the link's return are timed as a stop's are.

use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::config::faults::{FaultKind, FaultSpec};
use crate::contract::role::Role;

/// What noticed a fault first (`summary.json`'s `detected_by`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
pub enum DetectedBy {
    /// A kill: the process's output closed and it was reaped.
    #[serde(rename = "the process exited")]
    ProcessExited,
    /// A stop: the monitor saw the process's input wait past `stall_timeout_s` (a cut: the
    /// input of the stage across the link).
    #[serde(rename = "the monitor's input deadline")]
    InputDeadline,
    /// A stop of the monitor itself: its status lines stopped.
    #[serde(rename = "the monitor's heartbeat stopped")]
    MonitorHeartbeat,
    /// A stop of a bridge: the other bridge's link lease ran out. (A cut passes nothing of the
    /// loop but leaves the link up: the input deadline of the stage across it notices it.)
    #[serde(rename = "the link's lease ran out")]
    LinkLease,
}

/// What the launcher saw of one fault (CLOCK_MONOTONIC, ns).
#[derive(Debug, Default, Clone, PartialEq)]
pub struct FaultSeen {
    pub injected_ns: Option<u64>,
    pub detected_ns: Option<u64>,
    pub detected_by: Option<DetectedBy>,
    pub restarted_ns: Option<u64>,
    pub continued_ns: Option<u64>,
    pub resumed_ns: Option<u64>,
    /// A stop: when to send SIGCONT.
    pub continue_at_ns: Option<u64>,
    /// A stop (or a cut) still on when the run ended: it was continued then, before its time.
    pub continued_at_run_end: bool,
}

/// The process a fault targets (checked when the launch file was loaded).
pub fn target(spec: &FaultSpec) -> Role {
    spec.process.parse().expect("a fault's process is checked at load")
}

/// Real time: the faults the launcher injects that are due at `now_ns`, with tick 0 at
/// `start_ns`, and not injected yet.
pub fn due_by_time(faults: &[FaultSpec], seen: &[FaultSeen], start_ns: u64, now_ns: u64) -> Vec<usize> {
    (0..faults.len())
        .filter(|&i| {
            let due = start_ns + (faults[i].at_s * 1e9) as u64;
            noted_at_its_time(faults[i].kind) && seen[i].injected_ns.is_none() && now_ns >= due
        })
        .collect()
}

/// Real time: the faults the launcher injects, or notes (a cut), at their time.
fn noted_at_its_time(kind: FaultKind) -> bool {
    kind.from_outside() || kind == FaultKind::Cut
}

/// Real time: the loop a fault injected at `injected_ns` takes effect at: the first of the
/// plant's ticks at or after it (tick k at `start_ns + k·period_ns`, as the plant keeps them).
pub fn loop_at(injected_ns: u64, start_ns: u64, period_ns: u64) -> u64 {
    injected_ns.saturating_sub(start_ns).div_ceil(period_ns.max(1))
}

/// Lockstep: the faults the launcher injects at loop `k`, not injected yet.
pub fn due_at_loop(faults: &[FaultSpec], seen: &[FaultSeen], rate_hz: f64, k: u64) -> Vec<usize> {
    (0..faults.len())
        .filter(|&i| faults[i].kind.from_outside() && faults[i].ticks(rate_hz).0 == k && seen[i].injected_ns.is_none())
        .collect()
}

/// The faults on `role` of `kind` that were injected, newest first.
pub fn injected(faults: &[FaultSpec], seen: &[FaultSeen], role: Role, kind: FaultKind) -> Vec<usize> {
    let mut found: Vec<usize> = (0..faults.len())
        .filter(|&i| target(&faults[i]) == role && faults[i].kind == kind && seen[i].injected_ns.is_some())
        .collect();
    found.sort_by_key(|&i| std::cmp::Reverse(seen[i].injected_ns));
    found
}

/// What injecting `spec` at `now_ns` does to its process, if it runs: the signal to send, and
/// for a stop when to continue it (ns). None: the process does it itself (delay, drop, corrupt,
/// cut).
pub fn injection(spec: &FaultSpec, now_ns: u64) -> Option<(i32, Option<u64>)> {
    match spec.kind {
        FaultKind::Kill => Some((libc::SIGKILL, None)),
        FaultKind::Stop => {
            let lasts = Duration::from_secs_f64(spec.duration_s.unwrap_or_default());
            Some((libc::SIGSTOP, Some(now_ns + lasts.as_nanos() as u64)))
        }
        FaultKind::Delay | FaultKind::Drop | FaultKind::Corrupt | FaultKind::Cut => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::launch::Override;
    use crate::contract::clock::period_ns;
    use crate::scenarios::resolve;

    fn faults(texts: &[&str]) -> Vec<FaultSpec> {
        let overrides: Vec<Override> = texts.iter().map(|t| Override::fault(t).unwrap()).collect();
        resolve("pendulum", &overrides).unwrap().0.faults
    }

    #[test]
    fn real_time_faults_are_due_at_their_time_once_and_only_from_outside() {
        let f =
            faults(&["kill estimator at 1s", "stop controller at 2s for 100ms", "delay controller by 3 ticks at 1s"]);
        let mut seen = vec![FaultSeen::default(); 3];
        let start = 5_000_000_000;
        assert_eq!(due_by_time(&f, &seen, start, start + 999_999_999), Vec::<usize>::new());
        assert_eq!(due_by_time(&f, &seen, start, start + 1_000_000_000), [0], "the delay is the process's own");
        assert_eq!(due_by_time(&f, &seen, start, start + 2_000_000_000), [0, 1]);
        seen[0].injected_ns = Some(start + 1_000_000_000);
        assert_eq!(due_by_time(&f, &seen, start, start + 3_000_000_000), [1]);
    }

    #[test]
    fn a_fault_takes_effect_at_the_first_tick_at_or_after_its_real_injection() {
        let start = 5_000_000_000;
        let period = period_ns(1000.0);
        assert_eq!(period, 1_000_000);
        assert_eq!(loop_at(start, start, period), 0);
        assert_eq!(loop_at(start + 2_000_000_000, start, period), 2000, "on a tick: that tick");
        assert_eq!(loop_at(start + 2_000_000_001, start, period), 2001, "just after: the next");
        // Planned at 2 s, sent 1.0005 s late by a launcher that was stopped.
        assert_eq!(loop_at(start + 3_000_500_000, start, period), 3001);
        // The plant's period in whole ns, as it keeps its ticks: 3 Hz ticks at 333 333 333 ns.
        assert_eq!(period_ns(3.0), 333_333_333);
        assert_eq!(loop_at(start + 1_000_000_000, start, period_ns(3.0)), 4);
    }

    #[test]
    fn lockstep_faults_are_due_at_their_loop() {
        let f = faults(&["kill plant at 1.5s", "stop sensors at 1.5s for 20ms", "kill monitor at 2s"]);
        let mut seen = vec![FaultSeen::default(); 3];
        assert_eq!(due_at_loop(&f, &seen, 1000.0, 1499), Vec::<usize>::new());
        assert_eq!(due_at_loop(&f, &seen, 1000.0, 1500), [0, 1]);
        assert_eq!(due_at_loop(&f, &seen, 200.0, 400), [2]);
        seen[0].injected_ns = Some(1);
        assert_eq!(due_at_loop(&f, &seen, 1000.0, 1500), [1]);
    }

    #[test]
    fn injected_faults_are_found_by_process_and_kind_newest_first() {
        let f = faults(&["kill sensors at 1s", "stop sensors at 2s for 1s", "kill sensors at 3s", "kill plant at 4s"]);
        let mut seen = vec![FaultSeen::default(); 4];
        assert_eq!(injected(&f, &seen, Role::Sensors, FaultKind::Kill), Vec::<usize>::new());
        for (i, ns) in [(0, 10), (1, 20), (2, 30), (3, 40)] {
            seen[i].injected_ns = Some(ns);
        }
        assert_eq!(injected(&f, &seen, Role::Sensors, FaultKind::Kill), [2, 0]);
        assert_eq!(injected(&f, &seen, Role::Sensors, FaultKind::Stop), [1]);
        assert_eq!(injected(&f, &seen, Role::Plant, FaultKind::Kill), [3]);
    }

    #[test]
    fn detection_causes_keep_their_text() {
        for (by, text) in [
            (DetectedBy::ProcessExited, "the process exited"),
            (DetectedBy::InputDeadline, "the monitor's input deadline"),
            (DetectedBy::MonitorHeartbeat, "the monitor's heartbeat stopped"),
        ] {
            assert_eq!(serde_json::to_value(by).unwrap(), text);
            assert_eq!(serde_json::from_value::<DetectedBy>(text.into()).unwrap(), by);
        }
    }

    #[test]
    fn kills_and_stops_are_signals_and_a_stop_ends_after_its_duration() {
        let f = faults(&["kill plant at 1s", "stop sensors at 1s for 250ms", "drop sensors 20% at 1s"]);
        let now = 3_000_000_000;
        assert_eq!(injection(&f[0], now), Some((libc::SIGKILL, None)));
        assert_eq!(injection(&f[1], now), Some((libc::SIGSTOP, Some(3_250_000_000))));
        assert_eq!(injection(&f[2], now), None);
    }
}
