//! A real-time soak on a busy machine: the test starts its own CPU hog and a disk writer that
//! fsyncs without pause, then injects 45 seeded kills and stops, nine on each process of the
//! loop. It checks only outcomes that do not depend on how fast the machine is: every fault
//! seen by its own detection, every process back, the run complete, every loop either recorded
//! or reported missing, the recording missing only what went with a killed monitor, nothing left
//! behind.
//!
//! It runs 36 s; `LOOPLAB_SOAK_S=180` makes it the three-minute soak.

use crate::common;

use common::*;
use looplab_shared::tools::bench::restarts::Load;

/// The faults, in time order: (the fault's text, its process, whether it is a kill). Nine per
/// process, one every (duration − 2 s) / 45, each kill or stop and each stop's length drawn from
/// `seed` (xorshift: the same faults on every machine).
fn seeded_faults(duration_s: f64, seed: u64) -> Vec<(String, Role, bool)> {
    let mut state = seed;
    let mut draw = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let processes = [Role::Plant, Role::Sensors, Role::Estimator, Role::Controller, Role::Monitor];
    let spacing = (duration_s - 2.0) / 45.0;
    (0..45)
        .map(|i| {
            let process = processes[i % processes.len()];
            let at = 1.0 + i as f64 * spacing;
            if draw() % 5 < 3 {
                (format!("kill {process} at {at:.3}s"), process, true)
            } else {
                // The monitor is found stopped by its silence, which a stop must outlast.
                let ms = [200, 250, 300][(draw() % 3) as usize];
                (format!("stop {process} at {at:.3}s for {ms}ms"), process, false)
            }
        })
        .collect()
}

#[test]
fn under_cpu_and_fsync_load_every_fault_is_detected_and_only_a_killed_monitors_loops_are_lost() {
    let duration_s: f64 = std::env::var("LOOPLAB_SOAK_S").ok().and_then(|s| s.parse().ok()).unwrap_or(36.0);
    let faults = seeded_faults(duration_s, 0x5eed_1005);
    let mut args: Vec<String> = vec!["--duration".into(), duration_s.to_string()];
    for (fault, _, _) in &faults {
        args.extend(["--fault".into(), fault.clone()]);
    }
    let scratch = fresh_dir("soak-load");
    std::fs::create_dir_all(&scratch).unwrap();
    let load = Load::start(&scratch, 1).expect("start the load");
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let r = run("soak", &args);
    drop(load);
    std::fs::remove_dir_all(&scratch).unwrap();
    let s = r.summary();

    assert!(s.completed, "{:?}", s.stopped_because);
    assert_eq!(s.loops, (duration_s * 1000.0) as u64);
    let mut monitor_kills = vec![];
    for (f, (fault, process, kill)) in s.faults.iter().zip(&faults) {
        // Each by its own detection, never a stall found later (the ledger credits a stall to a
        // stop only if it began before the SIGCONT).
        let by = match (kill, process) {
            (true, _) => DetectedBy::ProcessExited,
            (false, Role::Monitor) => DetectedBy::MonitorHeartbeat,
            (false, _) => DetectedBy::InputDeadline,
        };
        assert_eq!(f.detected_by, Some(by), "{fault}: {f:?}");
        if *kill {
            assert!(f.restarted_after_ms.is_some(), "{fault}: it came back: {f:?}");
            let effect = f.effect.as_ref().unwrap_or_else(|| panic!("{fault}: no effect: {f:?}"));
            assert!(!effect.never_back, "{fault}: reported never back: {effect:?}");
            if *process == Role::Monitor {
                monitor_kills.push(effect.phases.as_ref().expect("phases").during.from_k);
            }
        } else {
            assert!(f.continued_after_ms.is_some(), "{fault}: it was continued: {f:?}");
        }
    }
    for process in Role::ALL {
        let kills = faults.iter().filter(|(_, p, kill)| *p == process && *kill).count() as u32;
        assert_eq!(s.restarts[&process], kills, "{process}");
    }
    assert_eq!(s.restart_steps.len(), faults.iter().filter(|(_, _, kill)| *kill).count());
    for step in &s.restart_steps {
        assert!(
            step.cleaned_after_ms.is_some() && step.spawned_after_ms.is_some() && step.ready_after_ms.is_some(),
            "every restart went through every step: {step:?}"
        );
    }

    // Every loop is accounted for: recorded, or reported missing.
    let m = &s.monitor;
    assert_eq!(m.records + m.missing.missing_loops, s.loops, "{m:?}");
    // trajectory.csv has a row for every loop but those that went with a killed monitor: each
    // gap runs from its last save to its successor's first loop, across the kill.
    let ks: Vec<u64> = std::fs::read_to_string(r.dir.join("trajectory.csv"))
        .unwrap()
        .lines()
        .skip(1)
        .map(|row| row.split(',').next().unwrap().parse().unwrap())
        .collect();
    assert_eq!(ks.len() as u64 + m.missing.missing_before_restart, s.loops, "{m:?}");
    let mut gaps = vec![];
    let mut expected = 0;
    for &k in ks.iter().chain([s.loops].iter()) {
        assert!(k >= expected, "trajectory.csv: loop {k} after {}", expected - 1);
        if k > expected {
            gaps.push((expected, k - 1));
        }
        expected = k + 1;
    }
    for &(from, to) in &gaps {
        assert!(
            monitor_kills.iter().any(|&kill| from <= kill + 1 && kill <= to),
            "loops {from}–{to} are missing from trajectory.csv with no monitor killed there (kills at {monitor_kills:?})"
        );
    }
    assert!(gaps.len() <= monitor_kills.len(), "{gaps:?} against kills at {monitor_kills:?}");

    for (name, p) in last_incarnations(s) {
        assert_eq!(p.exit, Exit::Status(0), "{name}'s last incarnation ended cleanly");
    }
    for p in &s.processes {
        assert!(!alive(i64::from(p.pid)), "{p:?} is still running");
    }
    assert!(s.shared_memory.clean, "{:?}", s.shared_memory);
    let left = looplab_shared::runtime::storage::run_storage::files_of_run(&s.run_id);
    assert!(left.is_empty(), "files left behind: {left:?}");
    let in_tmp: Vec<_> = std::fs::read_dir(std::env::temp_dir())
        .unwrap()
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|name| name.contains(&s.run_id))
        .collect();
    assert!(in_tmp.is_empty(), "left in the temporary folder: {in_tmp:?}");
}
