//! The monitor: a passive reader of every topic that records latency, jitter and the trajectory
//! without slowing the loop.
//!
//! - [`process`]: the monitor process (iceoryx2 readers, polling, the writer thread, status).
//! - [`recording`]: the recorder it feeds, usable without a process; [`recorder`]: the recorder
//!   on a thread of its own, fed in [`batches`] (an in-process run).
//! - [`join`]: the five messages of each loop joined by k; [`cause`]: why a late loop was late; [`stats`]: the latency histograms;
//!   [`fault_effect`]: what each fault did; [`stall`]: stalled processes found from the data.
//! - [`crossing`]: the hops to and from another host, corrected with the other host's clock as
//!   [`clock_fit`] fits it from the loops' own stamps.
//! - [`sinks`]: the files of the run folder, one sink each; [`live`]: what the dashboard shows,
//!   sent with each status.
//! - [`resume`]: the running state each checkpoint leaves for a restarted monitor to go on from.
//! - [`injections`]: when the launcher really injected each kill and stop (real time).

pub mod batches;
pub mod cause;
pub mod clock_fit;
pub mod crossing;
pub mod distribution;
pub mod fault_effect;
pub mod fault_phases;
pub mod injections;
pub mod join;
pub mod live;
pub mod process;
pub mod recording;
pub mod recording_thread;
pub mod resume;
pub mod sinks;
pub mod stall;
pub mod stats;

pub use join::Sample;
pub use process::run;
pub use recording::{Recording, StatusCallback};
