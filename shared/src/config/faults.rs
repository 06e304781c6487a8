//! Faults to inject and how the launcher supervises the processes: the `[[faults]]` list and the
//! `[supervision]` section of a launch file, the `--fault` text form, and the part of a fault
//! that a stage applies to itself (delay, drop, corrupt: applied by `crate::runtime::faults`).
//!
//! `kill` and `stop` are done to a process from outside, by the launcher; `delay`, `drop` and
//! `corrupt` change what a process does, so the process applies them itself, by loop index k,
//! which keeps them deterministic in lockstep mode.

use serde::{Deserialize, Serialize};

use crate::launch::{LaunchConfig, LaunchError, MAX_DURATION_S};

/// The longest a `stop` may last, wall-clock s (an hour). It is wall-clock time, which in
/// lockstep has nothing to do with the run's simulated duration_s (a short lockstep run may
/// want a stop longer than itself to trip `lockstep_stall_s`), and anything longer only hangs
/// the run.
pub const MAX_STOP_S: f64 = 3600.0;
/// The longest wall-clock timeout of `[supervision]`, s (an hour).
pub const MAX_TIMEOUT_S: f64 = 3600.0;
/// The longest wait before a restart, s (the launcher caps the doubled backoff at 1 s anyway).
pub const MAX_BACKOFF_S: f64 = 60.0;
/// The most restarts per process and run.
pub const MAX_RESTARTS: u32 = 1000;

/// Every process the launcher starts, in the order data flows.
pub const PROCESSES: [&str; 5] = ["plant", "sensors", "estimator", "controller", "monitor"];
/// The stages between the plant and the plant, which handle one input per loop.
pub const STAGES: [&str; 3] = ["sensors", "estimator", "controller"];

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FaultKind {
    /// SIGKILL the process.
    Kill,
    /// SIGSTOP it, then SIGCONT after `duration_s` (wall-clock seconds).
    Stop,
    /// The process adds `delay_s` (or `delay_ticks` loop periods) to each loop it handles.
    Delay,
    /// The process's output is dropped with `probability` for each loop.
    Drop,
    /// The controller sends `value` instead of its command.
    Corrupt,
}

impl FaultKind {
    pub fn name(self) -> &'static str {
        match self {
            FaultKind::Kill => "kill",
            FaultKind::Stop => "stop",
            FaultKind::Delay => "delay",
            FaultKind::Drop => "drop",
            FaultKind::Corrupt => "corrupt",
        }
    }

    /// The processes this kind of fault can be injected into.
    pub fn targets(self) -> &'static [&'static str] {
        match self {
            FaultKind::Kill | FaultKind::Stop => &PROCESSES,
            FaultKind::Delay | FaultKind::Drop => &STAGES,
            FaultKind::Corrupt => &["controller"],
        }
    }

    /// Whether the launcher does it (from outside), rather than the process itself.
    pub fn from_outside(self) -> bool {
        matches!(self, FaultKind::Kill | FaultKind::Stop)
    }
}

/// What a corrupted command holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum CorruptValue {
    #[default]
    Nan,
    Inf,
    /// Ten times the input's limit.
    OutOfRange,
}

/// One `[[faults]]` entry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultSpec {
    pub kind: FaultKind,
    pub process: String,
    /// Simulation time of the injection, s.
    #[serde(default)]
    pub at_s: f64,
    /// How long it lasts, s: wall-clock for `stop`, simulation time for the others. Left out:
    /// until the end of the run (a `stop` needs it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duration_s: Option<f64>,
    /// `delay`: added latency, s (lockstep: rounded to whole ticks).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delay_s: Option<f64>,
    /// `delay`: added latency in loop periods.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delay_ticks: Option<u32>,
    /// `drop`: the chance that each output is dropped, 0 to 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probability: Option<f64>,
    /// `corrupt`: nan | inf | out-of-range.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<CorruptValue>,
}

impl FaultSpec {
    /// The tick at which it starts, and the first tick after it (None: until the end).
    pub fn ticks(&self, rate_hz: f64) -> (u64, Option<u64>) {
        // at_s < duration_s ≤ a week, duration_s ≤ a week and rate_hz ≤ 100 kHz (checked at
        // load): both terms are below 1e11, so neither the casts nor the sum can overflow.
        let from = (self.at_s * rate_hz).round() as u64;
        (from, self.duration_s.map(|d| from + (d * rate_hz).round() as u64))
    }

    /// One line for reports, in the `--fault` form.
    pub fn describe(&self) -> String {
        let mut s = format!("{} {}", self.kind.name(), self.process);
        match self.kind {
            FaultKind::Delay => match (self.delay_ticks, self.delay_s) {
                (Some(t), _) => s += &format!(" by {t} ticks"),
                (_, Some(d)) => s += &format!(" by {}", seconds_text(d)),
                _ => {}
            },
            FaultKind::Drop => s += &format!(" {}%", self.probability.unwrap_or(0.0) * 100.0),
            FaultKind::Corrupt => {
                s += match self.value.unwrap_or_default() {
                    CorruptValue::Nan => " nan",
                    CorruptValue::Inf => " inf",
                    CorruptValue::OutOfRange => " out-of-range",
                }
            }
            _ => {}
        }
        s += &format!(" at {}", seconds_text(self.at_s));
        if let Some(d) = self.duration_s {
            s += &format!(" for {}", seconds_text(d));
        }
        s
    }

    /// Checks the fault against the run; `key` is its dotted key (`faults.2`).
    pub fn check(&self, c: &LaunchConfig, key: &str) -> Result<(), LaunchError> {
        let field = |f: &str| format!("{key}.{f}");
        let targets = self.kind.targets();
        if !targets.contains(&self.process.as_str()) {
            return Err(c.error(
                &field("process"),
                format!(
                    "a {} fault cannot target \"{}\"; allowed: {}",
                    self.kind.name(),
                    self.process,
                    targets.join(", ")
                ),
            ));
        }
        if !(self.at_s.is_finite() && self.at_s >= 0.0 && self.at_s < c.duration_s) {
            return Err(c.error(
                &field("at_s"),
                format!("must be a time within the run, 0 ≤ at_s < {} s, got {}", c.duration_s, self.at_s),
            ));
        }
        if let Some(d) = self.duration_s {
            // A stop lasts wall-clock seconds; the others simulation time, where anything past
            // the run's end means "to the end".
            let (most, what) = if self.kind == FaultKind::Stop {
                (MAX_STOP_S, "wall-clock seconds, at most 3600 (an hour)")
            } else {
                (MAX_DURATION_S, "seconds, at most 604800 (a week; leave it out for \"to the end of the run\")")
            };
            if !(d.is_finite() && d > 0.0 && d <= most) {
                return Err(c.error(&field("duration_s"), format!("must be a positive number of {what}, got {d}")));
            }
        }
        let only = |name: &str, present: bool, kind: FaultKind| -> Result<(), LaunchError> {
            if present && self.kind != kind {
                return Err(c.error(&field(name), format!("applies to {} faults only", kind.name())));
            }
            Ok(())
        };
        only("delay_s", self.delay_s.is_some(), FaultKind::Delay)?;
        only("delay_ticks", self.delay_ticks.is_some(), FaultKind::Delay)?;
        only("probability", self.probability.is_some(), FaultKind::Drop)?;
        only("value", self.value.is_some(), FaultKind::Corrupt)?;
        match self.kind {
            FaultKind::Kill if self.duration_s.is_some() => {
                Err(c.error(&field("duration_s"), "a kill has no duration (the process is restarted, or not)"))
            }
            FaultKind::Stop if self.duration_s.is_none() => {
                Err(c.error(&field("duration_s"), "a stop needs the seconds it lasts before SIGCONT"))
            }
            FaultKind::Delay => match (self.delay_s, self.delay_ticks) {
                (Some(_), Some(_)) | (None, None) => {
                    Err(c.error(&field("delay_s"), "give exactly one of delay_s (seconds) and delay_ticks (loops)"))
                }
                (Some(d), None) if !(d.is_finite() && d >= 0.0 && d < c.duration_s) => Err(c.error(
                    &field("delay_s"),
                    format!("must be 0 or more seconds, less than the run's duration_s = {} s, got {d}", c.duration_s),
                )),
                (None, Some(t)) if u64::from(t) > c.loops() => Err(
                    c.error(&field("delay_ticks"), format!("must be at most the run's {} loops, got {t}", c.loops()))
                ),
                _ => Ok(()),
            },
            FaultKind::Drop => match self.probability {
                Some(p) if (0.0..=1.0).contains(&p) => Ok(()),
                Some(p) => Err(c.error(&field("probability"), format!("must be between 0 and 1, got {p}"))),
                None => {
                    Err(c.error(&field("probability"), "a drop needs the chance, 0 to 1, that each output is lost"))
                }
            },
            _ => Ok(()),
        }
    }
}

fn seconds_text(s: f64) -> String {
    if s != 0.0 && s < 1.0 { format!("{}ms", (s * 1e6).round() / 1e3) } else { format!("{s}s") }
}

/// The `--fault` text form, for example `kill estimator at 3s`, `stop controller at 2s for
/// 200ms`, `delay controller by 5ms at 2s for 1s`, `delay controller by 3 ticks`,
/// `drop sensors 20% at 1s for 2s`, `corrupt controller nan at 4s for 100ms`.
pub const FAULT_SYNTAX: &str = "KIND PROCESS [by AMOUNT] [PROBABILITY%] [nan|inf|out-of-range] [at TIME] [for DURATION]; \
times as 3s, 250ms or 3 (seconds), amounts as 5ms or 3 ticks. Examples: \"kill estimator at 3s\", \
\"stop controller at 2s for 200ms\", \"delay controller by 3 ticks at 2s\", \"drop sensors 20% at 1s for 2s\", \
\"corrupt controller nan at 4s for 100ms\"";

/// Parses the `--fault` form into a fault (checked later, with the rest of the launch file).
pub fn parse_fault(text: &str) -> Result<FaultSpec, String> {
    let words: Vec<&str> = text.split_whitespace().collect();
    let bad = |why: String| format!("{why}; expected {FAULT_SYNTAX}");
    let (Some(kind), Some(process)) = (words.first(), words.get(1)) else {
        return Err(bad("a fault needs a kind and a process".into()));
    };
    let kind: FaultKind = match *kind {
        "kill" => FaultKind::Kill,
        "stop" => FaultKind::Stop,
        "delay" => FaultKind::Delay,
        "drop" => FaultKind::Drop,
        "corrupt" => FaultKind::Corrupt,
        other => return Err(bad(format!("unknown fault kind \"{other}\"; allowed: kill, stop, delay, drop, corrupt"))),
    };
    let mut spec = FaultSpec {
        kind,
        process: process.to_string(),
        at_s: 0.0,
        duration_s: None,
        delay_s: None,
        delay_ticks: None,
        probability: None,
        value: None,
    };
    let mut rest = words[2..].iter().copied().peekable();
    while let Some(word) = rest.next() {
        let mut next = || rest.next().ok_or_else(|| bad(format!("\"{word}\" needs a value after it")));
        match word {
            "at" => spec.at_s = parse_seconds(next()?).map_err(bad)?,
            "for" => spec.duration_s = Some(parse_seconds(next()?).map_err(bad)?),
            "by" => {
                let amount = next()?;
                let ticks = amount.strip_suffix("ticks").or_else(|| amount.strip_suffix("tick"));
                if let Some(number) = ticks.filter(|n| !n.is_empty()) {
                    spec.delay_ticks = Some(number.parse().map_err(|_| bad(format!("bad tick count \"{amount}\"")))?);
                } else if let Ok(n) = amount.parse::<u32>()
                    && rest.peek().is_some_and(|w| *w == "ticks" || *w == "tick")
                {
                    rest.next();
                    spec.delay_ticks = Some(n);
                } else {
                    spec.delay_s = Some(parse_seconds(amount).map_err(bad)?);
                }
            }
            "nan" => spec.value = Some(CorruptValue::Nan),
            "inf" => spec.value = Some(CorruptValue::Inf),
            "out-of-range" => spec.value = Some(CorruptValue::OutOfRange),
            w if w.ends_with('%') => {
                let p: f64 = w[..w.len() - 1].parse().map_err(|_| bad(format!("bad percentage \"{w}\"")))?;
                spec.probability = Some(p / 100.0);
            }
            w => return Err(bad(format!("unexpected \"{w}\""))),
        }
    }
    Ok(spec)
}

/// `3s`, `250ms`, `40us`, or a plain number of seconds.
fn parse_seconds(text: &str) -> Result<f64, String> {
    let (number, scale) = if let Some(n) = text.strip_suffix("ms") {
        (n, 1e-3)
    } else if let Some(n) = text.strip_suffix("us") {
        (n, 1e-6)
    } else if let Some(n) = text.strip_suffix('s') {
        (n, 1.0)
    } else {
        (text, 1.0)
    };
    number.parse::<f64>().map(|v| v * scale).map_err(|_| format!("bad time \"{text}\" (use 3s, 250ms or 3)"))
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Restart {
    Never,
    OnFailure,
    Always,
}

/// What the plant applies once its newest command is older than `command_timeout_s`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum OnStale {
    Hold,
    Zero,
}

/// One process's restart policy; keys left out take the `[supervision]` defaults.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProcessPolicy {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub restart: Option<Restart>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_restarts: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub backoff_s: Option<f64>,
}

/// The `[supervision]` section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Supervision {
    /// never | on-failure | always, for every process without its own policy.
    pub restart: Restart,
    /// Restarts allowed per process in one run.
    pub max_restarts: u32,
    /// Wait before a restart, s; it doubles with each restart of the same process, up to 1 s.
    pub backoff_s: f64,
    /// A process that has run this long (wall-clock seconds) since it was last ready counts as
    /// healthy again: its next restart waits `backoff_s`, not the doubled wait.
    pub backoff_reset_s: f64,
    /// A process whose input has been waiting this long with no output from it is stalled
    /// (wall-clock seconds; a stopped process looks alive to iceoryx2).
    pub stall_timeout_s: f64,
    /// Real time: once the newest command is older than this (s), the plant applies `on_stale`.
    pub command_timeout_s: f64,
    pub on_stale: OnStale,
    /// Lockstep: if command k has not come after this many wall-clock seconds, the run ends as
    /// stalled instead of hanging.
    pub lockstep_stall_s: f64,
    pub plant: ProcessPolicy,
    pub sensors: ProcessPolicy,
    pub estimator: ProcessPolicy,
    pub controller: ProcessPolicy,
    pub monitor: ProcessPolicy,
}

impl Default for Supervision {
    fn default() -> Self {
        Self {
            restart: Restart::OnFailure,
            max_restarts: 10,
            backoff_s: 0.01,
            backoff_reset_s: 1.0,
            stall_timeout_s: 0.05,
            command_timeout_s: 0.02,
            on_stale: OnStale::Hold,
            lockstep_stall_s: 10.0,
            plant: ProcessPolicy::default(),
            sensors: ProcessPolicy::default(),
            estimator: ProcessPolicy::default(),
            controller: ProcessPolicy::default(),
            monitor: ProcessPolicy::default(),
        }
    }
}

/// A process's policy with the defaults filled in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Policy {
    pub restart: Restart,
    pub max_restarts: u32,
    pub backoff_s: f64,
}

impl Supervision {
    pub fn policy(&self, process: &str) -> Policy {
        let own = self.policy_of(process);
        Policy {
            restart: own.restart.unwrap_or(self.restart),
            max_restarts: own.max_restarts.unwrap_or(self.max_restarts),
            backoff_s: own.backoff_s.unwrap_or(self.backoff_s),
        }
    }

    pub fn check(&self, c: &LaunchConfig) -> Result<(), LaunchError> {
        let timeout = |key: &str, v: f64| {
            if v.is_finite() && v > 0.0 && v <= MAX_TIMEOUT_S {
                Ok(())
            } else {
                Err(c.error(
                    &format!("supervision.{key}"),
                    format!("must be a positive number of seconds, at most {MAX_TIMEOUT_S} (an hour), got {v}"),
                ))
            }
        };
        timeout("stall_timeout_s", self.stall_timeout_s)?;
        timeout("command_timeout_s", self.command_timeout_s)?;
        timeout("lockstep_stall_s", self.lockstep_stall_s)?;
        timeout("backoff_reset_s", self.backoff_reset_s)?;
        for process in PROCESSES {
            // The key to blame: the process's own, or the default it took.
            let key = |field: &str| {
                let own = match field {
                    "backoff_s" => self.policy_of(process).backoff_s.is_some(),
                    _ => self.policy_of(process).max_restarts.is_some(),
                };
                if own { format!("supervision.{process}.{field}") } else { format!("supervision.{field}") }
            };
            let policy = self.policy(process);
            if !(policy.backoff_s.is_finite() && policy.backoff_s >= 0.0 && policy.backoff_s <= MAX_BACKOFF_S) {
                return Err(c.error(
                    &key("backoff_s"),
                    format!("must be 0 to {MAX_BACKOFF_S} seconds, got {}", policy.backoff_s),
                ));
            }
            if policy.max_restarts > MAX_RESTARTS {
                return Err(c.error(
                    &key("max_restarts"),
                    format!("must be 0 to {MAX_RESTARTS} restarts per process and run, got {}", policy.max_restarts),
                ));
            }
        }
        Ok(())
    }

    fn policy_of(&self, process: &str) -> &ProcessPolicy {
        match process {
            "plant" => &self.plant,
            "sensors" => &self.sensors,
            "estimator" => &self.estimator,
            "controller" => &self.controller,
            _ => &self.monitor,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fault_text_forms() {
        let f = parse_fault("kill estimator at 3s").unwrap();
        assert_eq!((f.kind, f.process.as_str(), f.at_s, f.duration_s), (FaultKind::Kill, "estimator", 3.0, None));
        let f = parse_fault("stop controller at 2.5 for 200ms").unwrap();
        assert_eq!((f.kind, f.at_s, f.duration_s), (FaultKind::Stop, 2.5, Some(0.2)));
        assert_eq!(parse_fault("delay controller by 3 ticks").unwrap().delay_ticks, Some(3));
        assert_eq!(parse_fault("delay controller by 7ticks at 1s").unwrap().delay_ticks, Some(7));
        assert_eq!(parse_fault("delay sensors by 5ms at 1s for 1s").unwrap().delay_s, Some(0.005));
        let f = parse_fault("drop sensors 20% at 1s for 2s").unwrap();
        assert_eq!((f.probability, f.duration_s), (Some(0.2), Some(2.0)));
        assert_eq!(parse_fault("corrupt controller out-of-range at 4s").unwrap().value, Some(CorruptValue::OutOfRange));
        for bad in ["kill", "explode plant at 1s", "kill plant at soon", "delay controller by", "kill plant now"] {
            let e = parse_fault(bad).unwrap_err();
            assert!(e.contains("expected KIND PROCESS"), "{bad}: {e}");
        }
        let f = parse_fault("stop controller at 2s for 200ms").unwrap();
        assert_eq!(parse_fault(&f.describe()).unwrap(), f, "{}", f.describe());
    }

    /// The error that the pendulum's defaults (10 s at 1 kHz) with this `--fault` give, if any.
    fn checked(fault: &str) -> Result<(), LaunchError> {
        let overrides = [crate::launch::Override::fault(fault).unwrap()];
        crate::scenarios::resolve("pendulum", &overrides).map(|_| ())
    }

    fn rejected(fault: &str, key: &str, fragment: &str) {
        let e = checked(fault).unwrap_err();
        assert_eq!(e.origin, format!("--fault {fault}"));
        assert_eq!(e.key.as_deref(), Some(key), "{fault}: {e}");
        assert!(e.message.contains(fragment), "{fault}: {e}");
    }

    #[test]
    fn fault_times_and_amounts_are_bounded() {
        rejected("stop controller at 1s for 1e19s", "faults.0.duration_s", "at most 3600");
        rejected("stop controller at 1s for 3601s", "faults.0.duration_s", "at most 3600");
        checked("stop controller at 1s for 3600s").unwrap();
        rejected("drop sensors 20% at 1s for 604801s", "faults.0.duration_s", "at most 604800");
        checked("drop sensors 20% at 1s for 60s").unwrap();
        rejected("delay controller by 1e20s at 1s", "faults.0.delay_s", "less than the run's duration_s = 10 s");
        rejected("delay controller by 10s at 1s", "faults.0.delay_s", "less than the run's duration_s");
        checked("delay controller by 9.999s at 1s").unwrap();
        rejected("delay controller by 10001 ticks at 1s", "faults.0.delay_ticks", "at most the run's 10000 loops");
        checked("delay controller by 10000 ticks at 1s").unwrap();
        rejected("kill plant at 1e19s", "faults.0.at_s", "within the run");
        rejected("kill plant at -1s", "faults.0.at_s", "within the run");
        rejected("drop sensors nan% at 1s", "faults.0.probability", "finite");
        rejected("drop sensors 101% at 1s", "faults.0.probability", "between 0 and 1");
    }
}
