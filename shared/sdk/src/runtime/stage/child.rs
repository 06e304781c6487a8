//! What every loop process shares: its arguments, its context, its `main`, and how it waits on
//! its iceoryx2 WaitSet. Each binary in `services/` is one call into here.

use std::io::Write;
use std::path::Path;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context as _, Result, anyhow};
use iceoryx2::prelude::*;

use crate::config::launch::LaunchConfig;
use crate::contract::protocol::{ChildEvent, ProcessArgs};
use crate::contract::role::Role;
use crate::runtime::signals::StopFlag;
use crate::runtime::transport::ipc::Ipc;

/// Longest a wait blocks before it looks at the stop flag again (a signal also ends it early).
pub const WAIT_SLICE: Duration = Duration::from_millis(100);

/// What every loop process starts with.
pub struct Context {
    pub config: LaunchConfig,
    pub ipc: Ipc,
    pub stop: StopFlag,
    pub run_dir: std::path::PathBuf,
    pub run_id: String,
    /// 0 for the first start of this process, then one more per restart.
    pub incarnation: u32,
}

/// A loop process's `main`: parses the arguments, loads the run's launch file (its scenario
/// from `catalog`) and connects to iceoryx2, runs `body`, and turns a failure into a message on
/// stderr and exit code 1. LoopLab's own binaries (`services/`) pass `scenarios::builtin()`.
///
/// A crate of its own with its own scenarios builds the same six binaries as `services/`, each
/// with the same catalog (for example `scenarios::builtin().with(MY_ENTRY)`):
/// - the launcher, any name: `fn main() -> ExitCode { looplab_shared::cli::main_with(&catalog()) }`;
/// - the five loop processes, named `looplab-plant`, `looplab-sensors`, `looplab-estimator`,
///   `looplab-controller` and `looplab-monitor`, each
///   `process_main_with(Role::Plant, runtime::builtin::plant, &catalog())` with its role and body
///   (`runtime::builtin::{sensors, estimator, controller}`, `monitor::run`; both in
///   `looplab_shared`), as in `services/`.
///
/// The launcher starts the loop processes found beside its own executable
/// (`launcher::locate_binaries`), so all six must be built into one folder (one package's
/// `[[bin]]`s do; under `cargo run` the launcher builds its package's binaries first). Every
/// process must get the same catalog: each reads the run's launch file by scenario name.
#[cfg(feature = "cli")]
pub fn process_main_with(
    role: Role,
    body: fn(&Context, &dyn crate::model::scenario::Scenario) -> Result<ChildEvent>,
    catalog: &crate::model::catalog::Catalog,
) -> ExitCode {
    use crate::contract::msg::layout_fingerprint;
    use clap::Parser;
    let load = |launch: &Path| Ok(catalog.load_resolved(launch)?);
    run_process_as(role, &ProcessArgs::parse(), layout_fingerprint(), load, |context, scenario| {
        body(context, scenario.as_ref())
    })
}

/// Connects the process of `role` to its run as `args` say (its launch file read by `load`,
/// which gives the configuration and what else the process needs of it), runs `body`, reports
/// what it returns, and tidies up. `layout`: the fingerprint of the message layouts this process
/// was built with (a user's stage may come from another build, and a test plays one).
pub fn run_process_as<T>(
    role: Role,
    args: &ProcessArgs,
    layout: &str,
    load: impl FnOnce(&Path) -> Result<(LaunchConfig, T)>,
    body: impl FnOnce(&Context, T) -> Result<ChildEvent>,
) -> ExitCode {
    let name = role.name();
    // SAFETY: getppid has no preconditions.
    let launcher = unsafe { libc::getppid() };
    let result = (|| -> Result<()> {
        let stop = StopFlag::install()?;
        let (config, loaded) = load(&args.launch)?;
        // Before any thread starts, so that they all inherit it; the monitor stays low.
        if role.in_loop() {
            crate::runtime::stage::realtime::apply(&config.realtime)?;
        }
        let ipc = Ipc::with_layout(name, &args.run_id, config.mode, layout)?;
        let context = Context {
            config,
            ipc,
            stop,
            run_dir: args.run_dir.clone(),
            run_id: args.run_id.clone(),
            incarnation: args.incarnation,
        };
        let report = body(&context, loaded)?;
        emit(&report)
    })();
    // Our node is gone now. If the launcher died (we were stopped by PR_SET_PDEATHSIG), nobody
    // else will tidy up: the last process of the run to go removes what is left of it. The others
    // are exiting at the same moment, so each waits a little for them to go (a frozen one never
    // goes: `looplab clean`, and every `looplab run`, removes the run once its launcher is gone).
    // SAFETY: as above.
    if unsafe { libc::getppid() } != launcher {
        let until = std::time::Instant::now() + std::time::Duration::from_secs(2);
        // An error (another process removing the run's files at the same moment) is tried
        // again too: it must not end the last process's clean-up.
        let cleaned = || {
            crate::runtime::storage::run_storage::files_of_run(&args.run_id).is_empty()
                || crate::runtime::storage::run_storage::clean_up_run(&args.run_id).is_ok_and(|c| c.leftover.is_empty())
        };
        while !cleaned() && std::time::Instant::now() < until {
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
    }
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // Not eprintln: its log may be on the disk that is full, and the exit status must
            // still say why.
            tell!("{name}: error: {e:#}");
            let disk_full = e.chain().any(|c| {
                c.downcast_ref::<std::io::Error>().is_some_and(|io| io.kind() == std::io::ErrorKind::StorageFull)
            });
            if disk_full { ExitCode::from(crate::contract::protocol::EXIT_DISK_FULL) } else { ExitCode::FAILURE }
        }
    }
}

pub fn waitset() -> Result<WaitSet<ipc::Service>> {
    WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| anyhow!("cannot create a WaitSet: {e:?}"))
}

/// Blocks until the WaitSet has an event, the slice ends, or a signal arrives.
pub fn wait(ws: &WaitSet<ipc::Service>) -> Result<()> {
    ws.wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, WAIT_SLICE)
        .map(|_| ())
        .map_err(|e| anyhow!("WaitSet wait failed: {e:?}"))
}

/// Where the event lines go when stdout is not theirs (see [`keep_stdout_for_events`]).
static EVENTS: std::sync::OnceLock<std::sync::Mutex<std::fs::File>> = std::sync::OnceLock::new();

/// Keeps the launcher's pipe for the event lines alone and sends whatever else the process
/// writes on stdout (a user's `print` in their stage) to its stderr, its log: a stray line on
/// the pipe would be read as a broken event.
pub fn keep_stdout_for_events() -> Result<()> {
    use std::os::fd::FromRawFd;
    // SAFETY: dup and dup2 on the process's own standard descriptors; the duplicate is owned by
    // the File from here on.
    let events = unsafe { libc::dup(1) };
    if events < 0 || unsafe { libc::dup2(2, 1) } < 0 {
        return Err(std::io::Error::last_os_error()).context("keep stdout for the event lines");
    }
    let _ = EVENTS.set(std::sync::Mutex::new(unsafe { std::fs::File::from_raw_fd(events) }));
    Ok(())
}

/// Writes one event line on stdout for the launcher.
pub fn emit(event: &ChildEvent) -> Result<()> {
    let line = serde_json::to_string(event).context("encode event")?;
    let write = |out: &mut dyn Write| writeln!(out, "{line}").and_then(|_| out.flush());
    let written = match EVENTS.get() {
        Some(events) => write(&mut *events.lock().unwrap_or_else(|e| e.into_inner())),
        None => write(&mut std::io::stdout().lock()),
    };
    written.context("write event to the launcher")
}

/// Writes `event` only if the launcher's pipe has room now: for what is only shown (the monitor's
/// status line), which must never make its writer wait for a launcher that is stopped or slow.
/// Returns whether it was written.
pub fn emit_if_room(event: &ChildEvent) -> Result<bool> {
    let mut pfd = libc::pollfd { fd: 1, events: libc::POLLOUT, revents: 0 };
    // SAFETY: one valid pollfd, no wait.
    let ready = unsafe { libc::poll(&mut pfd, 1, 0) };
    if ready <= 0 || pfd.revents & libc::POLLOUT == 0 {
        return Ok(false);
    }
    emit(event).map(|()| true)
}

/// Blocks until the launcher writes `expected` as a line on stdin. Returns false if a stop was
/// requested or the launcher went away first.
pub fn wait_for_line(stop: &StopFlag, expected: &str) -> Result<bool> {
    Ok(wait_for_lines(stop, &[expected])?.is_some())
}

/// Blocks until the launcher writes one of `expected` as a line on stdin; returns it. None if
/// a stop was requested or the launcher went away first.
pub fn wait_for_lines<'a>(stop: &StopFlag, expected: &[&'a str]) -> Result<Option<&'a str>> {
    while !stop.requested() {
        match read_line(100) {
            StdinLine::Line(line) => {
                if let Some(found) = expected.iter().find(|e| e.as_bytes() == line) {
                    return Ok(Some(found));
                }
            }
            StdinLine::Nothing => {}
            StdinLine::Closed => return Ok(None),
        }
    }
    Ok(None)
}

/// Whether the launcher has written `expected` on stdin, without waiting if nothing is there.
/// Other lines are read and dropped.
pub fn line_written(expected: &str) -> bool {
    loop {
        match read_line(0) {
            StdinLine::Line(line) if line == expected.as_bytes() => return true,
            StdinLine::Line(_) => {}
            StdinLine::Nothing | StdinLine::Closed => return false,
        }
    }
}

enum StdinLine {
    Line(Vec<u8>),
    /// Nothing within the wait.
    Nothing,
    /// The launcher closed our stdin.
    Closed,
}

/// One line from stdin, if one begins within `timeout_ms` (the launcher writes whole lines).
fn read_line(timeout_ms: i32) -> StdinLine {
    let mut pfd = libc::pollfd { fd: 0, events: libc::POLLIN, revents: 0 };
    // SAFETY: one valid pollfd; a signal makes poll return early, which the callers handle.
    let ready = unsafe { libc::poll(&mut pfd, 1, timeout_ms) };
    if ready <= 0 {
        return StdinLine::Nothing;
    }
    let mut line = Vec::new();
    loop {
        let mut byte = [0u8; 1];
        // SAFETY: reads one byte from stdin into a buffer we own.
        let n = unsafe { libc::read(0, byte.as_mut_ptr().cast(), 1) };
        if n <= 0 {
            return StdinLine::Closed;
        }
        if byte[0] == b'\n' {
            return StdinLine::Line(line);
        }
        line.push(byte[0]);
    }
}
