//! Layer 7, the tools built on the launcher: `looplab sweep`, `looplab bench`, `looplab export`,
//! `looplab compare`, and the figures (`plot`).

pub mod bench;
pub mod compare;
pub mod export;
pub mod plot;
pub mod sweep;
