//! Stop requests. SIGTERM and SIGINT set a flag that every wait checks (waits are bounded and a
//! signal also cuts them short), so a process always leaves cleanly: ports and node dropped,
//! shared memory removed. The flag counts them: a second one asks to hurry (the launcher then
//! kills what is left instead of waiting for it, and still cleans up).

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

#[derive(Clone, Debug)]
pub struct StopFlag(Arc<AtomicUsize>);

/// The process's flag, once [`StopFlag::install`] has made it.
static INSTALLED: Mutex<Option<StopFlag>> = Mutex::new(None);

impl StopFlag {
    /// Installs the handlers for SIGTERM and SIGINT, once per process: every caller shares one
    /// count, so a stop request reaches whatever part of a command (a sweep's next run, a
    /// bench's next part) looks next.
    pub fn install() -> std::io::Result<Self> {
        let mut installed = INSTALLED.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(flag) = installed.as_ref() {
            return Ok(flag.clone());
        }
        let count = Arc::new(AtomicUsize::new(0));
        // SIGHUP: the terminal closed; the run stops in order as for Ctrl-C and keeps its summary.
        for signal in [signal_hook::consts::SIGTERM, signal_hook::consts::SIGINT, signal_hook::consts::SIGHUP] {
            let count = count.clone();
            // SAFETY: the handler only increments an atomic, which is async-signal-safe.
            unsafe { signal_hook::low_level::register(signal, move || _ = count.fetch_add(1, Ordering::Relaxed)) }?;
        }
        let flag = Self(count);
        *installed = Some(flag.clone());
        Ok(flag)
    }

    /// The flag, if this process has installed it (a library wait that must stop when asked,
    /// without taking the signals over where its caller has not).
    pub fn installed() -> Option<Self> {
        INSTALLED.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    pub fn requested(&self) -> bool {
        self.0.load(Ordering::Relaxed) > 0
    }

    /// A second stop request came: stop at once.
    pub fn urgent(&self) -> bool {
        self.0.load(Ordering::Relaxed) > 1
    }
}

/// The error a command returns when a stop request ended it (exit code 130).
#[derive(Debug)]
pub struct Interrupted;

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("interrupted by a signal")
    }
}

impl std::error::Error for Interrupted {}
