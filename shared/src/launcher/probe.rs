//! The machine's floor in the same run (`looplab run --probe`): a thread of the launcher at the
//! plant's scheduling policy and priority sleeps to absolute deadlines at the loop's rate, as
//! `cyclictest` does (`clock_nanosleep`, `TIMER_ABSTIME`, CLOCK_MONOTONIC), and records how late
//! each wake-up was. The report sets the plant's tick wake-up latency beside it: what the OS alone
//! gives a timer here, now, against what the loop's own timer got.
//!
//! A thread of the launcher, not a process: the launcher lives for the whole run and hears the
//! plant's schedule (`started`), and a thread needs no binary of its own. It touches no port and
//! no file of the loop, and wakes half a period after each tick, when the loop has normally
//! finished, so that it neither delays the plant's wake-up nor sits on a stage's CPU.
//!
//! `looplab probe` runs the same sleeps on their own, as `cyclictest` is run ([`run_alone`]):
//! an interval, a loop count, a priority and a CPU; it prints p50/p99/p99.9/max and writes every
//! wake-up's lateness as a histogram in whole µs, as cyclictest's `-h` does, so that the two can
//! be set side by side (tests/probe.rs does).

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;

use crossbeam_channel::{Receiver, Sender};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::config::launch::LaunchConfig;
use crate::contract::clock::now_ns;
use crate::contract::report::Stats;
use crate::monitor::distribution::Distribution;
use crate::runtime::transport::wait::{allowed_cpus, pin_to_cpu, sleep_until, tighten_timer_slack};

/// What the probe measured (`summary.json`'s `probe`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ProbeSummary {
    /// How late each wake-up was: woke − deadline, ns.
    pub wake_latency_ns: Stats,
    /// Its deadlines' interval: the loop's period, ns.
    pub interval_ns: u64,
    /// Its deadlines' offset after each of the plant's ticks, ns (half a period).
    pub offset_ns: u64,
    /// Its scheduling policy as the kernel has it: `normal` or `fifo` (the plant's).
    pub policy: String,
    /// Its real-time priority (0 under the normal policy).
    pub priority: u32,
    /// Its timer slack, ns, as the kernel has it (a real-time thread's is 0).
    pub timer_slack_ns: u64,
    /// Deadlines passed over because a wake-up came after the next one was due too.
    pub overruns: u64,
    /// Why it could not run as asked (its priority refused), if so.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

/// The probe's thread, started with the run; it begins once the plant's schedule is known.
pub struct Probe {
    start: Option<Sender<u64>>,
    stop: Arc<AtomicBool>,
    thread: JoinHandle<ProbeSummary>,
}

impl Probe {
    /// Starts the thread at `config`'s rate and the plant's priority (`[realtime] priority`);
    /// it waits for [`Probe::begin`] and ends after as many deadlines as the run has loops.
    pub fn start(config: &LaunchConfig) -> Self {
        Self::with(config.period_ns(), config.loops(), config.realtime.priority)
    }

    /// `loops` deadlines every `period_ns`, at `SCHED_FIFO` `priority` (None: the normal
    /// policy). The thread inherits the caller's CPU affinity.
    pub fn with(period_ns: u64, loops: u64, priority: Option<u32>) -> Self {
        let (start, schedule) = crossbeam_channel::bounded(1);
        let stop = Arc::new(AtomicBool::new(false));
        let stopped = stop.clone();
        let thread = std::thread::Builder::new()
            .name("probe".into())
            .spawn(move || measure(schedule, &stopped, period_ns, loops, priority))
            .expect("a thread can be started");
        Self { start: Some(start), stop, thread }
    }

    /// The plant's tick 0 was due at `start_ns` (CLOCK_MONOTONIC); the first only (a restarted
    /// plant keeps its schedule).
    pub fn begin(&mut self, start_ns: u64) {
        if let Some(start) = self.start.take() {
            let _ = start.send(start_ns);
        }
    }

    /// Waits until it has had all its deadlines, and returns what it measured.
    pub fn wait(mut self) -> ProbeSummary {
        self.start.take();
        self.thread.join().unwrap_or_default()
    }

    /// Stops it (at its next wake-up, at most a period away) and returns what it measured.
    pub fn finish(self) -> ProbeSummary {
        self.stop.store(true, Ordering::Relaxed);
        drop(self.start);
        self.thread.join().unwrap_or_default()
    }
}

/// The probe's thread: the plant's policy, a timer asked to be on time, then `loops` deadlines
/// from half a period after the plant's tick 0.
fn measure(
    schedule: Receiver<u64>,
    stop: &AtomicBool,
    period_ns: u64,
    loops: u64,
    priority: Option<u32>,
) -> ProbeSummary {
    let note = priority.and_then(|p| set_fifo(p).err()).map(|e| format!("it ran at normal priority: {e}"));
    // As the plant's blocking waits ask (`Waiter`); a real-time thread has none anyway.
    tighten_timer_slack();
    let (policy, priority) = scheduling();
    let mut summary = ProbeSummary {
        interval_ns: period_ns,
        offset_ns: period_ns / 2,
        policy,
        priority,
        timer_slack_ns: timer_slack_ns(),
        note,
        ..Default::default()
    };
    // None: the plant never started (the run ended first).
    let Ok(start_ns) = schedule.recv() else { return summary };
    let woken = wake_ups(start_ns + period_ns / 2, period_ns, loops, stop);
    summary.wake_latency_ns = woken.latency.stats();
    summary.overruns = woken.overruns;
    summary
}

/// What `loops` absolute-deadline sleeps measured.
struct WakeUps {
    latency: Distribution,
    /// Each wake-up's lateness in whole µs (rounded down) and how many woke so late.
    histogram_us: BTreeMap<u64, u64>,
    overruns: u64,
}

/// `loops` deadlines every `period_ns` from `first_ns`: sleeps to each (`clock_nanosleep`,
/// `TIMER_ABSTIME`) and records how late it woke. Skips deadlines it woke too late for, as
/// cyclictest does, counting them.
fn wake_ups(first_ns: u64, period_ns: u64, loops: u64, stop: &AtomicBool) -> WakeUps {
    let mut woken = WakeUps { latency: Distribution::default(), histogram_us: BTreeMap::new(), overruns: 0 };
    let (mut k, mut next) = (0, first_ns);
    while k < loops && !stop.load(Ordering::Relaxed) {
        sleep_until(next);
        let woke = now_ns();
        // An interrupted sleep (a signal) ends early: sleep again.
        if woke < next {
            continue;
        }
        woken.latency.record(woke - next);
        *woken.histogram_us.entry((woke - next) / 1_000).or_default() += 1;
        (k, next) = (k + 1, next + period_ns);
        while next <= woke && k < loops {
            (k, next) = (k + 1, next + period_ns);
            woken.overruns += 1;
        }
    }
    woken
}

/// `looplab probe`: the probe on its own, as `cyclictest` is run: `loops` deadlines every
/// `interval_us` from one interval after it starts, at `SCHED_FIFO` `priority` (None: the
/// normal policy, its timer slack tightened to 1 ns as the in-run probe's), on `cpu` (None: any
/// the process may use), its memory locked if `mlock`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ProbeOptions {
    pub interval_us: u64,
    pub loops: u64,
    pub priority: Option<u32>,
    pub cpu: Option<usize>,
    pub mlock: bool,
}

/// What `looplab probe` measured (its `--json`): the in-run probe's summary and every wake-up's
/// lateness as a histogram, for pooling runs and setting beside cyclictest's (`-h`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProbeRun {
    #[serde(flatten)]
    pub summary: ProbeSummary,
    /// The CPU it was pinned to, if any.
    pub cpu: Option<usize>,
    /// Whether its memory was locked (`mlockall`).
    pub mlock: bool,
    /// Each wake-up's lateness in whole µs, rounded down as cyclictest's histogram counts it, and
    /// how many wake-ups: `[µs, count]`, ascending, no empty µs.
    pub histogram_us: Vec<[u64; 2]>,
}

impl ProbeRun {
    /// Its report: what ran where, and p50 / p99 / p99.9 / max of the wake-up latency.
    pub fn render(&self) -> String {
        let s = &self.summary;
        let us = |v: Option<u64>| v.map_or_else(|| "-".to_string(), |ns| format!("{:.1}", ns as f64 / 1e3));
        let l = &s.wake_latency_ns;
        format!(
            "probe: {} wake-ups every {} µs, {} {} (timer slack {} ns), {}{}\n  \
             wake-up latency µs: p50 {}  p99 {}  p99.9 {}  max {}   ({} overruns)",
            l.count,
            s.interval_ns / 1_000,
            s.policy,
            s.priority,
            s.timer_slack_ns,
            self.cpu.map_or_else(|| "any CPU".to_string(), |c| format!("CPU {c}")),
            if self.mlock { ", memory locked" } else { "" },
            us(l.p50),
            us(l.p99),
            us(l.p999),
            us(l.max),
            s.overruns,
        )
    }
}

/// The largest interval and loop count `looplab probe` takes.
pub const MAX_INTERVAL_US: u64 = 1_000_000;
pub const MAX_LOOPS: u64 = 100_000_000;

impl ProbeOptions {
    /// What is wrong with the options, as one line naming the flag and what it allows.
    pub fn check(&self) -> Result<(), String> {
        if !(10..=MAX_INTERVAL_US).contains(&self.interval_us) {
            return Err(format!("--interval-us {}: allowed 10 to {MAX_INTERVAL_US} (µs)", self.interval_us));
        }
        if !(1..=MAX_LOOPS).contains(&self.loops) {
            return Err(format!("--loops {}: allowed 1 to {MAX_LOOPS}", self.loops));
        }
        if let Some(p) = self.priority.filter(|p| !(1..=99).contains(p)) {
            return Err(format!("--priority {p}: allowed 1 to 99 (SCHED_FIFO); leave it out for the normal policy"));
        }
        if let Some(cpu) = self.cpu {
            let allowed = allowed_cpus();
            if !allowed.contains(&cpu) {
                let list: Vec<String> = allowed.iter().map(usize::to_string).collect();
                return Err(format!("--cpu {cpu}: allowed {} (the CPUs this process may run on)", list.join(", ")));
            }
        }
        Ok(())
    }
}

/// Runs the probe on a thread of its own, as `options` ask, and returns what it measured. An
/// error is one line naming the flag the machine refused (`--priority` without the permission,
/// `--mlock`).
pub fn run_alone(options: &ProbeOptions) -> Result<ProbeRun, String> {
    options.check()?;
    let options = options.clone();
    let thread = std::thread::Builder::new().name("probe".into()).spawn(move || {
        if let Some(cpu) = options.cpu {
            pin_to_cpu(cpu).map_err(|e| format!("--cpu {cpu}: {e}"))?;
        }
        if let Some(p) = options.priority {
            set_fifo(p).map_err(|e| {
                format!(
                    "--priority {p}: SCHED_FIFO is not permitted here ({e}): it needs CAP_SYS_NICE (root) or \
                     `ulimit -r` of at least {p}; leave out --priority to run at the normal policy"
                )
            })?;
        }
        // SAFETY: mlockall takes plain flags.
        if options.mlock && unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } != 0 {
            let e = std::io::Error::last_os_error();
            return Err(format!("--mlock: locking memory is not permitted here ({e}); leave out --mlock"));
        }
        tighten_timer_slack();
        let (policy, priority) = scheduling();
        let period_ns = options.interval_us * 1_000;
        let woken = wake_ups(now_ns() + period_ns, period_ns, options.loops, &AtomicBool::new(false));
        Ok(ProbeRun {
            summary: ProbeSummary {
                wake_latency_ns: woken.latency.stats(),
                interval_ns: period_ns,
                offset_ns: 0,
                policy,
                priority,
                timer_slack_ns: timer_slack_ns(),
                overruns: woken.overruns,
                note: None,
            },
            cpu: options.cpu,
            mlock: options.mlock,
            histogram_us: woken.histogram_us.into_iter().map(|(us, n)| [us, n]).collect(),
        })
    });
    thread
        .map_err(|e| format!("cannot start the probe's thread: {e}"))?
        .join()
        .map_err(|_| "the probe's thread panicked".to_string())?
}

fn set_fifo(priority: u32) -> std::io::Result<()> {
    let param = libc::sched_param { sched_priority: priority as i32 };
    // SAFETY: pid 0 is the calling thread; `param` is a valid sched_param.
    if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

/// The calling thread's policy and real-time priority, as the kernel has them.
fn scheduling() -> (String, u32) {
    let mut param = libc::sched_param { sched_priority: 0 };
    // SAFETY: pid 0 is the calling thread; both calls only read.
    let (policy, _) = unsafe { (libc::sched_getscheduler(0), libc::sched_getparam(0, &mut param)) };
    let name = match policy {
        libc::SCHED_FIFO => "fifo",
        libc::SCHED_RR => "rr",
        libc::SCHED_OTHER => "normal",
        _ => "other",
    };
    (name.into(), param.sched_priority.max(0) as u32)
}

/// The calling thread's timer slack, ns.
fn timer_slack_ns() -> u64 {
    // SAFETY: PR_GET_TIMERSLACK takes no pointer; it returns the slack.
    let slack = unsafe { libc::prctl(libc::PR_GET_TIMERSLACK) };
    slack.max(0) as u64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::launch::Override;
    use crate::scenarios::resolve;

    #[test]
    fn the_probe_wakes_at_its_deadlines_and_counts_them() {
        let sets = ["mode=realtime", "duration_s=0.05", "rate_hz=1000"].map(|s| Override::parse(s).unwrap());
        let (config, _) = resolve("pendulum", &sets).unwrap();
        let mut probe = Probe::start(&config);
        probe.begin(now_ns());
        let s = probe.finish_after(std::time::Duration::from_millis(200));
        assert_eq!(s.wake_latency_ns.count + s.overruns, 50, "one wake-up or overrun per loop: {s:?}");
        assert_eq!((s.interval_ns, s.offset_ns, s.policy.as_str()), (1_000_000, 500_000, "normal"));
    }

    #[test]
    fn the_probe_alone_checks_its_options_and_measures_each_deadline() {
        let options = ProbeOptions { interval_us: 1_000, loops: 20, priority: None, cpu: None, mlock: false };
        let run = run_alone(&options).unwrap();
        let s = &run.summary;
        assert_eq!(s.wake_latency_ns.count + s.overruns, 20, "{s:?}");
        assert_eq!(run.histogram_us.iter().map(|[_, n]| n).sum::<u64>(), s.wake_latency_ns.count);
        assert_eq!((s.interval_ns, s.policy.as_str(), s.timer_slack_ns), (1_000_000, "normal", 1));
        assert!(run.render().contains("p99.9"), "{}", run.render());
        for (bad, flag) in [
            (ProbeOptions { interval_us: 0, ..options.clone() }, "--interval-us 0: allowed 10 to"),
            (ProbeOptions { loops: 0, ..options.clone() }, "--loops 0: allowed 1 to"),
            (ProbeOptions { priority: Some(100), ..options.clone() }, "--priority 100: allowed 1 to 99"),
            (ProbeOptions { cpu: Some(100_000), ..options.clone() }, "--cpu 100000: allowed "),
        ] {
            let why = run_alone(&bad).unwrap_err();
            assert!(why.starts_with(flag) && !why.contains('\n'), "{why}");
        }
    }

    impl Probe {
        /// Lets it run for `wait` first: the test's run "lasts" that long.
        fn finish_after(self, wait: std::time::Duration) -> ProbeSummary {
            std::thread::sleep(wait);
            self.finish()
        }
    }
}
