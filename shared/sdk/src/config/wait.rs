//! How a loop process waits for its input: the `[wait]` section of a launch file.
//!
//! - `block`: sleep on the reader's futex until its writer wakes it. Cheap, but on a virtual
//!   machine each wake-up of a halted vCPU costs tens of microseconds per hop.
//! - `spin`: poll without pause. The lowest latency, and a whole core per process.
//! - `adaptive` (real time): the loop is periodic, so the input's arrival can be predicted.
//!   The process learns the plant's schedule and how long after a tick its input arrives, sleeps
//!   on an absolute timer until `lead_us` before that, less how late its sleeps typically end
//!   (learnt: a halted vCPU takes tens of µs to wake, a busy one a few), then polls, yielding the
//!   CPU to whichever process has work, until the input is there. An input that comes early
//!   ends the sleep (it waits on the input's wake-up with the timer as its deadline), and one that
//!   comes late is polled for up to `spin_cap_us` (default: one loop period) past its due time, so
//!   that neither costs a halted-vCPU wake-up. Only an input missing for that long (its writer died
//!   or stalls) makes it block, and it goes on blocking until inputs come again. On a busy
//!   machine (a poll's yield found another task wanting the CPU) it blocks for a while, as
//!   `block` does: there a yield gives the CPU away for a whole time slice.
//!   In lockstep there is no schedule to learn: see `lockstep`.
//!
//! Lockstep has no schedule, so each hop polls, blocks, or hands off (`lockstep`): polling needs a
//! CPU per loop process, and `auto` polls when the machine has one for each process of the loop,
//! the monitor's included; otherwise it hands off: a process polls for about one handoff's time
//! (yielding its CPU) and then sleeps on its reader's futex until its writer wakes it. On two CPUs
//! that runs faster than polling (the stage whose turn it is gets a CPU) at half its CPU time.

use serde::{Deserialize, Serialize};

use crate::contract::role::Role;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, strum::IntoStaticStr)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
#[strum(serialize_all = "lowercase")]
pub enum Strategy {
    Block,
    Spin,
    Adaptive,
}

impl Strategy {
    pub fn name(self) -> &'static str {
        self.into()
    }
}

/// How the loop's processes wait in lockstep.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, strum::IntoStaticStr)]
#[serde(rename_all = "lowercase")]
#[strum(serialize_all = "lowercase")]
pub enum LockstepWait {
    /// Poll when the machine has a CPU for every process of the loop, else hand off.
    Auto,
    /// Poll, yielding the CPU between looks, whatever the machine.
    Poll,
    /// Sleep until the input's wake-up.
    Block,
    /// Poll for [`HANDOFF_POLL_US`], yielding the CPU between looks, then sleep until woken.
    Handoff,
}

/// How long a handing-off process polls before it sleeps, µs: about one loop of four hops in
/// lockstep on a 2-CPU virtual machine (measured: 5 µs a hop), so that an input that follows
/// its writer's CPU time closely is caught without a wake-up, and a process whose turn is far
/// off sleeps.
pub const HANDOFF_POLL_US: u64 = 20;

/// CPUs that every process of the loop polling needs: one each, the monitor's included (lockstep's
/// `auto` polls only with them, and the bench spins only with them).
pub const CPUS_TO_POLL: usize = Role::ALL.len();

/// The longest `lead_us` and `spin_cap_us`, µs: a second, far beyond any loop period worth
/// polling through.
pub const MAX_WAIT_US: f64 = 1e6;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WaitSettings {
    /// Every loop process's strategy, unless its own key below says otherwise.
    pub strategy: Strategy,
    pub plant: Option<Strategy>,
    pub sensors: Option<Strategy>,
    pub estimator: Option<Strategy>,
    pub controller: Option<Strategy>,
    /// Adaptive: wake up this long before the input is due, on top of how late this process's
    /// sleeps typically end (learnt), µs.
    pub lead_us: f64,
    /// Adaptive: poll at most this long past the due time before blocking, µs; absent, one loop
    /// period.
    pub spin_cap_us: Option<f64>,
    /// Pin the loop processes to CPUs so that consecutive stages sit on different CPUs (plant,
    /// sensors, estimator, controller on CPUs 0, 1, 2, 3, modulo the CPUs there are): each hop's
    /// reader then waits on another CPU than its writer's.
    pub pin: bool,
    /// Lockstep: poll, block or hand off at each hop (`auto`: poll when there is a CPU per
    /// process, else hand off).
    pub lockstep: LockstepWait,
}

impl Default for WaitSettings {
    fn default() -> Self {
        Self {
            strategy: Strategy::Block,
            plant: None,
            sensors: None,
            estimator: None,
            controller: None,
            lead_us: 5.0,
            spin_cap_us: None,
            pin: false,
            lockstep: LockstepWait::Auto,
        }
    }
}

impl WaitSettings {
    pub fn for_process(&self, role: Role) -> Strategy {
        let own = match role {
            Role::Plant => self.plant,
            Role::Sensors => self.sensors,
            Role::Estimator => self.estimator,
            Role::Controller => self.controller,
            Role::Monitor | Role::Bridge | Role::BridgeRemote => None,
        };
        own.unwrap_or(self.strategy)
    }

    /// `lockstep = "auto"` decided for a machine with `cpus` CPUs: the launcher writes it so into
    /// the run's launch.toml, so that every process of the run waits, and wakes its reader, the
    /// same way, and the run says which was used.
    pub fn decided_for(&self, cpus: usize) -> Self {
        Self { lockstep: self.lockstep_on(cpus), ..self.clone() }
    }

    /// How lockstep waits on a machine with `cpus` CPUs (never `Auto`).
    pub fn lockstep_on(&self, cpus: usize) -> LockstepWait {
        match self.lockstep {
            LockstepWait::Auto if cpus >= CPUS_TO_POLL => LockstepWait::Poll,
            LockstepWait::Auto => LockstepWait::Handoff,
            chosen => chosen,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn per_process_strategy_overrides_the_default() {
        let s = WaitSettings { strategy: Strategy::Adaptive, plant: Some(Strategy::Spin), ..Default::default() };
        assert_eq!(s.for_process(Role::Plant), Strategy::Spin);
        assert_eq!(s.for_process(Role::Sensors), Strategy::Adaptive);
    }
}
