//! The supervision of one run: start every process, wait until all are ready, let the plant
//! start, then handle their events (deaths and restarts, stalls, the status line) until the
//! plant is done, and stop them in order.
//!
//! Here: the run's set-up and tear-down, start-up and the supervision loop. Beside it: the
//! process table (`processes`), what was seen of each fault (`fault_ledger`), fault injection
//! (`injection`), the child events (`events`), deaths and restarts (`deaths`), the ordered stop
//! (`stop`) and what the user sees (`live`).

mod deaths;
mod events;
mod fault_ledger;
mod injection;
mod live;
mod processes;
mod stop;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Result, anyhow};
use crossbeam_channel::{Receiver, RecvTimeoutError, Sender};

use crate::config::launch::{LaunchConfig, Mode};
use crate::contract::clock::now_ns;
use crate::contract::role::Role;
use crate::contract::run_format::files;
use crate::launcher::child::{self, Binaries, ChildArgs, ChildLine, Program, Start};
use crate::launcher::outcome::Exit;
use crate::launcher::outcome::Outcome;
use crate::launcher::probe::Probe;
use crate::launcher::run_dir::{begin_run, new_run_id};
use crate::launcher::sched_trace::{self, SchedTrace, TRACEFS};
use crate::launcher::summary::{self, CpuTimes, Reports, RunLog, SharedMemoryCheck, Summary, SummaryInputs};
use crate::model::scenario::Scenario;
use crate::runtime::signals::StopFlag;
use crate::runtime::storage::run_storage;

use fault_ledger::FaultLedger;
use live::Live;
pub use live::LiveView;
use processes::{Process, Processes};

/// A gap between two turns of the supervision loop longer than this is noted on the timeline.
const LAUNCHER_STALL: Duration = Duration::from_millis(250);
/// Longest wait between two looks at the fault schedule.
const SUPERVISE_TICK: Duration = Duration::from_millis(2);

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
    let decided = config.with_wait_decided(crate::runtime::transport::wait::available_cpus());
    Supervisor::run(&decided, scenario, binaries, run_dir, view)
}

/// The last line of a file that is not blank (a process's log), read from its end.
fn last_line(path: &Path) -> Option<String> {
    use std::io::{Read, Seek, SeekFrom};
    let mut file = std::fs::File::open(path).ok()?;
    let len = file.metadata().ok()?.len();
    file.seek(SeekFrom::Start(len.saturating_sub(4096))).ok()?;
    let mut tail = Vec::new();
    file.read_to_end(&mut tail).ok()?;
    String::from_utf8_lossy(&tail).lines().rev().map(str::trim).find(|l| !l.is_empty()).map(str::to_owned)
}

/// What reaches the supervision loop.
enum Event {
    /// Boxed: a plant's report is large beside the other events.
    Child(Box<ChildLine>),
    /// The clean-up after a death of `role` is done.
    Cleaned { role: Role, removed: u64 },
}

/// Why start-up did not finish.
enum NotReady {
    /// A stop request, or the dashboard's `q`.
    Stopped(Outcome),
    /// The output of this process ended.
    Ended(Role),
    /// These were not ready within `supervision.ready_timeout_s`.
    Late(Vec<Role>),
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
    /// The threads reading each start's output, by role.
    readers: Vec<(Role, std::thread::JoinHandle<()>)>,
    /// What a process left running when it exited (killed since), one line each.
    left_running: Vec<String>,
    reports: Reports,
    /// Restarts and the timeline, for the summary (its faults come from `faults` at the end).
    log: RunLog,
    /// Each fault of the launch file and what was seen of it.
    faults: FaultLedger<'a>,
    /// Lockstep: the plant is paused and waits for `go`.
    paused: bool,
    /// Lockstep: the loop of the newest pause (a stage lost there is lost from that loop on).
    last_pause: Option<u64>,
    /// Lockstep: the faults on the monitor due at the paused loop, held until the monitor has
    /// written and saved every loop before it, so that its successor goes on from there and no
    /// loop is lost: (the loop, when the pause began (ns), the faults).
    monitor_faults_held: Option<(u64, u64, Vec<usize>)>,
    /// Every loop before this one is written and saved by the monitor (its last status).
    monitor_written: u64,
    /// Processes whose output ended, not reaped yet, and when to stop waiting for that. A
    /// dying process can take a while to be reapable (a killed monitor's writer thread, at nice
    /// 19, needs the CPU to exit, hundreds of ms on a busy machine); the supervision goes on
    /// meanwhile instead of waiting for it.
    closing: Vec<(Role, Instant)>,
    /// When the monitor's last heartbeat or status came (CLOCK_MONOTONIC ns).
    monitor_heard_ns: u64,
    removed_dead_nodes: u64,
    stop: StopFlag,
    /// Clean-up requests (a process) for the clean-up thread: iceoryx2's clean-up of a dead
    /// process's resources can wait on the file system, and nothing of the supervision may.
    cleaner: Option<Sender<Role>>,
    live: Live,
    /// `--probe`: the OS's own timer beside the loop, begun at the plant's `started`.
    probe: Option<Probe>,
}

impl<'a> Supervisor<'a> {
    fn run(
        config: &'a LaunchConfig,
        scenario: &dyn Scenario,
        binaries: &'a Binaries,
        run_dir: &Path,
        view: LiveView,
    ) -> Result<(Summary, Outcome)> {
        let (launch_file, started_at) = begin_run(run_dir, config, scenario)?;
        let stop = StopFlag::install()?;
        let live = Live::open(view, config, scenario)?;
        let (tx, events) = crossbeam_channel::unbounded();
        let processes = config
            .hosts
            .processes()
            .into_iter()
            .map(|role| Process::new(role, config.supervision.policy(role)))
            .collect();
        let run_id = new_run_id();
        // The run's private folder; the lock in it says the run is alive until we return.
        let storage_lock = run_storage::create_run_storage(&run_id)?;
        let (cleaner, clean_requests) = crossbeam_channel::unbounded::<Role>();
        let cleaned = tx.clone();
        let clean_run_id = run_id.clone();
        let clean_thread = std::thread::spawn(move || {
            for role in clean_requests {
                let removed = run_storage::remove_dead_nodes(&clean_run_id).unwrap_or(0);
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
            processes: Processes::new(processes),
            tx,
            events,
            readers: vec![],
            left_running: vec![],
            reports: Reports::default(),
            log: RunLog::default(),
            faults: FaultLedger::new(&config.faults),
            paused: false,
            last_pause: None,
            monitor_faults_held: None,
            monitor_written: 0,
            closing: vec![],
            monitor_heard_ns: now_ns(),
            removed_dead_nodes: 0,
            stop,
            cleaner: Some(cleaner),
            live,
            probe: (config.probe && config.mode == Mode::Realtime).then(|| Probe::start(config)),
        };
        let cpu_at_start = CpuTimes::now();
        // Recording before any process starts, so that every loop's waits are in it.
        let sched_trace =
            config.trace_sched.then(|| SchedTrace::start(Path::new(TRACEFS), &supervisor.run_id, config.duration_s));
        let spawned = supervisor.start_all();
        let outcome = match spawned {
            Ok(()) => supervisor.supervise(),
            Err(e) => Outcome::Failed(format!("{e:#}")),
        };
        supervisor.stop_all();
        let probe = supervisor.probe.take().map(Probe::finish);
        supervisor.live.close();
        let outcome = match outcome {
            Outcome::Completed => supervisor.check_ends(),
            other => other,
        };
        let (tx, _) = crossbeam_channel::unbounded();
        drop(std::mem::replace(&mut supervisor.tx, tx));
        supervisor.join_readers();
        supervisor.cleaner = None;
        let _ = clean_thread.join();
        let mut cleanup = run_storage::clean_up_run(&supervisor.run_id)?;
        // A plant that died with its FMU unpacked left the folder behind.
        crate::scenarios::declared::fmu::remove_abandoned_unpack_folders();
        // The other host's bridge tidied its host up last and said what it left there.
        if let Some(remote) = supervisor.reports.bridges.get(&Role::BridgeRemote).and_then(|r| r.values().last()) {
            cleanup.leftover.extend(remote.leftover.iter().map(|f| format!("{f} (on the other host)")));
        }
        drop(storage_lock);
        let starts: BTreeMap<Role, Vec<Start>> =
            supervisor.processes.iter().map(|p| (p.role, p.runs.clone())).collect();
        supervisor.log.faults = supervisor.faults.seen().to_vec();
        let mut summary = summary::build(SummaryInputs {
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
                foreign: cleanup.foreign,
            },
        });
        summary.notes.extend(supervisor.left_running.iter().cloned());
        summary.probe = probe;
        summary.steal_share = cpu_at_start.zip(CpuTimes::now()).and_then(|(start, end)| start.steal_share_until(end));
        if let Some(trace) = sched_trace {
            let pids = starts.iter().map(|(role, runs)| (*role, runs.iter().map(|r| r.pid).collect())).collect();
            let named = trace
                .map_err(anyhow::Error::msg)
                .and_then(|trace| trace.finish(run_dir))
                .and_then(|trace| sched_trace::name_who_ran(&mut summary, &trace, run_dir, &pids));
            if let Err(e) = named {
                summary.notes.insert(0, format!("{e:#}"));
            }
        }
        // A summary that cannot be written (a full disk, the folder removed) does not hide why
        // the run ended: the report is still printed, with both.
        let outcome = match (summary::write(&summary, run_dir), outcome) {
            (Ok(()), outcome) => outcome,
            (Err(e), Outcome::Failed(why)) => Outcome::Failed(format!("{why}; and {e:#}")),
            (Err(e), _) => Outcome::Failed(format!("{e:#}")),
        };
        Ok((summary, outcome))
    }

    /// Starts every process. The other host's bridge goes first, and alone: it makes the run's
    /// folder on its host, where the stages placed there need it.
    fn start_all(&mut self) -> Result<()> {
        for role in self.config.hosts.processes() {
            self.spawn(role)?;
            if role == Role::BridgeRemote {
                self.wait_ready(&[role]).map_err(|not| match not {
                    NotReady::Stopped(_) => anyhow!("stopped while {role} started"),
                    NotReady::Ended(ended) => anyhow!(self.ended_in_start_up(ended)),
                    NotReady::Late(late) => anyhow!(self.not_ready(&late)),
                })?;
            }
        }
        Ok(())
    }

    /// Handles events until every process of `roles` is ready (start-up, before the supervision
    /// loop).
    fn wait_ready(&mut self, roles: &[Role]) -> Result<(), NotReady> {
        let deadline = Instant::now() + Duration::from_secs_f64(self.config.supervision.ready_timeout_s);
        loop {
            let late: Vec<Role> = roles.iter().copied().filter(|&r| !self.processes[r].ready).collect();
            if late.is_empty() {
                return Ok(());
            }
            self.show_processes();
            if let Some(outcome) = self.stop_outcome() {
                return Err(NotReady::Stopped(outcome));
            }
            match self.events.recv_timeout(Duration::from_millis(50)) {
                Ok(event) => {
                    if let Some(ended) = self.handle(event) {
                        self.reap_within(ended, events::REAP_WAIT);
                        return Err(NotReady::Ended(ended));
                    }
                }
                Err(_) if Instant::now() > deadline => return Err(NotReady::Late(late)),
                Err(_) => {}
            }
            if let Some(&ended) = self.exited_with_output_held().first() {
                self.reap_within(ended, events::REAP_WAIT);
                return Err(NotReady::Ended(ended));
            }
        }
    }

    fn ended_in_start_up(&self, role: Role) -> String {
        format!("{} during start-up{}; {}", self.processes[role].exit_text(), self.last_words(role), self.see_log(role))
    }

    /// Where to look for why `role` ended: its log, or, where that is empty (a crash before it
    /// could write a word), that it is.
    pub(super) fn see_log(&self, role: Role) -> String {
        let log = files::log(role);
        match std::fs::symlink_metadata(self.run_dir.join(&log)) {
            Ok(meta) if meta.len() == 0 => format!("{log} is empty: it wrote nothing before it ended"),
            _ => format!("see {log}"),
        }
    }

    /// Why start-up timed out: who was late. A stage of the user's own that never said ready
    /// is the cause (the processes that wait for its topic are late because of it): its command.
    fn not_ready(&self, late: &[Role]) -> String {
        let timeout = self.config.supervision.ready_timeout_s;
        let own: Vec<String> = late
            .iter()
            .filter_map(|&role| self.config.stages.command(role).map(|stage| (role, stage)))
            .map(|(role, stage)| {
                format!(
                    "{role}: the command `{}` (started in {}) never said ready; it must hand its step to \
                     LoopLab's runner (looplab.run, looplab_run, run_step); its stderr is in logs/{role}.log",
                    stage.text(),
                    stage.dir.display()
                )
            })
            .collect();
        if own.is_empty() {
            let names: Vec<&str> = late.iter().map(|r| r.name()).collect();
            format!("not ready after {timeout} s (supervision.ready_timeout_s): {}", names.join(", "))
        } else {
            format!("not ready after {timeout} s (supervision.ready_timeout_s): {}", own.join("; "))
        }
    }

    /// The last line `role` wrote on stderr (`": <line>"`), if it failed: a user's stage that
    /// raised says what.
    pub(super) fn last_words(&self, role: Role) -> String {
        let failed = matches!(self.processes[role].runs.last().map(|r| r.exit), Some(Exit::Status(code)) if code != 0);
        match last_line(&self.run_dir.join(files::log(role))).filter(|_| failed) {
            Some(line) => format!(": {line}"),
            None => String::new(),
        }
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
        let program = match self.config.stages.command(role) {
            Some(stage) => Program::Stage(stage),
            None => Program::Binary(&binary),
        };
        let spawned = child::spawn(role, program, &args, self.tx.clone(), |line| Event::Child(Box::new(line)))?;
        self.readers.push((role, spawned.reader));
        self.processes[role].started(spawned.start, spawned.stdin);
        Ok(())
    }

    /// Notes `event` on the timeline, at `ns`.
    fn note(&mut self, ns: u64, event: String) {
        self.log.note(ns, event);
        if let Some(entry) = self.log.timeline.last() {
            self.live.event(entry);
        }
    }

    /// The user quit the dashboard, or a signal asked to stop.
    fn stop_outcome(&self) -> Option<Outcome> {
        if self.stop.requested() {
            Some(Outcome::Interrupted)
        } else if self.live.quit_asked() {
            Some(Outcome::Quit)
        } else {
            None
        }
    }

    /// Sends the dashboard the processes' states when they changed.
    fn show_processes(&mut self) {
        self.live.processes(self.processes.rows());
    }

    fn supervise(&mut self) -> Outcome {
        // Start-up: every process, the monitor included, has its ports before the first sample.
        match self.wait_ready(&self.config.hosts.processes()) {
            Ok(()) => {}
            Err(NotReady::Stopped(outcome)) => return outcome,
            Err(NotReady::Ended(role)) => return Outcome::Failed(self.ended_in_start_up(role)),
            Err(NotReady::Late(late)) => return Outcome::Failed(self.not_ready(&late)),
        }
        if !self.processes[Role::Plant].write_line("start") {
            return Outcome::Failed("cannot tell the plant to start".into());
        }
        self.monitor_heard_ns = now_ns();

        let mut last_turn = Instant::now();
        loop {
            // A launcher that did not run (stopped, or starved of CPU) injects late: say so.
            let gap = last_turn.elapsed();
            last_turn = Instant::now();
            if gap > LAUNCHER_STALL {
                let ms = gap.as_secs_f64() * 1e3;
                self.note(now_ns(), format!("the launcher did not run for {ms:.0} ms (stopped or starved of CPU)"));
            }
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
                    if let Some(role) = self.handle(event) {
                        self.closed(role);
                    }
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return Outcome::Failed("lost every process's output".into()),
            }
            for role in self.reaped() {
                if let Some(outcome) = self.ended(role) {
                    return outcome;
                }
            }
        }
    }

    /// Injects the faults that are due (real time), continues stopped processes, restarts the
    /// dead ones whose clean-up and backoff are over, and watches the monitor's heartbeat. Returns
    /// the outcome if a restart failed and the run cannot go on.
    fn due_actions(&mut self) -> Option<Outcome> {
        let now = now_ns();
        self.inject_due_by_time();
        self.inject_held_monitor_faults(now);
        self.continue_stopped(now);
        self.continue_past_run_end(now);
        self.kill_hung(now);
        if let Some(outcome) = self.lockstep_plant_stall(now) {
            return Some(outcome);
        }
        if let Some(outcome) = self.start_due_restarts(now) {
            return Some(outcome);
        }
        self.watch_monitor_heartbeat();
        None
    }

    /// Lockstep: once the faults due at the paused tick are in and every process is back up,
    /// lets the plant go on.
    fn release_pause(&mut self) -> Option<Outcome> {
        if !self.paused || self.monitor_faults_held.is_some() || !self.processes.all_up() {
            return None;
        }
        self.paused = false;
        // The plant waited for the pause, not inside its own code: a hang is timed from now.
        self.processes[Role::Plant].time_hang_from(now_ns());
        if !self.processes[Role::Plant].write_line("go") {
            return Some(Outcome::Failed("cannot tell the plant to go on".into()));
        }
        None
    }
}
