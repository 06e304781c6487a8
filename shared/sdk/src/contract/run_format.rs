//! The run folder's format, owned here: its files, the recording's channels, the fields of their
//! messages and the version of all of it. The monitor's sinks write it, `runtime::replay::recording_reader`
//! reads the recording back, the launcher and `tools::run_folder` read the rest; each takes its
//! names from here, so a name changes in one place, and a change of meaning bumps
//! [`FORMAT_VERSION`].

/// The version of the run format: in every channel's metadata of the recording
/// ([`FORMAT_VERSION_KEY`]). A reader refuses a recording of another version with one line.
pub const FORMAT_VERSION: u32 = 1;
/// The recording's channel metadata key holding [`FORMAT_VERSION`].
pub const FORMAT_VERSION_KEY: &str = "looplab_format_version";

/// The files of a run folder.
pub mod files {
    /// The run's resolved launch file, with the `[vectors]` a stage of the user's own reads.
    pub const LAUNCH: &str = "launch.toml";
    pub const SUMMARY: &str = "summary.json";
    pub const TRAJECTORY: &str = "trajectory.csv";
    pub const LOOPS: &str = "loops.csv";
    pub const LATENCY_LOG: &str = "latency.hlog";
    /// The first monitor's recording; see [`restarted_recording`].
    pub const RECORDING: &str = "run.mcap";
    /// The folder of each process's log, `<role>.log`.
    pub const LOGS: &str = "logs";
    /// In a replay's folder: what the replay did.
    pub const REPLAY: &str = "replay.json";

    /// A process's log in the run folder, `logs/<role>.log`.
    pub fn log(role: impl std::fmt::Display) -> String {
        format!("{LOGS}/{role}.log")
    }

    /// The recording of the monitor's n-th incarnation (n = 1, 2, …): an MCAP file cannot be
    /// appended to, so a restarted monitor writes a file of its own.
    pub fn restarted_recording(n: u32) -> String {
        format!("run.{n}.mcap")
    }
}

/// The recording's channels.
pub mod channel {
    use crate::contract::role::Topic;

    /// The channel of a topic of the loop.
    pub fn of(topic: Topic) -> &'static str {
        match topic {
            Topic::State => STATE,
            Topic::Measurements => MEASUREMENTS,
            Topic::Estimate => ESTIMATE,
            Topic::Command => COMMAND,
            Topic::Loop => LOOP,
        }
    }

    pub const STATE: &str = "/state";
    pub const MEASUREMENTS: &str = "/measurements";
    pub const ESTIMATE: &str = "/estimate";
    pub const COMMAND: &str = "/command";
    pub const LOOP: &str = "/loop";
    pub const LATENCY: &str = "/latency";
    pub const FAULTS: &str = "/faults";
}

/// The fields of the recording's messages beside the vectors' own components (which keep their
/// names from the launch file).
pub mod field {
    /// Every message: the loop index and its simulation time.
    pub const K: &str = "k";
    pub const T: &str = "t";
    /// A message whose header says an upstream stage dropped the loop (only when true).
    pub const LOST: &str = "lost";
    /// The sending process's incarnation (only after its first restart).
    pub const INCARNATION: &str = "incarnation";
    /// The input the actuator applied over the last interval.
    pub const APPLIED: &str = "applied";
    /// A sensor's reading: its components, then what the sensor says of them.
    pub const VALUE: &str = "value";
    pub const SAMPLE_TIME: &str = "sample_time";
    pub const SEQ: &str = "seq";
    pub const FRESH: &str = "fresh";
    pub const VALID: &str = "valid";
    /// The loop's record.
    pub const DEADLINE_MISS: &str = "deadline_miss";
    pub const REJECTED: &str = "rejected";
    pub const INCARNATIONS: &str = "incarnations";
}
