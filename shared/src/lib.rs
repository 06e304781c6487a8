//! LoopLab's shared crate, in layers that depend only downwards:
//! contract → config → model → scenarios → runtime → monitor → launcher → tools → cli.
//! The binaries in `services/` are one call each into here. ARCHITECTURE.md has the picture.

// Text for the user that never panics: a closed terminal (SIGHUP ignored, EIO) or a pipe whose
// reader went away (`looplab show pendulum | head -1`, EPIPE) loses the text, not the run.
// `println!` and friends panic on a failed write; what the launcher and its tools print goes
// through these instead. Defined before the modules, so every module has them.
macro_rules! say {
    ($($text:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout().lock(), $($text)*);
    }};
}
macro_rules! say_raw {
    ($($text:tt)*) => {{
        use std::io::Write as _;
        let mut out = std::io::stdout().lock();
        let _ = write!(out, $($text)*).and_then(|_| out.flush());
    }};
}
macro_rules! tell {
    ($($text:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr().lock(), $($text)*);
    }};
}

pub mod cli;
pub mod config;
pub mod contract;
pub mod launcher;
pub mod model;
pub mod monitor;
pub mod runtime;
pub mod scenarios;
pub mod tools;
