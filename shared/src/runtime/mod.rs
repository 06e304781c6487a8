//! Layer 4, the runtime: the stage SDK's runtime (`looplab_sdk::runtime`: ports, waiting, the
//! stage runner, the plant loop, snapshots), with what LoopLab's own processes add to it: the
//! built-in processes' bodies, the playback of a recording, the in-process twin of the five
//! processes, and the bridge to a stage on another host.

pub use looplab_sdk::runtime::*;

pub mod bridge;
pub mod builtin;
pub mod in_process;
pub mod replay;

#[cfg(test)]
mod plant_tests;
#[cfg(test)]
mod task_tests;
