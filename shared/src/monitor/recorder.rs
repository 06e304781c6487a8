//! A [`Recording`] on a thread of its own, fed in batches: an in-process run's loop thread only
//! copies each message into a batch, and the joining, the statistics and the files (text
//! formatting, JSON, compression) run beside it, on the other core.

use std::thread::JoinHandle;

use anyhow::{Result, anyhow};

use crate::contract::report::MonitorReport;
use crate::monitor::batches::{BatchSender, batches};
use crate::monitor::join::Sample;
use crate::monitor::recording::Recording;

/// Messages handed over at a time: some fifty loops, so that the loop thread pays for a
/// hand-over (and maybe a wake-up of the recorder) every fifty loops, not every message, and
/// the batches in flight (128 KB each) stay in the cores' caches: batches four times as large
/// cost both threads a third more time.
const BATCH: usize = 256;

pub struct RecordingThread {
    samples: BatchSender<Sample>,
    thread: JoinHandle<Result<MonitorReport>>,
}

impl RecordingThread {
    /// Starts `recording` on a thread of its own.
    pub fn spawn(mut recording: Recording) -> Result<Self> {
        let (samples, received) = batches(BATCH);
        let thread = std::thread::Builder::new().name("recording".into()).spawn(move || {
            while let Some(mut batch) = received.recv() {
                batch.drain(..).try_for_each(|sample| recording.take(sample))?;
                received.give_back(batch);
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
