//! The in-loop faults a stage applies to itself (delay, drop, corrupt), by loop index k, and
//! what each means in each mode: this is the one place that decides it.

use rand::SeedableRng;
use rand::distr::{Distribution, StandardUniform};
use rand_chacha::ChaCha8Rng;

use crate::config::faults::{CorruptValue, FaultKind, FaultSpec};
use crate::config::launch::{LaunchConfig, Mode};
use crate::contract::role::Role;

/// The faults a stage applies to itself, by loop index.
pub struct StageFaults {
    windows: Vec<Window>,
    rng: ChaCha8Rng,
    dt: f64,
    mode: Mode,
}

struct Window {
    from: u64,
    until: Option<u64>,
    spec: FaultSpec,
}

impl Window {
    fn covers(&self, k: u64) -> bool {
        k >= self.from && self.until.is_none_or(|u| k < u)
    }
}

/// The latency a delay fault adds at one loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AddedDelay {
    /// Real time: wait this long before publishing.
    Wall(std::time::Duration),
    /// Lockstep: publish what was computed this many loops ago.
    Ticks(u32),
}

impl StageFaults {
    pub fn for_role(config: &LaunchConfig, role: Role) -> Self {
        let windows = config
            .faults
            .iter()
            .filter(|f| f.process == role.name() && !f.kind.from_outside())
            .map(|f| {
                let (from, until) = f.ticks(config.rate_hz);
                Window { from, until, spec: f.clone() }
            })
            .collect();
        // One stream per process, so that faults in one do not shift another's draws.
        let seed = config.seed ^ crate::config::seed::fnv1a(&format!("faults/{role}"));
        Self { windows, rng: ChaCha8Rng::seed_from_u64(seed), dt: config.dt(), mode: config.mode }
    }

    fn active(&self, kind: FaultKind, k: u64) -> Option<&FaultSpec> {
        self.windows.iter().find(|w| w.spec.kind == kind && w.covers(k)).map(|w| &w.spec)
    }

    /// The largest delay in ticks any of its faults asks for (lockstep history to keep).
    pub fn max_delay_ticks(&self) -> u32 {
        self.windows.iter().filter_map(|w| self.ticks_of(&w.spec)).max().unwrap_or(0)
    }

    fn ticks_of(&self, spec: &FaultSpec) -> Option<u32> {
        match (spec.delay_ticks, spec.delay_s) {
            (Some(t), _) => Some(t),
            // delay_s < duration_s (checked at load): at most the run's loops, ≤ MAX_LOOPS < u32::MAX.
            (_, Some(s)) => Some((s / self.dt).round() as u32),
            _ => None,
        }
    }

    pub fn delay(&self, k: u64) -> Option<AddedDelay> {
        let spec = self.active(FaultKind::Delay, k)?;
        Some(match self.mode {
            Mode::Lockstep => AddedDelay::Ticks(self.ticks_of(spec).unwrap_or(0)),
            // delay_s < duration_s and delay_ticks ≤ loops (checked at load): finite, not
            // negative and at most about a week, so this cannot panic.
            Mode::Realtime => AddedDelay::Wall(std::time::Duration::from_secs_f64(
                spec.delay_s.unwrap_or_else(|| f64::from(spec.delay_ticks.unwrap_or(0)) * self.dt),
            )),
        })
    }

    /// Whether this loop's output is dropped. Draws one number per loop inside a drop window,
    /// so a run's drops depend only on the seed.
    pub fn drops(&mut self, k: u64) -> bool {
        let Some(p) = self.active(FaultKind::Drop, k).and_then(|s| s.probability) else { return false };
        let draw: f64 = StandardUniform.sample(&mut self.rng);
        draw < p
    }

    pub fn corrupt(&self, k: u64) -> Option<CorruptValue> {
        self.active(FaultKind::Corrupt, k).map(|s| s.value.unwrap_or_default())
    }
}
