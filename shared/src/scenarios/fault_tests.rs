//! The bounds of fault settings, checked through a real scenario's resolution (config's own
//! tests cannot resolve a scenario: it is a layer above them).

use crate::config::launch::{LaunchError, Override};

/// The error that the pendulum's defaults (10 s at 1 kHz) with this `--fault` give, if any.
fn checked(fault: &str) -> Result<(), LaunchError> {
    let overrides = [Override::fault(fault).unwrap()];
    crate::scenarios::resolve("pendulum", &overrides).map(|_| ())
}

fn rejected(fault: &str, key: &str, fragment: &str) {
    let e = checked(fault).unwrap_err();
    assert_eq!(e.origin, format!("--fault {fault}"));
    assert_eq!(e.key.as_deref(), Some(key), "{fault}: {e}");
    assert!(e.message.contains(fragment), "{fault}: {e}");
}

#[test]
fn fault_times_and_amounts_are_bounded() {
    rejected("stop controller at 1s for 1e19s", "faults.0.duration_s", "at most 3600");
    rejected("stop controller at 1s for 3601s", "faults.0.duration_s", "at most 3600");
    checked("stop controller at 1s for 3600s").unwrap();
    rejected("drop sensors 20% at 1s for 604801s", "faults.0.duration_s", "at most 604800");
    checked("drop sensors 20% at 1s for 60s").unwrap();
    rejected("delay controller by 1e20s at 1s", "faults.0.delay_s", "less than the run's duration_s = 10 s");
    rejected("delay controller by 10s at 1s", "faults.0.delay_s", "less than the run's duration_s");
    checked("delay controller by 9.999s at 1s").unwrap();
    rejected("delay controller by 10001 ticks at 1s", "faults.0.delay_ticks", "at most the run's 10000 loops");
    checked("delay controller by 10000 ticks at 1s").unwrap();
    rejected("kill plant at 1e19s", "faults.0.at_s", "within the run");
    rejected("kill plant at -1s", "faults.0.at_s", "within the run");
    rejected("drop sensors nan% at 1s", "faults.0.probability", "finite");
    rejected("drop sensors 101% at 1s", "faults.0.probability", "between 0 and 1");
}

#[test]
fn a_cut_needs_a_stage_on_another_host_and_targets_this_machines_bridge() {
    rejected("cut bridge at 1s for 300ms", "faults.0.kind", "a cut needs a link");
    let e = checked("cut bridge at 1s for 300ms").unwrap_err();
    assert!(e.message.contains("allowed without one: kill, stop, delay, drop, corrupt"), "{e}");
    let placed = |fault: &str| {
        let overrides = [
            Override::parse("hosts.controller=\"companion\"").unwrap(),
            Override::parse("hosts.companion.address=\"10.0.0.2\"").unwrap(),
            Override::parse("hosts.companion.command=[\"ssh\", \"companion\"]").unwrap(),
            Override::fault(fault).unwrap(),
        ];
        crate::scenarios::resolve("pendulum", &overrides).map(|_| ())
    };
    placed("cut bridge at 1s for 300ms").unwrap();
    let e = placed("cut controller at 1s for 300ms").unwrap_err();
    assert_eq!(e.key.as_deref(), Some("faults.0.process"), "{e}");
    assert!(e.message.contains("a cut fault cannot target \"controller\"; allowed: bridge"), "{e}");
    let e = placed("cut bridge at 1s for 0s").unwrap_err();
    assert_eq!(e.key.as_deref(), Some("faults.0.duration_s"), "{e}");
}
