//! The loop's transport: iceoryx2 publish-subscribe services, each with an event service of
//! the same name that wakes the next stage.
//!
//! Every run has its own id. It is in every service name (`looplab/<run>/<topic>`) and in the
//! iceoryx2 file prefix (`looplab_<run>_`), so two runs on one machine never see each other and
//! the launcher can check that nothing of a run is left in shared memory when it ends.
//!
//! Quality of service, identical for every process of a run:
//! - real-time mode: safe overflow. A slow reader loses its oldest samples; no publisher ever
//!   waits. The loop's stages read with a one-sample buffer (the newest wins), the monitor with
//!   [`MONITOR_BUFFER`] samples and counts what it lost.
//! - lockstep mode: no overflow. A full reader makes the publisher wait (so the monitor records
//!   every loop of a deterministic run), for at most [`LOCKSTEP_BACKPRESSURE_LIMIT`], after which
//!   the sample is dropped for that reader and counted.

use std::fmt::Debug;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::port::{BackpressureAction, BackpressureInfo};
use iceoryx2::prelude::*;

use crate::launch::Mode;
use crate::signals::StopFlag;

/// Samples the monitor can fall behind by before it loses any (real-time mode); at 1 kHz that
/// is a second of slack.
pub const MONITOR_BUFFER: usize = 1024;
/// Longest a lockstep publisher waits for a full reader before dropping the sample for it.
pub const LOCKSTEP_BACKPRESSURE_LIMIT: Duration = Duration::from_secs(5);
/// Readers per topic: the next stage, the monitor, and room for a restarted one.
const MAX_SUBSCRIBERS: usize = 4;
/// Openers per service; a little room for restarts.
const MAX_NODES: usize = 10;
/// How long to keep retrying a service open while other processes are creating it.
const OPEN_RETRY: Duration = Duration::from_secs(3);
/// How long a reader waits at start-up for its writer to exist.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(20);

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Topic {
    /// plant → sensors, monitor
    State,
    /// sensors → estimator, monitor
    Measurements,
    /// estimator → controller, monitor
    Estimate,
    /// controller → plant, monitor
    Command,
    /// plant → monitor: finished loop records
    Loop,
}

impl Topic {
    pub fn name(self) -> &'static str {
        match self {
            Topic::State => "state",
            Topic::Measurements => "measurements",
            Topic::Estimate => "estimate",
            Topic::Command => "command",
            Topic::Loop => "loop",
        }
    }
}

/// The iceoryx2 file prefix of a run: every file the run creates starts with it.
pub fn file_prefix(run_id: &str) -> String {
    format!("looplab_{run_id}_")
}

/// The iceoryx2 configuration every process of a run uses.
pub fn run_config(run_id: &str) -> Result<Config> {
    let mut config = Config::default();
    config.global.prefix = FileName::new(file_prefix(run_id).as_bytes())
        .map_err(|e| anyhow!("run id {run_id:?} does not make a valid file prefix: {e:?}"))?;
    Ok(config)
}

pub fn service_name(run_id: &str, topic: Topic) -> Result<ServiceName> {
    let name = format!("looplab/{run_id}/{}", topic.name());
    ServiceName::new(&name).map_err(|e| anyhow!("invalid service name {name}: {e:?}"))
}

/// Retries an open-or-create while other processes of the run create the same service.
pub(crate) fn retry<T, E: Debug>(what: &str, mut attempt: impl FnMut() -> Result<T, E>) -> Result<T> {
    let start = Instant::now();
    loop {
        match attempt() {
            Ok(v) => return Ok(v),
            Err(e) if start.elapsed() > OPEN_RETRY => return Err(anyhow!("cannot open {what}: {e:?}")),
            Err(_) => std::thread::sleep(Duration::from_millis(5)),
        }
    }
}

/// iceoryx2 logs only errors, unless IOX2_LOG_LEVEL says otherwise.
fn quiet_logs() {
    set_log_level_from_env_or(LogLevel::Error);
}

/// One process's connection to the run's services.
pub struct Ipc {
    node: Node<ipc::Service>,
    run_id: String,
    mode: Mode,
}

impl Ipc {
    pub fn new(process: &str, run_id: &str, mode: Mode) -> Result<Self> {
        quiet_logs();
        let config = run_config(run_id)?;
        let node = NodeBuilder::new()
            .name(&NodeName::new(process).map_err(|e| anyhow!("invalid node name {process}: {e:?}"))?)
            .config(&config)
            // Each process handles SIGTERM/SIGINT itself (`crate::signals`), so that iceoryx2
            // never swallows them and a stop request is seen at any point of the run.
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .map_err(|e| anyhow!("cannot create the iceoryx2 node for {process}: {e:?}"))?;
        Ok(Self { node, run_id: run_id.to_owned(), mode })
    }

    fn pubsub<T: Debug + ZeroCopySend + 'static>(
        &self,
        topic: Topic,
    ) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>> {
        let name = service_name(&self.run_id, topic)?;
        let safe_overflow = self.mode == Mode::Realtime;
        retry(&format!("service {name}"), || {
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
                .open_or_create()
        })
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

    /// A publisher that, if `wake` is set, also wakes the topic's readers after each sample.
    pub fn publisher<T: Debug + ZeroCopySend + Copy + 'static>(
        &self,
        topic: Topic,
        wake: bool,
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
        let notifier = if wake {
            Some(
                self.event(topic)?
                    .notifier_builder()
                    .create()
                    .map_err(|e| anyhow!("cannot create the {} notifier: {e:?}", topic.name()))?,
            )
        } else {
            None
        };
        Ok(TopicPublisher { topic, publisher, notifier, counters })
    }

    /// A reader for the next stage: a one-sample buffer (the newest wins in real-time mode)
    /// and a listener that wakes it.
    pub fn stage_subscriber<T: Debug + ZeroCopySend + Copy + 'static>(
        &self,
        topic: Topic,
    ) -> Result<TopicSubscriber<T>> {
        let mut subscriber = self.subscriber_with_buffer::<T>(topic, 1)?;
        subscriber.listener = Some(
            self.event(topic)?
                .listener_builder()
                .create()
                .map_err(|e| anyhow!("cannot create the {} listener: {e:?}", topic.name()))?,
        );
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
        Ok(TopicSubscriber { topic, service, subscriber, listener: None })
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

pub struct TopicPublisher<T: Debug + ZeroCopySend + 'static> {
    topic: Topic,
    publisher: Publisher<ipc::Service, T, ()>,
    notifier: Option<Notifier<ipc::Service>>,
    counters: Arc<BackpressureCounters>,
}

impl<T: Debug + ZeroCopySend + Copy + 'static> TopicPublisher<T> {
    /// Writes `value` into shared memory, delivers it, and wakes the readers.
    pub fn send(&self, value: &T) -> Result<()> {
        let sample = self.publisher.loan_uninit().with_context(|| format!("loan on {}", self.topic.name()))?;
        sample.write_payload(*value).send().with_context(|| format!("send on {}", self.topic.name()))?;
        if self.counters.waiting.swap(false, Ordering::Relaxed) {
            self.counters.waited.fetch_add(1, Ordering::Relaxed);
        }
        if let Some(notifier) = &self.notifier {
            notifier.notify().with_context(|| format!("notify on {}", self.topic.name()))?;
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
    listener: Option<Listener<ipc::Service>>,
}

impl<T: Debug + ZeroCopySend + Copy + 'static> TopicSubscriber<T> {
    /// Waits until the topic's writer exists and connects to it. iceoryx2 connects readers
    /// lazily; a reader that has not connected loses what a writer sent if the writer is gone
    /// before it connects, so every process connects before it reports ready.
    pub fn connect(&self, stop: &StopFlag) -> Result<()> {
        let start = Instant::now();
        while self.service.dynamic_config().number_of_publishers() == 0 {
            if stop.requested() {
                return Ok(());
            }
            if start.elapsed() > CONNECT_TIMEOUT {
                return Err(anyhow!("no writer on {} after {} s", self.topic.name(), CONNECT_TIMEOUT.as_secs()));
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        self.subscriber.update_connections().map_err(|e| anyhow!("connect to {}: {e}", self.topic.name()))
    }

    /// The next queued sample, copied out of shared memory (the chunk goes back at once).
    pub fn receive(&self) -> Result<Option<T>> {
        Ok(self.subscriber.receive().context("receive")?.map(|sample| *sample))
    }

    /// The next queued sample. Once the queue is empty it consumes the pending wake-ups and
    /// looks once more, so that a sample landing later leaves a wake-up behind and a blocking
    /// wait cannot miss it; consuming them after the data keeps that syscall off the latency.
    /// `cleared` starts false for each drain.
    pub fn next(&self, cleared: &mut bool) -> Result<Option<T>> {
        if let Some(sample) = self.receive()? {
            return Ok(Some(sample));
        }
        if *cleared {
            return Ok(None);
        }
        self.clear_wakeups()?;
        *cleared = true;
        self.receive()
    }

    /// Whether a sample is queued (without taking it).
    pub fn has_samples(&self) -> Result<bool> {
        self.subscriber.has_samples().map_err(|e| anyhow!("{}: {e:?}", self.topic.name()))
    }

    pub fn listener(&self) -> Option<&Listener<ipc::Service>> {
        self.listener.as_ref()
    }

    /// Consumes pending wake-ups, so that the next wait blocks until new data.
    pub fn clear_wakeups(&self) -> Result<()> {
        if let Some(listener) = &self.listener {
            listener.try_wait(|_| {}).map_err(|e| anyhow!("listener: {e:?}"))?;
        }
        Ok(())
    }
}

/// iceoryx2's shared-memory folder on Linux; its other files are under the config's root path.
pub const SHM_DIR: &str = "/dev/shm";

/// After a run: removes the resources of the run's dead nodes (processes that were killed) and
/// the run's own node registry, then lists every file of the run still there.
pub struct Cleanup {
    pub removed_dead_nodes: u64,
    pub leftover: Vec<String>,
}

/// Removes the resources of the run's dead nodes (during a run, after a process died); returns
/// how many it removed.
pub fn remove_dead_nodes(run_id: &str) -> Result<u64> {
    quiet_logs();
    let config = run_config(run_id)?;
    let mut removed = 0;
    Node::<ipc::Service>::list(&config, |state| {
        if let NodeState::Dead(view) = state {
            removed += u64::from(view.try_remove_stale_resources().is_ok());
        }
        CallbackProgression::Continue
    })
    .map_err(|e| anyhow!("cannot list the run's iceoryx2 nodes: {e:?}"))?;
    Ok(removed)
}

pub fn clean_up_run(run_id: &str) -> Result<Cleanup> {
    quiet_logs();
    let config = run_config(run_id)?;
    let mut removed_dead_nodes = 0;
    let mut alive_nodes = 0;
    Node::<ipc::Service>::list(&config, |state| {
        match state {
            NodeState::Dead(view) => removed_dead_nodes += u64::from(view.try_remove_stale_resources().is_ok()),
            NodeState::Alive(_) => alive_nodes += 1,
            _ => {}
        }
        CallbackProgression::Continue
    })
    .map_err(|e| anyhow!("cannot list the run's iceoryx2 nodes: {e:?}"))?;

    let mut leftover = paths_of_run(run_id, &config);
    // iceoryx2 keeps one registry file per prefix for good. The prefix is this run's alone, so
    // once no node of the run is alive, it goes too, with the processes' snapshots.
    if alive_nodes == 0 {
        leftover.retain(|path| {
            let name = path.to_string_lossy();
            let ours = name.ends_with(".global_mgmt") || name.ends_with(".snapshot");
            !(path.starts_with(SHM_DIR) && ours && std::fs::remove_file(path).is_ok())
        });
    }
    Ok(Cleanup { removed_dead_nodes, leftover: leftover.iter().map(|p| p.display().to_string()).collect() })
}

/// Every file under `dir` (recursively) whose name starts with `prefix`.
fn collect_with_prefix(dir: &std::path::Path, prefix: &str, out: &mut Vec<std::path::PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let path = entry.path();
        if entry.file_name().to_string_lossy().starts_with(prefix) {
            out.push(path);
        } else if entry.file_type().is_ok_and(|t| t.is_dir()) {
            collect_with_prefix(&path, prefix, out);
        }
    }
}

fn paths_of_run(run_id: &str, config: &Config) -> Vec<std::path::PathBuf> {
    let root = String::from_utf8_lossy(config.global.root_path().as_bytes()).into_owned();
    let mut found = Vec::new();
    for dir in [SHM_DIR, root.as_str()] {
        collect_with_prefix(std::path::Path::new(dir), &file_prefix(run_id), &mut found);
    }
    found
}

/// Every file of a run still present; removes nothing (for checks from outside a run).
pub fn files_of_run(run_id: &str) -> Result<Vec<String>> {
    Ok(paths_of_run(run_id, &run_config(run_id)?).iter().map(|p| p.display().to_string()).collect())
}
