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
use crate::runtime::wait::{sleep_until, tighten_timer_slack};

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
/// from half a period after the plant's tick 0. Skips deadlines it woke too late for, as
/// cyclictest does, counting them.
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
    let mut latency = Distribution::default();
    let (mut k, mut next) = (0, start_ns + period_ns / 2);
    while k < loops && !stop.load(Ordering::Relaxed) {
        sleep_until(next);
        let woke = now_ns();
        // An interrupted sleep (a signal) ends early: sleep again.
        if woke < next {
            continue;
        }
        latency.record(woke - next);
        (k, next) = (k + 1, next + period_ns);
        while next <= woke && k < loops {
            (k, next) = (k + 1, next + period_ns);
            summary.overruns += 1;
        }
    }
    summary.wake_latency_ns = latency.stats();
    summary
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

    impl Probe {
        /// Lets it run for `wait` first: the test's run "lasts" that long.
        fn finish_after(self, wait: std::time::Duration) -> ProbeSummary {
            std::thread::sleep(wait);
            self.finish()
        }
    }
}
