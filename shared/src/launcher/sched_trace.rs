//! `--trace-sched`: the kernel's scheduler events for the run (sched_switch, sched_wakeup), from
//! a tracefs instance of the run's own (`instances/looplab_<run id>`, so that no other tracing on
//! the machine is touched), timestamped on CLOCK_MONOTONIC as the loop's stamps are. The trace is
//! kept in the run folder (`sched.trace`, as the kernel prints it), and every loop whose cause is
//! `queued: <role>` gets the task that ran on that process's CPU while it waited: who took it.
//!
//! It needs root or CAP_SYS_ADMIN (tracefs, mounted at /sys/kernel/tracing if it is not); without,
//! the run goes on untraced and one line says why.

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use crate::contract::role::Role;
use crate::contract::run_format::files;
use crate::launcher::summary::{SchedTraceReport, Summary};
use anyhow::{Context as _, Result};

/// Where tracefs lives.
pub const TRACEFS: &str = "/sys/kernel/tracing";

/// The trace file in the run folder.
pub const TRACE_FILE: &str = "sched.trace";

/// A tracefs instance recording the scheduler's events; removed when dropped.
pub struct SchedTrace {
    instance: PathBuf,
}

impl SchedTrace {
    /// Starts recording into a new instance under `tracefs` (mounting it if it is not), with
    /// room for about `duration_s` of events; or says in one line why it cannot.
    pub fn start(tracefs: &Path, run_id: &str, duration_s: f64) -> Result<Self, String> {
        let why = |what: &str, e: std::io::Error| {
            format!(
                "--trace-sched: no scheduler trace, {what} {} ({e}): it needs root or CAP_SYS_ADMIN; the run went on \
                 without it",
                tracefs.display()
            )
        };
        if !tracefs.join("instances").is_dir() {
            mount_tracefs(tracefs).map_err(|e| why("cannot mount tracefs at", e))?;
        }
        let instance = tracefs.join("instances").join(format!("looplab_{run_id}"));
        std::fs::create_dir(&instance).map_err(|e| why("cannot make an instance in", e))?;
        let trace = SchedTrace { instance };
        // A busy machine switches tasks tens of thousands of times a second: 4 MB a second a CPU,
        // at most 256 MB a CPU (events past it are dropped, and counted).
        let kb = ((duration_s + 2.0) * 4096.0).clamp(16_384.0, 262_144.0) as u64;
        let settings = [
            ("trace_clock", "mono".to_string()),
            ("buffer_size_kb", kb.to_string()),
            ("options/overwrite", "0".into()),
            ("events/sched/sched_switch/enable", "1".into()),
            ("events/sched/sched_wakeup/enable", "1".into()),
            ("tracing_on", "1".into()),
        ];
        for (file, value) in settings {
            std::fs::write(trace.instance.join(file), value).map_err(|e| why(&format!("cannot set {file} in"), e))?;
        }
        Ok(trace)
    }

    /// Stops recording, keeps the trace as `sched.trace` in `run_dir` and reads it back. The
    /// instance is removed.
    pub fn finish(self, run_dir: &Path) -> Result<Trace> {
        std::fs::write(self.instance.join("tracing_on"), "0").context("stop the scheduler trace")?;
        let text = std::fs::read_to_string(self.instance.join("trace")).context("read the scheduler trace")?;
        crate::launcher::write_atomically(&run_dir.join(TRACE_FILE), &text)?;
        Ok(Trace::parse(&text))
    }
}

impl Drop for SchedTrace {
    fn drop(&mut self) {
        let _ = std::fs::write(self.instance.join("tracing_on"), "0");
        let _ = std::fs::remove_dir(&self.instance);
    }
}

fn mount_tracefs(at: &Path) -> std::io::Result<()> {
    use std::os::unix::ffi::OsStrExt;
    let target = std::ffi::CString::new(at.as_os_str().as_bytes())?;
    // SAFETY: NUL-terminated strings that outlive the call; no mount data.
    let done = unsafe { libc::mount(c"nodev".as_ptr(), target.as_ptr(), c"tracefs".as_ptr(), 0, std::ptr::null()) };
    if done == 0 { Ok(()) } else { Err(std::io::Error::last_os_error()) }
}

/// A task as the scheduler names it.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct Task {
    pub comm: String,
    pub pid: u32,
    /// The kernel's priority: below 100 a real-time one (SCHED_FIFO/RR 99 − prio), else nice
    /// prio − 120.
    pub prio: u32,
}

impl fmt::Display for Task {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.prio {
            prio if prio < 100 => write!(f, "{} (pid {}, real-time priority {})", self.comm, self.pid, 99 - prio),
            prio => write!(f, "{} (pid {}, nice {})", self.comm, self.pid, prio as i64 - 120),
        }
    }
}

/// The scheduler's events, as intervals.
#[derive(Debug, Default)]
pub struct Trace {
    /// Per CPU, who ran from when to when (ns, CLOCK_MONOTONIC), in time order: each switch says
    /// who ran until then (its `prev`), since the CPU's last switch or, if later, since that task
    /// was woken there (a CPU idle before: the switch from idle is not always in the trace).
    runs: BTreeMap<u32, Vec<(u64, u64, Task)>>,
    /// Per task id, when it was runnable but not running: (from, to, CPU).
    waits: BTreeMap<u32, Vec<(u64, u64, u32)>>,
    /// Events the kernel could not keep (its buffer was full).
    pub lost_events: u64,
    /// The first and last event, ns.
    pub span: Option<(u64, u64)>,
}

/// One line of the trace: (CPU, ns, event, its fields).
pub(crate) fn parse_line(line: &str) -> Option<(u32, u64, &str, &str)> {
    // "<comm>-<pid> [<cpu>] <flags> <secs>.<µs>: <event>: <fields>"; a comm may hold anything.
    let open = line.find("] ")?;
    let cpu = line[..open].rsplit('[').next()?.trim().parse().ok()?;
    let mut rest = line[open + 2..].split_whitespace();
    let _flags = rest.next()?;
    let stamp = rest.next()?.strip_suffix(':')?;
    let (secs, micros) = stamp.split_once('.')?;
    let ns = secs.parse::<u64>().ok()? * 1_000_000_000 + micros.parse::<u64>().ok()? * 1_000;
    let event_at = line.find(&format!("{stamp}: "))? + stamp.len() + 2;
    let (event, fields) = line[event_at..].split_once(": ")?;
    Some((cpu, ns, event, fields))
}

/// The value of `key=` in `fields`, up to the next of `keys` (a comm may hold spaces).
pub(crate) fn field<'a>(fields: &'a str, key: &str, next: Option<&str>) -> Option<&'a str> {
    let from = fields.find(&format!("{key}="))? + key.len() + 1;
    let to = match next {
        Some(next) => fields[from..].find(&format!(" {next}="))? + from,
        None => fields[from..].find(' ').map_or(fields.len(), |i| i + from),
    };
    Some(&fields[from..to])
}

impl Trace {
    pub fn parse(text: &str) -> Self {
        let mut trace = Trace::default();
        // Runnable since (ns, CPU), per task id.
        let mut runnable: BTreeMap<u32, (u64, u32)> = BTreeMap::new();
        // Per task id, its last wake-up (ns, CPU); per CPU, its last switch.
        let mut woken: BTreeMap<u32, (u64, u32)> = BTreeMap::new();
        let mut switched: BTreeMap<u32, u64> = BTreeMap::new();
        for line in text.lines() {
            if let Some(entries) = line.strip_prefix("# entries-in-buffer/entries-written: ") {
                let counts: Vec<u64> =
                    entries.split(|c: char| !c.is_ascii_digit()).filter_map(|n| n.parse().ok()).collect();
                if let [kept, written, ..] = counts[..] {
                    trace.lost_events = written.saturating_sub(kept);
                }
                continue;
            }
            let Some((cpu, ns, event, fields)) = parse_line(line) else { continue };
            trace.span = Some(trace.span.map_or((ns, ns), |(first, _)| (first, ns)));
            let number = |key, next| field(fields, key, next).and_then(|v: &str| v.parse::<u32>().ok());
            match event {
                "sched_wakeup" => {
                    if let (Some(pid), Some(target)) = (number("pid", Some("prio")), number("target_cpu", None)) {
                        runnable.entry(pid).or_insert((ns, target));
                        woken.insert(pid, (ns, target));
                    }
                }
                "sched_switch" => {
                    let (Some(prev), Some(prio), Some(next)) = (
                        number("prev_pid", Some("prev_prio")),
                        number("prev_prio", Some("prev_state")),
                        number("next_pid", Some("next_prio")),
                    ) else {
                        continue;
                    };
                    // Preempted: still runnable, on this CPU.
                    if field(fields, "prev_state", None).is_some_and(|s| s.starts_with('R')) {
                        runnable.insert(prev, (ns, cpu));
                    }
                    if let Some((from, on)) = runnable.remove(&next) {
                        trace.waits.entry(next).or_default().push((from, ns, on));
                    }
                    let since = switched.insert(cpu, ns);
                    let since = match woken.get(&prev) {
                        Some(&(at, on)) if on == cpu && since.is_none_or(|s| at > s) => Some(at),
                        _ => since,
                    };
                    if let Some(since) = since {
                        let comm = field(fields, "prev_comm", Some("prev_pid")).unwrap_or_default().to_owned();
                        trace.runs.entry(cpu).or_default().push((since, ns, Task { comm, pid: prev, prio }));
                    }
                }
                _ => {}
            }
        }
        trace
    }

    /// The task that ran longest on the CPUs where one of `pids` waited, runnable, within
    /// `from..to` (ns), and for how long; None if none of them waited then.
    pub fn ran_instead(&self, pids: &[u32], from: u64, to: u64) -> Option<(Task, u64)> {
        let mut ran: BTreeMap<&Task, u64> = BTreeMap::new();
        for pid in pids {
            for &(wait_from, wait_to, cpu) in self.waits.get(pid).into_iter().flatten() {
                let (start, end) = (wait_from.max(from), wait_to.min(to));
                if start >= end {
                    continue;
                }
                let Some(runs) = self.runs.get(&cpu) else { continue };
                // The runs that end after `start` (in order of their ends), up to those that
                // begin at `end`.
                let first = runs.partition_point(|(_, until, _)| *until <= start);
                for (since, until, task) in &runs[first..] {
                    if *since >= end {
                        break;
                    }
                    let overlap = (*until).min(end).saturating_sub((*since).max(start));
                    if overlap > 0 && !pids.contains(&task.pid) && task.pid != 0 {
                        *ran.entry(task).or_default() += overlap;
                    }
                }
            }
        }
        ran.into_iter().max_by_key(|(_, ns)| *ns).map(|(task, ns)| (task.clone(), ns))
    }
}

/// Names, for every explained loop of the run folder's loops.csv whose cause is `queued:
/// <process>`, the task that ran on that process's CPU while it waited (`pids`: each process's
/// pid in every incarnation), and counts them in the summary's causes (`behind`).
pub fn name_who_ran(
    summary: &mut Summary,
    trace: &Trace,
    run_dir: &Path,
    pids: &BTreeMap<Role, Vec<u32>>,
) -> Result<()> {
    let path = run_dir.join(files::LOOPS);
    let mut reader = csv::Reader::from_path(&path).with_context(|| format!("read {}", path.display()))?;
    let headers = reader.headers()?.clone();
    let column =
        |name: &str| headers.iter().position(|h| h == name).with_context(|| format!("loops.csv has no {name}"));
    let [cause, missed, e2e, due, published, received, part] = [
        "cause",
        "deadline_miss",
        "end_to_end_ns",
        "tick_scheduled_ns",
        "plant_publish_ns",
        "plant_receive_ns",
        "cause_part_ns",
    ]
    .map(column);
    let (cause, missed, e2e, due, published, received, part) =
        (cause?, missed?, e2e?, due?, published?, received?, part?);
    let period_ns = crate::contract::clock::period_ns(summary.rate_hz);
    let slow_ns = summary.slow_loops.as_ref().map(|slow| (slow.over_us * 1e3).round() as u64);
    let mut report = SchedTraceReport { file: TRACE_FILE.into(), lost_events: trace.lost_events, ..Default::default() };
    for row in reader.records() {
        let row = row?;
        let number = |i: usize| row.get(i).and_then(|cell| cell.parse::<u64>().ok());
        let Some(role) = row.get(cause).and_then(|c| c.strip_prefix("queued: ")).and_then(|r| r.parse::<Role>().ok())
        else {
            continue;
        };
        report.queued_loops += 1;
        // From the tick (or the state going out) to the command in, or as long as the wait was.
        let Some(from) = number(due).or(number(published)) else { continue };
        let to = number(received).unwrap_or(from + number(part).unwrap_or(0) + 2 * period_ns);
        let Some((task, _)) = trace.ran_instead(pids.get(&role).map_or(&[][..], Vec::as_slice), from, to) else {
            continue;
        };
        report.named += 1;
        let name = row.get(cause).unwrap_or_default();
        let behind = |causes: &mut BTreeMap<String, crate::contract::report::CauseTally>| {
            if let Some(tally) = causes.get_mut(name) {
                *tally.behind.entry(task.to_string()).or_default() += 1;
            }
        };
        if row.get(missed) == Some("1") {
            behind(&mut summary.misses_by_cause);
        }
        if let (Some(slow), Some(over)) = (summary.slow_loops.as_mut(), slow_ns)
            && number(e2e).is_some_and(|ns| ns > over)
        {
            behind(&mut slow.by_cause);
        }
    }
    summary.sched_trace = Some(report);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const TRACE: &str = "\
# tracer: nop
#
# entries-in-buffer/entries-written: 7/9   #P:2
#
            my hog-400   [001] d..2.   100.000005: sched_switch: prev_comm=swapper/1 prev_pid=0 prev_prio=120 prev_state=R ==> next_comm=my hog next_pid=400 next_prio=49
 looplab-estimat-200     [000] d..2.   100.000010: sched_wakeup: comm=looplab-control pid=300 prio=120 target_cpu=001
            my hog-400   [001] d..2.   100.000500: sched_switch: prev_comm=my hog prev_pid=400 prev_prio=49 prev_state=S ==> next_comm=looplab-control next_pid=300 next_prio=120
 looplab-control-300     [001] d..2.   100.000520: sched_switch: prev_comm=looplab-control prev_pid=300 prev_prio=120 prev_state=R+ ==> next_comm=kworker/1:1 next_pid=50 next_prio=120
     kworker/1:1-50      [001] d..2.   100.000600: sched_switch: prev_comm=kworker/1:1 prev_pid=50 prev_prio=120 prev_state=I ==> next_comm=looplab-control next_pid=300 next_prio=120
";

    #[test]
    fn the_task_that_ran_while_a_process_waited_is_found() {
        let trace = Trace::parse(TRACE);
        assert_eq!(trace.lost_events, 2);
        assert_eq!(trace.span, Some((100_000_005_000, 100_000_600_000)));
        // Woken at 10 µs on CPU 1, ran at 500 µs: "my hog" had the CPU meanwhile.
        let (task, ns) = trace.ran_instead(&[300], 100_000_000_000, 100_001_000_000).unwrap();
        assert_eq!(task, Task { comm: "my hog".into(), pid: 400, prio: 49 });
        assert_eq!(ns, 490_000);
        assert_eq!(task.to_string(), "my hog (pid 400, real-time priority 50)");
        // Preempted at 520 µs by a kworker until 600 µs.
        let (task, ns) = trace.ran_instead(&[300], 100_000_510_000, 100_001_000_000).unwrap();
        assert_eq!((task.comm.as_str(), ns), ("kworker/1:1", 80_000));
        assert_eq!(task.to_string(), "kworker/1:1 (pid 50, nice 0)");
        assert_eq!(trace.ran_instead(&[300], 100_000_600_000, 100_001_000_000), None, "it ran from there on");
        assert_eq!(trace.ran_instead(&[999], 0, u64::MAX), None);
    }

    #[test]
    fn without_tracefs_it_says_so_in_one_line() {
        let Err(why) = SchedTrace::start(Path::new("/nonexistent/looplab/tracing"), "r", 1.0) else {
            panic!("started without tracefs");
        };
        assert!(why.starts_with("--trace-sched: no scheduler trace, cannot mount tracefs at /nonexistent"), "{why}");
        assert!(!why.contains('\n'));
    }
}
