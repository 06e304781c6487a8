//! LoopLab's stage SDK: what a stage of your own links (a controller, an estimator, sensors or a
//! plant model in Rust, and the Python and C bindings), in layers that depend only downwards:
//! contract → config → model → runtime. The rest of LoopLab (`looplab-shared`: the scenarios,
//! the monitor, the launcher, the tools) builds on it. ARCHITECTURE.md has the picture.

// A line for the user on stderr that never panics (a closed terminal, a reader gone away): the
// exit status must still say why a process ended. Defined before the modules, so every module
// has it.
#[macro_export]
macro_rules! tell {
    ($($text:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr().lock(), $($text)*);
    }};
}

pub mod config;
pub mod contract;
pub mod model;
pub mod runtime;
