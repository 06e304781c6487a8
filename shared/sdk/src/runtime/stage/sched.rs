//! What a loop process knows of its own scheduling, always on and without privileges: how long
//! its thread sat on the run queue (runnable, but another task had the CPU), from the kernel's
//! per-task schedstat (`/proc/thread-self/schedstat`: time on the CPU, time waiting on the run
//! queue, times run; CONFIG_SCHED_INFO, which every distribution kernel has).
//!
//! One read costs one `pread` (about 0.5 µs on the 2-vCPU VM, counted by `looplab bench`): a
//! stage reads when its input arrives (the run-queue time since its last read: the hop's wake-up
//! wait), and again when it publishes only if its computation took longer than
//! [`COMPUTE_READ_NS`], so that a long computation's own queueing is told apart; a short one's is
//! at most that long and goes with the next wait, clipped to the hop by the monitor.

use std::fs::File;
use std::os::unix::fs::FileExt;

use crate::contract::msg::SchedStamp;

/// A computation longer than this gets a read of its own at publish (ns).
pub const COMPUTE_READ_NS: u64 = 10_000;

/// `LOOPLAB_SCHEDSTAT=off` in a loop process's environment: no reads, every stamp zero. What
/// `looplab bench` runs beside the loop to measure the reads' cost on it.
pub const OFF_ENV: &str = "LOOPLAB_SCHEDSTAT";

/// The calling thread's cumulative run-queue wait, read from its schedstat.
pub struct RunQueue {
    /// None where the kernel has no schedstat: every stamp stays zero.
    file: Option<File>,
    /// The run-queue total at the last read, ns.
    last: u64,
}

impl RunQueue {
    /// Opens the calling thread's schedstat; call it on the thread that reads it.
    pub fn open() -> Self {
        let off = std::env::var_os(OFF_ENV).is_some_and(|value| value == "off");
        let file = if off { None } else { File::open("/proc/thread-self/schedstat").ok() };
        let mut clock = Self { file, last: 0 };
        clock.last = clock.total_ns().unwrap_or(0);
        clock
    }

    /// Whether the kernel tells (a missing schedstat leaves every stamp zero).
    pub fn available(&self) -> bool {
        self.file.is_some()
    }

    /// The thread's run-queue wait since it started, ns: schedstat's second field.
    fn total_ns(&self) -> Option<u64> {
        let file = self.file.as_ref()?;
        let mut buf = [0u8; 96];
        let n = file.read_at(&mut buf, 0).ok()?;
        parse_run_delay(&buf[..n])
    }

    /// The run-queue wait since the last read, ns (0 where the kernel does not tell).
    pub fn since_last(&mut self) -> u64 {
        match self.total_ns() {
            Some(total) => {
                let delta = total.saturating_sub(self.last);
                self.last = total;
                delta
            }
            None => 0,
        }
    }

    /// A stage's stamp for one loop: `waited` was read when its input arrived; the computation
    /// from `received_ns` to `now_ns` gets a read of its own if it was long.
    pub fn stamp(&mut self, waited: u64, received_ns: u64, now_ns: u64) -> SchedStamp {
        let long = now_ns.saturating_sub(received_ns) > COMPUTE_READ_NS;
        SchedStamp { queued_ns: clamp(waited), compute_queued_ns: if long { clamp(self.since_last()) } else { 0 } }
    }
}

/// ns as the stamp holds them (a wait of over 4 s reads as 4.29 s).
pub fn clamp(ns: u64) -> u32 {
    ns.min(u32::MAX as u64) as u32
}

/// schedstat is "<on cpu ns> <run queue ns> <timeslices>\n".
fn parse_run_delay(text: &[u8]) -> Option<u64> {
    let field = text.split(|&b| b == b' ').nth(1)?;
    let mut value: u64 = 0;
    for &b in field {
        if !b.is_ascii_digit() {
            return None;
        }
        value = value.checked_mul(10)?.checked_add(u64::from(b - b'0'))?;
    }
    (!field.is_empty()).then_some(value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_run_queue_field_is_the_second() {
        assert_eq!(parse_run_delay(b"126751317 97548818 39\n"), Some(97548818));
        assert_eq!(parse_run_delay(b"1 0 1\n"), Some(0));
        assert_eq!(parse_run_delay(b"126751317\n"), None);
        assert_eq!(parse_run_delay(b"1 x 2\n"), None);
    }

    #[test]
    fn this_thread_reads_its_own_run_queue_wait() {
        let mut clock = RunQueue::open();
        // Every Linux kernel LoopLab supports has schedstat; where one does not, stamps stay 0.
        if !clock.available() {
            return;
        }
        let first = clock.total_ns().expect("readable");
        assert!(clock.total_ns().expect("readable") >= first, "cumulative");
        let _ = clock.since_last();
        let stamp = clock.stamp(5, 0, 1_000);
        assert_eq!(stamp, SchedStamp { queued_ns: 5, compute_queued_ns: 0 }, "a short computation is not read");
    }
}
