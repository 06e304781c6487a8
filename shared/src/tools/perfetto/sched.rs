//! The kernel's scheduler events of a `--trace-sched` run (`sched.trace`, as tracefs printed them)
//! as Perfetto's own recorder writes them, so that the viewer draws its CPU tracks (who ran on
//! each CPU, when) and each thread's states: `TracePacket.ftrace_events`, an `FtraceEventBundle`
//! per CPU and up to `BUNDLE` events, each an `FtraceEvent` with a `sched_switch` or
//! `sched_wakeup`.
//!
//! Field numbers from Perfetto's protos (github.com/google/perfetto, protos/perfetto/trace/):
//! trace_packet.proto (`ftrace_events` = 1, `system_info` = 45), ftrace/ftrace_event_bundle.proto
//! (`FtraceEventBundle`), ftrace/ftrace_event.proto (`FtraceEvent`), ftrace/sched.proto
//! (`SchedSwitchFtraceEvent`, `SchedWakeupFtraceEvent`), ../common/system_info.proto (`SystemInfo`,
//! `Utsname`).
//!
//! Time: tracefs stamped the events on its `mono` clock (CLOCK_MONOTONIC, the loop's stamps'
//! clock), printed to the µs, so each is written as that µs in ns. Perfetto reads an ftrace bundle
//! without `ftrace_clock` as BOOTTIME (there is no FtraceClock for MONOTONIC), so the trace's clock
//! snapshot, with these events, gives BOOTTIME the same reading as MONOTONIC (`super::encode`):
//! in this file BOOTTIME is only a name for the MONOTONIC times the events carry, and they land on
//! the loop's slices unshifted.
//!
//! `prev_state`: the kernel's number, rebuilt from the letters it printed. Perfetto decodes it by
//! the kernel's version (trace_processor's `TaskState::FromRawPrevState`: 4.14 and later
//! TASK_REPORT's bits, S 0x1 … I 0x80, preempted `+` 0x100; before, the scheduler's own bits, and
//! 4.4's when no version is known), so the run's kernel release (summary.json's `machine.kernel`)
//! is written in a `SystemInfo` packet and the number follows it.
//!
//! What is kept: every sched_switch (who ran: the CPU tracks), and the wake-ups of the run's own
//! processes (each pid of each incarnation; every wake-up when the run has none, an in-process
//! run). Wake-ups of other tasks are a third of a busy machine's events and say only when
//! something else became runnable: they are left out.

use std::collections::{BTreeMap, HashSet};

use super::wire;
use crate::launcher::sched_trace::{field, parse_line};

/// Events per bundle (Perfetto's recorder writes one per kernel page, some tens).
const BUNDLE: usize = 512;

mod number {
    /// TracePacket.ftrace_events (FtraceEventBundle).
    pub const FTRACE_EVENTS: u32 = 1;
    /// TracePacket.system_info (SystemInfo).
    pub const SYSTEM_INFO: u32 = 45;
    /// SystemInfo.utsname (Utsname).
    pub const UTSNAME: u32 = 1;
    /// Utsname.sysname, Utsname.release (string).
    pub const SYSNAME: u32 = 1;
    pub const RELEASE: u32 = 3;
    /// FtraceEventBundle.cpu (uint32), .event (repeated FtraceEvent), .lost_events (bool).
    pub const BUNDLE_CPU: u32 = 1;
    pub const BUNDLE_EVENT: u32 = 2;
    pub const BUNDLE_LOST: u32 = 3;
    /// FtraceEvent.timestamp (uint64), .pid (uint32: the task that was running),
    /// .sched_switch (SchedSwitchFtraceEvent), .sched_wakeup (SchedWakeupFtraceEvent).
    pub const EVENT_TIMESTAMP: u32 = 1;
    pub const EVENT_PID: u32 = 2;
    pub const EVENT_SCHED_SWITCH: u32 = 4;
    pub const EVENT_SCHED_WAKEUP: u32 = 17;
    /// SchedSwitchFtraceEvent: prev_comm, prev_pid, prev_prio, prev_state (int64), next_comm,
    /// next_pid, next_prio.
    pub const PREV_COMM: u32 = 1;
    pub const PREV_PID: u32 = 2;
    pub const PREV_PRIO: u32 = 3;
    pub const PREV_STATE: u32 = 4;
    pub const NEXT_COMM: u32 = 5;
    pub const NEXT_PID: u32 = 6;
    pub const NEXT_PRIO: u32 = 7;
    /// SchedWakeupFtraceEvent: comm, pid, prio, target_cpu.
    pub const WAKEUP_COMM: u32 = 1;
    pub const WAKEUP_PID: u32 = 2;
    pub const WAKEUP_PRIO: u32 = 3;
    pub const WAKEUP_TARGET_CPU: u32 = 5;
}

/// One event, its strings borrowed from the trace's text.
enum Kind<'a> {
    Switch {
        prev_comm: &'a str,
        prev_pid: u32,
        prev_prio: u32,
        prev_state: u64,
        next_comm: &'a str,
        next_pid: u32,
        next_prio: u32,
    },
    Wakeup {
        comm: &'a str,
        pid: u32,
        prio: u32,
        target_cpu: u32,
    },
}

struct Event<'a> {
    ns: u64,
    /// The task that was running when it happened (the line's `<comm>-<pid>`).
    pid: u32,
    kind: Kind<'a>,
}

/// The scheduler events to write, per CPU in time order.
pub struct SchedEvents<'a> {
    cpus: BTreeMap<u32, Vec<Event<'a>>>,
    /// The kernel could not keep some events (its buffer was full).
    lost: bool,
    /// The kernel's release, when its version can be read from it: (release, major, minor).
    kernel: Option<(&'a str, u32, u32)>,
    pub switches: usize,
    pub wakeups: usize,
    /// Wake-ups of tasks not of the run, left out.
    pub wakeups_left_out: usize,
}

/// The version Perfetto reads from a kernel release ("6.1.0-13-amd64": 6.1), as
/// trace_processor's `SystemInfoTracker::SetKernelVersion` does.
fn kernel_version(release: &str) -> Option<(u32, u32)> {
    let mut parts = release.splitn(3, '.');
    let major = parts.next()?.parse().ok()?;
    let minor = parts.next()?.parse().ok()?;
    Some((major, minor))
}

/// `prev_state` as the kernel of `version` wrote it, from the letters it printed ("S", "R+",
/// "D|K"). 4.14 and later: TASK_REPORT's bits and TASK_REPORT_MAX (0x100) for a preempted task;
/// before (and with no version, as Perfetto then assumes 4.4): the scheduler's own bits, TASK_IDLE
/// as D and NOLOAD, preemption 0x800 (0x1000 from 4.8).
fn prev_state(letters: &str, version: Option<(u32, u32)>) -> u64 {
    let modern = version.is_some_and(|v| v >= (4, 14));
    letters
        .chars()
        .map(|c| match (modern, c) {
            (_, 'S') => 0x1,
            (_, 'D') => 0x2,
            (_, 'T') => 0x4,
            (_, 't') => 0x8,
            (_, 'X') => 0x10,
            (_, 'Z') => 0x20,
            (true, 'P') => 0x40,
            (true, 'I') => 0x80,
            (true, '+') => 0x100,
            (false, 'x') => 0x40,
            (false, 'K') => 0x80,
            (false, 'W') => 0x100,
            (false, 'P') => 0x200,
            (false, 'N') => 0x400,
            (false, 'I') => 0x402,
            (false, '+') if version.is_some_and(|v| v >= (4, 8)) => 0x1000,
            (false, '+') => 0x800,
            // R (running: no bit) and the separator.
            _ => 0,
        })
        .fold(0, |state, bit| state | bit)
}

/// The running task's pid from a line's `<comm>-<pid> [cpu]` (a comm may hold '-').
fn running_pid(line: &str) -> Option<u32> {
    let head = line[..line.find("] ")?].rsplit_once('[')?.0.trim_end();
    head.rsplit_once('-')?.1.parse().ok()
}

impl<'a> SchedEvents<'a> {
    /// The events of `text` (sched.trace), keeping the wake-ups of `pids` (all of them when
    /// `pids` is empty); `kernel` is the release the run's kernel gave.
    pub fn parse(text: &'a str, pids: &HashSet<u32>, kernel: &'a str) -> Self {
        let version = kernel_version(kernel);
        let mut events = SchedEvents {
            cpus: BTreeMap::new(),
            lost: false,
            kernel: version.map(|(major, minor)| (kernel, major, minor)),
            switches: 0,
            wakeups: 0,
            wakeups_left_out: 0,
        };
        for line in text.lines() {
            if let Some(entries) = line.strip_prefix("# entries-in-buffer/entries-written: ") {
                let counts: Vec<u64> =
                    entries.split(|c: char| !c.is_ascii_digit()).filter_map(|n| n.parse().ok()).collect();
                events.lost = matches!(counts[..], [kept, written, ..] if written > kept);
                continue;
            }
            let Some((cpu, ns, event, fields)) = parse_line(line) else { continue };
            let Some(pid) = running_pid(line) else { continue };
            let number = |key, next| field(fields, key, next).and_then(|v: &str| v.trim().parse::<u32>().ok());
            let kind = match event {
                "sched_switch" => {
                    let (Some(prev_pid), Some(prev_prio), Some(next_pid), Some(next_prio)) = (
                        number("prev_pid", Some("prev_prio")),
                        number("prev_prio", Some("prev_state")),
                        number("next_pid", Some("next_prio")),
                        number("next_prio", None),
                    ) else {
                        continue;
                    };
                    events.switches += 1;
                    Kind::Switch {
                        prev_comm: field(fields, "prev_comm", Some("prev_pid")).unwrap_or_default(),
                        prev_pid,
                        prev_prio,
                        prev_state: prev_state(field(fields, "prev_state", None).unwrap_or_default(), version),
                        next_comm: field(fields, "next_comm", Some("next_pid")).unwrap_or_default(),
                        next_pid,
                        next_prio,
                    }
                }
                "sched_wakeup" => {
                    let (Some(woken), Some(prio), Some(target_cpu)) =
                        (number("pid", Some("prio")), number("prio", Some("target_cpu")), number("target_cpu", None))
                    else {
                        continue;
                    };
                    if !pids.is_empty() && !pids.contains(&woken) {
                        events.wakeups_left_out += 1;
                        continue;
                    }
                    events.wakeups += 1;
                    let comm = field(fields, "comm", Some("pid")).unwrap_or_default();
                    Kind::Wakeup { comm, pid: woken, prio, target_cpu }
                }
                _ => continue,
            };
            events.cpus.entry(cpu).or_default().push(Event { ns, pid, kind });
        }
        events
    }

    /// Appends the packets (`Trace.packet` = `packet_field`) on packet sequence `sequence`: the
    /// kernel's release, then each CPU's bundles.
    pub fn encode(&self, out: &mut Vec<u8>, packet_field: u32, sequence_field: u32, sequence: u64) {
        use number::*;
        if let Some((release, ..)) = self.kernel {
            wire::message(out, packet_field, |p| {
                wire::uint(p, sequence_field, sequence);
                wire::message(p, SYSTEM_INFO, |s| {
                    wire::message(s, UTSNAME, |u| {
                        wire::bytes(u, SYSNAME, b"Linux");
                        wire::bytes(u, RELEASE, release.as_bytes());
                    });
                });
            });
        }
        for (&cpu, events) in &self.cpus {
            for (i, chunk) in events.chunks(BUNDLE).enumerate() {
                wire::message(out, packet_field, |p| {
                    wire::uint(p, sequence_field, sequence);
                    wire::message(p, FTRACE_EVENTS, |b| {
                        wire::uint(b, BUNDLE_CPU, cpu.into());
                        // Which CPU lost events tracefs does not say: each CPU's first bundle.
                        if i == 0 && self.lost {
                            wire::uint(b, BUNDLE_LOST, 1);
                        }
                        for event in chunk {
                            wire::message(b, BUNDLE_EVENT, |e| {
                                wire::uint(e, EVENT_TIMESTAMP, event.ns);
                                wire::uint(e, EVENT_PID, event.pid.into());
                                match event.kind {
                                    Kind::Switch {
                                        prev_comm,
                                        prev_pid,
                                        prev_prio,
                                        prev_state,
                                        next_comm,
                                        next_pid,
                                        next_prio,
                                    } => wire::message(e, EVENT_SCHED_SWITCH, |s| {
                                        wire::bytes(s, PREV_COMM, prev_comm.as_bytes());
                                        wire::uint(s, PREV_PID, prev_pid.into());
                                        wire::uint(s, PREV_PRIO, prev_prio.into());
                                        wire::uint(s, PREV_STATE, prev_state);
                                        wire::bytes(s, NEXT_COMM, next_comm.as_bytes());
                                        wire::uint(s, NEXT_PID, next_pid.into());
                                        wire::uint(s, NEXT_PRIO, next_prio.into());
                                    }),
                                    Kind::Wakeup { comm, pid, prio, target_cpu } => {
                                        wire::message(e, EVENT_SCHED_WAKEUP, |w| {
                                            wire::bytes(w, WAKEUP_COMM, comm.as_bytes());
                                            wire::uint(w, WAKEUP_PID, pid.into());
                                            wire::uint(w, WAKEUP_PRIO, prio.into());
                                            wire::uint(w, WAKEUP_TARGET_CPU, target_cpu.into());
                                        })
                                    }
                                }
                            });
                        }
                    });
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_kernels_state_letters_are_its_numbers_as_perfetto_decodes_them() {
        let modern = Some((6, 1));
        assert_eq!(prev_state("R", modern), 0);
        assert_eq!(prev_state("R+", modern), 0x100);
        assert_eq!(prev_state("S", modern), 0x1);
        assert_eq!(prev_state("D", modern), 0x2);
        assert_eq!(prev_state("I", modern), 0x80);
        assert_eq!(prev_state("P", modern), 0x40);
        // Before 4.14 (and with no version: Perfetto assumes 4.4).
        assert_eq!(prev_state("D|K", Some((4, 9))), 0x82);
        assert_eq!(prev_state("R+", Some((4, 9))), 0x1000);
        assert_eq!(prev_state("R+", None), 0x800);
        assert_eq!(prev_state("I", None), 0x402);
        assert_eq!(kernel_version("6.18.44-fc-v669"), Some((6, 18)));
        assert_eq!(kernel_version(""), None);
    }

    #[test]
    fn a_comm_may_hold_dashes_and_spaces() {
        assert_eq!(running_pid(" looplab-estimat-200     [000] d..2.   100.000010: sched_wakeup: …"), Some(200));
        assert_eq!(running_pid("            my hog-400   [001] d..2. 1.000000: x: y"), Some(400));
        assert_eq!(running_pid("         my [x]-7-12     [001] d..2. 1.000000: x: y"), Some(12));
    }
}
