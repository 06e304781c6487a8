//! Test hosts: two network namespaces joined by a veth pair, the remote one with its own /dev/shm
//! (and optionally a shifted CLOCK_MONOTONIC), and a slow or cut link between them.

use std::collections::VecDeque;
use std::fs::File;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::os::unix::fs::MetadataExt;
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, OnceLock, mpsc};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Where the mount and time namespaces are kept (bound to files, as `ip netns` keeps network
/// namespaces), with the locks that hand out the host numbers.
const STATE_DIR: &str = "/run/looplab-test";
/// Host numbers N (the subnet 10.77.N.0/24) are handed out from here up to LAST_HOST_NUMBER.
const FIRST_HOST_NUMBER: u32 = 10;
const LAST_HOST_NUMBER: u32 = 249;
/// The remote namespace's iptables chain of the slow link.
const SLOW_CHAIN: &str = "LOOPLAB_SLOW";

/// Which of the two hosts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Host {
    Local,
    Remote,
}

/// Two hosts, "local" and "remote", each a network namespace, joined by a veth pair: local is
/// 10.77.N.1/24, remote 10.77.N.2/24. The remote host has its own /dev/shm (a mount namespace),
/// so the processes of the two hosts can only meet over the link. Dropping it kills every process
/// left on either host and removes everything it made.
pub struct TestHosts {
    n: u32,
    local: String,
    remote: String,
    local_veth: String,
    remote_veth: String,
    mount_ns: PathBuf,
    time_ns: Option<PathBuf>,
    /// Dropped last (after Drop::drop cleaned up): the number is free again only then.
    _claim: Claim,
}

/// The hosts for one test, or a failure saying why they cannot be made. Each test that makes them
/// carries `#[cfg_attr(netns_unavailable, ignore = "...")]`: the root package's build script
/// (services/build.rs) sets that cfg where the build is not root or lacks a tool, so there the
/// tests show as ignored in the summary line; where they run, a failure here is a broken machine.
pub fn test_hosts(tag: &str, remote_monotonic_offset_s: Option<i64>) -> TestHosts {
    TestHosts::create(tag, remote_monotonic_offset_s)
        .unwrap_or_else(|e| panic!("cannot make the test hosts (root, ip, nsenter, unshare and mount are needed): {e}"))
}

impl TestHosts {
    /// Creates both hosts; `remote_monotonic_offset_s` puts the remote host's CLOCK_MONOTONIC that
    /// many seconds ahead (a time namespace). Err says why they cannot be made.
    pub fn create(tag: &str, remote_monotonic_offset_s: Option<i64>) -> Result<TestHosts, String> {
        // SAFETY: geteuid has no preconditions.
        if unsafe { libc::geteuid() } != 0 {
            return Err("not root: creating network namespaces needs root".into());
        }
        for (tool, version) in
            [("ip", "-V"), ("nsenter", "--version"), ("unshare", "--version"), ("mount", "--version")]
        {
            if !Command::new(tool).arg(version).output().is_ok_and(|o| o.status.success()) {
                return Err(format!("`{tool}` is missing"));
            }
        }
        let tag: String = tag
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c.to_ascii_lowercase() } else { '-' })
            .take(24)
            .collect();
        prepare_state_dir()?;
        static SWEPT: std::sync::Once = std::sync::Once::new();
        SWEPT.call_once(remove_all_stale);
        let claim = Claim::next()?;
        let n = claim.n;
        remove_stale(n);
        let hosts = TestHosts {
            n,
            local: format!("looplab{n}-{tag}-local"),
            remote: format!("looplab{n}-{tag}-remote"),
            local_veth: format!("looplab{n}l"),
            remote_veth: format!("looplab{n}r"),
            mount_ns: Path::new(STATE_DIR).join(format!("mnt-{n}")),
            time_ns: remote_monotonic_offset_s.map(|_| Path::new(STATE_DIR).join(format!("time-{n}"))),
            _claim: claim,
        };
        // From here on a failure drops `hosts`, which removes what was made so far.
        hosts.build(remote_monotonic_offset_s).map_err(|e| format!("cannot create the test hosts: {e}"))?;
        Ok(hosts)
    }

    fn build(&self, remote_monotonic_offset_s: Option<i64>) -> Result<(), String> {
        let (l, r) = (&self.local, &self.remote);
        run(&format!("ip netns add {l}"))?;
        run(&format!("ip netns add {r}"))?;
        // Created right inside the namespaces: nothing ever appears on the machine's own network.
        let (lv, rv) = (&self.local_veth, &self.remote_veth);
        run(&format!("ip link add {lv} netns {l} type veth peer name {rv} netns {r}"))?;
        for (ns, veth, address) in [(l, lv, self.local_address()), (r, rv, self.remote_address())] {
            run(&format!("ip -n {ns} address add {address}/24 dev {veth}"))?;
            run(&format!("ip -n {ns} link set {veth} up"))?;
            run(&format!("ip -n {ns} link set lo up"))?;
        }
        touch(&self.mount_ns)?;
        // The copy of the machine's mounts holds the network namespaces bound under /run/netns
        // (and this folder's files) alive; unmounting them there lets them go when deleted here.
        let script = format!(
            "mount -t tmpfs -o mode=1777 tmpfs /dev/shm && {{ umount -l /run/netns; umount -l {STATE_DIR}; true; }} 2>/dev/null"
        );
        let mount_arg = format!("--mount={}", self.mount_ns.display());
        run_args("unshare", &[&mount_arg, "--propagation", "private", "sh", "-c", &script])?;
        if let (Some(time_ns), Some(offset)) = (&self.time_ns, remote_monotonic_offset_s) {
            touch(time_ns)?;
            run(&format!("unshare --time={} --monotonic {offset} true", time_ns.display()))?;
        }
        Ok(())
    }

    /// The host number N: the subnet is 10.77.N.0/24.
    pub fn number(&self) -> u32 {
        self.n
    }

    pub fn local_address(&self) -> String {
        format!("10.77.{}.1", self.n)
    }

    pub fn remote_address(&self) -> String {
        format!("10.77.{}.2", self.n)
    }

    /// The network namespaces' names (as `ip netns` lists them).
    pub fn namespace(&self, host: Host) -> &str {
        match host {
            Host::Local => &self.local,
            Host::Remote => &self.remote,
        }
    }

    /// The veth end on that host.
    pub fn veth(&self, host: Host) -> &str {
        match host {
            Host::Local => &self.local_veth,
            Host::Remote => &self.remote_veth,
        }
    }

    /// The files that keep the remote host's mount namespace and (with an offset) time namespace.
    pub fn namespace_files(&self) -> Vec<PathBuf> {
        std::iter::once(self.mount_ns.clone()).chain(self.time_ns.clone()).collect()
    }

    /// A command prefix that runs a program on the local host, in place (it execs: same pid).
    pub fn local_prefix(&self) -> Vec<String> {
        // Not `ip netns exec`: it unshares the mount namespace, and a copied mount namespace
        // leaves out the mounted namespace files, so the remote host could not be entered from it.
        vec!["nsenter".to_owned(), format!("--net={}", netns_path(&self.local).display())]
    }

    /// A command prefix that runs a program on the remote host, in place (nsenter execs: same
    /// pid), in the caller's working directory (entering a mount namespace would put it at /).
    pub fn remote_prefix(&self) -> Vec<String> {
        let mut prefix = vec![
            "nsenter".to_owned(),
            format!("--net={}", netns_path(&self.remote).display()),
            format!("--mount={}", self.mount_ns.display()),
        ];
        if let Some(time_ns) = &self.time_ns {
            prefix.push(format!("--time={}", time_ns.display()));
        }
        prefix.push("--wd=.".to_owned());
        prefix
    }

    pub fn prefix(&self, host: Host) -> Vec<String> {
        match host {
            Host::Local => self.local_prefix(),
            Host::Remote => self.remote_prefix(),
        }
    }

    /// A command that runs `program` on that host.
    pub fn command(&self, host: Host, program: &str) -> Command {
        let prefix = self.prefix(host);
        let mut command = Command::new(&prefix[0]);
        command.args(&prefix[1..]).arg(program);
        command
    }

    /// Everything in the remote host's /dev/shm, as paths relative to it ("folder",
    /// "folder/file"), sorted; empty when it is clean.
    pub fn remote_shm_entries(&self) -> Vec<String> {
        let listing =
            run(&format!("nsenter --mount={} find /dev/shm -mindepth 1 -printf %P\\n", self.mount_ns.display()))
                .unwrap_or_else(|e| panic!("cannot list the remote host's /dev/shm: {e}"));
        let mut entries: Vec<String> = listing.lines().map(str::to_owned).collect();
        entries.sort();
        entries
    }

    /// Runs `f` on a new thread that has entered that host's network namespace (sockets it
    /// opens live there); the thread panics if it cannot enter.
    pub fn spawn_in<T: Send + 'static>(&self, host: Host, f: impl FnOnce() -> T + Send + 'static) -> JoinHandle<T> {
        let path = netns_path(self.namespace(host));
        std::thread::spawn(move || {
            enter_netns(&path).unwrap_or_else(|e| panic!("{e}"));
            f()
        })
    }

    /// Every rule of the remote host's filter table (`iptables -S`), to check what is set.
    pub fn remote_iptables_rules(&self) -> Result<String, String> {
        ensure_iptables()?;
        iptables(&self.remote, "-S")
    }

    /// Drops every packet on the link, both ways (rules in the remote host), until `mend_link`.
    pub fn cut_link(&self) -> Result<(), String> {
        ensure_iptables()?;
        for rule in self.cut_rules() {
            if iptables(&self.remote, &format!("-C {rule}")).is_err() {
                // -I: first in its chain, before the slow link's.
                iptables(&self.remote, &format!("-I {rule}"))?;
            }
        }
        Ok(())
    }

    /// Undoes `cut_link`.
    pub fn mend_link(&self) -> Result<(), String> {
        ensure_iptables()?;
        for rule in self.cut_rules() {
            while iptables(&self.remote, &format!("-C {rule}")).is_ok() {
                iptables(&self.remote, &format!("-D {rule}"))?;
            }
        }
        Ok(())
    }

    fn cut_rules(&self) -> [String; 2] {
        let v = &self.remote_veth;
        [format!("INPUT -i {v} -j DROP"), format!("OUTPUT -o {v} -j DROP")]
    }

    /// Delays every TCP packet the remote host sends on the link by `delay` (so a round trip
    /// grows by `delay`), in order, and first drops a `drop_probability` fraction of them. One at
    /// a time per pair of hosts; dropping the SlowLink restores the link.
    pub fn slow_link(&self, delay: Duration, drop_probability: f64) -> Result<SlowLink, String> {
        if !(0.0..=1.0).contains(&drop_probability) {
            return Err(format!("drop probability {drop_probability} is not in [0, 1]"));
        }
        ensure_iptables()?;
        // The queue number is the namespace's own; N just makes it recognisable.
        let queue = u16::try_from(self.n).expect("host numbers fit a queue number");
        let delayed = Arc::new(AtomicU64::new(0));
        let (stop_tx, stop_rx) = UnixStream::pair().map_err(|e| format!("socketpair: {e}"))?;
        let (ready_tx, ready_rx) = mpsc::channel();
        let path = netns_path(&self.remote);
        let counter = Arc::clone(&delayed);
        let thread = std::thread::Builder::new()
            .name("slow-link".into())
            .spawn(move || {
                let queue_socket = enter_netns(&path).and_then(|()| NfQueue::bind(queue));
                match queue_socket {
                    Ok(socket) => {
                        let _ = ready_tx.send(Ok(()));
                        delay_packets(&socket, delay, &stop_rx, &counter);
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                    }
                }
            })
            .map_err(|e| format!("cannot start the slow link's thread: {e}"))?;
        let mut link = SlowLink {
            remote: self.remote.clone(),
            remote_veth: self.remote_veth.clone(),
            delayed,
            stop: Some(stop_tx),
            thread: Some(thread),
            rules_added: false,
        };
        ready_rx.recv().map_err(|_| "the slow link's thread died".to_owned())??;
        link.add_rules(queue, drop_probability)?;
        Ok(link)
    }

    fn kill_all(&self) {
        for ns in [&self.local, &self.remote] {
            kill_processes_in(ns);
        }
    }
}

impl Drop for TestHosts {
    fn drop(&mut self) {
        self.kill_all();
        for file in self.namespace_files() {
            unmount_and_remove(&file);
        }
        for ns in [&self.remote, &self.local] {
            let _ = run(&format!("ip netns delete {ns}"));
        }
    }
}

/// The slow link: an NFQUEUE rule in the remote host's OUTPUT chain for the veth, and a thread
/// that holds each queued packet for the delay. Dropping it removes the rules, lets every held
/// packet go and stops the thread.
pub struct SlowLink {
    /// The remote network namespace's name.
    remote: String,
    remote_veth: String,
    delayed: Arc<AtomicU64>,
    /// Dropping it wakes the thread to finish.
    stop: Option<UnixStream>,
    thread: Option<JoinHandle<()>>,
    rules_added: bool,
}

impl SlowLink {
    fn jump_rule(&self) -> String {
        format!("OUTPUT -o {} -p tcp -j {SLOW_CHAIN}", self.remote_veth)
    }

    fn add_rules(&mut self, queue: u16, drop_probability: f64) -> Result<(), String> {
        let ns = &self.remote;
        iptables(ns, &format!("-N {SLOW_CHAIN}"))?;
        self.rules_added = true;
        iptables(ns, &format!("-A {SLOW_CHAIN} -m statistic --mode random --probability {drop_probability} -j DROP"))?;
        // --queue-bypass: should the thread be gone, packets pass instead of being dropped.
        iptables(ns, &format!("-A {SLOW_CHAIN} -j NFQUEUE --queue-num {queue} --queue-bypass"))?;
        iptables(ns, &format!("-A {}", self.jump_rule()))?;
        Ok(())
    }

    fn remove_rules(&mut self) {
        if !std::mem::take(&mut self.rules_added) {
            return;
        }
        let ns = &self.remote;
        while iptables(ns, &format!("-C {}", self.jump_rule())).is_ok() {
            if iptables(ns, &format!("-D {}", self.jump_rule())).is_err() {
                break;
            }
        }
        let _ = iptables(ns, &format!("-F {SLOW_CHAIN}"));
        let _ = iptables(ns, &format!("-X {SLOW_CHAIN}"));
    }

    /// Packets the drop rule dropped (its iptables counter).
    pub fn dropped_packets(&self) -> u64 {
        let listing = iptables(&self.remote, &format!("-L {SLOW_CHAIN} -v -x -n"))
            .unwrap_or_else(|e| panic!("cannot read the slow link's counters: {e}"));
        // Two header lines, then "pkts bytes target ..." per rule; the drop rule is the first.
        listing
            .lines()
            .filter_map(|line| {
                let fields: Vec<&str> = line.split_whitespace().collect();
                (fields.get(2) == Some(&"DROP")).then(|| fields[0].parse::<u64>().ok()).flatten()
            })
            .next()
            .unwrap_or_else(|| panic!("no drop rule in the slow link's chain:\n{listing}"))
    }

    /// Packets held for the delay and let through.
    pub fn delayed_packets(&self) -> u64 {
        self.delayed.load(Ordering::SeqCst)
    }
}

impl Drop for SlowLink {
    fn drop(&mut self) {
        // Rules first: no packet is queued any more once the thread lets the held ones go.
        self.remove_rules();
        drop(self.stop.take());
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// Makes sure `iptables` is installed, installing Debian's package if it is missing (once per
/// process; concurrent callers wait for the one doing it). Err says why it is not there.
pub fn ensure_iptables() -> Result<(), String> {
    static DONE: OnceLock<Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| {
        let present = || Command::new("iptables").arg("--version").output().is_ok_and(|o| o.status.success());
        if present() {
            return Ok(());
        }
        let apt = |args: &[&str]| {
            Command::new("apt-get")
                .args(["-o", "DPkg::Lock::Timeout=300"])
                .args(args)
                .env("DEBIAN_FRONTEND", "noninteractive")
                .output()
                .map_err(|e| format!("cannot run apt-get: {e}"))
                .and_then(|o| {
                    if o.status.success() {
                        Ok(())
                    } else {
                        Err(format!("apt-get {args:?} failed: {}", String::from_utf8_lossy(&o.stderr).trim()))
                    }
                })
        };
        let install = ["install", "-y", "--no-install-recommends", "iptables"];
        if apt(&install).is_err() {
            // A fresh machine has no package lists yet.
            apt(&["update"])?;
            apt(&install)?;
        }
        if present() { Ok(()) } else { Err("iptables is still missing after installing it".into()) }
    })
    .clone()
}

/// A claim on a host number: an exclusive lock on STATE_DIR/lock-N, so that test processes
/// running at the same time never share a number (a crashed process's lock is free again).
struct Claim {
    n: u32,
    path: PathBuf,
    _file: File,
}

impl Claim {
    fn next() -> Result<Claim, String> {
        static NEXT: AtomicU32 = AtomicU32::new(FIRST_HOST_NUMBER);
        let span = LAST_HOST_NUMBER - FIRST_HOST_NUMBER + 1;
        for _ in 0..span {
            let n = FIRST_HOST_NUMBER + (NEXT.fetch_add(1, Ordering::Relaxed) - FIRST_HOST_NUMBER) % span;
            if let Some(claim) = Claim::take(n)? {
                return Ok(claim);
            }
        }
        Err(format!("every host number {FIRST_HOST_NUMBER}..={LAST_HOST_NUMBER} is in use"))
    }

    /// Claims `n` if no live process holds it.
    fn take(n: u32) -> Result<Option<Claim>, String> {
        let path = Path::new(STATE_DIR).join(format!("lock-{n}"));
        let file = File::options()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&path)
            .map_err(|e| format!("cannot open {}: {e}", path.display()))?;
        if file.try_lock().is_err() {
            return Ok(None);
        }
        // The holder before us may have removed the file after we opened it: then the lock is on
        // a file nobody else will find; take the number only if ours is still the file.
        let same = std::fs::metadata(&path).is_ok_and(|m| file.metadata().is_ok_and(|f| f.ino() == m.ino()));
        Ok(same.then_some(Claim { n, path, _file: file }))
    }
}

impl Drop for Claim {
    fn drop(&mut self) {
        // Removed while still locked; the lock goes with the file.
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Creates STATE_DIR as a private bind mount of itself: a namespace file can only be bound
/// where the binding does not propagate into that namespace.
fn prepare_state_dir() -> Result<(), String> {
    std::fs::create_dir_all(STATE_DIR).map_err(|e| format!("cannot create {STATE_DIR}: {e}"))?;
    // Serialises the check and the mount between test processes.
    let dir = File::open(STATE_DIR).map_err(|e| format!("cannot open {STATE_DIR}: {e}"))?;
    dir.lock().map_err(|e| format!("cannot lock {STATE_DIR}: {e}"))?;
    let mountinfo = std::fs::read_to_string("/proc/self/mountinfo").map_err(|e| format!("mountinfo: {e}"))?;
    let mounted = mountinfo.lines().any(|line| line.split(' ').nth(4) == Some(STATE_DIR));
    if !mounted {
        run(&format!("mount --bind {STATE_DIR} {STATE_DIR}"))?;
    }
    run(&format!("mount --make-private {STATE_DIR}"))?;
    Ok(())
}

/// Removes what crashed earlier runs left under any host number that no live process holds.
fn remove_all_stale() {
    let names = |dir: &str| -> Vec<String> {
        let entries = std::fs::read_dir(dir).into_iter().flatten().flatten();
        entries.filter_map(|entry| entry.file_name().into_string().ok()).collect()
    };
    let mut numbers: Vec<u32> = names("/run/netns")
        .iter()
        .filter_map(|name| name.strip_prefix("looplab")?.split('-').next()?.parse().ok())
        .chain(names(STATE_DIR).iter().filter_map(|name| name.split_once('-')?.1.parse().ok()))
        .collect();
    numbers.sort_unstable();
    numbers.dedup();
    for n in numbers {
        if let Ok(Some(_claim)) = Claim::take(n) {
            remove_stale(n);
        }
    }
}

/// Removes what a crashed earlier run with host number `n` left: its processes, namespaces and
/// namespace files (we hold the claim on `n`, so none of it is anybody's).
fn remove_stale(n: u32) {
    let prefix = format!("looplab{n}-");
    let stale: Vec<String> = std::fs::read_dir("/run/netns")
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|entry| entry.file_name().into_string().ok())
        .filter(|name| name.starts_with(&prefix))
        .collect();
    for ns in &stale {
        kill_processes_in(ns);
        let _ = run(&format!("ip netns delete {ns}"));
    }
    for veth in [format!("looplab{n}l"), format!("looplab{n}r")] {
        if Path::new("/sys/class/net").join(&veth).exists() {
            let _ = run(&format!("ip link delete {veth}"));
        }
    }
    for file in [format!("mnt-{n}"), format!("time-{n}")] {
        unmount_and_remove(&Path::new(STATE_DIR).join(file));
    }
}

/// SIGKILLs every process in the network namespace and waits until none is left.
fn kill_processes_in(ns: &str) {
    // A killed process leaves the namespace when it exits; bounded, since a process stuck in
    // the kernel cannot be helped by waiting forever.
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let pids: Vec<i32> = run(&format!("ip netns pids {ns}"))
            .unwrap_or_default()
            .split_whitespace()
            .filter_map(|pid| pid.parse().ok())
            .collect();
        if pids.is_empty() || Instant::now() > deadline {
            return;
        }
        for pid in pids {
            // SAFETY: kill has no memory preconditions.
            unsafe { libc::kill(pid, libc::SIGKILL) };
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn unmount_and_remove(file: &Path) {
    if !file.exists() {
        return;
    }
    let path = file.display();
    if run(&format!("umount {path}")).is_err() {
        let _ = run(&format!("umount -l {path}"));
    }
    let _ = std::fs::remove_file(file);
}

fn netns_path(name: &str) -> PathBuf {
    Path::new("/run/netns").join(name)
}

fn touch(path: &Path) -> Result<(), String> {
    File::create(path).map(drop).map_err(|e| format!("cannot create {}: {e}", path.display()))
}

/// `iptables` in the network namespace `ns` (its filter table).
fn iptables(ns: &str, arguments: &str) -> Result<String, String> {
    run(&format!("nsenter --net={} iptables -w {arguments}", netns_path(ns).display()))
}

/// Runs a command line of words (our names and paths have no spaces) to completion.
fn run(line: &str) -> Result<String, String> {
    let words: Vec<&str> = line.split_whitespace().collect();
    run_args(words[0], &words[1..])
}

/// Runs a program to completion; Ok(stdout) if it succeeded, else Err naming it with its stderr.
fn run_args(program: &str, args: &[&str]) -> Result<String, String> {
    let output = Command::new(program).args(args).output().map_err(|e| format!("cannot run {program}: {e}"))?;
    if output.status.success() {
        Ok(String::from_utf8_lossy(&output.stdout).into_owned())
    } else {
        Err(format!(
            "{program} {} failed ({}): {}",
            args.join(" "),
            output.status,
            String::from_utf8_lossy(&output.stderr).trim()
        ))
    }
}

/// Moves the calling thread (only it) into the network namespace bound at `path`.
fn enter_netns(path: &Path) -> Result<(), String> {
    let file = File::open(path).map_err(|e| format!("cannot open {}: {e}", path.display()))?;
    // SAFETY: a valid open descriptor; setns changes only this thread's network namespace.
    if unsafe { libc::setns(file.as_raw_fd(), libc::CLONE_NEWNET) } != 0 {
        return Err(format!("cannot enter {}: {}", path.display(), std::io::Error::last_os_error()));
    }
    Ok(())
}

/// Holds each queued packet for `delay` after it arrived, lets them go in order, and stops when
/// the other end of `stop` is dropped (letting every held packet go).
fn delay_packets(socket: &NfQueue, delay: Duration, stop: &UnixStream, delayed: &AtomicU64) {
    let mut held: VecDeque<(Instant, u32)> = VecDeque::new();
    loop {
        let now = Instant::now();
        while held.front().is_some_and(|&(due, _)| due <= now) {
            let (_, id) = held.pop_front().expect("a front");
            // Counted first: whoever receives the packet then sees it counted.
            delayed.fetch_add(1, Ordering::SeqCst);
            socket.accept(id);
        }
        let timeout = held.front().map(|&(due, _)| due.saturating_duration_since(now));
        let [queue_ready, stop_ready] = wait_readable([socket.fd.as_raw_fd(), stop.as_raw_fd()], timeout);
        if stop_ready {
            break;
        }
        if queue_ready {
            let arrived = Instant::now();
            socket.receive(|id| held.push_back((arrived + delay, id)));
        }
    }
    for (_, id) in held {
        delayed.fetch_add(1, Ordering::SeqCst);
        socket.accept(id);
    }
    socket.unbind();
}

/// Waits until one of two descriptors is readable (or hung up), or the timeout passed.
fn wait_readable(fds: [i32; 2], timeout: Option<Duration>) -> [bool; 2] {
    let mut polled = fds.map(|fd| libc::pollfd { fd, events: libc::POLLIN, revents: 0 });
    // ppoll, not poll: its timeout is in nanoseconds, and a packet is held no less than `delay`.
    let timespec = timeout.map(|t| libc::timespec {
        tv_sec: t.as_secs() as libc::time_t,
        tv_nsec: libc::c_long::from(t.subsec_nanos() as i32),
    });
    let timeout_ptr = timespec.as_ref().map_or(std::ptr::null(), |t| t as *const libc::timespec);
    // SAFETY: two valid pollfds, a valid or null timespec, no signal mask.
    let n = unsafe { libc::ppoll(polled.as_mut_ptr(), 2, timeout_ptr, std::ptr::null()) };
    if n <= 0 {
        return [false, false];
    }
    polled.map(|p| p.revents != 0)
}

// The NFQUEUE netlink protocol (linux/netfilter/nfnetlink_queue.h), the few messages needed:
// bind a queue with metadata only, read packet ids, send verdicts. Netlink headers are in host
// order; nfnetlink's queue number and the attributes' values are big-endian.
const NFNL_SUBSYS_QUEUE: u16 = 3;
const NFQNL_MSG_PACKET: u16 = 0;
const NFQNL_MSG_VERDICT: u16 = 1;
const NFQNL_MSG_CONFIG: u16 = 2;
const NFQA_PACKET_HDR: u16 = 1;
const NFQA_VERDICT_HDR: u16 = 2;
const NFQA_CFG_CMD: u16 = 1;
const NFQA_CFG_PARAMS: u16 = 2;
const NFQA_CFG_QUEUE_MAXLEN: u16 = 3;
const NFQA_CFG_MASK: u16 = 4;
const NFQA_CFG_FLAGS: u16 = 5;
const NFQNL_CFG_CMD_BIND: u8 = 1;
const NFQNL_CFG_CMD_UNBIND: u8 = 2;
const NFQNL_COPY_META: u8 = 1;
const NFQA_CFG_F_FAIL_OPEN: u32 = 1;
const NF_ACCEPT: u32 = 1;
const NLMSG_ERROR: u16 = 2;
const NLMSG_HEADER_LEN: usize = 16;

/// A netlink socket bound to one NFQUEUE queue in the calling thread's network namespace.
struct NfQueue {
    fd: OwnedFd,
    queue: u16,
}

impl NfQueue {
    fn bind(queue: u16) -> Result<NfQueue, String> {
        // SAFETY: plain socket creation; the descriptor is owned right below.
        let fd =
            unsafe { libc::socket(libc::AF_NETLINK, libc::SOCK_RAW | libc::SOCK_CLOEXEC, libc::NETLINK_NETFILTER) };
        if fd < 0 {
            return Err(format!("netlink socket: {}", std::io::Error::last_os_error()));
        }
        // SAFETY: fd is a new descriptor nobody else owns.
        let socket = NfQueue { fd: unsafe { OwnedFd::from_raw_fd(fd) }, queue };
        // SAFETY: sockaddr_nl is plain data; all zeroes is "the kernel, no groups".
        let mut address: libc::sockaddr_nl = unsafe { std::mem::zeroed() };
        address.nl_family = libc::AF_NETLINK as libc::sa_family_t;
        // SAFETY: a valid address of the given size.
        let bound = unsafe {
            libc::bind(
                fd,
                (&address as *const libc::sockaddr_nl).cast(),
                std::mem::size_of::<libc::sockaddr_nl>() as libc::socklen_t,
            )
        };
        if bound != 0 {
            return Err(format!("netlink bind: {}", std::io::Error::last_os_error()));
        }
        // Room for bursts, and no ENOBUFS error: an overflow would only lose packets.
        socket.set_option(libc::SOL_SOCKET, libc::SO_RCVBUFFORCE, 8 << 20);
        socket.set_option(libc::SOL_NETLINK, libc::NETLINK_NO_ENOBUFS, 1);
        socket.configure(NFQA_CFG_CMD, &[NFQNL_CFG_CMD_BIND, 0, 0, 0])?;
        let mut params = 0u32.to_be_bytes().to_vec();
        params.push(NFQNL_COPY_META);
        socket.configure(NFQA_CFG_PARAMS, &params)?;
        socket.configure(NFQA_CFG_QUEUE_MAXLEN, &100_000u32.to_be_bytes())?;
        // A full queue lets packets pass rather than drop them.
        let mut flags = attribute(NFQA_CFG_MASK, &NFQA_CFG_F_FAIL_OPEN.to_be_bytes());
        flags.extend(attribute(NFQA_CFG_FLAGS, &NFQA_CFG_F_FAIL_OPEN.to_be_bytes()));
        socket.request(NFQNL_MSG_CONFIG, &flags, true)?;
        Ok(socket)
    }

    fn set_option(&self, level: i32, name: i32, value: i32) {
        // SAFETY: a valid int option of its size.
        unsafe {
            libc::setsockopt(
                self.fd.as_raw_fd(),
                level,
                name,
                (&value as *const i32).cast(),
                std::mem::size_of::<i32>() as libc::socklen_t,
            )
        };
    }

    fn configure(&self, kind: u16, value: &[u8]) -> Result<(), String> {
        self.request(NFQNL_MSG_CONFIG, &attribute(kind, value), true)
    }

    /// Sends one nfnetlink queue message; with `acknowledged`, waits for the kernel's answer.
    fn request(&self, kind: u16, attributes: &[u8], acknowledged: bool) -> Result<(), String> {
        let length = NLMSG_HEADER_LEN + 4 + attributes.len();
        let flags = (libc::NLM_F_REQUEST | if acknowledged { libc::NLM_F_ACK } else { 0 }) as u16;
        let mut message = Vec::with_capacity(length);
        message.extend((length as u32).to_ne_bytes());
        message.extend(((NFNL_SUBSYS_QUEUE << 8) | kind).to_ne_bytes());
        message.extend(flags.to_ne_bytes());
        message.extend([0u8; 8]); // sequence number, port id
        message.extend([libc::AF_UNSPEC as u8, 0]); // family, nfnetlink version 0
        message.extend(self.queue.to_be_bytes());
        message.extend_from_slice(attributes);
        // SAFETY: a valid buffer; the socket sends to the kernel (its bound default).
        let sent = unsafe { libc::send(self.fd.as_raw_fd(), message.as_ptr().cast(), message.len(), 0) };
        if sent < 0 {
            return Err(format!("netlink send: {}", std::io::Error::last_os_error()));
        }
        if !acknowledged {
            return Ok(());
        }
        let mut buffer = vec![0u8; 8192];
        loop {
            let n = self.recv(&mut buffer, 0)?;
            for (kind, body) in messages(&buffer[..n]) {
                if kind == NLMSG_ERROR && body.len() >= 4 {
                    let errno = -i32::from_ne_bytes(body[..4].try_into().expect("4 bytes"));
                    return if errno == 0 {
                        Ok(())
                    } else {
                        Err(format!("NFQUEUE configuration: {}", std::io::Error::from_raw_os_error(errno)))
                    };
                }
            }
        }
    }

    fn recv(&self, buffer: &mut [u8], flags: i32) -> Result<usize, String> {
        // SAFETY: a valid writable buffer of its length.
        let n = unsafe { libc::recv(self.fd.as_raw_fd(), buffer.as_mut_ptr().cast(), buffer.len(), flags) };
        if n < 0 { Err(format!("netlink recv: {}", std::io::Error::last_os_error())) } else { Ok(n as usize) }
    }

    /// Reads every packet notice waiting, without blocking, and hands each packet id to `on_packet`.
    fn receive(&self, mut on_packet: impl FnMut(u32)) {
        let mut buffer = vec![0u8; 64 * 1024];
        while let Ok(n) = self.recv(&mut buffer, libc::MSG_DONTWAIT) {
            for (kind, body) in messages(&buffer[..n]) {
                if kind != (NFNL_SUBSYS_QUEUE << 8) | NFQNL_MSG_PACKET || body.len() < 4 {
                    continue;
                }
                // After the nfgenmsg header: attributes; the packet header starts with the id.
                let header = attributes(&body[4..]).find(|(kind, value)| *kind == NFQA_PACKET_HDR && value.len() >= 4);
                if let Some((_, header)) = header {
                    on_packet(u32::from_be_bytes(header[..4].try_into().expect("4 bytes")));
                }
            }
        }
    }

    fn accept(&self, id: u32) {
        let mut verdict = NF_ACCEPT.to_be_bytes().to_vec();
        verdict.extend(id.to_be_bytes());
        // A failed verdict leaves the packet queued until unbind drops it: TCP sends it again.
        let _ = self.request(NFQNL_MSG_VERDICT, &attribute(NFQA_VERDICT_HDR, &verdict), false);
    }

    fn unbind(&self) {
        let _ = self.configure(NFQA_CFG_CMD, &[NFQNL_CFG_CMD_UNBIND, 0, 0, 0]);
    }
}

/// One netlink attribute: length, type, value, padded to 4 bytes.
fn attribute(kind: u16, value: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(4 + value.len() + 3);
    out.extend(((4 + value.len()) as u16).to_ne_bytes());
    out.extend(kind.to_ne_bytes());
    out.extend_from_slice(value);
    out.resize(out.len().next_multiple_of(4), 0);
    out
}

/// The netlink messages in a datagram, as (type, body after the header).
fn messages(mut data: &[u8]) -> impl Iterator<Item = (u16, &[u8])> {
    std::iter::from_fn(move || {
        if data.len() < NLMSG_HEADER_LEN {
            return None;
        }
        let length = u32::from_ne_bytes(data[..4].try_into().expect("4 bytes")) as usize;
        if length < NLMSG_HEADER_LEN || length > data.len() {
            return None;
        }
        let kind = u16::from_ne_bytes(data[4..6].try_into().expect("2 bytes"));
        let body = &data[NLMSG_HEADER_LEN..length];
        data = &data[length.next_multiple_of(4).min(data.len())..];
        Some((kind, body))
    })
}

/// The attributes in a message body, as (type without its flag bits, value).
fn attributes(mut data: &[u8]) -> impl Iterator<Item = (u16, &[u8])> {
    std::iter::from_fn(move || {
        if data.len() < 4 {
            return None;
        }
        let length = u16::from_ne_bytes(data[..2].try_into().expect("2 bytes")) as usize;
        if length < 4 || length > data.len() {
            return None;
        }
        let kind = u16::from_ne_bytes(data[2..4].try_into().expect("2 bytes")) & 0x3fff;
        let value = &data[4..length];
        data = &data[length.next_multiple_of(4).min(data.len())..];
        Some((kind, value))
    })
}
