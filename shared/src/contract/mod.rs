//! Layer 0, the contract between the processes: the messages, the clock they are stamped with,
//! and the launcher↔child protocol. Depends on nothing else in the crate.

pub mod clock;
pub mod msg;
pub mod protocol;
pub mod report;
pub mod role;
