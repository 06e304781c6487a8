//! Faults to inject and how the launcher supervises the processes: the `[[faults]]` list and the
//! `[supervision]` section of a launch file, the `--fault` text form, and the part of a fault
//! that a stage applies to itself (delay, drop, corrupt: applied by `crate::runtime::stage::faults`).
//!
//! `kill` and `stop` are done to a process from outside, by the launcher; `delay`, `drop` and
//! `corrupt` change what a process does, so the process applies them itself, by loop index k,
//! which keeps them deterministic in lockstep mode; so does `cut`, which this machine's bridge
//! applies to the link to the other host.

use serde::{Deserialize, Serialize};

use crate::contract::role::Role;

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

#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    PartialOrd,
    Ord,
    Serialize,
    Deserialize,
    strum::IntoStaticStr,
    schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
#[strum(serialize_all = "lowercase")]
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
    /// The link to the other host carries nothing, either way, for `duration_s` (simulation
    /// time): this machine's bridge drops every frame of those loops (lockstep: passes them
    /// marked lost, as a lockstep `drop` does, so that the loop goes on).
    Cut,
}

/// Every kind, in the order the messages list them.
pub const FAULT_KINDS: [FaultKind; 6] =
    [FaultKind::Kill, FaultKind::Stop, FaultKind::Delay, FaultKind::Drop, FaultKind::Corrupt, FaultKind::Cut];

/// Every process, the bridges included (they run only when a stage is on another host).
const KILLABLE: [Role; 7] =
    [Role::Plant, Role::Sensors, Role::Estimator, Role::Controller, Role::Monitor, Role::Bridge, Role::BridgeRemote];

impl FaultKind {
    pub fn name(self) -> &'static str {
        self.into()
    }

    /// The processes this kind of fault can be injected into.
    pub fn targets(self) -> &'static [Role] {
        match self {
            FaultKind::Kill | FaultKind::Stop => &KILLABLE,
            FaultKind::Delay | FaultKind::Drop => &Role::STAGES,
            FaultKind::Corrupt => &[Role::Controller],
            // The link is this machine's bridge's: it cuts both ways.
            FaultKind::Cut => &[Role::Bridge],
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
}

fn seconds_text(s: f64) -> String {
    if s != 0.0 && s < 1.0 { format!("{}ms", (s * 1e6).round() / 1e3) } else { format!("{s}s") }
}

/// The `--fault` text form, for example `kill estimator at 3s`, `stop controller at 2s for
/// 200ms`, `delay controller by 5ms at 2s for 1s`, `delay controller by 3 ticks`,
/// `drop sensors 20% at 1s for 2s`, `corrupt controller nan at 4s for 100ms`, `cut bridge at 2s
/// for 300ms` (the link to the other host).
pub const FAULT_SYNTAX: &str = "KIND PROCESS [by AMOUNT] [PROBABILITY%] [nan|inf|out-of-range] [at TIME] [for DURATION]; \
times as 3s, 250ms or 3 (seconds), amounts as 5ms or 3 ticks. Examples: \"kill estimator at 3s\", \
\"stop controller at 2s for 200ms\", \"delay controller by 3 ticks at 2s\", \"drop sensors 20% at 1s for 2s\", \
\"corrupt controller nan at 4s for 100ms\", \"cut bridge at 2s for 300ms\"";

/// Parses the `--fault` form into a fault (checked later, with the rest of the launch file).
pub fn parse_fault(text: &str) -> Result<FaultSpec, String> {
    let words: Vec<&str> = text.split_whitespace().collect();
    let bad = |why: String| format!("{why}; expected {FAULT_SYNTAX}");
    let (Some(kind), Some(process)) = (words.first(), words.get(1)) else {
        return Err(bad("a fault needs a kind and a process".into()));
    };
    let Some(kind) = FAULT_KINDS.into_iter().find(|k| k.name() == *kind) else {
        return Err(bad(format!("unknown fault kind \"{kind}\"; allowed: {}", kind_names())));
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

/// The kinds' names, for messages: `kill, stop, delay, drop, corrupt, cut`.
pub fn kind_names() -> String {
    FAULT_KINDS.map(FaultKind::name).join(", ")
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

/// What happens to the run when a process dies and is not restarted (its policy says no, or it
/// had its `max_restarts`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum OnDeath {
    /// The run ends there (a failure).
    End,
    /// The run goes on to its planned end with the process dead: the plant's fail-safe
    /// (`on_stale`) applies, and the report says what the loop did after the loss. Only for the
    /// stages (sensors, estimator, controller); the monitor always goes on.
    Continue,
}

/// The processes `on_death = "continue"` may be set for: the stages. The plant is the loop
/// itself and a bridge is a stage's only way in; the monitor's loss never ends the run.
pub const ON_DEATH_CONTINUE_ROLES: [Role; 3] = Role::STAGES;

/// One process's restart policy; keys left out take the `[supervision]` defaults.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProcessPolicy {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub restart: Option<Restart>,
    /// end | continue: what a death without a restart does to the run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub on_death: Option<OnDeath>,
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
    /// end | continue, for every stage without its own: what a stage's death without a restart
    /// does to the run (the plant and the bridges always end it; the monitor's never does).
    pub on_death: OnDeath,
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
    /// A process stalled this long (its input waiting, nothing out; not stopped by a fault) is
    /// stuck inside its own code: it is killed, and its restart policy decides what follows.
    pub hang_timeout_s: f64,
    /// Real time: once the newest command is older than this (s), the plant applies `on_stale`.
    pub command_timeout_s: f64,
    pub on_stale: OnStale,
    /// Lockstep: if command k has not come after this many wall-clock seconds, the run ends as
    /// stalled instead of hanging.
    pub lockstep_stall_s: f64,
    /// Every process must say it is ready within this many wall-clock seconds of its start.
    pub ready_timeout_s: f64,
    pub plant: ProcessPolicy,
    pub sensors: ProcessPolicy,
    pub estimator: ProcessPolicy,
    pub controller: ProcessPolicy,
    pub monitor: ProcessPolicy,
    /// Both bridges' (when a stage runs on another host).
    pub bridge: ProcessPolicy,
}

impl Default for Supervision {
    fn default() -> Self {
        Self {
            restart: Restart::OnFailure,
            on_death: OnDeath::End,
            max_restarts: 10,
            backoff_s: 0.01,
            backoff_reset_s: 1.0,
            stall_timeout_s: 0.05,
            hang_timeout_s: 5.0,
            command_timeout_s: 0.02,
            on_stale: OnStale::Hold,
            lockstep_stall_s: 10.0,
            ready_timeout_s: 20.0,
            plant: ProcessPolicy::default(),
            sensors: ProcessPolicy::default(),
            estimator: ProcessPolicy::default(),
            controller: ProcessPolicy::default(),
            monitor: ProcessPolicy::default(),
            bridge: ProcessPolicy::default(),
        }
    }
}

impl Supervision {
    /// How long a reader waits at start-up for its writer: longer than `ready_timeout_s`, so
    /// that the launcher, which knows which process never opened its output (a stage of the
    /// user's own that never called LoopLab's runner), says why, and not a reader that gave up
    /// first (the plant: "no writer on command").
    pub fn connect_timeout(&self) -> std::time::Duration {
        std::time::Duration::from_secs_f64(self.ready_timeout_s + 10.0)
    }
}

/// A process's policy with the defaults filled in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Policy {
    pub restart: Restart,
    pub on_death: OnDeath,
    pub max_restarts: u32,
    pub backoff_s: f64,
}

impl Supervision {
    pub fn policy(&self, role: Role) -> Policy {
        let own = self.policy_of(role);
        Policy {
            restart: own.restart.unwrap_or(self.restart),
            on_death: own.on_death.unwrap_or(self.default_on_death(role)),
            max_restarts: own.max_restarts.unwrap_or(self.max_restarts),
            backoff_s: own.backoff_s.unwrap_or(self.backoff_s),
        }
    }

    /// What a death without a restart does when the role's own table does not say: the
    /// `[supervision]` default for a stage; the monitor's loss never ends the run (the loop goes
    /// on without its recorder); the plant's and a bridge's always do.
    fn default_on_death(&self, role: Role) -> OnDeath {
        match role {
            Role::Monitor => OnDeath::Continue,
            _ if ON_DEATH_CONTINUE_ROLES.contains(&role) => self.on_death,
            _ => OnDeath::End,
        }
    }

    /// The role's own `[supervision.<role>]` settings.
    pub fn policy_of(&self, role: Role) -> &ProcessPolicy {
        match role {
            Role::Plant => &self.plant,
            Role::Sensors => &self.sensors,
            Role::Estimator => &self.estimator,
            Role::Controller => &self.controller,
            Role::Monitor => &self.monitor,
            Role::Bridge | Role::BridgeRemote => &self.bridge,
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

    #[test]
    fn a_reader_waits_for_its_writer_longer_than_the_launcher_waits_for_ready() {
        for ready_timeout_s in [1.0, 20.0, 600.0] {
            let supervision = Supervision { ready_timeout_s, ..Default::default() };
            assert!(supervision.connect_timeout().as_secs_f64() > ready_timeout_s, "{ready_timeout_s}");
        }
    }

    #[test]
    fn a_cut_is_the_link_of_this_machines_bridge_for_a_time() {
        let f = parse_fault("cut bridge at 2s for 300ms").unwrap();
        assert_eq!((f.kind, f.process.as_str(), f.at_s, f.duration_s), (FaultKind::Cut, "bridge", 2.0, Some(0.3)));
        assert_eq!(f.describe(), "cut bridge at 2s for 300ms");
        assert_eq!(parse_fault(&f.describe()).unwrap(), f);
        assert_eq!(f.ticks(1000.0), (2000, Some(2300)));
        assert_eq!(FaultKind::Cut.targets(), [Role::Bridge]);
        assert!(!FaultKind::Cut.from_outside(), "the bridge applies it by loop index");
        let e = parse_fault("sever bridge at 1s").unwrap_err();
        assert!(e.contains("allowed: kill, stop, delay, drop, corrupt, cut"), "{e}");
    }
}
