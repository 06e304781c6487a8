//! The monitor process: a passive reader of every topic that never slows the loop.
//!
//! Its readers have no listeners, so publishing never wakes it; it polls every few milliseconds
//! with deep buffers (real-time mode: safe overflow, so a slow monitor loses samples, counted,
//! and never blocks a stage). The receive loop only copies samples out of shared memory, feeds
//! the stall watch and hands each drain's samples over to the [`RecordingThread`], which runs
//! the [`Recording`] and sends the live status to the launcher. One hand-over per drain wakes the
//! recorder once per poll, not once per sample: on two CPUs each of its wake-ups can take a CPU
//! from a stage of the loop.

use std::fmt::Debug;
use std::time::{Duration, Instant};

use anyhow::Result;
use iceoryx2::prelude::ZeroCopySend;

use crate::config::launch::Mode;
use crate::contract::clock::now_ns;
use crate::contract::msg::MONITOR_BUFFER;
use crate::contract::protocol::ChildEvent;
use crate::model::scenario::Scenario;
use crate::monitor::join::Sample;
use crate::monitor::recording::{Recording, StatusCallback};
use crate::monitor::recording_thread::{RecorderOptions, RecordingThread};
use crate::monitor::stall::StallWatch;
use crate::runtime::stage::child::Context;
use crate::runtime::stage::child::{emit, emit_if_room};
use crate::runtime::transport::ipc::{Topic, TopicSubscriber};

/// Sleep between drains when the queues were nearly empty.
const POLL_PERIOD: Duration = Duration::from_millis(5);
/// How often the live status goes to the launcher; the files are flushed as often, so that a
/// killed monitor loses little.
const STATUS_PERIOD: Duration = Duration::from_millis(100);
/// How often the receive loop tells the launcher it runs (the monitor's heartbeat; the launcher
/// finds a stopped monitor by its silence). From the receive loop, not the recorder, which runs
/// at the lowest priority and may lag.
const HEARTBEAT_PERIOD: Duration = Duration::from_millis(20);

/// One topic's reader and how its samples go to the recorder.
struct Reader<T: Debug + ZeroCopySend + 'static> {
    subscriber: TopicSubscriber<T>,
    wrap: fn(T) -> Sample,
}

impl<T: Debug + ZeroCopySend + Copy + 'static> Reader<T> {
    fn new(context: &Context, topic: Topic, wrap: fn(T) -> Sample) -> Result<Self> {
        Ok(Self { subscriber: context.ipc.passive_subscriber(topic)?, wrap })
    }

    /// Passes every sample queued to `recording`; returns how many there were.
    fn drain(&self, watch: &mut StallWatch, recording: &mut RecordingThread) -> Result<usize> {
        let mut n = 0;
        while let Some(message) = self.subscriber.receive()? {
            let sample = (self.wrap)(message);
            let (k, topic) = sample.key();
            watch.saw(topic, k, sample.published_ns());
            recording.take(sample)?;
            n += 1;
        }
        Ok(n)
    }
}

pub fn run(context: &Context, scenario: &dyn Scenario) -> Result<ChildEvent> {
    let config = &context.config;
    let states = Reader::new(context, Topic::State, Sample::State)?;
    let measurements = Reader::new(context, Topic::Measurements, Sample::Measurements)?;
    let estimates = Reader::new(context, Topic::Estimate, Sample::Estimate)?;
    let commands = Reader::new(context, Topic::Command, Sample::Command)?;
    let records = Reader::new(context, Topic::Loop, Sample::Loop)?;
    // Every reader exists before any waits for its writer.
    states.subscriber.connect(&context.stop, context.config.supervision.connect_timeout())?;
    measurements.subscriber.connect(&context.stop, context.config.supervision.connect_timeout())?;
    estimates.subscriber.connect(&context.stop, context.config.supervision.connect_timeout())?;
    commands.subscriber.connect(&context.stop, context.config.supervision.connect_timeout())?;
    records.subscriber.connect(&context.stop, context.config.supervision.connect_timeout())?;
    // Only shown, so dropped when the launcher is not reading (stopped): the recording goes on.
    let status: StatusCallback =
        Box::new(|status| emit_if_room(&ChildEvent::Status(Box::new(status.clone()))).map(|_| ()));
    // Its running state goes on across restarts: the report covers the whole run. Each kill and
    // stop is judged from when the launcher says it really injected it.
    let recording = Recording::new(config, scenario, &context.run_dir, context.incarnation, Some(status))?
        .with_snapshot(crate::monitor::resume::path(&context.run_id)?, scenario)
        .with_injections(crate::monitor::injections::path(&context.run_id)?);
    // The mode's one say in the monitor process. In real time the monitor must never slow the
    // loop: its recorder (histograms, metrics, files: nearly all its work) runs at the lowest
    // priority, and the buffers hold a second of samples to catch up with. The receive loop
    // below stays at normal priority: it only copies samples out and watches for stalls, a few
    // microseconds per poll, and a starved one would see a stall too late (or lose samples).
    // The plant ticks on a clock there, so silence is a stall.
    let (plant_period_ns, background) = match config.mode {
        Mode::Realtime => (Some(config.period_ns()), true),
        Mode::Lockstep => (None, false),
    };
    emit(&ChildEvent::Ready)?;

    // The receive loop never waits for the recorder: a late recorder queues samples up rather
    // than leave them in shared memory to be lost.
    let options = RecorderOptions { in_flight: None, checkpoint_every: Some(STATUS_PERIOD), background };
    let mut recording = RecordingThread::spawn(recording, options)?;

    let timeout_ns = (config.supervision.stall_timeout_s * 1e9) as u64;
    let mut watch = StallWatch::new(timeout_ns, config.loops(), plant_period_ns, Box::new(now_ns));
    let mut last_heartbeat = Instant::now();
    let mut drain = || -> Result<usize> {
        // In the order data flows, so a loop's parts tend to arrive together.
        let n = states.drain(&mut watch, &mut recording)?
            + measurements.drain(&mut watch, &mut recording)?
            + estimates.drain(&mut watch, &mut recording)?
            + commands.drain(&mut watch, &mut recording)?
            + records.drain(&mut watch, &mut recording)?;
        for event in watch.check() {
            emit(&event)?;
        }
        if last_heartbeat.elapsed() >= HEARTBEAT_PERIOD {
            last_heartbeat = Instant::now();
            // Dropped while the launcher does not read: it only says the monitor is up.
            emit_if_room(&ChildEvent::Alive)?;
        }
        recording.hand_over()?;
        Ok(n)
    };
    let drained = (|| -> Result<()> {
        while !context.stop.requested() {
            if drain()? < MONITOR_BUFFER / 8 {
                std::thread::sleep(POLL_PERIOD);
            }
        }
        // The launcher stops the monitor last: everything the loop sent is queued by now.
        while drain()? > 0 {}
        Ok(())
    })();
    // The recorder's own error first (a full disk): the receive loop only saw it stop.
    let report = recording.finish()?;
    drained?;
    Ok(ChildEvent::MonitorReport(Box::new(report)))
}
