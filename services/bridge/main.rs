//! `looplab-bridge`: when a launch file places a stage on another host, one runs on each host.
//! It carries the topics that cross, each as one zenoh key, as the messages' own bytes: read
//! out of iceoryx2 on the writer's host when the writer's wake-up comes (no polling), published
//! into iceoryx2 on the reader's host, then the reader woken. zenoh runs peer to peer over TCP
//! with explicit endpoints (the remote bridge listens, this host's connects), no scouting,
//! express real-time publishing, and a short lease, so that a cut link is noticed in about a
//! second. The two bridges check at connect time that both hosts run the same build.

use std::collections::BTreeMap;
use std::process::ExitCode;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, anyhow, bail};
use clap::Parser;
use crossbeam_channel::RecvTimeoutError;
use serde::{Deserialize, Serialize};
use zenoh::Wait as _;
use zenoh::qos::{CongestionControl, Priority};
use zenoh::sample::SampleKind;

use looplab_shared::config::launch::{LaunchConfig, Mode};
use looplab_shared::contract::clock::now_ns;
use looplab_shared::contract::protocol::{BridgeReport, ChildEvent, CrossingCounts, LinkCounts, Outage, ProcessArgs};
use looplab_shared::contract::role::{Role, Topic};
use looplab_shared::runtime::bridge::{self, Inbound, Outbound, Plan, WireLayout};
use looplab_shared::runtime::signals::StopFlag;
use looplab_shared::runtime::stage::child::{WAIT_SLICE, emit, wait, waitset};
use looplab_shared::runtime::storage::run_storage;
use looplab_shared::runtime::transport::ipc::Ipc;

/// How long this host's bridge waits for the other's answer before giving up.
const MEET_TIMEOUT: Duration = Duration::from_secs(15);
/// zenoh's link lease, ms: a peer silent this long is gone. zenoh's default, 10 s, would hide a
/// cut link for that long.
const LEASE_MS: u64 = 1000;

#[derive(Parser)]
#[command(about = "A LoopLab bridge; started by `looplab run` when a stage runs on another host, not by hand.")]
struct Args {
    #[command(flatten)]
    process: ProcessArgs,
    /// Which bridge: this machine's (`bridge`) or the other host's (`bridge-remote`).
    #[arg(long)]
    role: Role,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let role = args.role;
    match run(&args).and_then(|report| emit(&ChildEvent::BridgeReport(report))) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{role}: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn zenoh_error(what: &str) -> impl FnOnce(zenoh::Error) -> anyhow::Error + '_ {
    move |e| anyhow!("{what}: {e}")
}

/// What the remote bridge answers this host's: its layout, and whether every topic it sends has
/// our subscriber by now (then nothing it sends from the start is lost).
#[derive(Serialize, Deserialize)]
struct Hello {
    layout: WireLayout,
    matched: bool,
}

/// The peer bridge's comings and goings, from its liveliness token.
#[derive(Default)]
struct Link {
    counts: LinkCounts,
    up: bool,
}

impl Link {
    /// The other bridge's token appeared (`up`) or went; this host's bridge tells the launcher
    /// of each loss and return after the first meeting.
    fn seen(&mut self, up: bool, ns: u64, tell: bool) {
        if up && !self.up {
            self.counts.connects += 1;
            if let Some(outage) = self.counts.outages.last_mut().filter(|o| o.back_ns.is_none()) {
                outage.back_ns = Some(ns);
                if tell {
                    let _ = emit(&ChildEvent::LinkBack { at_ns: ns });
                }
            }
        } else if !up && self.up {
            self.counts.losses += 1;
            self.counts.outages.push(Outage { lost_ns: ns, back_ns: None });
            if tell {
                let _ = emit(&ChildEvent::LinkLost { at_ns: ns });
            }
        }
        self.up = up;
    }
}

fn run(args: &Args) -> Result<BridgeReport> {
    let role = args.role;
    if !Role::BRIDGES.contains(&role) {
        bail!("--role must be bridge or bridge-remote, not {role}");
    }
    let stop = StopFlag::install()?;
    let (config, _) = looplab_shared::scenarios::load_resolved(&args.process.launch)?;
    let (_, host) = config.hosts.remote().ok_or_else(|| anyhow!("no stage is placed on another host"))?;
    let run_id = args.process.run_id.clone();
    let remote = role == Role::BridgeRemote;
    // The remote bridge is the run's first process on its host: it makes the run's folder there.
    let storage = if remote { Some(run_storage::take_run_storage(&run_id)?) } else { None };
    let plan = Plan::of(&config.hosts, role);
    let session = open_session(&host.endpoint(), remote)?;

    let link = Arc::new(Mutex::new(Link::default()));
    let peer = if remote { Role::Bridge } else { Role::BridgeRemote };
    let _token = session
        .liveliness()
        .declare_token(bridge::alive_key(&run_id, role))
        .wait()
        .map_err(zenoh_error("declare the liveliness token"))?;
    let watched = link.clone();
    let _watch = session
        .liveliness()
        .declare_subscriber(bridge::alive_key(&run_id, peer))
        .history(true)
        .callback(move |sample| {
            watched.lock().expect("not poisoned").seen(sample.kind() == SampleKind::Put, now_ns(), !remote)
        })
        .wait()
        .map_err(zenoh_error("watch the other bridge"))?;

    // In: frames from the link go to a thread of their own, which publishes them here.
    let (frames, frames_in) = crossbeam_channel::unbounded::<(Topic, zenoh::sample::Sample)>();
    let subscribers = plan
        .receive
        .iter()
        .map(|&topic| {
            let frames = frames.clone();
            session
                .declare_subscriber(bridge::link_key(&run_id, topic))
                .callback(move |sample| {
                    let _ = frames.send((topic, sample));
                })
                .wait()
                .map_err(zenoh_error("subscribe"))
        })
        .collect::<Result<Vec<_>>>()?;
    drop(frames);
    let (ready, inbound_ready) = crossbeam_channel::bounded::<()>(1);
    let inbound = {
        let (config, run_id, stop, receive) = (config.clone(), run_id.clone(), stop.clone(), plan.receive.clone());
        std::thread::spawn(move || publish_received(role, &config, &run_id, &receive, &frames_in, &stop, ready))
    };

    // Out: this thread reads the topics to send, on their writers' wake-ups.
    let ipc = Ipc::new(role.name(), &run_id, config.mode)?;
    let congestion = match config.mode {
        // Lockstep loses nothing: a full link makes the sender wait, as a full reader does.
        Mode::Lockstep => CongestionControl::Block,
        Mode::Realtime => CongestionControl::Drop,
    };
    let publishers: BTreeMap<Topic, zenoh::pubsub::Publisher<'static>> = plan
        .send
        .iter()
        .map(|&topic| {
            let publisher = session
                .declare_publisher(bridge::link_key(&run_id, topic))
                .congestion_control(congestion)
                .priority(Priority::RealTime)
                .express(true)
                .wait()
                .map_err(zenoh_error("declare a publisher"))?;
            Ok((topic, publisher))
        })
        .collect::<Result<_>>()?;
    let outs: Vec<Box<dyn Outbound>> =
        plan.send.iter().map(|&topic| bridge::outbound(&ipc, &config, role, topic)).collect::<Result<_>>()?;
    let ws = waitset()?;
    let wakes = outs.iter().map(|o| o.attach_to(&ws)).collect::<Result<Vec<_>>>()?;
    if inbound_ready.recv().is_err() {
        // The thread failed before its ports were up: its error says why.
        return Err(inbound
            .join()
            .map_err(|_| anyhow!("the receiving thread panicked"))?
            .err()
            .unwrap_or_else(|| anyhow!("the receiving thread ended")));
    }

    let publishers = Arc::new(publishers);
    let _hello = if remote {
        let publishers = publishers.clone();
        let key = bridge::layout_key(&run_id);
        Some(
            session
                .declare_queryable(&key)
                .callback(move |query| {
                    let matched = publishers.values().all(|p| p.matching_status().wait().is_ok_and(|m| m.matching()));
                    let hello =
                        serde_json::to_vec(&Hello { layout: WireLayout::ours(), matched }).expect("serialisable");
                    let _ = query.reply(query.key_expr().clone(), hello).wait();
                })
                .wait()
                .map_err(zenoh_error("declare the layout queryable"))?,
        )
    } else {
        meet(&session, &run_id, &publishers, &stop)?;
        None
    };
    emit(&ChildEvent::Ready)?;

    let mut send = |topic: Topic, frame: &[u8]| publishers[&topic].put(frame).wait().is_ok();
    while !stop.requested() {
        bridge::sleep_until_input(&outs, &mut || wait(&ws))?;
        for out in &outs {
            out.drain(&mut send)?;
        }
    }

    drop(subscribers);
    let received = inbound.join().map_err(|_| anyhow!("the receiving thread panicked"))??;
    let sent: Vec<(Topic, CrossingCounts)> = outs.iter().map(|o| (o.topic(), o.counts())).collect();
    drop(wakes);
    drop(outs);
    drop(ipc);
    let link = std::mem::take(&mut link.lock().expect("not poisoned").counts);
    let leftover = match storage {
        // The last of the run on its host (the launcher stops the stages first): tidy up there.
        Some(lock) => {
            let leftover = run_storage::clean_up_run(&run_id)?.leftover;
            drop(lock);
            leftover
        }
        None => vec![],
    };
    Ok(BridgeReport { topics: bridge::counts_by_topic(sent.into_iter(), received.into_iter()), link, leftover })
}

fn open_session(endpoint: &str, listen: bool) -> Result<zenoh::Session> {
    let mut config = zenoh::Config::default();
    let endpoints = format!("[\"{endpoint}\"]");
    let (listen_at, connect_to) = if listen { (endpoints.as_str(), "[]") } else { ("[]", endpoints.as_str()) };
    let settings = [
        ("mode", "\"peer\""),
        ("scouting/multicast/enabled", "false"),
        ("scouting/gossip/enabled", "false"),
        ("listen/endpoints", listen_at),
        ("connect/endpoints", connect_to),
        // Keep trying the other host, quickly: after a cut the link comes back within a retry.
        ("connect/timeout_ms", "10000"),
        ("connect/exit_on_failure", "false"),
        ("connect/retry", "{ period_init_ms: 50, period_max_ms: 500, period_increase_factor: 2 }"),
        ("transport/link/tx/lease", &LEASE_MS.to_string()),
        ("transport/link/tx/keep_alive", "4"),
    ];
    for (key, value) in settings {
        config.insert_json5(key, value).map_err(|e| anyhow!("zenoh setting {key} = {value}: {e}"))?;
    }
    zenoh::open(config).wait().map_err(|e| anyhow!("cannot open the link at {endpoint}: {e}"))
}

/// This host's bridge meets the other: asks for its layout until it answers that it can send to
/// us, checks that both run the same build, and waits until every topic we send has the other's
/// subscriber, so that nothing sent from the first loop on is lost.
fn meet(
    session: &zenoh::Session,
    run_id: &str,
    publishers: &BTreeMap<Topic, zenoh::pubsub::Publisher<'static>>,
    stop: &StopFlag,
) -> Result<()> {
    let deadline = Instant::now() + MEET_TIMEOUT;
    let mut answered = false;
    while Instant::now() < deadline && !stop.requested() {
        let replies = session
            .get(bridge::layout_key(run_id))
            .timeout(Duration::from_millis(500))
            .wait()
            .map_err(zenoh_error("ask the other bridge"))?;
        while let Ok(reply) = replies.recv() {
            let Ok(sample) = reply.result() else { continue };
            let hello: Hello = serde_json::from_slice(&sample.payload().to_bytes())
                .context("the other host's bridge answered something else than a layout")?;
            if let Some(why) = WireLayout::ours().mismatch(&hello.layout) {
                bail!("the hosts cannot share messages: {why}");
            }
            answered = true;
            let ours_matched = publishers.values().all(|p| p.matching_status().wait().is_ok_and(|m| m.matching()));
            if hello.matched && ours_matched {
                return Ok(());
            }
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    if answered {
        bail!("the other host's bridge answered, but its topics did not meet ours within {} s", MEET_TIMEOUT.as_secs())
    }
    bail!("no answer from the other host's bridge within {} s", MEET_TIMEOUT.as_secs())
}

/// The receiving thread: its own iceoryx2 node (ports stay on the thread that made them),
/// publishing each frame from the link into shared memory and waking the reader.
fn publish_received(
    role: Role,
    config: &LaunchConfig,
    run_id: &str,
    topics: &[Topic],
    frames: &crossbeam_channel::Receiver<(Topic, zenoh::sample::Sample)>,
    stop: &StopFlag,
    ready: crossbeam_channel::Sender<()>,
) -> Result<Vec<(Topic, CrossingCounts)>> {
    let ipc = Ipc::new(&format!("{role}-in"), run_id, config.mode)?;
    let mut ins: Vec<Box<dyn Inbound>> =
        topics.iter().map(|&topic| bridge::inbound(&ipc, config, role, topic)).collect::<Result<_>>()?;
    let _ = ready.send(());
    loop {
        match frames.recv_timeout(WAIT_SLICE) {
            Ok((topic, sample)) => {
                if let Some(port) = ins.iter_mut().find(|p| p.topic() == topic) {
                    port.deliver(&sample.payload().to_bytes())?;
                }
            }
            Err(RecvTimeoutError::Timeout) if stop.requested() => break,
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
    }
    Ok(ins.iter().map(|p| (p.topic(), p.counts())).collect())
}
