//! The latency budget, in milliseconds: the measured end-to-end latency (p99, p99.9, max), the
//! deadline, and the delay margin where one is known, with the headroom between them, for
//! summary.json's `latency_budget` and the report's `budget:` line.
//!
//! The delay margin is the scenario's theory (its linearised model, `ScenarioParts::delay_margin`)
//! for the loop as configured, gains included. A stage of the user's own (sensors, estimator or
//! controller) is not in that model: its margin is unknown (a sweep measures one).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::config::launch::{LaunchConfig, Mode};
use crate::contract::report::Stats;
use crate::contract::role::Role;
use crate::model::scenario::{Scenario, TheoreticalMargin};

/// The loop's deadline in ms (`deadline_us`, by default one period); None in lockstep, which has
/// no clock to keep a deadline by.
fn deadline_ms(config: &LaunchConfig) -> Option<f64> {
    (config.mode == Mode::Realtime).then(|| ms(config.deadline_ns() as f64 / 1e6))
}

/// The scenario's theoretical delay margin for the loop `config` runs, or why there is none.
pub fn theoretical_margin(config: &LaunchConfig, scenario: &dyn Scenario) -> Result<TheoreticalMargin, String> {
    if let Some(role) = Role::STAGES.into_iter().find(|role| config.stages.command(*role).is_some()) {
        return Err(format!("not the stock law: the {} is a stage of your own", role.name()));
    }
    scenario.delay_margin(config).ok_or_else(|| "the scenario has no linearised model of this loop".into())
}

/// summary.json's `latency_budget`: every figure in ms.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct LatencyBudget {
    /// End to end, plant to plant (`latency_ns.end_to_end`), in ms; None without a loop.
    pub p99_ms: Option<f64>,
    pub p999_ms: Option<f64>,
    pub max_ms: Option<f64>,
    /// The deadline (`deadline_us`, by default one loop period); None in lockstep.
    pub deadline_ms: Option<f64>,
    /// The extra command delay at which the loop goes unstable, in ms and loop periods (ticks);
    /// None where unknown.
    pub delay_margin_ms: Option<f64>,
    pub delay_margin_ticks: Option<u32>,
    /// Where the margin comes from, or why it is unknown.
    pub delay_margin_source: String,
    /// The deadline less the p99.9 (negative: loops late at p99.9).
    pub headroom_to_deadline_ms: Option<f64>,
    /// The delay margin less the p99.9: how much slower every loop could be before the loop
    /// goes unstable.
    pub headroom_to_margin_ms: Option<f64>,
}

/// Rounded to the µs, as the report prints it: the two say the same numbers.
fn ms(value: f64) -> f64 {
    (value * 1e3).round() / 1e3
}

/// The budget of a run of `config` whose end-to-end latency is `end_to_end`.
pub fn build(config: &LaunchConfig, scenario: &dyn Scenario, end_to_end: &Stats) -> LatencyBudget {
    let of_ns = |ns: Option<u64>| ns.map(|ns| ms(ns as f64 / 1e6));
    let (p99_ms, p999_ms, max_ms) = (of_ns(end_to_end.p99), of_ns(end_to_end.p999), of_ns(end_to_end.max));
    let deadline_ms = deadline_ms(config);
    let (delay_margin_ms, delay_margin_ticks, delay_margin_source) = match theoretical_margin(config, scenario) {
        Ok(m) => (
            Some(ms(f64::from(m.ticks) * 1e3 / config.rate_hz)),
            Some(m.ticks),
            "theory: the scenario's linearised sampled loop".to_string(),
        ),
        Err(why) => (None, None, format!("unknown ({why})")),
    };
    LatencyBudget {
        p99_ms,
        p999_ms,
        max_ms,
        deadline_ms,
        delay_margin_ms,
        delay_margin_ticks,
        delay_margin_source,
        headroom_to_deadline_ms: deadline_ms.zip(p999_ms).map(|(d, p)| ms(d - p)),
        headroom_to_margin_ms: delay_margin_ms.zip(p999_ms).map(|(m, p)| ms(m - p)),
    }
}

impl LatencyBudget {
    /// The report's line, every number in ms as summary.json has it.
    pub fn line(&self) -> String {
        let text = |v: Option<f64>| v.map_or("-".into(), |v| format!("{v:.3}"));
        let margin = match (self.delay_margin_ms, self.delay_margin_ticks) {
            (Some(m), Some(ticks)) => format!("delay margin {m:.3} ({ticks} ticks, {})", self.delay_margin_source),
            _ => format!("delay margin {}", self.delay_margin_source),
        };
        let (deadline, to_deadline) = match (self.deadline_ms, self.headroom_to_deadline_ms) {
            (Some(d), h) => (format!("{d:.3}"), format!("{} to the deadline", text(h))),
            (None, _) => ("n/a (lockstep)".into(), String::new()),
        };
        let to_margin = self.headroom_to_margin_ms.map(|h| format!("{h:.3} to the delay margin"));
        let headroom: Vec<String> =
            [Some(to_deadline), to_margin].into_iter().flatten().filter(|t| !t.is_empty()).collect();
        let mut line = format!(
            "budget (ms): end to end p99 {} · p99.9 {} · max {} · deadline {deadline} · {margin}",
            text(self.p99_ms),
            text(self.p999_ms),
            text(self.max_ms),
        );
        if !headroom.is_empty() {
            line.push_str(&format!(" · headroom at p99.9: {}", headroom.join(", ")));
        }
        line
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::launch::Override;
    use crate::scenarios::resolve;

    fn stats(p99: u64, p999: u64, max: u64) -> Stats {
        Stats { count: 1000, p99: Some(p99), p999: Some(p999), max: Some(max), ..Default::default() }
    }

    #[test]
    fn the_pendulums_budget_has_the_stock_laws_margin_and_a_stage_of_ones_own_has_none() {
        let (config, scenario) = resolve("pendulum", &[]).unwrap();
        let b = build(&config, scenario.as_ref(), &stats(386_000, 520_400, 1_040_000));
        assert_eq!((b.p99_ms, b.p999_ms, b.max_ms, b.deadline_ms), (Some(0.386), Some(0.52), Some(1.04), Some(1.0)));
        assert_eq!((b.delay_margin_ticks, b.delay_margin_ms), (Some(31), Some(31.0)));
        assert_eq!((b.headroom_to_deadline_ms, b.headroom_to_margin_ms), (Some(0.48), Some(30.48)));
        assert!(b.line().contains("p99.9 0.520 · max 1.040 · deadline 1.000"), "{}", b.line());
        assert!(b.line().ends_with("0.480 to the deadline, 30.480 to the delay margin"), "{}", b.line());

        // Any program stands for the user's own stage: nothing runs it here.
        let own = Override::parse(r#"stages.controller.command=["true"]"#).unwrap();
        let (config, scenario) = resolve("pendulum", &[own]).unwrap();
        let b = build(&config, scenario.as_ref(), &stats(1, 1, 1));
        assert_eq!(b.delay_margin_ms, None);
        assert_eq!(b.delay_margin_source, "unknown (not the stock law: the controller is a stage of your own)");
        assert!(b.line().contains("delay margin unknown (not the stock law"), "{}", b.line());
    }

    #[test]
    fn the_deadline_is_deadline_us_and_lockstep_has_none() {
        let short = Override::parse("deadline_us=400").unwrap();
        let (config, scenario) = resolve("pendulum", &[short]).unwrap();
        let b = build(&config, scenario.as_ref(), &stats(386_000, 520_400, 1_040_000));
        assert_eq!((b.deadline_ms, b.headroom_to_deadline_ms), (Some(0.4), Some(-0.12)));
        let lockstep = Override::parse("mode=\"lockstep\"").unwrap();
        let (config, scenario) = resolve("pendulum", &[lockstep]).unwrap();
        let b = build(&config, scenario.as_ref(), &stats(386_000, 520_400, 1_040_000));
        assert_eq!((b.deadline_ms, b.headroom_to_deadline_ms), (None, None));
        assert!(b.line().contains("deadline n/a (lockstep) · delay margin 31.000"), "{}", b.line());
        assert!(b.line().ends_with("headroom at p99.9: 30.480 to the delay margin"), "{}", b.line());
    }

    #[test]
    fn changed_gains_get_their_own_theory() {
        let gains = Override::parse("controller.gains=[-300.0, -45.0, -0.8]").unwrap();
        let (config, scenario) = resolve("pendulum", &[gains]).unwrap();
        let b = build(&config, scenario.as_ref(), &Stats::default());
        let stock =
            theoretical_margin(&resolve("pendulum", &[]).unwrap().0, resolve("pendulum", &[]).unwrap().1.as_ref());
        assert!(b.delay_margin_ticks.is_some() && b.delay_margin_ticks != stock.ok().map(|m| m.ticks), "{b:?}");
    }
}
