//! Layer 7, the tools built on the launcher: `looplab sweep`, `looplab bench` and `looplab export`.

pub mod bench;
pub mod export;
pub mod sweep;
