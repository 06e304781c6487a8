//! The probe (`looplab run --probe`, `launcher::probe`): its place in a run's summary and
//! report, and `looplab probe`, the same sleeps on their own, against `cyclictest` (Debian's
//! `rt-tests`; `.ci/run` installs it).
//!
//! The two are measured at once, on the same CPU, each CPU in turn: same interval (1 ms), same
//! policy and priority (SCHED_FIFO 1: cyclictest 2.40 refuses to start where it may not set
//! SCHED_FIFO, even with `--policy=other`, so the test needs root and is marked ignored elsewhere,
//! `services/build.rs`), memory locked alike, cyclictest with `--default-system` (it would
//! otherwise hold /dev/cpu_dma_latency at 0, which on this VM's haltpoll idle moves p50 from 38 to 22 µs: a
//! machine state the probe, and the loop, do not get). Measured at once, both sample the same
//! machine state; one after the other they do not. On the 2-vCPU VM, p99 of the probe ÷
//! cyclictest's, about 10 000–20 000 wake-ups pooled per side:
//! - one after the other in 1 s segments (probe, cyclictest, alternating, each CPU in turn),
//!   idle: 1.03 0.94 1.08 0.99 0.99 1.14 1.03 0.84 0.96 1.70: a burst of ms-late wake-ups lasting
//!   about a second (the host's, or another build's) lands in one side's segment and moves its
//!   pooled p99 (segments' p99 of 4.9 and 5.5 ms seen beside 0.2 ms);
//! - one after the other in 0.25 s segments, under `yes > /dev/null` and an fsync'd `dd` loop:
//!   1.38 0.92 1.05 0.84 1.42;
//! - at once, on the same CPU (this test), idle (p99 130–190 µs): 1.03 1.07 1.01 0.99 1.09 0.94
//!   1.00 0.97 1.03 0.87; under the same load (p99 0.57–1.35 ms): 0.93 0.85 0.87 0.93 1.00 0.78
//!   0.79 1.18 0.97 0.96.
//!
//! So the 20 % holds idle but not under load (0.78 twice in ten), and the test asserts
//! what held in every repetition with room: within 1.5× either way. Why not 20 %: under load the
//! tail is flat from p99 to p99.9 (0.6–1 ms to 2.0–2.4 ms), so the p99 of 20 000 wake-ups (the
//! 200th latest) moves by a quarter when a few dozen wake-ups fall on one side of it rather than
//! the other; in the loaded runs the p99.9 agreed within 13 %. The probe came out lower more
//! often than not (not explained; candidates: both at FIFO 1 on one CPU, the one woken second
//! waits for the other's few µs, and cyclictest's main thread wakes every 10 ms), which 1.5×
//! covers. It still fails a probe that does not measure what cyclictest does: the bench's 1 kHz
//! timerfd line (issue 44) gave p99 613 µs on an idle machine where cyclictest gave 45–53 µs.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Stdio};

use crate::common::{fresh_dir, looplab, run};

/// `--probe` puts the probe's numbers in summary.json and its line beside the tick's in the
/// report; lockstep, which has no timer, refuses it.
#[test]
fn a_run_with_the_probe_reports_it_beside_the_tick() {
    let r = run("probe", &["pendulum", "--duration", "1", "--probe"]);
    let probe = r.summary().probe.as_ref().expect("summary.json has the probe");
    assert_eq!(probe.interval_ns, 1_000_000);
    assert_eq!(probe.wake_latency_ns.count + probe.overruns, 1000, "a deadline per loop: {probe:?}");
    assert!(r.stdout().contains("the OS alone woke the probe p99"), "{}", r.stdout());
    let lockstep =
        crate::common::looplab().args(["run", "pendulum", "--mode", "lockstep", "--probe"]).output().unwrap();
    assert_eq!(lockstep.status.code(), Some(2), "{}", String::from_utf8_lossy(&lockstep.stderr));
}

/// Segments measured at once, and wake-ups in each: 20 s in all.
const SEGMENTS: usize = 10;
const LOOPS: u64 = 2_000;

/// `looplab probe` and `cyclictest` at once on the same CPU, each CPU in turn, at the same
/// interval, policy and priority: their pooled p99 agree within 1.5× (20 % idle; under load it
/// does not hold, the header says why).
#[test]
#[cfg_attr(cyclictest_unavailable, ignore = "needs root and cyclictest (rt-tests; .ci/run installs it)")]
fn the_probe_alone_agrees_with_cyclictest_at_p99() {
    assert!(
        Command::new("cyclictest").arg("--help").stdout(Stdio::null()).stderr(Stdio::null()).status().is_ok(),
        "cyclictest is not installed: `apt-get install rt-tests` (.ci/run installs it)"
    );
    assert!(fifo_permitted(), "SCHED_FIFO 1 is not permitted: cyclictest and this test need CAP_SYS_NICE");
    let dir = fresh_dir("probe-cyclictest");
    std::fs::create_dir_all(&dir).unwrap();
    let cpus = allowed_cpus();
    let (mut probe, mut cyclic) = (BTreeMap::new(), BTreeMap::new());
    let mut segments = vec![];
    for segment in 0..SEGMENTS {
        let cpu = cpus[segment % cpus.len()];
        let (probe_json, cyclic_json) =
            (dir.join(format!("probe-{segment}.json")), dir.join(format!("ct-{segment}.json")));
        let mut ours = looplab();
        ours.args(["probe", "--interval-us", "1000", "--loops", &LOOPS.to_string(), "--cpu", &cpu.to_string()]);
        ours.arg("--json").arg(&probe_json);
        let mut theirs = Command::new("cyclictest");
        theirs.args(["-q", "-i", "1000", "-l", &LOOPS.to_string(), "-a", &cpu.to_string(), "-h", "100000"]);
        theirs.args(["--default-system", &format!("--json={}", cyclic_json.display())]);
        ours.args(["--priority", "1", "--mlock"]);
        theirs.args(["-p", "1", "-m"]);
        // Started in turn first, so neither always has the head start.
        let started: Vec<_> = if segment % 2 == 0 { [&mut ours, &mut theirs] } else { [&mut theirs, &mut ours] }
            .into_iter()
            .map(|c| c.stdout(Stdio::null()).stderr(Stdio::piped()).spawn().expect("start it"))
            .collect();
        for child in started {
            let out = child.wait_with_output().unwrap();
            assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        }
        let (p, c) = (probe_histogram(&probe_json), cyclictest_histogram(&cyclic_json));
        segments.push(format!("CPU {cpu}: {:?}/{:?}", quantile(&p, 0.99), quantile(&c, 0.99)));
        p.into_iter().for_each(|(us, n)| *probe.entry(us).or_insert(0) += n);
        c.into_iter().for_each(|(us, n)| *cyclic.entry(us).or_insert(0) += n);
    }
    let counts = [probe.values().sum::<u64>(), cyclic.values().sum::<u64>()];
    // The probe counts a deadline it woke too late for among its loops, cyclictest does not.
    let wanted = SEGMENTS as u64 * LOOPS;
    assert!(counts[0] >= wanted * 9 / 10 && counts[1] == wanted, "wake-ups: {counts:?} of {wanted}");
    let (ours, theirs) = (quantile(&probe, 0.99).unwrap(), quantile(&cyclic, 0.99).unwrap());
    let ratio = ours as f64 / theirs as f64;
    eprintln!(
        "probe against cyclictest, SCHED_FIFO 1: p99 {ours} µs against {theirs} µs ({ratio:.3}); p50 {:?}/{:?}, \
         p99.9 {:?}/{:?}; p99 per segment, probe/cyclictest: {}",
        quantile(&probe, 0.5),
        quantile(&cyclic, 0.5),
        quantile(&probe, 0.999),
        quantile(&cyclic, 0.999),
        segments.join(", ")
    );
    assert!(
        (1.0 / 1.5..=1.5).contains(&ratio),
        "p99: the probe {ours} µs, cyclictest {theirs} µs, {ratio:.3}×; per segment: {}",
        segments.join(", ")
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Whether this process may give a thread SCHED_FIFO 1: tried on a thread of its own.
fn fifo_permitted() -> bool {
    std::thread::spawn(|| {
        let param = libc::sched_param { sched_priority: 1 };
        // SAFETY: pid 0 is this short-lived thread; `param` is a valid sched_param.
        unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) == 0 }
    })
    .join()
    .unwrap()
}

/// The CPUs this process may run on.
fn allowed_cpus() -> Vec<usize> {
    // SAFETY: a zeroed cpu_set_t is a valid empty set; sched_getaffinity fills it.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        assert_eq!(libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set), 0);
        (0..libc::CPU_SETSIZE as usize).filter(|&c| libc::CPU_ISSET(c, &set)).collect()
    }
}

/// `looplab probe --json`'s histogram, µs → wake-ups, after checking it ran as asked.
fn probe_histogram(path: &Path) -> BTreeMap<u64, u64> {
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    let policy = (json["policy"].as_str().unwrap(), json["priority"].as_u64().unwrap());
    assert_eq!(policy, ("fifo", 1), "{json}");
    let rows = json["histogram_us"].as_array().unwrap();
    rows.iter().map(|row| (row[0].as_u64().unwrap(), row[1].as_u64().unwrap())).collect()
}

/// cyclictest's `--json` histogram (with `-h`), µs → wake-ups; none above its 100 ms limit.
fn cyclictest_histogram(path: &Path) -> BTreeMap<u64, u64> {
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    assert_eq!(json["return_code"], 0, "{path:?}");
    let thread = &json["thread"]["0"];
    let histogram = thread["histogram"].as_object().unwrap_or_else(|| panic!("no histogram in {path:?}"));
    let h: BTreeMap<u64, u64> = histogram.iter().map(|(us, n)| (us.parse().unwrap(), n.as_u64().unwrap())).collect();
    assert_eq!(h.values().sum::<u64>(), thread["cycles"].as_u64().unwrap(), "a wake-up over 100 ms: {path:?}");
    h
}

/// The smallest µs at or under which a share `q` of the wake-ups fall.
fn quantile(h: &BTreeMap<u64, u64>, q: f64) -> Option<u64> {
    let total = h.values().sum::<u64>();
    let mut seen = 0;
    h.iter()
        .find(|&(_, n)| {
            seen += n;
            seen as f64 >= q * total as f64
        })
        .map(|(us, _)| *us)
}
