//! Layer 6, the launcher: runs one launch configuration as the loop's five processes. It creates
//! the run folder, starts the processes, supervises them (fault injection, detection, restarts),
//! stops them in order, checks that nothing is left in shared memory, and writes the summary.
//! The command line that calls it is `crate::cli`.

pub mod budget;
pub mod child;
pub mod dashboard;
pub mod gate;
pub mod inject;
pub mod network;
pub mod outcome;
pub mod probe;
pub mod report;
pub mod report_phases;
pub mod restart;
pub mod run_dir;
pub mod sched_trace;
pub mod summary;
pub mod supervisor;
pub mod verdict;

pub use child::{Binaries, locate_binaries, supervised};
pub use outcome::{EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK, Exit, Outcome, StopReason};
pub use report::exit_code;
pub use run_dir::{create_run_dir, new_run_id, write_atomically};
pub use summary::Summary;
pub use supervisor::{LiveView, run_once, run_with};
pub mod in_process;
