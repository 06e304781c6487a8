//! Where a hop's time goes: one loop message sent through the loop's own ports
//! (`runtime::transport::ipc`, the same services and settings) from a writer pinned to one CPU to a spinning
//! reader pinned to another, paced at 1 kHz, with a clock stamp between every step:
//!
//! - writer: `deliver` (the call that loans, writes the message and hands it to every reader),
//!   then `wake` (the notifier's syscall, which only a blocking reader needs);
//! - reader: `seen` (from the start of `deliver` until its poll sees the sample: it can see it
//!   before the writer's call returns), `take` (receive it, in place), `copy` (copying the whole
//!   message out, which stages did before), `release` (giving the chunk back to the writer, now
//!   done after the stage has published).
//!
//! Variants: with and without the monitor's passive reader on the topic, and the largest loop
//! message (the measurements). The two ends are threads of one process: the trip between two
//! cores through shared memory is the same as between two processes.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Result, anyhow, bail};
use serde::Serialize;

use super::Dist;
use super::raw_floor::{pin_to, restore, two_cpus};
use crate::config::launch::Mode;
use crate::contract::clock::now_ns;
use crate::contract::msg::{Measurements, Message, PlantState};
use crate::contract::role::Topic;
use crate::runtime::signals::StopFlag;
use crate::runtime::transport::ipc::{Ipc, Wake};
use crate::runtime::transport::wait::sleep_until;

/// The steps of one hop, in order.
pub const STEPS: [&str; 6] = ["deliver", "wake", "seen", "take", "copy", "release"];

#[derive(Debug, Clone, Serialize)]
pub struct AnatomyRow {
    pub variant: String,
    pub message_bytes: usize,
    /// Each step's time, µs.
    pub steps_us: BTreeMap<String, Dist>,
    /// The hop as stages stamped it before (start of deliver to release) and as they stamp it
    /// now (to take), µs.
    pub hop_before_us: Dist,
    pub hop_now_us: Dist,
}

/// The reader's stamps of the newest sample, handed to the writer.
#[derive(Default)]
struct ReaderStamps {
    k: AtomicU64,
    seen: AtomicU64,
    taken: AtomicU64,
    copied: AtomicU64,
    released: AtomicU64,
}

/// The loop's period, ns: between two messages the writer sleeps, as a 1 kHz plant does.
const PACED: u64 = 1_000_000;

/// Runs the variants, `rounds` hops each, in the bench's run `run_id`: paced at 1 kHz, and back
/// to back (caches warm, the CPUs never idle).
pub fn measure(run_id: &str, rounds: usize) -> Result<Vec<AnatomyRow>> {
    Ok(vec![
        variant::<PlantState>(run_id, "state, monitor reading", Topic::State, true, PACED, rounds)?,
        variant::<PlantState>(run_id, "state, no monitor", Topic::State, false, PACED, rounds)?,
        variant::<Measurements>(run_id, "measurements, monitor reading", Topic::Measurements, true, PACED, rounds)?,
        variant::<PlantState>(run_id, "state, monitor reading, back to back", Topic::State, true, 0, rounds)?,
    ])
}

fn variant<T: Message>(
    run_id: &str,
    name: &str,
    topic: Topic,
    monitor: bool,
    period: u64,
    rounds: usize,
) -> Result<AnatomyRow> {
    let (near, far) = two_cpus().ok_or_else(|| anyhow!("the hop anatomy needs two CPUs"))?;
    let stamps = Arc::new(ReaderStamps::default());
    let done = Arc::new(AtomicBool::new(false));
    let ready = Arc::new(AtomicBool::new(false));
    let reader = {
        let (run_id, stamps, done, ready) = (run_id.to_owned(), stamps.clone(), done.clone(), ready.clone());
        std::thread::spawn(move || read::<T>(&run_id, far, topic, &stamps, &done, &ready))
    };
    let before = pin_to(near);
    let written = write::<T>(run_id, topic, monitor, period, rounds, &stamps, &ready);
    restore(&before);
    done.store(true, Ordering::Relaxed);
    let read = reader.join().map_err(|_| anyhow!("the anatomy's reader panicked"))?;
    let steps = written?;
    read?;
    let dist = |v: &[u64]| {
        let mut v = v.to_vec();
        v.sort_unstable();
        Dist::of(&v)
    };
    let step = |i: usize| steps.iter().map(|s| s[i]).collect::<Vec<u64>>();
    // The reader's path: seen, take, copy, release (deliver and wake are the writer's calls).
    let sum = |range: std::ops::RangeInclusive<usize>| {
        steps.iter().map(|s| s[range.clone()].iter().sum()).collect::<Vec<u64>>()
    };
    Ok(AnatomyRow {
        variant: name.to_owned(),
        message_bytes: std::mem::size_of::<T>(),
        steps_us: STEPS.iter().enumerate().map(|(i, s)| ((*s).to_owned(), dist(&step(i)))).collect(),
        hop_before_us: dist(&sum(2..=5)),
        hop_now_us: dist(&sum(2..=3)),
    })
}

/// The writer: one message per period (0: back to back), timed step by step; returns per hop the six steps, ns.
fn write<T: Message>(
    run_id: &str,
    topic: Topic,
    monitor: bool,
    period: u64,
    rounds: usize,
    stamps: &ReaderStamps,
    ready: &AtomicBool,
) -> Result<Vec<[u64; 6]>> {
    let ipc = Ipc::new("anatomy-writer", run_id, Mode::Realtime)?;
    let publisher = ipc.publisher::<T>(topic, Wake::Futex)?;
    let monitor = if monitor { Some(ipc.passive_subscriber::<T>(topic)?) } else { None };
    let until = Instant::now() + Duration::from_secs(10);
    while !ready.load(Ordering::Acquire) {
        if Instant::now() > until {
            bail!("the anatomy's reader did not start");
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    let warm_up = (rounds / 10).clamp(5, 200) as u64;
    let mut steps = Vec::with_capacity(rounds);
    let first = now_ns() + 10_000_000;
    for k in 1..=warm_up + rounds as u64 {
        if period > 0 {
            sleep_until(first + k * period);
        }
        let mut message = T::default();
        message.header_mut().k = k;
        let start = now_ns();
        publisher.deliver(&message)?;
        let delivered = now_ns();
        publisher.wake()?;
        let woken = now_ns();
        let give_up = Instant::now() + Duration::from_secs(2);
        while stamps.k.load(Ordering::Acquire) != k {
            if Instant::now() > give_up {
                bail!("the anatomy's reader did not see message {k}");
            }
            std::hint::spin_loop();
        }
        let [seen, taken, copied, released] =
            [&stamps.seen, &stamps.taken, &stamps.copied, &stamps.released].map(|s| s.load(Ordering::Relaxed));
        if let Some(monitor) = &monitor {
            while monitor.receive()?.is_some() {}
        }
        if k > warm_up {
            steps.push([
                delivered - start,
                woken - delivered,
                seen.saturating_sub(start),
                taken - seen,
                copied - taken,
                released - copied,
            ]);
        }
    }
    Ok(steps)
}

/// The reader: spins on the topic like a spinning stage and stamps each step.
fn read<T: Message>(
    run_id: &str,
    cpu: usize,
    topic: Topic,
    stamps: &ReaderStamps,
    done: &AtomicBool,
    ready: &AtomicBool,
) -> Result<()> {
    pin_to(cpu);
    let ipc = Ipc::new("anatomy-reader", run_id, Mode::Realtime)?;
    // With a listener, so that the writer's wake-up is the real syscall; it never waits on it.
    let subscriber = ipc.stage_subscriber::<T>(topic, true)?;
    subscriber.connect(&StopFlag::install()?, std::time::Duration::from_secs(20))?;
    ready.store(true, Ordering::Release);
    while !done.load(Ordering::Relaxed) {
        if !subscriber.has_samples()? {
            std::hint::spin_loop();
            continue;
        }
        let seen = now_ns();
        let mut cleared = true;
        let Some(sample) = subscriber.next(&mut cleared)? else { continue };
        let taken = now_ns();
        let copy: T = *sample;
        let copied = now_ns();
        drop(sample);
        let released = now_ns();
        subscriber.clear_wakeups()?;
        stamps.seen.store(seen, Ordering::Relaxed);
        stamps.taken.store(taken, Ordering::Relaxed);
        stamps.copied.store(copied, Ordering::Relaxed);
        stamps.released.store(released, Ordering::Relaxed);
        stamps.k.store(std::hint::black_box(copy).header().k, Ordering::Release);
    }
    Ok(())
}
