//! The runtime a stage runs in: it owns time and policy. `signals` (a stop requested by a signal)
//! under three concerns, each importing only the ones before it:
//! - `storage`: the run's private folder in shared memory and what lives in it (files never
//!   written through a link, the snapshots a restarted process goes on from);
//! - `transport`: iceoryx2 ports and how a reader waits for its writer;
//! - `stage`: the loop's processes: the stage runner and its tasks, the plant loop, faults by
//!   loop index, and the runners of a stage or a plant of the user's own.

pub mod signals;
pub mod stage;
pub mod storage;
pub mod transport;
