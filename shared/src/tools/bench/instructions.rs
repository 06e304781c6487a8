//! `looplab bench --instructions`: instruction counts, which a busy machine does not move, so
//! that a change's cost shows in one run. valgrind's callgrind counts every instruction the
//! process runs in user space, in every thread (perf's counters are not there in a VM); the
//! bench runs each workload under it twice, short and long, and divides the difference of the
//! two counts by the difference of their lengths, so that start-up and finish cancel out. The
//! latency log's intervals, which close per second of wall-clock time (and so come more often
//! the slower callgrind runs), are left out of the count.
//!
//! The workloads (`looplab bench --count WHAT:N`, hidden: what callgrind runs):
//! - `in-process:N`: N loops of the pendulum in one process (`looplab run --in-process`), every
//!   file of the run folder written;
//! - `hop:N`: N hops of a 488 B state message through the loop's own ports
//!   (`runtime::transport::ipc`, the same services and settings): send, then receive in place and give the
//!   chunk back, in one thread, so that no wait adds instructions;
//! - `hop-monitor:N`: the same with the monitor's passive reader on the topic, its receive included;
//! - `schedstat:N`: N reads of the thread's run-queue wait (`runtime::stage::sched`), as every loop
//!   process makes once or twice per loop (user space only: the kernel's side of the `pread` is
//!   not counted; `looplab bench` times the loop without the reads for the whole cost).

use std::path::Path;
use std::process::Command;

use anyhow::{Context as _, Result, anyhow, bail};
use serde::Serialize;

use crate::config::launch::{Mode, Override};
use crate::contract::msg::{Message, PlantState};
use crate::contract::role::Topic;
use crate::model::catalog::Catalog;
use crate::runtime::signals::StopFlag;
use crate::runtime::transport::ipc::{Ipc, Wake};

/// One workload: its `--count` name, what it is, its unit, and the two lengths run.
struct Workload {
    name: &'static str,
    what: &'static str,
    unit: &'static str,
    short: u64,
    long: u64,
}

const WORKLOADS: [Workload; 4] = [
    Workload {
        name: "in-process",
        what: "in-process pendulum, every file written",
        unit: "loop",
        short: 2_000,
        long: 6_000,
    },
    Workload {
        name: "hop",
        what: "state hop (488 B): send, receive, release",
        unit: "hop",
        short: 2_000,
        long: 12_000,
    },
    Workload {
        name: "hop-monitor",
        what: "the same, the monitor reading too",
        unit: "hop",
        short: 2_000,
        long: 12_000,
    },
    Workload {
        name: "schedstat",
        what: "run-queue read (schedstat pread), user space",
        unit: "read",
        short: 2_000,
        long: 12_000,
    },
];

#[derive(Debug, Clone, Serialize)]
pub struct InstructionCount {
    pub workload: String,
    pub unit: String,
    pub per_unit: f64,
    /// The two runs: (length, instructions).
    pub runs: [(u64, u64); 2],
}

/// Counts every workload under callgrind (its files, `callgrind.<workload>.<n>.out`, go to `out`
/// for `callgrind_annotate`), prints the counts and writes `instructions.json`.
pub fn run(out: &Path) -> Result<Vec<InstructionCount>> {
    let version = Command::new("valgrind").arg("--version").output();
    if !version.as_ref().is_ok_and(|o| o.status.success()) {
        bail!(
            "counting instructions needs valgrind (its callgrind tool): install it, for example `apt-get install valgrind`"
        );
    }
    let exe = std::env::current_exe()?;
    tell!("looplab bench --instructions: each workload twice under valgrind's callgrind (about a minute)");
    let mut counts = vec![];
    for workload in &WORKLOADS {
        let runs = [workload.short, workload.long].map(|n| (n, 0));
        let mut runs = runs;
        for (n, instructions) in &mut runs {
            *instructions = count(&exe, workload.name, *n, out)?;
        }
        let [(short, low), (long, high)] = runs;
        let per_unit = high.saturating_sub(low) as f64 / (long - short) as f64;
        counts.push(InstructionCount {
            workload: workload.what.to_owned(),
            unit: workload.unit.to_owned(),
            per_unit,
            runs,
        });
    }
    say_raw!("{}", render(&counts));
    std::fs::write(out.join("instructions.json"), serde_json::to_string_pretty(&counts)? + "\n")?;
    Ok(counts)
}

fn render(counts: &[InstructionCount]) -> String {
    let mut s = String::from("\n  instructions (valgrind callgrind, every thread, start-up cancelled)\n");
    for c in counts {
        s += &format!("    {:<48}{:>10.0} per {}\n", c.workload, c.per_unit, c.unit);
    }
    s
}

/// The instructions of one workload run under callgrind.
fn count(exe: &Path, workload: &str, n: u64, out: &Path) -> Result<u64> {
    let folder = out.join(format!("{workload}-{n}"));
    let output = Command::new("valgrind")
        .arg("--tool=callgrind")
        // Everything but the latency log's intervals, which close once per second of wall-clock
        // time: the more of them, the slower callgrind ran. (In this order: the toggle alone
        // would count only inside the function.)
        .arg("--toggle-collect=*LatencyLog::flush_interval*")
        .arg("--collect-atstart=yes")
        .arg(format!("--callgrind-out-file={}", out.join(format!("callgrind.{workload}.{n}.out")).display()))
        .arg(exe)
        .args(["bench", "--count", &format!("{workload}:{n}"), "--out"])
        .arg(&folder)
        .output()
        .context("run valgrind")?;
    let stderr = String::from_utf8_lossy(&output.stderr);
    if !output.status.success() {
        bail!(
            "{workload}:{n} under callgrind failed: {}",
            stderr.lines().rev().take(5).collect::<Vec<_>>().join(" / ")
        );
    }
    collected(&stderr).ok_or_else(|| anyhow!("{workload}:{n}: no instruction count in callgrind's output"))
}

/// The count callgrind prints at the end: `==123== Collected : 299759488`.
fn collected(stderr: &str) -> Option<u64> {
    stderr.lines().find_map(|line| line.split_once("Collected :").and_then(|(_, n)| n.trim().parse().ok()))
}

/// Runs workload `spec` (`WHAT:N`) in this process, in the bench's run `run_id`, the in-process
/// run's folder at `out`.
pub fn workload(spec: &str, run_id: &str, out: &Path, catalog: &Catalog) -> Result<()> {
    let (name, n) = spec.split_once(':').ok_or_else(|| anyhow!("--count takes WHAT:N, not {spec}"))?;
    let n: u64 = n.parse().map_err(|_| anyhow!("--count {spec}: N is a whole number"))?;
    match name {
        "in-process" => in_process(n, out, catalog),
        "hop" => hops(run_id, n, false),
        "hop-monitor" => hops(run_id, n, true),
        "schedstat" => run_queue_reads(n),
        _ => bail!("--count: no workload {name} (in-process, hop, hop-monitor, schedstat)"),
    }
}

/// `looplab run pendulum --in-process` for n loops into `out`.
fn in_process(n: u64, out: &Path, catalog: &Catalog) -> Result<()> {
    let (probe, _) = catalog.resolve("pendulum", &[])?;
    let duration = format!("duration_s={}", n as f64 / probe.rate_hz);
    let overrides = [Override::parse("mode=lockstep")?, Override::parse(&duration)?];
    let (config, scenario) = catalog.resolve("pendulum", &overrides)?;
    std::fs::create_dir_all(out)?;
    let (summary, _) = crate::launcher::in_process::run_in_process(&config, scenario.as_ref(), out)?;
    if summary.loops != n {
        bail!("the in-process run ran {} loops of {n}", summary.loops);
    }
    Ok(())
}

/// n hops of the state through the loop's ports, as the plant sends it and the sensors read it.
fn hops(run_id: &str, n: u64, monitor: bool) -> Result<()> {
    let ipc = Ipc::new("instructions", run_id, Mode::Lockstep)?;
    let publisher = ipc.publisher::<PlantState>(Topic::State, Wake::Futex)?;
    let subscriber = ipc.stage_subscriber::<PlantState>(Topic::State, true)?;
    let monitor = if monitor { Some(ipc.passive_subscriber::<PlantState>(Topic::State)?) } else { None };
    subscriber.connect(&StopFlag::install()?, std::time::Duration::from_secs(20))?;
    let mut message = PlantState::default();
    for k in 0..n {
        message.header_mut().k = k;
        publisher.send(&message)?;
        let mut cleared = false;
        let sample = subscriber.next(&mut cleared)?.ok_or_else(|| anyhow!("hop {k}: nothing arrived"))?;
        if std::hint::black_box(sample.payload().header().k) != k {
            bail!("hop {k}: another message arrived");
        }
        drop(sample);
        if let Some(monitor) = &monitor {
            monitor.receive()?.ok_or_else(|| anyhow!("hop {k}: nothing reached the monitor"))?;
        }
    }
    Ok(())
}

/// n reads of this thread's run-queue wait, as a loop process makes them.
fn run_queue_reads(n: u64) -> Result<()> {
    let mut run_queue = crate::runtime::stage::sched::RunQueue::open();
    if !run_queue.available() {
        bail!("this kernel has no /proc/thread-self/schedstat: nothing to count");
    }
    for _ in 0..n {
        std::hint::black_box(run_queue.since_last());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_count_is_read_from_callgrinds_output() {
        let stderr =
            "==4429== Events    : Ir\n==4429== Collected : 299759488\n==4429== \n==4429== I   refs:      299,759,488\n";
        assert_eq!(collected(stderr), Some(299_759_488));
        assert_eq!(collected("==1== no count\n"), None);
    }

    #[test]
    fn the_workloads_run_without_callgrind() {
        let catalog = crate::scenarios::builtin();
        let dir = tempfile::tempdir().unwrap();
        workload("in-process:50", "unused", &dir.path().join("run"), &catalog).unwrap();
        assert!(dir.path().join("run/run.mcap").exists());
        let run_id = crate::launcher::new_run_id();
        let lock = crate::runtime::storage::run_storage::create_run_storage(&run_id).unwrap();
        let hopped = workload("hop:100", &run_id, dir.path(), &catalog)
            .and_then(|()| workload("hop-monitor:100", &run_id, dir.path(), &catalog));
        let cleanup = crate::runtime::storage::run_storage::clean_up_run(&run_id).unwrap();
        drop(lock);
        hopped.unwrap();
        assert!(cleanup.leftover.is_empty(), "{:?}", cleanup.leftover);
        assert!(workload("hops:1", &run_id, dir.path(), &catalog).is_err());
    }
}
