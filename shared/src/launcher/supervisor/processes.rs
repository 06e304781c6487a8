//! The process table: each process of the run across its restarts (its starts, whether it is
//! ready, stopped by a fault, waiting for a restart or gone), by role. Times are passed in
//! (CLOCK_MONOTONIC ns, as `contract::clock::now_ns` reads it).

use std::io::Write as _;
use std::ops::{Index, IndexMut};
use std::process::ChildStdin;
use std::time::Duration;

use crate::config::faults::Policy;
use crate::contract::protocol::EXIT_DISK_FULL;
use crate::contract::role::Role;
use crate::launcher::child::Start;
use crate::launcher::dashboard::{ProcessRow, ProcessState};
use crate::launcher::outcome::Exit;
use crate::launcher::restart::Death;

/// A process of the loop across its restarts.
pub(super) struct Process {
    pub(super) role: Role,
    pub(super) policy: Policy,
    /// Every start; the last is the running incarnation.
    pub(super) runs: Vec<Start>,
    stdin: Option<ChildStdin>,
    /// Its ports are up (cleared when it dies or is killed).
    pub(super) ready: bool,
    /// When its running incarnation became ready.
    ready_since_ns: Option<u64>,
    /// Set while it waits for its clean-up and backoff before a restart.
    restart: Option<PendingRestart>,
    /// Restarts since it last ran healthy (`backoff_reset_s`): the backoff doubles with each.
    pub(super) quick_restarts: u32,
    /// SIGSTOPped by a fault and not continued yet.
    pub(super) stopped: bool,
    /// It died and will not be restarted (the monitor may; the others end the run).
    pub(super) gone: bool,
    /// A stage gone with `on_death = "continue"`: the run goes on without it, and its death is
    /// the summary's `lost_stages`, not an unclean end.
    pub(super) lost: bool,
    /// The last words of its quick deaths in a row, numbers aside, and how many ended with them.
    same_failure: Option<(String, u32)>,
    /// Its running incarnation's end was seen (its output closed, or it exited while something
    /// it started still holds its output): its death is being handled.
    pub(super) end_seen: bool,
    /// Since when the monitor has seen it stalled (its input waiting, nothing out), until it
    /// resumes; a restarted one is dated from when it is ready again.
    pub(super) stalled_since_ns: Option<u64>,
    /// Its running incarnation was killed as hung, after stalling this long (s).
    pub(super) hung_s: Option<f64>,
    /// When its running incarnation was first seen exited with its output still open.
    pub(super) exited_seen_at: Option<std::time::Instant>,
    /// At the run's end it did not exit within this long of the launcher's SIGTERM, and the
    /// launcher killed it: not a crash of its own.
    pub(super) killed_at_stop: Option<std::time::Duration>,
}

/// A restart under way: it starts once the dead process's resources are removed and the backoff
/// has passed.
struct PendingRestart {
    not_before_ns: u64,
    cleaned: bool,
}

impl Process {
    pub(super) fn new(role: Role, policy: Policy) -> Self {
        Process {
            role,
            policy,
            runs: vec![],
            stdin: None,
            ready: false,
            ready_since_ns: None,
            restart: None,
            quick_restarts: 0,
            stopped: false,
            gone: false,
            lost: false,
            same_failure: None,
            end_seen: false,
            stalled_since_ns: None,
            hung_s: None,
            exited_seen_at: None,
            killed_at_stop: None,
        }
    }

    /// The running (or last) incarnation's number.
    pub(super) fn incarnation(&self) -> u32 {
        self.runs.len().saturating_sub(1) as u32
    }

    pub(super) fn running(&self) -> bool {
        self.runs.last().is_some_and(|r| r.exit == Exit::Running)
    }

    pub(super) fn try_reap(&mut self) -> bool {
        self.runs.last_mut().is_none_or(Start::try_reap)
    }

    pub(super) fn signal(&self, signal: i32) {
        if let Some(run) = self.runs.last() {
            run.signal(signal);
        }
    }

    pub(super) fn exit_text(&self) -> String {
        if let Some(stalled_s) = self.hung_s {
            return format!("{} hung: stalled {stalled_s:.1} s inside its own code, and was killed", self.role);
        }
        if let Some(timeout) = self.killed_at_stop {
            return format!(
                "{} did not exit within {} s of the launcher's SIGTERM at the run's end, and was killed",
                self.role,
                timeout.as_secs()
            );
        }
        match self.runs.last().map(|r| r.exit) {
            Some(exit) if exit == Exit::Status(EXIT_DISK_FULL.into()) => {
                format!("{} exited with status {exit} (its disk is full)", self.role)
            }
            Some(exit) if exit != Exit::Running => format!("{} exited with status {exit}", self.role),
            _ => format!("{} closed its output", self.role),
        }
    }

    /// What the dashboard calls its state.
    pub(super) fn row(&self) -> ProcessRow {
        let state = if self.gone {
            ProcessState::Dead
        } else if self.restart.is_some() {
            ProcessState::Restarting
        } else if !self.running() {
            ProcessState::Exited
        } else if self.stopped {
            ProcessState::Stopped
        } else if self.ready {
            ProcessState::Running
        } else {
            ProcessState::Starting
        };
        let pid = self.runs.last().filter(|r| r.exit == Exit::Running).map(|r| r.pid);
        ProcessRow { role: self.role, state, restarts: self.incarnation(), pid }
    }

    pub(super) fn ended_cleanly(&self) -> bool {
        self.runs.last().is_some_and(|r| r.exit.clean())
    }

    pub(super) fn write_line(&mut self, line: &str) -> bool {
        let written = self.stdin.as_mut().map(|s| s.write_all(format!("{line}\n").as_bytes()).and_then(|_| s.flush()));
        matches!(written, Some(Ok(())))
    }

    /// Its next incarnation started.
    pub(super) fn started(&mut self, start: Start, stdin: Option<ChildStdin>) {
        self.runs.push(start);
        self.stdin = stdin;
        self.ready = false;
        self.ready_since_ns = None;
        self.restart = None;
        self.end_seen = false;
        self.hung_s = None;
        self.exited_seen_at = None;
    }

    /// A stall it was in is timed as a hang from `now_ns` on: what held it (a stop, a pause, its
    /// start-up) is over, and it has not answered yet.
    pub(super) fn time_hang_from(&mut self, now_ns: u64) {
        if self.stalled_since_ns.is_some() {
            self.stalled_since_ns = Some(now_ns);
        }
    }

    /// Its running incarnation said it is ready, at `now_ns`.
    pub(super) fn became_ready(&mut self, now_ns: u64) {
        self.ready = true;
        self.ready_since_ns = Some(now_ns);
        self.time_hang_from(now_ns);
    }

    /// Its output ended at `now_ns`: it is no longer ready nor stopped. Returns what the restart
    /// policy needs to know of its death.
    pub(super) fn died(&mut self, now_ns: u64) -> Death {
        let ran_s = self.ready_since_ns.map(|t| now_ns.saturating_sub(t) as f64 / 1e9);
        self.ready = false;
        self.ready_since_ns = None;
        self.stopped = false;
        let disk_full = self.runs.last().is_some_and(|r| r.exit == Exit::Status(EXIT_DISK_FULL.into()));
        Death {
            clean: self.ended_cleanly(),
            restarts: self.incarnation(),
            quick_restarts: self.quick_restarts,
            ran_s,
            disk_full,
            same_failure_in_a_row: 0,
        }
    }

    /// Its death that ended with `last_words` (empty: none), before it ran healthy or not:
    /// how many quick deaths in a row ended the same way, numbers aside (a step that fails at
    /// another time each start is the same failure).
    pub(super) fn same_failure_in_a_row(&mut self, last_words: &str, healthy: bool) -> u32 {
        if last_words.is_empty() || healthy {
            self.same_failure = None;
            return 0;
        }
        let words: String = last_words.chars().map(|c| if c.is_ascii_digit() { '0' } else { c }).collect();
        let count = match &self.same_failure {
            Some((same, n)) if *same == words => n + 1,
            _ => 1,
        };
        self.same_failure = Some((words, count));
        count
    }

    /// It is to start again once its clean-up is done and `backoff` after `now_ns` has passed.
    pub(super) fn restart_after(&mut self, backoff: Duration, quick_restarts: u32, now_ns: u64) {
        self.quick_restarts = quick_restarts;
        let not_before_ns = now_ns + backoff.as_nanos() as u64;
        self.restart = Some(PendingRestart { not_before_ns, cleaned: false });
    }

    /// Its clean-up is done; true if a restart waited for it (the first time only).
    pub(super) fn cleaned(&mut self) -> bool {
        match &mut self.restart {
            Some(restart) if !restart.cleaned => {
                restart.cleaned = true;
                true
            }
            _ => false,
        }
    }

    /// Its restart may start at `now_ns`: its clean-up is done and its backoff over.
    pub(super) fn restart_due(&self, now_ns: u64) -> bool {
        self.restart.as_ref().is_some_and(|r| r.cleaned && now_ns >= r.not_before_ns)
    }

    /// It will not run again (a restart that failed to start, or a refusal).
    pub(super) fn give_up(&mut self) {
        self.restart = None;
        self.gone = true;
    }
}

/// The run's processes, in start order, by role.
pub(super) struct Processes(Vec<Process>);

impl Processes {
    pub(super) fn new(processes: Vec<Process>) -> Self {
        Self(processes)
    }

    pub(super) fn iter(&self) -> impl Iterator<Item = &Process> {
        self.0.iter()
    }

    pub(super) fn iter_mut(&mut self) -> impl Iterator<Item = &mut Process> {
        self.0.iter_mut()
    }

    /// Every process is ready, or gone for good.
    pub(super) fn all_up(&self) -> bool {
        self.iter().all(|p| p.ready || p.gone)
    }

    pub(super) fn rows(&self) -> Vec<ProcessRow> {
        self.iter().map(Process::row).collect()
    }

    /// The order they stop in: `Role::STOP_ORDER`, with the bridges after the stages (the remote
    /// one tidies its host up once they are gone) and the monitor last.
    pub(super) fn stop_order(&self) -> Vec<Role> {
        Role::STOP_ORDER
            .into_iter()
            .flat_map(|r| if r == Role::Monitor { vec![Role::Bridge, Role::BridgeRemote, r] } else { vec![r] })
            .filter(|r| self.iter().any(|p| p.role == *r))
            .collect()
    }

    /// How each process that did not end cleanly ended (a lost stage is the summary's
    /// `lost_stages`).
    pub(super) fn unclean_ends(&self) -> Vec<String> {
        self.iter().filter(|p| !p.ended_cleanly() && !p.lost).map(Process::exit_text).collect()
    }
}

impl Index<Role> for Processes {
    type Output = Process;

    fn index(&self, role: Role) -> &Process {
        self.0.iter().find(|p| p.role == role).expect("every role has its process")
    }
}

impl IndexMut<Role> for Processes {
    fn index_mut(&mut self, role: Role) -> &mut Process {
        self.0.iter_mut().find(|p| p.role == role).expect("every role has its process")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::faults::{OnDeath, Restart};
    use crate::launcher::restart::{Decision, decide};

    const ON_FAILURE: Policy =
        Policy { restart: Restart::OnFailure, on_death: OnDeath::End, max_restarts: 3, backoff_s: 0.01 };

    fn ms(ms: u64) -> Duration {
        Duration::from_millis(ms)
    }

    /// CLOCK_MONOTONIC ns, `ms` milliseconds after an arbitrary start.
    fn at(ms: u64) -> u64 {
        7_000_000_000 + ms * 1_000_000
    }

    /// A process with one start that ended with `exit` (no real process: its pid is never used).
    fn ended(role: Role, exit: Exit) -> Process {
        let mut p = Process::new(role, ON_FAILURE);
        p.started(Start { pid: 0, exit, cpu_s: 0.0, wakeups: 0, preemptions: 0, left_running: vec![] }, None);
        p
    }

    /// Follows a killed process through the policy, as the supervisor does at its death.
    fn kill(p: &mut Process, backoff_reset_s: f64, now_ns: u64) -> Decision {
        p.runs.last_mut().unwrap().exit = Exit::Signal(libc::SIGKILL);
        let death = p.died(now_ns);
        let decision = decide(&p.policy, backoff_reset_s, death);
        if let Decision::Restart { backoff, quick_restarts } = decision {
            p.restart_after(backoff, quick_restarts, now_ns);
        }
        decision
    }

    /// The same last line on quick deaths in a row counts up, numbers aside; a healthy run, a
    /// silent death or other words start again.
    #[test]
    fn the_same_failure_in_a_row_is_counted_numbers_aside() {
        let mut p = Process::new(Role::Controller, ON_FAILURE);
        assert_eq!(p.same_failure_in_a_row(": error: step failed at t = 1.01 s", false), 1);
        assert_eq!(p.same_failure_in_a_row(": error: step failed at t = 1.27 s", false), 2);
        assert_eq!(p.same_failure_in_a_row(": error: another", false), 1);
        assert_eq!(p.same_failure_in_a_row(": error: another", true), 0);
        assert_eq!(p.same_failure_in_a_row(": error: another", false), 1);
        assert_eq!(p.same_failure_in_a_row("", false), 0);
    }

    #[test]
    fn a_restart_is_due_once_cleaned_and_past_its_backoff() {
        let mut p = ended(Role::Estimator, Exit::Running);
        p.became_ready(at(0));
        let died = at(500);
        assert_eq!(kill(&mut p, 1.0, died), Decision::Restart { backoff: ms(10), quick_restarts: 1 });
        assert_eq!(p.row().state, ProcessState::Restarting);
        assert!(!p.ready && !p.restart_due(died + 10_000_000), "not cleaned yet");
        assert!(p.cleaned() && !p.cleaned(), "the clean-up counts once");
        assert!(!p.restart_due(died + 9_999_999), "within the backoff");
        assert!(p.restart_due(died + 10_000_000));
        p.started(Start::running(0), None);
        assert!(!p.restart_due(died + 20_000_000) && p.incarnation() == 1);
        assert_eq!(p.row().state, ProcessState::Starting);
    }

    #[test]
    fn the_time_it_ran_ready_decides_whether_its_backoff_starts_again() {
        let mut p = ended(Role::Sensors, Exit::Running);
        p.became_ready(at(0));
        assert_eq!(kill(&mut p, 1.0, at(100)), Decision::Restart { backoff: ms(10), quick_restarts: 1 });
        p.started(Start::running(0), None);
        p.became_ready(at(200));
        assert_eq!(kill(&mut p, 1.0, at(300)), Decision::Restart { backoff: ms(20), quick_restarts: 2 });
        p.started(Start::running(0), None);
        p.became_ready(at(400));
        // It ran one second (backoff_reset_s) ready: healthy, back to the first backoff.
        assert_eq!(kill(&mut p, 1.0, at(1400)), Decision::Restart { backoff: ms(10), quick_restarts: 1 });
        p.started(Start::running(0), None);
        // Killed before it was ready: it never ran healthy; and it reached max_restarts.
        assert_eq!(kill(&mut p, 1.0, at(9000)), Decision::TooMany { max_restarts: 3 });
    }

    #[test]
    fn a_death_forgets_ready_and_stopped_and_tells_the_policy_how_it_ended() {
        let mut p = ended(Role::Plant, Exit::Status(0));
        p.became_ready(at(0));
        p.stopped = true;
        let death = p.died(at(2500));
        assert_eq!(
            death,
            Death {
                clean: true,
                restarts: 0,
                quick_restarts: 0,
                ran_s: Some(2.5),
                disk_full: false,
                same_failure_in_a_row: 0
            }
        );
        assert!(!p.ready && !p.stopped);
        assert_eq!(p.row().state, ProcessState::Exited);
        assert_eq!(p.exit_text(), "plant exited with status 0");
        assert_eq!(ended(Role::Plant, Exit::Running).exit_text(), "plant closed its output");
    }

    #[test]
    fn the_table_says_who_is_up_how_each_ended_and_the_stop_order() {
        let mut five = Processes::new(Role::START_ORDER.into_iter().map(|r| ended(r, Exit::Status(0))).collect());
        assert_eq!(five.stop_order(), Role::STOP_ORDER);
        assert!(five.unclean_ends().is_empty());
        five[Role::Sensors].runs[0].exit = Exit::Signal(9);
        assert_eq!(five.unclean_ends(), ["sensors exited with status signal 9"]);
        assert!(!five.all_up());
        for role in Role::START_ORDER {
            five[role].became_ready(at(0));
        }
        five[Role::Monitor].give_up();
        five[Role::Monitor].ready = false;
        assert!(five.all_up(), "a monitor gone for good holds nothing up");
        five[Role::Plant].died(at(10));
        assert!(!five.all_up(), "a dead plant does");
        let seven = Processes::new(
            Role::BRIDGES.into_iter().chain(Role::START_ORDER).map(|r| ended(r, Exit::Status(0))).collect(),
        );
        let order = seven.stop_order();
        assert_eq!(&order[4..], [Role::Bridge, Role::BridgeRemote, Role::Monitor], "bridges after the stages");
    }
}
