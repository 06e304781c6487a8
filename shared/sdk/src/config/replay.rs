//! `[replay]`: a run that plays a recorded run back into one stage (`looplab replay`, which
//! writes this table into the replay's launch file).
//!
//! ```toml
//! [replay]
//! recording = "/home/me/runs/golden"   # the recorded run folder (its run.mcap)
//! stage = "estimator"                  # the stage that runs; sensors | estimator | controller
//! closed_loop = false                  # true: only a note, every process runs
//! skipped = [[2000, 2149]]             # loops the recorded stage did not compute
//! recorded_in_real_time = true         # leave out of the files what the recording never had
//! ```
//!
//! Open loop, every other process of the loop plays its recorded messages back, loop by loop:
//! the plant its recorded states, each stage its recorded outputs. Closed loop, everything
//! downstream of the stage runs (which, in a loop, is every process): the run is an ordinary
//! lockstep run of the recording's launch file with the stage changed.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::contract::role::Role;
use crate::contract::run_format::files;

/// The top-level key.
pub const KEY: &str = "replay";

#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReplaySpec {
    /// The recorded run folder.
    pub recording: PathBuf,
    /// The stage that runs: sensors, estimator or controller.
    pub stage: String,
    #[serde(default)]
    pub closed_loop: bool,
    /// The loops the recorded stage did not compute (from, to; inclusive): the process before it
    /// withholds them, so that the stage skips them again.
    #[serde(default)]
    pub skipped: Vec<[u64; 2]>,
    /// The recording ran in real time, where a message that did not come left no trace: the
    /// replay's files leave out what is sent on marked lost for it, as the recording's do.
    #[serde(default)]
    pub recorded_in_real_time: bool,
}

impl ReplaySpec {
    /// The stage that runs (checked at load).
    pub fn role(&self) -> Role {
        self.stage.parse().expect("checked at load")
    }

    /// Whether `role` plays its recorded messages back in this replay.
    pub fn plays_back(&self, role: Role) -> bool {
        // Before the stage is checked (the loader asks), a stage that is no role plays nothing.
        !self.closed_loop && role.in_loop() && self.stage.parse::<Role>().is_ok_and(|stage| stage != role)
    }

    /// Whether the recorded stage skipped loop k.
    pub fn skipped(&self, k: u64) -> bool {
        self.skipped.iter().any(|[from, to]| (*from..=*to).contains(&k))
    }

    /// What is wrong with it, if anything: (key, message).
    pub fn check(&self) -> Result<(), (String, String)> {
        let allowed = Role::STAGES.iter().map(|r| r.name()).collect::<Vec<_>>().join(", ");
        if !self.stage.parse::<Role>().is_ok_and(|r| Role::STAGES.contains(&r)) {
            return Err((format!("{KEY}.stage"), format!("unknown stage \"{}\"; allowed: {allowed}", self.stage)));
        }
        if !self.recording.join(files::LAUNCH).is_file() {
            return Err((
                format!("{KEY}.recording"),
                format!("{} is not a run folder (it has no launch.toml)", self.recording.display()),
            ));
        }
        Ok(())
    }
}
