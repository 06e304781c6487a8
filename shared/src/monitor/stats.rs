//! Latency distributions: an HDR histogram per hop, end to end, the plant's tick timing and
//! each sensor's data age, summarised as `contract::report::Stats`.

use crate::contract::report::HOPS;
use crate::monitor::crossing::Crossing;
pub use crate::monitor::distribution::{Distribution, histogram};
use crate::monitor::join::LoopParts;

/// Every distribution the report gives, fed one joined loop at a time.
#[derive(serde::Serialize, serde::Deserialize)]
pub struct LoopStats {
    pub end_to_end: Distribution,
    pub hops: [Distribution; HOPS.len()],
    /// |actual tick period − dt|, for the ticks the plant woke for on its clock.
    pub plant_tick_jitter: Distribution,
    /// Wake-up time − the time the first tick it served was due: its own, or, after ticks the
    /// plant skipped, the first skipped one's (that much later it woke for them).
    pub plant_wake_latency: Distribution,
    /// The plant's `skipped_ticks` in the newest state seen: the next state's tells how many
    /// ticks were skipped before it.
    #[serde(default)]
    skipped_ticks: u64,
    /// Per sensor, in the launch file's order.
    pub data_age: Vec<Distribution>,
    period_ns: i64,
    /// The loop runs in wall-clock time: the time command k took to take effect adds to the age
    /// of the data it used.
    wall_clock: bool,
    /// With a stage on another host: its hops across the link, recorded clock-corrected.
    pub crossing: Option<Crossing>,
}

impl LoopStats {
    pub fn new(sensors: usize, period_ns: u64, wall_clock: bool) -> Self {
        Self {
            end_to_end: Distribution::default(),
            hops: Default::default(),
            plant_tick_jitter: Distribution::default(),
            plant_wake_latency: Distribution::default(),
            skipped_ticks: 0,
            data_age: (0..sensors).map(|_| Distribution::default()).collect(),
            period_ns: period_ns as i64,
            wall_clock,
            crossing: None,
        }
    }

    /// With the hops of a stage on another host recorded by `crossing`.
    pub fn with_crossing(self, crossing: Option<Crossing>) -> Self {
        Self { crossing, ..self }
    }

    /// |a tick's period − dt|.
    pub fn tick_period_error(&self, period_ns: u64) -> u64 {
        (period_ns as i64 - self.period_ns).unsigned_abs()
    }

    /// Records loop `k` at simulation time `t`.
    pub fn observe(&mut self, t: f64, parts: &LoopParts) {
        if let Some(state) = &parts.state {
            let timing = state.timing;
            // Tick 0 is published at start, not on a timer wake-up; in lockstep the plant has
            // no clock and every timing is zero.
            let skipped = state.counters.skipped_ticks.saturating_sub(self.skipped_ticks);
            self.skipped_ticks = self.skipped_ticks.max(state.counters.skipped_ticks);
            if timing.period_ns > 0 {
                self.plant_tick_jitter.record(self.tick_period_error(timing.period_ns));
                // Tick k's due time is `scheduled_ns`; the first skipped tick's, that many
                // periods before.
                let due = timing.scheduled_ns.saturating_sub(skipped * self.period_ns as u64);
                self.plant_wake_latency.record(timing.wake_ns.saturating_sub(due));
            }
        }
        let (Some(e2e), Some(hops)) = (parts.end_to_end_ns(), parts.hops_ns()) else {
            return;
        };
        self.end_to_end.record(e2e);
        for (i, (distribution, ns)) in self.hops.iter_mut().zip(hops).enumerate() {
            if !self.crossing.as_ref().is_some_and(|c| c.crosses(i)) {
                distribution.record(ns);
            }
        }
        if let (Some(crossing), Some(record)) = (&mut self.crossing, &parts.record) {
            crossing.observe(&record.header.trace, &mut self.hops);
        }
        if let Some(meas) = &parts.measurements {
            // Simulation-time age of the sample used, plus (in wall-clock time) the time the
            // command took to take effect.
            let actuation = if self.wall_clock { e2e as f64 } else { 0.0 };
            for (distribution, reading) in self.data_age.iter_mut().zip(&meas.readings) {
                if reading.valid != 0 {
                    distribution.record(((t - reading.sample_time) * 1e9 + actuation).round().max(0.0) as u64);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contract::msg::{LoopRecord, Measurements, PlantState, TickTiming};
    use crate::contract::report::Stats;

    #[test]
    fn stats_keep_exact_extremes_and_mean() {
        let mut d = Distribution::default();
        assert_eq!(d.stats(), Stats::default());
        for ns in [1000, 2000, 5001] {
            d.record(ns);
        }
        let s = d.stats();
        assert_eq!((s.count, s.min, s.max, s.mean), (3, Some(1000), Some(5001), Some(2667.0)));
        // 5001 falls in the bucket 5000..=5003, whose highest value HDR reports: clamped to the max.
        assert_eq!(d.quantile(0.999), Some(5003));
        assert_eq!(s.p999, Some(5001));
        assert_eq!(s.p50, Some(2000));
    }

    fn loop_at(k: u64, sample_time: f64, timing: TickTiming) -> LoopParts {
        let state = PlantState { timing, ..Default::default() };
        let mut record = LoopRecord::default();
        record.header.k = k;
        record.header.trace.plant_publish = 1_000;
        record.header.trace.plant_receive = 1_000 + 400_000;
        let mut meas = Measurements::default();
        meas.readings[0].valid = 1;
        meas.readings[0].sample_time = sample_time;
        LoopParts { state: Some(state), measurements: Some(meas), record: Some(record), ..Default::default() }
    }

    #[test]
    fn data_age_adds_the_actuation_time_only_in_wall_clock_time() {
        let timing = TickTiming { scheduled_ns: 5_000_000, wake_ns: 5_020_000, period_ns: 1_003_000 };
        let mut realtime = LoopStats::new(1, 1_000_000, true);
        let mut lockstep = LoopStats::new(1, 1_000_000, false);
        // Loop 5 (t = 5 ms) used a sample taken at 3 ms.
        realtime.observe(0.005, &loop_at(5, 0.003, timing));
        lockstep.observe(0.005, &loop_at(5, 0.003, TickTiming::default()));
        assert_eq!(realtime.data_age[0].stats().max, Some(2_000_000 + 400_000));
        assert_eq!(lockstep.data_age[0].stats().max, Some(2_000_000));
        assert_eq!(realtime.plant_tick_jitter.stats().max, Some(3_000));
        assert_eq!(realtime.plant_wake_latency.stats().max, Some(20_000));
        assert_eq!(lockstep.plant_tick_jitter.stats().count, 0, "no clock in lockstep");
        assert_eq!(lockstep.end_to_end.stats().max, Some(400_000));
        assert_eq!(lockstep.hops[6].stats().count, 1);
    }

    #[test]
    fn a_tick_after_skipped_ticks_woke_late_from_the_first_ones_due_time() {
        let mut stats = LoopStats::new(1, 1_000_000, true);
        let mut tick = |k: u64, wake_late_ns: u64, skipped_ticks: u64| {
            let timing =
                TickTiming { scheduled_ns: k * 1_000_000, wake_ns: k * 1_000_000 + wake_late_ns, period_ns: 1 };
            let mut parts = loop_at(k, 0.0, timing);
            parts.state.as_mut().unwrap().counters.skipped_ticks = skipped_ticks;
            stats.observe(k as f64 * 0.001, &parts);
        };
        tick(1, 20_000, 0);
        // Ticks 2 to 4 skipped: tick 5 woke 30 µs after its own due time, 3 ms + 30 µs after tick 2's.
        tick(5, 30_000, 3);
        tick(6, 40_000, 3);
        let wake = &stats.plant_wake_latency;
        assert_eq!((wake.stats().count, wake.stats().min, wake.max()), (3, Some(20_000), Some(3_030_000)));
    }
}
