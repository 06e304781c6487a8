//! The transport between the loop's processes: iceoryx2 ports, and how a reader waits for its
//! writer (block, spin, adaptive; lockstep's poll, block or handoff) on the futex word its writer
//! wakes.

pub mod ipc;
pub mod reader_state;
pub mod wait;

#[cfg(test)]
mod private_run_tests;
