//! Why a loop was late: its response time split into parts that add up to it exactly, each
//! part named by what it was, and the largest one the loop's primary cause.
//!
//! The response time of loop k runs from when tick k was due to when command k reached the plant
//! (in lockstep, which has no clock: the end-to-end latency). Its parts, in the order they pass:
//! - the timer: the plant woke after tick k was due; of that, the time the plant sat on the run
//!   queue (its schedstat, `runtime::stage::sched`) is `queued: plant`, the rest `timer` (the OS's own
//!   wake-up, interrupts, and time the hypervisor ran something else);
//! - `compute: plant`: from its wake-up (or the tick's due time, if it woke earlier for a
//!   command) to the state going out (integration and snapshot);
//! - each hop from a writer's publish to its reader's receive: while the reader stage was still
//!   computing an earlier loop (until its last output went out), `compute: <reader>` (of that,
//!   its run-queue wait while computing is `queued: <reader>`); after that, the reader's
//!   run-queue wait is `queued: <reader>`, the rest `transport: <hop>` (the wake-up itself);
//! - each stage's computation: its run-queue wait while computing is `queued: <stage>`, the rest
//!   `compute: <stage>`.
//!
//! A fault whose outage covers the loop takes the blame where the primary part is its process's
//! (`fault: delay controller`); a kill or stop of a loop process takes every loop of its outage
//! (`fault: stop controller`), whatever else was slow in it. A loop whose command never came is `skipped: <stage>` (the first
//! stage whose output is missing), and a tick the plant never woke for is `timer`, unless a fault
//! of that process covers it.

use std::collections::BTreeMap;
use std::fmt;

use crate::config::faults::FaultKind;
use crate::contract::msg::{Header, SchedStamp, Stamp};
use crate::contract::report::HOPS;
use crate::contract::role::{Role, Topic};
use crate::monitor::join::LoopParts;

/// What one part of a loop's response time was.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Cause {
    /// The plant's timer woke it late (and not because it sat on the run queue).
    Timer,
    /// The process was runnable but did not run: another task had its CPU.
    Queued(Role),
    /// The process computed (or slept, or the hypervisor took its CPU while it did).
    Compute(Role),
    /// A hop's own wake-up: index into [`HOPS`].
    Transport(usize),
    /// A fault of the launch file.
    Fault(FaultKind, Role),
    /// No command came: this stage never sent its output for the loop.
    Skipped(Role),
    /// Stamps that do not add up (a stage on another host, whose clock differs).
    Unknown,
}

impl Cause {
    /// The process a part belongs to: the one a fault must be of to take the blame.
    pub fn process(self) -> Option<Role> {
        match self {
            Cause::Timer => Some(Role::Plant),
            Cause::Queued(role) | Cause::Compute(role) | Cause::Skipped(role) | Cause::Fault(_, role) => Some(role),
            Cause::Transport(hop) => Some(Stamp::ALL[HOPS[hop].2].role()),
            Cause::Unknown => None,
        }
    }
}

impl fmt::Display for Cause {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Cause::Timer => f.write_str("timer"),
            Cause::Queued(role) => write!(f, "queued: {role}"),
            Cause::Compute(role) => write!(f, "compute: {role}"),
            Cause::Transport(hop) => {
                let (_, from, to) = HOPS[*hop];
                write!(f, "transport: {}->{}", Stamp::ALL[from].role(), Stamp::ALL[to].role())
            }
            Cause::Fault(kind, role) => write!(f, "fault: {} {role}", <&str>::from(*kind)),
            Cause::Skipped(role) => write!(f, "skipped: {role}"),
            Cause::Unknown => f.write_str("unknown"),
        }
    }
}

/// One part of a loop's response time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Part {
    pub cause: Cause,
    pub ns: u64,
}

/// A late loop explained: its primary cause, how much of the response time that was, and the
/// response time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Explanation {
    pub cause: Cause,
    /// The primary cause's part, ns: of the response time; for a loop a stage skipped, how long
    /// after that loop's input the stage took up its next one. None where nothing was measured.
    pub part_ns: Option<u64>,
    /// From tick k due (lockstep: the state going out) to command k reaching the plant, ns; None
    /// for a loop with no command.
    pub response_ns: Option<u64>,
}

/// Each role's own scheduling stamp in loop k, from the message it sent (the plant's: the loop
/// record, stamped when the command came).
fn sched_of(parts: &LoopParts, role: Role) -> SchedStamp {
    let topic = if role == Role::Plant { Topic::Loop } else { role.output().expect("a loop role") };
    parts.header(topic).map_or_else(SchedStamp::default, |h| h.sched)
}

/// `span` split into the run-queue wait `queued` (at most all of it) and the rest.
fn split(out: &mut Vec<Part>, span: u64, queued: u32, role: Role, rest: Cause) {
    let queued = u64::from(queued).min(span);
    out.push(Part { cause: Cause::Queued(role), ns: queued });
    out.push(Part { cause: rest, ns: span - queued });
}

/// Loop k's response time in parts, in the order they pass; they add up to the response time
/// exactly. `before(stage)` is the stage's last output of an earlier loop. A command that never
/// reached the plant (a newer one replaced it there) gives the parts up to its sending. None
/// without a command or with stamps out of order (another host's clock).
pub fn decompose(parts: &LoopParts, before: impl Fn(Role) -> Option<Header>) -> Option<Vec<Part>> {
    let (trace, last) = match (&parts.record, &parts.command) {
        (Some(record), _) => (record.header.trace, Stamp::PlantReceive.index()),
        (None, Some(command)) => (command.header.trace, Stamp::ControllerPublish.index()),
        (None, None) => return None,
    };
    let stamps = trace.stamps();
    if stamps[..=last].windows(2).any(|w| w[0] > w[1]) || stamps[0] == 0 {
        return None;
    }
    let mut out = Vec::with_capacity(2 * HOPS.len() + 3);
    // The tick's timing, where the state of this very loop went out on the plant's clock.
    if let Some(state) = &parts.state {
        let timing = state.timing;
        // A plant that woke for a command just before the tick was due handles the tick in the
        // same wake-up: it woke in time.
        let woke = timing.wake_ns.max(timing.scheduled_ns);
        if timing.scheduled_ns > 0 && woke <= stamps[0] {
            let sched = state.header.sched;
            split(&mut out, woke - timing.scheduled_ns, sched.queued_ns, Role::Plant, Cause::Timer);
            out.push(Part { cause: Cause::Compute(Role::Plant), ns: stamps[0] - woke });
        }
    }
    for (hop, &(_, from, to)) in HOPS.iter().enumerate().filter(|(_, (_, _, to))| *to <= last) {
        let span = stamps[to] - stamps[from];
        let reader = Stamp::ALL[to].role();
        if Stamp::ALL[from].role() == reader {
            // A stage's computation.
            split(&mut out, span, sched_of(parts, reader).compute_queued_ns, reader, Cause::Compute(reader));
        } else {
            // A stage still busy with an earlier loop when this input went out.
            let earlier = Stamp::published_by(reader).filter(|_| reader != Role::Plant).and_then(|published| {
                before(reader).map(|h| (h.trace.get(published).saturating_sub(stamps[from]).min(span), h.sched))
            });
            let busy = match earlier {
                Some((busy, sched)) if busy > 0 => {
                    split(&mut out, busy, sched.compute_queued_ns, reader, Cause::Compute(reader));
                    busy
                }
                _ => 0,
            };
            split(&mut out, span - busy, sched_of(parts, reader).queued_ns, reader, Cause::Transport(hop));
        }
    }
    Some(out)
}

/// The parts by cause, largest first (ties in [`Cause`] order).
pub fn by_cause(parts: &[Part]) -> Vec<Part> {
    let mut totals: BTreeMap<Cause, u64> = BTreeMap::new();
    for part in parts {
        *totals.entry(part.cause).or_default() += part.ns;
    }
    let mut out: Vec<Part> = totals.into_iter().map(|(cause, ns)| Part { cause, ns }).collect();
    out.sort_by(|a, b| b.ns.cmp(&a.ns).then(a.cause.cmp(&b.cause)));
    out
}

/// Explains loop k. `fault_of(role)` is the fault whose outage covers loop k and is of `role`,
/// if any: it takes the blame where the primary part is that process's, except that a kill or
/// stop of a loop process takes it for every loop its outage covers (`outage`: no command can
/// pass through a process that is not running). `before(stage)` and `after(stage)` are the
/// stage's last output of an earlier loop and first output of a later one.
pub fn explain(
    parts: &LoopParts,
    outage: Option<(FaultKind, Role)>,
    fault_of: impl Fn(Role) -> Option<FaultKind>,
    before: impl Fn(Role) -> Option<Header>,
    after: impl Fn(Role) -> Option<Header>,
) -> Explanation {
    let blamed = |cause: Cause| match outage
        .or_else(|| cause.process().and_then(|role| fault_of(role).map(|kind| (kind, role))))
    {
        Some((kind, role)) => Cause::Fault(kind, role),
        None => cause,
    };
    let Some(decomposed) = decompose(parts, &before) else {
        let (cause, part_ns) = match (&parts.state, &parts.record) {
            // No tick: the plant did not wake for it.
            (None, None) => (Cause::Timer, None),
            (Some(_), None) => skipped(parts, before, after),
            (_, Some(_)) => (Cause::Unknown, None),
        };
        return Explanation { cause: blamed(cause), part_ns, response_ns: None };
    };
    let response_ns = parts.record.is_some().then(|| decomposed.iter().map(|p| p.ns).sum());
    let primary = by_cause(&decomposed)[0];
    Explanation { cause: blamed(primary.cause), part_ns: Some(primary.ns), response_ns }
}

/// A loop whose command never came: the first stage whose output is missing skipped it. From
/// this loop's input going out to the stage taking up its next input (`away`), it was either
/// still computing an earlier loop (`compute`, or `queued` if it mostly sat on the run queue
/// meanwhile), or on the run queue before that next input (`queued`), whichever took most of
/// that time; else `skipped` (asleep or stopped).
fn skipped(
    parts: &LoopParts,
    before: impl Fn(Role) -> Option<Header>,
    after: impl Fn(Role) -> Option<Header>,
) -> (Cause, Option<u64>) {
    let Some(stage) = Role::STAGES.into_iter().find(|stage| !parts.has(stage.output().expect("a stage has an output")))
    else {
        return (Cause::Unknown, None);
    };
    let input = stage.input().expect("a stage has an input");
    let Some(sent) = parts.header(input).map(|h| h.trace.get(Stamp::sent_on(input))).filter(|&ns| ns > 0) else {
        return (Cause::Skipped(stage), None);
    };
    let (received, published) =
        (Stamp::received_by(stage).expect("a stage"), Stamp::published_by(stage).expect("a stage"));
    let (before, after) = (before(stage), after(stage));
    let away = after.map(|h| h.trace.get(received).saturating_sub(sent));
    // Still computing an earlier loop when this one's input went out.
    if let Some(before) = before {
        let busy = before.trace.get(published).saturating_sub(sent).min(away.unwrap_or(u64::MAX));
        if busy > 0 && away.is_none_or(|away| 2 * busy >= away) {
            let computing = before.trace.between_ns(received, published);
            let cause = if 2 * u64::from(before.sched.compute_queued_ns) >= computing {
                Cause::Queued(stage)
            } else {
                Cause::Compute(stage)
            };
            return (cause, Some(busy));
        }
    }
    let Some((away, after)) = away.zip(after).filter(|(away, _)| *away > 0) else {
        return (Cause::Skipped(stage), None);
    };
    let queued = u64::from(after.sched.queued_ns).min(away);
    if 2 * queued >= away { (Cause::Queued(stage), Some(queued)) } else { (Cause::Skipped(stage), Some(away)) }
}

#[cfg(test)]
#[path = "cause_tests.rs"]
mod tests;
