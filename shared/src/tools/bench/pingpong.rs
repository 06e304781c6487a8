//! Two-process ping-pong: the transport's floor. The parent sends a ping every period (or as
//! fast as it can), a child (`looplab bench-echo`) answers each with a pong of the same size,
//! and both one-way hops are measured from CLOCK_MONOTONIC stamps carried in the message:
//! ping sent → ping received, and pong sent → pong received.
//!
//! Over iceoryx2 the payload is a `[u8]` slice in shared memory: the sender writes only the
//! stamps into its loan (zero copy: a producer writes its data into the loan once, whatever the
//! transport). Over a Unix stream socket the payload is a byte vector serialised with bincode,
//! length-prefixed, with blocking reads: what one would write by hand.

use std::io::{Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow, bail};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use serde::{Deserialize, Serialize};

use crate::config::wait::{Strategy, WaitSettings};
use crate::contract::clock::now_ns;
use crate::contract::codec;
use crate::runtime::storage::run_storage::run_config;
use crate::runtime::transport::ipc::{doze, retry};
use crate::runtime::transport::wait::{ArrivalModel, Waiter, sleep_until};

/// Bytes at the start of every message: sequence, ping sent, echo received, echo sent.
const STAMPS: usize = 32;
/// The sequence number that ends the echo.
const END: u64 = u64::MAX;
/// A wait gives up and looks at the clock again after this long.
const SLICE: Duration = Duration::from_millis(100);

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
pub enum Transport {
    Iox,
    Uds,
    /// One cache line in shared memory, both ends pinned (`super::raw_floor`).
    Raw,
}

#[derive(Debug, Clone, clap::Args)]
pub struct EchoArgs {
    #[arg(long)]
    pub run_id: String,
    #[arg(long, value_enum)]
    pub transport: Transport,
    #[arg(long, value_enum)]
    pub mode: Strategy,
    #[arg(long)]
    pub period_ns: u64,
    #[arg(long)]
    pub max_bytes: usize,
    #[arg(long)]
    pub socket: Option<PathBuf>,
    /// Raw: the CPU the echo pins itself to.
    #[arg(long, default_value_t = 1)]
    pub cpu: usize,
}

fn write_stamps(bytes: &mut [u8], stamps: [u64; 4]) {
    for (i, s) in stamps.iter().enumerate() {
        bytes[8 * i..8 * i + 8].copy_from_slice(&s.to_le_bytes());
    }
}

fn read_stamps(bytes: &[u8]) -> [u64; 4] {
    std::array::from_fn(|i| u64::from_le_bytes(bytes[8 * i..8 * i + 8].try_into().expect("8 bytes")))
}

/// One side of an iceoryx2 ping-pong: a publisher and notifier on one service, a subscriber
/// and listener on the other.
struct IoxEnd {
    _node: Node<ipc::Service>,
    publisher: Publisher<ipc::Service, [u8], ()>,
    notifier: Notifier<ipc::Service>,
    subscriber: Subscriber<ipc::Service, [u8], ()>,
    listener: Listener<ipc::Service>,
}

impl IoxEnd {
    fn open(run_id: &str, send: &str, receive: &str, max_bytes: usize) -> Result<Self> {
        let config = run_config(run_id)?;
        let node = NodeBuilder::new()
            .config(&config)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .map_err(|e| anyhow!("node: {e:?}"))?;
        let name = |topic: &str| ServiceName::new(&format!("bench/{run_id}/{topic}")).map_err(|e| anyhow!("{e:?}"));
        // Both processes open the same services: retry while the other is creating them.
        let pubsub = |topic: &str| -> Result<_> {
            let name = name(topic)?;
            retry(&format!("service {topic}"), || {
                node.service_builder(&name)
                    .publish_subscribe::<[u8]>()
                    .history_size(0)
                    .subscriber_max_buffer_size(2)
                    .enable_safe_overflow(true)
                    .open_or_create()
            })
        };
        let event = |topic: &str| -> Result<_> {
            let name = name(&format!("{topic}-wake"))?;
            retry(&format!("event {topic}"), || node.service_builder(&name).event().open_or_create())
        };
        let publisher = pubsub(send)?
            .publisher_builder()
            .initial_max_slice_len(max_bytes)
            .create()
            .map_err(|e| anyhow!("publisher: {e:?}"))?;
        let subscriber =
            pubsub(receive)?.subscriber_builder().buffer_size(2).create().map_err(|e| anyhow!("subscriber: {e:?}"))?;
        let notifier = event(send)?.notifier_builder().create().map_err(|e| anyhow!("notifier: {e:?}"))?;
        let listener = event(receive)?.listener_builder().create().map_err(|e| anyhow!("listener: {e:?}"))?;
        Ok(Self { _node: node, publisher, notifier, subscriber, listener })
    }

    fn send(&self, bytes: usize, stamps: [u64; 4]) -> Result<()> {
        let mut sample = self.publisher.loan_slice_uninit(bytes).map_err(|e| anyhow!("loan: {e:?}"))?;
        let mut head = [0u8; STAMPS];
        write_stamps(&mut head, stamps);
        for (slot, byte) in sample.payload_mut().iter_mut().zip(head) {
            slot.write(byte);
        }
        // SAFETY: the data segment is a shared-memory file mapping, which the kernel zero-fills,
        // so every byte of the chunk is initialised memory; only the stamps are ever read.
        let sample = unsafe { sample.assume_init() };
        sample.send().map_err(|e| anyhow!("send: {e:?}"))?;
        self.notifier.notify().map_err(|e| anyhow!("notify: {e:?}"))?;
        Ok(())
    }

    /// Waits with `waiter` for the next message; returns its size, stamps and arrival time.
    fn receive(&self, waiter: &mut Waiter, due: Option<u64>) -> Result<Option<(usize, [u64; 4], u64)>> {
        let slice_end = now_ns() + SLICE.as_nanos() as u64;
        waiter.wait(
            due,
            slice_end,
            || self.subscriber.has_samples().map_err(|e| anyhow!("{e:?}")),
            |until| doze(&self.listener, until),
            || self.listener.timed_wait(|_| {}, SLICE).map(|_| ()).map_err(|e| anyhow!("listener: {e:?}")),
        )?;
        let sample = self.subscriber.receive().map_err(|e| anyhow!("receive: {e:?}"))?;
        let arrived = now_ns();
        self.listener.try_wait(|_| {}).map_err(|e| anyhow!("listener: {e:?}"))?;
        Ok(sample.map(|s| (s.payload().len(), read_stamps(s.payload()), arrived)))
    }
}

/// A length-prefixed, bincode-encoded frame on a Unix stream socket.
#[derive(Serialize, Deserialize)]
struct Frame {
    stamps: [u64; 4],
    #[serde(with = "serde_bytes")]
    payload: Vec<u8>,
}

fn write_frame(stream: &mut UnixStream, frame: &Frame, buffer: &mut Vec<u8>) -> Result<()> {
    codec::encode(frame, buffer)?;
    stream.write_all(&(buffer.len() as u32).to_le_bytes())?;
    stream.write_all(buffer)?;
    Ok(())
}

fn read_frame(stream: &mut UnixStream, buffer: &mut Vec<u8>) -> Result<Frame> {
    let mut length = [0u8; 4];
    stream.read_exact(&mut length)?;
    buffer.resize(u32::from_le_bytes(length) as usize, 0);
    stream.read_exact(buffer)?;
    codec::decode(buffer)
}

/// The child's side: answers every ping until the end marker.
pub fn echo_main(args: &EchoArgs) -> Result<()> {
    match args.transport {
        Transport::Raw => super::raw_floor::echo_main(&args.run_id, args.cpu),
        Transport::Iox => {
            let end = IoxEnd::open(&args.run_id, "pong", "ping", args.max_bytes)?;
            let settings = WaitSettings { strategy: args.mode, ..Default::default() };
            let mut waiter = Waiter::with_method(&settings, args.mode.into(), args.period_ns);
            let mut arrivals = ArrivalModel::new(args.period_ns.max(1));
            let mut last: Option<u64> = None;
            println!("ready");
            loop {
                let due = if args.period_ns > 0 { last.and_then(|k| arrivals.due(k + 1)) } else { None };
                let Some((bytes, stamps, arrived)) = end.receive(&mut waiter, due)? else { continue };
                if stamps[0] == END {
                    return Ok(());
                }
                arrivals.observe(stamps[0], stamps[1], arrived);
                last = Some(stamps[0]);
                end.send(bytes, [stamps[0], stamps[1], arrived, now_ns()])?;
            }
        }
        Transport::Uds => {
            let socket = args.socket.as_ref().context("--socket is required for uds")?;
            let mut stream = UnixStream::connect(socket)?;
            let mut buffer = Vec::new();
            loop {
                let frame = read_frame(&mut stream, &mut buffer)?;
                let arrived = now_ns();
                if frame.stamps[0] == END {
                    return Ok(());
                }
                let reply =
                    Frame { stamps: [frame.stamps[0], frame.stamps[1], arrived, now_ns()], payload: frame.payload };
                write_frame(&mut stream, &reply, &mut buffer)?;
            }
        }
    }
}

/// What one ping-pong series measured: one-way hop latencies (ns), two per round trip.
pub struct Series {
    pub one_way_ns: Vec<u64>,
}

fn spawn_echo(exe: &Path, args: &[String]) -> Result<Child> {
    let mut command = Command::new(exe);
    command.arg("bench-echo").args(args).stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::inherit());
    crate::launcher::supervised(&mut command);
    command.spawn().context("start the echo process")
}

/// Where a ping-pong runs: the looplab executable (for the echo process), the bench's run id
/// (its iceoryx2 prefix) and a folder for sockets.
pub struct Setup<'a> {
    pub exe: &'a Path,
    pub run_id: &'a str,
    pub scratch: &'a Path,
}

/// Runs `rounds` pings of `bytes` bytes, one every `period_ns` (0: back to back), against a
/// fresh echo process.
pub fn ping(
    setup: &Setup,
    transport: Transport,
    mode: Strategy,
    bytes: usize,
    rounds: usize,
    period_ns: u64,
) -> Result<Series> {
    let Setup { exe, run_id, scratch } = *setup;
    let bytes = bytes.max(STAMPS);
    // A stop request ends the series early, the echo process told to go as usual.
    let stop = crate::runtime::signals::StopFlag::install()?;
    let mut args = vec![
        "--run-id".into(),
        run_id.into(),
        "--transport".into(),
        format!("{transport:?}").to_lowercase(),
        "--mode".into(),
        mode.name().into(),
        "--period-ns".into(),
        period_ns.to_string(),
        "--max-bytes".into(),
        bytes.to_string(),
    ];
    let mut one_way = Vec::with_capacity(2 * rounds);
    // A few rounds first, unmeasured: page faults, caches, the echo's arrival model.
    let warm_up = (rounds / 10).clamp(5, 200);
    match transport {
        Transport::Iox => {
            let end = IoxEnd::open(run_id, "ping", "pong", bytes)?;
            let mut child = spawn_echo(exe, &args)?;
            let mut ready = String::new();
            std::io::BufRead::read_line(&mut std::io::BufReader::new(child.stdout.take().expect("piped")), &mut ready)?;
            let settings = WaitSettings { strategy: mode, ..Default::default() };
            let mut waiter = Waiter::with_method(&settings, mode.into(), period_ns);
            let mut arrivals = ArrivalModel::new(period_ns.max(1));
            // iceoryx2 connects lazily: make sure both directions are up before the first ping.
            use iceoryx2::port::update_connections::UpdateConnections;
            end.publisher.update_connections().map_err(|e| anyhow!("{e:?}"))?;
            end.subscriber.update_connections().map_err(|e| anyhow!("{e:?}"))?;
            let first = now_ns() + 10_000_000;
            for k in 0..(warm_up + rounds) as u64 {
                if stop.requested() {
                    break;
                }
                if period_ns > 0 {
                    sleep_until(first + k * period_ns);
                }
                let sent = now_ns();
                end.send(bytes, [k, sent, 0, 0])?;
                let due = if period_ns > 0 { arrivals.due(k) } else { None };
                let give_up = Instant::now() + Duration::from_secs(2);
                let reply = loop {
                    match end.receive(&mut waiter, due)? {
                        Some(r) if r.1[0] == k => break r,
                        _ if Instant::now() > give_up => bail!("no answer to ping {k} from the echo process"),
                        _ => {}
                    }
                };
                let (_, stamps, arrived) = reply;
                arrivals.observe(k, sent, arrived);
                if k >= warm_up as u64 {
                    one_way.push(stamps[2].saturating_sub(stamps[1]));
                    one_way.push(arrived.saturating_sub(stamps[3]));
                }
            }
            end.send(STAMPS, [END, 0, 0, 0])?;
            child.wait()?;
        }
        Transport::Uds => {
            let socket = scratch.join(format!("{run_id}.sock"));
            let _ = std::fs::remove_file(&socket);
            let listener = UnixListener::bind(&socket)?;
            args.extend(["--socket".into(), socket.display().to_string()]);
            let mut child = spawn_echo(exe, &args)?;
            let (mut stream, _) = listener.accept()?;
            let mut ping = Frame { stamps: [0; 4], payload: vec![0x5au8; bytes] };
            let mut buffer = Vec::new();
            let first = now_ns() + 10_000_000;
            for k in 0..(warm_up + rounds) as u64 {
                if stop.requested() {
                    break;
                }
                if period_ns > 0 {
                    sleep_until(first + k * period_ns);
                }
                let sent = now_ns();
                ping.stamps = [k, sent, 0, 0];
                write_frame(&mut stream, &ping, &mut buffer)?;
                let reply = read_frame(&mut stream, &mut buffer)?;
                let arrived = now_ns();
                if k >= warm_up as u64 {
                    one_way.push(reply.stamps[2].saturating_sub(reply.stamps[1]));
                    one_way.push(arrived.saturating_sub(reply.stamps[3]));
                }
            }
            write_frame(&mut stream, &Frame { stamps: [END, 0, 0, 0], payload: Vec::new() }, &mut buffer)?;
            child.wait()?;
            let _ = std::fs::remove_file(&socket);
        }
        Transport::Raw => return Err(anyhow!("the raw floor has its own ping: raw_floor::measure")),
    }
    if stop.requested() {
        return Err(crate::runtime::signals::Interrupted.into());
    }
    Ok(Series { one_way_ns: one_way })
}
