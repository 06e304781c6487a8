//! The runtime a stage runs in: it owns time and policy. iceoryx2 ports, waiting, the stage
//! runner and its tasks, the plant loop, snapshots, and the runners of a stage or a plant of the
//! user's own.

pub mod child;
pub mod faults;
pub mod ipc;
pub mod plant;
pub mod private_file;
pub mod reader_state;
pub mod realtime;
pub mod relay;
pub mod run_file;
pub mod run_storage;
pub mod sched;
pub mod shared_file;
pub mod shm_secret;
pub mod signals;
pub mod snapshot;
pub mod task;
pub mod user_plant;
pub mod user_stage;
pub mod wait;
