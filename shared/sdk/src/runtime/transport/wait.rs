//! How a loop process waits for its input, by the strategy of its `[wait]` settings (see
//! `crate::config::wait` for what each strategy does).

use std::collections::VecDeque;

use anyhow::Result;

use crate::config::launch::{LaunchConfig, Mode};
use crate::config::wait::{HANDOFF_POLL_US, LockstepWait, Strategy, WaitSettings};
use crate::contract::clock::now_ns;
use crate::contract::protocol::WaitCounts;
use crate::contract::role::{Role, Topic};
use crate::runtime::transport::reader_state::Wake;

/// Observations kept to estimate how soon after a tick the input arrives.
const WINDOW: usize = 64;

/// Sleeps remembered to learn how late this process wakes.
const OVERSLEEP_WINDOW: usize = 32;

/// A yield that gives the CPU away for this long means another task wanted it: the machine is
/// busy.
const BUSY_YIELD_NS: u64 = 30_000;

/// On a busy machine, this many waits block before polling is tried again; each try that finds it
/// still busy doubles them, up to [`MAX_BUSY_WAITS`] (a try costs the CPU for a time slice).
const BUSY_WAITS: u32 = 1000;
const MAX_BUSY_WAITS: u32 = 64_000;

/// `ns` nanoseconds as a timespec.
pub fn timespec(ns: u64) -> libc::timespec {
    libc::timespec { tv_sec: (ns / 1_000_000_000) as libc::time_t, tv_nsec: (ns % 1_000_000_000) as libc::c_long }
}

/// Sleeps until an absolute CLOCK_MONOTONIC time.
pub fn sleep_until(deadline_ns: u64) {
    let ts = timespec(deadline_ns);
    // SAFETY: a valid timespec; an interrupted sleep just returns early, which is harmless.
    unsafe { libc::clock_nanosleep(libc::CLOCK_MONOTONIC, libc::TIMER_ABSTIME, &ts, std::ptr::null_mut()) };
}

/// Asks the kernel to wake this thread's timers on time: the default slack lets a sleep end up
/// to 50 µs late.
pub fn tighten_timer_slack() {
    // SAFETY: PR_SET_TIMERSLACK takes a plain integer.
    unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong) };
}

/// Pins this process to CPU i mod n, i its place in the loop (plant 0, sensors 1, ...).
fn pin_in_loop_order(role: Role) {
    let Some(place) = role.slot() else {
        return;
    };
    // Best effort: an unpinned process still runs.
    let _ = pin_to_cpu(place % available_cpus());
}

/// Pins the calling thread to `cpu`.
pub fn pin_to_cpu(cpu: usize) -> std::io::Result<()> {
    // SAFETY: a zeroed cpu_set_t is a valid empty set; CPU_SET writes inside it; pid 0 is the
    // calling thread.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu, &mut set);
        if libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) != 0 {
            return Err(std::io::Error::last_os_error());
        }
    }
    Ok(())
}

/// The CPUs the calling thread may run on, ascending.
pub fn allowed_cpus() -> Vec<usize> {
    // SAFETY: a zeroed cpu_set_t is a valid empty set that sched_getaffinity fills; CPU_ISSET
    // reads inside it.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        if libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) != 0 {
            return vec![];
        }
        (0..libc::CPU_SETSIZE as usize).filter(|&c| libc::CPU_ISSET(c, &set)).collect()
    }
}

/// Gives the calling thread (and threads it starts later) the lowest normal priority, nice 19:
/// a loop process that wakes preempts it, yet it still gets a share of a busy machine.
/// (SCHED_IDLE would get next to none, and a starved monitor loses records.)
pub fn run_in_background() {
    // SAFETY: setpriority on this thread (who = 0) with a valid nice value.
    unsafe { libc::setpriority(libc::PRIO_PROCESS, 0, 19) };
}

/// The input's timing as a process has seen it: the plant's schedule (the earliest tick phase
/// seen) and the recent arrival delays after a tick.
pub struct ArrivalModel {
    period_ns: u64,
    /// min over ticks of (plant publish − k·period): the schedule's start plus the plant's
    /// quickest wake-up.
    phase_ns: Option<u64>,
    /// Recent (arrival − plant publish) delays.
    delays: VecDeque<u64>,
}

impl ArrivalModel {
    pub fn new(period_ns: u64) -> Self {
        Self { period_ns, phase_ns: None, delays: VecDeque::with_capacity(WINDOW) }
    }

    /// Input of tick k, published by the plant at `published` and arrived at `arrived`.
    pub fn observe(&mut self, k: u64, published: u64, arrived: u64) {
        let phase = published.saturating_sub(k * self.period_ns);
        self.phase_ns = Some(self.phase_ns.map_or(phase, |p| p.min(phase)));
        if self.delays.len() == WINDOW {
            self.delays.pop_front();
        }
        self.delays.push_back(arrived.saturating_sub(published));
    }

    /// When the input of tick k is expected at the earliest.
    pub fn due(&self, k: u64) -> Option<u64> {
        let phase = self.phase_ns?;
        let delay = self.delays.iter().copied().min()?;
        Some(phase + k * self.period_ns + delay)
    }
}

/// Yields the CPU; returns whether another task had it meanwhile (the yield took long).
fn yield_found_cpu_wanted() -> bool {
    let yielded = now_ns();
    // SAFETY: sched_yield has no preconditions.
    unsafe { libc::sched_yield() };
    now_ns() - yielded > BUSY_YIELD_NS
}

/// How a waiter waits: a real-time strategy, or lockstep's poll.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    Block,
    Spin,
    Adaptive,
    /// Lockstep: look, yield the CPU, look again.
    Poll,
    /// Lockstep: poll for about a handoff's time ([`HANDOFF_POLL_US`]), then sleep until woken.
    Handoff,
}

impl Method {
    /// Whether a process waiting this way ever blocks: only then does its writer need to wake it
    /// (a poller sees the sample itself, and both notify syscalls are saved).
    pub fn blocks(self) -> bool {
        matches!(self, Method::Block | Method::Adaptive | Method::Handoff)
    }
}

/// How `role` waits: its own strategy in real time, lockstep's otherwise.
pub fn method_of(settings: &WaitSettings, role: Role, realtime: bool) -> Method {
    if realtime {
        settings.for_process(role).into()
    } else {
        match settings.lockstep_on(available_cpus()) {
            LockstepWait::Poll => Method::Poll,
            LockstepWait::Handoff => Method::Handoff,
            LockstepWait::Block | LockstepWait::Auto => Method::Block,
        }
    }
}

/// Whether the loop process that waits on `topic` ever blocks: then it listens for wake-ups and
/// its writer sends them.
pub fn reader_blocks(settings: &WaitSettings, topic: Topic, realtime: bool) -> bool {
    Role::reading(topic).is_some_and(|reader| method_of(settings, reader, realtime).blocks())
}

/// How the writer of `topic` wakes its reader: by the reader's futex if the reader blocks, by
/// iceoryx2's event if it runs on another host and a bridge, which always blocks, reads the topic
/// on the writer's host; never if the reader polls.
pub fn writer_wakes(config: &LaunchConfig, topic: Topic) -> Wake {
    if config.hosts.read_by_bridge(topic) {
        Wake::Event
    } else if reader_blocks(&config.wait, topic, config.mode == Mode::Realtime) {
        Wake::Futex
    } else {
        Wake::Never
    }
}

impl From<Strategy> for Method {
    fn from(strategy: Strategy) -> Self {
        match strategy {
            Strategy::Block => Method::Block,
            Strategy::Spin => Method::Spin,
            Strategy::Adaptive => Method::Adaptive,
        }
    }
}

/// Waits for input with the process's method. `ready` says whether input is there; `doze`
/// sleeps until the input's wake-up or a deadline, whichever comes first; `block` sleeps until
/// the input's wake-up or the slice's end (the real-time plant: its next tick).
pub struct Waiter {
    pub method: Method,
    lead_ns: u64,
    cap_ns: u64,
    pub counts: WaitCounts,
    /// How late the last sleeps woke up, ns: a halted vCPU takes tens of µs to wake, a busy
    /// one a few; the sleep is cut short by what this process typically needs.
    oversleeps: VecDeque<u64>,
    /// Adaptive: the last wait polled its whole cap without input (its writer died, stalls or
    /// the run ends), so waits block until an input comes again rather than poll for nothing.
    silent: bool,
    /// Adaptive: waits left that block because a poll's yield found the CPU wanted by another
    /// task. There a yield hands the CPU over for a whole time slice (milliseconds), while a
    /// blocked waiter is woken ahead of a busy task the moment its input comes.
    busy_waits_left: u32,
    /// Adaptive: how many waits block the next time the machine is found busy.
    busy_waits_next: u32,
    /// Adaptive: one poll's yield (a field, so that tests choose what it finds).
    yield_cpu: fn() -> bool,
}

impl Waiter {
    /// The third quartile of the recent oversleeps: early enough most of the time, without
    /// letting one long VM stall make every wait spin for longer.
    fn typical_oversleep(&self) -> u64 {
        let mut recent: Vec<u64> = self.oversleeps.iter().copied().collect();
        if recent.is_empty() {
            return 0;
        }
        recent.sort_unstable();
        recent[recent.len() * 3 / 4]
    }

    /// The waiter of a loop process: its own strategy in real time, lockstep's (`wait.lockstep`)
    /// otherwise, pinned to its core if the settings say so. `period_ns` is
    /// the loop's period.
    pub fn new(settings: &WaitSettings, role: Role, realtime: bool, period_ns: u64) -> Self {
        let method = method_of(settings, role, realtime);
        if settings.pin {
            pin_in_loop_order(role);
        }
        Self::with_method(settings, method, period_ns)
    }

    /// A waiter with the given method and the settings' lead and cap (the bench's ends).
    pub fn with_method(settings: &WaitSettings, method: Method, period_ns: u64) -> Self {
        // A futex's timeout (the plant's tick, a doze's end) is a timer too.
        if method.blocks() {
            tighten_timer_slack();
        }
        Self {
            method,
            // At most MAX_WAIT_US (checked at load): well within u64 nanoseconds.
            lead_ns: (settings.lead_us * 1e3) as u64,
            cap_ns: settings.spin_cap_us.map_or(period_ns, |us| (us * 1e3) as u64),
            counts: WaitCounts::default(),
            oversleeps: VecDeque::with_capacity(OVERSLEEP_WINDOW),
            silent: false,
            busy_waits_left: 0,
            busy_waits_next: BUSY_WAITS,
            yield_cpu: yield_found_cpu_wanted,
        }
    }

    /// Waits until `ready()`, `slice_end_ns` (for spin, poll and a handoff's polling; blocking
    /// leaves that to `block`'s own deadline), or `block` returns.
    pub fn wait(
        &mut self,
        due_ns: Option<u64>,
        slice_end_ns: u64,
        mut ready: impl FnMut() -> Result<bool>,
        mut doze: impl FnMut(u64) -> Result<()>,
        mut block: impl FnMut() -> Result<()>,
    ) -> Result<()> {
        match self.method {
            Method::Block => block(),
            Method::Spin => {
                while !ready()? && now_ns() < slice_end_ns {
                    std::hint::spin_loop();
                }
                Ok(())
            }
            Method::Poll => {
                while !ready()? && now_ns() < slice_end_ns {
                    // SAFETY: sched_yield has no preconditions.
                    unsafe { libc::sched_yield() };
                }
                Ok(())
            }
            Method::Handoff => {
                let poll_end = now_ns() + HANDOFF_POLL_US * 1000;
                while now_ns() < poll_end {
                    if ready()? {
                        return Ok(());
                    }
                    // SAFETY: sched_yield has no preconditions.
                    unsafe { libc::sched_yield() };
                }
                block()
            }
            Method::Adaptive => {
                let Some(due) = due_ns else { return block() };
                if ready()? {
                    return Ok(());
                }
                if self.busy_waits_left > 0 {
                    self.busy_waits_left -= 1;
                    self.counts.busy += 1;
                    return block();
                }
                if !self.silent {
                    if self.doze_then_poll(due, &mut ready, &mut doze)? {
                        self.counts.caught += 1;
                        return Ok(());
                    }
                    if self.busy_waits_left > 0 {
                        self.counts.busy += 1;
                        return block();
                    }
                    // Polled the whole cap for nothing: the writer is silent.
                    self.counts.blocked += 1;
                    self.silent = true;
                }
                block()?;
                self.silent = !ready()?;
                Ok(())
            }
        }
    }

    /// Adaptive: dozes until shortly before the input is due (an input that comes earlier ends
    /// the doze with its wake-up), then polls, yielding the CPU to whichever process has work,
    /// until the cap past the due time. A late input is polled for: a blocking wake-up of a
    /// halted vCPU costs more than the polling. A yield that finds the CPU wanted by another
    /// task ends the polling for [`BUSY_WAITS`] waits. Returns whether the input came.
    fn doze_then_poll(
        &mut self,
        due: u64,
        ready: &mut impl FnMut() -> Result<bool>,
        doze: &mut impl FnMut(u64) -> Result<()>,
    ) -> Result<bool> {
        let wake_at = due.saturating_sub(self.lead_ns + self.typical_oversleep());
        while now_ns() < wake_at {
            doze(wake_at)?;
            let woke = now_ns();
            if ready()? {
                return Ok(true);
            }
            if woke >= wake_at {
                if self.oversleeps.len() == OVERSLEEP_WINDOW {
                    self.oversleeps.pop_front();
                }
                self.oversleeps.push_back(woke - wake_at);
            }
        }
        let give_up = due.max(now_ns()) + self.cap_ns;
        while now_ns() < give_up {
            if ready()? {
                return Ok(true);
            }
            if (self.yield_cpu)() {
                self.busy_waits_left = self.busy_waits_next;
                self.busy_waits_next = (self.busy_waits_next * 2).min(MAX_BUSY_WAITS);
                return ready();
            }
            // A yield that came straight back: the machine is not busy (any more).
            self.busy_waits_next = BUSY_WAITS;
        }
        Ok(false)
    }
}

/// The CPUs this process may run on.
pub fn available_cpus() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_model_learns_the_schedule_and_the_quickest_arrival() {
        let mut m = ArrivalModel::new(1_000_000);
        assert_eq!(m.due(1), None);
        // Ticks due at 5 ms + k ms; the plant wakes 10–300 µs late; input 40–90 µs after it.
        for (k, late, delay) in [(0u64, 300_000u64, 90_000u64), (1, 10_000, 40_000), (2, 50_000, 60_000)] {
            let published = 5_000_000 + k * 1_000_000 + late;
            m.observe(k, published, published + delay);
        }
        assert_eq!(m.due(3), Some(5_000_000 + 3_000_000 + 10_000 + 40_000));
    }

    #[test]
    fn lockstep_polls_or_blocks_by_its_own_key() {
        let mut s = WaitSettings { strategy: Strategy::Adaptive, ..Default::default() };
        assert_eq!(Waiter::new(&s, Role::Sensors, true, 1_000_000).method, Method::Adaptive);
        s.lockstep = LockstepWait::Poll;
        assert_eq!(Waiter::new(&s, Role::Sensors, false, 1_000_000).method, Method::Poll);
        s.lockstep = LockstepWait::Block;
        assert_eq!(Waiter::new(&s, Role::Sensors, false, 1_000_000).method, Method::Block);
        s.lockstep = LockstepWait::Handoff;
        assert_eq!(Waiter::new(&s, Role::Sensors, false, 1_000_000).method, Method::Handoff);
        s.lockstep = LockstepWait::Auto;
        let auto = Waiter::new(&s, Role::Sensors, false, 1_000_000).method;
        let polls = available_cpus() >= crate::config::wait::CPUS_TO_POLL;
        assert_eq!(auto, if polls { Method::Poll } else { Method::Handoff });
    }

    /// An input that arrives while the process dozes ends the doze; one that is late is polled
    /// for, and only one that stays away for the whole cap makes the waiter block, after which it
    /// blocks until inputs come again. (Times far from now, or a cap of zero, keep the test free
    /// of the clock.)
    #[test]
    fn adaptive_catches_early_and_late_inputs_and_blocks_only_when_silent() {
        use std::cell::Cell;
        const HOUR: u64 = 3_600_000_000_000;
        // What the waiter did: blocks, looks, dozes; `arrive` sets whether input is there.
        let (blocks, looks, dozes, here) = (Cell::new(0), Cell::new(0), Cell::new(0), Cell::new(false));
        let ready = || {
            looks.set(looks.get() + 1);
            Ok(here.get())
        };
        let block = || {
            blocks.set(blocks.get() + 1);
            Ok(())
        };
        let doze_brings_input = |_| {
            dozes.set(dozes.get() + 1);
            here.set(true);
            Ok(())
        };
        let reset = || {
            here.set(false);
            looks.set(0);
        };

        let patient = WaitSettings { spin_cap_us: Some(3.6e9), ..Default::default() };
        let mut w = Waiter::with_method(&patient, Method::Adaptive, 1_000_000);
        // An idle machine: a yield finds no other task (whatever this machine is doing now).
        w.yield_cpu = || false;
        // Early: the doze ends with the input's wake-up.
        w.wait(Some(now_ns() + HOUR), u64::MAX, ready, doze_brings_input, block).unwrap();
        assert_eq!((w.counts.caught, blocks.get(), dozes.get()), (1, 0, 1));
        // Late: due already, there on the 100th look.
        reset();
        let late = || {
            looks.set(looks.get() + 1);
            Ok(looks.get() >= 100)
        };
        w.wait(Some(now_ns()), u64::MAX, late, |_| Ok(()), block).unwrap();
        assert_eq!((w.counts.caught, w.counts.blocked, blocks.get(), looks.get()), (2, 0, 0, 100));

        // Missing for the whole cap: a block; while silent, every wait blocks at once.
        reset();
        let impatient = WaitSettings { spin_cap_us: Some(0.0), ..Default::default() };
        let mut w = Waiter::with_method(&impatient, Method::Adaptive, 1_000_000);
        w.yield_cpu = || false;
        w.wait(Some(now_ns()), u64::MAX, ready, |_| Ok(()), block).unwrap();
        assert_eq!((w.counts.blocked, blocks.get()), (1, 1));
        reset();
        w.wait(Some(now_ns() + HOUR), u64::MAX, ready, |_| panic!("no doze while silent"), block).unwrap();
        assert_eq!((blocks.get(), looks.get()), (2, 2));
        // An input that comes ends the silence: the next wait dozes again.
        let block_brings_input = || {
            here.set(true);
            Ok(())
        };
        w.wait(Some(now_ns()), u64::MAX, ready, |_| Ok(()), block_brings_input).unwrap();
        reset();
        w.wait(Some(now_ns() + HOUR), u64::MAX, ready, doze_brings_input, || panic!("not silent")).unwrap();
        assert_eq!(dozes.get(), 2);
    }

    /// Once a poll's yield found the CPU wanted by another task, that wait and the next ones
    /// block at once, neither dozing nor polling, and polling is tried again after them.
    #[test]
    fn on_a_busy_machine_adaptive_blocks_for_a_while_then_polls_again() {
        use std::cell::Cell;
        const HOUR: u64 = 3_600_000_000_000;
        let (blocks, dozes, looks) = (Cell::new(0), Cell::new(0), Cell::new(0));
        let patient = WaitSettings { spin_cap_us: Some(3.6e9), ..Default::default() };
        let mut w = Waiter::with_method(&patient, Method::Adaptive, 1_000_000);
        w.yield_cpu = || true;
        let block = || {
            blocks.set(blocks.get() + 1);
            Ok(())
        };
        let ready = || {
            looks.set(looks.get() + 1);
            Ok(false)
        };
        // Due now: the first yield finds the CPU wanted, and the wait blocks.
        w.wait(Some(now_ns()), u64::MAX, ready, |_| Ok(()), block).unwrap();
        assert_eq!((blocks.get(), looks.get(), w.counts.busy, w.counts.blocked), (1, 3, 1, 0));
        w.yield_cpu = || false;
        for _ in 1..=BUSY_WAITS {
            w.wait(Some(now_ns() + HOUR), u64::MAX, || Ok(false), |_| panic!("no doze while busy"), block).unwrap();
        }
        assert_eq!((blocks.get(), w.counts.busy, w.counts.blocked, w.counts.caught), (1001, 1001, 0, 0));
        // Still busy at the next try: twice as many waits block before the one after.
        w.yield_cpu = || true;
        w.wait(Some(now_ns()), u64::MAX, || Ok(false), |_| Ok(()), || Ok(())).unwrap();
        assert_eq!(w.busy_waits_left, 2 * BUSY_WAITS);
        w.busy_waits_left = 0;
        w.yield_cpu = || false;
        let here = Cell::new(false);
        let doze = |_| {
            dozes.set(dozes.get() + 1);
            here.set(true);
            Ok(())
        };
        w.wait(Some(now_ns() + HOUR), u64::MAX, || Ok(here.get()), doze, || panic!("not busy any more")).unwrap();
        assert_eq!((dozes.get(), w.counts.caught), (1, 1));
    }
}
