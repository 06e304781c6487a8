//! Layer 0, the contract between the processes: the messages, the clock they are stamped with,
//! the launcher↔child protocol, and how state is serialised. Depends on nothing else in the crate.

pub mod clock;
pub mod codec;
pub mod limits;
pub mod msg;
pub mod protocol;
pub mod report;
pub mod role;
pub mod run_format;
