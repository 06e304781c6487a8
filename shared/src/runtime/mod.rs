//! Layer 4, the runtime: it owns time and policy. iceoryx2 ports, waiting, the stage runner and
//! its tasks, the plant loop, snapshots, and the in-process twin of the five processes.

pub mod bridge;
pub mod child;
pub mod faults;
pub mod in_process;
pub mod ipc;
pub mod plant;
pub mod playback;
pub mod private_file;
pub mod reader_state;
pub mod realtime;
pub mod recorded;
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
