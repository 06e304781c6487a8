//! The loop's transport: iceoryx2 publish-subscribe services, each with an event service of
//! the same name that wakes the next stage.
//!
//! Every run has its own id. It is in every service name (`looplab/<run>/<topic>`) and in the
//! iceoryx2 file prefix (`looplab_<run>_<secret>_`), so two runs on one machine never see each
//! other and the launcher can check that nothing of a run is left in shared memory when it ends;
//! the secret ([`crate::runtime::storage::shm_secret`]) keeps another user from creating a run's files
//! before the run does.
//!
//! Quality of service, identical for every process of a run:
//! - real-time mode: safe overflow. A slow reader loses its oldest samples; no publisher ever
//!   waits. The loop's stages read with a one-sample buffer (the newest wins), the monitor with
//!   [`MONITOR_BUFFER`] samples and counts what it lost.
//! - lockstep mode: no overflow. A full reader makes the publisher wait (so the monitor records
//!   every loop of a deterministic run), for at most [`LOCKSTEP_BACKPRESSURE_LIMIT`], after which
//!   the sample is dropped for that reader and counted.

use std::cell::Cell;
use std::fmt::Debug;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow, bail};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::port::{BackpressureAction, BackpressureInfo};
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use iceoryx2::service::attribute::{AttributeKey, AttributeValue};
use iceoryx2::service::builder::publish_subscribe::{PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError};
use iceoryx2::waitset::{WaitSet, WaitSetGuard};

use crate::config::launch::Mode;
use crate::contract::clock::now_ns;
use crate::contract::msg::{MONITOR_BUFFER, layout_fingerprint};
use crate::runtime::signals::StopFlag;
use crate::runtime::transport::reader_state::ReaderState;
pub use crate::runtime::transport::reader_state::Wake;
use crate::runtime::transport::wait::{sleep_until, timespec};

/// Longest a lockstep publisher waits for a full reader before dropping the sample for it.
pub const LOCKSTEP_BACKPRESSURE_LIMIT: Duration = Duration::from_secs(5);
/// Readers per topic: the next stage, the monitor, and room for a restarted one.
const MAX_SUBSCRIBERS: usize = 4;
/// Openers per service; a little room for restarts.
const MAX_NODES: usize = 10;
/// How long to keep retrying a service open while other processes are creating it.
const OPEN_RETRY: Duration = Duration::from_secs(3);

pub use crate::contract::role::Topic;

pub fn service_name(run_id: &str, topic: Topic) -> Result<ServiceName> {
    let name = format!("looplab/{run_id}/{}", topic.name());
    ServiceName::new(&name).map_err(|e| anyhow!("invalid service name {name}: {e:?}"))
}

/// Retries an open-or-create while other processes of the run create the same service.
pub fn retry<T, E: Debug>(what: &str, mut attempt: impl FnMut() -> Result<T, E>) -> Result<T> {
    let start = Instant::now();
    loop {
        match attempt() {
            Ok(v) => return Ok(v),
            Err(e) if start.elapsed() > OPEN_RETRY => return Err(anyhow!("cannot open {what}: {e:?}")),
            Err(_) => std::thread::sleep(Duration::from_millis(5)),
        }
    }
}

/// The service attribute that carries the message layouts' fingerprint.
const LAYOUT_KEY: &str = "looplab.layout";

/// One process's connection to the run's services.
pub struct Ipc {
    node: Node<ipc::Service>,
    config: Config,
    run_id: String,
    mode: Mode,
    /// The message layouts this process was built with ([`layout_fingerprint`]).
    layout: String,
}

impl Ipc {
    pub fn new(process: &str, run_id: &str, mode: Mode) -> Result<Self> {
        Self::with_layout(process, run_id, mode, layout_fingerprint())
    }

    /// As a process built with message layouts of fingerprint `layout` would connect: only a
    /// test that plays a stage from another build has a reason to call it.
    #[doc(hidden)]
    pub fn with_layout(process: &str, run_id: &str, mode: Mode, layout: &str) -> Result<Self> {
        let config = run_config(run_id)?;
        let node = node(process, &config)?;
        Ok(Self { node, config, run_id: run_id.to_owned(), mode, layout: layout.to_owned() })
    }

    /// The fingerprint the service `name` was created with, if it exists and has one.
    fn layout_of(&self, name: &ServiceName) -> Option<String> {
        let details = ipc::Service::details(name, &self.config, MessagingPattern::PublishSubscribe).ok()??;
        let key = AttributeKey::try_from(LAYOUT_KEY).ok()?;
        details.static_details.attributes().key_value(&key, 0).map(|v| v.to_string())
    }

    fn pubsub<T: Debug + ZeroCopySend + 'static>(
        &self,
        topic: Topic,
    ) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>> {
        let name = service_name(&self.run_id, topic)?;
        let safe_overflow = self.mode == Mode::Realtime;
        let key = AttributeKey::try_from(LAYOUT_KEY).map_err(|e| anyhow!("attribute key: {e:?}"))?;
        let value = AttributeValue::try_from(self.layout.as_str()).map_err(|e| anyhow!("attribute value: {e:?}"))?;
        let layout = AttributeVerifier::new().require(&key, &value).map_err(|e| anyhow!("attribute: {e:?}"))?;
        let open = || {
            self.node
                .service_builder(&name)
                .publish_subscribe::<T>()
                .history_size(0)
                .subscriber_max_buffer_size(MONITOR_BUFFER)
                .subscriber_max_borrowed_samples(2)
                .enable_safe_overflow(safe_overflow)
                .max_publishers(2)
                .max_subscribers(MAX_SUBSCRIBERS)
                .max_nodes(MAX_NODES)
                .open_or_create_with_attributes(&layout)
        };
        // Another build's layouts: refused at once, naming both fingerprints.
        if let Err(PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
            PublishSubscribeOpenError::IncompatibleAttributes,
        )) = open()
        {
            let theirs = self.layout_of(&name).unwrap_or_else(|| "none".into());
            let what = format!("the run's {} messages have", topic.name());
            bail!(crate::contract::msg::layout_mismatch(&what, &theirs, &self.layout));
        }
        retry(&format!("service {name}"), open)
    }

    fn event(&self, topic: Topic) -> Result<iceoryx2::service::port_factory::event::PortFactory<ipc::Service>> {
        let name = service_name(&self.run_id, topic)?;
        retry(&format!("event service {name}"), || {
            self.node
                .service_builder(&name)
                .event()
                .max_notifiers(MAX_SUBSCRIBERS)
                .max_listeners(MAX_SUBSCRIBERS)
                .max_nodes(MAX_NODES)
                .open_or_create()
        })
    }

    /// Whether `topic`'s reader may be asleep, shared by the reader and the writer.
    fn reader_state(&self, topic: Topic) -> Result<ReaderState> {
        let folder = run_folder(&self.run_id);
        check_private(&folder)?;
        ReaderState::open(&folder, topic)
    }

    /// A publisher that wakes the topic's reader after each sample as `wake` says.
    pub fn publisher<T: Debug + ZeroCopySend + Copy + 'static>(
        &self,
        topic: Topic,
        wake: Wake,
    ) -> Result<TopicPublisher<T>> {
        let counters = Arc::new(BackpressureCounters::default());
        let handler_counters = counters.clone();
        let publisher = self
            .pubsub::<T>(topic)?
            .publisher_builder()
            .max_loaned_samples(1)
            .set_backpressure_handler(move |info: &BackpressureInfo| {
                handler_counters.waiting.store(true, Ordering::Relaxed);
                if info.elapsed_time < LOCKSTEP_BACKPRESSURE_LIMIT {
                    BackpressureAction::Retry
                } else {
                    handler_counters.dropped.fetch_add(1, Ordering::Relaxed);
                    BackpressureAction::DiscardData
                }
            })
            .create()
            .map_err(|e| anyhow!("cannot create the {} publisher: {e:?}", topic.name()))?;
        let waker = match wake {
            Wake::Never => None,
            Wake::Futex => Some(Waker::Futex(self.reader_state(topic)?)),
            Wake::Event => {
                let notifier = self
                    .event(topic)?
                    .notifier_builder()
                    .create()
                    .map_err(|e| anyhow!("cannot create the {} notifier: {e:?}", topic.name()))?;
                Some(Waker::Event(Box::new(notifier), self.reader_state(topic)?))
            }
        };
        Ok(TopicPublisher { topic, publisher, waker, counters })
    }

    /// A reader for the next stage: a one-sample buffer (the newest wins in real-time mode),
    /// and if it `listens` (its process ever blocks), the futex its writer wakes it with.
    pub fn stage_subscriber<T: Debug + ZeroCopySend + Copy + 'static>(
        &self,
        topic: Topic,
        listens: bool,
    ) -> Result<TopicSubscriber<T>> {
        let mut subscriber = self.subscriber_with_buffer::<T>(topic, 1)?;
        if listens {
            subscriber.wakeup = Some(Wakeup::Futex(self.reader_state(topic)?));
        }
        Ok(subscriber)
    }

    /// The bridge's reader of a topic it sends: a one-sample buffer, woken through iceoryx2's
    /// event, which the bridge's WaitSet waits on for all its topics at once.
    pub fn bridge_subscriber<T: Debug + ZeroCopySend + Copy + 'static>(
        &self,
        topic: Topic,
    ) -> Result<TopicSubscriber<T>> {
        let mut subscriber = self.subscriber_with_buffer::<T>(topic, 1)?;
        let listener = self
            .event(topic)?
            .listener_builder()
            .create()
            .map_err(|e| anyhow!("cannot create the {} listener: {e:?}", topic.name()))?;
        subscriber.wakeup = Some(Wakeup::Event(Box::new(listener), self.reader_state(topic)?));
        Ok(subscriber)
    }

    /// A passive reader for the monitor: a deep buffer and no listener, so publishing never
    /// wakes the monitor and the monitor never slows the loop.
    pub fn passive_subscriber<T: Debug + ZeroCopySend + Copy + 'static>(
        &self,
        topic: Topic,
    ) -> Result<TopicSubscriber<T>> {
        self.subscriber_with_buffer::<T>(topic, MONITOR_BUFFER)
    }

    fn subscriber_with_buffer<T: Debug + ZeroCopySend + Copy + 'static>(
        &self,
        topic: Topic,
        buffer: usize,
    ) -> Result<TopicSubscriber<T>> {
        let service = self.pubsub::<T>(topic)?;
        let subscriber = service
            .subscriber_builder()
            .buffer_size(buffer)
            .create()
            .map_err(|e| anyhow!("cannot create the {} subscriber: {e:?}", topic.name()))?;
        Ok(TopicSubscriber { topic, service, subscriber, wakeup: None, slept: Cell::new(false) })
    }
}

/// What a publisher's back-pressure handler saw (lockstep mode only: in real-time mode readers
/// overflow and the handler never runs).
#[derive(Default)]
struct BackpressureCounters {
    /// Set when the current send found a reader full.
    waiting: AtomicBool,
    /// Sends that had to wait for a full reader.
    waited: AtomicU64,
    /// Samples dropped for a reader that stayed full past the limit.
    dropped: AtomicU64,
}

/// How a publisher wakes its reader, and the word that says whether the reader may be asleep.
enum Waker {
    Futex(ReaderState),
    /// Boxed: a notifier is large beside the futex's word.
    Event(Box<Notifier<ipc::Service>>, ReaderState),
}

/// How a blocking reader is woken (the writer's [`Waker`]).
enum Wakeup {
    Futex(ReaderState),
    /// Boxed: a listener is large beside the futex's word.
    Event(Box<Listener<ipc::Service>>, ReaderState),
}

impl Wakeup {
    fn state(&self) -> &ReaderState {
        match self {
            Wakeup::Futex(state) | Wakeup::Event(_, state) => state,
        }
    }
}

pub struct TopicPublisher<T: Debug + ZeroCopySend + 'static> {
    topic: Topic,
    publisher: Publisher<ipc::Service, T, ()>,
    waker: Option<Waker>,
    counters: Arc<BackpressureCounters>,
}

impl<T: Debug + ZeroCopySend + Copy + 'static> TopicPublisher<T> {
    /// Writes `value` into shared memory, delivers it, and wakes the readers.
    pub fn send(&self, value: &T) -> Result<()> {
        self.deliver(value)?;
        self.wake()
    }

    /// Writes `value` into a loan and delivers it to every reader, waking none.
    pub fn deliver(&self, value: &T) -> Result<()> {
        let sample = self.publisher.loan_uninit().with_context(|| format!("loan on {}", self.topic.name()))?;
        sample.write_payload(*value).send().with_context(|| format!("send on {}", self.topic.name()))?;
        if self.counters.waiting.swap(false, Ordering::Relaxed) {
            self.counters.waited.fetch_add(1, Ordering::Relaxed);
        }
        Ok(())
    }

    /// Wakes the topic's reader, if this publisher wakes it (it ever blocks) and it may be
    /// asleep now: a polling reader sees the sample itself, and the syscall is saved.
    pub fn wake(&self) -> Result<()> {
        match &self.waker {
            None => {}
            Some(Waker::Futex(reader)) => reader.wake(),
            Some(Waker::Event(notifier, reader)) if reader.needs_waking() => {
                notifier.notify().with_context(|| format!("notify on {}", self.topic.name()))?;
            }
            Some(Waker::Event(..)) => {}
        }
        Ok(())
    }

    /// Sends that waited for a full reader (lockstep), and samples dropped for one that stayed
    /// full past the limit.
    pub fn backpressure(&self) -> (u64, u64) {
        (self.counters.waited.load(Ordering::Relaxed), self.counters.dropped.load(Ordering::Relaxed))
    }
}

pub struct TopicSubscriber<T: Debug + ZeroCopySend + 'static> {
    topic: Topic,
    service: iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>,
    subscriber: Subscriber<ipc::Service, T, ()>,
    /// How it is woken, with the mark that tells the writer when it may sleep.
    wakeup: Option<Wakeup>,
    /// It has slept on an event since it last consumed its wake-ups (only then can any be
    /// pending; a futex leaves none).
    slept: Cell<bool>,
}

impl<T: Debug + ZeroCopySend + Copy + 'static> TopicSubscriber<T> {
    /// Waits until the topic's writer exists and connects to it. iceoryx2 connects readers
    /// lazily; a reader that has not connected loses what a writer sent if the writer is gone
    /// before it connects, so every process connects before it reports ready.
    /// Gives up after `timeout`.
    pub fn connect(&self, stop: &StopFlag, timeout: Duration) -> Result<()> {
        let start = Instant::now();
        while self.service.dynamic_config().number_of_publishers() == 0 {
            if stop.requested() {
                return Ok(());
            }
            if start.elapsed() > timeout {
                return Err(anyhow!("no writer on {} after {} s", self.topic.name(), timeout.as_secs_f64()));
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        self.subscriber.update_connections().map_err(|e| anyhow!("connect to {}: {e}", self.topic.name()))
    }

    /// The next queued sample, copied out of shared memory (the chunk goes back at once).
    pub fn receive(&self) -> Result<Option<T>> {
        Ok(self.subscriber.receive().context("receive")?.map(|sample| *sample))
    }

    /// The next queued sample, in place in shared memory: its chunk goes back to the writer
    /// when the sample is dropped, so a stage reads only what it uses and returns the chunk
    /// after it has published, off the hop's path. Once the queue is empty, a reader woken by
    /// an event consumes the pending wake-ups and looks once more, so that a sample landing
    /// later leaves a wake-up behind and a blocking wait cannot miss it; consuming them after
    /// the data keeps that syscall off the latency. `cleared` starts false for each drain.
    pub fn next(&self, cleared: &mut bool) -> Result<Option<Sample<ipc::Service, T, ()>>> {
        if let Some(sample) = self.subscriber.receive().context("receive")? {
            return Ok(Some(sample));
        }
        if *cleared || !self.slept.get() {
            return Ok(None);
        }
        self.clear_wakeups()?;
        *cleared = true;
        self.subscriber.receive().context("receive")
    }

    /// Whether a sample is queued (without taking it).
    pub fn has_samples(&self) -> Result<bool> {
        self.subscriber.has_samples().map_err(|e| anyhow!("{}: {e:?}", self.topic.name()))
    }

    /// Attaches this reader's event listener, if it has one (a bridge's reader), to a WaitSet.
    pub fn attach_to<'w, 'a>(
        &'a self,
        ws: &'w WaitSet<ipc::Service>,
    ) -> Result<Option<WaitSetGuard<'w, 'a, ipc::Service>>> {
        let Some(Wakeup::Event(listener, _)) = &self.wakeup else { return Ok(None) };
        ws.attach_notification(listener.as_ref())
            .map(Some)
            .map_err(|e| anyhow!("cannot attach the {} listener: {e:?}", self.topic.name()))
    }

    /// Sleeps until this reader's next wake-up or `deadline_ns`, whichever comes first (a
    /// reader that is never woken sleeps until the deadline).
    pub fn doze_until(&self, deadline_ns: u64) -> Result<()> {
        match &self.wakeup {
            Some(Wakeup::Futex(state)) => self.asleep(|| {
                state.sleep_until(deadline_ns);
                Ok(())
            }),
            Some(Wakeup::Event(listener, _)) => self.asleep(|| doze(listener, deadline_ns)),
            None => {
                sleep_until(deadline_ns);
                Ok(())
            }
        }
    }

    /// Runs `sleep` (a doze, or a block in the WaitSet) marked asleep, so that the writer wakes
    /// this reader; skips it if a sample came in the meantime.
    pub fn asleep(&self, sleep: impl FnOnce() -> Result<()>) -> Result<()> {
        let Some(wakeup) = &self.wakeup else { return sleep() };
        let state = wakeup.state();
        state.asleep();
        self.slept.set(matches!(wakeup, Wakeup::Event(..)));
        if !self.has_samples()? {
            sleep()?;
        }
        state.polling();
        Ok(())
    }

    /// Consumes pending wake-ups, so that the next wait blocks until new data.
    pub fn clear_wakeups(&self) -> Result<()> {
        if let Some(Wakeup::Event(listener, _)) = &self.wakeup {
            listener.try_wait(|_| {}).map_err(|e| anyhow!("listener: {e:?}"))?;
        }
        self.slept.set(false);
        Ok(())
    }
}

/// Sleeps until the listener's next wake-up or `deadline_ns` (CLOCK_MONOTONIC), whichever comes
/// first, then consumes the wake-ups: a timed sleep that the input's arrival ends early.
pub fn doze(listener: &Listener<ipc::Service>, deadline_ns: u64) -> Result<()> {
    let left = deadline_ns.saturating_sub(now_ns());
    if left > 0 {
        let timeout = timespec(left);
        // SAFETY: the descriptor belongs to the listener, alive for the call.
        let fd = unsafe { listener.file_descriptor().native_handle() };
        let mut pfd = libc::pollfd { fd, events: libc::POLLIN, revents: 0 };
        // SAFETY: one valid pollfd and timeout; a signal ends the sleep early, which is harmless.
        unsafe { libc::ppoll(&mut pfd, 1, &timeout, std::ptr::null()) };
    }
    listener.try_wait(|_| {}).map_err(|e| anyhow!("listener: {e:?}"))?;
    Ok(())
}

use crate::runtime::storage::run_storage::{check_private, node, run_config, run_folder};
