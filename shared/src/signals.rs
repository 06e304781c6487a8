//! Stop requests. SIGTERM and SIGINT set a flag that every wait checks (waits are bounded and a
//! signal also cuts them short), so a process always leaves cleanly: ports and node dropped,
//! shared memory removed. The flag counts them: a second one asks to hurry (the launcher then
//! kills what is left instead of waiting for it, and still cleans up).

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

#[derive(Clone, Debug)]
pub struct StopFlag(Arc<AtomicUsize>);

impl StopFlag {
    /// Installs the handlers for SIGTERM and SIGINT.
    pub fn install() -> std::io::Result<Self> {
        let count = Arc::new(AtomicUsize::new(0));
        for signal in [signal_hook::consts::SIGTERM, signal_hook::consts::SIGINT] {
            let count = count.clone();
            // SAFETY: the handler only increments an atomic, which is async-signal-safe.
            unsafe { signal_hook::low_level::register(signal, move || _ = count.fetch_add(1, Ordering::Relaxed)) }?;
        }
        Ok(Self(count))
    }

    pub fn requested(&self) -> bool {
        self.0.load(Ordering::Relaxed) > 0
    }

    /// A second stop request came: stop at once.
    pub fn urgent(&self) -> bool {
        self.0.load(Ordering::Relaxed) > 1
    }
}
