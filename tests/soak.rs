//! A real-time soak on a busy machine: the test starts its own CPU hog and a disk writer that
//! fsyncs without pause, then kills every process of the loop and freezes two of them. It checks
//! only outcomes that do not depend on how fast the machine is: every fault seen, every process
//! back, the run complete, every loop either recorded or reported missing, nothing left behind.

mod common;

use common::*;
use looplab_shared::bench::restarts::Load;

#[test]
fn under_cpu_and_fsync_load_every_killed_process_comes_back_and_nothing_is_lost_or_left() {
    let kills = [
        ("plant", 1.0),
        ("sensors", 1.5),
        ("estimator", 2.0),
        ("controller", 2.5),
        ("monitor", 3.0),
        ("plant", 4.0),
        ("sensors", 4.5),
        ("estimator", 5.0),
        ("controller", 5.5),
    ];
    let stops = [("controller", 6.5), ("sensors", 7.2)];
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
    let s = &r.summary;

    assert_eq!(s["completed"], true, "{}", s["stopped_because"]);
    assert_eq!(s["loops"], 8000);
    for (i, (process, _)) in kills.iter().enumerate() {
        let f = &s["faults"][i];
        assert_eq!(f["detected_by"], "the process exited", "{process}: {f}");
        assert!(f["restarted_after_ms"].is_number(), "{process} came back: {f}");
    }
    for (i, (process, _)) in stops.iter().enumerate() {
        let f = &s["faults"][kills.len() + i];
        assert!(f["detected_after_ms"].is_number(), "{process}'s stop was seen: {f}");
        assert!(f["continued_after_ms"].is_number(), "{process} was continued: {f}");
    }
    for process in ["plant", "sensors", "estimator", "controller", "monitor"] {
        let killed = kills.iter().filter(|(p, _)| *p == process).count();
        assert_eq!(s["restarts"][process], killed, "{process}");
    }
    let steps = s["restart_steps"].as_array().unwrap();
    assert_eq!(steps.len(), kills.len());
    for step in steps {
        for key in ["cleaned_after_ms", "spawned_after_ms", "ready_after_ms"] {
            assert!(step[key].is_number(), "every restart went through every step: {step}");
        }
    }
    // Every loop is accounted for: recorded, or reported missing (the monitor was down for some).
    let m = &s["monitor"];
    assert_eq!(
        m["records"].as_u64().unwrap() + m["missing_loops"].as_u64().unwrap(),
        s["loops"].as_u64().unwrap(),
        "{m}"
    );
    let last: std::collections::BTreeMap<&str, &serde_json::Value> =
        s["processes"].as_array().unwrap().iter().map(|p| (p["name"].as_str().unwrap(), &p["exit"])).collect();
    for (name, exit) in last {
        assert_eq!(*exit, "0", "{name}'s last incarnation ended cleanly");
    }
    for p in s["processes"].as_array().unwrap() {
        assert!(!alive(p["pid"].as_i64().unwrap()), "{p} is still running");
    }
    assert_eq!(s["shared_memory"]["clean"], true, "{}", s["shared_memory"]);
    let left = looplab_shared::ipc::files_of_run(s["run_id"].as_str().unwrap());
    assert!(left.is_empty(), "files left behind: {left:?}");
}
