//! The test hosts themselves: the link between the two network namespaces, the remote host's own
//! /dev/shm and clock, the slow and the cut link, and that nothing is left after them. Root only:
//! where the build is not root or lacks a tool the hosts need, every test is ignored
//! (services/build.rs).

use crate::common;

use std::io::{Read, Write};
use std::net::{IpAddr, SocketAddr, TcpListener, TcpStream};
use std::os::unix::process::ExitStatusExt;
use std::process::{Command, Stdio};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use common::netns::{Host, TestHosts, test_hosts};

fn address(hosts: &TestHosts, host: Host) -> IpAddr {
    let text = match host {
        Host::Local => hosts.local_address(),
        Host::Remote => hosts.remote_address(),
    };
    text.parse().expect("an IP address")
}

/// A TCP echo server listening on `host`'s address: it serves one connection until the client
/// closes it, and returns the client's address.
fn echo_server(hosts: &TestHosts, host: Host) -> (SocketAddr, JoinHandle<SocketAddr>) {
    let ip = address(hosts, host);
    // A socket stays in the namespace it was made in, whichever thread uses it later.
    let listener = hosts.spawn_in(host, move || TcpListener::bind((ip, 0))).join().expect("no panic").expect("bind");
    let at = listener.local_addr().expect("an address");
    let server = std::thread::spawn(move || {
        let (mut stream, peer) = listener.accept().expect("accept");
        stream.set_nodelay(true).expect("nodelay");
        let mut buffer = [0u8; 256];
        loop {
            let n = stream.read(&mut buffer).expect("read");
            if n == 0 {
                return peer;
            }
            stream.write_all(&buffer[..n]).expect("echo");
        }
    });
    (at, server)
}

fn connect_from(hosts: &TestHosts, host: Host, to: SocketAddr) -> TcpStream {
    let stream = hosts.spawn_in(host, move || TcpStream::connect(to)).join().expect("no panic").expect("connect");
    stream.set_nodelay(true).expect("nodelay");
    stream
}

/// One 64-byte round trip; returns how long it took.
fn round_trip(stream: &mut TcpStream, seq: u8) -> Duration {
    let message = [seq; 64];
    let mut reply = [0u8; 64];
    let start = Instant::now();
    stream.write_all(&message).expect("send");
    stream.read_exact(&mut reply).expect("reply");
    let took = start.elapsed();
    assert_eq!(reply, message);
    took
}

#[test]
#[cfg_attr(netns_unavailable, ignore = "needs root, iproute2 and util-linux (network namespaces)")]
fn the_hosts_reach_each_other_over_tcp_on_their_own_addresses() {
    let hosts = test_hosts("reach", None);
    for (server, client) in [(Host::Remote, Host::Local), (Host::Local, Host::Remote)] {
        let (at, server_thread) = echo_server(&hosts, server);
        assert_eq!(at.ip(), address(&hosts, server));
        let mut stream = connect_from(&hosts, client, at);
        round_trip(&mut stream, 7);
        drop(stream);
        // The server saw the client's address on the link: the packets crossed the veth pair.
        assert_eq!(server_thread.join().expect("no panic").ip(), address(&hosts, client));
    }
}

#[test]
#[cfg_attr(netns_unavailable, ignore = "needs root, iproute2 and util-linux (network namespaces)")]
fn the_remote_host_has_its_own_dev_shm() {
    let hosts = test_hosts("shm", None);
    assert_eq!(hosts.remote_shm_entries(), Vec::<String>::new(), "a fresh host's /dev/shm is empty");
    let name = |side: &str| format!("looplab-netns-test-{}-{}-{side}", std::process::id(), hosts.number());
    let (remote_file, local_file) = (name("remote"), name("local"));
    let create = |host: Host, file: &str| {
        let status = hosts
            .command(host, "sh")
            .args(["-c", &format!("mkdir /dev/shm/{file} && touch /dev/shm/{file}/x")])
            .status();
        assert!(status.expect("sh runs").success(), "creating /dev/shm/{file} on {host:?}");
    };
    create(Host::Remote, &remote_file);
    create(Host::Local, &local_file);
    let local_path = std::path::Path::new("/dev/shm").join(&local_file);
    let local_there = local_path.join("x").exists();
    let _ = std::fs::remove_dir_all(&local_path);
    assert!(local_there, "the local host's /dev/shm is this machine's");
    assert!(!std::path::Path::new("/dev/shm").join(&remote_file).exists(), "the remote file leaked here");
    assert_eq!(hosts.remote_shm_entries(), vec![remote_file.clone(), format!("{remote_file}/x")]);
}

/// CLOCK_MONOTONIC in nanoseconds, as read by this process (on the machine's clock).
fn monotonic_ns() -> i128 {
    let mut now = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: a valid timespec to write into.
    assert_eq!(unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut now) }, 0);
    i128::from(now.tv_sec) * 1_000_000_000 + i128::from(now.tv_nsec)
}

/// CLOCK_MONOTONIC in nanoseconds as a program on `host` reads it, bracketed by this process's
/// reads before and after. Python's `time.clock_gettime_ns` is the one stock program here that
/// prints that clock (`date` shows the wall clock, /proc/uptime the boot time).
fn monotonic_on(hosts: &TestHosts, host: Host) -> (i128, i128, i128) {
    let before = monotonic_ns();
    let output = hosts
        .command(host, "python3")
        .args(["-c", "import time; print(time.clock_gettime_ns(time.CLOCK_MONOTONIC))"])
        .output()
        .unwrap_or_else(|e| panic!("python3 is needed to read CLOCK_MONOTONIC on a host: {e}"));
    let after = monotonic_ns();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let there = String::from_utf8_lossy(&output.stdout).trim().parse().expect("nanoseconds");
    (before, there, after)
}

#[test]
#[cfg_attr(netns_unavailable, ignore = "needs root, iproute2 and util-linux (network namespaces)")]
fn the_remote_hosts_monotonic_clock_runs_1000_s_ahead_with_the_offset() {
    let hosts = test_hosts("clock", Some(1000));
    // The kernel's own statement of the remote host's offsets (needs no program that reads clocks).
    let offsets = hosts.command(Host::Remote, "cat").arg("/proc/self/timens_offsets").output().expect("cat runs");
    let offsets = String::from_utf8_lossy(&offsets.stdout).into_owned();
    assert!(offsets.lines().any(|l| l.split_whitespace().eq(["monotonic", "1000", "0"])), "{offsets}");
    let (before, local, after) = monotonic_on(&hosts, Host::Local);
    assert!(before <= local && local <= after, "the local host's clock is this machine's: {before} {local} {after}");
    let (before, remote, after) = monotonic_on(&hosts, Host::Remote);
    let offset = 1000 * 1_000_000_000;
    assert!(
        before + offset <= remote && remote <= after + offset,
        "the remote clock read {remote} ns, not within [{before}, {after}] + 1000 s"
    );
}

#[test]
#[cfg_attr(netns_unavailable, ignore = "needs root, iproute2 and util-linux (network namespaces)")]
fn a_slow_link_delays_the_round_trip_drops_packets_and_leaves_no_rule() {
    let hosts = test_hosts("slow", None);
    let (at, server) = echo_server(&hosts, Host::Remote);
    let mut stream = connect_from(&hosts, Host::Local, at);
    let delay = Duration::from_millis(1);

    let slow = hosts.slow_link(delay, 0.0).expect("a slow link");
    let round_trips: Vec<Duration> = (0..50).map(|i| round_trip(&mut stream, i)).collect();
    // Each reply leaves the remote host as at least one packet, held for the delay.
    assert!(round_trips.iter().all(|&t| t >= delay), "a round trip shorter than the delay: {round_trips:?}");
    assert!(slow.delayed_packets() >= 50, "{} packets delayed", slow.delayed_packets());
    assert_eq!(slow.dropped_packets(), 0);
    drop(slow);
    let rules = hosts.remote_iptables_rules().expect("iptables runs");
    assert!(!rules.contains("LOOPLAB_SLOW") && !rules.contains("NFQUEUE"), "rules left:\n{rules}");
    round_trip(&mut stream, 1);

    let lossy = hosts.slow_link(delay, 0.25).expect("a lossy slow link");
    // Bounded: at a quarter of the packets dropped, one batch of 20 round trips all but surely
    // loses one; TCP sends it again after its retransmission timeout.
    let mut batches = 0;
    while lossy.dropped_packets() == 0 && batches < 10 {
        for i in 0..20 {
            assert!(round_trip(&mut stream, i) >= delay);
        }
        batches += 1;
    }
    assert!(lossy.dropped_packets() > 0, "no packet dropped in {batches} batches");
    drop(lossy);
    let rules = hosts.remote_iptables_rules().expect("iptables runs");
    assert!(!rules.contains("LOOPLAB_SLOW") && !rules.contains("NFQUEUE"), "rules left:\n{rules}");
    round_trip(&mut stream, 2);
    drop(stream);
    assert_eq!(server.join().expect("no panic").ip(), address(&hosts, Host::Local));
}

#[test]
#[cfg_attr(netns_unavailable, ignore = "needs root, iproute2 and util-linux (network namespaces)")]
fn a_cut_link_passes_nothing_until_it_is_mended() {
    let hosts = test_hosts("cut", None);
    let (at, server) = echo_server(&hosts, Host::Remote);
    hosts.cut_link().expect("cut");
    hosts.cut_link().expect("cutting twice is cutting once");
    let attempt = hosts
        .spawn_in(Host::Local, move || TcpStream::connect_timeout(&at, Duration::from_millis(300)))
        .join()
        .expect("no panic");
    assert_eq!(attempt.map(drop).map_err(|e| e.kind()), Err(std::io::ErrorKind::TimedOut));
    hosts.mend_link().expect("mend");
    let rules = hosts.remote_iptables_rules().expect("iptables runs");
    assert!(!rules.contains("DROP"), "rules left:\n{rules}");
    let mut stream = connect_from(&hosts, Host::Local, at);
    round_trip(&mut stream, 3);
    drop(stream);
    assert_eq!(server.join().expect("no panic").ip(), address(&hosts, Host::Local));
}

#[test]
#[cfg_attr(netns_unavailable, ignore = "needs root, iproute2 and util-linux (network namespaces)")]
fn dropping_the_hosts_kills_their_processes_and_leaves_nothing() {
    let hosts = test_hosts("drop", Some(5));
    let mut sleepers: Vec<_> = [Host::Local, Host::Remote]
        .map(|host| hosts.command(host, "sleep").arg("1000").stdin(Stdio::null()).spawn().expect("sleep starts"))
        .into();
    // Wait until both really run on their hosts (the prefixes exec in place: same pids).
    for (sleeper, host) in sleepers.iter_mut().zip([Host::Local, Host::Remote]) {
        let ns = hosts.namespace(host).to_owned();
        let pid = sleeper.id().to_string();
        while !Command::new("ip")
            .args(["netns", "pids", &ns])
            .output()
            .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).split_whitespace().any(|p| p == pid))
        {
            assert_eq!(sleeper.try_wait().expect("waitable"), None, "sleep on {host:?} ended early");
            std::thread::sleep(Duration::from_millis(5));
        }
    }
    let namespaces = [Host::Local, Host::Remote].map(|host| hosts.namespace(host).to_owned());
    let files = hosts.namespace_files();
    assert_eq!(files.len(), 2, "a mount and a time namespace");
    let lock = std::path::Path::new("/run/looplab-test").join(format!("lock-{}", hosts.number()));
    assert!(files.iter().chain([&lock]).all(|f| f.exists()));
    drop(hosts);
    for sleeper in &mut sleepers {
        assert_eq!(sleeper.wait().expect("reaped").signal(), Some(libc::SIGKILL));
    }
    let listed = Command::new("ip").args(["netns", "list"]).output().expect("ip runs");
    let listed = String::from_utf8_lossy(&listed.stdout).into_owned();
    for ns in &namespaces {
        assert!(!listed.lines().any(|l| l.split_whitespace().next() == Some(ns)), "{ns} is still listed");
        assert!(!std::path::Path::new("/run/netns").join(ns).exists());
    }
    for file in files.iter().chain([&lock]) {
        assert!(!file.exists(), "{} is left", file.display());
    }
}
