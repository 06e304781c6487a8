//! Every late loop has a cause (`monitor::cause`), on real runs of the five processes: a stopped
//! controller, a controller of one's own that sleeps in its step, a process that takes the
//! controller's CPU; the parts of every loop add up to its response time (checked against the
//! stamps and run-queue waits in loops.csv, recomputed here); and the misses in loops.csv, the
//! summary and the report agree.

use crate::common;

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use common::*;
use looplab_shared::contract::msg::LoopTrace;

const REPO: &str = env!("CARGO_MANIFEST_DIR");

/// loops.csv by column name, its cells as text.
struct Loops(Table);

impl Loops {
    fn read(dir: &Path) -> Self {
        Loops(Table::read(&dir.join("loops.csv")))
    }

    fn rows(&self) -> impl Iterator<Item = usize> {
        0..self.0.rows.len()
    }

    fn text(&self, row: usize, column: &str) -> &str {
        let i = *self.0.columns.get(column).unwrap_or_else(|| panic!("no column {column}"));
        &self.0.rows[row][i]
    }

    /// A whole-number cell; None if empty.
    fn number(&self, row: usize, column: &str) -> Option<u64> {
        let cell = self.text(row, column);
        (!cell.is_empty()).then(|| cell.parse().unwrap_or_else(|_| panic!("{column}: {cell:?}")))
    }

    fn k(&self, row: usize) -> u64 {
        self.number(row, "k").unwrap()
    }

    fn missed(&self, row: usize) -> bool {
        self.text(row, "deadline_miss") == "1"
    }

    fn cause(&self, row: usize) -> &str {
        self.text(row, "cause")
    }
}

/// The misses agree everywhere: loops.csv's flags count what the plant counted (summary.json's
/// `deadline_misses`, skipped ticks included), every one has a cause there, the causes tally as
/// summary.json's `misses_by_cause`, and the report's line says the same. Returns loops.csv.
fn assert_misses_agree(run: &Run) -> Loops {
    let s = run.summary();
    let loops = Loops::read(&run.dir);
    assert_eq!(s.monitor.lost, 0, "the monitor saw every loop");
    let mut tally: BTreeMap<String, u64> = BTreeMap::new();
    for row in loops.rows().filter(|&row| loops.missed(row)) {
        assert!(!loops.cause(row).is_empty(), "loop {} missed with no cause", loops.k(row));
        *tally.entry(loops.cause(row).to_owned()).or_default() += 1;
    }
    assert_eq!(tally.values().sum::<u64>(), s.deadline_misses, "loops.csv's misses against the plant's count");
    let summarised: BTreeMap<String, u64> = s.misses_by_cause.iter().map(|(c, t)| (c.clone(), t.loops)).collect();
    assert_eq!(tally, summarised);
    // The report, printed again from the run folder.
    let report = looplab().arg("report").arg(&run.dir).output().expect("looplab report");
    let report = String::from_utf8_lossy(&report.stdout).into_owned();
    if s.deadline_misses > 0 {
        let line = report.lines().find(|l| l.trim_start().starts_with("why the deadline misses")).expect(&report);
        assert!(line.contains(&format!("({};", s.deadline_misses)), "{line}");
        for (cause, n) in &tally {
            assert!(line.contains(&format!(" {n} {cause}")), "{cause}: {n} not in {line}");
        }
        let headline = format!("deadline misses {} of {}", s.deadline_misses, s.loops);
        assert!(report.contains(&headline), "{headline:?} not in\n{report}");
    }
    loops
}

#[test]
fn a_stopped_controller_is_the_cause_of_every_miss_in_its_outage() {
    let r = run("explain-stop", &["pendulum", "--duration", "2.5", "--fault", "stop controller at 1s for 300ms"]);
    let loops = assert_misses_agree(&r);
    let effect = r.summary().faults[0].effect.as_ref().expect("its effect");
    let during = effect.phases.as_ref().expect("phases").during.clone();
    assert!(during.to_k - during.from_k >= 300, "a 300 ms stop at 1 kHz: {during:?}");
    let mut in_outage = 0;
    for row in loops.rows().filter(|&row| loops.missed(row) && (during.from_k..during.to_k).contains(&loops.k(row))) {
        assert_eq!(loops.cause(row), "fault: stop controller", "loop {}", loops.k(row));
        in_outage += u64::from(loops.number(row, "tick_scheduled_ns").is_some());
    }
    assert_eq!(in_outage, during.misses, "the fault's phase counts the loops with a state");
}

/// The example C controller with a sleep of 8 ms in its step every 250th loop.
const SLEEPY_CONTROLLER: &str = r#"
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <time.h>
#include "looplab_stage.h"

struct law { double gains[3], limit; };

static int step(void *user, double t, const double *x, size_t n_x, double *u, size_t n_u) {
    (void)n_x, (void)n_u;
    const struct law *k = user;
    if ((long)(t * 1000.0 + 0.5) % 250 == 125) {
        struct timespec nap = { 0, 8000000 };
        nanosleep(&nap, NULL);
    }
    double current = -(k->gains[0] * x[0] + k->gains[1] * x[1] + k->gains[2] * x[2]);
    u[0] = current < -k->limit ? -k->limit : current > k->limit ? k->limit : current;
    return 0;
}

int main(void) {
    struct law k;
    if (looplab_config_f64("controller.gains.0", &k.gains[0]) || looplab_config_f64("controller.gains.1", &k.gains[1])
        || looplab_config_f64("controller.gains.2", &k.gains[2]) || looplab_config_f64("model.current_limit_a", &k.limit)) {
        return 2;
    }
    return looplab_run(step, &k);
}
"#;

#[test]
fn a_controller_that_sleeps_in_its_step_is_the_cause_of_the_loops_it_made_late() {
    let dir = fresh_dir("sleepy-source");
    std::fs::create_dir_all(&dir).unwrap();
    let source = dir.join("sleepy_controller.c");
    std::fs::write(&source, SLEEPY_CONTROLLER).unwrap();
    let program = crate::c_and_rust_stages::compile_c("sleepy_controller", &source);
    let launch = Path::new(REPO).join("services/examples/controller/pendulum_c.toml").display().to_string();
    let command = format!("stages.controller.command=[{:?}]", program.display().to_string());
    let r = run("explain-sleepy", &[&launch, "--duration", "2.2", "--set", &command]);
    let loops = assert_misses_agree(&r);
    let mut naps = 0;
    for row in loops.rows() {
        let k = loops.k(row);
        // The controller's own message of the loop is there (its run-queue column): it handled it.
        let handled = |column: &str| loops.number(row, column).is_some();
        if k % 250 == 125 && handled("controller_queued_ns") {
            // Its own loop: 8 ms in the step.
            naps += 1;
            assert!(loops.missed(row), "loop {k}");
            assert_eq!(loops.cause(row), "compute: controller", "loop {k}");
            assert!(loops.number(row, "cause_part_ns").unwrap() >= 8_000_000, "loop {k}");
        } else if k % 250 > 125
            && k % 250 < 125 + 7
            && handled("estimator_queued_ns")
            && !handled("controller_queued_ns")
        {
            // The loops whose estimate came while it slept, which it skipped: it was computing
            // an earlier one (or, on a busy machine, waited for its CPU after).
            let cause = loops.cause(row);
            assert!(["compute: controller", "queued: controller"].contains(&cause), "loop {k}: {cause}");
        }
    }
    // A busy machine may skip the very tick of a nap (its cause is then the plant's timer).
    assert!(naps >= 1, "no nap was handled");
}

/// The response time of one loops.csv row in parts, recomputed from its stamps and run-queue
/// waits as `monitor::cause` documents them: (cause, ns) in the order they pass. `earlier[stage]`
/// is when the stage's last output of an earlier loop went out and its run-queue wait while it
/// computed that one.
fn parts_of(loops: &Loops, row: usize, earlier: &BTreeMap<&str, (u64, u64)>) -> Option<Vec<(String, u64)>> {
    let stamp = |name: &str| loops.number(row, &format!("{name}_ns"));
    let stamps: Vec<u64> = LoopTrace::STAMP_NAMES.iter().map(|n| stamp(n)).collect::<Option<_>>()?;
    let queued = |column: &str| loops.number(row, column).unwrap_or(0);
    let mut parts = vec![];
    let mut split = |span: u64, wait: u64, role: &str, rest: String| {
        let wait = wait.min(span);
        parts.push((format!("queued: {role}"), wait));
        parts.push((rest, span - wait));
    };
    if let (Some(due), Some(wake)) = (loops.number(row, "tick_scheduled_ns"), loops.number(row, "tick_wake_ns")) {
        // Woken for a command just before the tick was due, the plant was in time for it.
        let wake = wake.max(due);
        split(wake - due, queued("plant_tick_queued_ns"), "plant", "timer".into());
        split(stamps[0] - wake, 0, "plant", "compute: plant".into());
    }
    let roles = ["plant", "sensors", "estimator", "controller", "plant"];
    for i in 0..4 {
        let (reader, writer) = (roles[i + 1], roles[i]);
        let wait_column =
            if reader == "plant" { "plant_command_queued_ns".into() } else { format!("{reader}_queued_ns") };
        let (sent, span) = (stamps[2 * i], stamps[2 * i + 1] - stamps[2 * i]);
        // The reader still computing an earlier loop when this input went out.
        let busy = match earlier.get(reader) {
            Some(&(published, compute_wait)) if published > sent => {
                let busy = (published - sent).min(span);
                split(busy, compute_wait, reader, format!("compute: {reader}"));
                busy
            }
            _ => 0,
        };
        split(span - busy, queued(&wait_column), reader, format!("transport: {writer}->{reader}"));
        if i < 3 {
            let compute = format!("{reader}_compute_queued_ns");
            split(stamps[2 * i + 2] - stamps[2 * i + 1], queued(&compute), reader, format!("compute: {reader}"));
        }
    }
    Some(parts)
}

/// Keeps both CPUs busy from threads of this process until dropped.
struct CpuHog(Arc<AtomicBool>, Vec<std::thread::JoinHandle<()>>);

impl CpuHog {
    fn start(threads: usize) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let handles = (0..threads)
            .map(|_| {
                let stop = stop.clone();
                std::thread::spawn(move || {
                    let mut x = 0u64;
                    while !stop.load(Ordering::Relaxed) {
                        x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
                    }
                })
            })
            .collect();
        CpuHog(stop, handles)
    }
}

impl Drop for CpuHog {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
        self.1.drain(..).for_each(|h| h.join().unwrap());
    }
}

#[test]
fn every_loop_of_a_loaded_run_has_parts_that_add_up_to_its_response_time() {
    let hog = CpuHog::start(2);
    // Every loop over 1 ns end to end (all of them) is explained.
    let r = run("explain-loaded", &["pendulum", "--duration", "2", "--explain-over", "0.001"]);
    drop(hog);
    let loops = assert_misses_agree(&r);
    let mut explained = 0;
    let mut primaries: BTreeMap<String, u64> = BTreeMap::new();
    // Each stage's last output before the row: (published, run-queue wait computing it). A row
    // without a record has no stamps: the loop after it cannot be recomputed.
    let mut earlier: BTreeMap<&str, (u64, u64)> = BTreeMap::new();
    let mut after_unrecorded = 0;
    for row in loops.rows() {
        let recomputed = parts_of(&loops, row, &earlier);
        let unknown_earlier = row > 0 && loops.number(row - 1, "plant_receive_ns").is_none();
        for stage in ["sensors", "estimator", "controller"] {
            if let Some(published) = loops.number(row, &format!("{stage}_publish_ns")) {
                let wait = loops.number(row, &format!("{stage}_compute_queued_ns")).unwrap_or(0);
                earlier.insert(stage, (published, wait));
            }
        }
        let Some(parts) = recomputed else { continue };
        *primaries.entry(loops.cause(row).to_owned()).or_default() += 1;
        if unknown_earlier {
            after_unrecorded += 1;
            continue;
        }
        let k = loops.k(row);
        explained += 1;
        let response = loops.number(row, "response_ns").unwrap_or_else(|| panic!("loop {k} has no response time"));
        assert_eq!(parts.iter().map(|p| p.1).sum::<u64>(), response, "loop {k}: the parts against the response time");
        let e2e: u64 =
            parts.iter().skip(if loops.number(row, "tick_wake_ns").is_some() { 4 } else { 0 }).map(|p| p.1).sum();
        assert_eq!(e2e, loops.number(row, "end_to_end_ns").unwrap(), "loop {k}: the hops against end to end");
        if let (Some(due), Some(received)) =
            (loops.number(row, "tick_scheduled_ns"), loops.number(row, "plant_receive_ns"))
        {
            assert_eq!(response, received - due, "loop {k}");
        }
        // The primary cause: the largest part by cause, where one is largest.
        let mut by_cause: BTreeMap<String, u64> = BTreeMap::new();
        for (cause, ns) in parts {
            *by_cause.entry(cause).or_default() += ns;
        }
        let mut sorted: Vec<_> = by_cause.into_iter().collect();
        sorted.sort_by_key(|entry| std::cmp::Reverse(entry.1));
        if sorted[0].1 > sorted[1].1 {
            assert_eq!(loops.cause(row), sorted[0].0, "loop {k}: {sorted:?}");
            assert_eq!(loops.number(row, "cause_part_ns"), Some(sorted[0].1), "loop {k}");
        }
    }
    assert_eq!(explained + after_unrecorded, r.summary().monitor.records, "every loop with a command");
    let slow = r.summary().slow_loops.as_ref().expect("explain_over_us was set");
    let summarised: BTreeMap<String, u64> = slow.by_cause.iter().map(|(c, t)| (c.clone(), t.loops)).collect();
    assert_eq!(primaries, summarised);
}

/// This thread on CPU `cpu` only.
fn pin_to(pid: i32, cpu: usize) {
    // SAFETY: a zeroed cpu_set_t is an empty set; CPU_SET and sched_setaffinity get valid pointers.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu, &mut set);
        assert_eq!(libc::sched_setaffinity(pid, size_of::<libc::cpu_set_t>(), &set), 0, "sched_setaffinity {pid}");
    }
}

/// The pid of the child of `parent` named `comm`, once it exists; None if `parent` ended first.
fn child_named(parent: u32, comm: &str) -> Option<i32> {
    loop {
        for entry in std::fs::read_dir("/proc").unwrap().flatten() {
            let Ok(stat) = std::fs::read_to_string(entry.path().join("stat")) else { continue };
            let Some((name, rest)) = stat.split_once(") ") else { continue };
            let ppid = rest.split(' ').nth(1).and_then(|p| p.parse::<u32>().ok());
            if name.ends_with(&format!("({comm}")) && ppid == Some(parent) {
                return entry.file_name().to_str()?.parse().ok();
            }
        }
        if !alive(parent as i64) {
            return None;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// With `--trace-sched` the misses are also put on the task that took the CPU: a thread of this
/// test, named `ll-burst`.
#[test]
fn a_process_that_takes_the_controllers_cpu_makes_its_misses_queued_controller_behind_it() {
    if std::thread::available_parallelism().map_or(1, |n| n.get()) < 2 {
        panic!("this test needs two CPUs: the controller on one, the rest of the loop on the other");
    }
    let dir = fresh_dir("explain-queued");
    // Every process of the run on CPU 0; the controller alone moves to CPU 1 below. The loop at
    // SCHED_FIFO 10, as a real-time loop runs: whatever else a busy machine runs at the normal
    // policy does not make its misses, the bursts (FIFO 50) do.
    let mut launcher = Command::new("taskset")
        .args(["-c", "0"])
        .arg(env!("CARGO_BIN_EXE_looplab"))
        .args(["run", "pendulum", "--duration", "3", "--trace-sched", "--set", "realtime.priority=10", "-q", "--out"])
        .arg(&dir)
        .stdout(Stdio::null())
        .spawn()
        .expect("taskset looplab");
    let controller = child_named(launcher.id(), "looplab-control").expect("the controller started");
    pin_to(controller, 1);
    // Bursts of 30 ms every 200 ms at SCHED_FIFO on CPU 1, while the run goes on.
    let running = Arc::new(AtomicBool::new(true));
    let burster_tid = Arc::new(std::sync::atomic::AtomicI32::new(0));
    let burster = {
        let tid = burster_tid.clone();
        let running = running.clone();
        std::thread::Builder::new().name("ll-burst".into()).spawn(move || {
            pin_to(0, 1);
            // SAFETY: gettid has no arguments and cannot fail.
            tid.store(unsafe { libc::gettid() }, Ordering::Relaxed);
            let param = libc::sched_param { sched_priority: 50 };
            // SAFETY: sets this thread's own policy with a valid parameter.
            let set = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
            assert_eq!(set, 0, "SCHED_FIFO needs root or CAP_SYS_NICE: {}", std::io::Error::last_os_error());
            let mut bursts = vec![];
            while running.load(Ordering::Relaxed) {
                let start = now_ns();
                while now_ns() < start + 30_000_000 {
                    std::hint::spin_loop();
                }
                bursts.push((start, now_ns()));
                std::thread::sleep(Duration::from_millis(170));
            }
            bursts
        })
    }
    .unwrap();
    let status = launcher.wait().unwrap();
    running.store(false, Ordering::Relaxed);
    let bursts = burster.join().unwrap();
    assert!(status.success(), "{status}");
    let r = Run::at(dir);
    let loops = assert_misses_agree(&r);
    let (mut in_bursts, mut queued) = (0, 0);
    for row in loops.rows().filter(|&row| loops.missed(row)) {
        let Some(due) = loops.number(row, "tick_scheduled_ns") else { continue };
        if bursts.iter().any(|&(start, end)| start <= due && due < end) {
            in_bursts += 1;
            queued += u64::from(loops.cause(row) == "queued: controller");
        }
    }
    assert!(in_bursts >= 100, "{in_bursts} misses in {} bursts of 30 ms", bursts.len());
    assert!(queued * 10 >= in_bursts * 9, "{queued} of {in_bursts} misses in the bursts are queued: controller");
    // Named: the trace shows the burst thread on the controller's CPU while it waited.
    let trace = r.summary().sched_trace.as_ref().expect("the scheduler trace (the test runs as root)");
    assert!(r.dir.join(&trace.file).is_file());
    let tally = &r.summary().misses_by_cause["queued: controller"];
    let burst = format!("ll-burst (pid {}, real-time priority 50)", burster_tid.load(Ordering::Relaxed));
    let behind_burst = tally.behind.get(&burst).copied().unwrap_or(0);
    assert!(
        behind_burst * 10 >= queued * 9,
        "{behind_burst} of {queued} behind {burst}: {:?}; {trace:?}",
        tally.behind
    );
}

fn now_ns() -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: a valid timespec to write to; CLOCK_MONOTONIC always exists.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}
