//! CLOCK_MONOTONIC stamps and the plant's absolute-deadline tick timer.

use std::io;

use iceoryx2::prelude::{FileDescriptor, FileDescriptorBased, SynchronousMultiplexing};

/// CLOCK_MONOTONIC in nanoseconds: the one clock every process of a run stamps with.
/// The loop period in whole ns at `rate_hz`: the plant's schedule keeps its ticks this far apart,
/// and everything that turns the rate into ticks (the monitor, the injector, the figures, the
/// traces) takes it from here, so all say the same period.
pub fn period_ns(rate_hz: f64) -> u64 {
    (1.0 / rate_hz * 1e9).round() as u64
}

pub fn now_ns() -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// User plus system CPU time of a `getrusage`/`wait4` result, in seconds.
pub fn cpu_seconds(usage: &libc::rusage) -> f64 {
    let secs = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    secs(usage.ru_utime) + secs(usage.ru_stime)
}

/// A periodic timerfd on CLOCK_MONOTONIC with an absolute first expiry. The kernel keeps the
/// schedule (start + k·period), so wake-ups never drift, unlike WaitSet intervals, which have
/// millisecond resolution. It can be attached to an iceoryx2 WaitSet.
#[derive(Debug)]
pub struct TickTimer {
    fd: FileDescriptor,
}

fn timespec(ns: u64) -> libc::timespec {
    libc::timespec { tv_sec: (ns / 1_000_000_000) as libc::time_t, tv_nsec: (ns % 1_000_000_000) as libc::c_long }
}

impl TickTimer {
    /// First expiry at `start_ns` (CLOCK_MONOTONIC), then every `period_ns`.
    pub fn new(start_ns: u64, period_ns: u64) -> io::Result<Self> {
        // SAFETY: plain syscalls on a descriptor we own; arguments are valid for their lifetime.
        unsafe {
            let fd = libc::timerfd_create(libc::CLOCK_MONOTONIC, libc::TFD_NONBLOCK | libc::TFD_CLOEXEC);
            if fd < 0 {
                return Err(io::Error::last_os_error());
            }
            let fd = FileDescriptor::new(fd).ok_or_else(|| io::Error::other("timerfd is not a valid descriptor"))?;
            let spec = libc::itimerspec { it_interval: timespec(period_ns), it_value: timespec(start_ns) };
            if libc::timerfd_settime(fd.native_handle(), libc::TFD_TIMER_ABSTIME, &spec, std::ptr::null_mut()) < 0 {
                return Err(io::Error::last_os_error());
            }
            Ok(Self { fd })
        }
    }

    /// Number of periods that expired since the last call (0 if none); consumes them.
    pub fn expirations(&self) -> u64 {
        let mut count: u64 = 0;
        // SAFETY: reads 8 bytes into a u64 we own from a non-blocking timerfd.
        let n = unsafe { libc::read(self.fd.native_handle(), (&mut count as *mut u64).cast(), 8) };
        if n == 8 { count } else { 0 }
    }
}

impl FileDescriptorBased for TickTimer {
    fn file_descriptor(&self) -> &FileDescriptor {
        &self.fd
    }
}

impl SynchronousMultiplexing for TickTimer {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timer_counts_expired_periods() {
        const HOUR: u64 = 3_600_000_000_000;
        let due = TickTimer::new(now_ns(), HOUR).unwrap();
        let later = TickTimer::new(now_ns() + HOUR, HOUR).unwrap();
        std::thread::sleep(std::time::Duration::from_millis(2));
        assert_eq!(due.expirations(), 1, "the first, absolute expiry has passed");
        assert_eq!(due.expirations(), 0, "expirations are consumed");
        assert_eq!(later.expirations(), 0);
    }
}
