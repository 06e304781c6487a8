//! The summary's builder and its schema.

use std::path::Path;

use super::*;
use crate::config::launch::LaunchConfig;
use crate::config::launch::Override;
use crate::contract::protocol::{PlantReport, StageReport};
use crate::contract::report::MonitorReport;
use crate::launcher::child::Start;
use crate::launcher::outcome::Outcome;
use crate::model::scenario::Scenario;
use crate::scenarios::resolve;

/// A complete lockstep run's summary, for the tests of what reads one.
pub(crate) fn summary() -> Summary {
    Summary {
        schema_version: SCHEMA_VERSION,
        looplab_version: "0.1.0".into(),
        git_commit: "unknown".into(),
        command_line: vec!["looplab".into(), "run".into()],
        machine: Machine::default(),
        scenario: "pendulum".into(),
        title: "pendulum".into(),
        mode: Mode::Lockstep,
        rate_hz: 200.0,
        duration_s: 5.0,
        seed: 1,
        run_id: "r".into(),
        run_dir: "/tmp/r".into(),
        started_at: "2024-01-01T00:00:00Z".into(),
        loops: 1000,
        loops_planned: 1000,
        completed: true,
        stopped_because: None,
        lost_stages: vec![],
        fail_safe: None,
        deadline_misses: 0,
        late_or_no_command: 0,
        misses_by_cause: BTreeMap::new(),
        slow_loops: None,
        sched_trace: None,
        steal_share: None,
        deadline_us: None,
        deadline_miss_share: None,
        rejected_commands: 0,
        skipped_ticks: 0,
        stale_ticks: 0,
        lost_commands: 0,
        loops_without_command: 0,
        wall_time_s: 1.0,
        loops_per_s: 1000.0,
        restarts: BTreeMap::new(),
        processes: vec![],
        adaptive_waits: BTreeMap::new(),
        latency_ns: Latency::default(),
        latency_budget: LatencyBudget::default(),
        jitter_ns: Jitter::default(),
        data_age_ns: BTreeMap::new(),
        monitor: MonitorCounts::default(),
        metrics: BTreeMap::new(),
        notes: vec![],
        diverged_at_loop: None,
        error_measure: ErrorMeasureInfo { name: "angle".into(), recovery_band: 0.05, limit: 1.0, ..Default::default() },
        limits: LimitsVerdict::default(),
        faults: vec![],
        timeline: vec![],
        restart_steps: vec![],
        shared_memory: SharedMemoryCheck { clean: true, ..Default::default() },
        network: None,
        probe: None,
    }
}

/// What a run without child processes has: the reports, nothing the supervisor saw.
#[test]
fn a_summary_builds_from_the_reports_alone() {
    let overrides = [Override::parse("mode=lockstep").unwrap(), Override::parse("duration_s=0.5").unwrap()];
    let (config, scenario) = resolve("pendulum", &overrides).unwrap();
    let plant = PlantReport {
        loops: 500,
        published: 500,
        commands: 500,
        first_publish_ns: 1_000_000_000,
        last_publish_ns: 1_499_000_000,
        waited: 2,
        ..Default::default()
    };
    let stage = StageReport {
        processed: 500,
        waited: 1,
        wait: WaitCounts { caught: 3, blocked: 4, busy: 0 },
        ..Default::default()
    };
    let monitor = MonitorReport { records: 500, loops_seen: 500, ..Default::default() };
    let reports = Reports {
        plant: Some(plant),
        stages: Role::STAGES.into_iter().map(|r| (r, [(0, stage.clone())].into())).collect(),
        monitor: Some(monitor),
        ..Default::default()
    };
    let starts: BTreeMap<Role, Vec<Start>> = [(
        Role::Sensors,
        vec![Start { pid: 7, exit: Exit::Status(0), cpu_s: 0.5, wakeups: 0, preemptions: 0, left_running: vec![] }],
    )]
    .into();
    let summary = build(SummaryInputs {
        config: &config,
        scenario: scenario.as_ref(),
        run_id: "0123",
        run_dir: Path::new("/tmp/run"),
        started_at: "2024-01-01T00:00:00Z".into(),
        outcome: &Outcome::Completed,
        reports: &reports,
        starts: &starts,
        log: &RunLog::default(),
        shared_memory: SharedMemoryCheck { clean: true, ..Default::default() },
    });
    assert!(summary.completed);
    assert_eq!(summary.stopped_because, None);
    assert_eq!((summary.loops, summary.loops_planned, summary.loops_without_command), (500, 500, 0));
    assert_eq!(summary.mode, Mode::Lockstep);
    let wall_time_s = 499_000_000f64 * 1e-9;
    assert_eq!(summary.wall_time_s, wall_time_s);
    assert_eq!(summary.loops_per_s, 499.0 / wall_time_s);
    assert_eq!(summary.monitor.records, 500);
    assert_eq!(summary.monitor.missing.missing_loops, 0);
    assert_eq!(summary.monitor.loop_waits, 2 + 3);
    assert_eq!(summary.restarts, [(Role::Sensors, 0)].into());
    assert_eq!(summary.processes.len(), 1);
    assert_eq!((summary.processes[0].name, summary.processes[0].processed), (Role::Sensors, Some(500)));
    let waits: Vec<_> = summary.adaptive_waits.iter().map(|(r, w)| (*r, w.caught, w.blocked)).collect();
    assert_eq!(waits, [(Role::Sensors, 3, 4), (Role::Estimator, 3, 4), (Role::Controller, 3, 4)]);
    assert!(summary.faults.is_empty() && summary.timeline.is_empty() && summary.restart_steps.is_empty());

    // The plant ran short: not completed, and said why.
    let short = Reports {
        plant: Some(PlantReport { loops: 400, stopped_early: true, ..Default::default() }),
        monitor: Some(MonitorReport { records: 300, loops_seen: 300, ..Default::default() }),
        ..reports
    };
    let summary = summary_of(&config, scenario.as_ref(), &short, &BTreeMap::new());
    assert!(!summary.completed);
    assert_eq!(summary.stopped_because, Some(StopReason::PlantStoppedEarly));
    assert_eq!(summary.monitor.missing.ranges, [[300, 399]], "the loops after the last the monitor saw");
}

/// The summary of a completed run with these reports and process starts, the rest default.
fn summary_of(
    config: &LaunchConfig,
    scenario: &dyn Scenario,
    reports: &Reports,
    starts: &BTreeMap<Role, Vec<Start>>,
) -> Summary {
    build(SummaryInputs {
        config,
        scenario,
        run_id: "0123",
        run_dir: Path::new("/tmp/run"),
        started_at: String::new(),
        outcome: &Outcome::Completed,
        reports,
        starts,
        log: &RunLog::default(),
        shared_memory: SharedMemoryCheck::default(),
    })
}

/// The schema kept in the repo is the one the types make; `LOOPLAB_WRITE_SCHEMA=1` rewrites it.
#[test]
fn summary_schema_is_the_file_in_the_repo() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("schema/summary.schema.json");
    let schema = json_schema();
    if std::env::var_os("LOOPLAB_WRITE_SCHEMA").is_some() {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, &schema).unwrap();
    }
    let kept = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        kept == schema,
        "{} is not the schema of `Summary`; regenerate it with \
         `LOOPLAB_WRITE_SCHEMA=1 cargo test --release -p looplab-shared summary_schema`",
        path.display()
    );
}

/// A killed incarnation sends no report: its count comes from the monitor's loop records,
/// the restarted one's from its own report, and neither repeats the other's.
#[test]
fn each_incarnation_of_a_stage_has_its_own_counts() {
    let overrides = [Override::parse("mode=lockstep").unwrap(), Override::parse("duration_s=2").unwrap()];
    let (config, scenario) = resolve("pendulum", &overrides).unwrap();
    let reported = StageReport { processed: 1500, skipped: 2, ..Default::default() };
    let reports = Reports {
        plant: Some(PlantReport { loops: 2000, ..Default::default() }),
        stages: [(Role::Estimator, [(1, reported)].into())].into(),
        monitor: Some(MonitorReport {
            records_by_incarnation: [(Role::Estimator, vec![500, 1500]), (Role::Sensors, vec![2000])].into(),
            ..Default::default()
        }),
        ..Default::default()
    };
    let start = |pid, exit| Start { pid, exit, cpu_s: 0.0, wakeups: 0, preemptions: 0, left_running: vec![] };
    let starts: BTreeMap<Role, Vec<Start>> = [
        (Role::Estimator, vec![start(1, Exit::Signal(9)), start(2, Exit::Status(0))]),
        (Role::Plant, vec![start(3, Exit::Status(0))]),
    ]
    .into();
    let summary = summary_of(&config, scenario.as_ref(), &reports, &starts);
    let counts: Vec<_> = summary.processes.iter().map(|p| (p.name, p.incarnation, p.processed, p.skipped)).collect();
    assert_eq!(
        counts,
        [
            (Role::Estimator, 0, Some(500), None),
            (Role::Estimator, 1, Some(1500), Some(2)),
            (Role::Plant, 0, None, None)
        ]
    );
}

#[test]
fn a_summary_says_what_wrote_it_and_where() {
    let s = {
        let (config, scenario) = resolve("pendulum", &[]).unwrap();
        summary_of(&config, scenario.as_ref(), &Reports::default(), &BTreeMap::new())
    };
    assert_eq!((s.schema_version, s.looplab_version.as_str()), (1, env!("CARGO_PKG_VERSION")));
    assert_eq!(s.command_line, std::env::args().collect::<Vec<_>>());
    assert_eq!(s.machine.cpus as usize, std::thread::available_parallelism().unwrap().get());
    assert!(!s.machine.kernel.is_empty() && !s.machine.hostname.is_empty(), "{:?}", s.machine);
}

#[test]
fn maps_by_process_keep_their_alphabetical_keys_and_every_value_reads_back() {
    let mut s = summary();
    s.restarts = Role::ALL.into_iter().map(|r| (r, 0)).collect();
    s.adaptive_waits =
        [(Role::Plant, WaitCounts { caught: 1, blocked: 0, busy: 0 }), (Role::Controller, WaitCounts::default())]
            .into();
    s.stopped_because = Some(StopReason::Interrupted);
    s.processes = vec![ProcessInfo {
        name: Role::Monitor,
        incarnation: 0,
        pid: 9,
        exit: Exit::Signal(9),
        cpu_s: 0.0,
        wakeups: 0,
        preemptions: 0,
        processed: None,
        skipped: None,
        command: None,
        scheduling: None,
    }];
    let json = serde_json::to_value(&s).unwrap();
    let keys: Vec<&String> = json["restarts"].as_object().unwrap().keys().collect();
    assert_eq!(keys, ["controller", "estimator", "monitor", "plant", "sensors"]);
    let text = serde_json::to_string(&s).unwrap();
    assert!(
        text.contains(
            r#""adaptive_waits":{"controller":{"caught":0,"blocked":0,"busy":0},"plant":{"caught":1,"blocked":0,"busy":0}}"#
        ),
        "{text}"
    );
    assert!(text.contains(r#""mode":"lockstep""#) && text.contains(r#""stopped_because":"interrupted by a signal""#));
    assert!(text.contains(r#""name":"monitor","incarnation":0,"pid":9,"exit":"signal 9""#), "{text}");
    assert_eq!(serde_json::from_str::<Summary>(&text).unwrap(), s);
}
