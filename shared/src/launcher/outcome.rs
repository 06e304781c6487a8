//! How a run ended (the supervisor's outcome, the reason `summary.json` gives, the exit codes)
//! and how each of its processes ended.

use std::fmt::Display;
use std::str::FromStr;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// The run completed.
pub const EXIT_OK: u8 = 0;
/// The run did not complete, or something of it could not be written or removed.
pub const EXIT_FAILED: u8 = 1;
/// Bad input: a launch file, an option, a missing binary; nothing was started.
pub const EXIT_BAD_INPUT: u8 = 2;
/// The run completed and a control gate failed (`--fail-on`, `[gate]`: the limits, a metric).
pub const EXIT_CONTROL_GATE: u8 = 3;
/// The run completed and a timing gate failed (deadline misses, latency, jitter, restart time).
pub const EXIT_TIMING_GATE: u8 = 4;
/// The run completed and gates of both kinds failed.
pub const EXIT_BOTH_GATES: u8 = 5;
/// A stop request (Ctrl-C, SIGTERM) ended it.
pub const EXIT_INTERRUPTED: u8 = 130;

/// How the supervision of a run ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// The plant finished its loops (whether all loops ran is the summary's `completed`).
    Completed,
    Interrupted,
    /// The user quit the dashboard (`q`): stopped in order, as for Ctrl-C, and not a failure.
    Quit,
    /// The run cannot go on; the reason in words.
    Failed(String),
}

/// Why a run ended early: `summary.json`'s `stopped_because`, serialized as its text.
#[derive(Debug, Clone, PartialEq, Eq, strum::Display, strum::EnumString)]
pub enum StopReason {
    #[strum(serialize = "the plant stopped before the last loop")]
    PlantStoppedEarly,
    #[strum(serialize = "interrupted by a signal")]
    Interrupted,
    #[strum(serialize = "quit from the dashboard")]
    Quit,
    /// A process could not go on or be restarted, the loop stalled...: the reason in words.
    #[strum(default)]
    Failed(String),
}

impl StopReason {
    /// The reason for an outcome; `plant_stopped_early`: the plant's report says it stopped
    /// before its last loop.
    pub fn of(outcome: &Outcome, plant_stopped_early: bool) -> Option<Self> {
        match outcome {
            Outcome::Completed if plant_stopped_early => Some(StopReason::PlantStoppedEarly),
            Outcome::Completed => None,
            Outcome::Interrupted => Some(StopReason::Interrupted),
            Outcome::Quit => Some(StopReason::Quit),
            Outcome::Failed(why) => Some(StopReason::Failed(why.clone())),
        }
    }
}

/// Serializes a type as its `Display` text.
fn serialize_text<T: Display, S: Serializer>(value: &T, serializer: S) -> Result<S::Ok, S::Error> {
    serializer.collect_str(value)
}

/// Reads a type from its text with `FromStr`.
fn deserialize_text<'de, T, D>(deserializer: D) -> Result<T, D::Error>
where
    T: FromStr<Err: Display>,
    D: Deserializer<'de>,
{
    String::deserialize(deserializer)?.parse().map_err(serde::de::Error::custom)
}

/// How a process ended, as `summary.json` writes it: "0", "1", "signal 9", or "running".
#[derive(Debug, Clone, Copy, PartialEq, Eq, strum::Display)]
pub enum Exit {
    #[strum(to_string = "{0}")]
    Status(i32),
    #[strum(to_string = "signal {0}")]
    Signal(i32),
    /// Not reaped: it never ended while the launcher looked.
    #[strum(to_string = "running")]
    Running,
}

impl Exit {
    /// It exited on its own with status 0.
    pub fn clean(self) -> bool {
        self == Exit::Status(0)
    }
}

impl FromStr for Exit {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let bad = || format!("not an exit status: {text:?}");
        match text.strip_prefix("signal ") {
            _ if text == "running" => Ok(Exit::Running),
            Some(signal) => signal.parse().map(Exit::Signal).map_err(|_| bad()),
            None => text.parse().map(Exit::Status).map_err(|_| bad()),
        }
    }
}

impl Serialize for Exit {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serialize_text(self, serializer)
    }
}

impl<'de> Deserialize<'de> for Exit {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserialize_text(deserializer)
    }
}

impl Serialize for StopReason {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serialize_text(self, serializer)
    }
}

impl<'de> Deserialize<'de> for StopReason {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserialize_text(deserializer)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stop_reasons_keep_their_text() {
        for (reason, text) in [
            (StopReason::PlantStoppedEarly, "the plant stopped before the last loop"),
            (StopReason::Interrupted, "interrupted by a signal"),
            (StopReason::Quit, "quit from the dashboard"),
            (StopReason::Failed("the monitor sent no report".into()), "the monitor sent no report"),
        ] {
            let json = serde_json::to_string(&reason).unwrap();
            assert_eq!(json, format!("\"{text}\""));
            assert_eq!(serde_json::from_str::<StopReason>(&json).unwrap(), reason);
        }
        assert_eq!(StopReason::of(&Outcome::Completed, false), None);
        assert_eq!(StopReason::of(&Outcome::Completed, true), Some(StopReason::PlantStoppedEarly));
        assert_eq!(StopReason::of(&Outcome::Interrupted, true), Some(StopReason::Interrupted));
    }

    #[test]
    fn exit_statuses_keep_their_text() {
        for (exit, text) in
            [(Exit::Status(0), "0"), (Exit::Status(1), "1"), (Exit::Signal(9), "signal 9"), (Exit::Running, "running")]
        {
            assert_eq!(serde_json::to_value(exit).unwrap(), text);
            assert_eq!(serde_json::from_value::<Exit>(text.into()).unwrap(), exit);
        }
        assert!(Exit::Status(0).clean() && !Exit::Status(1).clean() && !Exit::Signal(15).clean());
        assert!("signal x".parse::<Exit>().is_err() && "".parse::<Exit>().is_err());
    }
}
