//! How a run ended: the supervisor's outcome, the reason `summary.json` gives, and the exit code.

use std::fmt::Display;
use std::str::FromStr;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::summary::Summary;

/// The run completed.
pub const EXIT_OK: u8 = 0;
/// The run did not complete, or something of it could not be written or removed.
pub const EXIT_FAILED: u8 = 1;
/// Bad input: a launch file, an option, a missing binary; nothing was started.
pub const EXIT_BAD_INPUT: u8 = 2;
/// A stop request (Ctrl-C, SIGTERM) ended it.
pub const EXIT_INTERRUPTED: u8 = 130;

/// How the supervision of a run ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// The plant finished its loops (whether all loops ran is the summary's `completed`).
    Completed,
    Interrupted,
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
            Outcome::Failed(why) => Some(StopReason::Failed(why.clone())),
        }
    }
}

/// The launcher's exit code for a finished run, and the error line it prints, if any.
pub fn exit_code(outcome: &Outcome, summary: &Summary) -> (u8, Option<String>) {
    match outcome {
        Outcome::Completed if !summary.completed => {
            let why = summary.stopped_because.as_ref().map_or("it ran fewer loops than planned".into(), |r| r.to_string());
            let error = format!("the run did not complete: {why} ({} of {} loops)", summary.loops, summary.loops_planned);
            (EXIT_FAILED, Some(error))
        }
        Outcome::Completed if summary.shared_memory.clean => (EXIT_OK, None),
        Outcome::Completed => {
            let error = format!("files of the run were left behind: {}", summary.shared_memory.leftover.join(", "));
            (EXIT_FAILED, Some(error))
        }
        Outcome::Interrupted => (EXIT_INTERRUPTED, None),
        Outcome::Failed(why) => (EXIT_FAILED, Some(why.clone())),
    }
}

/// Serializes a type as its `Display` text.
pub(crate) fn serialize_text<T: Display, S: Serializer>(value: &T, serializer: S) -> Result<S::Ok, S::Error> {
    serializer.collect_str(value)
}

/// Reads a type from its text with `FromStr`.
pub(crate) fn deserialize_text<'de, T, D>(deserializer: D) -> Result<T, D::Error>
where
    T: FromStr<Err: Display>,
    D: Deserializer<'de>,
{
    String::deserialize(deserializer)?.parse().map_err(serde::de::Error::custom)
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
    use crate::launcher::summary::tests::summary;

    #[test]
    fn stop_reasons_keep_their_text() {
        for (reason, text) in [
            (StopReason::PlantStoppedEarly, "the plant stopped before the last loop"),
            (StopReason::Interrupted, "interrupted by a signal"),
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
    fn each_outcome_has_its_exit_code_and_error_line() {
        let done = summary();
        assert_eq!(exit_code(&Outcome::Completed, &done), (0, None));
        assert_eq!(exit_code(&Outcome::Interrupted, &done), (130, None));
        assert_eq!(exit_code(&Outcome::Failed("sensors could not be restarted".into()), &done), (1, Some("sensors could not be restarted".into())));

        let mut short = summary();
        short.completed = false;
        short.loops = 10;
        assert_eq!(
            exit_code(&Outcome::Completed, &short),
            (1, Some("the run did not complete: it ran fewer loops than planned (10 of 1000 loops)".into()))
        );
        short.stopped_because = Some(StopReason::PlantStoppedEarly);
        assert_eq!(
            exit_code(&Outcome::Completed, &short),
            (1, Some("the run did not complete: the plant stopped before the last loop (10 of 1000 loops)".into()))
        );

        let mut left = summary();
        left.shared_memory.clean = false;
        left.shared_memory.leftover = vec!["/dev/shm/a".into(), "/dev/shm/b".into()];
        assert_eq!(
            exit_code(&Outcome::Completed, &left),
            (1, Some("files of the run were left behind: /dev/shm/a, /dev/shm/b".into()))
        );
    }
}
