//! The probe (`looplab run --probe`, `launcher::probe`): its place in a run's summary and
//! report. (Its agreement with `cyclictest` is not a test yet: on this 2-vCPU VM the two CPUs'
//! tails differ 2×, so two programs measured at once on different CPUs do not agree within 20 %.)

use crate::common::run;

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
