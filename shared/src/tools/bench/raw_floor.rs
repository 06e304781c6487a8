//! The physical floor of a hop: two processes, each pinned to a CPU of its own, pass one cache
//! line back and forth in shared memory, paced at the loop's rate. Nothing but the cache line's
//! trip between the two cores and the clock reads that stamp it: what a hop between two
//! processes costs at least on this machine, whatever the transport.
//!
//! The parent writes (sequence, sent) into the ping line; the echo process (`looplab bench-echo
//! --transport raw`), spinning on it, stamps its arrival and answers in the pong line. Both
//! one-way trips are measured, as in the ping-pong of `super::pingpong`.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow, bail};

use crate::contract::clock::now_ns;
use crate::runtime::signals::StopFlag;
use crate::runtime::storage::shared_file::{self, Open};
use crate::runtime::transport::wait::sleep_until;

/// One direction's cache line. Two lines apart, so that the adjacent-line prefetcher does not
/// pull the other direction's line along.
#[repr(C, align(128))]
#[derive(Default)]
struct Line {
    sequence: AtomicU64,
    /// Pong only: when the echo wrote the line.
    sent: AtomicU64,
    /// Pong only: when the echo saw the ping.
    received: AtomicU64,
}

#[repr(C)]
#[derive(Default)]
struct Lines {
    ping: Line,
    pong: Line,
}

/// The sequence number that ends the echo.
const END: u64 = u64::MAX;

/// The two lines, mapped from a file of the bench's run folder (tmpfs).
struct Mapping {
    lines: *const Lines,
}

impl Mapping {
    fn map(path: &Path, create: bool) -> Result<Self> {
        let open = if create { Open::New } else { Open::Existing };
        // Zero-filled when new: a valid Lines, every counter zero.
        Ok(Self { lines: shared_file::map(path, std::mem::size_of::<Lines>(), open)?.cast() })
    }

    fn lines(&self) -> &Lines {
        // SAFETY: mapped for the life of self, only ever accessed through atomics.
        unsafe { &*self.lines }
    }
}

impl Drop for Mapping {
    fn drop(&mut self) {
        // SAFETY: unmaps what `map` mapped.
        unsafe { shared_file::unmap(self.lines as *mut libc::c_void, std::mem::size_of::<Lines>()) };
    }
}

fn file_of(run_id: &str) -> PathBuf {
    crate::runtime::storage::run_storage::run_folder(run_id).join("raw-floor")
}

/// Pins the calling thread to `cpu`; returns the CPUs it had, to restore.
pub(super) fn pin_to(cpu: usize) -> libc::cpu_set_t {
    // SAFETY: zeroed cpu_set_t values are valid empty sets; the calls fill or read them.
    unsafe {
        let mut before: libc::cpu_set_t = std::mem::zeroed();
        libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut before);
        let mut only: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu, &mut only);
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &only);
        before
    }
}

/// The first two CPUs this thread may run on, for the two ends of a pinned ping-pong.
pub(super) fn two_cpus() -> Option<(usize, usize)> {
    let mut cpus = crate::runtime::transport::wait::allowed_cpus().into_iter();
    Some((cpus.next()?, cpus.next()?))
}

pub(super) fn restore(cpus: &libc::cpu_set_t) {
    // SAFETY: a set read by sched_getaffinity.
    unsafe { libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), cpus) };
}

/// The echo process: pinned to `cpu`, it answers every ping until the end marker.
pub fn echo_main(run_id: &str, cpu: usize) -> Result<()> {
    let stop = StopFlag::install()?;
    pin_to(cpu);
    let mapping = Mapping::map(&file_of(run_id), false)?;
    let Lines { ping, pong } = mapping.lines();
    println!("ready");
    let mut last = 0;
    let mut spins = 0u64;
    loop {
        let k = ping.sequence.load(Ordering::Acquire);
        if k == last {
            spins += 1;
            if spins.is_multiple_of(1 << 20) && stop.requested() {
                return Ok(());
            }
            std::hint::spin_loop();
            continue;
        }
        let received = now_ns();
        if k == END {
            return Ok(());
        }
        pong.received.store(received, Ordering::Relaxed);
        pong.sent.store(now_ns(), Ordering::Relaxed);
        pong.sequence.store(k, Ordering::Release);
        last = k;
    }
}

/// Runs `rounds` pings, one every `period_ns`, between this thread pinned to one CPU and an echo
/// process pinned to another; returns the one-way trips, ns, two per round.
pub fn measure(exe: &Path, run_id: &str, period_ns: u64, rounds: usize) -> Result<Vec<u64>> {
    let (near, far) = two_cpus().ok_or_else(|| anyhow!("the raw floor needs two CPUs"))?;
    let path = file_of(run_id);
    let mapping = Mapping::map(&path, true)?;
    let result = (|| {
        let mut command = std::process::Command::new(exe);
        command
            .args(["bench-echo", "--transport", "raw", "--mode", "spin", "--max-bytes", "0"])
            .args(["--cpu", &far.to_string(), "--run-id", run_id, "--period-ns", &period_ns.to_string()])
            .stdin(std::process::Stdio::null())
            .stdout(std::process::Stdio::piped());
        crate::launcher::supervised(&mut command);
        let mut child = command.spawn().context("start the raw echo process")?;
        let mut ready = String::new();
        std::io::BufRead::read_line(&mut std::io::BufReader::new(child.stdout.take().expect("piped")), &mut ready)?;
        let before = pin_to(near);
        let measured = ping_pong(mapping.lines(), period_ns, rounds);
        restore(&before);
        mapping.lines().ping.sequence.store(END, Ordering::Release);
        child.wait()?;
        measured
    })();
    drop(mapping);
    let _ = std::fs::remove_file(&path);
    result
}

fn ping_pong(lines: &Lines, period_ns: u64, rounds: usize) -> Result<Vec<u64>> {
    let Lines { ping, pong } = lines;
    let warm_up = (rounds / 10).clamp(5, 200) as u64;
    let mut one_way = Vec::with_capacity(2 * rounds);
    let first = now_ns() + 10_000_000;
    for k in 1..=warm_up + rounds as u64 {
        sleep_until(first + k * period_ns);
        let sent = now_ns();
        ping.sequence.store(k, Ordering::Release);
        let give_up = Instant::now() + Duration::from_secs(2);
        let mut spins = 0u64;
        while pong.sequence.load(Ordering::Acquire) != k {
            spins += 1;
            if spins.is_multiple_of(1 << 16) && Instant::now() > give_up {
                bail!("no answer to raw ping {k} from the echo process");
            }
            std::hint::spin_loop();
        }
        let arrived = now_ns();
        if k > warm_up {
            one_way.push(pong.received.load(Ordering::Relaxed).saturating_sub(sent));
            one_way.push(arrived.saturating_sub(pong.sent.load(Ordering::Relaxed)));
        }
    }
    Ok(one_way)
}
