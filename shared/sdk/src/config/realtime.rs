//! The `[realtime]` section of a launch file: the loop's processes (plant, sensors, estimator,
//! controller, a user's stage included) at a real-time priority (`SCHED_FIFO`), and their
//! memory locked so that a page fault never stalls a loop. The monitor stays at its low normal
//! priority: it must never take a CPU from the loop.

use serde::{Deserialize, Serialize};

/// The highest `SCHED_FIFO` priority Linux has.
pub const MAX_PRIORITY: u32 = 99;

#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RealtimeSettings {
    /// `SCHED_FIFO` priority 1 to 99 for each loop process; absent, the normal scheduler.
    pub priority: Option<u32>,
    /// Lock each loop process's memory, present and future (`mlockall`).
    pub mlock: bool,
}

impl RealtimeSettings {
    /// Whether anything is asked for.
    pub fn any(&self) -> bool {
        self.priority.is_some() || self.mlock
    }
}
