//! The loop's processes: a child's arguments, context and main, the stage runner and its tasks,
//! a stage's process (relay) and the plant's, faults by loop index, real-time
//! scheduling, the run-queue stamps, and the runners of a stage or a plant of the user's own.

pub mod child;
pub mod faults;
pub mod plant;
pub mod realtime;
pub mod relay;
pub mod sched;
pub mod task;
pub mod user_plant;
pub mod user_stage;
