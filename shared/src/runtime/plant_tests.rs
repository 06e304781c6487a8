//! The plant's pure core, driven by explicit times: no clock, no process. The pendulum at
//! 1 kHz: one period is 1 ms, its input range ±10 A, the command timeout 20 ms. Here, a layer
//! above the stage SDK's runtime, for the pendulum.

use crate::config::launch::Override;
use crate::contract::msg::*;
use crate::contract::role::Role;
use crate::runtime::stage::plant::*;

/// Tick 0 is due here (any time will do: the core only compares times).
const START: u64 = 1_000_000_000;
const PERIOD: u64 = 1_000_000;

/// When tick `k` is due.
fn due(k: u64) -> u64 {
    START + k * PERIOD
}

/// A new plant (a real-time one has no schedule yet).
fn core_with(mode: &str, settings: &[&str]) -> PlantCore {
    let mut overrides = vec![Override::parse(&format!("mode=\"{mode}\"")).unwrap()];
    overrides.extend(settings.iter().map(|s| Override::parse(s).unwrap()));
    let (config, scenario) = crate::scenarios::resolve("pendulum", &overrides).unwrap();
    PlantCore::new(&config, scenario.as_ref(), 0)
}

/// A real-time plant whose tick 0 is due at [`START`].
fn realtime_with(settings: &[&str]) -> PlantCore {
    let mut core = core_with("realtime", settings);
    assert_eq!(core.start_schedule(START), START);
    core
}

fn realtime() -> PlantCore {
    realtime_with(&[])
}

fn command(k: u64, u: f64) -> Command {
    let mut c = Command::default();
    c.header.k = k;
    c.u[0] = u;
    c
}

/// Publishes the current tick's state at its due time.
fn publish(core: &mut PlantCore) -> PlantState {
    let k = core.k;
    core.state_message(TickTiming::default(), due(k))
}

/// The current the actuator applied over the last period, as the next state reports it.
fn applied(core: &mut PlantCore) -> f64 {
    publish(core).u_applied[0]
}

#[test]
fn a_command_in_before_the_next_tick_takes_effect_at_it() {
    let mut core = realtime();
    let state = publish(&mut core);
    assert_eq!((state.header.k, state.header.trace.get(Stamp::PlantPublish)), (0, due(0)));
    let mut answer = command(0, 1.5);
    answer.header = state.header;
    let record = core.accept(&answer, due(0) + PERIOD / 2);
    assert_eq!((record.deadline_miss, record.rejected, record.lost, record.sequence), (0, 0, 0, 1));
    assert_eq!(record.header.trace.get(Stamp::PlantReceive), due(0) + PERIOD / 2);
    assert_eq!(record.header.trace.end_to_end_ns(), PERIOD / 2);
    core.advance().unwrap();
    assert_eq!(core.k, 1);
    assert_eq!(applied(&mut core), 1.5);
    assert_eq!(core.counters, PlantCounters::default());
}

#[test]
fn a_command_after_its_deadline_is_a_miss_and_takes_effect_one_period_later() {
    let mut core = realtime();
    publish(&mut core);
    // Command 0 arrives after tick 1 was due; the plant had not integrated tick 1 yet.
    let record = core.accept(&command(0, 2.0), due(1) + 10);
    assert_eq!(record.deadline_miss, 1);
    core.advance().unwrap();
    assert_eq!(core.counters.deadline_misses, 1, "loop 0's state went out and its command was not in");
    assert_eq!(applied(&mut core), 0.0, "tick 1 was integrated with what was held before");
    core.advance().unwrap();
    assert_eq!(applied(&mut core), 2.0, "it took effect at tick 2");
    assert_eq!(core.counters.deadline_misses, 2, "loop 1 got no command either");
}

#[test]
fn a_deadline_shorter_than_a_period_ends_at_the_tick_plus_the_deadline() {
    // 300 µs: command k is in time up to 300 µs after tick k is due, and no later.
    let mut core = realtime_with(&["deadline_us=300"]);
    // (loop, arrival after its tick, flagged a miss, misses counted so far)
    for (k, late_by, miss, misses) in
        [(0, 300_000, 0, 0), (1, 300_001, 1, 1), (2, 100_000, 0, 1), (3, PERIOD - 1, 1, 2)]
    {
        publish(&mut core);
        let record = core.accept(&command(k, 1.0), due(k) + late_by);
        assert_eq!(record.deadline_miss, miss, "loop {k}, {late_by} ns after its tick");
        core.advance().unwrap();
        assert_eq!(core.counters.deadline_misses, misses, "after loop {k}");
    }
    // A late command still takes effect at the next tick: the deadline only judges it.
    assert_eq!(applied(&mut core), 1.0);
    // The default is one period: 999 999 ns after the tick is in time, as before.
    let mut default = realtime();
    publish(&mut default);
    assert_eq!(default.accept(&command(0, 1.0), due(0) + PERIOD).deadline_miss, 0);
    assert_eq!(default.accept(&command(0, 1.0), due(0) + PERIOD + 1).deadline_miss, 1);
}

#[test]
fn the_newest_command_in_by_the_tick_wins() {
    let mut core = realtime();
    publish(&mut core);
    core.accept(&command(0, 1.0), due(0) + 100);
    core.accept(&command(0, 3.0), due(0) + 200);
    core.advance().unwrap();
    assert_eq!(applied(&mut core), 3.0);
}

#[test]
fn a_loop_whose_state_never_went_out_misses_no_deadline() {
    let mut core = realtime();
    core.advance().unwrap();
    assert_eq!(core.counters.deadline_misses, 0);
    publish(&mut core);
    core.advance().unwrap();
    assert_eq!(core.counters.deadline_misses, 1);
}

#[test]
fn a_non_finite_or_out_of_range_command_is_rejected_and_the_last_valid_one_held() {
    let mut core = realtime();
    publish(&mut core);
    core.accept(&command(0, 1.0), due(0) + 100);
    core.advance().unwrap();
    for (k, u) in [(1, f64::NAN), (2, f64::INFINITY), (3, 10.5), (4, -10.01)] {
        publish(&mut core);
        let record = core.accept(&command(k, u), due(k) + 100);
        assert_eq!((record.rejected, record.deadline_miss), (1, 0), "{u}");
        core.advance().unwrap();
        assert_eq!(core.counters.deadline_misses, 0, "a rejected command was still in time");
    }
    assert_eq!(core.counters.rejected_commands, 4);
    assert_eq!(applied(&mut core), 1.0);
    // The range is closed: its ends are valid.
    let record = core.accept(&command(5, -10.0), due(5) + 100);
    assert_eq!(record.rejected, 0);
}

#[test]
fn a_command_marked_lost_is_counted_and_the_last_held() {
    let mut core = core_with("lockstep", &[]);
    core.state_message(TickTiming::default(), 7);
    core.accept(&command(0, 1.0), 8);
    core.advance().unwrap();
    core.state_message(TickTiming::default(), 9);
    let mut lost = command(1, 4.0);
    lost.header.lost = 1;
    let record = core.accept(&lost, 10);
    assert_eq!((record.lost, record.rejected, record.deadline_miss), (1, 0, 0));
    core.advance().unwrap();
    assert_eq!(core.counters.lost_commands, 1);
    assert_eq!(core.state_message(TickTiming::default(), 11).u_applied[0], 1.0);
}

#[test]
fn lockstep_has_no_deadlines_and_nothing_goes_stale() {
    let mut core = core_with("lockstep", &["supervision.on_stale=\"zero\""]);
    core.state_message(TickTiming::default(), 1);
    // However late it comes, command k is what tick k → k+1 integrates with.
    let record = core.accept(&command(0, 2.0), u64::MAX / 2);
    assert_eq!(record.deadline_miss, 0);
    for _ in 0..100 {
        core.advance().unwrap();
    }
    assert_eq!(core.counters, PlantCounters::default());
    assert_eq!(core.state_message(TickTiming::default(), 2).u_applied[0], 2.0);
}

/// Command 0 arrives half a period after tick 0; after 25 ticks without another one, the
/// ticks whose due time is more than the 20 ms timeout past its arrival are stale.
fn stale_after_one_command(on_stale: &str) -> PlantCore {
    let mut core = realtime_with(&[&format!("supervision.on_stale=\"{on_stale}\"")]);
    publish(&mut core);
    core.accept(&command(0, 1.0), due(0) + PERIOD / 2);
    for _ in 0..25 {
        core.advance().unwrap();
    }
    core
}

#[test]
fn a_command_older_than_the_timeout_is_stale_and_on_stale_applies() {
    // Tick k → k+1 is due (k + 1) ms after tick 0, so it is stale once k + 0.5 > 20: ticks 20 to 24.
    let mut hold = stale_after_one_command("hold");
    assert_eq!(hold.counters.stale_ticks, 5);
    assert_eq!(applied(&mut hold), 1.0);
    let mut zero = stale_after_one_command("zero");
    assert_eq!(zero.counters.stale_ticks, 5);
    assert_eq!(applied(&mut zero), 0.0);
    // A new command ends it.
    zero.accept(&command(25, 3.0), due(25) + 100);
    zero.advance().unwrap();
    assert_eq!((zero.counters.stale_ticks, applied(&mut zero)), (5, 3.0));
}

#[test]
fn the_boundary_of_the_timeout_is_not_stale() {
    // Arrived when tick 1 was due, so exactly as old as the timeout when tick 21 is due (the
    // 21st tick integrated): not older.
    let mut core = realtime();
    publish(&mut core);
    core.accept(&command(0, 1.0), due(1));
    for _ in 0..21 {
        core.advance().unwrap();
    }
    assert_eq!(core.counters.stale_ticks, 0);
    core.advance().unwrap();
    assert_eq!(core.counters.stale_ticks, 1);
}

#[test]
fn before_any_command_every_tick_is_stale() {
    let mut core = realtime_with(&["supervision.on_stale=\"zero\""]);
    for _ in 0..3 {
        core.advance().unwrap();
    }
    assert_eq!(core.counters.stale_ticks, 3);
}

#[test]
fn ticks_the_timer_passed_over_are_skipped_and_the_run_ends_at_its_last_loop() {
    let mut core = realtime();
    publish(&mut core);
    assert_eq!(core.advance_expired(0, 10_000).unwrap(), 0);
    assert_eq!(core.advance_expired(1, 10_000).unwrap(), 1);
    assert_eq!(core.counters.skipped_ticks, 0);
    assert_eq!(core.advance_expired(4, 10_000).unwrap(), 4);
    assert_eq!((core.k, core.counters.skipped_ticks), (5, 3), "only the newest tick's state goes out");
    // Only loop 0's state went out, so only loop 0 missed its deadline.
    assert_eq!(core.counters.deadline_misses, 1);
    // The run's last loop (7) goes out, late, rather than being passed over.
    assert_eq!(core.advance_expired(10, 8).unwrap(), 2, "up to the run's last loop");
    assert_eq!((core.k, core.counters.skipped_ticks), (7, 4));
    assert_eq!(core.advance_expired(10, 8).unwrap(), 1, "not past the run's last loop");
    assert_eq!((core.k, core.counters.skipped_ticks), (8, 4));
}

#[test]
fn a_restarted_plant_catches_up_and_counts_the_ticks_without_a_state() {
    for (published_last, skipped) in [(true, 3), (false, 4)] {
        let mut core = realtime();
        for _ in 0..5 {
            publish(&mut core);
            core.advance().unwrap();
        }
        if published_last {
            publish(&mut core);
        }
        let misses = core.counters.deadline_misses;
        core.catch_up(9).unwrap();
        assert_eq!(core.k, 9);
        assert_eq!(core.counters.skipped_ticks, skipped, "tick 5 published: {published_last}");
        assert_eq!(core.counters.deadline_misses, misses + u64::from(published_last));
        core.catch_up(7).unwrap();
        assert_eq!((core.k, core.counters.skipped_ticks), (9, skipped), "never backwards");
    }
}

#[test]
fn a_restored_core_goes_on_exactly_where_the_last_one_stopped() {
    let (mut first, mut second) = (realtime(), core_with("realtime", &[]));
    for k in 0..40 {
        publish(&mut first);
        first.accept(&command(k, (k as f64 * 0.3).sin()), due(k) + 100);
        first.advance().unwrap();
    }
    publish(&mut first);
    // The schedule comes from the snapshot: restarting later does not move it.
    second.restore(&first.snapshot());
    assert_eq!(second.start_schedule(START + 123 * PERIOD), START);
    assert_eq!((second.k, second.counters, second.published_k), (first.k, first.counters, first.published_k));
    for k in 40..60 {
        for core in [&mut first, &mut second] {
            core.accept(&command(k, -0.5), due(k) + 100);
            core.advance().unwrap();
        }
        let (a, b) = (publish(&mut first), publish(&mut second));
        assert_eq!(a.x.map(f64::to_bits), b.x.map(f64::to_bits), "tick {}", k + 1);
        assert_eq!(a.u_applied, b.u_applied);
    }
    assert_eq!(second.report.published, first.report.published);
}

#[test]
fn the_report_counts_published_and_skipped_ticks_as_loops() {
    let mut core = realtime();
    let state = core.state_message(TickTiming::default(), 555);
    assert_eq!(state.header.incarnations, [0; 4]);
    core.advance_expired(3, 100).unwrap();
    core.state_message(TickTiming::default(), 777);
    core.finish(100);
    let report = &core.report;
    assert_eq!((report.published, report.loops, report.first_publish_ns, report.last_publish_ns), (2, 4, 555, 777));
    assert!(report.stopped_early);
    assert_eq!(report.counters, core.counters);
}

#[test]
fn the_plant_stamps_its_own_incarnation_slot() {
    let (config, scenario) = crate::scenarios::resolve("pendulum", &[]).unwrap();
    let mut core = PlantCore::new(&config, scenario.as_ref(), 3);
    let state = core.state_message(TickTiming::default(), 1);
    let mut expected = [0; 4];
    expected[Role::Plant.slot().unwrap()] = 3;
    assert_eq!(state.header.incarnations, expected);
}
