//! The root package's build script: it only says whether this machine can make the test hosts
//! of `tests/netns.rs` and `tests/remote.rs` (network namespaces need root, `ip` from iproute2,
//! and `nsenter`, `unshare` and `mount` from util-linux). Where it cannot, it sets
//! `cfg(netns_unavailable)` and those tests are marked ignored, so the skip shows in the test
//! summary line instead of passing silently. Likewise `cfg(cyclictest_unavailable)` where the build
//! is not root or `cyclictest` (rt-tests) is missing: tests/probe.rs sets `looplab probe` beside
//! it, and cyclictest runs only where it may set SCHED_FIFO.

use std::process::Command;

fn main() {
    println!("cargo::rustc-check-cfg=cfg(netns_unavailable)");
    println!("cargo::rustc-check-cfg=cfg(cyclictest_unavailable)");
    // Decided again when this file changes or the build runs as another user (sudo sets these).
    println!("cargo::rerun-if-changed=services/build.rs");
    for variable in ["USER", "SUDO_UID"] {
        println!("cargo::rerun-if-env-changed={variable}");
    }
    if !test_hosts_possible() {
        println!("cargo::rustc-cfg=netns_unavailable");
    }
    if effective_uid() != Some(0) || Command::new("cyclictest").arg("--help").output().is_err() {
        println!("cargo::rustc-cfg=cyclictest_unavailable");
    }
}

/// Whether the build runs as root with every tool the test hosts use.
fn test_hosts_possible() -> bool {
    let runs = |tool: &str, version: &str| Command::new(tool).arg(version).output().is_ok_and(|o| o.status.success());
    effective_uid() == Some(0)
        && [("ip", "-V"), ("nsenter", "--version"), ("unshare", "--version"), ("mount", "--version")]
            .into_iter()
            .all(|(tool, version)| runs(tool, version))
}

/// The effective user id, from /proc (no libc in a build script); None where it is unreadable.
fn effective_uid() -> Option<u32> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    // "Uid:	real	effective	saved	filesystem"
    let line = status.lines().find(|l| l.starts_with("Uid:"))?;
    line.split_whitespace().nth(2)?.parse().ok()
}
