//! The shared-memory side of a bridge: which topics it carries on its host, reading them out of
//! iceoryx2 as frames (the `#[repr(C)]` bytes) and publishing received frames back in, with the
//! counts of each, and the `cut` faults on every frame both ways. The link itself (zenoh) is the
//! bridge binary's, so that nothing else of LoopLab is built with it.

use std::cell::Cell;
use std::collections::BTreeMap;

use anyhow::{Result, anyhow, bail};
use serde::{Deserialize, Serialize};

use crate::config::hosts::{Crossing, Hosts};
use crate::config::launch::{LaunchConfig, Mode};
use crate::contract::msg::{Command, Estimate, Measurements, Message, PlantState, layout_fingerprint, layout_mismatch};
use crate::contract::protocol::CrossingCounts;
use crate::contract::role::{Role, Topic};
use iceoryx2::prelude::ipc;
use iceoryx2::waitset::{WaitSet, WaitSetGuard};

use crate::runtime::stage::faults::{LinkCut, OnLink};
use crate::runtime::transport::ipc::{Ipc, TopicPublisher, TopicSubscriber, Wake};
use crate::runtime::transport::wait::reader_blocks;

/// The key of a topic on the link: the run's id keeps two runs on one network apart.
pub fn link_key(run_id: &str, topic: Topic) -> String {
    format!("looplab/{run_id}/{}", topic.name())
}

/// The key under which the remote bridge answers with its [`WireLayout`].
pub fn layout_key(run_id: &str) -> String {
    format!("looplab/{run_id}/layout")
}

/// The key of each bridge's liveliness token: each side watches the other's.
pub fn alive_key(run_id: &str, role: Role) -> String {
    format!("looplab/{run_id}/alive/{role}")
}

/// What a frame of each crossing topic is: both hosts must run the same build, or the bytes
/// would be read as something else. Checked when the bridges meet.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct WireLayout {
    /// The messages' layout fingerprint (`contract::msg::layout_fingerprint`), the one every
    /// port on either host checks.
    pub fingerprint: String,
    /// The commit and version the bridge was built from.
    pub build: String,
    pub topics: Vec<TopicLayout>,
}

#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct TopicLayout {
    pub topic: String,
    pub type_name: String,
    pub size: usize,
    pub align: usize,
}

impl WireLayout {
    /// This build's layout of every topic that can cross.
    pub fn ours() -> Self {
        fn of<T>(topic: Topic) -> TopicLayout {
            TopicLayout {
                topic: topic.name().into(),
                type_name: std::any::type_name::<T>().into(),
                size: std::mem::size_of::<T>(),
                align: std::mem::align_of::<T>(),
            }
        }
        WireLayout {
            fingerprint: layout_fingerprint().to_owned(),
            build: format!("{} {}", env!("CARGO_PKG_VERSION"), env!("LOOPLAB_GIT_COMMIT")),
            topics: vec![
                of::<PlantState>(Topic::State),
                of::<Measurements>(Topic::Measurements),
                of::<Estimate>(Topic::Estimate),
                of::<Command>(Topic::Command),
            ],
        }
    }

    /// Why `theirs` cannot talk to us, if it cannot.
    pub fn mismatch(&self, theirs: &WireLayout) -> Option<String> {
        if self.fingerprint != theirs.fingerprint {
            return Some(layout_mismatch("the other host's messages have", &theirs.fingerprint, &self.fingerprint));
        }
        if self.build != theirs.build {
            return Some(format!("the other host runs build {}, this one {}", theirs.build, self.build));
        }
        let differs = self.topics.iter().zip(&theirs.topics).find(|(a, b)| a != b);
        if let Some((a, b)) = differs {
            return Some(format!("{} differs: {:?} here, {:?} there", a.topic, a, b));
        }
        (self.topics.len() != theirs.topics.len()).then(|| "the hosts carry different topics".into())
    }
}

/// The topics a bridge carries on its host: those it reads here and sends over the link, and
/// those it receives and publishes here.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Plan {
    pub send: Vec<Topic>,
    pub receive: Vec<Topic>,
}

impl Plan {
    pub fn of(hosts: &Hosts, bridge: Role) -> Self {
        let (send, receive) =
            if bridge == Role::BridgeRemote { (Crossing::In, Crossing::Out) } else { (Crossing::Out, Crossing::In) };
        let with = |way: Crossing| Topic::ALL.into_iter().filter(|&t| hosts.crossing(t) == Some(way)).collect();
        Plan { send: with(send), receive: with(receive) }
    }
}

/// A crossing topic read out of shared memory on its writer's host.
pub trait Outbound {
    fn topic(&self) -> Topic;
    /// Hands every waiting sample's bytes to `send` (which returns whether the link took it).
    fn drain(&self, send: &mut dyn FnMut(Topic, &[u8]) -> bool) -> Result<usize>;
    /// Attaches its wake-up, if it listens, to the bridge's WaitSet.
    fn attach_to<'w, 'a>(&'a self, ws: &'w WaitSet<ipc::Service>)
    -> Result<Option<WaitSetGuard<'w, 'a, ipc::Service>>>;
    /// Runs `sleep` marked asleep, so that its writer wakes it (`TopicSubscriber::asleep`).
    fn asleep(&self, sleep: &mut dyn FnMut() -> Result<()>) -> Result<()>;
    fn counts(&self) -> CrossingCounts;
}

/// Blocks in `sleep` with every outbound topic marked asleep; returns at once if one has a sample.
pub fn sleep_until_input(outs: &[Box<dyn Outbound>], sleep: &mut dyn FnMut() -> Result<()>) -> Result<()> {
    match outs.split_first() {
        None => sleep(),
        Some((first, rest)) => first.asleep(&mut || sleep_until_input(rest, sleep)),
    }
}

/// A crossing topic published into shared memory on its reader's host.
pub trait Inbound {
    fn topic(&self) -> Topic;
    fn deliver(&mut self, frame: &[u8]) -> Result<()>;
    fn counts(&self) -> CrossingCounts;
}

struct Out<T: Message> {
    topic: Topic,
    subscriber: TopicSubscriber<T>,
    cut: LinkCut,
    /// A cell: the WaitSet holds the port borrowed while it drains.
    counts: Cell<CrossingCounts>,
}

impl<T: Message> Outbound for Out<T> {
    fn topic(&self) -> Topic {
        self.topic
    }

    fn drain(&self, send: &mut dyn FnMut(Topic, &[u8]) -> bool) -> Result<usize> {
        let mut cleared = false;
        let mut n = 0;
        let mut counts = self.counts.get();
        while let Some(sample) = self.subscriber.next(&mut cleared)? {
            let mut value: T = *sample;
            match self.cut.on_link(value.header().k) {
                OnLink::Pass => {}
                // Cut: it never reaches the link; the other bridge sees the gap.
                OnLink::Drop => continue,
                OnLink::MarkLost => value.header_mut().lost = 1,
            }
            if send(self.topic, frame_of(&value)) {
                counts.sent += 1;
            } else {
                counts.send_errors += 1;
            }
            n += 1;
        }
        self.counts.set(counts);
        Ok(n)
    }

    fn attach_to<'w, 'a>(
        &'a self,
        ws: &'w WaitSet<ipc::Service>,
    ) -> Result<Option<WaitSetGuard<'w, 'a, ipc::Service>>> {
        self.subscriber.attach_to(ws)
    }

    fn asleep(&self, sleep: &mut dyn FnMut() -> Result<()>) -> Result<()> {
        self.subscriber.asleep(sleep)
    }

    fn counts(&self) -> CrossingCounts {
        self.counts.get()
    }
}

struct In<T: Message> {
    topic: Topic,
    publisher: TopicPublisher<T>,
    cut: LinkCut,
    last_k: Option<u64>,
    counts: CrossingCounts,
}

impl<T: Message> Inbound for In<T> {
    fn topic(&self) -> Topic {
        self.topic
    }

    fn deliver(&mut self, frame: &[u8]) -> Result<()> {
        let Some(mut value) = from_frame::<T>(frame) else {
            self.counts.malformed += 1;
            return Ok(());
        };
        let k = value.header().k;
        match self.cut.on_link(k) {
            OnLink::Pass => {}
            // Cut: it came, but not across the link; it counts as lost (sent, not received).
            OnLink::Drop => return Ok(()),
            OnLink::MarkLost => value.header_mut().lost = 1,
        }
        if let Some(last) = self.last_k
            && k > last + 1
        {
            self.counts.gaps += 1;
            self.counts.missing += k - last - 1;
        }
        self.last_k = Some(k);
        // Into shared memory first, then the wake-up: a stage never wakes before its sample.
        self.publisher.send(&value)?;
        self.counts.received += 1;
        Ok(())
    }

    fn counts(&self) -> CrossingCounts {
        self.counts
    }
}

/// The bytes of a message. The messages are `#[repr(C)]` plain data with explicit reserved
/// fields, no padding and no pointers, so their bytes are all there is to them.
fn frame_of<T: Message>(value: &T) -> &[u8] {
    // SAFETY: `value` is a valid T for the returned slice's lifetime; T has no padding (above).
    unsafe { std::slice::from_raw_parts((value as *const T).cast::<u8>(), std::mem::size_of::<T>()) }
}

/// A message from its bytes, if they are the right size. Every bit pattern is a valid message:
/// they hold only integers and floats.
fn from_frame<T: Message>(frame: &[u8]) -> Option<T> {
    // SAFETY: the length is checked; read_unaligned copes with any alignment of the frame.
    (frame.len() == std::mem::size_of::<T>()).then(|| unsafe { std::ptr::read_unaligned(frame.as_ptr().cast::<T>()) })
}

/// The reader of a topic to send: it blocks, so the topic's writer here wakes it
/// (`Hosts::read_by_bridge`); a topic that only the monitor needs is read passively (its stage
/// reader is on this host too and decides the wake-ups) and drained at each wake-up.
pub fn outbound(ipc: &Ipc, config: &LaunchConfig, bridge: Role, topic: Topic) -> Result<Box<dyn Outbound>> {
    fn make<T: Message>(ipc: &Ipc, topic: Topic, listens: bool, cut: LinkCut) -> Result<Box<dyn Outbound>> {
        let subscriber = if listens { ipc.bridge_subscriber::<T>(topic)? } else { ipc.passive_subscriber::<T>(topic)? };
        Ok(Box::new(Out { topic, subscriber, cut, counts: Cell::default() }))
    }
    let reader_here = Role::reading(topic).is_some_and(|r| config.hosts.is_remote(r) == (bridge == Role::BridgeRemote));
    let listens = !reader_here;
    let cut = LinkCut::for_bridge(config, bridge);
    match topic {
        Topic::State => make::<PlantState>(ipc, topic, listens, cut),
        Topic::Measurements => make::<Measurements>(ipc, topic, listens, cut),
        Topic::Estimate => make::<Estimate>(ipc, topic, listens, cut),
        Topic::Command => make::<Command>(ipc, topic, listens, cut),
        Topic::Loop => bail!("the loop records never cross"),
    }
}

/// The writer of a received topic: it wakes the topic's reader here as that reader's own writer
/// would (whether it blocks is its own waiting method's business).
pub fn inbound(ipc: &Ipc, config: &LaunchConfig, bridge: Role, topic: Topic) -> Result<Box<dyn Inbound>> {
    fn make<T: Message>(ipc: &Ipc, topic: Topic, wakes: Wake, cut: LinkCut) -> Result<Box<dyn Inbound>> {
        let publisher = ipc.publisher::<T>(topic, wakes)?;
        Ok(Box::new(In { topic, publisher, cut, last_k: None, counts: CrossingCounts::default() }))
    }
    let wakes =
        if reader_blocks(&config.wait, topic, config.mode == Mode::Realtime) { Wake::Futex } else { Wake::Never };
    let cut = LinkCut::for_bridge(config, bridge);
    match topic {
        Topic::State => make::<PlantState>(ipc, topic, wakes, cut),
        Topic::Measurements => make::<Measurements>(ipc, topic, wakes, cut),
        Topic::Estimate => make::<Estimate>(ipc, topic, wakes, cut),
        Topic::Command => make::<Command>(ipc, topic, wakes, cut),
        Topic::Loop => Err(anyhow!("the loop records never cross")),
    }
}

/// Counts by topic name, for the bridge's report.
pub fn counts_by_topic<'a>(
    outs: impl Iterator<Item = (Topic, CrossingCounts)>,
    ins: impl Iterator<Item = (Topic, CrossingCounts)> + 'a,
) -> BTreeMap<String, CrossingCounts> {
    let mut by_topic: BTreeMap<String, CrossingCounts> = BTreeMap::new();
    for (topic, counts) in outs.chain(ins) {
        *by_topic.entry(topic.name().into()).or_default() += counts;
    }
    by_topic
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_is_the_message_bytes_and_reads_back_exactly() {
        let mut command = Command::default();
        command.header.k = 41;
        command.header.trace.controller_publish = 123_456_789;
        command.u[0] = -0.25;
        let frame = frame_of(&command).to_vec();
        assert_eq!(frame.len(), std::mem::size_of::<Command>());
        let back: Command = from_frame(&frame).unwrap();
        assert_eq!((back.header.k, back.header.trace.controller_publish, back.u[0]), (41, 123_456_789, -0.25));
        assert!(from_frame::<Command>(&frame[1..]).is_none(), "a frame of another size is refused");
    }

    #[test]
    fn layouts_of_one_build_match_and_another_build_is_named() {
        let ours = WireLayout::ours();
        assert_eq!(ours.mismatch(&ours.clone()), None);
        let mut theirs = ours.clone();
        theirs.topics[3].size += 8;
        assert!(ours.mismatch(&theirs).unwrap().starts_with("command differs"));
        theirs.build = "0.0.0 other".into();
        assert!(ours.mismatch(&theirs).unwrap().contains("the other host runs build 0.0.0 other"));
        theirs.fingerprint = "0123456789abcdef".into();
        let why = ours.mismatch(&theirs).unwrap();
        let expected = format!(
            "the other host's messages have layout fingerprint 0123456789abcdef, this process was built with {}",
            ours.fingerprint
        );
        assert!(why.starts_with(&expected), "{why}");
    }
}
