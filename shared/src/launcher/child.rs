//! The loop's processes as children: finding their binaries, starting one supervised, reading
//! its event lines, and reaping it with its exit status and CPU time.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{ChildStdin, Stdio};

use anyhow::{Context as _, Result, anyhow, bail};
use crossbeam_channel::Sender;

use crate::config::stages::StageCommand;
use crate::contract::protocol::{ChildEvent, ProcessArgs};
use crate::contract::role::Role;
use crate::contract::run_format::files;
use crate::launcher::outcome::Exit;

/// The loop's binaries by role.
pub type Binaries = BTreeMap<Role, PathBuf>;

/// The five loop binaries, next to this one.
/// The loop process's binary, beside the launcher: `looplab-<role>`, so that an installed
/// LoopLab cannot shadow a system tool (lm-sensors has a `sensors`).
pub fn binary_name(role: Role) -> String {
    match role {
        Role::Bridge | Role::BridgeRemote => "looplab-bridge".into(),
        _ => format!("looplab-{}", role.name()),
    }
}

pub fn locate_binaries() -> Result<Binaries> {
    let exe = std::env::current_exe().context("cannot find the looplab executable")?;
    let dir = exe.parent().ok_or_else(|| anyhow!("{} has no parent folder", exe.display()))?;
    build_siblings_under_cargo(dir)?;
    let mut found = BTreeMap::new();
    for role in Role::START_ORDER {
        let path = dir.join(binary_name(role));
        if !path.is_file() {
            bail!(
                "missing binary {}: the loop processes are built with the launcher; run `cargo build --release` \
                 (or start with `cargo run --release`)",
                path.display()
            );
        }
        found.insert(role, path);
    }
    Ok(found)
}

/// The bridge's binary, beside the launcher's, for a run with a stage on another host. It is a
/// package of its own (zenoh is built only for it), so under `cargo run` it is built now.
pub fn locate_bridge() -> Result<PathBuf> {
    let exe = std::env::current_exe().context("cannot find the looplab executable")?;
    let dir = exe.parent().ok_or_else(|| anyhow!("{} has no parent folder", exe.display()))?;
    if let Some(mut cargo) = cargo_build(dir) {
        tell!("looplab: a stage runs on another host; building the bridge (the first build takes minutes)");
        let status = cargo.args(["-p", "looplab-bridge"]).status().context("cannot run cargo to build the bridge")?;
        if !status.success() {
            bail!("building the bridge failed ({status})");
        }
    }
    let path = dir.join(binary_name(Role::Bridge));
    if !path.is_file() {
        bail!(
            "missing binary {}: a stage on another host needs the bridge; run `cargo build --release -p looplab-bridge`",
            path.display()
        );
    }
    Ok(path)
}

/// `cargo build` with this binary's profile and target folder, when we were started by cargo.
fn cargo_build(exe_dir: &Path) -> Option<std::process::Command> {
    let (Ok(cargo), Ok(manifest_dir)) = (std::env::var("CARGO"), std::env::var("CARGO_MANIFEST_DIR")) else {
        return None;
    };
    let profile_dir = exe_dir.file_name().and_then(|n| n.to_str()).unwrap_or("debug");
    let profile = if profile_dir == "debug" { "dev" } else { profile_dir };
    let target_dir = exe_dir.parent().unwrap_or(exe_dir);
    let mut command = std::process::Command::new(cargo);
    command
        .args(["build", "--quiet", "--profile", profile, "--manifest-path"])
        .arg(Path::new(&manifest_dir).join("Cargo.toml"))
        .arg("--target-dir")
        .arg(target_dir);
    Some(command)
}

/// `cargo run` builds only the binary it runs. When we were started by it, ask the same cargo
/// to build the loop binaries too, with the same profile and target folder, so that they are
/// never missing or stale.
fn build_siblings_under_cargo(exe_dir: &Path) -> Result<()> {
    let Some(mut cargo) = cargo_build(exe_dir) else { return Ok(()) };
    let status = cargo.arg("--bins").status().context("cannot run cargo to build the loop processes")?;
    if !status.success() {
        bail!("building the loop processes failed ({status})");
    }
    Ok(())
}

/// Makes `command` a child that this process stops: in a session of its own, so that a Ctrl-C
/// in the terminal reaches only us and we stop the children in order, and so that what it starts
/// can be found and stopped when it exits; and asked to stop (SIGTERM) if we die, so that nothing
/// is orphaned.
pub fn supervised(command: &mut std::process::Command) {
    let parent = std::process::id() as libc::pid_t;
    // SAFETY: setsid, prctl and getppid are async-signal-safe. If the parent died before prctl
    // took effect, the child does not start at all.
    unsafe {
        command.pre_exec(move || {
            if libc::setsid() < 0 {
                return Err(std::io::Error::last_os_error());
            }
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
            if libc::getppid() != parent {
                return Err(std::io::Error::other("the parent is gone"));
            }
            Ok(())
        });
    }
}

/// `program` run through `prefix` (the command that runs it on its host), or directly.
fn prefixed(prefix: &[String], program: &std::ffi::OsStr) -> std::process::Command {
    match prefix.split_first() {
        Some((first, rest)) => {
            let mut command = std::process::Command::new(first);
            command.args(rest).arg(program);
            command
        }
        None => std::process::Command::new(program),
    }
}

/// One start of a process.
#[derive(Debug, Clone, PartialEq)]
pub struct Start {
    pub pid: u32,
    pub exit: Exit,
    /// User + system CPU seconds, once reaped.
    pub cpu_s: f64,
    /// Times it slept and was woken (voluntary context switches), once reaped.
    pub wakeups: u64,
    /// Times another task took its CPU while it could run (involuntary context switches).
    pub preemptions: u64,
    /// The processes of its session still running when it exited (what it started and
    /// left behind, `pid 123 (sleep)`): killed then, and said.
    pub left_running: Vec<String>,
}

impl Start {
    pub fn running(pid: u32) -> Start {
        Start { pid, exit: Exit::Running, cpu_s: 0.0, wakeups: 0, preemptions: 0, left_running: vec![] }
    }

    /// Reaps it if it has exited (without blocking), with its CPU time; true once it is reaped.
    pub fn try_reap(&mut self) -> bool {
        if self.exit != Exit::Running {
            return true;
        }
        if !self.has_exited() {
            return false;
        }
        // Its pid is not reaped yet, so its session's id cannot have been reused.
        self.left_running = kill_session_members(self.pid);
        let mut status = 0;
        // SAFETY: plain wait4 on our own child; rusage is a valid out-parameter.
        let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
        let pid = unsafe { libc::wait4(self.pid as i32, &mut status, libc::WNOHANG, &mut usage) };
        if pid != self.pid as i32 {
            return false;
        }
        self.cpu_s = crate::contract::clock::cpu_seconds(&usage);
        (self.wakeups, self.preemptions) = (usage.ru_nvcsw as u64, usage.ru_nivcsw as u64);
        self.exit = if libc::WIFEXITED(status) {
            Exit::Status(libc::WEXITSTATUS(status))
        } else {
            Exit::Signal(libc::WTERMSIG(status))
        };
        true
    }

    /// Whether it has exited, asked without reaping it.
    pub fn has_exited(&self) -> bool {
        if self.exit != Exit::Running {
            return true;
        }
        // SAFETY: waitid on our own unreaped child; info is a valid out-parameter. WNOWAIT leaves
        // it a zombie.
        unsafe {
            let mut info: libc::siginfo_t = std::mem::zeroed();
            let waited = libc::waitid(libc::P_PID, self.pid, &mut info, libc::WEXITED | libc::WNOHANG | libc::WNOWAIT);
            waited == 0 && info.si_pid() != 0
        }
    }

    /// Sends `signal` unless it has been reaped.
    pub fn signal(&self, signal: i32) {
        if self.exit == Exit::Running {
            // SAFETY: the pid is our unreaped child, so it cannot have been reused.
            unsafe { libc::kill(self.pid as i32, signal) };
        }
    }
}

/// Kills what is left of session `sid` (a child's, started by `supervised`) but its leader, and
/// says what that was: a stage's background child would otherwise outlive the run, and one that
/// holds the stage's output would keep the launcher reading it.
fn kill_session_members(sid: u32) -> Vec<String> {
    let mut killed = vec![];
    // A member may fork while it is being killed: look again until none is left.
    for _ in 0..8 {
        let members = session_members(sid);
        if members.is_empty() {
            break;
        }
        for (pid, comm) in members {
            // SAFETY: plain kill of a process seen in the session; the session's id stays
            // reserved while its leader is unreaped.
            unsafe { libc::kill(pid as libc::pid_t, libc::SIGKILL) };
            let seen = format!("pid {pid} ({comm})");
            if !killed.contains(&seen) {
                killed.push(seen);
            }
        }
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    killed
}

/// The processes of session `sid` other than its leader, by pid with their names.
fn session_members(sid: u32) -> Vec<(u32, String)> {
    let Ok(entries) = std::fs::read_dir("/proc") else { return vec![] };
    let mut members: Vec<(u32, String)> = entries
        .flatten()
        .filter_map(|entry| entry.file_name().to_str()?.parse::<u32>().ok())
        .filter(|&pid| pid != sid)
        .filter_map(|pid| {
            let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
            // `pid (comm) state ppid pgrp session …`; comm may hold spaces and parentheses.
            let (head, tail) = stat.rsplit_once(')')?;
            let comm = head.split_once('(')?.1;
            let mut fields = tail.split_whitespace();
            let state = fields.next()?;
            let session: u32 = fields.nth(2)?.parse().ok()?;
            // A zombie is dead already; its parent reaps it.
            (session == sid && state != "Z").then(|| (pid, comm.to_owned()))
        })
        .collect();
    members.sort();
    members
}

/// One line of a child's output, or its end.
#[derive(Debug)]
pub enum Line {
    Event(ChildEvent),
    /// A line that is not an event.
    Unreadable {
        line: String,
        error: String,
    },
    /// Its output ended: it is exiting.
    Closed,
}

/// What a child said, and which start of which process said it.
#[derive(Debug)]
pub struct ChildLine {
    pub role: Role,
    pub incarnation: u32,
    pub line: Line,
}

/// What a loop process is started with (see `contract::protocol::ProcessArgs`).
pub struct ChildArgs<'a> {
    pub launch_file: &'a Path,
    pub run_id: &'a str,
    pub run_dir: &'a Path,
    pub incarnation: u32,
    /// The command that runs it on its host (`hosts.<name>.command`); empty here.
    pub prefix: &'a [String],
}

/// A started child: its start, its stdin (the plant's only), and the thread that reads it.
pub struct Spawned {
    pub start: Start,
    pub stdin: Option<ChildStdin>,
    pub reader: std::thread::JoinHandle<()>,
}

/// What runs a loop process: LoopLab's binary, or a stage of the user's own.
#[derive(Clone, Copy)]
pub enum Program<'a> {
    Binary(&'a Path),
    /// Started in its folder, with the run's arguments in its environment.
    Stage(&'a StageCommand),
}

/// Starts `role` from `program` with its stderr appended to `logs/<role>.log`; every line of its
/// stdout goes to `lines`, as `into` makes it, then `Closed`.
pub fn spawn<E: Send + 'static>(
    role: Role,
    program: Program,
    args: &ChildArgs,
    lines: Sender<E>,
    into: fn(ChildLine) -> E,
) -> Result<Spawned> {
    let log_path = args.run_dir.join(files::log(role));
    // A restarted process appends to its log.
    let log = crate::runtime::storage::run_file::open(&log_path, crate::runtime::storage::run_file::Existing::Append)?;
    let process_args = ProcessArgs {
        launch: args.launch_file.to_path_buf(),
        run_id: args.run_id.to_owned(),
        run_dir: args.run_dir.to_path_buf(),
        incarnation: args.incarnation,
    };
    let (mut command, what) = match program {
        Program::Binary(binary) => {
            let mut command = prefixed(args.prefix, binary.as_os_str());
            if Role::BRIDGES.contains(&role) {
                command.arg("--role").arg(role.name());
            }
            command
                .arg("--launch")
                .arg(args.launch_file)
                .arg("--run-id")
                .arg(args.run_id)
                .arg("--run-dir")
                .arg(args.run_dir)
                .arg("--incarnation")
                .arg(args.incarnation.to_string());
            (command, binary.display().to_string())
        }
        Program::Stage(stage) => {
            // The stage starts in its own folder: the run's paths must not be relative to ours.
            let absolute = |path: &Path| std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
            let env = ProcessArgs {
                launch: absolute(&process_args.launch),
                run_dir: absolute(&process_args.run_dir),
                ..process_args
            }
            .to_env(role.name());
            let command = if args.prefix.is_empty() {
                let mut command = std::process::Command::new(&stage.command[0]);
                command.args(&stage.command[1..]).current_dir(&stage.dir).envs(env);
                command
            } else {
                // On another host the prefix runs `env`, which sets the folder and the variables
                // there (a prefix such as ssh passes neither).
                let mut command = prefixed(args.prefix, "env".as_ref());
                command.arg("-C").arg(&stage.dir);
                command.args(env.iter().map(|(k, v)| format!("{k}={v}"))).args(&stage.command);
                command
            };
            (command, format!("`{}` (in {})", stage.text(), stage.dir.display()))
        }
    };
    command.stdin(if role == Role::Plant { Stdio::piped() } else { Stdio::null() }).stdout(Stdio::piped()).stderr(log);
    supervised(&mut command);
    let mut child = command.spawn().with_context(|| match args.prefix.first() {
        Some(prefix) => format!("cannot start {what} with {prefix}"),
        None => format!("cannot start {what}"),
    })?;
    let stdout = child.stdout.take().expect("stdout is piped");
    let incarnation = args.incarnation;
    let reader = std::thread::spawn(move || {
        let send = |line| lines.send(into(ChildLine { role, incarnation, line }));
        for text in BufReader::new(stdout).lines().map_while(Result::ok) {
            let _ = send(match serde_json::from_str::<ChildEvent>(&text) {
                Ok(event) => Line::Event(event),
                Err(e) => Line::Unreadable { line: text, error: e.to_string() },
            });
        }
        let _ = send(Line::Closed);
    });
    Ok(Spawned { start: Start::running(child.id()), stdin: child.stdin.take(), reader })
}
