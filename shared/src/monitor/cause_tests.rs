use super::*;
use crate::contract::msg::{Command, Estimate, LoopRecord, LoopTrace, Measurements, PlantState, TickTiming};

/// A real-time loop: tick due at 1 000 ns, woken at `wake`, the stamps `stamps`, each role's
/// stamp `(queued, compute_queued)`: plant (record), sensors, estimator, controller; the state's
/// own wake-up wait `tick_queued`.
fn loop_of(wake: u64, stamps: [u64; 8], sched: [(u32, u32); 4], tick_queued: u32) -> LoopParts {
    let stamp = |(queued_ns, compute_queued_ns): (u32, u32)| SchedStamp { queued_ns, compute_queued_ns };
    let trace = LoopTrace::from_stamps(stamps);
    let mut state = PlantState::default();
    state.header.trace.plant_publish = stamps[0];
    state.header.sched = stamp((tick_queued, 0));
    state.timing = TickTiming { scheduled_ns: 1_000, wake_ns: wake, period_ns: 1_000_000 };
    let mut record = LoopRecord::default();
    record.header.trace = trace;
    record.header.sched = stamp(sched[0]);
    let mut measurements = Measurements::default();
    measurements.header.sched = stamp(sched[1]);
    let mut estimate = Estimate::default();
    estimate.header.sched = stamp(sched[2]);
    let mut command = Command::default();
    command.header.sched = stamp(sched[3]);
    LoopParts {
        state: Some(state),
        measurements: Some(measurements),
        estimate: Some(estimate),
        command: Some(command),
        record: Some(record),
    }
}

fn no_fault(_: Role) -> Option<FaultKind> {
    None
}

/// No output of a stage before or after the loop.
fn none(_: Role) -> Option<Header> {
    None
}

#[test]
fn the_parts_add_up_to_the_response_time_and_the_hops_to_end_to_end() {
    let stamps = [2_000, 2_500, 2_700, 3_100, 3_200, 903_200, 903_300, 903_900];
    let parts = loop_of(1_500, stamps, [(100, 0), (200, 0), (300, 0), (800_000, 40)], 300);
    let decomposed = decompose(&parts, none).unwrap();
    let total: u64 = decomposed.iter().map(|p| p.ns).sum();
    assert_eq!(total, 903_900 - 1_000, "tick due to command in");
    // The e2e parts: everything after the plant's own two.
    let e2e: u64 = decomposed.iter().skip(3).map(|p| p.ns).sum();
    assert_eq!(e2e, 903_900 - 2_000);
    assert_eq!(decomposed[0], Part { cause: Cause::Queued(Role::Plant), ns: 300 });
    assert_eq!(decomposed[1], Part { cause: Cause::Timer, ns: 200 });
    assert_eq!(decomposed[2], Part { cause: Cause::Compute(Role::Plant), ns: 500 });
    let explained = explain(&parts, None, no_fault, none, none);
    assert_eq!(explained.cause, Cause::Queued(Role::Controller));
    assert_eq!(
        (explained.part_ns, explained.response_ns),
        (Some(800_040), Some(902_900)),
        "the hop's wait and the computation's"
    );
    assert_eq!(explained.cause.to_string(), "queued: controller");
    // The rest of that hop is its own wake-up.
    let hop = by_cause(&decomposed).into_iter().find(|p| p.cause == Cause::Transport(4)).unwrap();
    assert_eq!(hop.ns, 100_000);
    assert_eq!(Cause::Transport(4).to_string(), "transport: estimator->controller");
}

#[test]
fn a_queued_wait_is_never_longer_than_its_hop() {
    // The controller's wait since its last read was long, but the hop took 100 ns.
    let stamps = [2_000, 2_100, 2_200, 2_300, 2_400, 2_500, 902_500, 902_600];
    let parts = loop_of(2_000, stamps, [(0, 0), (0, 0), (0, 0), (5_000_000, 0)], 0);
    let decomposed = decompose(&parts, none).unwrap();
    assert_eq!(decomposed.iter().map(|p| p.ns).sum::<u64>(), 902_600 - 1_000);
    assert_eq!(explain(&parts, None, no_fault, none, none).cause, Cause::Compute(Role::Controller));
    assert_eq!(explain(&parts, None, no_fault, none, none).part_ns, Some(900_000));
}

#[test]
fn a_hop_whose_reader_still_computed_an_earlier_loop_is_that_computation() {
    // The estimate went out at 2 400 ns; the controller published loop k−1's command at
    // 602 400 ns (300 µs of it on the run queue) and took this estimate at 702 400 ns.
    let stamps = [2_000, 2_100, 2_200, 2_300, 2_400, 702_400, 702_500, 702_600];
    let parts = loop_of(2_000, stamps, [(0, 0), (0, 0), (0, 0), (50_000, 0)], 0);
    let mut earlier = Header::default();
    earlier.trace.controller_publish = 602_400;
    earlier.sched.compute_queued_ns = 300_000;
    let controller = |role: Role| (role == Role::Controller).then_some(earlier);
    let decomposed = decompose(&parts, controller).unwrap();
    assert_eq!(decomposed.iter().map(|p| p.ns).sum::<u64>(), 702_600 - 1_000);
    let hop: Vec<Part> = decomposed[decomposed.len() - 8..decomposed.len() - 4].to_vec();
    assert_eq!(
        hop,
        [
            Part { cause: Cause::Queued(Role::Controller), ns: 300_000 },
            Part { cause: Cause::Compute(Role::Controller), ns: 300_000 },
            Part { cause: Cause::Queued(Role::Controller), ns: 50_000 },
            Part { cause: Cause::Transport(4), ns: 50_000 },
        ]
    );
    let explained = explain(&parts, None, no_fault, controller, none);
    assert_eq!((explained.cause, explained.part_ns), (Cause::Queued(Role::Controller), Some(350_000)));
    // Without what came before, the same hop is its wake-up and the wait.
    let explained = explain(&parts, None, no_fault, none, none);
    assert_eq!((explained.cause, explained.part_ns), (Cause::Transport(4), Some(650_000)));
}

#[test]
fn a_plant_woken_early_by_a_command_was_in_time_for_its_tick() {
    // Woke at 900 ns for a command; the tick fell due at 1 000 ns meanwhile.
    let stamps = [3_000, 3_100, 3_200, 3_300, 3_400, 3_500, 3_600, 3_700];
    let decomposed = decompose(&loop_of(900, stamps, [(0, 0); 4], 50), none).unwrap();
    assert_eq!(decomposed.iter().map(|p| p.ns).sum::<u64>(), 3_700 - 1_000);
    assert_eq!(decomposed[..3].iter().map(|p| p.ns).collect::<Vec<_>>(), [0, 0, 2_000]);
}

#[test]
fn a_late_timer_is_the_timer() {
    let stamps = [701_000, 701_100, 701_200, 701_300, 701_400, 701_500, 701_600, 701_700];
    let parts = loop_of(700_000, stamps, [(0, 0); 4], 20_000);
    let explained = explain(&parts, None, no_fault, none, none);
    assert_eq!((explained.cause, explained.part_ns), (Cause::Timer, Some(699_000 - 20_000)));
    assert_eq!(explained.response_ns, Some(700_700));
}

#[test]
fn a_fault_takes_the_blame_only_where_its_process_is_the_primary_part() {
    let stamps = [2_000, 2_100, 2_200, 2_300, 2_400, 902_400, 902_500, 902_600];
    let parts = loop_of(2_000, stamps, [(0, 0); 4], 0);
    let stopped = |role: Role| (role == Role::Controller).then_some(FaultKind::Stop);
    let explained = explain(&parts, None, stopped, none, none);
    assert_eq!(explained.cause, Cause::Fault(FaultKind::Stop, Role::Controller));
    assert_eq!(explained.cause.to_string(), "fault: stop controller");
    let sensors_delayed = |role: Role| (role == Role::Sensors).then_some(FaultKind::Delay);
    assert_eq!(explain(&parts, None, sensors_delayed, none, none).cause, Cause::Transport(4));
    // A stopped stage holds every loop of its outage, whatever else was slow in it.
    let outage = Some((FaultKind::Stop, Role::Sensors));
    assert_eq!(explain(&parts, outage, no_fault, none, none).cause, Cause::Fault(FaultKind::Stop, Role::Sensors));
}

#[test]
fn a_loop_without_a_command_names_the_stage_that_skipped_it() {
    let mut parts = loop_of(2_000, [2_000; 8], [(0, 0); 4], 0);
    parts.record = None;
    parts.command = None;
    let explained = explain(&parts, None, no_fault, none, none);
    assert_eq!(explained, Explanation { cause: Cause::Skipped(Role::Controller), part_ns: None, response_ns: None });
    parts.estimate = None;
    assert_eq!(explain(&parts, None, no_fault, none, none).cause, Cause::Skipped(Role::Estimator));
    let killed = |role: Role| (role == Role::Estimator).then_some(FaultKind::Kill);
    assert_eq!(explain(&parts, None, killed, none, none).cause.to_string(), "fault: kill estimator");
    // Had the estimator sat on the run queue for most of the time until it took its next input,
    // it was queued.
    let mut next = Header::default();
    next.trace.estimator_receive = 2_000 + 600_000;
    next.sched.queued_ns = 500_000;
    parts.measurements.as_mut().unwrap().header.trace.sensors_publish = 2_000;
    let after = |next: Header| move |_| Some(next);
    let explained = explain(&parts, None, no_fault, none, after(next));
    assert_eq!((explained.cause, explained.part_ns), (Cause::Queued(Role::Estimator), Some(500_000)));
    next.sched.queued_ns = 200_000;
    let explained = explain(&parts, None, no_fault, none, after(next));
    assert_eq!((explained.cause, explained.part_ns), (Cause::Skipped(Role::Estimator), Some(600_000)));
    // Still computing an earlier loop for most of that time: its computation is the cause.
    let mut before = Header::default();
    before.trace.estimator_receive = 1_000;
    before.trace.estimator_publish = 2_000 + 400_000;
    let explained = explain(&parts, None, no_fault, |_| Some(before), |_| Some(next));
    assert_eq!((explained.cause, explained.part_ns), (Cause::Compute(Role::Estimator), Some(400_000)));
    before.sched.compute_queued_ns = 300_000;
    let explained = explain(&parts, None, no_fault, |_| Some(before), |_| Some(next));
    assert_eq!(explained.cause, Cause::Queued(Role::Estimator), "it sat on the run queue for most of it");
    // A tick the plant never woke for.
    assert_eq!(explain(&LoopParts::default(), None, no_fault, none, none).cause, Cause::Timer);
}

#[test]
fn a_command_that_never_reached_the_plant_is_explained_up_to_its_sending() {
    // Command k went out 8 ms late; a newer one replaced it at the plant: no record.
    let stamps = [2_000, 2_100, 2_200, 2_300, 2_400, 2_500, 8_002_500, 0];
    let mut parts = loop_of(2_000, stamps, [(0, 0); 4], 0);
    parts.command.as_mut().unwrap().header.trace = LoopTrace::from_stamps(stamps);
    parts.record = None;
    let decomposed = decompose(&parts, none).unwrap();
    assert_eq!(decomposed.iter().map(|p| p.ns).sum::<u64>(), 8_002_500 - 1_000);
    let explained = explain(&parts, None, no_fault, none, none);
    assert_eq!(
        explained,
        Explanation { cause: Cause::Compute(Role::Controller), part_ns: Some(8_000_000), response_ns: None }
    );
}

#[test]
fn stamps_from_another_clock_are_not_decomposed() {
    let parts = loop_of(2_000, [2_000, 1_900, 2_200, 2_300, 2_400, 2_500, 2_600, 2_700], [(0, 0); 4], 0);
    assert_eq!(decompose(&parts, none), None);
    assert_eq!(explain(&parts, None, no_fault, none, none).cause, Cause::Unknown);
}

#[test]
fn every_decomposition_adds_up_exactly() {
    // A fixed pseudo-random walk over stamps and waits: the sum never drifts from the response.
    let mut seed: u64 = 0x9e37_79b9_7f4a_7c15;
    let mut next = |bound: u64| {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed % bound
    };
    for _ in 0..10_000 {
        let wake = 1_000 + next(2_000_000);
        let mut stamps = [0u64; 8];
        let mut at = wake + next(50_000);
        for s in &mut stamps {
            at += next(300_000);
            *s = at;
        }
        let mut sched = [(0u32, 0u32); 4];
        for s in &mut sched {
            *s = (next(400_000) as u32, next(400_000) as u32);
        }
        let parts = loop_of(wake, stamps, sched, next(3_000_000) as u32);
        let decomposed = decompose(&parts, none).unwrap();
        assert_eq!(decomposed.iter().map(|p| p.ns).sum::<u64>(), stamps[7] - 1_000);
        let explained = explain(&parts, None, no_fault, none, none);
        assert!(explained.part_ns <= explained.response_ns);
        assert!(explained.part_ns.is_some());
    }
}
