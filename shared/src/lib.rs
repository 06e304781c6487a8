//! LoopLab's shared crate, in layers that depend only downwards: the stage SDK's
//! (`looplab-sdk`: contract → config → model → runtime), then scenarios → runtime (LoopLab's own
//! processes) → monitor → launcher → tools → cli.
//! The binaries in `services/` are one call each into here. ARCHITECTURE.md has the picture.

// Text for the user that never panics: a closed terminal (SIGHUP ignored, EIO) or a pipe whose
// reader went away (`looplab show pendulum | head -1`, EPIPE) loses the text, not the run.
// `println!` and friends panic on a failed write; what the launcher and its tools print goes
// through these instead. Defined before the modules, so every module has them.
// Their control characters are escaped, as `tell!`'s.
macro_rules! say {
    ($($text:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout().lock(), "{}", looplab_sdk::printable(&format!($($text)*)));
    }};
}
macro_rules! say_raw {
    ($($text:tt)*) => {{
        use std::io::Write as _;
        let mut out = std::io::stdout().lock();
        let _ = write!(out, "{}", looplab_sdk::printable(&format!($($text)*))).and_then(|_| out.flush());
    }};
}
// `tell!`, its line on stderr, and `frozen_fields!`, a metric's freeze and thaw, are the SDK's.
#[macro_use]
extern crate looplab_sdk;

pub use looplab_sdk::{config, contract, model};

pub mod cli;
pub mod launcher;
pub mod monitor;
pub mod runtime;
pub mod scenarios;
pub mod tools;
