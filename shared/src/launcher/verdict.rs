//! The run's control outcome: what the monitor saw of the scenario's error
//! ([`LimitsWatch`]) judged against its `[limits]` ([`ErrorMeasureInfo`]) into one verdict,
//! `within limits`, `limits exceeded at t = … s (key)` or `lost`, for summary.json's `limits`,
//! the report's line and `--fail-on limits` (`launcher::gate`).
//!
//! Lost means the run cannot be counted on to come back: the error passed the scenario's point
//! of no return (the pendulum past the horizontal), or it was still beyond the limit when the
//! run ended (a vehicle that never came back), or it stopped being a number (the simulation
//! diverged). Each scenario's README says which applies to it.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::contract::limits::LimitsWatch;
use crate::model::scenario::ErrorMeasureInfo;

/// The control outcome in one word.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema, strum::Display)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// No state of the plant was recorded: nothing to judge.
    #[default]
    #[strum(serialize = "not judged")]
    NotJudged,
    #[strum(serialize = "within limits")]
    WithinLimits,
    /// Beyond the limit at some loop, back within it by the end.
    #[strum(serialize = "limits exceeded")]
    LimitsExceeded,
    #[strum(serialize = "lost")]
    Lost,
}

impl Verdict {
    /// A failure for `--fail-on limits`.
    pub fn failed(self) -> bool {
        matches!(self, Verdict::LimitsExceeded | Verdict::Lost)
    }
}

/// summary.json's `limits`: the run judged against the scenario's limit, in simulation time.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct LimitsVerdict {
    pub verdict: Verdict,
    /// The error judged, as `error_measure.name` ("|theta| rad").
    pub measure: String,
    /// The launch-file key of the limit ("limits.fall_angle_rad") and its value.
    pub limit_key: String,
    pub limit: f64,
    /// The first loop beyond the limit.
    pub exceeded_at_s: Option<f64>,
    /// The largest error, and when.
    pub worst_error: Option<f64>,
    pub worst_at_s: Option<f64>,
    /// Lost: from when, and why in words.
    pub lost_at_s: Option<f64>,
    pub lost_because: Option<String>,
    /// Loops judged (those whose true state the monitor recorded, from `judged_from_s` on).
    pub loops_judged: u64,
    /// The first simulation time judged, s (`[limits] judge_from_s`; 0: every loop).
    #[serde(default)]
    pub judged_from_s: f64,
}

/// `watch` judged against `measure`.
pub fn judge(watch: &LimitsWatch, measure: &ErrorMeasureInfo) -> LimitsVerdict {
    let (name, limit) = (&measure.name, measure.limit);
    // Each way of being lost, with when it began; the first that applies is the verdict's, the
    // scenario's own point of no return before the general ones.
    let mut lost: Vec<(f64, String)> = vec![];
    if let (Some(t), Some(beyond)) = (watch.no_return_at_s, measure.lost_beyond) {
        let means = measure.lost_means.as_deref().unwrap_or("the point of no return");
        lost.push((t, format!("{name} reached {} ({means})", number(beyond))));
    }
    if let Some(t) = watch.not_finite_at_s {
        lost.push((t, format!("{name} is not a number: the simulation diverged")));
    }
    if let Some(t) = watch.beyond_since_s {
        lost.push((t, format!("{name} stayed beyond {} from then to the end of the run", number(limit))));
    }
    let lost = lost.into_iter().next();
    let verdict = match (&lost, watch.exceeded_at_s) {
        _ if watch.loops == 0 => Verdict::NotJudged,
        (Some(_), _) => Verdict::Lost,
        (None, Some(_)) => Verdict::LimitsExceeded,
        // One loop within the limit says nothing of the loop over time.
        (None, None) if watch.loops == 1 => Verdict::NotJudged,
        (None, None) => Verdict::WithinLimits,
    };
    let (lost_at_s, lost_because) = lost.map_or((None, None), |(t, why)| (Some(t), Some(why)));
    LimitsVerdict {
        verdict,
        measure: name.clone(),
        limit_key: measure.limit_key.clone(),
        limit,
        exceeded_at_s: watch.exceeded_at_s,
        worst_error: watch.worst,
        worst_at_s: watch.worst_at_s,
        lost_at_s,
        lost_because,
        loops_judged: watch.loops,
        judged_from_s: measure.judged_from_s,
    }
}

/// A number to four significant digits, as the report prints errors.
fn number(v: f64) -> String {
    format!("{}", format!("{v:.3e}").parse::<f64>().unwrap_or(v))
}

impl LimitsVerdict {
    /// The report's line: the verdict first, then what it rests on.
    pub fn line(&self) -> String {
        let worst = match (self.worst_error, self.worst_at_s) {
            (Some(e), Some(t)) => format!("worst {} at t = {} s", number(e), number(t)),
            _ => "no finite error".into(),
        };
        let from = if self.judged_from_s > 0.0 {
            format!(" from t = {} s", number(self.judged_from_s))
        } else {
            String::new()
        };
        let exceeded = |t: f64| {
            format!("limits exceeded at t = {} s ({} = {}{from})", number(t), self.limit_key, number(self.limit))
        };
        match self.verdict {
            Verdict::NotJudged if self.loops_judged == 1 => {
                "not judged (1 loop): one loop within the limit says nothing of the loop over time".into()
            }
            Verdict::NotJudged => "not judged: the monitor recorded no state of the plant".into(),
            // A declared system without [limits] has no limit to stay within (the largest f64).
            Verdict::WithinLimits if self.limit >= f64::MAX => {
                format!("no limit set (the launch file has no [limits]); {}: {worst}", self.measure)
            }
            Verdict::WithinLimits => format!(
                "within limits{from}: {} stayed within {} ({}); {worst}",
                self.measure,
                number(self.limit),
                self.limit_key
            ),
            Verdict::LimitsExceeded => {
                format!("{}; {worst}; back within it by the end", exceeded(self.exceeded_at_s.unwrap_or(f64::NAN)))
            }
            Verdict::Lost => {
                let mut line = format!(
                    "LOST at t = {} s: {}",
                    number(self.lost_at_s.unwrap_or(f64::NAN)),
                    self.lost_because.as_deref().unwrap_or("")
                );
                if let Some(t) = self.exceeded_at_s {
                    line.push_str(&format!("; {}; {worst}", exceeded(t)));
                }
                line
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pendulum() -> ErrorMeasureInfo {
        ErrorMeasureInfo {
            name: "|theta| rad".into(),
            recovery_band: 0.01,
            limit: 0.3,
            limit_key: "limits.fall_angle_rad".into(),
            lost_beyond: Some(std::f64::consts::FRAC_PI_2),
            lost_means: Some("fallen past the horizontal".into()),
            judged_from_s: 0.0,
        }
    }

    /// One loop within the limit says nothing; one beyond it does.
    #[test]
    fn a_run_of_one_loop_is_not_judged_unless_that_loop_failed() {
        let one = judge(&watched(&[0.0]), &pendulum());
        assert_eq!((one.verdict, one.loops_judged), (Verdict::NotJudged, 1));
        assert_eq!(one.line(), "not judged (1 loop): one loop within the limit says nothing of the loop over time");
        assert_eq!(judge(&watched(&[0.4]), &pendulum()).verdict, Verdict::Lost);
    }

    /// Errors at 1 ms loops.
    fn watched(errors: &[f64]) -> LimitsWatch {
        let mut watch = LimitsWatch::default();
        for (k, e) in errors.iter().enumerate() {
            watch.observe(k as f64 / 1000.0, *e, 0.3, Some(std::f64::consts::FRAC_PI_2));
        }
        watch
    }

    #[test]
    fn a_run_beyond_its_limit_for_a_while_has_exceeded_it_at_the_first_such_loop() {
        let v = judge(&watched(&[0.05, 0.2, 0.31, 0.4, 0.29, 0.1]), &pendulum());
        assert_eq!(v.verdict, Verdict::LimitsExceeded);
        assert_eq!((v.exceeded_at_s, v.worst_error, v.worst_at_s), (Some(0.002), Some(0.4), Some(0.003)));
        assert_eq!(v.lost_at_s, None);
        assert_eq!(
            v.line(),
            "limits exceeded at t = 0.002 s (limits.fall_angle_rad = 0.3); worst 0.4 at t = 0.003 s; back within it by the end"
        );
        assert!(v.verdict.failed());
    }

    #[test]
    fn a_run_within_its_limit_passes() {
        let v = judge(&watched(&[0.05, 0.3, 0.1]), &pendulum());
        assert_eq!(v.verdict, Verdict::WithinLimits, "the limit itself is within");
        assert_eq!(
            v.line(),
            "within limits: |theta| rad stayed within 0.3 (limits.fall_angle_rad); worst 0.3 at t = 0.001 s"
        );
        assert!(!v.verdict.failed());
        assert_eq!(judge(&LimitsWatch::default(), &pendulum()).verdict, Verdict::NotJudged);
        // A declared system without [limits]: no limit, and the line says so rather than "within inf".
        let unlimited = ErrorMeasureInfo { limit: f64::MAX, recovery_band: f64::MAX, lost_beyond: None, ..pendulum() };
        let mut watch = LimitsWatch::default();
        for (k, e) in [0.05, 43.7].into_iter().enumerate() {
            watch.observe(k as f64 / 1000.0, e, f64::MAX, None);
        }
        let v = judge(&watch, &unlimited);
        assert_eq!(v.verdict, Verdict::WithinLimits);
        assert_eq!(v.line(), "no limit set (the launch file has no [limits]); |theta| rad: worst 43.7 at t = 0.001 s");
    }

    #[test]
    fn a_run_past_the_point_of_no_return_or_ending_beyond_its_limit_is_lost() {
        // Swung over and came back up: lost all the same.
        let v = judge(&watched(&[0.1, 0.5, 1.6, 5.1, 0.0]), &pendulum());
        assert_eq!((v.verdict, v.lost_at_s, v.exceeded_at_s), (Verdict::Lost, Some(0.002), Some(0.001)));
        assert_eq!(v.lost_because.as_deref(), Some("|theta| rad reached 1.571 (fallen past the horizontal)"));
        assert!(v.line().starts_with("LOST at t = 0.002 s: |theta| rad reached 1.571"), "{}", v.line());
        // Beyond the limit from 3 ms to the end: lost since it last went beyond.
        let v = judge(&watched(&[0.1, 0.4, 0.2, 0.4, 0.5]), &pendulum());
        assert_eq!((v.verdict, v.lost_at_s, v.exceeded_at_s), (Verdict::Lost, Some(0.003), Some(0.001)));
        assert_eq!(v.lost_because.as_deref(), Some("|theta| rad stayed beyond 0.3 from then to the end of the run"));
        // Fell and stayed down: the point of no return is the reason given, though it came later.
        let v = judge(&watched(&[0.1, 0.4, 1.0, 1.6, 3.0]), &pendulum());
        assert_eq!((v.verdict, v.lost_at_s), (Verdict::Lost, Some(0.003)));
        // Diverged.
        let v = judge(&watched(&[0.1, f64::NAN]), &pendulum());
        assert_eq!((v.verdict, v.lost_at_s), (Verdict::Lost, Some(0.001)));
        assert_eq!(serde_json::to_value(Verdict::Lost).unwrap(), "lost");
        assert_eq!(serde_json::to_value(Verdict::WithinLimits).unwrap(), "within_limits");
    }
}
