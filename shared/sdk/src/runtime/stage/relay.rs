//! The process runner of a stage: wake on input, let the [`StageRunner`] handle it, stamp the
//! loop trace and publish. The sensors, estimator and controller processes are this loop around
//! their task.

use std::collections::VecDeque;

use anyhow::Result;

use crate::config::launch::Mode;
use crate::contract::clock::now_ns;
use crate::contract::msg::{Message, Stamp};
use crate::contract::protocol::ChildEvent;
use crate::contract::role::Role;
use crate::runtime::stage::child::emit;
use crate::runtime::stage::child::{Context, WAIT_SLICE};
use crate::runtime::stage::sched::RunQueue;
use crate::runtime::stage::task::{StageRunner, Task};
use crate::runtime::storage::snapshot::{FrozenSnapshot, MAX_FROZEN_BYTES, Snapshot, stage_frozen};
use crate::runtime::transport::ipc::{TopicPublisher, TopicSubscriber};
use crate::runtime::transport::wait::{ArrivalModel, Waiter, reader_blocks, writer_wakes};

/// Sends the held-back outputs whose time has come, in order.
fn release_due<O: Message>(delayed: &mut VecDeque<(u64, O)>, publisher: &TopicPublisher<O>) -> Result<()> {
    while let Some((at, _)) = delayed.front()
        && *at <= now_ns()
    {
        let (_, out) = delayed.pop_front().expect("a front");
        publisher.send(&out)?;
    }
    Ok(())
}

/// Runs `task` as the process of `role` until a stop is requested (or the task fails).
pub fn relay<T: Task>(context: &Context, role: Role, task: T) -> Result<ChildEvent> {
    let (input, output) = (role.input().expect("a stage has an input"), role.output().expect("and an output"));
    let (wait_settings, realtime) = (&context.config.wait, context.config.mode == Mode::Realtime);
    let subscriber: TopicSubscriber<T::In> =
        context.ipc.stage_subscriber(input, reader_blocks(wait_settings, input, realtime))?;
    let publisher: TopicPublisher<T::Out> = context.ipc.publisher(output, writer_wakes(&context.config, output))?;
    // The frozen state of the task survives a restart in the run's snapshot folder.
    let mut kept: Option<FrozenSnapshot> =
        if T::FREEZES { Some(FrozenSnapshot::open(&context.run_id, role.name(), MAX_FROZEN_BYTES)?) } else { None };
    let mut runner = StageRunner::new(task, role, &context.config, context.incarnation);
    if context.incarnation > 0
        && let Some(frozen) = kept.as_ref().and_then(FrozenSnapshot::newest)
    {
        runner.task.thaw(&frozen)?;
    }
    // Lockstep: the input being handled, kept until its output is out. The loop waits for this
    // stage's output, so a predecessor that died in the middle of a loop (its step failed) left
    // an input nobody will send again: its successor handles it first.
    let mut in_flight: Option<Snapshot<InFlight<T::In>>> =
        if realtime { None } else { Some(Snapshot::open(&context.run_id, &format!("{}-input", role.name()))?) };
    let mut replay = in_flight
        .as_ref()
        .and_then(|j| j.read())
        .filter(|j| j.pending != 0 && context.incarnation > 0)
        .map(|j| j.input);
    subscriber.connect(&context.stop, context.config.supervision.connect_timeout())?;
    emit(&ChildEvent::Ready)?;

    let mut last_k: Option<u64> = None;
    let period_ns = context.config.period_ns();
    let mut waiter = Waiter::new(wait_settings, role, realtime, period_ns);
    let mut arrivals = ArrivalModel::new(period_ns);
    let mut run_queue = RunQueue::open();
    // Real time: outputs a delay fault holds back, each with when it goes out, in order (a
    // transport delay: the stage goes on computing the next loops meanwhile).
    let mut delayed: VecDeque<(u64, T::Out)> = VecDeque::new();
    while !context.stop.requested() {
        release_due(&mut delayed, &publisher)?;
        // With outputs held back, wake for the first of them too.
        let next_release = delayed.front().map(|(at, _)| *at);
        let due = if next_release.is_some() { None } else { last_k.and_then(|k| arrivals.due(k + 1)) };
        let slice_end = (now_ns() + WAIT_SLICE.as_nanos() as u64).min(next_release.unwrap_or(u64::MAX));
        if replay.is_none() {
            waiter.wait(
                due,
                slice_end,
                || subscriber.has_samples(),
                |until| subscriber.doze_until(until),
                || subscriber.doze_until(slice_end),
            )?;
        }
        let mut cleared = false;
        loop {
            let replayed = replay.take();
            let sample = if replayed.is_none() { subscriber.next(&mut cleared)? } else { None };
            let input: &T::In = match (&replayed, &sample) {
                (Some(input), _) => input,
                (None, Some(sample)) => sample,
                (None, None) => break,
            };
            let received = now_ns();
            let waited = run_queue.since_last();
            let header = *input.header();
            arrivals.observe(header.k, header.trace.get(Stamp::PlantPublish), received);
            if let Some(journal) = in_flight.as_mut() {
                journal.write(&InFlight { input: *input, pending: 1 });
            }
            let handled = runner.handle(input)?;
            // Lockstep: the state is kept before the output goes out, so that a kill injected
            // at a later loop (with the plant holding the loop) always finds this loop's state;
            // real time: after the send, off the hop's path.
            if !realtime {
                keep(&mut kept, &runner.task, header.k)?;
            }
            if let Some(mut out) = handled.output {
                // A long computation's own read, before the publish stamp: it is part of the stage.
                let sched = run_queue.stamp(waited, received, now_ns());
                let out_header = out.header_mut();
                out_header.trace.stamp(role, received, now_ns());
                out_header.sched = sched;
                // A held-back output goes out after its delay, and every later one after it (in
                // order, as a link delivers them); the time held shows in the next hop.
                match handled.hold {
                    None if delayed.is_empty() => publisher.send(&out)?,
                    hold => delayed.push_back((now_ns() + hold.map_or(0, |d| d.as_nanos() as u64), out)),
                }
                release_due(&mut delayed, &publisher)?;
                last_k = Some(header.k);
            }
            if let Some(journal) = in_flight.as_mut() {
                journal.write(&InFlight { input: *input, pending: 0 });
            }
            // After the send, off the hop's path: the input's chunk goes back.
            drop(sample);
            if realtime {
                keep(&mut kept, &runner.task, header.k)?;
            }
        }
    }
    // What a delay still held when the run stopped goes out: the loop may wait for it.
    for (_, out) in delayed.drain(..) {
        publisher.send(&out)?;
    }
    let mut report = runner.report;
    (report.waited, report.dropped) = publisher.backpressure();
    report.wait = waiter.counts;
    Ok(ChildEvent::StageReport(report))
}

/// A lockstep stage's input while it is handled.
#[derive(Clone, Copy)]
#[repr(C)]
struct InFlight<I> {
    input: I,
    /// 1 from its arrival until its output is sent.
    pending: u32,
}

/// Writes the task's frozen state of loop k to its snapshot, if it has one.
fn keep<T: Task>(kept: &mut Option<FrozenSnapshot>, task: &T, k: u64) -> Result<()> {
    if let Some(kept) = kept.as_mut()
        && let Some(frozen) = stage_frozen(task.freeze()?)?
    {
        kept.write(k, &frozen);
    }
    Ok(())
}
