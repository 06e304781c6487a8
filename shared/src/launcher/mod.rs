//! `looplab`: resolves a launch file, starts the five loop processes, supervises them, stops
//! them in order, checks that nothing is left in shared memory, and reports.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Write};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{ChildStdin, ExitCode, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, anyhow, bail};
use clap::{Args, Parser, Subcommand};
use crossbeam_channel::{Receiver, RecvTimeoutError};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::clock::now_ns;
use crate::faults::{FaultKind, Policy, Restart};
use crate::ipc;
use crate::launch::{self, LaunchConfig, Mode, Override};
use crate::contract::report::MonitorReport;
use crate::protocol::{ChildEvent, MonitorStatus, PlantReport, StageReport};
use crate::report::{
    FaultReport, Jitter, Latency, MonitorCounts, ProcessInfo, SharedMemoryCheck, Summary, TimelineEntry,
};
use crate::model::scenario::Scenario;
use crate::scenarios;
use crate::signals::StopFlag;

/// The loop processes in start order: readers before writers, the plant last.
const START_ORDER: [&str; 5] = ["monitor", "controller", "estimator", "sensors", "plant"];
/// Stop order: the plant first (no new loops), the monitor last (it drains everything).
const STOP_ORDER: [&str; 5] = ["plant", "sensors", "estimator", "controller", "monitor"];
/// Longest start-up: every process must report ready within it.
const READY_TIMEOUT: Duration = Duration::from_secs(20);
/// Longest a stage may take to exit after SIGTERM before it is killed.
const STOP_TIMEOUT: Duration = Duration::from_secs(5);
/// The monitor writes its files on exit, so it gets longer.
const MONITOR_STOP_TIMEOUT: Duration = Duration::from_secs(60);
const EXIT_BAD_INPUT: u8 = 2;
pub(crate) const EXIT_INTERRUPTED: u8 = 130;

#[derive(Debug, Parser)]
#[command(
    name = "looplab",
    version,
    about = "Run a closed control loop as separate processes over iceoryx2 shared memory, and measure it",
    long_about = "Run a closed control loop as separate processes over iceoryx2 shared memory, and measure it.\n\n\
The plant, sensors, estimator, controller and a monitor each run as their own process. LoopLab \
reports the latency of every hop and end to end, the plant's tick jitter, deadline misses, sensor \
data age and the scenario's control metrics, and writes a run folder with summary.json, \
trajectory.csv, loops.csv, latency.hlog and the resolved launch file.\n\n\
With no command, runs the default: the pendulum scenario, real time, 1 kHz, 10 s.",
    after_help = "Examples:\n  looplab\n  looplab list\n  looplab show pendulum\n  looplab run pendulum --mode lockstep --duration 30 \
--set sensors.encoder.bias=0.05 --set estimator.kind=no-bias\n  looplab run my-launch.toml --out /tmp/run1"
)]
pub struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run a scenario or a launch file and report latency, jitter and control metrics
    Run(RunArgs),
    /// List the built-in scenarios and their launch files
    List,
    /// Print a scenario's launch file: every key, its default and what it means
    Show {
        /// The scenario (see `looplab list`)
        scenario: String,
    },
    /// Run a scenario repeatedly in lockstep while one key varies; report the metrics per value
    /// and, for a controller delay, the measured delay margin against theory
    Sweep(SweepCli),
    /// Remove what runs killed with SIGKILL left in shared memory (their launcher is gone): kill
    /// their orphaned processes, remove their files. `looplab run` does this too before it starts.
    Clean,
    /// Measure LoopLab's own latency against the transport's floor and a hand-written Unix-socket
    /// loop, per wait strategy, plus zero copy, the monitor's cost and lockstep speed; writes
    /// bench.json and SVG charts
    Bench(crate::bench::BenchArgs),
    /// (internal) the far end of the bench's ping-pong
    #[command(hide = true)]
    BenchEcho(crate::bench::pingpong::EchoArgs),
    /// (internal) one stage of the bench's Unix-socket baseline loop
    #[command(hide = true)]
    BenchUdsStage(crate::bench::uds_loop::StageArgs),
}

#[derive(Debug, Args)]
#[command(after_help = "Example: the pendulum's delay margin, measured against its linearised model:\n  \
looplab sweep pendulum --set sensors.encoder.quantum=0 --set sensors.wheel_speed.noise_std=0 \
--fault \"delay controller by 0 ticks at 2s\" --param faults.0.delay_ticks --from 25 --to 35 --duration 20\n\
A value is unstable when the swept fault's error (see `looplab show`, [limits]) passes the limit, or its peak in \
the run's last second is larger than in the fault's first second: the disturbance grew instead of dying out. \
Turn sensor noise and quantisation off to judge linear stability near the margin, as the theory does. \
Writes sweep.json and one run folder per value.")]
struct SweepCli {
    /// A scenario name or a launch file
    #[arg(default_value = "pendulum")]
    target: String,
    /// The dotted key to vary, as for --set; a number indexes a list (faults.0.delay_ticks)
    #[arg(long, value_name = "KEY")]
    param: String,
    #[arg(long)]
    from: f64,
    #[arg(long)]
    to: f64,
    #[arg(long, default_value_t = 1.0)]
    step: f64,
    #[command(flatten)]
    launch: LaunchArgs,
    /// Folder for sweep.json and the runs (default: runs/<time>-sweep-<scenario>)
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Runs at a time
    #[arg(long, default_value_t = 2)]
    jobs: usize,
}

/// The options `run` and `sweep` share: each becomes a launch-file override.
#[derive(Debug, Default, Args)]
struct LaunchArgs {
    /// Simulated duration in seconds (same as --set duration_s=S)
    #[arg(long, value_name = "SECONDS")]
    duration: Option<f64>,
    /// Loop rate in Hz (same as --set rate_hz=HZ)
    #[arg(long, value_name = "HZ")]
    rate: Option<f64>,
    /// Noise seed (same as --set seed=N)
    #[arg(long)]
    seed: Option<u64>,
    /// Override any key of the launch file by its dotted path, for example
    /// --set sensors.encoder.bias=0.05 or --set estimator.kind=no-bias. Repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Inject a fault, added to the launch file's [[faults]]: KIND PROCESS [by AMOUNT]
    /// [P%] [nan|inf|out-of-range] [at TIME] [for DURATION]. Kinds: kill, stop (SIGSTOP, then
    /// SIGCONT), delay, drop, corrupt. Examples: "kill estimator at 3s", "stop controller at 2s
    /// for 200ms", "delay controller by 3 ticks at 2s", "drop sensors 20% at 1s for 2s",
    /// "corrupt controller nan at 4s for 100ms". Repeatable.
    #[arg(long = "fault", value_name = "FAULT")]
    fault: Vec<String>,
}

#[derive(Debug, Args)]
#[command(
    after_help = "Keys: `looplab show <scenario>` prints the scenario's launch file, every key with its default \
and meaning; --set takes any of them.\n\
Run folder: summary.json, trajectory.csv, loops.csv, latency.hlog, launch.toml (resolved), logs/.\n\
Exit codes: 0 completed, 1 the run failed (a process died, or files were left in shared memory), \
2 bad input, 130 interrupted (Ctrl-C or SIGTERM; the report is still written)."
)]
struct RunArgs {
    /// A scenario name (see `looplab list`) or the path of a launch file (.toml). A launch file
    /// overrides its scenario's defaults key by key.
    #[arg(default_value = "pendulum")]
    target: String,
    /// realtime: the plant ticks on a timer and counts deadline misses; lockstep: the plant
    /// waits for each command, deterministic and as fast as the loop allows
    #[arg(long, value_parser = ["realtime", "lockstep"])]
    mode: Option<String>,
    #[command(flatten)]
    launch: LaunchArgs,
    /// The run folder to write (default: runs/<time>-<scenario>); created if missing, must be
    /// empty if it exists
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// No live status line
    #[arg(long, short)]
    quiet: bool,
}

impl Default for RunArgs {
    fn default() -> Self {
        Self { target: "pendulum".into(), mode: None, launch: LaunchArgs::default(), out: None, quiet: false }
    }
}

pub fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Some(Command::List) => {
            list();
            ExitCode::SUCCESS
        }
        Some(Command::Show { scenario }) => match scenarios::builtin(&scenario) {
            Some(entry) => {
                print!("{}", entry.text);
                ExitCode::SUCCESS
            }
            None => bad_input(format!("unknown scenario \"{scenario}\"; allowed: {}", scenarios::scenario_names())),
        },
        Some(Command::Run(args)) => run(args),
        Some(Command::Clean) => clean(),
        Some(Command::Sweep(args)) => sweep(args),
        Some(Command::Bench(args)) => report_failure(crate::bench::run(&args)),
        Some(Command::BenchEcho(args)) => report_failure(crate::bench::pingpong::echo_main(&args)),
        Some(Command::BenchUdsStage(args)) => report_failure(crate::bench::uds_loop::stage_main(&args)),
        None => run(RunArgs::default()),
    }
}

/// Tells what the clean-up of runs whose launcher was killed found.
fn report_abandoned(done: &ipc::Abandoned) {
    if !done.runs.is_empty() {
        eprintln!(
            "looplab: removed the shared-memory files of {} run(s) whose launcher was killed ({}){}",
            done.runs.len(),
            done.runs.join(", "),
            if done.killed > 0 { format!("; killed {} orphaned process(es)", done.killed) } else { String::new() }
        );
    }
    for path in &done.leftover {
        eprintln!("looplab: could not remove {path}");
    }
}

fn clean() -> ExitCode {
    let done = ipc::clean_abandoned_runs();
    report_abandoned(&done);
    if done.runs.is_empty() {
        println!("nothing to clean: no abandoned run of this user in {}", ipc::SHM_DIR);
    }
    if done.leftover.is_empty() { ExitCode::SUCCESS } else { ExitCode::FAILURE }
}

fn report_failure(result: Result<()>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if e.is::<crate::signals::Interrupted>() => {
            eprintln!("looplab: interrupted; stopped in order, nothing left behind");
            ExitCode::from(EXIT_INTERRUPTED)
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn list() {
    println!("Scenarios (looplab run <name>; defaults in the launch file named):");
    for s in scenarios::ALL {
        println!("  {:<12} {}  [{}]", s.name, s.description, s.file);
    }
}

fn bad_input(message: impl std::fmt::Display) -> ExitCode {
    eprintln!("error: {message}");
    ExitCode::from(EXIT_BAD_INPUT)
}

fn sweep(args: SweepCli) -> ExitCode {
    let overrides = match overrides(None, &args.launch) {
        Ok(o) => o,
        Err(e) => return bad_input(e),
    };
    crate::sweep::run(crate::sweep::SweepArgs {
        target: args.target,
        param: args.param,
        from: args.from,
        to: args.to,
        step: args.step,
        overrides,
        out: args.out,
        jobs: args.jobs,
    })
}

/// The launch-file overrides the command line gives, in the order they apply: the options,
/// then each --set, then each --fault.
fn overrides(mode: Option<&str>, launch: &LaunchArgs) -> Result<Vec<Override>, launch::LaunchError> {
    let mut texts: Vec<String> = Vec::new();
    if let Some(mode) = mode {
        texts.push(format!("mode={mode}"));
    }
    if let Some(d) = launch.duration {
        texts.push(format!("duration_s={d:?}"));
    }
    if let Some(r) = launch.rate {
        texts.push(format!("rate_hz={r:?}"));
    }
    if let Some(s) = launch.seed {
        texts.push(format!("seed={s}"));
    }
    texts.extend(launch.set.iter().cloned());
    texts.iter().map(|t| Override::parse(t)).chain(launch.fault.iter().map(|f| Override::fault(f))).collect()
}

fn run(args: RunArgs) -> ExitCode {
    let overrides = overrides(args.mode.as_deref(), &args.launch);
    let resolved = overrides.and_then(|o| scenarios::resolve(&args.target, &o));
    let (config, scenario) = match resolved {
        Ok(r) => r,
        Err(e) => return bad_input(e),
    };
    let binaries = match locate_binaries() {
        Ok(b) => b,
        Err(e) => return bad_input(format!("{e:#}")),
    };
    let run_dir = match create_run_dir(args.out.as_deref(), &config.scenario) {
        Ok(d) => d,
        Err(e) => return bad_input(format!("{e:#}")),
    };
    report_abandoned(&ipc::clean_abandoned_runs());
    match Supervisor::run(&config, scenario.as_ref(), &binaries, &run_dir, args.quiet) {
        Ok((summary, outcome)) => {
            print!("{}", report::render(&summary));
            match outcome {
                Outcome::Completed if !summary.completed => {
                    let why = summary.stopped_because.as_deref().unwrap_or("it ran fewer loops than planned");
                    eprintln!("error: the run did not complete: {why} ({} of {} loops)", summary.loops, summary.loops_planned);
                    ExitCode::FAILURE
                }
                Outcome::Completed if summary.shared_memory.clean => ExitCode::SUCCESS,
                Outcome::Completed => {
                    eprintln!(
                        "error: files of the run were left behind: {}",
                        summary.shared_memory.leftover.join(", ")
                    );
                    ExitCode::FAILURE
                }
                Outcome::Interrupted => ExitCode::from(EXIT_INTERRUPTED),
                Outcome::Failed(why) => {
                    eprintln!("error: {why}");
                    ExitCode::FAILURE
                }
            }
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// The five loop binaries, next to this one.
pub(crate) fn locate_binaries() -> Result<BTreeMap<&'static str, PathBuf>> {
    let exe = std::env::current_exe().context("cannot find the looplab executable")?;
    let dir = exe.parent().ok_or_else(|| anyhow!("{} has no parent folder", exe.display()))?;
    build_siblings_under_cargo(dir)?;
    let mut found = BTreeMap::new();
    for name in START_ORDER {
        let path = dir.join(name);
        if !path.is_file() {
            bail!(
                "missing binary {}: the loop processes are built with the launcher; run `cargo build --release` \
                 (or start with `cargo run --release`)",
                path.display()
            );
        }
        found.insert(name, path);
    }
    Ok(found)
}

/// `cargo run` builds only the binary it runs. When we were started by it, ask the same cargo
/// to build the loop binaries too, with the same profile and target folder, so that they are
/// never missing or stale.
fn build_siblings_under_cargo(exe_dir: &Path) -> Result<()> {
    let (Ok(cargo), Ok(manifest_dir)) = (std::env::var("CARGO"), std::env::var("CARGO_MANIFEST_DIR")) else {
        return Ok(());
    };
    let profile_dir = exe_dir.file_name().and_then(|n| n.to_str()).unwrap_or("debug");
    let profile = if profile_dir == "debug" { "dev" } else { profile_dir };
    let target_dir = exe_dir.parent().unwrap_or(exe_dir);
    let status = std::process::Command::new(cargo)
        .args(["build", "--quiet", "--bins", "--profile", profile, "--manifest-path"])
        .arg(Path::new(&manifest_dir).join("Cargo.toml"))
        .arg("--target-dir")
        .arg(target_dir)
        .status()
        .context("cannot run cargo to build the loop processes")?;
    if !status.success() {
        bail!("building the loop processes failed ({status})");
    }
    Ok(())
}

pub(crate) fn create_run_dir(out: Option<&Path>, scenario: &str) -> Result<PathBuf> {
    let dir = match out {
        Some(dir) => {
            if dir.exists() && !dir.is_dir() {
                bail!("--out {}: is a file, not a folder; give a new or empty folder", dir.display());
            }
            if dir.exists() && std::fs::read_dir(dir).map(|mut d| d.next().is_some()).unwrap_or(true) {
                bail!("--out {}: the folder exists and is not empty; give a new or empty folder", dir.display());
            }
            dir.to_path_buf()
        }
        None => {
            let stamp = chrono::Local::now().format("%Y%m%d-%H%M%S");
            let base = PathBuf::from("runs").join(format!("{stamp}-{scenario}"));
            std::fs::create_dir_all("runs").context("cannot create the runs folder")?;
            // Claim a new folder atomically: two runs started in the same second get two.
            let mut n = 1;
            loop {
                let dir = if n == 1 { base.clone() } else { PathBuf::from(format!("{}-{n}", base.display())) };
                match std::fs::create_dir(&dir) {
                    Ok(()) => break dir,
                    Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => n += 1,
                    Err(e) => return Err(e).with_context(|| format!("cannot create the run folder {}", dir.display())),
                }
            }
        }
    };
    std::fs::create_dir_all(dir.join("logs"))
        .with_context(|| format!("cannot create the run folder {}", dir.display()))?;
    Ok(dir)
}

/// Makes `command` a child that this process stops: in its own process group, so that a Ctrl-C
/// in the terminal reaches only us and we stop the children in order; and asked to stop
/// (SIGTERM) if we die, so that nothing is orphaned.
pub(crate) fn supervised(command: &mut std::process::Command) {
    command.process_group(0);
    let parent = std::process::id() as libc::pid_t;
    // SAFETY: prctl and getppid are async-signal-safe. If the parent died before prctl took
    // effect, the child does not start at all.
    unsafe {
        command.pre_exec(move || {
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
            if libc::getppid() != parent {
                return Err(std::io::Error::other("the parent is gone"));
            }
            Ok(())
        });
    }
}

/// A new run id: 64 random bits from the kernel, so that no one can guess the names of a run's
/// files before it creates them.
pub(crate) fn new_run_id() -> String {
    let mut bytes = [0u8; 8];
    // SAFETY: getrandom writes at most `bytes.len()` bytes into the buffer.
    let n = unsafe { libc::getrandom(bytes.as_mut_ptr().cast(), bytes.len(), 0) };
    assert_eq!(n, bytes.len() as isize, "the kernel's random source failed");
    format!("{:016x}", u64::from_ne_bytes(bytes))
}

/// Writes a file whole or not at all: a failed write (a full disk) leaves no truncated file
/// behind that a script could take for the real one, and says which file it was.
pub(crate) fn write_atomically(path: &Path, contents: &str) -> Result<()> {
    let partial = path.with_extension("partial");
    let written = std::fs::write(&partial, contents).and_then(|()| std::fs::rename(&partial, path));
    if let Err(e) = written {
        let _ = std::fs::remove_file(&partial);
        bail!("cannot write {}: {e}", path.display());
    }
    Ok(())
}

/// Runs one launch configuration to its end in `run_dir` (which must exist, with `logs/`).
pub(crate) fn run_once(
    config: &LaunchConfig,
    scenario: &dyn Scenario,
    binaries: &BTreeMap<&'static str, PathBuf>,
    run_dir: &Path,
    quiet: bool,
) -> Result<(Summary, Outcome)> {
    Supervisor::run(config, scenario, binaries, run_dir, quiet)
}

pub enum Outcome {
    Completed,
    Interrupted,
    Failed(String),
}

/// One start of a process.
struct Incarnation {
    pid: u32,
    exit: Option<(String, bool)>,
    cpu_s: f64,
}

/// A process of the loop across its restarts.
struct Process {
    name: &'static str,
    policy: Policy,
    /// The running incarnation's number (index into `runs`).
    incarnation: usize,
    runs: Vec<Incarnation>,
    stdin: Option<ChildStdin>,
    /// Its ports are up (cleared when it dies or is killed).
    ready: bool,
    /// When its running incarnation became ready.
    ready_since: Option<Instant>,
    /// Set while it waits for its clean-up and backoff before a restart.
    restart: Option<PendingRestart>,
    /// Restarts since it last ran healthy (`backoff_reset_s`): the backoff doubles with each.
    quick_restarts: u32,
    /// SIGSTOPped by a fault and not continued yet.
    stopped: bool,
    /// It died and will not be restarted (the monitor may; the others end the run).
    gone: bool,
}

impl Process {
    fn current(&mut self) -> &mut Incarnation {
        &mut self.runs[self.incarnation]
    }

    fn running(&self) -> bool {
        self.runs.get(self.incarnation).is_some_and(|r| r.exit.is_none())
    }

    /// Reaps the running incarnation if it has exited (without blocking), with its CPU time.
    fn try_reap(&mut self) -> bool {
        let Some(run) = self.runs.get_mut(self.incarnation) else { return true };
        if run.exit.is_some() {
            return true;
        }
        let mut status = 0;
        // SAFETY: plain wait4 on our own child; rusage is a valid out-parameter.
        let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
        let pid = unsafe { libc::wait4(run.pid as i32, &mut status, libc::WNOHANG, &mut usage) };
        if pid != run.pid as i32 {
            return false;
        }
        run.cpu_s = crate::clock::cpu_seconds(&usage);
        run.exit = Some(if libc::WIFEXITED(status) {
            (libc::WEXITSTATUS(status).to_string(), libc::WEXITSTATUS(status) == 0)
        } else {
            (format!("signal {}", libc::WTERMSIG(status)), false)
        });
        true
    }

    fn signal(&self, signal: i32) {
        if let Some(run) = self.runs.get(self.incarnation)
            && run.exit.is_none()
        {
            // SAFETY: the pid is our unreaped child, so it cannot have been reused.
            unsafe { libc::kill(run.pid as i32, signal) };
        }
    }

    fn exit_text(&self) -> String {
        match self.runs.get(self.incarnation).and_then(|r| r.exit.as_ref()) {
            Some((status, _)) => format!("{} exited with status {status}", self.name),
            None => format!("{} closed its output", self.name),
        }
    }

    fn write_line(&mut self, line: &str) -> bool {
        let written = self.stdin.as_mut().map(|s| s.write_all(format!("{line}\n").as_bytes()).and_then(|_| s.flush()));
        matches!(written, Some(Ok(())))
    }
}

/// What reaches the supervision loop.
enum Event {
    /// A child's event (None: its output ended, it is exiting).
    Child { index: usize, incarnation: usize, event: Option<ChildEvent> },
    /// A line on a child's stdout that is not an event.
    Unreadable { index: usize, line: String, error: String },
    /// The clean-up after a death of process `index` is done.
    Cleaned { index: usize, removed: u64 },
}

#[derive(Default)]
struct Reports {
    plant: Option<PlantReport>,
    monitor: Option<MonitorReport>,
    /// Per stage, the reports of every incarnation that ended cleanly.
    stages: BTreeMap<&'static str, Vec<StageReport>>,
}

/// A restart under way: it starts once the dead process's resources are removed and the backoff
/// has passed.
struct PendingRestart {
    not_before: Instant,
    cleaned: bool,
}

/// The steps of one restart (CLOCK_MONOTONIC, ns), for the report.
struct RestartRecord {
    process: &'static str,
    incarnation: usize,
    backoff: Duration,
    died_ns: u64,
    cleaned_ns: Option<u64>,
    spawned_ns: Option<u64>,
    ready_ns: Option<u64>,
}

/// What the launcher saw of one injected fault (CLOCK_MONOTONIC, ns).
#[derive(Default, Clone)]
struct FaultSeen {
    injected_ns: Option<u64>,
    detected_ns: Option<u64>,
    detected_by: Option<&'static str>,
    restarted_ns: Option<u64>,
    continued_ns: Option<u64>,
    resumed_ns: Option<u64>,
    /// A stop: when to send SIGCONT.
    continue_at: Option<Instant>,
}

/// How long the monitor may stay silent (it reports ten times a second) before it counts as
/// stalled.
const MONITOR_SILENCE: Duration = Duration::from_millis(300);
/// Longest wait between two looks at the fault schedule.
const SUPERVISE_TICK: Duration = Duration::from_millis(2);
/// Restart backoff doubles up to this.
const MAX_BACKOFF: Duration = Duration::from_secs(1);

struct Supervisor<'a> {
    config: &'a LaunchConfig,
    binaries: &'a BTreeMap<&'static str, PathBuf>,
    launch_file: PathBuf,
    run_id: String,
    run_dir: PathBuf,
    processes: Vec<Process>,
    tx: crossbeam_channel::Sender<Event>,
    events: Receiver<Event>,
    readers: Vec<std::thread::JoinHandle<()>>,
    reports: Reports,
    progress: ProgressBar,
    /// The plant's schedule once it started: tick 0 at this CLOCK_MONOTONIC time.
    plant_start_ns: Option<u64>,
    faults: Vec<FaultSeen>,
    timeline: Vec<TimelineEntry>,
    /// Lockstep: the plant is paused and waits for `go`.
    paused: bool,
    last_status: Instant,
    removed_dead_nodes: u64,
    /// Run stopping: deaths are expected, nothing is restarted.
    stopping: bool,
    stop: StopFlag,
    /// Clean-up requests (a process index) for the clean-up thread: iceoryx2's clean-up of a dead
    /// process's resources can wait on the file system, and nothing of the supervision may.
    cleaner: Option<crossbeam_channel::Sender<usize>>,
    restarts: Vec<RestartRecord>,
}

impl<'a> Supervisor<'a> {
    fn run(
        config: &'a LaunchConfig,
        scenario: &dyn Scenario,
        binaries: &'a BTreeMap<&'static str, PathBuf>,
        run_dir: &Path,
        quiet: bool,
    ) -> Result<(Summary, Outcome)> {
        let launch_file = run_dir.join("launch.toml");
        write_atomically(&launch_file, &config.to_toml())?;
        let stop = StopFlag::install()?;
        let started_at = chrono::Utc::now().to_rfc3339_opts(chrono::SecondsFormat::Secs, true);

        let progress = if quiet {
            ProgressBar::hidden()
        } else {
            ProgressBar::with_draw_target(Some(config.loops()), ProgressDrawTarget::stderr())
        };
        progress.set_style(
            ProgressStyle::with_template("{spinner} {bar:16} {pos}/{len} loops · {msg}").expect("valid template"),
        );
        let (tx, events) = crossbeam_channel::unbounded();
        let processes = START_ORDER
            .iter()
            .map(|&name| Process {
                name,
                policy: config.supervision.policy(name),
                incarnation: 0,
                runs: vec![],
                stdin: None,
                ready: false,
                ready_since: None,
                restart: None,
                quick_restarts: 0,
                stopped: false,
                gone: false,
            })
            .collect();
        let run_id = new_run_id();
        // The run's private folder; the lock in it says the run is alive until we return.
        let storage_lock = ipc::create_run_storage(&run_id)?;
        let (cleaner, clean_requests) = crossbeam_channel::unbounded::<usize>();
        let cleaned = tx.clone();
        let clean_run_id = run_id.clone();
        let clean_thread = std::thread::spawn(move || {
            for index in clean_requests {
                let removed = ipc::remove_dead_nodes(&clean_run_id).unwrap_or(0);
                if cleaned.send(Event::Cleaned { index, removed }).is_err() {
                    break;
                }
            }
        });
        let mut supervisor = Supervisor {
            config,
            binaries,
            launch_file,
            run_id,
            run_dir: run_dir.to_path_buf(),
            processes,
            tx,
            events,
            readers: vec![],
            reports: Reports::default(),
            progress,
            plant_start_ns: None,
            faults: vec![FaultSeen::default(); config.faults.len()],
            timeline: vec![],
            paused: false,
            last_status: Instant::now(),
            removed_dead_nodes: 0,
            stopping: false,
            stop,
            cleaner: Some(cleaner),
            restarts: vec![],
        };
        let spawned: Result<()> = (0..supervisor.processes.len()).try_for_each(|i| supervisor.spawn(i));
        let outcome = match spawned {
            Ok(()) => supervisor.supervise(),
            Err(e) => Outcome::Failed(format!("{e:#}")),
        };
        supervisor.stop_all();
        supervisor.progress.finish_and_clear();
        let outcome = match outcome {
            Outcome::Completed => supervisor.check_ends(),
            other => other,
        };
        let (tx, _) = crossbeam_channel::unbounded();
        drop(std::mem::replace(&mut supervisor.tx, tx));
        for reader in supervisor.readers.drain(..) {
            let _ = reader.join();
        }
        supervisor.cleaner = None;
        let _ = clean_thread.join();
        let cleanup = ipc::clean_up_run(&supervisor.run_id)?;
        drop(storage_lock);
        let summary = supervisor.summary(scenario, started_at, &outcome, cleanup);
        write_atomically(&run_dir.join("summary.json"), &(serde_json::to_string_pretty(&summary)? + "\n"))?;
        Ok((summary, outcome))
    }

    /// Starts the next incarnation of process `index`.
    fn spawn(&mut self, index: usize) -> Result<()> {
        let name = self.processes[index].name;
        let incarnation = self.processes[index].runs.len();
        let log_path = self.run_dir.join("logs").join(format!("{name}.log"));
        // A restarted process appends to its log.
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&log_path)
            .with_context(|| format!("create {}", log_path.display()))?;
        let mut command = std::process::Command::new(&self.binaries[name]);
        command
            .arg("--launch")
            .arg(&self.launch_file)
            .arg("--run-id")
            .arg(&self.run_id)
            .arg("--run-dir")
            .arg(&self.run_dir)
            .arg("--incarnation")
            .arg(incarnation.to_string())
            .stdin(if name == "plant" { Stdio::piped() } else { Stdio::null() })
            .stdout(Stdio::piped())
            .stderr(log);
        supervised(&mut command);
        let mut child = command.spawn().with_context(|| format!("cannot start {}", self.binaries[name].display()))?;
        let stdout = child.stdout.take().expect("stdout is piped");
        let tx = self.tx.clone();
        self.readers.push(std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                let _ = tx.send(match serde_json::from_str::<ChildEvent>(&line) {
                    Ok(event) => Event::Child { index, incarnation, event: Some(event) },
                    Err(e) => Event::Unreadable { index, line, error: e.to_string() },
                });
            }
            let _ = tx.send(Event::Child { index, incarnation, event: None });
        }));
        let process = &mut self.processes[index];
        process.runs.push(Incarnation { pid: child.id(), exit: None, cpu_s: 0.0 });
        process.incarnation = incarnation;
        process.stdin = child.stdin.take();
        process.ready = false;
        process.ready_since = None;
        process.restart = None;
        Ok(())
    }

    fn index_of(&self, name: &str) -> usize {
        self.processes.iter().position(|p| p.name == name).expect("every process is known")
    }

    /// Milliseconds since tick 0, for the timeline.
    fn since_start_ms(&self, ns: u64) -> f64 {
        self.plant_start_ns.map_or(0.0, |start| (ns as f64 - start as f64) / 1e6)
    }

    fn note(&mut self, ns: u64, event: String) {
        self.timeline.push(TimelineEntry { at_ms: self.since_start_ms(ns), event });
    }

    fn supervise(&mut self) -> Outcome {
        let stop = self.stop.clone();
        // Start-up: every process, the monitor included, has its ports before the first sample.
        let deadline = Instant::now() + READY_TIMEOUT;
        while !self.processes.iter().all(|p| p.ready) {
            if stop.requested() {
                return Outcome::Interrupted;
            }
            match self.events.recv_timeout(Duration::from_millis(50)) {
                Ok(event) => {
                    if let Some(index) = self.handle(event) {
                        return Outcome::Failed(format!(
                            "{} during start-up; see logs/{}.log",
                            self.processes[index].exit_text(),
                            self.processes[index].name
                        ));
                    }
                }
                Err(RecvTimeoutError::Timeout) if Instant::now() > deadline => {
                    let late: Vec<_> = self.processes.iter().filter(|p| !p.ready).map(|p| p.name).collect();
                    return Outcome::Failed(format!(
                        "not ready after {} s: {}",
                        READY_TIMEOUT.as_secs(),
                        late.join(", ")
                    ));
                }
                Err(_) => {}
            }
        }
        let plant = self.index_of("plant");
        if !self.processes[plant].write_line("start") {
            return Outcome::Failed("cannot tell the plant to start".into());
        }
        self.last_status = Instant::now();

        loop {
            if stop.requested() {
                return Outcome::Interrupted;
            }
            if let Some(outcome) = self.due_actions() {
                return outcome;
            }
            if let Some(outcome) = self.release_pause() {
                return outcome;
            }
            match self.events.recv_timeout(SUPERVISE_TICK) {
                Ok(event) => {
                    if let Some(index) = self.handle(event)
                        && let Some(outcome) = self.ended(index)
                    {
                        return outcome;
                    }
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return Outcome::Failed("lost every process's output".into()),
            }
        }
    }

    /// Injects the faults that are due (real time), continues stopped processes, restarts the
    /// dead ones whose clean-up and backoff are over, and watches the monitor's heartbeat. Returns
    /// the outcome if a restart failed and the run cannot go on.
    fn due_actions(&mut self) -> Option<Outcome> {
        let now = Instant::now();
        if self.config.mode == Mode::Realtime
            && let Some(start) = self.plant_start_ns
        {
            for i in 0..self.config.faults.len() {
                let fault = &self.config.faults[i];
                let due = start + (fault.at_s * 1e9) as u64;
                if fault.kind.from_outside() && self.faults[i].injected_ns.is_none() && now_ns() >= due {
                    self.inject(i);
                }
            }
        }
        for i in 0..self.faults.len() {
            if self.faults[i].continue_at.is_some_and(|at| now >= at) {
                self.faults[i].continue_at = None;
                let index = self.index_of(&self.config.faults[i].process);
                self.processes[index].signal(libc::SIGCONT);
                self.processes[index].stopped = false;
                let ns = now_ns();
                self.faults[i].continued_ns = Some(ns);
                self.note(ns, format!("SIGCONT {}", self.processes[index].name));
            }
        }
        for index in 0..self.processes.len() {
            if !self.processes[index].restart.as_ref().is_some_and(|r| r.cleaned && now >= r.not_before) {
                continue;
            }
            let name = self.processes[index].name;
            match self.spawn(index) {
                Ok(()) => {
                    let ns = now_ns();
                    let n = self.processes[index].incarnation;
                    if let Some(r) = self.latest_restart(name) {
                        r.spawned_ns = Some(ns);
                    }
                    self.note(ns, format!("{name} restarted (incarnation {n})"));
                }
                Err(e) => {
                    self.processes[index].restart = None;
                    self.processes[index].gone = true;
                    let why = format!("{name} could not be restarted: {e:#}");
                    self.note(now_ns(), why.clone());
                    if name != "monitor" {
                        return Some(Outcome::Failed(why));
                    }
                }
            }
        }
        let monitor = self.index_of("monitor");
        let silent = self.last_status.elapsed() > MONITOR_SILENCE;
        if silent && self.processes[monitor].ready && self.processes[monitor].stopped {
            // Only a stop fault on the monitor makes it silent while alive; note the detection.
            for i in self.fault_indices("monitor", FaultKind::Stop) {
                if self.faults[i].detected_ns.is_none() && self.faults[i].continued_ns.is_none() {
                    let ns = now_ns();
                    self.faults[i].detected_ns = Some(ns);
                    self.faults[i].detected_by = Some("the monitor's heartbeat stopped");
                    self.note(ns, "monitor silent: stalled".into());
                }
            }
        }
        None
    }

    /// The faults on `process` of `kind` that were injected, newest first.
    fn fault_indices(&self, process: &str, kind: FaultKind) -> Vec<usize> {
        let mut found: Vec<usize> = (0..self.faults.len())
            .filter(|&i| {
                let f = &self.config.faults[i];
                f.process == process && f.kind == kind && self.faults[i].injected_ns.is_some()
            })
            .collect();
        found.sort_by_key(|&i| std::cmp::Reverse(self.faults[i].injected_ns));
        found
    }

    fn inject(&mut self, i: usize) {
        let fault = self.config.faults[i].clone();
        let index = self.index_of(&fault.process);
        let ns = now_ns();
        self.faults[i].injected_ns = Some(ns);
        if !self.processes[index].running() {
            self.note(ns, format!("{}: not injected, {} is not running", fault.describe(), fault.process));
            return;
        }
        match fault.kind {
            FaultKind::Kill => {
                self.processes[index].signal(libc::SIGKILL);
                self.processes[index].ready = false;
            }
            FaultKind::Stop => {
                self.processes[index].signal(libc::SIGSTOP);
                self.processes[index].stopped = true;
                self.faults[i].continue_at =
                    Some(Instant::now() + Duration::from_secs_f64(fault.duration_s.unwrap_or_default()));
            }
            _ => {}
        }
        self.note(ns, format!("inject: {}", fault.describe()));
    }

    /// Lockstep: once the faults due at the paused tick are in and every process is back up,
    /// lets the plant go on.
    fn release_pause(&mut self) -> Option<Outcome> {
        if !self.paused || !self.processes.iter().all(|p| p.ready || p.gone) {
            return None;
        }
        self.paused = false;
        let plant = self.index_of("plant");
        if !self.processes[plant].write_line("go") {
            return Some(Outcome::Failed("cannot tell the plant to go on".into()));
        }
        None
    }

    /// Files an event; returns the index of a process whose output ended.
    fn handle(&mut self, event: Event) -> Option<usize> {
        let (index, incarnation, event) = match event {
            Event::Child { index, incarnation, event } => (index, incarnation, event),
            Event::Unreadable { index, line, error } => {
                let name = self.processes[index].name;
                eprintln!("looplab: {name} wrote a line that is not an event ({error}): {line}");
                self.note(now_ns(), format!("{name} wrote a line that is not an event ({error})"));
                return None;
            }
            Event::Cleaned { index, removed } => {
                self.cleaned(index, removed);
                return None;
            }
        };
        let name = self.processes[index].name;
        if incarnation != self.processes[index].incarnation {
            // A report from an incarnation that has since been replaced.
            if let Some(ChildEvent::StageReport(r)) = event {
                self.reports.stages.entry(name).or_default().push(r);
            }
            return None;
        }
        match event {
            None => {
                // Its output ends when it exits: reap it (it may take a moment to go).
                let until = Instant::now() + Duration::from_secs(2);
                while !self.processes[index].try_reap() && Instant::now() < until {
                    std::thread::sleep(Duration::from_millis(1));
                }
                return Some(index);
            }
            Some(ChildEvent::Ready) => {
                self.processes[index].ready = true;
                self.processes[index].ready_since = Some(Instant::now());
                if incarnation > 0 {
                    let ns = now_ns();
                    if let Some(r) = self.latest_restart(name) {
                        r.ready_ns.get_or_insert(ns);
                    }
                    for i in self.fault_indices(name, FaultKind::Kill) {
                        if self.faults[i].restarted_ns.is_none() {
                            self.faults[i].restarted_ns = Some(ns);
                        }
                    }
                    self.note(ns, format!("{name} ready again"));
                    if name == "plant" && !self.processes[index].write_line("start") {
                        self.note(ns, "cannot tell the restarted plant to start".into());
                    }
                }
            }
            Some(ChildEvent::Started { start_ns, .. }) => {
                self.plant_start_ns.get_or_insert(start_ns);
            }
            Some(ChildEvent::Paused { k }) => {
                let rate = self.config.rate_hz;
                for i in 0..self.config.faults.len() {
                    let fault = &self.config.faults[i];
                    if fault.kind.from_outside() && fault.ticks(rate).0 == k && self.faults[i].injected_ns.is_none() {
                        self.inject(i);
                    }
                }
                self.paused = true;
            }
            Some(ChildEvent::Stall { process, since_ns, detected_ns }) => {
                let kind_index = self.fault_indices(&process, FaultKind::Stop);
                for i in kind_index {
                    if self.faults[i].detected_ns.is_none() {
                        self.faults[i].detected_ns = Some(detected_ns);
                        self.faults[i].detected_by = Some("the monitor's input deadline");
                    }
                }
                let waited = (detected_ns.saturating_sub(since_ns)) as f64 / 1e6;
                self.note(detected_ns, format!("{process} stalled: its input has waited {waited:.1} ms"));
            }
            Some(ChildEvent::Resumed { process, at_ns }) => {
                for i in self.fault_indices(&process, FaultKind::Stop) {
                    if self.faults[i].resumed_ns.is_none() && self.faults[i].detected_ns.is_some() {
                        self.faults[i].resumed_ns = Some(at_ns);
                    }
                }
                self.note(at_ns, format!("{process} handles its input again"));
            }
            Some(ChildEvent::Status(status)) => {
                self.last_status = Instant::now();
                self.show(&status);
            }
            Some(ChildEvent::PlantReport(r)) => self.reports.plant = Some(r),
            Some(ChildEvent::MonitorReport(r)) => self.reports.monitor = Some(*r),
            Some(ChildEvent::StageReport(r)) => self.reports.stages.entry(name).or_default().push(r),
        }
        None
    }

    /// A process's output ended during the run: the run completed (the plant finished), or the
    /// process is restarted, or the run fails. Returns the outcome if the run is over.
    fn ended(&mut self, index: usize) -> Option<Outcome> {
        let ns = now_ns();
        let process = &mut self.processes[index];
        let name = process.name;
        let healthy = process
            .ready_since
            .is_some_and(|t| t.elapsed().as_secs_f64() >= self.config.supervision.backoff_reset_s);
        process.ready = false;
        process.ready_since = None;
        process.stopped = false;
        if name == "plant" {
            // A pause belongs to the plant that asked; its successor asks again at the same tick.
            self.paused = false;
        }
        let clean = process.current().exit.as_ref().is_some_and(|(_, ok)| *ok);
        if name == "plant"
            && clean
            && let Some(report) = &self.reports.plant
        {
            return Some(match report.stalled_at {
                Some(k) => Outcome::Failed(format!(
                    "the loop stalled at loop {k}: no command within {} s (supervision.lockstep_stall_s)",
                    self.config.supervision.lockstep_stall_s
                )),
                None => Outcome::Completed,
            });
        }
        let exit = process.exit_text();
        for i in self.fault_indices(name, FaultKind::Kill) {
            if self.faults[i].detected_ns.is_none() {
                self.faults[i].detected_ns = Some(ns);
                self.faults[i].detected_by = Some("the process exited");
            }
        }
        // Free what the dead process held in shared memory before its successor opens it, on the
        // clean-up thread.
        if let Some(cleaner) = &self.cleaner {
            let _ = cleaner.send(index);
        }
        let process = &mut self.processes[index];
        let restarts = process.runs.len() as u32 - 1;
        let policy = process.policy;
        let wanted = match policy.restart {
            Restart::Never => false,
            Restart::OnFailure => !clean,
            Restart::Always => true,
        };
        if wanted && restarts < policy.max_restarts {
            if healthy {
                process.quick_restarts = 0;
            }
            // backoff_s is checked at load to be a small number of seconds.
            let backoff = Duration::try_from_secs_f64(policy.backoff_s)
                .unwrap_or(MAX_BACKOFF)
                .saturating_mul(1 << process.quick_restarts.min(20))
                .min(MAX_BACKOFF);
            process.quick_restarts += 1;
            process.restart = Some(PendingRestart { not_before: Instant::now() + backoff, cleaned: false });
            self.restarts.push(RestartRecord {
                process: name,
                incarnation: process.runs.len(),
                backoff,
                died_ns: ns,
                cleaned_ns: None,
                spawned_ns: None,
                ready_ns: None,
            });
            self.note(ns, format!("{exit}; restart after its clean-up and {:.0} ms of backoff", backoff.as_secs_f64() * 1e3));
            return None;
        }
        let why = if wanted {
            format!("{exit}; not restarted: it reached supervision max_restarts = {}", policy.max_restarts)
        } else {
            format!("{exit}; not restarted (restart = {})", restart_name(policy.restart))
        };
        process.gone = true;
        self.note(ns, why.clone());
        if name == "monitor" {
            // The loop goes on without its recorder; the report says which loops have none.
            return None;
        }
        Some(Outcome::Failed(format!("{why}; see logs/{name}.log")))
    }

    /// The newest restart of `process`, the one under way.
    fn latest_restart(&mut self, process: &str) -> Option<&mut RestartRecord> {
        self.restarts.iter_mut().rev().find(|r| r.process == process)
    }

    /// The clean-up after a death of process `index` is done: its restart may go ahead.
    fn cleaned(&mut self, index: usize, removed: u64) {
        let ns = now_ns();
        self.removed_dead_nodes += removed;
        let name = self.processes[index].name;
        if let Some(restart) = &mut self.processes[index].restart
            && !restart.cleaned
        {
            restart.cleaned = true;
            if let Some(r) = self.latest_restart(name) {
                r.cleaned_ns = Some(ns);
            }
            self.note(ns, format!("{name}: its iceoryx2 resources removed ({removed} dead node(s))"));
        }
    }

    fn show(&self, status: &MonitorStatus) {
        self.progress.set_position(status.loops_recorded);
        let p99 = status.end_to_end_p99_ns.map_or("-".into(), |ns| format!("{:.0} µs", ns as f64 / 1000.0));
        self.progress.set_message(format!("end-to-end p99 {p99} · deadline misses {}", status.deadline_misses));
    }

    /// After a run whose plant finished: every other process must have ended cleanly too, and
    /// the monitor must have reported.
    fn check_ends(&self) -> Outcome {
        let failed: Vec<String> = self
            .processes
            .iter()
            .filter(|p| !p.runs.last().and_then(|r| r.exit.as_ref()).is_some_and(|(_, ok)| *ok))
            .map(|p| p.exit_text())
            .collect();
        if !failed.is_empty() {
            Outcome::Failed(format!("{}; see the logs folder", failed.join(", ")))
        } else if self.reports.monitor.is_none() {
            Outcome::Failed("the monitor sent no report".into())
        } else {
            Outcome::Completed
        }
    }

    /// Adaptive-wait counts per process, summed over its incarnations.
    fn adaptive_waits(&self, plant: &PlantReport) -> BTreeMap<String, crate::contract::protocol::WaitCounts> {
        let mut all = BTreeMap::new();
        let mut add = |name: &str, w: crate::contract::protocol::WaitCounts| {
            if w.caught + w.blocked > 0 {
                let entry: &mut crate::contract::protocol::WaitCounts = all.entry(name.to_string()).or_default();
                entry.caught += w.caught;
                entry.blocked += w.blocked;
            }
        };
        add("plant", plant.wait);
        for (name, reports) in &self.reports.stages {
            for r in reports {
                add(name, r.wait);
            }
        }
        all
    }

    /// Stops every process still running, in order, each with SIGTERM and then, past its
    /// timeout, SIGKILL; collects their reports on the way.
    fn stop_all(&mut self) {
        self.stopping = true;
        // A stopped process cannot act on SIGTERM.
        for p in &self.processes {
            p.signal(libc::SIGCONT);
        }
        for name in STOP_ORDER {
            let index = self.index_of(name);
            if self.processes[index].try_reap() {
                continue;
            }
            // After a second stop request, nothing is asked: everything left is killed.
            if !self.stop.urgent() {
                self.processes[index].signal(libc::SIGTERM);
            }
            let timeout = if name == "monitor" { MONITOR_STOP_TIMEOUT } else { STOP_TIMEOUT };
            let until = Instant::now() + timeout;
            while !self.processes[index].try_reap() {
                let urgent = self.stop.urgent();
                if urgent || Instant::now() > until {
                    if urgent {
                        eprintln!("looplab: second stop request; killing {name}");
                    } else {
                        eprintln!("looplab: {name} did not stop within {} s; killing it", timeout.as_secs());
                    }
                    self.processes[index].signal(libc::SIGKILL);
                    while !self.processes[index].try_reap() {
                        std::thread::sleep(Duration::from_millis(5));
                    }
                    break;
                }
                if let Ok(event) = self.events.recv_timeout(Duration::from_millis(5)) {
                    self.handle(event);
                }
            }
        }
        // Every process has exited: read what is left in their pipes, until every reader is done.
        while let Ok(event) = self.events.recv_timeout(Duration::from_millis(200)) {
            self.handle(event);
        }
    }

    fn summary(
        &self,
        scenario: &dyn Scenario,
        started_at: String,
        outcome: &Outcome,
        cleanup: ipc::Cleanup,
    ) -> Summary {
        let config = self.config;
        let plant = self.reports.plant.clone().unwrap_or_default();
        let monitor = self.reports.monitor.clone().unwrap_or_default();
        let counters = plant.counters;
        let wall_ns = plant.last_publish_ns.saturating_sub(plant.first_publish_ns);
        let wall_time_s = wall_ns as f64 * 1e-9;
        let stopped_because = match outcome {
            Outcome::Completed if plant.stopped_early => Some("the plant stopped before the last loop".into()),
            Outcome::Completed => None,
            Outcome::Interrupted => Some("interrupted by a signal".into()),
            Outcome::Failed(why) => Some(why.clone()),
        };
        let missing = monitor.missing.clone().up_to(monitor.loops_seen, plant.loops);
        let stage_total = |f: fn(&StageReport) -> u64| -> u64 { self.reports.stages.values().flatten().map(f).sum() };
        let mut processes = vec![];
        for p in &self.processes {
            let reports = self.reports.stages.get(p.name);
            for (n, run) in p.runs.iter().enumerate() {
                processes.push(ProcessInfo {
                    name: p.name.into(),
                    incarnation: n as u32,
                    pid: run.pid,
                    exit: run.exit.as_ref().map_or("running".into(), |(s, _)| s.clone()),
                    cpu_s: run.cpu_s,
                    processed: reports.map(|r| r.iter().map(|r| r.processed).sum()),
                    skipped: reports.map(|r| r.iter().map(|r| r.skipped).sum()),
                });
            }
        }
        let faults = config
            .faults
            .iter()
            .zip(&self.faults)
            .enumerate()
            .map(|(i, (spec, seen))| {
                let after = |ns: Option<u64>| match (seen.injected_ns, ns) {
                    (Some(a), Some(b)) => Some((b as f64 - a as f64) / 1e6),
                    _ => None,
                };
                FaultReport {
                    fault: spec.describe(),
                    kind: spec.kind.name().into(),
                    process: spec.process.clone(),
                    at_s: spec.at_s,
                    injected_at_ms: seen.injected_ns.map(|ns| self.since_start_ms(ns)),
                    detected_after_ms: after(seen.detected_ns),
                    detected_by: seen.detected_by.map(str::to_owned),
                    restarted_after_ms: after(seen.restarted_ns),
                    continued_after_ms: after(seen.continued_ns),
                    resumed_after_ms: after(seen.resumed_ns),
                    effect: monitor.faults.get(i).cloned(),
                }
            })
            .collect();
        Summary {
            scenario: config.scenario.clone(),
            title: scenario.title(),
            mode: config.mode.name().into(),
            rate_hz: config.rate_hz,
            duration_s: config.duration_s,
            seed: config.seed,
            run_id: self.run_id.clone(),
            run_dir: self.run_dir.display().to_string(),
            started_at,
            loops: plant.loops,
            loops_planned: config.loops(),
            completed: matches!(outcome, Outcome::Completed) && !plant.stopped_early && plant.loops == config.loops(),
            stopped_because,
            deadline_misses: counters.deadline_misses,
            rejected_commands: counters.rejected_commands,
            skipped_ticks: counters.skipped_ticks,
            stale_ticks: counters.stale_ticks,
            lost_commands: counters.lost_commands,
            loops_without_command: plant.published.saturating_sub(plant.commands),
            wall_time_s,
            loops_per_s: if wall_ns > 0 { plant.loops.saturating_sub(1) as f64 / wall_time_s } else { 0.0 },
            restarts: self
                .processes
                .iter()
                .map(|p| (p.name.to_string(), p.runs.len().saturating_sub(1) as u32))
                .collect(),
            processes,
            adaptive_waits: self.adaptive_waits(&plant),
            latency_ns: Latency { end_to_end: monitor.end_to_end.clone(), hops: monitor.hops.clone() },
            jitter_ns: Jitter {
                plant_tick: monitor.plant_tick_jitter.clone(),
                plant_wake_latency: monitor.plant_wake_latency.clone(),
            },
            data_age_ns: monitor.data_age.clone(),
            monitor: MonitorCounts {
                records: monitor.records,
                lost: monitor.lost_records(plant.commands),
                missing,
                received: monitor.received.clone(),
                partial_rows: monitor.partial_rows,
                loop_waits: plant.waited + stage_total(|r| r.waited),
                dropped_for_monitor: plant.dropped + stage_total(|r| r.dropped),
            },
            metrics: monitor.metrics.clone(),
            notes: monitor.notes.clone(),
            error_measure: scenario.error_measure().describe(),
            faults,
            timeline: self.timeline.clone(),
            restart_steps: self
                .restarts
                .iter()
                .map(|r| {
                    let after = |ns: Option<u64>| ns.map(|ns| (ns as f64 - r.died_ns as f64) / 1e6);
                    report::RestartSteps {
                        process: r.process.into(),
                        incarnation: r.incarnation as u32,
                        died_at_ms: self.since_start_ms(r.died_ns),
                        cleaned_after_ms: after(r.cleaned_ns),
                        backoff_ms: r.backoff.as_secs_f64() * 1e3,
                        spawned_after_ms: after(r.spawned_ns),
                        ready_after_ms: after(r.ready_ns),
                    }
                })
                .collect(),
            shared_memory: SharedMemoryCheck {
                clean: cleanup.leftover.is_empty(),
                removed_dead_nodes: cleanup.removed_dead_nodes + self.removed_dead_nodes,
                leftover: cleanup.leftover,
            },
        }
    }
}

fn restart_name(r: Restart) -> &'static str {
    match r {
        Restart::Never => "never",
        Restart::OnFailure => "on-failure",
        Restart::Always => "always",
    }
}

pub mod report;
pub mod in_process;
