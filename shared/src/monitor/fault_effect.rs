//! What each fault of the launch file did, followed through the loops as they are joined: the
//! command outage, when the loop was whole again, the worst error and the recovery time.
//!
//! In real time a kill or a stop happens when the launcher sends its signal, which a stopped or
//! starved launcher sends late: its tracker waits for the loop at which it really happened
//! ([`crate::monitor::injections`]), keeping what it needs of each loop from the planned one on,
//! and judges the effect from there.

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

use crate::config::faults::FaultKind;
use crate::config::launch::LaunchConfig;
use crate::contract::report::FaultEffect;
use crate::contract::role::Role;
use crate::model::scenario::ErrorMeasure;
use crate::monitor::fault_phases::{LoopFacts, Phase, PhaseTally};
use crate::monitor::join::LoopParts;

/// Loops a tracker keeps while it waits for its fault's injection: the launcher's lateness and
/// the monitor's time to hear of it (a checkpoint, 100 ms) are far shorter. Past it, the oldest
/// loops count as before the fault.
const AWAITED_LOOPS: usize = 1 << 15;

/// What the tracker needs of one loop.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct Seen {
    k: u64,
    /// The target process's incarnation in the loop's record.
    incarnation: Option<u32>,
    /// The loop's record says its command was fresh.
    fresh: bool,
    /// What the before/during/after split needs of it (its error measure too).
    facts: LoopFacts,
}

/// A fault injected from outside, in real time, whose injection the monitor has not heard of.
#[derive(Serialize, Deserialize)]
struct Awaiting {
    /// The loops from its planned tick on, in order.
    log: VecDeque<Seen>,
    /// The planned starts of the faults after it, and the run's end: its window ends at the
    /// first after its real injection.
    later_starts: Vec<u64>,
    loops: u64,
}

/// Follows one fault through the loops the monitor writes. Serialisable: a restarted monitor
/// goes on from the last one's.
#[derive(Serialize, Deserialize)]
pub struct FaultTracker {
    kind: FaultKind,
    /// The process it is done to (None: not a loop process, such as a bridge).
    role: Option<Role>,
    /// The process's slot in `Header::incarnations`, if it has one.
    slot: Option<usize>,
    from: u64,
    /// The first tick after the fault.
    end: u64,
    /// The first tick of the next fault, or the end of the run.
    window_end: u64,
    /// Ticks in a second.
    second: u64,
    incarnation_before: Option<u32>,
    /// A kill: the fault is over once the restarted process is in the loop.
    after_restart: bool,
    back: Option<u64>,
    rejoined: Option<u64>,
    last_outside: Option<u64>,
    /// A loop of its window was recorded.
    recorded: bool,
    /// Real time, a kill or a stop: its injection is not known yet.
    awaiting: Option<Awaiting>,
    /// The launcher did not inject it (its process was not running).
    not_injected: bool,
    /// The run's planned loops.
    loops: u64,
    /// The run split at this fault: before, during, after.
    phases: PhaseTally,
    effect: FaultEffect,
}

impl FaultTracker {
    /// One tracker per fault of the launch file, in its order. `wall_clock`: the loop runs in
    /// wall-clock time, so that a `stop` (which lasts wall-clock time) lasts for the loop too.
    pub fn for_faults(config: &LaunchConfig, wall_clock: bool) -> Vec<Self> {
        let loops = config.loops();
        let starts: Vec<u64> = config.faults.iter().map(|f| f.ticks(config.rate_hz).0).collect();
        config
            .faults
            .iter()
            .zip(&starts)
            .map(|(f, &from)| {
                let end = match f.kind {
                    FaultKind::Kill => from,
                    FaultKind::Stop if !wall_clock => from,
                    FaultKind::Stop => from + (f.duration_s.unwrap_or_default() * config.rate_hz).round() as u64,
                    _ => f.ticks(config.rate_hz).1.unwrap_or(loops),
                };
                let window_end = starts.iter().copied().filter(|&s| s > from).min().unwrap_or(loops);
                let awaiting = (wall_clock && f.kind.from_outside()).then(|| Awaiting {
                    log: VecDeque::new(),
                    later_starts: starts.iter().copied().filter(|&s| s > from).collect(),
                    loops,
                });
                let role = f.process.parse::<Role>().ok();
                Self {
                    kind: f.kind,
                    role,
                    slot: role.and_then(Role::slot),
                    from,
                    end,
                    window_end,
                    second: config.rate_hz.round() as u64,
                    incarnation_before: None,
                    after_restart: f.kind == FaultKind::Kill,
                    back: None,
                    rejoined: None,
                    last_outside: None,
                    recorded: false,
                    awaiting,
                    not_injected: false,
                    loops,
                    phases: PhaseTally::default(),
                    effect: FaultEffect { within_limits: true, ..Default::default() },
                }
            })
            .collect()
    }

    /// Takes loop `k`, recorded by monitor `recorder` (its incarnation); loops come in order.
    pub fn observe(&mut self, k: u64, part: &LoopParts, recorder: u32, measure: &ErrorMeasure) {
        // The loop's record names each stage's incarnation; the monitor is the one recording it.
        let incarnation = match self.role {
            Some(Role::Monitor) => Some(recorder),
            _ => self.slot.zip(part.record.as_ref()).map(|(i, r)| r.header.incarnations[i]),
        };
        let fresh = part.record.as_ref().is_some_and(|r| r.deadline_miss == 0 && r.rejected == 0 && r.lost == 0);
        // Every loop's error: the before/during/after split covers the whole run.
        let error = part.state.as_ref().map(|s| (measure.of_state)(s.header.t, &s.x));
        let facts = LoopFacts {
            state: part.state.is_some(),
            commanded: part.record.is_some(),
            in_time: part.record.as_ref().is_some_and(|r| r.deadline_miss == 0),
            end_to_end_ns: part.end_to_end_ns(),
            error,
        };
        let seen = Seen { k, incarnation, fresh, facts };
        match &mut self.awaiting {
            Some(awaiting) if k >= self.from => {
                awaiting.log.push_back(seen);
                if awaiting.log.len() > AWAITED_LOOPS
                    && let Some(oldest) = awaiting.log.pop_front()
                {
                    // Past the bound the oldest loops count as before the fault.
                    self.incarnation_before = oldest.incarnation.or(self.incarnation_before);
                    self.phases.add(Phase::Before, &oldest.facts);
                }
            }
            _ => self.take(seen, measure),
        }
    }

    /// The fault's kind, if it is of `role` and its outage covers loop `k`: from its injection
    /// (the planned tick until the real one is known) until commands are back in time, within
    /// its window (up to the next fault). Loop k must have been observed.
    pub fn blames(&self, k: u64, role: Role) -> Option<FaultKind> {
        let covers = k >= self.from && k < self.window_end && self.back.is_none_or(|back| k < back);
        (self.role == Some(role) && covers && !self.not_injected).then_some(self.kind)
    }

    /// The kill or stop of a loop process whose outage covers loop `k`, if this is one: no loop
    /// can get its command through a process that is not running, whatever else held it up.
    pub fn outage(&self, k: u64) -> Option<(FaultKind, Role)> {
        let role = self.role.filter(|r| r.in_loop())?;
        (self.kind.from_outside() && self.blames(k, role).is_some()).then_some((self.kind, role))
    }

    /// The launcher injected the fault before loop `k` (real time): its effect is judged from
    /// there, on the loops kept meanwhile first. Once only; nothing if it was not awaited.
    pub fn injected_at(&mut self, k: u64, measure: &ErrorMeasure) {
        let Some(awaiting) = self.awaiting.take() else { return };
        // Never before its planned tick: the plant's period is rounded to whole ns.
        let shift = k.saturating_sub(self.from);
        self.from += shift;
        // A stop's SIGCONT comes its duration after the real injection.
        self.end += shift;
        self.window_end =
            awaiting.later_starts.iter().copied().filter(|&s| s > self.from).min().unwrap_or(awaiting.loops);
        for seen in awaiting.log {
            self.take(seen, measure);
        }
    }

    /// The launcher did not inject the fault (its process was not running at its time).
    pub fn not_injected(&mut self) {
        if self.awaiting.take().is_some() {
            self.not_injected = true;
        }
    }

    /// Takes one loop, the fault's injection known.
    fn take(&mut self, seen: Seen, measure: &ErrorMeasure) {
        let Seen { k, incarnation, fresh, facts } = seen;
        if k < self.from {
            self.incarnation_before = incarnation.or(self.incarnation_before);
            self.phases.add(Phase::Before, &facts);
            return;
        }
        if k >= self.window_end {
            let phase = if self.back.is_some() { Phase::After } else { Phase::During };
            self.phases.add(phase, &facts);
            return;
        }
        let error = facts.error;
        self.recorded = true;
        if self.rejoined.is_none()
            && self.incarnation_before.is_some()
            && incarnation.is_some_and(|i| Some(i) != self.incarnation_before)
        {
            self.rejoined = Some(k);
        }
        // After a kill, commands are back once they carry the restarted process's work (a
        // command or two may still come from before the kill landed).
        let restarted = !self.after_restart || self.rejoined.is_some();
        if self.back.is_none() {
            if fresh && k >= self.end && restarted {
                self.back = Some(k);
            } else if !fresh {
                self.effect.outage_ticks += 1;
            }
        }
        self.phases.add(if self.back.is_some() { Phase::After } else { Phase::During }, &facts);
        if let Some(error) = error {
            if measure.beyond(error) && self.effect.limit_exceeded_at_s.is_none() {
                // Loop index for now; `finish` turns it into simulation time.
                self.effect.limit_exceeded_at_s = Some(k as f64);
            }
            let worst = if self.back.is_none() {
                &mut self.effect.worst_error_during
            } else {
                &mut self.effect.worst_error_after
            };
            *worst = Some(worst.map_or(error, |w: f64| w.max(error)));
            let peak = |p: &mut Option<f64>| *p = Some(p.map_or(error, |v: f64| v.max(error)));
            if k < self.from + self.second {
                peak(&mut self.effect.error_peak_first_s);
            }
            if k + self.second >= self.window_end {
                peak(&mut self.effect.error_peak_last_s);
            }
            if measure.beyond(error) {
                self.effect.within_limits = false;
            }
            if measure.outside_band(error) {
                self.last_outside = Some(k);
            }
        }
    }

    /// The fault's effect, with loop indices turned into simulation time, k / rate exactly as
    /// the recorder's `t` (k·dt would print 0.009000000000000001).
    pub fn finish(mut self, rate_hz: f64) -> FaultEffect {
        let at = |k: u64| k as f64 / rate_hz;
        // Still awaited at the end: the run ended before the launcher injected it.
        if self.not_injected || self.awaiting.is_some() {
            return FaultEffect { not_injected: true, unrecorded: true, within_limits: true, ..Default::default() };
        }
        self.effect.unrecorded = !self.recorded;
        self.effect.limit_exceeded_at_s = self.effect.limit_exceeded_at_s.map(|k| at(k as u64));
        // A killed process that never came back: the loop never recovered from its loss, whatever
        // the error did meanwhile.
        self.effect.never_back = self.after_restart && self.rejoined.is_none() && self.recorded;
        self.effect.phases = Some(self.phases.finish(self.from, self.back, self.loops));
        self.effect.commands_back_at_s = self.back.map(at);
        self.effect.rejoined_at_s = self.rejoined.map(at);
        self.effect.recovery_s = match self.last_outside {
            _ if self.end >= self.window_end || self.effect.never_back => None,
            None => Some(0.0),
            Some(k) if k < self.end => Some(0.0),
            Some(k) if k + 1 >= self.window_end => None,
            Some(k) => Some(at(k + 1 - self.end)),
        };
        self.effect
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::launch::Override;
    use crate::contract::msg::{LoopRecord, PlantState};
    use crate::scenarios::resolve;

    /// A pendulum run of 20 loops at 1 kHz with these faults.
    fn config(faults: &[&str]) -> LaunchConfig {
        let mut overrides = vec![Override::parse("duration_s=0.02").unwrap()];
        overrides.extend(faults.iter().map(|f| Override::fault(f).unwrap()));
        resolve("pendulum", &overrides).unwrap().0
    }

    /// The error is the first state component; back within 0.1, fallen at 1.
    fn measure() -> ErrorMeasure {
        ErrorMeasure {
            name: "error",
            of_state: std::sync::Arc::new(|_, x| x[0]),
            recovery_band: 0.1,
            limit: 1.0,
            limit_key: "limits.error",
            lost_beyond: None,
            judged_from_s: 0.0,
        }
    }

    /// Loop k with error `error`; its record (if any) says whether the command was lost and
    /// which estimator incarnation handled it.
    fn loop_with(error: f64, record: Option<(bool, u32)>) -> LoopParts {
        let mut state = PlantState::default();
        state.x[0] = error;
        let record = record.map(|(lost, estimator)| {
            let mut r = LoopRecord { lost: u32::from(lost), ..Default::default() };
            r.header.incarnations[Role::Estimator.slot().unwrap()] = estimator;
            r
        });
        LoopParts { state: Some(state), record, ..Default::default() }
    }

    #[test]
    fn a_drop_then_a_kill_on_a_hand_made_trajectory() {
        let config = config(&["drop controller 50% at 5ms for 3ms", "kill estimator at 12ms"]);
        let mut trackers = FaultTracker::for_faults(&config, false);
        let ok = |error| loop_with(error, Some((false, 0)));
        let trajectory = [
            ok(0.0),
            ok(0.0),
            ok(0.0),
            ok(0.0),
            ok(0.0),
            // The drop, loops 5 to 7: two commands lost.
            loop_with(0.3, Some((true, 0))),
            loop_with(0.5, Some((true, 0))),
            ok(0.4),
            // Over at 8: fresh commands are back; the error is within 0.1 from 10 on.
            ok(0.2),
            ok(0.15),
            ok(0.05),
            ok(0.02),
            // The kill at 12: no command, then one more from the old estimator, then the new one.
            loop_with(0.3, None),
            ok(0.4),
            loop_with(0.6, Some((false, 1))),
            loop_with(1.2, Some((false, 1))),
            loop_with(0.3, Some((false, 1))),
            loop_with(0.08, Some((false, 1))),
            loop_with(0.05, Some((false, 1))),
            loop_with(0.01, Some((false, 1))),
        ];
        for (k, parts) in trajectory.iter().enumerate() {
            for tracker in &mut trackers {
                tracker.observe(k as u64, parts, 0, &measure());
            }
        }
        let rate = config.rate_hz;
        let effects: Vec<FaultEffect> = trackers.into_iter().map(|t| t.finish(rate)).collect();
        assert_eq!(
            effects[0],
            FaultEffect {
                never_back: false,
                limit_exceeded_at_s: None,
                phases: effects[0].phases.clone(),
                outage_ticks: 2,
                commands_back_at_s: Some(8.0 / rate),
                rejoined_at_s: None,
                worst_error_during: Some(0.5),
                worst_error_after: Some(0.2),
                recovery_s: Some(2.0 / rate),
                within_limits: true,
                error_peak_first_s: Some(0.5),
                error_peak_last_s: Some(0.5),
                unrecorded: false,
                not_injected: false,
            }
        );
        assert_eq!(
            effects[1],
            FaultEffect {
                never_back: false,
                limit_exceeded_at_s: Some(15.0 / rate),
                phases: effects[1].phases.clone(),
                outage_ticks: 1,
                commands_back_at_s: Some(14.0 / rate),
                rejoined_at_s: Some(14.0 / rate),
                worst_error_during: Some(0.4),
                worst_error_after: Some(1.2),
                recovery_s: Some(5.0 / rate),
                within_limits: false,
                error_peak_first_s: Some(1.2),
                error_peak_last_s: Some(1.2),
                unrecorded: false,
                not_injected: false,
            }
        );
    }

    /// At an error equal to the limit, the fault's report says what the verdict says: within.
    #[test]
    fn an_error_equal_to_the_limit_is_within_it_as_for_the_verdict() {
        let config = config(&["delay controller by 2 ticks at 5ms"]);
        let mut trackers = FaultTracker::for_faults(&config, false);
        let mut watch = crate::contract::limits::LimitsWatch::default();
        for k in 0..20 {
            let error = if k >= 5 { measure().limit } else { 0.0 };
            trackers[0].observe(k, &loop_with(error, Some((false, 0))), 0, &measure());
            watch.observe(k as f64 / config.rate_hz, error, measure().limit, None);
        }
        let effect = trackers.pop().unwrap().finish(config.rate_hz);
        assert!(effect.within_limits);
        assert_eq!(effect.limit_exceeded_at_s, None);
        assert_eq!(watch.exceeded_at_s, None);
        let mut trackers = FaultTracker::for_faults(&config, false);
        trackers[0].observe(6, &loop_with(f64::NAN, Some((false, 0))), 0, &measure());
        assert!(!trackers.pop().unwrap().finish(config.rate_hz).within_limits, "NaN is beyond");
    }

    #[test]
    fn an_error_still_outside_at_the_end_has_no_recovery() {
        let config = config(&["delay controller by 2 ticks at 5ms"]);
        let mut trackers = FaultTracker::for_faults(&config, false);
        for k in 0..20 {
            let error = if k >= 5 { 0.5 } else { 0.0 };
            trackers[0].observe(k, &loop_with(error, Some((false, 0))), 0, &measure());
        }
        let effect = trackers.pop().unwrap().finish(config.dt());
        // The delay lasts to the end of the run: no loop after it to recover in.
        assert_eq!(effect.recovery_s, None);
        assert_eq!(effect.commands_back_at_s, None);
        assert_eq!(effect.outage_ticks, 0, "delayed commands are fresh");
        assert_eq!(effect.worst_error_during, Some(0.5));
    }

    /// A pendulum run of `seconds` at 1 kHz with one fault, tracked as in real time.
    fn real_time_tracker(fault: &str, seconds: f64) -> (LaunchConfig, FaultTracker) {
        let mut overrides = vec![Override::parse(&format!("duration_s={seconds}")).unwrap()];
        overrides.push(Override::fault(fault).unwrap());
        let config = resolve("pendulum", &overrides).unwrap().0;
        let tracker = FaultTracker::for_faults(&config, true).pop().unwrap();
        (config, tracker)
    }

    /// A kill of the estimator that really happened at loop 300: no record from 300 to 499, its
    /// restarted incarnation from 500 on, the error 0.5 in the outage and back within the band
    /// at 520.
    fn killed_at_300(k: u64) -> LoopParts {
        match k {
            ..300 => loop_with(0.0, Some((false, 0))),
            300..500 => loop_with(0.5, None),
            500..520 => loop_with(0.2, Some((false, 1))),
            _ => loop_with(0.0, Some((false, 1))),
        }
    }

    #[test]
    fn a_kill_injected_late_is_judged_from_when_it_really_happened() {
        let (config, mut tracker) = real_time_tracker("kill estimator at 100ms", 1.0);
        assert_eq!((tracker.from, config.loops()), (100, 1000));
        // The monitor hears of the injection at a checkpoint, in the middle of the outage.
        for k in 0..350 {
            tracker.observe(k, &killed_at_300(k), 0, &measure());
        }
        tracker.injected_at(300, &measure());
        for k in 350..1000 {
            tracker.observe(k, &killed_at_300(k), 0, &measure());
        }
        let effect = tracker.finish(config.rate_hz);
        assert_eq!(
            effect,
            FaultEffect {
                never_back: false,
                limit_exceeded_at_s: None,
                phases: effect.phases.clone(),
                outage_ticks: 200,
                commands_back_at_s: Some(0.5),
                rejoined_at_s: Some(0.5),
                worst_error_during: Some(0.5),
                worst_error_after: Some(0.2),
                // From the injection at 300 to the first loop back within the band, 520.
                recovery_s: Some(0.22),
                within_limits: true,
                error_peak_first_s: Some(0.5),
                error_peak_last_s: Some(0.5),
                unrecorded: false,
                not_injected: false,
            }
        );
        // Split at the real injection (300) and the restarted estimator's first loop (500).
        let phases = effect.phases.unwrap();
        let spans = [&phases.before, &phases.during, &phases.after].map(|p| (p.from_k, p.to_k, p.loops, p.misses));
        assert_eq!(spans, [(0, 300, 300, 0), (300, 500, 200, 200), (500, 1000, 500, 0)]);
        assert_eq!((phases.during.error_max, phases.after.error_max), (Some(0.5), Some(0.2)));
    }

    /// A stop of the controller that really happened at loop 400, for 200 loops: no fresh
    /// command from 400 to 599.
    fn stopped_at_400(k: u64) -> LoopParts {
        let outage = (400..600).contains(&k);
        loop_with(if outage { 0.5 } else { 0.0 }, Some((outage, 0)))
    }

    #[test]
    fn a_kill_whose_process_never_came_back_never_recovered_and_is_during_to_the_end() {
        let (config, mut tracker) = real_time_tracker("kill estimator at 100ms", 1.0);
        tracker.injected_at(100, &measure());
        // No command from the kill on, and the error back within the band at once: still no
        // recovery, since the loop never had its estimator again.
        for k in 0..1000 {
            let record = (k < 100).then_some((false, 0));
            tracker.observe(k, &loop_with(if k < 100 { 0.0 } else { 0.05 }, record), 0, &measure());
        }
        let effect = tracker.finish(config.rate_hz);
        assert!(effect.never_back, "{effect:?}");
        assert_eq!((effect.recovery_s, effect.commands_back_at_s, effect.outage_ticks), (None, None, 900));
        let phases = effect.phases.unwrap();
        assert_eq!((phases.during.from_k, phases.during.to_k, phases.during.misses), (100, 1000, 900));
        assert_eq!((phases.after.loops, phases.before.loops), (0, 100));
    }

    #[test]
    fn a_killed_monitor_is_back_once_its_successor_records_a_loop() {
        let (config, mut tracker) = real_time_tracker("kill monitor at 100ms", 1.0);
        tracker.injected_at(100, &measure());
        // The first monitor recorded loops 0 to 109; loops 110 to 149 went by with none; its
        // successor (incarnation 1) records from 150 on. The loop itself never lost a command.
        for k in (0..110).chain(150..1000) {
            let recorder = u32::from(k >= 150);
            tracker.observe(k, &loop_with(0.0, Some((false, 0))), recorder, &measure());
        }
        let effect = tracker.finish(config.rate_hz);
        assert!(!effect.never_back, "{effect:?}");
        assert_eq!((effect.rejoined_at_s, effect.commands_back_at_s), (Some(0.15), Some(0.15)), "{effect:?}");
        assert_eq!((effect.outage_ticks, effect.recovery_s), (0, Some(0.0)), "{effect:?}");
    }

    #[test]
    fn a_stop_injected_after_its_planned_end_has_its_whole_outage() {
        let stop = "stop controller at 100ms for 200ms";
        let (config, mut tracker) = real_time_tracker(stop, 1.0);
        // As if judged from the planned tick: over by 300, before it began.
        let (_, mut planned) = real_time_tracker(stop, 1.0);
        planned.awaiting = None;
        for k in 0..1000 {
            if k == 450 {
                tracker.injected_at(400, &measure());
            }
            tracker.observe(k, &stopped_at_400(k), 0, &measure());
            planned.observe(k, &stopped_at_400(k), 0, &measure());
        }
        let planned = planned.finish(config.rate_hz);
        assert_eq!((planned.outage_ticks, planned.commands_back_at_s), (0, Some(0.3)), "{planned:?}");
        let effect = tracker.finish(config.rate_hz);
        assert_eq!((effect.outage_ticks, effect.commands_back_at_s), (200, Some(0.6)), "{effect:?}");
        assert_eq!((effect.worst_error_during, effect.worst_error_after), (Some(0.5), Some(0.0)));
        // The SIGCONT came 200 ms after the injection: the error was back at once.
        assert_eq!(effect.recovery_s, Some(0.0));
    }

    #[test]
    fn a_fault_never_injected_is_reported_so_not_as_kept() {
        let (config, mut tracker) = real_time_tracker("kill estimator at 100ms", 1.0);
        let (_, mut told) = real_time_tracker("kill estimator at 100ms", 1.0);
        for k in 0..1000 {
            if k == 150 {
                told.not_injected();
            }
            tracker.observe(k, &loop_with(0.0, Some((false, 0))), 0, &measure());
            told.observe(k, &loop_with(0.0, Some((false, 0))), 0, &measure());
        }
        // The run ended before the launcher injected it; or it said it did not.
        for effect in [tracker.finish(config.rate_hz), told.finish(config.rate_hz)] {
            assert!(effect.not_injected && effect.unrecorded, "{effect:?}");
            assert_eq!((effect.outage_ticks, effect.worst_error_during), (0, None));
        }
    }

    #[test]
    fn an_awaited_fault_keeps_a_bounded_log_across_a_monitor_restart() {
        let (config, mut tracker) = real_time_tracker("kill estimator at 100ms", 40.0);
        // Heard of long after its planned tick, 10 loops after it really happened; the
        // restarted estimator is in the loop 50 loops after that.
        let heard = 100 + AWAITED_LOOPS as u64 + 1000;
        let injected = heard - 10;
        let parts = |k: u64| match k {
            _ if k < injected => loop_with(0.0, Some((false, 0))),
            _ if k < injected + 50 => loop_with(0.0, None),
            _ => loop_with(0.0, Some((false, 1))),
        };
        for k in 0..heard {
            tracker.observe(k, &parts(k), 0, &measure());
        }
        assert_eq!(tracker.awaiting.as_ref().unwrap().log.len(), AWAITED_LOOPS);
        // Frozen into `monitor.state` and thawed by the next monitor, still awaiting.
        let bytes = crate::contract::codec::to_bytes(&tracker).unwrap();
        let mut tracker: FaultTracker = crate::contract::codec::decode(&bytes).unwrap();
        tracker.injected_at(injected, &measure());
        assert!(tracker.awaiting.is_none());
        for k in heard..heard + 100 {
            tracker.observe(k, &parts(k), 0, &measure());
        }
        let effect = tracker.finish(config.rate_hz);
        assert_eq!(effect.outage_ticks, 50, "{effect:?}");
        assert_eq!(effect.rejoined_at_s, Some((injected + 50) as f64 / 1000.0));
    }

    #[test]
    fn only_real_time_kills_and_stops_await_their_injection() {
        let config = config(&["kill plant at 5ms", "stop controller at 6ms for 3ms", "drop sensors 50% at 7ms"]);
        let awaits = |wall_clock| -> Vec<bool> {
            FaultTracker::for_faults(&config, wall_clock).iter().map(|t| t.awaiting.is_some()).collect()
        };
        assert_eq!(awaits(true), [true, true, false]);
        assert_eq!(awaits(false), [false, false, false], "lockstep: injected at their loop");
    }

    #[test]
    fn a_stop_lasts_for_the_loop_only_in_wall_clock_time() {
        let config = config(&["stop controller at 5ms for 3ms"]);
        assert_eq!(FaultTracker::for_faults(&config, true)[0].end, 8);
        assert_eq!(FaultTracker::for_faults(&config, false)[0].end, 5);
        assert_eq!(FaultTracker::for_faults(&config, false)[0].slot, Some(3));
    }
}
