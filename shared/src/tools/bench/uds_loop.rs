//! The hand-written baseline: the same four-stage loop (plant → sensors → estimator →
//! controller → plant) over Unix datagram sockets, each message serialised with bincode, every
//! stage blocking in `recv`. The plant ticks on an absolute clock in the bench process (one
//! thread sends the states, one receives the commands); the three stages are child processes
//! (`looplab bench-uds-stage`). The stages only relay: LoopLab's own stages compute for about a
//! microsecond each, which the comparison leaves in.
//!
//! The messages have the byte sizes of LoopLab's own (`PlantState`, `Measurements`,
//! `Estimate`, `Command`), carried as vectors of floats, and the same eight stamps.

use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use anyhow::{Context, Result, anyhow};
use serde::{Deserialize, Serialize};

use crate::contract::clock::{cpu_seconds, now_ns};
use crate::contract::codec;
use crate::contract::msg::{Command as CommandMessage, Estimate, Measurements, PlantState};
use crate::contract::role::Role;
use crate::runtime::signals::{Interrupted, StopFlag};
use crate::runtime::transport::wait::sleep_until;

const END: u64 = u64::MAX;

#[derive(Serialize, Deserialize)]
struct LoopMessage {
    k: u64,
    stamps: [u64; 8],
    data: Vec<f64>,
}

#[derive(Debug, Clone, clap::Args)]
pub struct StageArgs {
    #[arg(long)]
    pub role: Role,
    #[arg(long)]
    pub dir: PathBuf,
}

/// The loop process that reads what `role` sends.
fn next_of(role: Role) -> Role {
    Role::LOOP.into_iter().find(|next| next.input() == role.output()).expect("every loop topic has a reader")
}

/// Floats in the message a role sends: LoopLab's message of that hop, in bytes, over 8.
fn floats_sent_by(role: Role) -> usize {
    let bytes = match role {
        Role::Plant => std::mem::size_of::<PlantState>(),
        Role::Sensors => std::mem::size_of::<Measurements>(),
        Role::Estimator => std::mem::size_of::<Estimate>(),
        Role::Controller => std::mem::size_of::<CommandMessage>(),
        Role::Monitor | Role::Bridge | Role::BridgeRemote => unreachable!("only loop stages are in the baseline loop"),
    };
    bytes / 8
}

/// A child stage: receive, stamp, relay to the next, until the end marker has passed.
pub fn stage_main(args: &StageArgs) -> Result<()> {
    let index =
        Role::STAGES.iter().position(|r| *r == args.role).ok_or_else(|| anyhow!("unknown role {}", args.role))?;
    let socket = UnixDatagram::bind(args.dir.join(format!("{}.sock", args.role)))?;
    let next = args.dir.join(format!("{}.sock", next_of(args.role)));
    println!("ready");
    let mut buffer = vec![0u8; 64 * 1024];
    let mut out = Vec::new();
    let floats = floats_sent_by(args.role);
    loop {
        let n = socket.recv(&mut buffer)?;
        let received = now_ns();
        let mut message: LoopMessage = codec::decode(&buffer[..n])?;
        message.stamps[1 + 2 * index] = received;
        message.data.resize(floats, 0.0);
        message.stamps[2 + 2 * index] = now_ns();
        codec::encode(&message, &mut out)?;
        socket.send_to(&out, &next)?;
        if message.k == END {
            return Ok(());
        }
    }
}

/// What a baseline run measured.
pub struct LoopResult {
    /// Per loop: the eight stamps, in LoopLab's trace order.
    pub traces: Vec<[u64; 8]>,
    pub loops: u64,
    pub deadline_misses: u64,
    /// CPU seconds: plant (both threads), sensors, estimator, controller.
    pub cpu_s: [f64; 4],
}

fn thread_cpu_s() -> f64 {
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: getrusage writes into the struct we own.
    unsafe { libc::getrusage(libc::RUSAGE_THREAD, &mut usage) };
    cpu_seconds(&usage)
}

/// Waits for a child and returns its CPU seconds.
fn reap(child: Child) -> Result<f64> {
    let mut status = 0;
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: wait4 on our own child's pid, writing into structs we own.
    let pid = unsafe { libc::wait4(child.id() as libc::pid_t, &mut status, 0, &mut usage) };
    if pid < 0 {
        return Err(std::io::Error::last_os_error().into());
    }
    Ok(cpu_seconds(&usage))
}

/// Runs the baseline loop for `loops` ticks at `rate_hz`.
pub fn run(exe: &Path, dir: &Path, rate_hz: f64, loops: u64) -> Result<LoopResult> {
    std::fs::create_dir_all(dir)?;
    for role in Role::LOOP {
        let _ = std::fs::remove_file(dir.join(format!("{role}.sock")));
    }
    let plant_socket = UnixDatagram::bind(dir.join("plant.sock"))?;
    let mut children = Vec::new();
    for role in Role::STAGES {
        let mut command = Command::new(exe);
        command
            .args(["bench-uds-stage", "--role", role.name(), "--dir"])
            .arg(dir)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit());
        crate::launcher::supervised(&mut command);
        let mut child = command.spawn().context("start a baseline stage")?;
        let mut line = String::new();
        std::io::BufRead::read_line(&mut std::io::BufReader::new(child.stdout.take().expect("piped")), &mut line)?;
        children.push(child);
    }
    let period = crate::contract::clock::period_ns(rate_hz);
    let start = now_ns() + 20_000_000;
    let receiver = plant_socket.try_clone()?;
    let collect = std::thread::spawn(move || -> Result<(Vec<[u64; 8]>, u64, f64)> {
        let mut buffer = vec![0u8; 64 * 1024];
        let mut traces = Vec::new();
        let mut misses = 0;
        loop {
            let n = receiver.recv(&mut buffer)?;
            let arrived = now_ns();
            let message: LoopMessage = codec::decode(&buffer[..n])?;
            if message.k == END {
                return Ok((traces, misses, thread_cpu_s()));
            }
            if arrived > start + (message.k + 1) * period {
                misses += 1;
            }
            let mut stamps = message.stamps;
            stamps[7] = arrived;
            traces.push(stamps);
        }
    });
    let sensors = dir.join("sensors.sock");
    let stop = StopFlag::install()?;
    let send_stop = stop.clone();
    let send = std::thread::spawn(move || -> Result<f64> {
        let mut out = Vec::new();
        let floats = floats_sent_by(Role::Plant);
        // A stop request ends the loop early; the stages are told to go as usual.
        for k in (0..loops).take_while(|_| !send_stop.requested()) {
            sleep_until(start + k * period);
            let mut message = LoopMessage { k, stamps: [0; 8], data: vec![0.0; floats] };
            message.stamps[0] = now_ns();
            codec::encode(&message, &mut out)?;
            plant_socket.send_to(&out, &sensors)?;
        }
        std::thread::sleep(Duration::from_millis(50));
        codec::encode(&LoopMessage { k: END, stamps: [0; 8], data: Vec::new() }, &mut out)?;
        plant_socket.send_to(&out, &sensors)?;
        Ok(thread_cpu_s())
    });
    let sender_cpu = send.join().map_err(|_| anyhow!("the sender panicked"))??;
    let (traces, deadline_misses, receiver_cpu) = collect.join().map_err(|_| anyhow!("the receiver panicked"))??;
    let mut cpu_s = [sender_cpu + receiver_cpu, 0.0, 0.0, 0.0];
    for (i, child) in children.into_iter().enumerate() {
        cpu_s[1 + i] = reap(child)?;
    }
    for role in Role::LOOP {
        let _ = std::fs::remove_file(dir.join(format!("{role}.sock")));
    }
    if stop.requested() {
        return Err(Interrupted.into());
    }
    Ok(LoopResult { traces, loops, deadline_misses, cpu_s })
}
