//! Attacks on a run by another local user: files planted in /dev/shm under the run's names the
//! moment its folder appears. Root only: the attacker is the user nobody.

use crate::common;

use std::os::unix::process::CommandExt as _;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::*;

/// What iceoryx2 0.10 names a node registry after the file prefix: `looplab_<run>_` followed by
/// this was the registry of every run before the names had a secret part.
const OLD_REGISTRY_NAME: &str = "9204dd183d1c4d8e1ff592a30766ffa6765aa8b5_node.0_10_0.global_mgmt";
/// Longest a one-second lockstep run may take before the test calls it hung.
const HANG: Duration = Duration::from_secs(90);

/// An inotify watch on /dev/shm for new entries.
fn watch_shm() -> i32 {
    // SAFETY: plain syscalls on a descriptor this function owns.
    unsafe {
        let fd = libc::inotify_init1(libc::IN_CLOEXEC);
        assert!(fd >= 0, "inotify_init1");
        assert!(libc::inotify_add_watch(fd, c"/dev/shm".as_ptr(), libc::IN_CREATE) >= 0, "watch /dev/shm");
        fd
    }
}

/// The next run folder (`looplab_<16 hex digits>`) created in /dev/shm, within `HANG`.
fn next_run_folder(fd: i32, seen: &mut std::collections::VecDeque<String>) -> Option<String> {
    let until = Instant::now() + HANG;
    let mut buffer = [0u64; 512];
    // One read may bring several runs' folders (the other test starts runs too): every one is
    // kept, so that ours is not lost behind another's.
    while seen.is_empty() && Instant::now() < until {
        let mut pfd = libc::pollfd { fd, events: libc::POLLIN, revents: 0 };
        // SAFETY: one valid pollfd.
        if unsafe { libc::poll(&mut pfd, 1, 100) } <= 0 {
            continue;
        }
        // SAFETY: reads into a buffer of its size, aligned for inotify_event.
        let n = unsafe { libc::read(fd, buffer.as_mut_ptr().cast(), std::mem::size_of_val(&buffer)) };
        let bytes = unsafe { std::slice::from_raw_parts(buffer.as_ptr().cast::<u8>(), n.max(0) as usize) };
        let mut at = 0;
        while at + 16 <= bytes.len() {
            let mask = u32::from_ne_bytes(bytes[at + 4..at + 8].try_into().unwrap());
            let len = u32::from_ne_bytes(bytes[at + 12..at + 16].try_into().unwrap()) as usize;
            let name = String::from_utf8_lossy(&bytes[at + 16..at + 16 + len]).trim_end_matches('\0').to_owned();
            at += 16 + len;
            let id = name.strip_prefix("looplab_").unwrap_or("");
            if mask & libc::IN_ISDIR != 0 && id.len() == 16 && id.bytes().all(|b| b.is_ascii_hexdigit()) {
                seen.push_back(id.to_owned());
            }
        }
    }
    seen.pop_front()
}

/// Whether the process `pid` has a file open in another run's folder than `run_id`'s.
fn in_another_run(pid: u32, run_id: &str) -> bool {
    let Ok(fds) = std::fs::read_dir(format!("/proc/{pid}/fd")) else { return false };
    fds.flatten().filter_map(|fd| std::fs::read_link(fd.path()).ok()).any(|target| {
        let target = target.display().to_string();
        target.starts_with("/dev/shm/looplab_") && !target.starts_with(&format!("/dev/shm/looplab_{run_id}"))
    })
}

/// Creates `names` in /dev/shm as the user nobody: the first empty, the others with junk.
fn plant_as_nobody(names: &[String]) {
    let script = r#"cd /dev/shm && : > "$1" && shift && for name; do printf 'junk junk junk' > "$name"; done"#;
    let mut planter = Command::new("sh");
    planter.args(["-c", script, "sh"]).args(names);
    // SAFETY: between fork and exec only async-signal-safe calls, dropping to nobody for good.
    unsafe {
        planter.pre_exec(|| {
            if libc::setgroups(0, std::ptr::null()) != 0 || libc::setgid(65534) != 0 || libc::setuid(65534) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    assert!(planter.status().unwrap().success(), "nobody could not plant {names:?}");
}

/// Files nobody planted in /dev/shm, removed when the test is done with them, failed or not.
struct Planted(Vec<String>);

impl Planted {
    fn paths(&self) -> impl Iterator<Item = std::path::PathBuf> + '_ {
        self.0.iter().map(|name| Path::new("/dev/shm").join(name))
    }
}

impl Drop for Planted {
    fn drop(&mut self) {
        self.paths().for_each(|path| _ = std::fs::remove_file(path));
    }
}

/// What a racer can name from a run's id alone, the old registry name first.
fn derivable_names(run_id: &str, registry_empty: bool) -> Vec<String> {
    let registry = format!("looplab_{run_id}_{OLD_REGISTRY_NAME}");
    let others = ["planted", "x.data", "node.0_10_0.global_mgmt"].map(|n| format!("looplab_{run_id}_{n}"));
    // The first is planted empty, the rest with junk.
    if registry_empty {
        [vec![registry], others.to_vec()].concat()
    } else {
        [vec![others[0].clone(), registry], others[1..].to_vec()].concat()
    }
}

/// One run raced by nobody: when its folder appears the launcher is held (SIGSTOP) until nobody
/// has planted every name derivable from the run id, so the racer always wins the race. Returns
/// whether it won (the launcher had not yet created a file in /dev/shm), or None where the folder
/// that appeared was another run's (another test run on the machine).
fn raced_run(registry_empty: bool) -> Option<bool> {
    let inotify = watch_shm();
    let mut folders = std::collections::VecDeque::new();
    let dir = fresh_dir("raced");
    let mut launcher = looplab()
        .args(["run", "pendulum", "--mode", "lockstep", "--duration", "1", "-q", "--out"])
        .arg(&dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let pid = launcher.id();
    let (run_id, planted, won) = loop {
        let run_id = next_run_folder(inotify, &mut folders).expect("the run's folder appeared");
        // SAFETY: our own child.
        unsafe { libc::kill(pid as i32, libc::SIGSTOP) };
        if in_another_run(pid, &run_id) {
            unsafe { libc::kill(pid as i32, libc::SIGCONT) };
            continue;
        }
        let ours = std::fs::read_dir("/dev/shm")
            .unwrap()
            .flatten()
            .any(|e| e.file_name().to_string_lossy().starts_with(&format!("looplab_{run_id}_")));
        let planted = Planted(derivable_names(&run_id, registry_empty));
        plant_as_nobody(&planted.0);
        unsafe { libc::kill(pid as i32, libc::SIGCONT) };
        break (run_id, planted, !ours);
    };
    unsafe { libc::close(inotify) };
    let until = Instant::now() + HANG;
    while launcher.try_wait().unwrap().is_none() {
        if Instant::now() > until {
            let _ = launcher.kill();
            let _ = looplab().arg("clean").status();
            panic!("the launcher hung on a file nobody planted");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let output = launcher.wait_with_output().unwrap();
    let summary = dir.join("summary.json").exists().then(|| load_summary(&dir));
    if summary.as_ref().is_some_and(|s| s.run_id != run_id) {
        return None;
    }
    let said = format!("{}{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr));
    assert!(output.status.success(), "the raced run failed ({}):\n{said}", output.status);
    let s = summary.expect("summary.json");
    assert!(s.completed, "{:?}", s.stopped_because);
    assert_nothing_left(&s);
    let mut reported = s.shared_memory.foreign.clone();
    reported.sort();
    let mut expected: Vec<_> = planted.paths().map(|p| p.display().to_string()).collect();
    expected.sort();
    assert_eq!(reported, expected, "every planted file is reported as another user's");
    for path in planted.paths() {
        use std::os::unix::fs::MetadataExt;
        assert_eq!(std::fs::symlink_metadata(&path).unwrap().uid(), 65534, "{} left as it was", path.display());
    }
    std::fs::remove_dir_all(&dir).unwrap();
    Some(won)
}

/// Another user who plants every name derivable from a run's id, empty or with junk, the moment
/// the run's folder appears (the issue's inotify racer), neither fails the run nor makes it
/// hang: iceoryx2's files are named with a secret drawn before any of them exists.
#[test]
#[cfg_attr(netns_unavailable, ignore = "needs root, to plant files as another user")]
fn files_planted_under_a_runs_names_as_it_starts_neither_fail_nor_hang_it() {
    for registry_empty in [true, false] {
        let mut won = false;
        for _ in 0..5 {
            if raced_run(registry_empty) == Some(true) {
                won = true;
                break;
            }
        }
        assert!(won, "the racer never got its files in before the run's (registry empty: {registry_empty})");
    }
}

/// The newest loop the monitor has written to `loops.csv` so far.
fn newest_loop(dir: &Path) -> u64 {
    let text = std::fs::read_to_string(dir.join("loops.csv")).unwrap_or_default();
    let whole = &text[..text.rfind('\n').unwrap_or(0)];
    whole.rsplit('\n').next().and_then(|line| line.split(',').next()?.parse().ok()).unwrap_or(0)
}

/// The command lines of the launcher's children.
fn children(launcher: u32) -> Vec<(i32, Vec<String>)> {
    let list = std::fs::read_to_string(format!("/proc/{launcher}/task/{launcher}/children")).unwrap_or_default();
    list.split_whitespace()
        .filter_map(|pid| {
            let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).ok()?;
            let args = cmdline.split(|&b| b == 0).map(|a| String::from_utf8_lossy(a).into_owned()).collect();
            Some((pid.parse().ok()?, args))
        })
        .collect()
}

/// Links planted in a run folder where the run writes (`trajectory.csv`, reopened by a restarted
/// monitor, and `summary.partial`) are refused, not followed: the files they point at are
/// unchanged, the run fails with a line naming the file, and nothing is left in /dev/shm.
#[test]
fn links_planted_in_a_run_folder_are_refused_not_followed() {
    let dir = fresh_dir("planted-links");
    let victims = fresh_dir("link-victims");
    std::fs::create_dir_all(&victims).unwrap();
    let mut launcher = looplab()
        .args(["run", "pendulum", "--duration", "5", "-q", "--out"])
        .arg(&dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let until = Instant::now() + HANG;
    while newest_loop(&dir) < 300 {
        assert!(Instant::now() < until && launcher.try_wait().unwrap().is_none(), "the run did not start");
        std::thread::sleep(Duration::from_millis(20));
    }
    let processes = children(launcher.id());
    let arg_after = |flag: &str| {
        processes.iter().find_map(|(_, args)| Some(args[args.iter().position(|a| a == flag)? + 1].clone()))
    };
    let run_id = arg_after("--run-id").expect("a process with the run id");
    for name in ["trajectory.csv", "summary.partial"] {
        std::fs::write(victims.join(name), b"precious").unwrap();
        let _ = std::fs::remove_file(dir.join(name));
        std::os::unix::fs::symlink(victims.join(name), dir.join(name)).unwrap();
    }
    // The monitor dies; its successor reopens trajectory.csv to append to it.
    let monitor = processes.iter().find(|(_, args)| args[0].ends_with("looplab-monitor")).expect("the monitor").0;
    // SAFETY: a child of our launcher.
    unsafe { libc::kill(monitor, libc::SIGKILL) };
    let output = launcher.wait_with_output().unwrap();
    let said = String::from_utf8_lossy(&output.stderr).into_owned();
    assert_eq!(output.status.code(), Some(1), "{said}");
    let error = said.lines().find(|l| l.starts_with("error: ")).unwrap_or_else(|| panic!("no error line: {said}"));
    let summary_partial = dir.join("summary.partial").display().to_string();
    assert!(error.contains(&format!("cannot write {summary_partial}: it is a symbolic link")), "{error}");
    let log = std::fs::read_to_string(dir.join("logs/monitor.log")).unwrap();
    let trajectory = dir.join("trajectory.csv").display().to_string();
    assert!(log.contains(&format!("cannot write {trajectory}: it is a symbolic link")), "{log}");
    for name in ["trajectory.csv", "summary.partial"] {
        assert_eq!(std::fs::read(victims.join(name)).unwrap(), b"precious", "{name} was written through");
    }
    let left = looplab_shared::runtime::storage::run_storage::files_of_run(&run_id);
    assert!(left.is_empty(), "files of run {run_id} left behind: {left:?}");
    std::fs::remove_dir_all(&dir).unwrap();
    std::fs::remove_dir_all(&victims).unwrap();
}
