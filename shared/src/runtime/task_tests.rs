//! The stage runner, driven loop by loop with no clock and no process: incarnations, and each
//! in-loop fault by loop index in both modes. The pendulum's launch file at 1 kHz, so 10 ms is
//! loop 10. Here, a layer above the stage SDK's runtime, for the pendulum.

use std::time::Duration;

use crate::config::faults::CorruptValue;
use crate::config::launch::{LaunchConfig, Override};
use crate::contract::msg::{Command, Estimate, Measurements};
use crate::contract::role::Role;
use crate::runtime::stage::task::*;

/// Echoes its input's first value into the command, counting its calls.
#[derive(Default)]
struct Echo {
    calls: u64,
}

impl Task for Echo {
    type In = Estimate;
    type Out = Command;
    fn process(&mut self, input: &Estimate, output: &mut Command) -> anyhow::Result<()> {
        self.calls += 1;
        output.u[0] = input.x[0];
        Ok(())
    }
    fn corrupt(&self, output: &mut Command, value: CorruptValue) {
        output.u[0] = match value {
            CorruptValue::Nan => f64::NAN,
            CorruptValue::Inf => f64::INFINITY,
            CorruptValue::OutOfRange => 1e9,
        };
    }
}

fn config(mode: &str, faults: &[&str]) -> LaunchConfig {
    let mut overrides = vec![Override::parse(&format!("mode=\"{mode}\"")).unwrap()];
    overrides.extend(faults.iter().map(|f| Override::fault(f).unwrap()));
    crate::scenarios::resolve("pendulum", &overrides).unwrap().0
}

/// The controller's runner, incarnation `incarnation`, with these faults.
fn runner(mode: &str, faults: &[&str], incarnation: u32) -> StageRunner<Echo> {
    StageRunner::new(Echo::default(), Role::Controller, &config(mode, faults), incarnation)
}

/// The estimate of loop k: its first value is k.
fn input(k: u64) -> Estimate {
    let mut e = Estimate::default();
    e.header.k = k;
    e.header.t = k as f64 * 1e-3;
    e.x[0] = k as f64;
    e
}

/// The first command value of each loop in `ks` (None: nothing was sent).
fn outputs(runner: &mut StageRunner<Echo>, ks: impl IntoIterator<Item = u64>) -> Vec<Option<f64>> {
    ks.into_iter().map(|k| runner.handle(&input(k)).unwrap().output.map(|c| c.u[0])).collect()
}

const MODES: [&str; 2] = ["realtime", "lockstep"];

#[test]
fn the_output_carries_the_inputs_header_and_the_stages_incarnation() {
    for mode in MODES {
        let mut r = runner(mode, &[], 2);
        let mut estimate = input(5);
        estimate.header.incarnations = [1, 0, 3, 0];
        estimate.header.trace.stamp_published(Role::Plant, 42);
        let out = r.handle(&estimate).unwrap().output.unwrap();
        let mut expected = estimate.header;
        expected.set_incarnation(Role::Controller, 2);
        assert_eq!(out.header, expected, "{mode}");
        assert_eq!(out.header.incarnations, [1, 0, 3, 2]);
    }
}

#[test]
fn a_restart_upstream_is_counted_when_its_incarnation_changes() {
    let mut r = runner("lockstep", &[], 0);
    let with = |k, incarnations: [u32; 4]| {
        let mut e = input(k);
        e.header.incarnations = incarnations;
        e
    };
    r.handle(&with(0, [0, 0, 0, 0])).unwrap();
    r.handle(&with(1, [0, 0, 0, 0])).unwrap();
    assert_eq!(r.report.upstream_restarts, 0);
    r.handle(&with(2, [0, 1, 0, 0])).unwrap();
    r.handle(&with(3, [0, 1, 0, 0])).unwrap();
    assert_eq!(r.report.upstream_restarts, 1, "the sensors restarted once");
    // Its own slot and the ones after are not upstream.
    r.handle(&with(4, [0, 1, 0, 7])).unwrap();
    assert_eq!(r.report.upstream_restarts, 1);
    r.handle(&with(5, [1, 1, 1, 0])).unwrap();
    assert_eq!(r.report.upstream_restarts, 2, "the plant and the estimator, seen in one loop");
}

#[test]
fn loops_that_never_came_are_counted_as_skipped() {
    let mut r = runner("realtime", &[], 0);
    outputs(&mut r, [0, 1, 4, 5, 9]);
    assert_eq!((r.report.processed, r.report.skipped), (5, 5));
}

#[test]
fn a_corrupt_fault_corrupts_the_outputs_of_its_window_in_both_modes() {
    for mode in MODES {
        let mut r = runner(mode, &["corrupt controller inf at 10ms for 3ms"], 0);
        let out = outputs(&mut r, 8..15);
        let inf = Some(f64::INFINITY);
        assert_eq!(out, [Some(8.0), Some(9.0), inf, inf, inf, Some(13.0), Some(14.0)], "{mode}");
        assert_eq!(r.task.calls, 7, "a corrupt output was computed first");
    }
}

#[test]
fn a_drop_sends_nothing_in_real_time_and_a_lost_loop_in_lockstep() {
    let drop = ["drop controller 100% at 10ms for 2ms"];
    let mut r = runner("realtime", &drop, 0);
    assert_eq!(outputs(&mut r, 9..13), [Some(9.0), None, None, Some(12.0)]);
    assert_eq!((r.report.dropped_by_fault, r.report.processed), (2, 2));

    let mut r = runner("lockstep", &drop, 0);
    let lost: Vec<_> = (9..13).map(|k| r.handle(&input(k)).unwrap().output.unwrap().header.lost).collect();
    assert_eq!(lost, [0, 1, 1, 0], "the loop goes on, marked lost");
    assert_eq!((r.report.dropped_by_fault, r.report.processed), (2, 4));
}

#[test]
fn a_drop_with_a_probability_depends_only_on_the_seed() {
    let drop = ["drop controller 50% at 10ms for 200ms"];
    let pattern = |r: &mut StageRunner<Echo>, ks: std::ops::Range<u64>| -> Vec<bool> {
        ks.map(|k| r.handle(&input(k)).unwrap().output.is_none()).collect()
    };
    let first = pattern(&mut runner("realtime", &drop, 0), 10..210);
    // A restarted stage (another incarnation) that also saw the loops before the window draws
    // the same numbers in the window.
    let mut second = runner("realtime", &drop, 1);
    pattern(&mut second, 0..10);
    assert_eq!(pattern(&mut second, 10..210), first);
    let dropped = first.iter().filter(|d| **d).count();
    assert!((60..140).contains(&dropped), "about half of 200: {dropped}");
}

#[test]
fn a_loop_lost_upstream_is_passed_on_without_running_the_task() {
    let mut r = runner("lockstep", &[], 0);
    r.handle(&input(0)).unwrap();
    let mut lost = input(1);
    lost.header.lost = 1;
    let out = r.handle(&lost).unwrap().output.unwrap();
    assert_eq!((out.u[0], out.header.lost, out.header.k), (0.0, 1, 1), "the last output, marked lost");
    assert_eq!((r.task.calls, r.report.processed), (1, 2));
}

#[test]
fn a_lockstep_delay_sends_what_was_computed_that_many_loops_ago() {
    let mut r = runner("lockstep", &["delay controller by 3 ticks at 10ms for 5ms"], 0);
    let out = outputs(&mut r, 0..17);
    let expected = [8.0, 9.0, 7.0, 8.0, 9.0, 10.0, 11.0, 15.0, 16.0].map(Some);
    assert_eq!(out[8..], expected);
    // From the first loop of a run: the oldest output computed stands in for the ones before.
    let mut r = runner("lockstep", &["delay controller by 3 ticks at 0s"], 0);
    assert_eq!(outputs(&mut r, 0..6), [0.0, 0.0, 0.0, 0.0, 1.0, 2.0].map(Some));
    // A delay in seconds is whole ticks in lockstep.
    let mut r = runner("lockstep", &["delay controller by 2ms at 10ms for 1ms"], 0);
    assert_eq!(outputs(&mut r, 0..12)[9..], [9.0, 8.0, 11.0].map(Some));
    assert!(r.handle(&input(12)).unwrap().hold.is_none());
}

#[test]
fn a_real_time_delay_holds_the_current_output() {
    let mut r = runner("realtime", &["delay controller by 3 ticks at 10ms for 2ms"], 0);
    // Holds in whole microseconds (seconds from floats need not be whole nanoseconds).
    let micros = |hold: Option<Duration>| hold.map(|d| (d.as_secs_f64() * 1e6).round() as u64);
    let handled: Vec<_> =
        (9..13).map(|k| r.handle(&input(k)).unwrap()).map(|h| (micros(h.hold), h.output.map(|c| c.u[0]))).collect();
    let held = Some(3000);
    assert_eq!(handled, [(None, Some(9.0)), (held, Some(10.0)), (held, Some(11.0)), (None, Some(12.0))]);
    let mut r = runner("realtime", &["delay controller by 1.5ms at 0s"], 0);
    assert_eq!(micros(r.handle(&input(0)).unwrap().hold), Some(1500));
}

#[test]
fn faults_of_other_processes_and_kills_leave_the_stage_alone() {
    let others = [
        "drop sensors 100% at 0s",
        "corrupt controller at 1s",
        "kill controller at 5ms",
        "stop controller at 5ms for 1ms",
    ];
    for mode in MODES {
        let mut r = runner(mode, &others, 0);
        let handled: Vec<_> = (0..20).map(|k| r.handle(&input(k)).unwrap()).collect();
        assert!(handled.iter().all(|h| h.hold.is_none()), "{mode}");
        let out: Vec<_> = handled.iter().map(|h| h.output.map(|c| c.u[0])).collect();
        assert_eq!(out, (0..20).map(|k| Some(k as f64)).collect::<Vec<_>>(), "{mode}");
    }
}

/// Drives a scenario's loop in lockstep with its tasks, no runner; at loop `at` a fresh
/// controller takes over the frozen state of the running one. Returns whether the thawed one
/// commanded bit for bit what the running one did from then on, and whether one that was not
/// thawed did too.
fn restart_controller(scenario_name: &str, at: u64, after: u64) -> (bool, bool) {
    let overrides = [Override::parse("mode=\"lockstep\"").unwrap()];
    let (config, scenario) = crate::scenarios::resolve(scenario_name, &overrides).unwrap();
    let s = scenario.as_ref();
    let mut plant = crate::runtime::stage::plant::PlantCore::new(&config, s, 0);
    let (mut sensors, mut estimator) = (SensorsTask::new(&config, s), EstimatorTask::new(&config, s));
    let mut controller = ControllerTask::new(&config, s);
    let (mut thawed, mut fresh) = (ControllerTask::new(&config, s), ControllerTask::new(&config, s));
    let (mut thawed_same, mut fresh_same) = (true, true);
    let bits = |c: &Command| c.u.map(f64::to_bits);
    for k in 0..at + after {
        let state = plant.state_message(Default::default(), 0);
        let mut measurements = Measurements { header: state.header, ..Default::default() };
        sensors.process(&state, &mut measurements).unwrap();
        let mut estimate = Estimate { header: measurements.header, ..Default::default() };
        estimator.process(&measurements, &mut estimate).unwrap();
        if k == at
            && let Some(frozen) = controller.freeze().unwrap()
        {
            thawed.thaw(&frozen).unwrap();
        }
        let mut command = Command { header: estimate.header, ..Default::default() };
        controller.process(&estimate, &mut command).unwrap();
        if k >= at {
            let (mut a, mut b) = (command, command);
            thawed.process(&estimate, &mut a).unwrap();
            fresh.process(&estimate, &mut b).unwrap();
            thawed_same &= bits(&a) == bits(&command);
            fresh_same &= bits(&b) == bits(&command);
        }
        plant.accept(&command, 0);
        plant.advance().unwrap();
    }
    (thawed_same, fresh_same)
}

#[test]
fn a_thawed_controller_resumes_its_integrators_bit_for_bit() {
    for name in ["quadcopter", "tethered", "tiltrotor"] {
        let (thawed, fresh) = restart_controller(name, 300, 100);
        assert!(thawed, "{name}: the thawed controller commanded otherwise");
        assert!(!fresh, "{name}: a controller started afresh commanded the same: the test proves nothing");
    }
}

#[test]
fn a_static_controller_resumes_too() {
    // The pendulum's law keeps nothing; the FIP's keeps only its reference's phase.
    for name in ["pendulum", "fip"] {
        assert!(restart_controller(name, 300, 100).0, "{name}");
    }
    let (config, scenario) = crate::scenarios::resolve("pendulum", &[]).unwrap();
    assert!(ControllerTask::new(&config, scenario.as_ref()).freeze().unwrap().is_none(), "nothing to keep");
}
