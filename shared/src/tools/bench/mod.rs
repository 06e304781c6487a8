//! `looplab bench`: how fast LoopLab's own loop is, against the machine's limits and against
//! what one would write by hand, measured in one invocation with the parts interleaved (each
//! round runs every part once) so that drift on a shared machine hits them alike.
//!
//! 1. The floors: the physical one (one cache line passed between two pinned processes, the
//!    least any hop can cost here), and a two-process iceoryx2 ping-pong with the loop's message
//!    size, per wait mode. The loop's physical limit is four physical hops plus the stages' own
//!    compute time.
//!    Where a hop's time goes: the loop's own ports timed step by step (`anatomy`).
//!    With `--instructions`, only instruction counts per loop and per hop (`instructions`).
//! 2. The LoopLab loop (pendulum, real time, 1 kHz, monitor running) per wait mode, and the
//!    adaptive mode at 10 kHz.
//! 3. The baseline: the same four-stage loop over Unix sockets with bincode, blocking reads.
//! 4. The monitor's cost: its CPU next to the loop's, and the loop with the monitor stopped.
//! 5. Zero copy: one-way latency against payload size, iceoryx2 against the Unix socket.
//! 6. Lockstep speed, polling and blocking, against the same four stages called in one process
//!    (the ceiling).
//! 7. The machine: CPUs, kernel, load, and the timer's own wake-up error at 1 kHz.
//!
//! A part that needs more CPUs than the machine has (spinning needs one per spinning process) is
//! skipped and named as such.

pub mod anatomy;
pub mod instructions;
pub mod own_stage;
pub mod pingpong;
pub mod plants;
pub mod raw_floor;
mod report;
pub mod restarts;
pub mod uds_loop;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Result, anyhow, bail};

use self::own_stage::OwnController;
use self::pingpong::Transport;
use self::report::render;
pub use self::report::{BenchReport, Dist, LoopBench, Machine, PayloadPoint};
use crate::config::launch::Override;
use crate::config::wait::{CPUS_TO_POLL, LockstepWait, Strategy, WaitSettings};
use crate::contract::clock::{TickTimer, now_ns};
use crate::contract::msg::{LoopTrace, PlantState};
use crate::contract::role::Role;
use crate::contract::run_format::files;
use crate::launcher::{Binaries, Outcome, Summary};
use crate::model::catalog::Catalog;
use crate::runtime::signals::{Interrupted, StopFlag};
use crate::tools::plot::latency as plot;
use crate::tools::run_folder::RunFolder;

#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// A short form that finishes in under a minute: fewer rounds, shorter runs
    #[arg(long)]
    pub quick: bool,
    /// Seconds of loop per configuration, over all rounds (default 60; --quick 4)
    #[arg(long, value_name = "SECONDS")]
    pub seconds: Option<f64>,
    /// Folder for bench.json, the charts and the runs (default: runs/<time>-bench)
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Only measure restarts: N real-time kills of the loop's processes, idle and then with two
    /// CPU hogs and an fsync loop; p50/p99/max of each step; writes restarts.json
    #[arg(long, value_name = "N")]
    pub restarts: Option<usize>,
    /// Only measure plants: each one's step cost per tick and its lockstep loops/s in one
    /// process, for the launch files (or scenario names) given, else the built-in list
    /// (plants.rs); writes plants.json
    #[arg(long, value_name = "LAUNCH", num_args = 0..)]
    pub plants: Option<Vec<String>>,
    /// Only count instructions, with valgrind's callgrind (every thread; a busy machine does
    /// not move them): per loop of the in-process pendulum with its files written, and per hop
    /// through the loop's ports (instructions.rs); writes instructions.json
    #[arg(long)]
    pub instructions: bool,
    /// The workload --instructions runs under callgrind: in-process:N, hop:N or hop-monitor:N
    #[arg(long, value_name = "WHAT:N", hide = true)]
    pub count: Option<String>,
}

const MODES: [Strategy; 3] = [Strategy::Block, Strategy::Spin, Strategy::Adaptive];

fn sorted(mut v: Vec<u64>) -> Vec<u64> {
    v.sort_unstable();
    v
}

fn machine(timer_periods: u64) -> Result<Machine> {
    let read = |path: &str| std::fs::read_to_string(path).unwrap_or_default().trim().to_string();
    let cpu_model = read("/proc/cpuinfo")
        .lines()
        .find(|l| l.starts_with("model name"))
        .and_then(|l| l.split(':').nth(1))
        .unwrap_or("unknown")
        .trim()
        .to_string();
    // The timer's own error: how late a 1 kHz timerfd wakes a blocked thread.
    let period = 1_000_000;
    let start = now_ns() + 5_000_000;
    let timer = TickTimer::new(start, period)?;
    let mut late = Vec::with_capacity(timer_periods as usize);
    let mut k = 0;
    while k < timer_periods {
        let mut fds = libc::pollfd { fd: timer_fd(&timer), events: libc::POLLIN, revents: 0 };
        // SAFETY: one valid pollfd.
        unsafe { libc::poll(&mut fds, 1, 100) };
        let woke = now_ns();
        let expired = timer.expirations();
        if expired > 0 {
            late.push(woke.saturating_sub(start + (k + expired - 1) * period));
            k += expired;
        }
    }
    Ok(Machine {
        cpus: std::thread::available_parallelism().map_or(1, |n| n.get()),
        cpu_model,
        kernel: read("/proc/sys/kernel/osrelease"),
        load_average: read("/proc/loadavg"),
        timer_wake_error_us: Dist::of(&sorted(late)),
    })
}

fn timer_fd(timer: &TickTimer) -> i32 {
    use iceoryx2::prelude::FileDescriptorBased;
    // SAFETY: the descriptor is only polled while the timer, which owns it, is alive.
    unsafe { timer.file_descriptor().native_handle() }
}

/// The eight stamps of every recorded loop of a run (its loops.csv); a loop without a record
/// has none.
fn traces(run_dir: &Path) -> Result<Vec<[u64; 8]>> {
    let loops = RunFolder::open(run_dir, &[files::LOOPS])?.table(files::LOOPS)?;
    let stamps = loops.stamps()?;
    Ok((0..loops.len())
        .filter_map(|row| stamps.iter().map(|column| column[row]).collect::<Option<Vec<u64>>>()?.try_into().ok())
        .collect())
}

/// Accumulates a loop configuration's rounds.
#[derive(Default)]
struct LoopAccumulator {
    traces: Vec<[u64; 8]>,
    loops: u64,
    misses: u64,
    cpu_s: BTreeMap<Role, f64>,
    seconds: f64,
    /// Per run, the plant's tick wake-up latency and the probe's beside it: (p50, p99), µs.
    tick_wake: Vec<[f64; 2]>,
    probe_wake: Vec<[f64; 2]>,
}

/// A run's (p50, p99) in µs, if it has them.
fn p50_p99(s: &crate::contract::report::Stats) -> Option<[f64; 2]> {
    Some([s.p50? as f64 / 1e3, s.p99? as f64 / 1e3])
}

/// The median over runs of each of (p50, p99): quantiles of separate runs do not merge exactly.
fn median_of(runs: &[[f64; 2]]) -> Option<[f64; 2]> {
    let median = |i: usize| {
        let mut v: Vec<f64> = runs.iter().map(|r| r[i]).collect();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    (!runs.is_empty()).then(|| [median(0), median(1)])
}

impl LoopAccumulator {
    fn add_run(&mut self, summary: &Summary, run_dir: &Path) -> Result<()> {
        self.traces.extend(traces(run_dir)?);
        self.loops += summary.loops;
        self.misses += summary.deadline_misses;
        self.seconds += summary.duration_s;
        self.tick_wake.extend(p50_p99(&summary.jitter_ns.plant_wake_latency));
        self.probe_wake.extend(summary.probe.as_ref().and_then(|p| p50_p99(&p.wake_latency_ns)));
        for p in &summary.processes {
            *self.cpu_s.entry(p.name).or_default() += p.cpu_s;
        }
        Ok(())
    }

    fn finish(self, name: &str, rate_hz: f64) -> LoopBench {
        let e2e = sorted(self.traces.iter().map(|s| LoopTrace::from_stamps(*s).end_to_end_ns()).collect());
        let hop = |from: usize, to: usize| {
            Dist::of(&sorted(self.traces.iter().map(|s| s[to].saturating_sub(s[from])).collect()))
        };
        let percent = |cpu_s: f64| 100.0 * cpu_s / self.seconds.max(1e-9);
        let cpu_percent: BTreeMap<String, f64> =
            self.cpu_s.iter().map(|(role, v)| (role.name().to_owned(), percent(*v))).collect();
        let loop_cpu_percent = self.cpu_s.iter().filter(|(role, _)| role.in_loop()).map(|(_, v)| percent(*v)).sum();
        let compute = self.traces.iter().map(|s| (s[2] + s[4] + s[6]).saturating_sub(s[1] + s[3] + s[5])).collect();
        LoopBench {
            name: name.into(),
            rate_hz,
            loops: self.loops,
            deadline_misses: self.misses,
            end_to_end_us: Dist::of(&e2e),
            hops_us: [hop(0, 1), hop(2, 3), hop(4, 5), hop(6, 7)],
            stage_compute_us: Dist::of(&sorted(compute)),
            controller_compute_us: hop(5, 6),
            cpu_percent,
            loop_cpu_percent,
            tick_wake_us: median_of(&self.tick_wake),
            probe_wake_us: median_of(&self.probe_wake),
            e2e,
        }
    }
}

/// A LoopLab loop configuration the bench runs: the pendulum in real time.
struct LoopConfig {
    name: &'static str,
    /// Its run folders' prefix.
    label: &'static str,
    strategy: Strategy,
    rate_hz: f64,
    /// SIGSTOP the monitor for the whole run.
    stop_monitor: bool,
    pin: bool,
    /// A controller of the user's own in place of the built-in one.
    own: Option<OwnController>,
    /// The loop processes read their run-queue wait (`runtime::stage::sched`); off, the same loop
    /// without those reads: their cost on the loop.
    schedstat: bool,
}

impl LoopConfig {
    /// Spinning takes a CPU per loop process, and the monitor needs one of its own.
    fn needs_cpus(&self) -> usize {
        if self.strategy == Strategy::Spin { CPUS_TO_POLL } else { 1 }
    }
}

const LOOP_CONFIGS: [LoopConfig; 10] = [
    LoopConfig {
        name: "looplab block",
        label: "block",
        strategy: Strategy::Block,
        rate_hz: 1000.0,
        stop_monitor: false,
        pin: false,
        own: None,
        schedstat: true,
    },
    LoopConfig {
        name: "looplab block, no run-queue reads",
        label: "block-no-schedstat",
        strategy: Strategy::Block,
        rate_hz: 1000.0,
        stop_monitor: false,
        pin: false,
        own: None,
        schedstat: false,
    },
    LoopConfig {
        name: "looplab spin",
        label: "spin",
        strategy: Strategy::Spin,
        rate_hz: 1000.0,
        stop_monitor: false,
        pin: false,
        own: None,
        schedstat: true,
    },
    LoopConfig {
        name: "looplab spin, pinned",
        label: "spin-pinned",
        strategy: Strategy::Spin,
        rate_hz: 1000.0,
        stop_monitor: false,
        pin: true,
        own: None,
        schedstat: true,
    },
    LoopConfig {
        name: "looplab adaptive",
        label: "adaptive",
        strategy: Strategy::Adaptive,
        rate_hz: 1000.0,
        stop_monitor: false,
        pin: false,
        own: None,
        schedstat: true,
    },
    LoopConfig {
        name: "looplab adaptive, pinned",
        label: "adaptive-pinned",
        strategy: Strategy::Adaptive,
        rate_hz: 1000.0,
        stop_monitor: false,
        pin: true,
        own: None,
        schedstat: true,
    },
    LoopConfig {
        name: "looplab adaptive 10 kHz",
        label: "adaptive-10khz",
        strategy: Strategy::Adaptive,
        rate_hz: 10_000.0,
        stop_monitor: false,
        pin: false,
        own: None,
        schedstat: true,
    },
    LoopConfig {
        name: "looplab adaptive, monitor stopped",
        label: "monitor-stopped",
        strategy: Strategy::Adaptive,
        rate_hz: 1000.0,
        stop_monitor: true,
        pin: false,
        own: None,
        schedstat: true,
    },
    LoopConfig {
        name: BLOCK_PYTHON,
        label: "block-python",
        strategy: Strategy::Block,
        rate_hz: 1000.0,
        stop_monitor: false,
        pin: false,
        own: Some(OwnController::Python),
        schedstat: true,
    },
    LoopConfig {
        name: BLOCK_C,
        label: "block-c",
        strategy: Strategy::Block,
        rate_hz: 1000.0,
        stop_monitor: false,
        pin: false,
        own: Some(OwnController::C),
        schedstat: true,
    },
];

const BLOCK_PYTHON: &str = "looplab block, Python controller";
const BLOCK_C: &str = "looplab block, C controller";

/// One LoopLab run of the pendulum (of `catalog`) in real time.
/// `own`: the override that runs its controller of the user's own.
fn looplab_run(
    out: &Path,
    c: &LoopConfig,
    own: Option<&String>,
    seconds: f64,
    binaries: &Binaries,
    catalog: &Catalog,
) -> Result<(Summary, PathBuf)> {
    let mut sets = vec![
        "mode=realtime".to_string(),
        format!("rate_hz={:?}", c.rate_hz),
        format!("duration_s={seconds:?}"),
        format!("wait.strategy={}", c.strategy.name()),
        format!("wait.pin={}", c.pin),
        // Always: the OS's own timer beside each loop, for the table's timer lines.
        "probe=true".to_string(),
    ];
    sets.extend(own.cloned());
    let mut overrides: Vec<Override> = sets.iter().map(|s| Override::parse(s)).collect::<Result<_, _>>()?;
    if c.stop_monitor {
        // SIGSTOP the monitor for the whole run once it is up: the loop runs without it.
        overrides.push(Override::fault(&format!("stop monitor at 0.001s for {}s", seconds + 1.0))?);
    }
    let (config, scenario) = catalog.resolve("pendulum", &overrides)?;
    let mut n = 0;
    let dir = loop {
        let dir = out.join(format!("{}-{n}", c.label));
        if !dir.exists() {
            break dir;
        }
        n += 1;
    };
    if !c.schedstat {
        // The switch is the loop processes' environment: a launcher of its own, started with it.
        let status = std::process::Command::new(std::env::current_exe()?)
            .args(["run", "pendulum", "-q", "--out"])
            .arg(&dir)
            .args(sets.iter().flat_map(|s| ["--set", s.as_str()]))
            .env(crate::runtime::stage::sched::OFF_ENV, "off")
            .status()?;
        if !status.success() {
            bail!("the run without run-queue reads failed ({status}); its folder: {}", dir.display());
        }
        return Ok((crate::launcher::report::read_summary(&dir)?, dir));
    }
    let dir = crate::launcher::create_run_dir(Some(&dir), "pendulum")?;
    let (summary, outcome) = crate::launcher::run_once(&config, scenario.as_ref(), binaries, &dir, true)?;
    if outcome == Outcome::Interrupted {
        return Err(Interrupted.into());
    }
    Ok((summary, dir))
}

/// Loops per second of a lockstep run of the pendulum through the five processes, with the given
/// `wait.lockstep`.
fn lockstep_run(out: &Path, method: &str, seconds: f64, binaries: &Binaries, catalog: &Catalog) -> Result<f64> {
    let sets = ["mode=lockstep".to_string(), format!("duration_s={seconds:?}"), format!("wait.lockstep={method}")];
    let overrides: Vec<Override> = sets.iter().map(|s| Override::parse(s)).collect::<Result<_, _>>()?;
    let (config, scenario) = catalog.resolve("pendulum", &overrides)?;
    let dir = crate::launcher::create_run_dir(Some(&out.join(format!("lockstep-{method}"))), "pendulum")?;
    let (summary, outcome) = crate::launcher::run_once(&config, scenario.as_ref(), binaries, &dir, true)?;
    if outcome == Outcome::Interrupted {
        return Err(Interrupted.into());
    }
    Ok(summary.loops_per_s)
}

/// The in-process twin (`runtime::in_process`: the same plant core, stage runners and tasks in
/// one thread, nothing recorded): the ceiling of lockstep speed.
fn in_process_loops_per_s(loops: u64, stop: &StopFlag, catalog: &Catalog) -> Result<f64> {
    let (probe, _) = catalog.resolve("pendulum", &[])?;
    let duration = format!("duration_s={}", loops as f64 / probe.rate_hz);
    let overrides = [Override::parse("mode=lockstep")?, Override::parse(&duration)?];
    let (config, scenario) = catalog.resolve("pendulum", &overrides)?;
    let start = Instant::now();
    let reports = crate::runtime::in_process::run(&config, scenario.as_ref(), stop, |_| Ok(()))?;
    check(stop)?;
    Ok(reports.plant.loops as f64 / start.elapsed().as_secs_f64())
}

/// Runs the bench; its loops run the pendulum of `catalog`.
pub fn run(args: &BenchArgs, catalog: &Catalog) -> Result<()> {
    // The ping-pongs' iceoryx2 files live in a run of their own (the loop runs clean up after
    // themselves); whatever happens to the parts, they go at the end.
    let run_id = crate::launcher::new_run_id();
    let lock = crate::runtime::storage::run_storage::create_run_storage(&run_id)?;
    let result = run_parts(args, &run_id, catalog);
    let cleanup = crate::runtime::storage::run_storage::clean_up_run(&run_id);
    drop(lock);
    let leftover = cleanup?.leftover;
    if result.is_ok() && !leftover.is_empty() {
        return Err(anyhow!("files left in shared memory: {}", leftover.join(", ")));
    }
    result
}

/// Ends the bench when a stop request came (Ctrl-C, SIGTERM).
fn check(stop: &StopFlag) -> Result<()> {
    if stop.requested() { Err(Interrupted.into()) } else { Ok(()) }
}

fn run_parts(args: &BenchArgs, run_id: &str, catalog: &Catalog) -> Result<()> {
    let stop = StopFlag::install()?;
    if let Some(kills) = args.restarts {
        let out = crate::launcher::create_run_dir(args.out.as_deref(), "bench-restarts")?;
        return restarts::run(kills, &out, &crate::launcher::locate_binaries()?, catalog);
    }
    if let Some(spec) = &args.count {
        let out = args.out.as_deref().ok_or_else(|| anyhow!("--count needs --out"))?;
        return instructions::workload(spec, run_id, out, catalog);
    }
    if args.instructions {
        let out = crate::launcher::create_run_dir(args.out.as_deref(), "bench-instructions")?;
        instructions::run(&out)?;
        say!("  written: {}", out.display());
        return Ok(());
    }
    if let Some(targets) = &args.plants {
        let out = crate::launcher::create_run_dir(args.out.as_deref(), "bench-plants")?;
        plants::run(catalog, targets, args.quick, &out, &stop)?;
        say!("  written: {}", out.display());
        return Ok(());
    }
    let began = Instant::now();
    let quick = args.quick;
    let seconds = args.seconds.unwrap_or(if quick { 4.0 } else { 60.0 });
    let rounds = if quick { 1 } else { 6 };
    let segment = seconds / rounds as f64;
    let out = crate::launcher::create_run_dir(args.out.as_deref(), "bench")?;
    let exe = std::env::current_exe()?;
    let binaries = crate::launcher::locate_binaries()?;
    let setup = pingpong::Setup { exe: &exe, run_id, scratch: &out };
    let message_bytes = std::mem::size_of::<PlantState>();
    tell!("looplab bench: {rounds} round(s) of {segment} s per loop configuration; writing {}", out.display());

    let machine = machine(if quick { 500 } else { 3000 })?;
    let cpus = machine.cpus;
    let mut skipped = Vec::new();
    let floor_modes: Vec<Strategy> = MODES.into_iter().filter(|m| *m != Strategy::Spin || cpus >= 2).collect();
    if cpus < 2 {
        skipped.push("the raw floor and the spinning ping-pong: need 2 CPUs".to_owned());
    }
    // A controller of the user's own runs only where its stage can be prepared and resolved.
    let mut own: BTreeMap<&'static str, String> = BTreeMap::new();
    for c in LOOP_CONFIGS.iter() {
        let Some(language) = c.own else { continue };
        let resolved = language.command_override(&out).and_then(|set| {
            let overrides = [Override::parse(&set).map_err(|e| e.to_string())?];
            catalog.resolve("pendulum", &overrides).map_err(|e| format!("{e:#}"))?;
            Ok(set)
        });
        match resolved {
            Ok(set) => {
                own.insert(c.name, set);
            }
            Err(why) => skipped.push(format!("{}: {why}", c.name)),
        }
    }
    let loop_configs: Vec<&LoopConfig> = LOOP_CONFIGS
        .iter()
        .filter(|c| {
            let enough = cpus >= c.needs_cpus();
            if !enough {
                skipped.push(format!("{}: needs {} CPUs", c.name, c.needs_cpus()));
            }
            enough && (c.own.is_none() || own.contains_key(c.name))
        })
        .collect();
    let floor_rounds = if quick { 500 } else { 2000 };
    let mut raw_floor = Vec::new();
    let mut floor: BTreeMap<String, Vec<u64>> = BTreeMap::new();
    let mut ours: BTreeMap<&'static str, LoopAccumulator> = BTreeMap::new();
    let mut baseline = LoopAccumulator::default();
    // Each round, then the payload sweep, then the lockstep speed.
    let progress = crate::tools::sweep::progress_bar(rounds as u64 + 2, "parts");
    for round in 0..rounds {
        progress.suspend(|| tell!("  round {} of {rounds}", round + 1));
        if cpus >= 2 {
            raw_floor.extend(raw_floor::measure(&exe, run_id, 1_000_000, floor_rounds)?);
            check(&stop)?;
        }
        for &mode in &floor_modes {
            let series = pingpong::ping(&setup, Transport::Iox, mode, message_bytes, floor_rounds, 1_000_000)?;
            floor.entry(mode.name().into()).or_default().extend(series.one_way_ns);
            check(&stop)?;
        }
        for c in &loop_configs {
            let (summary, dir) = looplab_run(&out, c, own.get(c.name), segment, &binaries, catalog)?;
            ours.entry(c.name).or_default().add_run(&summary, &dir)?;
        }
        let loops = (segment * 1000.0).round() as u64;
        let result = uds_loop::run(&exe, &out.join("uds"), 1000.0, loops)?;
        check(&stop)?;
        baseline.traces.extend(result.traces);
        baseline.loops += result.loops;
        baseline.misses += result.deadline_misses;
        baseline.seconds += segment;
        for (role, cpu) in Role::ALL.into_iter().filter(|r| r.in_loop()).zip(result.cpu_s) {
            *baseline.cpu_s.entry(role).or_default() += cpu;
        }
        progress.inc(1);
    }

    let hop_anatomy = if cpus >= 2 {
        progress.suspend(|| tell!("  hop anatomy"));
        anatomy::measure(run_id, floor_rounds)?
    } else {
        skipped.push("the hop anatomy: needs 2 CPUs".to_owned());
        Vec::new()
    };
    check(&stop)?;
    progress.suspend(|| tell!("  payload sweep"));
    let sizes: Vec<usize> = (0..9).map(|i| 64usize << (2 * i)).collect();
    let samples = if quick { 40 } else { 300 };
    let mut payload = Vec::new();
    for &bytes in &sizes {
        let iox = pingpong::ping(&setup, Transport::Iox, Strategy::Block, bytes, samples, 0)?;
        let uds = pingpong::ping(&setup, Transport::Uds, Strategy::Block, bytes, samples, 0)?;
        check(&stop)?;
        payload.push(PayloadPoint {
            bytes,
            iceoryx2_us: Dist::of(&sorted(iox.one_way_ns)),
            unix_socket_us: Dist::of(&sorted(uds.one_way_ns)),
        });
    }

    progress.inc(1);
    progress.suspend(|| tell!("  lockstep speed"));
    let lockstep_seconds = if quick { 3.0 } else { 20.0 };
    let auto = WaitSettings::default().lockstep_on(cpus);
    let mut lockstep_by_method = BTreeMap::new();
    for method in [LockstepWait::Poll, LockstepWait::Handoff, LockstepWait::Block] {
        let name: &'static str = method.into();
        lockstep_by_method.insert(name.to_owned(), lockstep_run(&out, name, lockstep_seconds, &binaries, catalog)?);
    }
    let in_process = in_process_loops_per_s(if quick { 200_000 } else { 2_000_000 }, &stop, catalog)?;
    progress.finish_and_clear();

    let mut loops: Vec<LoopBench> =
        LOOP_CONFIGS.iter().filter_map(|c| ours.remove(c.name).map(|acc| acc.finish(c.name, c.rate_hz))).collect();
    let floor_raw_one_way_ns = (!raw_floor.is_empty()).then(|| Dist::scaled(&sorted(raw_floor), 1.0));
    // The least median compute of the 1 kHz configurations: the stages at their quickest.
    let compute = loops
        .iter()
        .filter(|l| l.rate_hz == 1000.0 && l.loops > 0)
        .map(|l| l.stage_compute_us.p50)
        .fold(f64::INFINITY, f64::min);
    let physical_limit_us =
        floor_raw_one_way_ns.as_ref().filter(|_| compute.is_finite()).map(|raw| 4.0 * raw.p50 / 1e3 + compute);
    loops.push(baseline.finish("unix socket + bincode (hand-written)", 1000.0));
    let report = BenchReport {
        started_at: chrono::Utc::now().to_rfc3339(),
        quick,
        rounds,
        machine,
        skipped,
        floor_raw_one_way_ns,
        physical_limit_us,
        floor_one_way_us: floor.iter().map(|(k, v)| (k.clone(), Dist::of(&sorted(v.clone())))).collect(),
        message_bytes,
        hop_anatomy,
        loops,
        payload,
        lockstep_loops_per_s: lockstep_by_method.get(<&str>::from(auto)).copied().unwrap_or(f64::NAN),
        lockstep_auto: <&str>::from(auto).to_owned(),
        lockstep_by_method,
        in_process_loops_per_s: in_process,
        wall_time_s: began.elapsed().as_secs_f64(),
    };
    crate::runtime::storage::run_file::write(
        &out.join("bench.json"),
        serde_json::to_string_pretty(&report)?.as_bytes(),
    )?;
    let mut curves: Vec<(String, Vec<u64>)> =
        report.loops.iter().filter(|l| l.rate_hz == 1000.0).map(|l| (l.name.clone(), l.e2e.clone())).collect();
    if let Some(spin) = floor.get("spin") {
        // Four one-way hops, as a loop of them would take at best.
        curves.push(("floor: 4 × spin hop (median)".into(), vec![4 * sorted(spin.clone())[spin.len() / 2]]));
    }
    // At 1 kHz the default deadline is one period.
    plot::cdf(&out.join("latency-cdf.png"), "end-to-end loop latency, 1 kHz", &curves, &[1_000_000])?;
    let floor_curves: Vec<(String, Vec<u64>)> =
        floor.into_iter().map(|(k, v)| (format!("iceoryx2 hop, {k}"), sorted(v))).collect();
    plot::cdf(&out.join("floor-cdf.png"), "one-way iceoryx2 hop, loop message size, 1 kHz", &floor_curves, &[])?;
    plot::payload(
        &out.join("payload.png"),
        &[
            ("iceoryx2 (zero copy)".into(), report.payload.iter().map(|p| (p.bytes, p.iceoryx2_us.p50)).collect()),
            ("unix socket + bincode".into(), report.payload.iter().map(|p| (p.bytes, p.unix_socket_us.p50)).collect()),
        ],
    )?;
    say_raw!("{}", render(&report));
    say!("  written: {}", out.display());
    Ok(())
}
