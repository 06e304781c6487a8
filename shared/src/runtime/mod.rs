//! Layer 4, the runtime: iceoryx2 ports, waiting, the stage runner, the plant loop, snapshots.

pub mod ipc;
pub mod plant;
pub mod signals;
pub mod snapshot;
pub mod stages;
pub mod wait;
