//! The ordered stop at a run's end: each process still running gets SIGTERM, in order, and
//! SIGKILL past its timeout; their last lines (the reports) are filed on the way. Then whether
//! a run whose plant finished ended well.

use std::time::{Duration, Instant};

use crate::contract::role::Role;
use crate::launcher::outcome::Outcome;

use super::Supervisor;
use super::processes::Processes;

/// Longest a stage may take to exit after SIGTERM before it is killed.
const STOP_TIMEOUT: Duration = Duration::from_secs(5);
/// Longest the launcher waits for the processes' output to close once every process has exited.
const READERS_TIMEOUT: Duration = Duration::from_secs(2);
/// The monitor writes its files on exit, so it gets longer.
const MONITOR_STOP_TIMEOUT: Duration = Duration::from_secs(60);

impl Supervisor<'_> {
    /// Stops every process still running, in order, each with SIGTERM and then, past its
    /// timeout, SIGKILL; collects their reports on the way.
    pub(super) fn stop_all(&mut self) {
        self.live.stopping();
        // A stop longer than the run ends with it, and says so.
        self.continue_at_run_end();
        // A stopped process cannot act on SIGTERM.
        for p in self.processes.iter() {
            p.signal(libc::SIGCONT);
        }
        for role in self.processes.stop_order() {
            self.show_processes();
            if self.processes[role].try_reap() {
                continue;
            }
            // After a second stop request, nothing is asked: everything left is killed.
            if !self.stop.urgent() {
                self.processes[role].signal(libc::SIGTERM);
            }
            let timeout = if role == Role::Monitor { MONITOR_STOP_TIMEOUT } else { STOP_TIMEOUT };
            let until = Instant::now() + timeout;
            while !self.processes[role].try_reap() {
                let urgent = self.stop.urgent();
                if urgent || Instant::now() > until {
                    if urgent {
                        tell!("looplab: second stop request; killing {role}");
                    } else {
                        tell!("looplab: {role} did not stop within {} s; killing it", timeout.as_secs());
                        self.processes[role].killed_at_stop = Some(timeout);
                    }
                    self.processes[role].signal(libc::SIGKILL);
                    while !self.processes[role].try_reap() {
                        std::thread::sleep(Duration::from_millis(5));
                    }
                    break;
                }
                if let Ok(event) = self.events.recv_timeout(Duration::from_millis(5)) {
                    self.handle(event);
                }
            }
        }
        for role in self.processes.stop_order() {
            self.note_left_running(role);
        }
        // Every process has exited: read what is left in their pipes, until every reader is done.
        while let Ok(event) = self.events.recv_timeout(Duration::from_millis(200)) {
            self.handle(event);
        }
    }

    /// Waits for the threads reading the processes' output. Every process has exited and what
    /// each left in its session is killed, so their pipes are closed, unless a process that
    /// left its session holds one: that reader is left behind, and said, not waited for forever.
    pub(super) fn join_readers(&mut self) {
        let until = Instant::now() + READERS_TIMEOUT;
        while Instant::now() < until && self.readers.iter().any(|(_, reader)| !reader.is_finished()) {
            std::thread::sleep(Duration::from_millis(5));
        }
        for (role, reader) in std::mem::take(&mut self.readers) {
            if reader.is_finished() {
                let _ = reader.join();
            } else {
                let line = format!(
                    "{role}'s output stayed open after it exited: a process it started holds it from a session of \
                     its own, and was not stopped"
                );
                self.note(crate::contract::clock::now_ns(), line.clone());
                self.left_running.push(line);
            }
        }
    }

    /// After a run whose plant finished: every other process must have ended cleanly too, and
    /// the monitor must have reported.
    pub(super) fn check_ends(&self) -> Outcome {
        ends_outcome(&self.processes, self.reports.monitor.is_some())
    }
}

/// The outcome of a run whose plant finished, from how its processes ended and whether the
/// monitor reported.
fn ends_outcome(processes: &Processes, monitor_reported: bool) -> Outcome {
    let failed = processes.unclean_ends();
    if !failed.is_empty() {
        Outcome::Failed(format!("{}; see the logs folder", failed.join(", ")))
    } else if !monitor_reported {
        Outcome::Failed("the monitor sent no report".into())
    } else {
        Outcome::Completed
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::faults::{OnDeath, Policy, Restart};
    use crate::launcher::child::Start;
    use crate::launcher::outcome::Exit;
    use crate::launcher::supervisor::processes::Process;

    fn ended(exits: [Exit; 5]) -> Processes {
        let policy = Policy { restart: Restart::OnFailure, on_death: OnDeath::End, max_restarts: 0, backoff_s: 0.0 };
        let processes = Role::START_ORDER.into_iter().zip(exits).map(|(role, exit)| {
            let mut p = Process::new(role, policy);
            p.started(Start { pid: 0, exit, cpu_s: 0.0, wakeups: 0, preemptions: 0, left_running: vec![] }, None);
            p
        });
        Processes::new(processes.collect())
    }

    #[test]
    fn a_finished_run_completes_only_if_every_process_ended_cleanly_and_the_monitor_reported() {
        let clean = ended([Exit::Status(0); 5]);
        assert_eq!(ends_outcome(&clean, true), Outcome::Completed);
        assert_eq!(ends_outcome(&clean, false), Outcome::Failed("the monitor sent no report".into()));
        // In start order: monitor, controller, estimator, sensors, plant.
        let killed = ended([Exit::Status(0), Exit::Signal(9), Exit::Status(0), Exit::Status(0), Exit::Running]);
        assert_eq!(
            ends_outcome(&killed, true),
            Outcome::Failed(
                "controller exited with status signal 9, plant closed its output; see the logs folder".into()
            )
        );
    }
}
