//! The in-loop faults a stage applies to itself (delay, drop, corrupt), and the cut this
//! machine's bridge applies to the link, by loop index k, and what each means in each mode:
//! this is the one place that decides it.

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

/// What a bridge does with a frame of one loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OnLink {
    Pass,
    /// Real time: the link is cut; the frame is not sent, or not published if it came.
    Drop,
    /// Lockstep: the link is cut, but the loop must go on: the frame passes marked lost, as a
    /// lockstep `drop` sends its output, and the plant holds its command.
    MarkLost,
}

/// The `cut` faults of the link, as this machine's bridge applies them to every frame both
/// ways, by the frame's loop index.
#[derive(Debug, Clone, Default)]
pub struct LinkCut {
    windows: Vec<(u64, Option<u64>)>,
    lockstep: bool,
}

impl LinkCut {
    /// The cuts `bridge` applies: this machine's bridge applies every cut; the other host's none.
    pub fn for_bridge(config: &LaunchConfig, bridge: Role) -> Self {
        let windows = config
            .faults
            .iter()
            .filter(|f| f.kind == FaultKind::Cut && f.process == bridge.name())
            .map(|f| f.ticks(config.rate_hz))
            .collect();
        Self { windows, lockstep: config.mode == Mode::Lockstep }
    }

    pub fn on_link(&self, k: u64) -> OnLink {
        let cut = self.windows.iter().any(|&(from, until)| k >= from && until.is_none_or(|u| k < u));
        match (cut, self.lockstep) {
            (false, _) => OnLink::Pass,
            (true, false) => OnLink::Drop,
            (true, true) => OnLink::MarkLost,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::launch::Override;

    /// The pendulum at 1 kHz (10 ms is loop 10) with these faults.
    fn faults(mode: &str, role: Role, faults: &[&str]) -> StageFaults {
        let mut overrides = vec![Override::parse(&format!("mode=\"{mode}\"")).unwrap()];
        overrides.extend(faults.iter().map(|f| Override::fault(f).unwrap()));
        let config = crate::config::launch::test_pendulum(&overrides).unwrap();
        StageFaults::for_role(&config, role)
    }

    #[test]
    fn a_window_covers_its_first_loop_and_not_its_end() {
        let f = faults("lockstep", Role::Controller, &["corrupt controller out-of-range at 10ms for 5ms"]);
        let covered: Vec<u64> = (0..30).filter(|&k| f.corrupt(k).is_some()).collect();
        assert_eq!(covered, (10..15).collect::<Vec<_>>());
        assert_eq!(f.corrupt(10), Some(CorruptValue::OutOfRange));
        // Without a duration a fault lasts to the end of the run.
        let f = faults("lockstep", Role::Controller, &["corrupt controller at 10ms"]);
        assert_eq!((f.corrupt(9), f.corrupt(9999)), (None, Some(CorruptValue::default())));
    }

    #[test]
    fn a_stage_applies_only_its_own_in_loop_faults() {
        let all = ["delay sensors by 2 ticks at 0s", "kill controller at 5ms", "stop controller at 5ms for 1ms"];
        let mut f = faults("lockstep", Role::Controller, &all);
        assert!((0..100).all(|k| f.delay(k).is_none() && !f.drops(k) && f.corrupt(k).is_none()));
        assert_eq!(f.max_delay_ticks(), 0);
        let f = faults("lockstep", Role::Sensors, &all);
        assert_eq!(f.delay(0), Some(AddedDelay::Ticks(2)));
    }

    #[test]
    fn a_delay_is_ticks_in_lockstep_and_wall_time_in_real_time() {
        let delays = ["delay controller by 4 ticks at 0s for 10ms", "delay controller by 7ms at 20ms for 10ms"];
        let lockstep = faults("lockstep", Role::Controller, &delays);
        assert_eq!((lockstep.delay(0), lockstep.delay(25)), (Some(AddedDelay::Ticks(4)), Some(AddedDelay::Ticks(7))));
        assert_eq!((lockstep.delay(10), lockstep.max_delay_ticks()), (None, 7));
        let realtime = faults("realtime", Role::Controller, &delays);
        let wall = |k| match realtime.delay(k) {
            Some(AddedDelay::Wall(d)) => (d.as_secs_f64() * 1e6).round() as u64,
            other => panic!("{other:?}"),
        };
        assert_eq!((wall(0), wall(25)), (4000, 7000));
        assert_eq!(realtime.max_delay_ticks(), 7, "the history a lockstep run would keep");
    }

    #[test]
    fn drops_are_drawn_only_inside_the_window_from_the_stages_own_stream() {
        let drop = ["drop controller 50% at 10ms for 100ms", "drop estimator 50% at 10ms for 100ms"];
        let draws = |f: &mut StageFaults, ks: std::ops::Range<u64>| ks.map(|k| f.drops(k)).collect::<Vec<_>>();
        let first = draws(&mut faults("lockstep", Role::Controller, &drop), 10..110);
        let mut again = faults("realtime", Role::Controller, &drop);
        assert!(draws(&mut again, 0..10).iter().all(|d| !d), "nothing before the window");
        assert_eq!(draws(&mut again, 10..110), first, "the same loops drop, whatever the mode or what came before");
        let estimator = draws(&mut faults("lockstep", Role::Estimator, &drop), 10..110);
        assert_ne!(estimator, first, "each process draws from its own stream");
        let mut all = faults("lockstep", Role::Controller, &["drop controller 100% at 0s"]);
        let mut none = faults("lockstep", Role::Controller, &["drop controller 0% at 0s"]);
        assert!((0..50).all(|k| all.drops(k) && !none.drops(k)));
    }

    #[test]
    fn a_cut_drops_its_loops_in_real_time_and_marks_them_lost_in_lockstep_on_this_machines_bridge_only() {
        let cut = |mode: &str, bridge: Role| {
            let overrides = [
                Override::parse(&format!("mode=\"{mode}\"")).unwrap(),
                Override::parse("hosts.controller=\"companion\"").unwrap(),
                Override::parse("hosts.companion.address=\"10.0.0.2\"").unwrap(),
                Override::parse("hosts.companion.command=[\"ssh\", \"companion\"]").unwrap(),
                Override::fault("cut bridge at 10ms for 5ms").unwrap(),
            ];
            let config = crate::config::launch::test_pendulum(&overrides).unwrap();
            LinkCut::for_bridge(&config, bridge)
        };
        let realtime = cut("realtime", Role::Bridge);
        let dropped: Vec<u64> = (0..30).filter(|&k| realtime.on_link(k) == OnLink::Drop).collect();
        assert_eq!(dropped, (10..15).collect::<Vec<_>>());
        let lockstep = cut("lockstep", Role::Bridge);
        assert_eq!(
            (lockstep.on_link(9), lockstep.on_link(10), lockstep.on_link(15)),
            (OnLink::Pass, OnLink::MarkLost, OnLink::Pass)
        );
        let remote = cut("realtime", Role::BridgeRemote);
        assert!((0..30).all(|k| remote.on_link(k) == OnLink::Pass), "one end applies it, both ways");
    }
}
