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

use crate::ipc;
use crate::launch::{self, LaunchConfig, Override};
use crate::monitor::MonitorReport;
use crate::protocol::{ChildEvent, MonitorStatus, PlantReport, StageReport};
use crate::report::{self, Jitter, Latency, MonitorCounts, ProcessInfo, SharedMemoryCheck, Summary};
use crate::scenarios::{self, Scenario};
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
const EXIT_INTERRUPTED: u8 = 130;

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
        Self {
            target: "pendulum".into(),
            mode: None,
            duration: None,
            rate: None,
            seed: None,
            set: vec![],
            out: None,
            quiet: false,
        }
    }
}

pub fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Some(Command::List) => {
            list();
            ExitCode::SUCCESS
        }
        Some(Command::Show { scenario }) => match launch::builtin(&scenario) {
            Some(entry) => {
                print!("{}", entry.text);
                ExitCode::SUCCESS
            }
            None => bad_input(format!("unknown scenario \"{scenario}\"; allowed: {}", launch::scenario_names())),
        },
        Some(Command::Run(args)) => run(args),
        None => run(RunArgs::default()),
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

fn run(args: RunArgs) -> ExitCode {
    let mut texts: Vec<String> = Vec::new();
    if let Some(mode) = &args.mode {
        texts.push(format!("mode={mode}"));
    }
    if let Some(d) = args.duration {
        texts.push(format!("duration_s={d:?}"));
    }
    if let Some(r) = args.rate {
        texts.push(format!("rate_hz={r:?}"));
    }
    if let Some(s) = args.seed {
        texts.push(format!("seed={s}"));
    }
    texts.extend(args.set.iter().cloned());
    let overrides: Result<Vec<Override>, _> = texts.iter().map(|t| Override::parse(t)).collect();
    let resolved = overrides.and_then(|o| launch::resolve(&args.target, &o));
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
    match Supervisor::run(&config, scenario.as_ref(), &binaries, &run_dir, args.quiet) {
        Ok((summary, outcome)) => {
            print!("{}", report::render(&summary));
            match outcome {
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
fn locate_binaries() -> Result<BTreeMap<&'static str, PathBuf>> {
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

fn create_run_dir(out: Option<&Path>, scenario: &str) -> Result<PathBuf> {
    let dir = match out {
        Some(dir) => {
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

fn new_run_id() -> String {
    use std::hash::BuildHasher;
    let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos());
    let hash = std::collections::hash_map::RandomState::new().hash_one((std::process::id(), nanos));
    format!("{:08x}", hash as u32)
}

pub enum Outcome {
    Completed,
    Interrupted,
    Failed(String),
}

struct Child {
    name: &'static str,
    pid: u32,
    stdin: Option<ChildStdin>,
    exit: Option<(String, bool)>,
    cpu_s: f64,
}

impl Child {
    /// Reaps the child if it has exited (without blocking), with its CPU time.
    fn try_reap(&mut self) -> bool {
        if self.exit.is_some() {
            return true;
        }
        let mut status = 0;
        // SAFETY: plain wait4 on our own child; rusage is a valid out-parameter.
        let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
        let pid = unsafe { libc::wait4(self.pid as i32, &mut status, libc::WNOHANG, &mut usage) };
        if pid != self.pid as i32 {
            return false;
        }
        let secs = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
        self.cpu_s = secs(usage.ru_utime) + secs(usage.ru_stime);
        self.exit = Some(if libc::WIFEXITED(status) {
            (libc::WEXITSTATUS(status).to_string(), libc::WEXITSTATUS(status) == 0)
        } else {
            (format!("signal {}", libc::WTERMSIG(status)), false)
        });
        true
    }

    fn signal(&self, signal: i32) {
        if self.exit.is_none() {
            // SAFETY: the pid is our unreaped child, so it cannot have been reused.
            unsafe { libc::kill(self.pid as i32, signal) };
        }
    }
}

/// What a child's stdout reader passes on: an event, or None at end of output.
type Event = (usize, Option<ChildEvent>);

#[derive(Default)]
struct Reports {
    plant: Option<PlantReport>,
    monitor: Option<MonitorReport>,
    stages: BTreeMap<&'static str, StageReport>,
}

struct Supervisor {
    children: Vec<Child>,
    events: Receiver<Event>,
    readers: Vec<std::thread::JoinHandle<()>>,
    reports: Reports,
    progress: ProgressBar,
}

impl Supervisor {
    fn run(
        config: &LaunchConfig,
        scenario: &dyn Scenario,
        binaries: &BTreeMap<&'static str, PathBuf>,
        run_dir: &Path,
        quiet: bool,
    ) -> Result<(Summary, Outcome)> {
        let launch_file = run_dir.join("launch.toml");
        std::fs::write(&launch_file, config.to_toml()).with_context(|| format!("write {}", launch_file.display()))?;
        let run_id = new_run_id();
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
        let mut supervisor =
            Supervisor { children: vec![], events, readers: vec![], reports: Reports::default(), progress };
        let outcome = match supervisor.spawn_all(binaries, &launch_file, &run_id, run_dir, tx) {
            Ok(()) => supervisor.supervise(&stop),
            Err(e) => Outcome::Failed(format!("{e:#}")),
        };
        supervisor.stop_all();
        supervisor.progress.finish_and_clear();
        let outcome = match outcome {
            Outcome::Completed => supervisor.check_ends(),
            other => other,
        };
        for reader in supervisor.readers.drain(..) {
            let _ = reader.join();
        }
        let cleanup = ipc::clean_up_run(&run_id)?;
        let summary = supervisor.summary(config, scenario, &run_id, run_dir, started_at, &outcome, cleanup);
        let path = run_dir.join("summary.json");
        std::fs::write(&path, serde_json::to_string_pretty(&summary)? + "\n")
            .with_context(|| format!("write {}", path.display()))?;
        Ok((summary, outcome))
    }

    fn spawn_all(
        &mut self,
        binaries: &BTreeMap<&'static str, PathBuf>,
        launch_file: &Path,
        run_id: &str,
        run_dir: &Path,
        tx: crossbeam_channel::Sender<Event>,
    ) -> Result<()> {
        for (index, name) in START_ORDER.into_iter().enumerate() {
            let log_path = run_dir.join("logs").join(format!("{name}.log"));
            let log = std::fs::File::create(&log_path).with_context(|| format!("create {}", log_path.display()))?;
            let mut command = std::process::Command::new(&binaries[name]);
            command
                .arg("--launch")
                .arg(launch_file)
                .arg("--run-id")
                .arg(run_id)
                .arg("--run-dir")
                .arg(run_dir)
                .stdin(if name == "plant" { Stdio::piped() } else { Stdio::null() })
                .stdout(Stdio::piped())
                .stderr(log)
                // Its own process group: a Ctrl-C in the terminal reaches only the launcher,
                // which then stops the loop in order.
                .process_group(0);
            // SAFETY: prctl and getppid are async-signal-safe. If the launcher dies, the child
            // is asked to stop, so nothing is orphaned; if it died before prctl took effect,
            // the child does not start at all.
            let launcher = std::process::id() as libc::pid_t;
            unsafe {
                command.pre_exec(move || {
                    libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
                    if libc::getppid() != launcher {
                        return Err(std::io::Error::other("the launcher is gone"));
                    }
                    Ok(())
                });
            }
            let mut child = command.spawn().with_context(|| format!("cannot start {}", binaries[name].display()))?;
            let stdout = child.stdout.take().expect("stdout is piped");
            let tx = tx.clone();
            self.readers.push(std::thread::spawn(move || {
                for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                    if let Ok(event) = serde_json::from_str::<ChildEvent>(&line) {
                        let _ = tx.send((index, Some(event)));
                    }
                }
                let _ = tx.send((index, None));
            }));
            self.children.push(Child { name, pid: child.id(), stdin: child.stdin.take(), exit: None, cpu_s: 0.0 });
        }
        Ok(())
    }

    /// Files an event; returns the index of a child whose output ended.
    fn handle(&mut self, (index, event): Event) -> Option<usize> {
        let name = self.children[index].name;
        match event {
            None => {
                // Its output ends when it exits: reap it (it may take a moment to go).
                let until = Instant::now() + Duration::from_secs(2);
                while !self.children[index].try_reap() && Instant::now() < until {
                    std::thread::sleep(Duration::from_millis(1));
                }
                return Some(index);
            }
            Some(ChildEvent::Status(status)) => self.show(&status),
            Some(ChildEvent::PlantReport(r)) => self.reports.plant = Some(r),
            Some(ChildEvent::MonitorReport(r)) => self.reports.monitor = Some(*r),
            Some(ChildEvent::StageReport(r)) => {
                self.reports.stages.insert(name, r);
            }
            Some(ChildEvent::Ready) => {}
        }
        None
    }

    fn show(&self, status: &MonitorStatus) {
        self.progress.set_position(status.loops_recorded);
        let p99 = status.end_to_end_p99_ns.map_or("-".into(), |ns| format!("{:.0} µs", ns as f64 / 1000.0));
        self.progress.set_message(format!("end-to-end p99 {p99} · deadline misses {}", status.deadline_misses));
    }

    fn exit_text(&self, index: usize) -> String {
        let child = &self.children[index];
        match &child.exit {
            Some((status, _)) => format!("{} exited with status {status}", child.name),
            None => format!("{} closed its output", child.name),
        }
    }

    fn supervise(&mut self, stop: &StopFlag) -> Outcome {
        // Start-up: every process, the monitor included, has its ports before the first sample.
        let deadline = Instant::now() + READY_TIMEOUT;
        let mut ready = vec![false; self.children.len()];
        while !ready.iter().all(|r| *r) {
            if stop.requested() {
                return Outcome::Interrupted;
            }
            match self.events.recv_timeout(Duration::from_millis(50)) {
                Ok((index, Some(ChildEvent::Ready))) => ready[index] = true,
                Ok(event) => {
                    if let Some(index) = self.handle(event) {
                        return Outcome::Failed(format!(
                            "{} during start-up; see logs/{}.log",
                            self.exit_text(index),
                            self.children[index].name
                        ));
                    }
                }
                Err(RecvTimeoutError::Timeout) if Instant::now() > deadline => {
                    let late: Vec<_> =
                        self.children.iter().zip(&ready).filter(|(_, r)| !**r).map(|(c, _)| c.name).collect();
                    return Outcome::Failed(format!(
                        "not ready after {} s: {}",
                        READY_TIMEOUT.as_secs(),
                        late.join(", ")
                    ));
                }
                Err(_) => {}
            }
        }
        let plant = self.children.iter().position(|c| c.name == "plant").expect("every process was started");
        let started = self.children[plant].stdin.as_mut().map(|s| s.write_all(b"start\n").and_then(|_| s.flush()));
        if !matches!(started, Some(Ok(()))) {
            return Outcome::Failed("cannot tell the plant to start".into());
        }

        loop {
            if stop.requested() {
                return Outcome::Interrupted;
            }
            match self.events.recv_timeout(Duration::from_millis(50)) {
                Ok(event) => {
                    if let Some(index) = self.handle(event) {
                        let child = &self.children[index];
                        let clean_exit = child.exit.as_ref().is_some_and(|(_, ok)| *ok);
                        return if index == plant && clean_exit && self.reports.plant.is_some() {
                            Outcome::Completed
                        } else {
                            Outcome::Failed(format!(
                                "{} during the run; see logs/{}.log",
                                self.exit_text(index),
                                child.name
                            ))
                        };
                    }
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return Outcome::Failed("lost every process's output".into()),
            }
        }
    }

    /// After a run whose plant finished: every other process must have ended cleanly too, and
    /// the monitor must have reported.
    fn check_ends(&self) -> Outcome {
        let failed: Vec<String> = self
            .children
            .iter()
            .filter(|c| !c.exit.as_ref().is_some_and(|(_, ok)| *ok))
            .map(|c| {
                format!("{} exited with status {}", c.name, c.exit.as_ref().map_or("unknown", |(s, _)| s.as_str()))
            })
            .collect();
        if !failed.is_empty() {
            Outcome::Failed(format!("{}; see the logs folder", failed.join(", ")))
        } else if self.reports.monitor.is_none() {
            Outcome::Failed("the monitor sent no report".into())
        } else {
            Outcome::Completed
        }
    }

    /// Stops every process still running, in order, each with SIGTERM and then, past its
    /// timeout, SIGKILL; collects their reports on the way.
    fn stop_all(&mut self) {
        for name in STOP_ORDER {
            // A start-up failure can leave some processes never started.
            let Some(index) = self.children.iter().position(|c| c.name == name) else { continue };
            if self.children[index].try_reap() {
                continue;
            }
            self.children[index].signal(libc::SIGTERM);
            let timeout = if name == "monitor" { MONITOR_STOP_TIMEOUT } else { STOP_TIMEOUT };
            let until = Instant::now() + timeout;
            while !self.children[index].try_reap() {
                if Instant::now() > until {
                    eprintln!("looplab: {name} did not stop within {} s; killing it", timeout.as_secs());
                    self.children[index].signal(libc::SIGKILL);
                    while !self.children[index].try_reap() {
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
        while let Ok(event) = self.events.recv_timeout(Duration::from_secs(5)) {
            self.handle(event);
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn summary(
        &self,
        config: &LaunchConfig,
        scenario: &dyn Scenario,
        run_id: &str,
        run_dir: &Path,
        started_at: String,
        outcome: &Outcome,
        cleanup: ipc::Cleanup,
    ) -> Summary {
        let plant = self.reports.plant.clone().unwrap_or_default();
        let monitor = self.reports.monitor.clone().unwrap_or_default();
        let wall_ns = plant.last_publish_ns.saturating_sub(plant.first_publish_ns);
        let wall_time_s = wall_ns as f64 * 1e-9;
        let stopped_because = match outcome {
            Outcome::Completed if plant.stopped_early => Some("the plant stopped before the last loop".into()),
            Outcome::Completed => None,
            Outcome::Interrupted => Some("interrupted by a signal".into()),
            Outcome::Failed(why) => Some(why.clone()),
        };
        let mut missing = monitor.missing_records.clone();
        if monitor.loops_seen < plant.loops && missing.len() < 100 {
            // Loops after the last one the monitor saw anything of.
            missing.push([monitor.loops_seen, plant.loops - 1]);
        }
        Summary {
            scenario: config.scenario.clone(),
            title: scenario.title(),
            mode: config.mode.name().into(),
            rate_hz: config.rate_hz,
            duration_s: config.duration_s,
            seed: config.seed,
            run_id: run_id.into(),
            run_dir: run_dir.display().to_string(),
            started_at,
            loops: plant.loops,
            loops_planned: config.loops(),
            completed: matches!(outcome, Outcome::Completed) && !plant.stopped_early && plant.loops == config.loops(),
            stopped_because,
            deadline_misses: plant.deadline_misses,
            rejected_commands: plant.rejected_commands,
            skipped_ticks: plant.skipped_ticks,
            loops_without_command: plant.published.saturating_sub(plant.commands),
            wall_time_s,
            loops_per_s: if wall_ns > 0 { plant.loops.saturating_sub(1) as f64 / wall_time_s } else { 0.0 },
            processes: self
                .children
                .iter()
                .map(|c| ProcessInfo {
                    name: c.name.into(),
                    pid: c.pid,
                    exit: c.exit.as_ref().map_or("running".into(), |(s, _)| s.clone()),
                    cpu_s: c.cpu_s,
                    processed: self.reports.stages.get(c.name).map(|r| r.processed),
                    skipped: self.reports.stages.get(c.name).map(|r| r.skipped),
                })
                .collect(),
            latency_ns: Latency { end_to_end: monitor.end_to_end.clone(), hops: monitor.hops.clone() },
            jitter_ns: Jitter {
                plant_tick: monitor.plant_tick_jitter.clone(),
                plant_wake_latency: monitor.plant_wake_latency.clone(),
            },
            data_age_ns: monitor.data_age.clone(),
            monitor: MonitorCounts {
                records: monitor.records,
                lost: plant.commands.saturating_sub(monitor.records),
                missing,
                received: monitor.received.clone(),
                partial_rows: monitor.partial_rows,
                loop_waits: plant.waited + self.reports.stages.values().map(|r| r.waited).sum::<u64>(),
                dropped_for_monitor: plant.dropped + self.reports.stages.values().map(|r| r.dropped).sum::<u64>(),
            },
            metrics: monitor.metrics.clone(),
            shared_memory: SharedMemoryCheck {
                clean: cleanup.leftover.is_empty(),
                removed_dead_nodes: cleanup.removed_dead_nodes,
                leftover: cleanup.leftover,
            },
        }
    }
}
