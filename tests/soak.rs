//! A real-time soak on a busy machine: the test starts its own CPU hog and a disk writer that
//! fsyncs without pause, then kills every process of the loop and freezes two of them. It checks
//! only outcomes that do not depend on how fast the machine is: every fault seen, every process
//! back, the run complete, every loop either recorded or reported missing, nothing left behind.

use crate::common;

use common::*;
use looplab_shared::tools::bench::restarts::Load;

#[test]
fn under_cpu_and_fsync_load_every_killed_process_comes_back_and_nothing_is_lost_or_left() {
    let kills = [
        (Role::Plant, 1.0),
        (Role::Sensors, 1.5),
        (Role::Estimator, 2.0),
        (Role::Controller, 2.5),
        (Role::Monitor, 3.0),
        (Role::Plant, 4.0),
        (Role::Sensors, 4.5),
        (Role::Estimator, 5.0),
        (Role::Controller, 5.5),
    ];
    let stops = [(Role::Controller, 6.5), (Role::Sensors, 7.2)];
    let mut args: Vec<String> = vec!["--duration".into(), "8".into()];
    for (process, at) in kills {
        args.extend(["--fault".into(), format!("kill {process} at {at}s")]);
    }
    for (process, at) in stops {
        args.extend(["--fault".into(), format!("stop {process} at {at}s for 200ms")]);
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
    assert_eq!(s.loops, 8000);
    for (i, (process, _)) in kills.iter().enumerate() {
        let f = &s.faults[i];
        assert_eq!(f.detected_by, Some(DetectedBy::ProcessExited), "{process}: {f:?}");
        assert!(f.restarted_after_ms.is_some(), "{process} came back: {f:?}");
    }
    for (i, (process, _)) in stops.iter().enumerate() {
        let f = &s.faults[kills.len() + i];
        assert!(f.detected_after_ms.is_some(), "{process}'s stop was seen: {f:?}");
        assert!(f.continued_after_ms.is_some(), "{process} was continued: {f:?}");
    }
    for process in Role::ALL {
        let killed = kills.iter().filter(|(p, _)| *p == process).count() as u32;
        assert_eq!(s.restarts[&process], killed, "{process}");
    }
    assert_eq!(s.restart_steps.len(), kills.len());
    for step in &s.restart_steps {
        assert!(
            step.cleaned_after_ms.is_some() && step.spawned_after_ms.is_some() && step.ready_after_ms.is_some(),
            "every restart went through every step: {step:?}"
        );
    }
    // Every loop is accounted for: recorded, or reported missing (the monitor was down for some).
    let m = &s.monitor;
    assert_eq!(m.records + m.missing.missing_loops, s.loops, "{m:?}");
    for (name, p) in last_incarnations(s) {
        assert_eq!(p.exit, Exit::Status(0), "{name}'s last incarnation ended cleanly");
    }
    for p in &s.processes {
        assert!(!alive(i64::from(p.pid)), "{p:?} is still running");
    }
    assert!(s.shared_memory.clean, "{:?}", s.shared_memory);
    let left = looplab_shared::runtime::storage::run_storage::files_of_run(&s.run_id);
    assert!(left.is_empty(), "files left behind: {left:?}");
}
