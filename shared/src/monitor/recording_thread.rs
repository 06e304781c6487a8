//! A [`Recording`] on a thread of its own, fed in batches: the thread that reads the loop (an
//! in-process run's loop, the monitor process's receive loop) only copies each message into a
//! batch, and the joining, the statistics and the files (text formatting, JSON, compression) run
//! beside it, on the other core.

use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{Result, anyhow};

use crate::contract::report::MonitorReport;
use crate::monitor::batches::{BatchSender, batches};
use crate::monitor::join::Sample;
use crate::monitor::recording::Recording;

/// Messages handed over at a time: some fifty loops, so that the reading thread pays for a
/// hand-over (and maybe a wake-up of the recorder) every fifty loops, not every message, and
/// the batches in flight (128 KB each) stay in the cores' caches: batches four times as large
/// cost both threads a third more time.
const BATCH: usize = 256;

/// How the two uses differ.
#[derive(Debug, Clone, Copy)]
pub struct RecorderOptions {
    /// The full batches the reading thread may hand over before it waits for the recorder;
    /// None: it never waits (a monitor that waited would lose samples), and they queue up.
    pub in_flight: Option<usize>,
    /// A checkpoint (the live status, the files flushed, the resume state) this often while it
    /// records; None: only the end.
    pub checkpoint_every: Option<Duration>,
    /// Whether the recorder runs at the lowest priority (a real-time run's monitor must never
    /// take a CPU from the loop).
    pub background: bool,
}

impl RecorderOptions {
    /// An in-process run: the loop waits for a recorder four batches behind (its speed is the
    /// run's speed), and the end is the only checkpoint.
    pub const IN_PROCESS: Self = Self { in_flight: Some(4), checkpoint_every: None, background: false };
}

pub struct RecordingThread {
    samples: BatchSender<Sample>,
    thread: JoinHandle<Result<MonitorReport>>,
}

impl RecordingThread {
    /// Starts `recording` on a thread of its own.
    pub fn spawn(mut recording: Recording, options: RecorderOptions) -> Result<Self> {
        let (samples, received) = batches(BATCH, options.in_flight);
        let thread = std::thread::Builder::new().name("recording".into()).spawn(move || {
            if options.background {
                crate::runtime::transport::wait::run_in_background();
            }
            let mut last_checkpoint = Instant::now();
            // Without checkpoints it waits for batches alone (a wait that long never ends).
            let wait = options.checkpoint_every.unwrap_or(Duration::MAX);
            while let Ok(batch) = received.recv_timeout(wait) {
                if let Some(mut batch) = batch {
                    batch.drain(..).try_for_each(|sample| recording.take(sample))?;
                    received.give_back(batch);
                }
                if let Some(period) = options.checkpoint_every
                    && last_checkpoint.elapsed() >= period
                {
                    last_checkpoint = Instant::now();
                    recording.checkpoint()?;
                }
            }
            recording.finish()
        })?;
        Ok(Self { samples, thread })
    }

    /// Takes one message, as [`Recording::take`].
    pub fn take(&mut self, sample: Sample) -> Result<()> {
        // The thread's error comes from `finish`.
        self.samples.push(sample).map_err(|_| anyhow!("the recording stopped"))
    }

    /// Hands over what has been taken so far, without waiting for a full batch (the monitor
    /// process, once per drain: one wake-up of the recorder per poll).
    pub fn hand_over(&mut self) -> Result<()> {
        self.samples.send().map_err(|_| anyhow!("the recording stopped"))
    }

    /// Everything has been taken: records what is left and returns the report, as
    /// [`Recording::finish`], or the error that stopped the recording.
    pub fn finish(mut self) -> Result<MonitorReport> {
        let sent = self.samples.send();
        drop(self.samples);
        let report = self.thread.join().map_err(|_| anyhow!("the recording thread panicked"))??;
        sent.map_err(|_| anyhow!("the recording stopped"))?;
        Ok(report)
    }
}
