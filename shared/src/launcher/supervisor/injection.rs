//! Fault injection from outside: the kills and stops that are due are sent to their processes,
//! stopped processes are continued when their stop is over, and a stopped monitor is noticed by
//! its silence. What is due is the fault ledger's and `launcher::inject`'s to say.

use crate::config::faults::FaultKind;
use crate::config::launch::Mode;
use crate::contract::clock::now_ns;
use crate::contract::role::Role;
use crate::launcher::inject::{self, DetectedBy};
use crate::launcher::outcome::Outcome;
use crate::monitor::injections::{self, Injection};

use super::Supervisor;

/// Lockstep: how long a fault on the monitor waits for it to write the loops before it.
const MONITOR_CATCH_UP_NS: u64 = 5_000_000_000;

/// How long the monitor may stay silent (its heartbeat comes every 20 ms) before it counts as
/// stalled: three heartbeats and a little.
const MONITOR_SILENCE_NS: u64 = 70_000_000;

impl Supervisor<'_> {
    /// Real time: injects the faults that are due.
    pub(super) fn inject_due_by_time(&mut self) {
        if self.config.mode != Mode::Realtime {
            return;
        }
        if let Some(start) = self.log.plant_start_ns {
            for i in self.faults.due_by_time(start, now_ns()) {
                self.inject(i);
            }
        }
    }

    /// Lockstep: the plant holds loop `k`; injects the faults due there (the monitor's once it
    /// has written every loop before `k`). The plant goes on once every process is back up.
    pub(super) fn pause_at(&mut self, k: u64) {
        let (on_monitor, others): (Vec<usize>, Vec<usize>) = self
            .faults
            .due_at_loop(self.config.rate_hz, k)
            .into_iter()
            .partition(|&i| inject::target(self.faults.spec(i)) == Role::Monitor);
        for i in others {
            self.inject(i);
        }
        if !on_monitor.is_empty() {
            self.monitor_faults_held = Some((k, now_ns(), on_monitor));
        }
        self.paused = true;
        self.last_pause = Some(k);
    }

    /// Lockstep: injects the monitor's held faults once it has written and saved every loop
    /// before the paused one (its writer may lag the loop by thousands of loops), or, noted,
    /// once it has not done so within [`MONITOR_CATCH_UP_NS`].
    pub(super) fn inject_held_monitor_faults(&mut self, now: u64) {
        let Some((k, since, _)) = self.monitor_faults_held else { return };
        let caught_up = self.monitor_written >= k;
        if !caught_up && now.saturating_sub(since) < MONITOR_CATCH_UP_NS {
            return;
        }
        let (_, _, held) = self.monitor_faults_held.take().expect("checked above");
        if !caught_up {
            self.note(
                now,
                format!(
                    "the monitor had written {} of the {k} loops before its fault after {} s; injected anyway",
                    self.monitor_written,
                    MONITOR_CATCH_UP_NS / 1_000_000_000
                ),
            );
        }
        for i in held {
            self.inject(i);
        }
    }

    /// Sends SIGCONT to the processes whose stop is over at `now` (ns).
    pub(super) fn continue_stopped(&mut self, now: u64) {
        let due = self.faults.take_continues_due(now);
        self.continue_faults(due, "");
    }

    /// The run is over (real time: its duration has passed; or it ends for any reason): every
    /// stop still on is continued now, not at its time, so that the run ends on time.
    pub(super) fn continue_at_run_end(&mut self) {
        let left = self.faults.take_continues_at_run_end();
        self.continue_faults(left, ", before its time: the run is over");
    }

    /// Real time: the run's duration has passed since tick 0 at `now` (a stopped plant cannot
    /// end it by itself).
    pub(super) fn continue_past_run_end(&mut self, now: u64) {
        let Some(start) = self.log.plant_start_ns else { return };
        if self.config.mode == Mode::Realtime && now >= start + (self.config.duration_s * 1e9) as u64 {
            self.continue_at_run_end();
        }
    }

    /// Lockstep: a plant stopped by a fault for longer than `lockstep_stall_s` has stalled the
    /// loop, as any stopped stage does (the plant would say so of another): the run ends there.
    pub(super) fn lockstep_plant_stall(&self, now: u64) -> Option<Outcome> {
        if self.config.mode != Mode::Lockstep {
            return None;
        }
        let (i, since) = self.faults.stopped_since(Role::Plant)?;
        let stall_s = self.config.supervision.lockstep_stall_s;
        if now.saturating_sub(since) as f64 * 1e-9 <= stall_s {
            return None;
        }
        let k = self.faults.spec(i).ticks(self.config.rate_hz).0;
        Some(Outcome::Failed(format!(
            "the loop stalled at loop {k}: the plant was stopped for longer than {stall_s} s \
             (supervision.lockstep_stall_s)"
        )))
    }

    /// Continues the faults `due` (SIGCONT, or a cut's mending noted); `why` ends each note.
    fn continue_faults(&mut self, due: Vec<usize>, why: &str) {
        for i in due {
            let fault = self.faults.spec(i);
            if fault.kind == FaultKind::Cut {
                // The bridge mends it by itself at its end loop; this notes when.
                let ns = now_ns();
                self.faults.continued(i, ns);
                self.note(ns, format!("{}: the link carries the loop again{why}", fault.describe()));
                continue;
            }
            let role = inject::target(fault);
            // Stamped before the signal: the process may run, and the monitor stamp it resumed,
            // before this thread reads the clock again.
            let ns = now_ns();
            self.processes[role].signal(libc::SIGCONT);
            self.processes[role].stopped = false;
            // Its stall was the stop's: a hang is timed from now, until it answers again.
            self.processes[role].time_hang_from(ns);
            self.faults.continued(i, ns);
            self.note(ns, format!("SIGCONT {role}{why}"));
        }
    }

    fn inject(&mut self, i: usize) {
        let fault = self.faults.spec(i);
        let role = inject::target(fault);
        let ns = now_ns();
        self.faults.injected(i, ns);
        if fault.kind == FaultKind::Cut {
            // This machine's bridge drops the loops of the cut by itself; noted at its time, and
            // mended at its end (a cut without a duration lasts to the end of the run).
            let lasts = fault.duration_s.map(|d| ns + std::time::Duration::from_secs_f64(d).as_nanos() as u64);
            self.faults.continue_at(i, lasts);
            self.note(ns, format!("inject: {} (the link passes nothing either way)", fault.describe()));
            return;
        }
        if !self.processes[role].running() {
            self.note(ns, format!("{}: not injected, {role} is not running", fault.describe()));
            self.tell_monitor(i, Injection::NotInjected);
            return;
        }
        if let Some((signal, continue_at_ns)) = inject::injection(fault, ns) {
            let process = &mut self.processes[role];
            process.signal(signal);
            match fault.kind {
                FaultKind::Kill => process.ready = false,
                _ => process.stopped = true,
            }
            self.faults.continue_at(i, continue_at_ns);
        }
        self.note(ns, format!("inject: {}", fault.describe()));
        if let Some(start) = self.log.plant_start_ns {
            let k = inject::loop_at(ns, start, self.config.period_ns());
            self.tell_monitor(i, Injection::AtLoop(k));
        }
    }

    /// Real time: tells the monitor how fault `i` (a kill or a stop) went, so that it judges its
    /// effect from when it really happened (a stopped launcher injects late). A cut is the
    /// bridge's own, by loop index: on time whatever the launcher does.
    fn tell_monitor(&mut self, i: usize, injection: Injection) {
        if self.config.mode != Mode::Realtime {
            return;
        }
        let injections = self.faults.landed(i, injection);
        if let Err(e) = injections::path(&self.run_id).and_then(|path| injections::write(&path, injections)) {
            let fault = self.faults.spec(i).describe();
            self.note(now_ns(), format!("{fault}: the monitor cannot be told when it was injected ({e:#})"));
        }
    }

    /// Only a stop fault on the monitor makes it silent while alive: its silence past
    /// `MONITOR_SILENCE_NS` detects that stop.
    pub(super) fn watch_monitor_heartbeat(&mut self) {
        let now = now_ns();
        let monitor = &self.processes[Role::Monitor];
        if !monitor_silent(self.monitor_heard_ns, now, monitor.ready, monitor.stopped) {
            return;
        }
        for _ in self.faults.detect(Role::Monitor, DetectedBy::MonitorHeartbeat, now) {
            self.note(now, "monitor silent: stalled".into());
        }
    }
}

/// Whether a monitor last heard from (a heartbeat or a status) at `monitor_heard_ns` counts as
/// silent at `now_ns`: only while it is up and stopped by a fault (a starting or dead one says
/// nothing either).
fn monitor_silent(monitor_heard_ns: u64, now_ns: u64, ready: bool, stopped: bool) -> bool {
    now_ns.saturating_sub(monitor_heard_ns) > MONITOR_SILENCE_NS && ready && stopped
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_monitor_is_silent_past_70_ms_without_a_heartbeat_while_up_and_stopped() {
        let last = 4_000_000_000;
        assert!(!monitor_silent(last, last + 70_000_000, true, true));
        assert!(monitor_silent(last, last + 70_000_001, true, true));
        assert!(!monitor_silent(last, last + 900_000_000, false, true), "not ready: starting again");
        assert!(!monitor_silent(last, last + 900_000_000, true, false), "not stopped by a fault");
        assert!(!monitor_silent(last, last - 1, true, true), "a status after the look");
    }
}
