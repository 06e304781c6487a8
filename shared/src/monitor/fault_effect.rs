//! What each fault of the launch file did, followed through the loops as they are joined: the
//! command outage, when the loop was whole again, the worst error and the recovery time.

use crate::config::faults::FaultKind;
use crate::config::launch::LaunchConfig;
use crate::contract::report::FaultEffect;
use crate::contract::role::Role;
use crate::model::scenario::ErrorMeasure;
use crate::monitor::join::LoopParts;

/// Follows one fault through the loops the monitor writes. Serialisable: a restarted monitor
/// goes on from the last one's.
#[derive(serde::Serialize, serde::Deserialize)]
pub struct FaultTracker {
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
                Self {
                    slot: f.process.parse::<Role>().ok().and_then(Role::slot),
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
                    effect: FaultEffect { within_limits: true, ..Default::default() },
                }
            })
            .collect()
    }

    /// Takes loop `k`; loops come in order.
    pub fn observe(&mut self, k: u64, part: &LoopParts, measure: &ErrorMeasure) {
        let incarnation = self.slot.zip(part.record.as_ref()).map(|(i, r)| r.header.incarnations[i]);
        if k < self.from {
            self.incarnation_before = incarnation.or(self.incarnation_before);
            return;
        }
        if k >= self.window_end {
            return;
        }
        self.recorded = true;
        if self.rejoined.is_none()
            && self.incarnation_before.is_some()
            && incarnation.is_some_and(|i| Some(i) != self.incarnation_before)
        {
            self.rejoined = Some(k);
        }
        let fresh = part.record.as_ref().is_some_and(|r| r.deadline_miss == 0 && r.rejected == 0 && r.lost == 0);
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
        if let Some(state) = &part.state {
            let error = (measure.of_state)(state.header.t, &state.x);
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
            // NaN counts as outside.
            if error.is_nan() || error >= measure.limit {
                self.effect.within_limits = false;
            }
            if error.is_nan() || error > measure.recovery_band {
                self.last_outside = Some(k);
            }
        }
    }

    /// The fault's effect, with loop indices turned into simulation time, k / rate exactly as
    /// the recorder's `t` (k·dt would print 0.009000000000000001).
    pub fn finish(mut self, rate_hz: f64) -> FaultEffect {
        let at = |k: u64| k as f64 / rate_hz;
        self.effect.unrecorded = !self.recorded;
        self.effect.commands_back_at_s = self.back.map(at);
        self.effect.rejoined_at_s = self.rejoined.map(at);
        self.effect.recovery_s = match self.last_outside {
            _ if self.end >= self.window_end => None,
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
        ErrorMeasure { name: "error", of_state: std::sync::Arc::new(|_, x| x[0]), recovery_band: 0.1, limit: 1.0 }
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
                tracker.observe(k as u64, parts, &measure());
            }
        }
        let rate = config.rate_hz;
        let effects: Vec<FaultEffect> = trackers.into_iter().map(|t| t.finish(rate)).collect();
        assert_eq!(
            effects[0],
            FaultEffect {
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
            }
        );
        assert_eq!(
            effects[1],
            FaultEffect {
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
            }
        );
    }

    #[test]
    fn an_error_still_outside_at_the_end_has_no_recovery() {
        let config = config(&["delay controller by 2 ticks at 5ms"]);
        let mut trackers = FaultTracker::for_faults(&config, false);
        for k in 0..20 {
            let error = if k >= 5 { 0.5 } else { 0.0 };
            trackers[0].observe(k, &loop_with(error, Some((false, 0))), &measure());
        }
        let effect = trackers.pop().unwrap().finish(config.dt());
        // The delay lasts to the end of the run: no loop after it to recover in.
        assert_eq!(effect.recovery_s, None);
        assert_eq!(effect.commands_back_at_s, None);
        assert_eq!(effect.outage_ticks, 0, "delayed commands are fresh");
        assert_eq!(effect.worst_error_during, Some(0.5));
    }

    #[test]
    fn a_stop_lasts_for_the_loop_only_in_wall_clock_time() {
        let config = config(&["stop controller at 5ms for 3ms"]);
        assert_eq!(FaultTracker::for_faults(&config, true)[0].end, 8);
        assert_eq!(FaultTracker::for_faults(&config, false)[0].end, 5);
        assert_eq!(FaultTracker::for_faults(&config, false)[0].slot, Some(3));
    }
}
