//! How a loop process waits for its input, by the strategy of its `[wait]` settings (see
//! `crate::config::wait` for what each strategy does).

use std::collections::VecDeque;

use anyhow::Result;

use crate::config::wait::{Strategy, WaitSettings};
use crate::contract::clock::now_ns;
use crate::contract::protocol::WaitCounts;
use crate::contract::role::Role;

/// Observations kept to estimate how soon after a tick the input arrives.
const WINDOW: usize = 64;

/// Sleeps remembered to learn how late this process wakes.
const OVERSLEEP_WINDOW: usize = 32;

/// Sleeps until an absolute CLOCK_MONOTONIC time.
pub fn sleep_until(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
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
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
    // SAFETY: a zeroed cpu_set_t is a valid empty set; CPU_SET writes inside it.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(place % cpus, &mut set);
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set);
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

/// Waits for input with the process's strategy. `ready` says whether input is there;
/// `block` waits in the WaitSet (for the input or the next timer).
pub struct Waiter {
    pub strategy: Strategy,
    lead_ns: u64,
    cap_ns: u64,
    pub counts: WaitCounts,
    /// How late the last sleeps woke up, ns: a halted vCPU takes tens of µs to wake, a busy
    /// one a few; the sleep is cut short by what this process typically needs.
    oversleeps: VecDeque<u64>,
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

    /// The waiter of a loop process: its own strategy (adaptive blocks in lockstep, which has
    /// no schedule to learn), pinned to its core if the settings say so.
    pub fn new(settings: &WaitSettings, role: Role, realtime: bool) -> Self {
        let strategy = match settings.for_process(role) {
            Strategy::Adaptive if !realtime => Strategy::Block,
            s => s,
        };
        if settings.pin {
            pin_in_loop_order(role);
        }
        Self::with_strategy(settings, strategy)
    }

    /// A waiter with the given strategy and the settings' lead and cap (the bench's ends).
    pub fn with_strategy(settings: &WaitSettings, strategy: Strategy) -> Self {
        if strategy == Strategy::Adaptive {
            tighten_timer_slack();
        }
        Self {
            strategy,
            // At most MAX_WAIT_US (checked at load): well within u64 nanoseconds.
            lead_ns: (settings.lead_us * 1e3) as u64,
            cap_ns: (settings.spin_cap_us * 1e3) as u64,
            counts: WaitCounts::default(),
            oversleeps: VecDeque::with_capacity(OVERSLEEP_WINDOW),
        }
    }

    /// Waits until `ready()`, `until_ns` (for spin; block and adaptive leave that to the
    /// WaitSet's timers), or `block` returns.
    pub fn wait(
        &mut self,
        due_ns: Option<u64>,
        slice_end_ns: u64,
        mut ready: impl FnMut() -> Result<bool>,
        block: impl FnOnce() -> Result<()>,
    ) -> Result<()> {
        match self.strategy {
            Strategy::Block => block(),
            Strategy::Spin => {
                while !ready()? && now_ns() < slice_end_ns {
                    std::hint::spin_loop();
                }
                Ok(())
            }
            Strategy::Adaptive => {
                let Some(due) = due_ns else { return block() };
                if ready()? {
                    return Ok(());
                }
                let wake_at = due.saturating_sub(self.lead_ns + self.typical_oversleep());
                if wake_at > now_ns() {
                    sleep_until(wake_at);
                    if self.oversleeps.len() == OVERSLEEP_WINDOW {
                        self.oversleeps.pop_front();
                    }
                    self.oversleeps.push_back(now_ns() - wake_at);
                }
                let give_up = due.max(now_ns()) + self.cap_ns;
                while now_ns() < give_up {
                    if ready()? {
                        self.counts.caught += 1;
                        return Ok(());
                    }
                    // SAFETY: sched_yield has no preconditions.
                    unsafe { libc::sched_yield() };
                }
                self.counts.blocked += 1;
                block()
            }
        }
    }
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
    fn lockstep_blocks_whatever_the_strategy() {
        let s = WaitSettings { strategy: Strategy::Adaptive, ..Default::default() };
        assert_eq!(Waiter::new(&s, Role::Sensors, true).strategy, Strategy::Adaptive);
        assert_eq!(Waiter::new(&s, Role::Sensors, false).strategy, Strategy::Block);
    }
}
