//! `[realtime]` applied: each loop process sets its own priority and locks its memory as it
//! starts; the launcher first checks that the machine permits it (so that a refusal is one line
//! before anything starts, not a start-up failure), and reads back what each process really got.

use anyhow::{Context, Result, bail};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::config::launch::{LaunchConfig, Mode};
use crate::config::realtime::RealtimeSettings;
use crate::config::wait::{CPUS_TO_POLL, LockstepWait, Strategy};
use crate::contract::role::Role;

/// Capability bits (linux/capability.h).
const CAP_IPC_LOCK: u32 = 14;
const CAP_SYS_NICE: u32 = 23;

/// Gives the calling process the priority and memory locking `settings` ask for. Called by a
/// loop process before it starts any thread, so that its threads inherit the policy.
pub fn apply(settings: &RealtimeSettings) -> Result<()> {
    if let Some(priority) = settings.priority {
        let param = libc::sched_param { sched_priority: priority as i32 };
        // SAFETY: pid 0 is the calling thread; `param` is a valid sched_param.
        if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) } != 0 {
            return Err(std::io::Error::last_os_error())
                .with_context(|| format!("cannot set SCHED_FIFO priority {priority} (realtime.priority)"));
        }
    }
    // SAFETY: mlockall takes plain flags.
    if settings.mlock && unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } != 0 {
        return Err(std::io::Error::last_os_error()).context("cannot lock the process's memory (realtime.mlock)");
    }
    Ok(())
}

/// Why the loop's processes could not be given what `[realtime]` asks, on this machine with
/// `cpus` CPUs: a missing permission, or a polling wait that a real-time priority would turn
/// into a CPU taken from everything else. `None` when it can be applied. Returns the key and the
/// reason.
pub fn refusal(config: &LaunchConfig, cpus: usize) -> Option<(&'static str, String)> {
    let settings = &config.realtime;
    if let Some(priority) = settings.priority {
        let limit = rlimit(libc::RLIMIT_RTPRIO);
        if !has_capability(CAP_SYS_NICE) && limit < u64::from(priority) {
            return Some((
                "realtime.priority",
                format!(
                    "SCHED_FIFO priority {priority} is not permitted here: it needs CAP_SYS_NICE (root) or a \
                     real-time priority limit of at least {priority} (`ulimit -r`, now {}); leave out \
                     [realtime] priority to run at normal priority",
                    limit_text(limit)
                ),
            ));
        }
        if cpus < CPUS_TO_POLL && polls(config, cpus) {
            return Some((
                "realtime.priority",
                format!(
                    "a loop process that polls ([wait]) at a real-time priority would keep its CPU from every \
                     other process, and this machine has {cpus} CPUs for the loop's {CPUS_TO_POLL} processes; \
                     use wait.strategy = \"block\" (and wait.lockstep = \"block\") with it"
                ),
            ));
        }
    }
    if settings.mlock && !has_capability(CAP_IPC_LOCK) && rlimit(libc::RLIMIT_MEMLOCK) != libc::RLIM_INFINITY {
        return Some((
            "realtime.mlock",
            format!(
                "locking the loop's memory is not permitted here: it needs CAP_IPC_LOCK (root) or an unlimited \
                 locked-memory limit (`ulimit -l unlimited`, now {} KiB); set realtime.mlock = false",
                rlimit(libc::RLIMIT_MEMLOCK) / 1024
            ),
        ));
    }
    None
}

/// Whether any loop process of `config` polls for its input on a machine with `cpus` CPUs.
fn polls(config: &LaunchConfig, cpus: usize) -> bool {
    let wait = config.wait.decided_for(cpus);
    if config.mode == Mode::Lockstep {
        return wait.lockstep == LockstepWait::Poll;
    }
    Role::LOOP.iter().any(|&role| wait.for_process(role) != Strategy::Block)
}

fn rlimit(resource: libc::__rlimit_resource_t) -> u64 {
    let mut limit = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
    // SAFETY: getrlimit fills a valid rlimit.
    unsafe { libc::getrlimit(resource, &mut limit) };
    limit.rlim_cur
}

fn limit_text(limit: u64) -> String {
    if limit == libc::RLIM_INFINITY { "unlimited".into() } else { limit.to_string() }
}

/// Whether this process has capability `bit` in its effective set.
fn has_capability(bit: u32) -> bool {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("CapEff:"))
        .and_then(|hex| u64::from_str_radix(hex.trim(), 16).ok())
        .is_some_and(|caps| caps & (1 << bit) != 0)
}

/// How a process is scheduled and how much of its memory is locked, as the kernel says.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
pub struct Scheduling {
    /// `normal`, `fifo`, `rr`, `batch`, `idle` or `deadline`.
    pub policy: String,
    /// The real-time priority (0 under a normal policy).
    pub priority: u32,
    /// Memory locked (`VmLck`), KiB.
    pub locked_kib: u64,
}

/// Reads how process `pid` is scheduled from /proc.
pub fn read(pid: u32) -> Result<Scheduling> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat"))?;
    // Fields after the command name, which is in parentheses and may hold spaces; the first of
    // them is field 3 of proc(5): rt_priority is field 40, policy 41.
    let Some((_, after)) = stat.rsplit_once(')') else { bail!("unreadable /proc/{pid}/stat") };
    let fields: Vec<&str> = after.split_whitespace().collect();
    let field = |n: usize| fields.get(n - 3).and_then(|f| f.parse::<u32>().ok());
    let (Some(priority), Some(policy)) = (field(40), field(41)) else { bail!("unreadable /proc/{pid}/stat") };
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))?;
    let locked_kib = status
        .lines()
        .find_map(|l| l.strip_prefix("VmLck:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or(0);
    let policy = match policy as i32 {
        libc::SCHED_OTHER => "normal",
        libc::SCHED_FIFO => "fifo",
        libc::SCHED_RR => "rr",
        libc::SCHED_BATCH => "batch",
        libc::SCHED_IDLE => "idle",
        6 => "deadline",
        _ => "unknown",
    };
    Ok(Scheduling { policy: policy.into(), priority, locked_kib })
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::config::launch::Override;

    fn config(sets: &[&str]) -> LaunchConfig {
        let overrides: Vec<Override> = sets.iter().map(|s| Override::parse(s).unwrap()).collect();
        crate::config::launch::test_pendulum(&overrides).unwrap()
    }

    #[test]
    fn a_polling_loop_at_real_time_priority_needs_a_cpu_per_process() {
        // Root (the tests' user) may set any priority, so only the CPUs can refuse here.
        let spin = config(&["realtime.priority=10", "wait.strategy=\"spin\""]);
        let (key, why) = refusal(&spin, 2).unwrap();
        assert_eq!(key, "realtime.priority");
        assert!(why.contains("2 CPUs for the loop's 5 processes") && why.contains("\"block\""), "{why}");
        assert_eq!(refusal(&spin, CPUS_TO_POLL), None);
        assert_eq!(refusal(&config(&["realtime.priority=10"]), 2), None, "block is the default");
        // Lockstep's auto polls only with a CPU per process.
        assert_eq!(refusal(&config(&["realtime.priority=10", "mode=\"lockstep\""]), 2), None);
        let poll = config(&["realtime.priority=10", "mode=\"lockstep\"", "wait.lockstep=\"poll\""]);
        assert!(refusal(&poll, 2).is_some());
        assert_eq!(refusal(&config(&["wait.strategy=\"spin\""]), 2), None, "no priority, no refusal");
    }

    #[test]
    fn a_priority_outside_1_to_99_is_refused_at_load() {
        for p in [0, 100] {
            let overrides = [Override::parse(&format!("realtime.priority={p}")).unwrap()];
            let e = crate::config::launch::test_pendulum(&overrides).err().unwrap().to_string();
            assert!(e.contains("realtime.priority") && e.contains("1 to 99"), "{e}");
        }
        let overrides = [Override::parse("realtime.nice=3").unwrap()];
        let e = crate::config::launch::test_pendulum(&overrides).err().unwrap().to_string();
        assert!(e.contains("nice"), "{e}");
    }

    #[test]
    fn this_process_reads_as_normal_priority() {
        let me = read(std::process::id()).unwrap();
        assert_eq!((me.policy.as_str(), me.priority), ("normal", 0));
    }
}
