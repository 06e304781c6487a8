//! Layer 7, the tools built on the launcher: `looplab sweep` and `looplab bench`.

pub mod bench;
pub mod sweep;
