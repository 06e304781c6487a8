//! What the processes say: each event line is filed (readiness, the plant's start and pauses,
//! stalls and link losses into the fault ledger, statuses to the live view, reports for the
//! summary); the end of a process's output is passed on to the supervision loop.

use std::time::{Duration, Instant};

use crate::contract::clock::now_ns;
use crate::contract::protocol::ChildEvent;
use crate::contract::role::Role;
use crate::launcher::child::{ChildLine, Line};
use crate::launcher::inject::DetectedBy;
use crate::launcher::outcome::Exit;

use super::{Event, Supervisor};

/// How long a process whose output ended may take to be reapable before its death is handled
/// anyway (its exit status then unknown).
pub(super) const REAP_WAIT: Duration = Duration::from_secs(2);
/// How long the output of a process that exited may stay open before its death is handled
/// without waiting for it to close.
const OUTPUT_GRACE: Duration = Duration::from_secs(2);

impl Supervisor<'_> {
    /// Reaps `role`, waiting up to `limit` (where nothing else is to go on meanwhile).
    pub(super) fn reap_within(&mut self, role: Role, limit: Duration) {
        let until = Instant::now() + limit;
        while !self.processes[role].try_reap() && Instant::now() < until {
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// The processes that exited whose output has stayed open for [`OUTPUT_GRACE`] since: a
    /// process they started holds it. (Their last lines, the report among them, come before
    /// their output closes, so a process that closes it is waited for.)
    pub(super) fn exited_with_output_held(&mut self) -> Vec<Role> {
        let now = Instant::now();
        let mut held = vec![];
        for p in self.processes.iter_mut().filter(|p| !p.end_seen) {
            if !p.runs.last().is_some_and(|r| r.exit == Exit::Running && r.has_exited()) {
                continue;
            }
            if now.duration_since(*p.exited_seen_at.get_or_insert(now)) >= OUTPUT_GRACE {
                held.push(p.role);
            }
        }
        held
    }

    /// `role`'s output ended: its death is handled once it is reaped (or waited for long enough).
    pub(super) fn closed(&mut self, role: Role) {
        if !std::mem::replace(&mut self.processes[role].end_seen, true) {
            self.closing.push((role, Instant::now() + REAP_WAIT));
        }
    }

    /// The processes whose output ended that are reaped now, or that were waited for long
    /// enough: their deaths are to be handled. A process that exited while its output stays open
    /// (held by a process it started) is among them too.
    pub(super) fn reaped(&mut self) -> Vec<Role> {
        for role in self.exited_with_output_held() {
            self.closed(role);
        }
        let now = Instant::now();
        let processes = &mut self.processes;
        let mut done = vec![];
        self.closing.retain(|&(role, until)| {
            let gone = processes[role].try_reap() || now >= until;
            if gone {
                done.push(role);
            }
            !gone
        });
        done
    }

    /// Files an event; returns the process whose output ended.
    pub(super) fn handle(&mut self, event: Event) -> Option<Role> {
        let ChildLine { role, incarnation, line } = match event {
            Event::Child(line) => *line,
            Event::Cleaned { role, removed } => {
                self.cleaned(role, removed);
                return None;
            }
        };
        if let Line::Unreadable { line, error } = &line {
            tell!("looplab: {role} wrote a line that is not an event ({error}): {line}");
            self.note(now_ns(), format!("{role} wrote a line that is not an event ({error})"));
            return None;
        }
        if incarnation != self.processes[role].incarnation() {
            // A report from an incarnation that has since been replaced.
            match line {
                Line::Event(ChildEvent::StageReport(r)) => {
                    self.reports.stages.entry(role).or_default().insert(incarnation, r);
                }
                Line::Event(ChildEvent::BridgeReport(r)) => {
                    self.reports.bridges.entry(role).or_default().insert(incarnation, r);
                }
                _ => {}
            }
            return None;
        }
        let event = match line {
            Line::Event(event) => event,
            Line::Unreadable { .. } => return None,
            // Its output ends when it exits; the caller reaps it.
            Line::Closed => return Some(role),
        };
        match event {
            ChildEvent::Ready => self.ready(role, incarnation),
            ChildEvent::Started { start_ns, .. } => {
                self.log.plant_start_ns.get_or_insert(start_ns);
                if let Some(probe) = &mut self.probe {
                    probe.begin(start_ns);
                }
            }
            ChildEvent::Paused { k } => self.pause_at(k),
            ChildEvent::Stall { process, since_ns, detected_ns } => {
                // A stage lost for good is dead, not stalled: its death is on the timeline.
                if process.parse::<Role>().is_ok_and(|r| self.processes[r].lost) {
                    return None;
                }
                if let Ok(stalled) = process.parse::<Role>() {
                    self.processes[stalled].stalled_since_ns = Some(since_ns.min(detected_ns));
                    self.faults.detect_stall(stalled, since_ns, detected_ns);
                    // A stage across the link waits on the link: a cut stalls it.
                    if self.config.hosts.is_remote(stalled) {
                        self.faults.detect_cut(since_ns, detected_ns);
                    }
                }
                let waited = (detected_ns.saturating_sub(since_ns)) as f64 / 1e6;
                self.note(detected_ns, format!("{process} stalled: its input has waited {waited:.1} ms"));
            }
            ChildEvent::Resumed { process, at_ns } => {
                if let Ok(resumed) = process.parse::<Role>() {
                    self.processes[resumed].stalled_since_ns = None;
                    self.faults.resume(resumed, at_ns);
                    if self.config.hosts.is_remote(resumed) {
                        self.faults.resume_cut(at_ns);
                    }
                }
                self.note(at_ns, format!("{process} handles its input again"));
            }
            ChildEvent::LinkLost { at_ns } => {
                for bridge in Role::BRIDGES {
                    self.faults.detect(bridge, DetectedBy::LinkLease, at_ns);
                }
                self.note(at_ns, "link to the other host lost".into());
            }
            ChildEvent::LinkBack { at_ns } => {
                for bridge in Role::BRIDGES {
                    self.faults.resume(bridge, at_ns);
                }
                self.note(at_ns, "link to the other host back".into());
            }
            ChildEvent::Alive => self.monitor_heard_ns = now_ns(),
            ChildEvent::Status(status) => {
                self.monitor_heard_ns = now_ns();
                self.monitor_written = status.loops_written;
                self.live.status(status);
            }
            ChildEvent::PlantReport(r) => self.reports.plant = Some(r),
            ChildEvent::MonitorReport(r) => self.reports.monitor = Some(*r),
            ChildEvent::StageReport(r) => {
                self.reports.stages.entry(role).or_default().insert(incarnation, r);
            }
            ChildEvent::BridgeReport(r) => {
                self.reports.bridges.entry(role).or_default().insert(incarnation, r);
            }
        }
        None
    }

    /// `role`'s running incarnation is ready; a restarted one ends its restart (the plant is
    /// told to start again).
    fn ready(&mut self, role: Role, incarnation: u32) {
        let ns = now_ns();
        self.processes[role].became_ready(ns);
        // It set its own priority and locked its memory before it said ready: read back what it got.
        if role.in_loop()
            && self.config.realtime.any()
            && let Some(pid) = self.processes[role].row().pid
            && let Ok(scheduling) = crate::runtime::stage::realtime::read(pid)
        {
            self.log.scheduling.insert((role, incarnation), scheduling);
        }
        if incarnation == 0 {
            return;
        }
        if let Some(r) = self.latest_restart(role) {
            r.ready_ns.get_or_insert(ns);
        }
        self.faults.restarted(role, ns);
        self.note(ns, format!("{role} ready again"));
        if role == Role::Plant {
            if !self.processes[role].write_line("start") {
                self.note(ns, "cannot tell the restarted plant to start".into());
            }
            // A restarted plant hears again of a stage lost before.
            self.tell_plant_lost();
        }
    }
}
