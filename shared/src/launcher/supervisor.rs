//! The supervision of one run: start every process, wait until all are ready, let the plant
//! start, then handle their events (deaths and restarts, stalls, the status line) until the
//! plant is done, and stop them in order.

use std::collections::BTreeMap;
use std::io::Write as _;
use std::ops::{Index, IndexMut};
use std::path::{Path, PathBuf};
use std::process::ChildStdin;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Result;
use crossbeam_channel::{Receiver, RecvTimeoutError, Sender};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::config::faults::{FaultKind, Policy};
use crate::config::launch::{LaunchConfig, Mode};
use crate::contract::clock::now_ns;
use crate::contract::protocol::{ChildEvent, MonitorStatus};
use crate::contract::role::Role;
use crate::launcher::child::{self, Binaries, ChildArgs, ChildLine, Line, Start};
use crate::launcher::dashboard::{self, Dashboard, ProcessRow, ProcessState, Update};
use crate::launcher::inject::{self, DetectedBy};
use crate::launcher::outcome::{Exit, Outcome};
use crate::launcher::restart::{self, Death, Decision, RestartRecord};
use crate::launcher::run_dir::{begin_run, new_run_id};
use crate::launcher::summary::{self, Reports, RunLog, SharedMemoryCheck, Summary, SummaryInputs};
use crate::model::scenario::Scenario;
use crate::monitor::layout::Layout;
use crate::monitor::live::{Truth, key_signals};
use crate::runtime::ipc;
use crate::runtime::signals::StopFlag;

/// Longest start-up: every process must report ready within it.
const READY_TIMEOUT: Duration = Duration::from_secs(20);
/// Longest a stage may take to exit after SIGTERM before it is killed.
const STOP_TIMEOUT: Duration = Duration::from_secs(5);
/// The monitor writes its files on exit, so it gets longer.
const MONITOR_STOP_TIMEOUT: Duration = Duration::from_secs(60);
/// How long the monitor may stay silent (it reports ten times a second) before it counts as
/// stalled.
const MONITOR_SILENCE: Duration = Duration::from_millis(300);
/// Longest wait between two looks at the fault schedule.
const SUPERVISE_TICK: Duration = Duration::from_millis(2);

/// What the user sees while a run goes on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LiveView {
    Quiet,
    /// A progress bar with the end-to-end p99 on stderr.
    StatusLine,
    /// The full-screen dashboard (stdout must be a terminal).
    Dashboard,
}

/// Runs one launch configuration to its end in `run_dir` (which must exist, with `logs/`):
/// writes `launch.toml` and `summary.json` there.
pub fn run_once(
    config: &LaunchConfig,
    scenario: &dyn Scenario,
    binaries: &Binaries,
    run_dir: &Path,
    quiet: bool,
) -> Result<(Summary, Outcome)> {
    run_with(config, scenario, binaries, run_dir, if quiet { LiveView::Quiet } else { LiveView::StatusLine })
}

/// [`run_once`], shown as `view` says.
pub fn run_with(
    config: &LaunchConfig,
    scenario: &dyn Scenario,
    binaries: &Binaries,
    run_dir: &Path,
    view: LiveView,
) -> Result<(Summary, Outcome)> {
    let decided = config.with_wait_decided(crate::runtime::wait::available_cpus());
    Supervisor::run(&decided, scenario, binaries, run_dir, view)
}

/// A process of the loop across its restarts.
struct Process {
    role: Role,
    policy: Policy,
    /// Every start; the last is the running incarnation.
    runs: Vec<Start>,
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
    /// The running (or last) incarnation's number.
    fn incarnation(&self) -> u32 {
        self.runs.len().saturating_sub(1) as u32
    }

    fn running(&self) -> bool {
        self.runs.last().is_some_and(|r| r.exit == Exit::Running)
    }

    fn try_reap(&mut self) -> bool {
        self.runs.last_mut().is_none_or(Start::try_reap)
    }

    fn signal(&self, signal: i32) {
        if let Some(run) = self.runs.last() {
            run.signal(signal);
        }
    }

    fn exit_text(&self) -> String {
        match self.runs.last().map(|r| r.exit) {
            Some(exit) if exit != Exit::Running => format!("{} exited with status {exit}", self.role),
            _ => format!("{} closed its output", self.role),
        }
    }

    /// What the dashboard calls its state.
    fn row(&self) -> ProcessRow {
        let state = if self.gone {
            ProcessState::Dead
        } else if self.restart.is_some() {
            ProcessState::Restarting
        } else if !self.running() {
            ProcessState::Exited
        } else if self.stopped {
            ProcessState::Stopped
        } else if self.ready {
            ProcessState::Running
        } else {
            ProcessState::Starting
        };
        let pid = self.runs.last().filter(|r| r.exit == Exit::Running).map(|r| r.pid);
        ProcessRow { role: self.role, state, restarts: self.incarnation(), pid }
    }

    fn ended_cleanly(&self) -> bool {
        self.runs.last().is_some_and(|r| r.exit.clean())
    }

    fn write_line(&mut self, line: &str) -> bool {
        let written = self.stdin.as_mut().map(|s| s.write_all(format!("{line}\n").as_bytes()).and_then(|_| s.flush()));
        matches!(written, Some(Ok(())))
    }
}

/// The run's processes, in start order, by role.
struct Processes(Vec<Process>);

impl Processes {
    fn iter(&self) -> impl Iterator<Item = &Process> {
        self.0.iter()
    }
}

impl Index<Role> for Processes {
    type Output = Process;

    fn index(&self, role: Role) -> &Process {
        self.0.iter().find(|p| p.role == role).expect("every role has its process")
    }
}

impl IndexMut<Role> for Processes {
    fn index_mut(&mut self, role: Role) -> &mut Process {
        self.0.iter_mut().find(|p| p.role == role).expect("every role has its process")
    }
}

/// What reaches the supervision loop.
enum Event {
    Child(ChildLine),
    /// The clean-up after a death of `role` is done.
    Cleaned {
        role: Role,
        removed: u64,
    },
}

/// A restart under way: it starts once the dead process's resources are removed and the backoff
/// has passed.
struct PendingRestart {
    not_before: Instant,
    cleaned: bool,
}

struct Supervisor<'a> {
    config: &'a LaunchConfig,
    binaries: &'a Binaries,
    launch_file: PathBuf,
    run_id: String,
    run_dir: PathBuf,
    processes: Processes,
    tx: Sender<Event>,
    events: Receiver<Event>,
    readers: Vec<std::thread::JoinHandle<()>>,
    reports: Reports,
    progress: ProgressBar,
    /// Faults, restarts and the timeline, for the summary.
    log: RunLog,
    /// Lockstep: the plant is paused and waits for `go`.
    paused: bool,
    last_status: Instant,
    removed_dead_nodes: u64,
    stop: StopFlag,
    /// Clean-up requests (a process) for the clean-up thread: iceoryx2's clean-up of a dead
    /// process's resources can wait on the file system, and nothing of the supervision may.
    cleaner: Option<Sender<Role>>,
    dashboard: Option<Dashboard>,
    /// The processes as last sent to the dashboard.
    shown: Vec<ProcessRow>,
    /// Set by the dashboard's `q`.
    quit: Arc<AtomicBool>,
}

impl<'a> Supervisor<'a> {
    fn run(
        config: &'a LaunchConfig,
        scenario: &dyn Scenario,
        binaries: &'a Binaries,
        run_dir: &Path,
        view: LiveView,
    ) -> Result<(Summary, Outcome)> {
        let (launch_file, started_at) = begin_run(run_dir, config)?;
        let stop = StopFlag::install()?;

        let progress = match view {
            LiveView::StatusLine => ProgressBar::with_draw_target(Some(config.loops()), ProgressDrawTarget::stderr()),
            LiveView::Quiet | LiveView::Dashboard => ProgressBar::hidden(),
        };
        let quit = Arc::new(AtomicBool::new(false));
        let dashboard = match view {
            LiveView::Dashboard => Some(Dashboard::open(dashboard_header(config, scenario), quit.clone())?),
            LiveView::Quiet | LiveView::StatusLine => None,
        };
        progress.set_style(
            ProgressStyle::with_template("{spinner} {bar:16} {pos}/{len} loops · {msg}").expect("valid template"),
        );
        let (tx, events) = crossbeam_channel::unbounded();
        let processes = config
            .hosts
            .processes()
            .into_iter()
            .map(|role| Process {
                role,
                policy: config.supervision.policy(role),
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
        let (cleaner, clean_requests) = crossbeam_channel::unbounded::<Role>();
        let cleaned = tx.clone();
        let clean_run_id = run_id.clone();
        let clean_thread = std::thread::spawn(move || {
            for role in clean_requests {
                let removed = ipc::remove_dead_nodes(&clean_run_id).unwrap_or(0);
                if cleaned.send(Event::Cleaned { role, removed }).is_err() {
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
            processes: Processes(processes),
            tx,
            events,
            readers: vec![],
            reports: Reports::default(),
            progress,
            log: RunLog { faults: vec![Default::default(); config.faults.len()], ..Default::default() },
            paused: false,
            last_status: Instant::now(),
            removed_dead_nodes: 0,
            stop,
            cleaner: Some(cleaner),
            dashboard,
            shown: vec![],
            quit,
        };
        let spawned = supervisor.start_all();
        let outcome = match spawned {
            Ok(()) => supervisor.supervise(),
            Err(e) => Outcome::Failed(format!("{e:#}")),
        };
        supervisor.stop_all();
        supervisor.progress.finish_and_clear();
        if let Some(dashboard) = supervisor.dashboard.take() {
            dashboard.close();
        }
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
        let mut cleanup = ipc::clean_up_run(&supervisor.run_id)?;
        // The other host's bridge tidied its host up last and said what it left there.
        if let Some(remote) = supervisor.reports.bridges.get(&Role::BridgeRemote).and_then(|r| r.values().last()) {
            cleanup.leftover.extend(remote.leftover.iter().map(|f| format!("{f} (on the other host)")));
        }
        drop(storage_lock);
        let starts: BTreeMap<Role, Vec<Start>> =
            supervisor.processes.iter().map(|p| (p.role, p.runs.clone())).collect();
        let summary = summary::build(SummaryInputs {
            config,
            scenario,
            run_id: &supervisor.run_id,
            run_dir,
            started_at,
            outcome: &outcome,
            reports: &supervisor.reports,
            starts: &starts,
            log: &supervisor.log,
            shared_memory: SharedMemoryCheck {
                clean: cleanup.leftover.is_empty(),
                removed_dead_nodes: cleanup.removed_dead_nodes + supervisor.removed_dead_nodes,
                leftover: cleanup.leftover,
            },
        });
        summary::write(&summary, run_dir)?;
        Ok((summary, outcome))
    }

    /// Starts every process. The other host's bridge goes first, and alone: it makes the run's
    /// folder on its host, where the stages placed there need it.
    fn start_all(&mut self) -> Result<()> {
        for role in self.config.hosts.processes() {
            self.spawn(role)?;
            if role == Role::BridgeRemote {
                self.wait_ready(role)?;
            }
        }
        Ok(())
    }

    /// Handles events until `role` is ready (start-up, before the supervision loop).
    fn wait_ready(&mut self, role: Role) -> Result<()> {
        let deadline = Instant::now() + READY_TIMEOUT;
        while !self.processes[role].ready {
            if self.stop_outcome().is_some() {
                anyhow::bail!("stopped while {role} started");
            }
            match self.events.recv_timeout(Duration::from_millis(50)) {
                Ok(event) => {
                    if let Some(ended) = self.handle(event) {
                        anyhow::bail!("{} during start-up; see logs/{ended}.log", self.processes[ended].exit_text());
                    }
                }
                Err(_) if Instant::now() > deadline => {
                    anyhow::bail!("{role} not ready after {} s", READY_TIMEOUT.as_secs())
                }
                Err(_) => {}
            }
        }
        Ok(())
    }

    /// Starts the next incarnation of `role`.
    fn spawn(&mut self, role: Role) -> Result<()> {
        let binary = match role {
            Role::Bridge | Role::BridgeRemote => child::locate_bridge()?,
            _ => self.binaries[&role].clone(),
        };
        let remote = self.config.hosts.remote().filter(|_| self.config.hosts.is_remote(role));
        let args = ChildArgs {
            launch_file: &self.launch_file,
            run_id: &self.run_id,
            run_dir: &self.run_dir,
            incarnation: self.processes[role].runs.len() as u32,
            prefix: remote.map(|(_, host)| host.command.as_slice()).unwrap_or_default(),
        };
        let spawned = child::spawn(role, &binary, &args, self.tx.clone(), Event::Child)?;
        self.readers.push(spawned.reader);
        let process = &mut self.processes[role];
        process.runs.push(spawned.start);
        process.stdin = spawned.stdin;
        process.ready = false;
        process.ready_since = None;
        process.restart = None;
        Ok(())
    }

    /// Notes `event` on the timeline, at `ns`.
    fn note(&mut self, ns: u64, event: String) {
        self.log.note(ns, event);
        if let (Some(dashboard), Some(entry)) = (&self.dashboard, self.log.timeline.last()) {
            dashboard.send(Update::Event(entry.clone()));
        }
    }

    /// The user quit the dashboard, or a signal asked to stop.
    fn stop_outcome(&self) -> Option<Outcome> {
        if self.stop.requested() {
            Some(Outcome::Interrupted)
        } else if self.quit.load(Ordering::Relaxed) {
            Some(Outcome::Quit)
        } else {
            None
        }
    }

    /// Sends the dashboard the processes' states when they changed.
    fn show_processes(&mut self) {
        let Some(dashboard) = &self.dashboard else { return };
        let rows: Vec<ProcessRow> = self.processes.iter().map(Process::row).collect();
        if rows != self.shown {
            dashboard.send(Update::Processes(rows.clone()));
            self.shown = rows;
        }
    }

    fn supervise(&mut self) -> Outcome {
        // Start-up: every process, the monitor included, has its ports before the first sample.
        let deadline = Instant::now() + READY_TIMEOUT;
        while !self.processes.iter().all(|p| p.ready) {
            self.show_processes();
            if let Some(outcome) = self.stop_outcome() {
                return outcome;
            }
            match self.events.recv_timeout(Duration::from_millis(50)) {
                Ok(event) => {
                    if let Some(role) = self.handle(event) {
                        return Outcome::Failed(format!(
                            "{} during start-up; see logs/{role}.log",
                            self.processes[role].exit_text()
                        ));
                    }
                }
                Err(RecvTimeoutError::Timeout) if Instant::now() > deadline => {
                    let late: Vec<_> = self.processes.iter().filter(|p| !p.ready).map(|p| p.role.name()).collect();
                    return Outcome::Failed(format!(
                        "not ready after {} s: {}",
                        READY_TIMEOUT.as_secs(),
                        late.join(", ")
                    ));
                }
                Err(_) => {}
            }
        }
        if !self.processes[Role::Plant].write_line("start") {
            return Outcome::Failed("cannot tell the plant to start".into());
        }
        self.last_status = Instant::now();

        loop {
            self.show_processes();
            if let Some(outcome) = self.stop_outcome() {
                return outcome;
            }
            if let Some(outcome) = self.due_actions() {
                return outcome;
            }
            if let Some(outcome) = self.release_pause() {
                return outcome;
            }
            match self.events.recv_timeout(SUPERVISE_TICK) {
                Ok(event) => {
                    if let Some(role) = self.handle(event)
                        && let Some(outcome) = self.ended(role)
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
        self.inject_due_by_time();
        self.continue_stopped(now);
        for role in self.config.hosts.processes() {
            if !self.processes[role].restart.as_ref().is_some_and(|r| r.cleaned && now >= r.not_before) {
                continue;
            }
            match self.spawn(role) {
                Ok(()) => {
                    let ns = now_ns();
                    let n = self.processes[role].incarnation();
                    if let Some(r) = self.latest_restart(role) {
                        r.spawned_ns = Some(ns);
                    }
                    self.note(ns, format!("{role} restarted (incarnation {n})"));
                }
                Err(e) => {
                    self.processes[role].restart = None;
                    self.processes[role].gone = true;
                    let why = format!("{role} could not be restarted: {e:#}");
                    self.note(now_ns(), why.clone());
                    if role != Role::Monitor {
                        return Some(Outcome::Failed(why));
                    }
                }
            }
        }
        let monitor = &self.processes[Role::Monitor];
        if self.last_status.elapsed() > MONITOR_SILENCE && monitor.ready && monitor.stopped {
            // Only a stop fault on the monitor makes it silent while alive; note the detection.
            for i in self.injected(Role::Monitor, FaultKind::Stop) {
                let seen = &mut self.log.faults[i];
                if seen.detected_ns.is_none() && seen.continued_ns.is_none() {
                    let ns = now_ns();
                    seen.detected_ns = Some(ns);
                    seen.detected_by = Some(DetectedBy::MonitorHeartbeat);
                    self.note(ns, "monitor silent: stalled".into());
                }
            }
        }
        None
    }

    /// The faults on `role` of `kind` that were injected, newest first.
    fn injected(&self, role: Role, kind: FaultKind) -> Vec<usize> {
        inject::injected(&self.config.faults, &self.log.faults, role, kind)
    }

    /// Real time: injects the faults that are due.
    fn inject_due_by_time(&mut self) {
        if self.config.mode != Mode::Realtime {
            return;
        }
        if let Some(start) = self.log.plant_start_ns {
            for i in inject::due_by_time(&self.config.faults, &self.log.faults, start, now_ns()) {
                self.inject(i);
            }
        }
    }

    /// Lockstep: the plant holds loop `k`; injects the faults due there. The plant goes on once
    /// every process is back up.
    fn pause_at(&mut self, k: u64) {
        for i in inject::due_at_loop(&self.config.faults, &self.log.faults, self.config.rate_hz, k) {
            self.inject(i);
        }
        self.paused = true;
    }

    /// Sends SIGCONT to the processes whose stop is over at `now`.
    fn continue_stopped(&mut self, now: Instant) {
        for i in 0..self.log.faults.len() {
            if self.log.faults[i].continue_at.is_some_and(|at| now >= at) {
                self.log.faults[i].continue_at = None;
                let role = inject::target(&self.config.faults[i]);
                self.processes[role].signal(libc::SIGCONT);
                self.processes[role].stopped = false;
                let ns = now_ns();
                self.log.faults[i].continued_ns = Some(ns);
                self.note(ns, format!("SIGCONT {role}"));
            }
        }
    }

    fn inject(&mut self, i: usize) {
        let config = self.config;
        let fault = &config.faults[i];
        let role = inject::target(fault);
        let ns = now_ns();
        self.log.faults[i].injected_ns = Some(ns);
        if !self.processes[role].running() {
            self.note(ns, format!("{}: not injected, {role} is not running", fault.describe()));
            return;
        }
        if let Some((signal, continue_at)) = inject::injection(fault, Instant::now()) {
            let process = &mut self.processes[role];
            process.signal(signal);
            match fault.kind {
                FaultKind::Kill => process.ready = false,
                _ => process.stopped = true,
            }
            self.log.faults[i].continue_at = continue_at;
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
        if !self.processes[Role::Plant].write_line("go") {
            return Some(Outcome::Failed("cannot tell the plant to go on".into()));
        }
        None
    }

    /// Files an event; returns the process whose output ended.
    fn handle(&mut self, event: Event) -> Option<Role> {
        let ChildLine { role, incarnation, line } = match event {
            Event::Child(line) => line,
            Event::Cleaned { role, removed } => {
                self.cleaned(role, removed);
                return None;
            }
        };
        if let Line::Unreadable { line, error } = &line {
            eprintln!("looplab: {role} wrote a line that is not an event ({error}): {line}");
            self.note(now_ns(), format!("{role} wrote a line that is not an event ({error})"));
            return None;
        }
        if incarnation != self.processes[role].incarnation() {
            // A report from an incarnation that has since been replaced.
            match line {
                Line::Event(ChildEvent::StageReport(r)) => {
                    self.reports.stages.entry(role).or_default().insert(incarnation, r);
                }
                Line::Event(ChildEvent::BridgeReport(r)) => {
                    self.reports.bridges.entry(role).or_default().insert(incarnation, r);
                }
                _ => {}
            }
            return None;
        }
        let event = match line {
            Line::Event(event) => event,
            Line::Unreadable { .. } => return None,
            Line::Closed => {
                // Its output ends when it exits: reap it (it may take a moment to go).
                let until = Instant::now() + Duration::from_secs(2);
                while !self.processes[role].try_reap() && Instant::now() < until {
                    std::thread::sleep(Duration::from_millis(1));
                }
                return Some(role);
            }
        };
        match event {
            ChildEvent::Ready => {
                self.processes[role].ready = true;
                self.processes[role].ready_since = Some(Instant::now());
                if incarnation > 0 {
                    let ns = now_ns();
                    if let Some(r) = self.latest_restart(role) {
                        r.ready_ns.get_or_insert(ns);
                    }
                    for i in self.injected(role, FaultKind::Kill) {
                        self.log.faults[i].restarted_ns.get_or_insert(ns);
                    }
                    self.note(ns, format!("{role} ready again"));
                    if role == Role::Plant && !self.processes[role].write_line("start") {
                        self.note(ns, "cannot tell the restarted plant to start".into());
                    }
                }
            }
            ChildEvent::Started { start_ns, .. } => {
                self.log.plant_start_ns.get_or_insert(start_ns);
            }
            ChildEvent::Paused { k } => self.pause_at(k),
            ChildEvent::Stall { process, since_ns, detected_ns } => {
                if let Ok(stalled) = process.parse::<Role>() {
                    for i in self.injected(stalled, FaultKind::Stop) {
                        let seen = &mut self.log.faults[i];
                        if seen.detected_ns.is_none() {
                            seen.detected_ns = Some(detected_ns);
                            seen.detected_by = Some(DetectedBy::InputDeadline);
                        }
                    }
                }
                let waited = (detected_ns.saturating_sub(since_ns)) as f64 / 1e6;
                self.note(detected_ns, format!("{process} stalled: its input has waited {waited:.1} ms"));
            }
            ChildEvent::Resumed { process, at_ns } => {
                if let Ok(resumed) = process.parse::<Role>() {
                    for i in self.injected(resumed, FaultKind::Stop) {
                        let seen = &mut self.log.faults[i];
                        if seen.resumed_ns.is_none() && seen.detected_ns.is_some() {
                            seen.resumed_ns = Some(at_ns);
                        }
                    }
                }
                self.note(at_ns, format!("{process} handles its input again"));
            }
            ChildEvent::LinkLost { at_ns } => {
                for bridge in Role::BRIDGES {
                    for i in self.injected(bridge, FaultKind::Stop) {
                        let seen = &mut self.log.faults[i];
                        if seen.detected_ns.is_none() && seen.continued_ns.is_none() {
                            seen.detected_ns = Some(at_ns);
                            seen.detected_by = Some(DetectedBy::LinkLease);
                        }
                    }
                }
                self.note(at_ns, "link to the other host lost".into());
            }
            ChildEvent::LinkBack { at_ns } => {
                for bridge in Role::BRIDGES {
                    for i in self.injected(bridge, FaultKind::Stop) {
                        let seen = &mut self.log.faults[i];
                        if seen.resumed_ns.is_none() && seen.detected_ns.is_some() {
                            seen.resumed_ns = Some(at_ns);
                        }
                    }
                }
                self.note(at_ns, "link to the other host back".into());
            }
            ChildEvent::Status(status) => {
                self.last_status = Instant::now();
                self.show(&status);
                if let Some(dashboard) = &self.dashboard {
                    dashboard.send(Update::Status(status));
                }
            }
            ChildEvent::PlantReport(r) => self.reports.plant = Some(r),
            ChildEvent::MonitorReport(r) => self.reports.monitor = Some(*r),
            ChildEvent::StageReport(r) => {
                self.reports.stages.entry(role).or_default().insert(incarnation, r);
            }
            ChildEvent::BridgeReport(r) => {
                self.reports.bridges.entry(role).or_default().insert(incarnation, r);
            }
        }
        None
    }

    /// A process's output ended during the run: the run completed (the plant finished), or the
    /// process is restarted, or the run fails. Returns the outcome if the run is over.
    fn ended(&mut self, role: Role) -> Option<Outcome> {
        let ns = now_ns();
        let process = &mut self.processes[role];
        let ran_s = process.ready_since.map(|t| t.elapsed().as_secs_f64());
        process.ready = false;
        process.ready_since = None;
        process.stopped = false;
        if role == Role::Plant {
            // A pause belongs to the plant that asked; its successor asks again at the same tick.
            self.paused = false;
        }
        let process = &self.processes[role];
        let clean = process.ended_cleanly();
        if role == Role::Plant
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
        for i in self.injected(role, FaultKind::Kill) {
            let seen = &mut self.log.faults[i];
            if seen.detected_ns.is_none() {
                seen.detected_ns = Some(ns);
                seen.detected_by = Some(DetectedBy::ProcessExited);
            }
        }
        // Free what the dead process held in shared memory before its successor opens it, on the
        // clean-up thread.
        if let Some(cleaner) = &self.cleaner {
            let _ = cleaner.send(role);
        }
        let process = &mut self.processes[role];
        let death = Death { clean, restarts: process.incarnation(), quick_restarts: process.quick_restarts, ran_s };
        let decision = restart::decide(&process.policy, self.config.supervision.backoff_reset_s, death);
        if let Decision::Restart { backoff, quick_restarts } = decision {
            process.quick_restarts = quick_restarts;
            process.restart = Some(PendingRestart { not_before: Instant::now() + backoff, cleaned: false });
            self.log.restarts.push(RestartRecord {
                process: role,
                incarnation: process.runs.len() as u32,
                backoff,
                died_ns: ns,
                cleaned_ns: None,
                spawned_ns: None,
                ready_ns: None,
            });
            self.note(
                ns,
                format!("{exit}; restart after its clean-up and {:.0} ms of backoff", backoff.as_secs_f64() * 1e3),
            );
            return None;
        }
        let why = format!("{exit}; {}", decision.refusal().expect("a refusal says why"));
        process.gone = true;
        self.note(ns, why.clone());
        if role == Role::Monitor {
            // The loop goes on without its recorder; the report says which loops have none.
            return None;
        }
        Some(Outcome::Failed(format!("{why}; see logs/{role}.log")))
    }

    /// The newest restart of `role`, the one under way.
    fn latest_restart(&mut self, role: Role) -> Option<&mut RestartRecord> {
        self.log.restarts.iter_mut().rev().find(|r| r.process == role)
    }

    /// The clean-up after a death of `role` is done: its restart may go ahead.
    fn cleaned(&mut self, role: Role, removed: u64) {
        let ns = now_ns();
        self.removed_dead_nodes += removed;
        if let Some(restart) = &mut self.processes[role].restart
            && !restart.cleaned
        {
            restart.cleaned = true;
            if let Some(r) = self.latest_restart(role) {
                r.cleaned_ns = Some(ns);
            }
            self.note(ns, format!("{role}: its iceoryx2 resources removed ({removed} dead node(s))"));
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
        let failed: Vec<String> = self.processes.iter().filter(|p| !p.ended_cleanly()).map(|p| p.exit_text()).collect();
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
        if let Some(dashboard) = &self.dashboard {
            dashboard.send(Update::Stopping);
        }
        // A stopped process cannot act on SIGTERM.
        for p in self.processes.iter() {
            p.signal(libc::SIGCONT);
        }
        // The bridges after the stages (the remote one tidies its host up once they are gone),
        // the monitor last.
        let order = Role::STOP_ORDER
            .into_iter()
            .flat_map(|r| if r == Role::Monitor { vec![Role::Bridge, Role::BridgeRemote, r] } else { vec![r] });
        let present: Vec<Role> = order.filter(|r| self.processes.iter().any(|p| p.role == *r)).collect();
        for role in present {
            self.show_processes();
            if self.processes[role].try_reap() {
                continue;
            }
            // After a second stop request, nothing is asked: everything left is killed.
            if !self.stop.urgent() {
                self.processes[role].signal(libc::SIGTERM);
            }
            let timeout = if role == Role::Monitor { MONITOR_STOP_TIMEOUT } else { STOP_TIMEOUT };
            let until = Instant::now() + timeout;
            while !self.processes[role].try_reap() {
                let urgent = self.stop.urgent();
                if urgent || Instant::now() > until {
                    if urgent {
                        eprintln!("looplab: second stop request; killing {role}");
                    } else {
                        eprintln!("looplab: {role} did not stop within {} s; killing it", timeout.as_secs());
                    }
                    self.processes[role].signal(libc::SIGKILL);
                    while !self.processes[role].try_reap() {
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
}

/// The dashboard's fixed lines: the run, and the key signals with their units.
fn dashboard_header(config: &LaunchConfig, scenario: &dyn Scenario) -> dashboard::Header {
    let signals = key_signals(&Layout::new(config, scenario))
        .into_iter()
        .map(|s| dashboard::SignalPlot {
            title: format!("{} [{}]", s.name, s.unit),
            curve: match s.truth {
                Truth::State(_) => "true",
                Truth::Command(_) => "command",
            },
            estimated: s.estimate.is_some(),
        })
        .collect();
    dashboard::Header {
        run: format!("{} · {} · {} Hz", config.scenario, config.mode.name(), config.rate_hz),
        loops_planned: config.loops(),
        signals,
    }
}
