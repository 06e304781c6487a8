//! Deaths and restarts: a process whose output ended either finished the run (the plant), or is
//! restarted once its resources are cleaned up and its backoff is over (`launcher::restart`
//! decides), or is gone, which ends the run unless its `on_death` says the run goes on (the
//! monitor's default; a stage's with `on_death = "continue"`).

use crate::config::faults::OnDeath;
use crate::config::launch::Mode;
use crate::contract::clock::now_ns;
use crate::contract::protocol::PlantReport;
use crate::contract::role::Role;
use crate::launcher::inject::{self, DetectedBy};
use crate::launcher::outcome::Outcome;
use crate::launcher::restart::{self, Decision, RestartRecord};
use crate::launcher::summary::LostStage;

use super::Supervisor;

impl Supervisor<'_> {
    /// A process's output ended during the run: the run completed (the plant finished), or the
    /// process is restarted, or the run fails. Returns the outcome if the run is over.
    pub(super) fn ended(&mut self, role: Role) -> Option<Outcome> {
        let ns = now_ns();
        self.note_left_running(role);
        let mut death = self.processes[role].died(ns);
        if role == Role::Plant {
            // A pause belongs to the plant that asked; its successor asks again at the same tick.
            self.paused = false;
        }
        if role == Role::Plant
            && death.clean
            && let Some(report) = &self.reports.plant
        {
            return Some(plant_finished(report, self.config.supervision.lockstep_stall_s));
        }
        let hung = self.processes[role].hung_s.is_some();
        // A hang is a failure of its own: three in a row are a crash loop, however long each ran.
        let last_words = if hung { ": hung".to_owned() } else { self.last_words(role) };
        let exit = if hung {
            self.processes[role].exit_text()
        } else if death.clean {
            // A loop process runs until it is stopped: ending by itself mid-run, even with status
            // 0, it failed (and `on-failure` restarts it).
            death.clean = false;
            format!("{} before the run's end", self.processes[role].exit_text())
        } else {
            format!("{}{last_words}", self.processes[role].exit_text())
        };
        let healthy = !hung && death.ran_s.is_some_and(|s| s >= self.config.supervision.backoff_reset_s);
        death.same_failure_in_a_row = self.processes[role].same_failure_in_a_row(&last_words, healthy);
        self.faults.detect(role, DetectedBy::ProcessExited, ns);
        // Free what the dead process held in shared memory before its successor opens it, on the
        // clean-up thread.
        if let Some(cleaner) = &self.cleaner {
            let _ = cleaner.send(role);
        }
        let decision = restart::decide(&self.processes[role].policy, self.config.supervision.backoff_reset_s, death);
        if let Decision::Restart { backoff, quick_restarts } = decision {
            let process = &mut self.processes[role];
            process.restart_after(backoff, quick_restarts, ns);
            self.log.restarts.push(RestartRecord {
                process: role,
                incarnation: process.runs.len() as u32,
                backoff,
                died_ns: ns,
                cleaned_ns: None,
                spawned_ns: None,
                ready_ns: None,
            });
            self.note(
                ns,
                format!("{exit}; restart after its clean-up and {:.0} ms of backoff", backoff.as_secs_f64() * 1e3),
            );
            return None;
        }
        let why = format!("{exit}; {}", decision.refusal().expect("a refusal says why"));
        self.processes[role].gone = true;
        if self.processes[role].policy.on_death == OnDeath::End {
            self.note(ns, why.clone());
            return Some(Outcome::Failed(format!("{why}; {}", self.see_log(role))));
        }
        if role == Role::Monitor {
            // The loop goes on without its recorder; the report says which loops have none.
            self.note(ns, why);
            return None;
        }
        // on_death = continue: the loop runs on to its planned end without the stage, under the
        // plant's fail-safe; the summary and the report say it was lost.
        self.note(ns, format!("{why}; the run goes on without it (on_death = continue)"));
        self.processes[role].lost = true;
        let at_ms = self.log.since_start_ms(ns);
        let at_loop = match self.config.mode {
            Mode::Lockstep => self.last_pause.filter(|_| self.paused),
            Mode::Realtime => self.log.plant_start_ns.map(|start| inject::loop_at(ns, start, self.config.period_ns())),
        };
        let why = format!("{why}; {}", self.see_log(role));
        self.log.lost.push(LostStage { process: role, at_ms, at_loop, why });
        self.tell_plant_lost();
        None
    }

    /// Kills each process stuck inside its own code: stalled for `hang_timeout_s`, and not
    /// because a fault stopped it or the loop is held for one. Its death then goes the way of
    /// any other (its restart policy), so a run never hangs on a model that never returns.
    pub(super) fn kill_hung(&mut self, now: u64) {
        let hang_s = self.config.supervision.hang_timeout_s;
        for role in self.config.hosts.processes() {
            let p = &self.processes[role];
            let Some(since) = p.stalled_since_ns else { continue };
            let held = p.stopped || self.paused || (self.config.hosts.is_remote(role) && self.faults.cut_open());
            // A delay fault holds each of its answers that long (real time).
            let delayed_s = self.config.faults.iter().filter(|f| inject::target(f) == role).filter_map(|f| f.delay_s);
            let limit_s = hang_s + delayed_s.fold(0.0, f64::max);
            if held
                || p.hung_s.is_some()
                || !p.ready
                || !p.running()
                || (now.saturating_sub(since) as f64) < limit_s * 1e9
            {
                continue;
            }
            let stalled_s = now.saturating_sub(since) as f64 * 1e-9;
            // Still stalled, as the monitor sees it, until the next incarnation answers: its hang
            // clock starts again once it is ready.
            self.processes[role].hung_s = Some(stalled_s);
            self.processes[role].signal(libc::SIGKILL);
            self.note(
                now,
                format!(
                    "{role} hung: stalled {stalled_s:.1} s inside its own code \
                     (supervision.hang_timeout_s = {hang_s} s); killed it"
                ),
            );
        }
    }

    /// Says what `role`'s last incarnation left running in its session when it exited
    /// (killed then), on the timeline and in the summary's notes.
    pub(super) fn note_left_running(&mut self, role: Role) {
        let Some(run) = self.processes[role].runs.last_mut() else { return };
        let left = std::mem::take(&mut run.left_running);
        if left.is_empty() {
            return;
        }
        let line = format!(
            "{role} exited leaving {} process(es) it started running: {}; killed them",
            left.len(),
            left.join(", ")
        );
        self.note(now_ns(), line.clone());
        self.left_running.push(line);
    }

    /// Lockstep: a stage was lost, so command k will never come; the plant goes on without
    /// waiting for it, applying `on_stale` (real time: its command timeout does that already).
    pub(super) fn tell_plant_lost(&mut self) {
        if self.config.mode == Mode::Lockstep
            && !self.log.lost.is_empty()
            && !self.processes[Role::Plant].write_line("lost")
        {
            self.note(now_ns(), "cannot tell the plant that a stage was lost".into());
        }
    }

    /// The newest restart of `role`, the one under way.
    pub(super) fn latest_restart(&mut self, role: Role) -> Option<&mut RestartRecord> {
        self.log.restarts.iter_mut().rev().find(|r| r.process == role)
    }

    /// The clean-up after a death of `role` is done: its restart may go ahead.
    pub(super) fn cleaned(&mut self, role: Role, removed: u64) {
        let ns = now_ns();
        self.removed_dead_nodes += removed;
        if self.processes[role].cleaned() {
            if let Some(r) = self.latest_restart(role) {
                r.cleaned_ns = Some(ns);
            }
            self.note(ns, format!("{role}: its iceoryx2 resources removed ({removed} dead node(s))"));
        }
    }

    /// Starts the restarts that are due at `now` (ns). Returns the outcome if one could not start
    /// and the run cannot go on.
    pub(super) fn start_due_restarts(&mut self, now: u64) -> Option<Outcome> {
        for role in self.config.hosts.processes() {
            if !self.processes[role].restart_due(now) {
                continue;
            }
            match self.spawn(role) {
                Ok(()) => {
                    let ns = now_ns();
                    let n = self.processes[role].incarnation();
                    if let Some(r) = self.latest_restart(role) {
                        r.spawned_ns = Some(ns);
                    }
                    self.note(ns, format!("{role} restarted (incarnation {n})"));
                }
                Err(e) => {
                    self.processes[role].give_up();
                    let why = format!("{role} could not be restarted: {e:#}");
                    self.note(now_ns(), why.clone());
                    if role != Role::Monitor {
                        return Some(Outcome::Failed(why));
                    }
                }
            }
        }
        None
    }
}

/// The outcome of a plant that exited cleanly with its report: it finished, unless it stalled.
fn plant_finished(report: &PlantReport, lockstep_stall_s: f64) -> Outcome {
    match report.stalled_at {
        Some(k) => Outcome::Failed(format!(
            "the loop stalled at loop {k}: no command within {lockstep_stall_s} s (supervision.lockstep_stall_s)"
        )),
        None => Outcome::Completed,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plant_that_finished_completes_the_run_unless_its_loop_stalled() {
        let finished = PlantReport { loops: 2000, ..Default::default() };
        assert_eq!(plant_finished(&finished, 10.0), Outcome::Completed);
        let stalled = PlantReport { loops: 700, stalled_at: Some(700), ..Default::default() };
        assert_eq!(
            plant_finished(&stalled, 2.5),
            Outcome::Failed(
                "the loop stalled at loop 700: no command within 2.5 s (supervision.lockstep_stall_s)".into()
            )
        );
    }
}
