//! A stage on another host: the pendulum's controller in a second network namespace, with its
//! own /dev/shm (a mount namespace), reached over a veth pair through the two bridges and zenoh.
//! Root only (namespaces): where the build is not root or lacks a tool the hosts need, every test
//! is ignored (services/build.rs).

use crate::common;

use common::netns::{Host, TestHosts, test_hosts};
use common::*;

/// `--set` arguments that place the controller on the test's remote host.
fn placed(hosts: &TestHosts) -> Vec<String> {
    let command: Vec<String> = hosts.remote_prefix().iter().map(|w| format!("{w:?}")).collect();
    vec![
        "--set".into(),
        "hosts.controller=companion".into(),
        "--set".into(),
        format!("hosts.companion.address={}", hosts.remote_address()),
        "--set".into(),
        format!("hosts.companion.command=[{}]", command.join(", ")),
    ]
}

fn launcher_on(hosts: &TestHosts) -> std::process::Command {
    let mut command = hosts.command(Host::Local, env!("CARGO_BIN_EXE_looplab"));
    command.env_remove("CARGO").env_remove("CARGO_MANIFEST_DIR");
    command
}

#[test]
#[cfg_attr(netns_unavailable, ignore = "needs root, iproute2 and util-linux (network namespaces)")]
fn the_pendulum_with_its_controller_on_another_host_keeps_its_loop() {
    let hosts = test_hosts("rt", None);
    let mut args: Vec<String> = ["pendulum", "--set", "duration_s=3"].map(String::from).to_vec();
    args.extend(placed(&hosts));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let run = run_from(launcher_on(&hosts), "remote-rt", &args);
    println!("{}", run.stdout());
    assert!(run.summary["shared_memory"]["clean"].as_bool().unwrap(), "{}", run.summary["shared_memory"]);
    assert_eq!(hosts.remote_shm_entries(), Vec::<String>::new());
}

#[test]
#[cfg_attr(netns_unavailable, ignore = "needs root, iproute2 and util-linux (network namespaces)")]
fn lockstep_with_a_remote_controller_writes_the_local_runs_bytes() {
    let hosts = test_hosts("ls", None);
    let base = ["pendulum", "--set", "mode=lockstep", "--set", "duration_s=2"];
    let local = run("remote-ls-local", &base);
    let mut args: Vec<String> = base.map(String::from).to_vec();
    args.extend(placed(&hosts));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let remote = run_from(launcher_on(&hosts), "remote-ls", &args);
    let bytes = |r: &Run| std::fs::read(r.dir.join("trajectory.csv")).unwrap();
    assert_eq!(remote.summary["loops"], 2000);
    assert!(bytes(&local) == bytes(&remote), "the remote run's trajectory.csv differs from the local run's");
    let topics = &remote.summary["network"]["topics"];
    for topic in ["estimate", "command"] {
        assert_eq!(topics[topic]["sent"], 2000, "{topic}: {topics}");
        assert_eq!(topics[topic]["received"], 2000, "{topic}: {topics}");
        assert_eq!(topics[topic]["gaps"], 0, "{topic}: {topics}");
    }
}

/// The fitted clock of a run on `hosts`, and the corrected crossing hops checked against the
/// link's round trip: a one-way hop is at most the round trip, give or take the offset's
/// uncertainty, which an uncorrected hop between clocks 1000 s apart could never be.
/// A stage of one's own on the other host: the Rust example controller (its own program, started
/// there through the host's prefix with the run's environment), byte-identical to the local run.
#[test]
#[cfg_attr(netns_unavailable, ignore = "needs root, iproute2 and util-linux (network namespaces)")]
fn a_controller_of_ones_own_runs_on_another_host_like_a_built_in_one() {
    let program = built().join("looplab-example-controller");
    let hosts = test_hosts("own", None);
    let base = ["pendulum", "--set", "mode=lockstep", "--set", "duration_s=1"];
    let local = run("remote-own-local", &base);
    let mut args: Vec<String> = base.map(String::from).to_vec();
    args.extend(placed(&hosts));
    args.extend(["--set".into(), format!("stages.controller.command=[{:?}]", program.display().to_string())]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let remote = run_from(launcher_on(&hosts), "remote-own", &args);
    let bytes = |r: &Run| std::fs::read(r.dir.join("trajectory.csv")).unwrap();
    assert!(bytes(&local) == bytes(&remote), "the remote run's trajectory.csv differs from the local run's");
    let controller = remote.summary().processes.iter().find(|p| p.name == Role::Controller).unwrap();
    assert_eq!(controller.command.as_deref(), Some(program.display().to_string().as_str()));
    assert_eq!(hosts.remote_shm_entries(), Vec::<String>::new());
}

fn fitted_offset_ns(hosts: &TestHosts, name: &str) -> (f64, f64) {
    let mut args: Vec<String> = ["pendulum", "--set", "duration_s=3"].map(String::from).to_vec();
    args.extend(placed(hosts));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let run = run_from(launcher_on(hosts), name, &args);
    println!("{}", run.stdout());
    let network = &run.summary["network"];
    let clock = &network["clock"];
    let (offset, uncertainty) = (clock["offset_ns"].as_f64().unwrap(), clock["uncertainty_ns"].as_f64().unwrap());
    let round_trip_p50 = network["round_trip_ns"]["p50"].as_f64().unwrap();
    assert_eq!(network["crossing_hops"], serde_json::json!(["estimator_to_controller", "controller_to_plant"]));
    for hop in ["estimator_to_controller", "controller_to_plant"] {
        let p50 = run.summary["latency_ns"]["hops"][hop]["p50"].as_f64().unwrap();
        assert!(p50 <= round_trip_p50 + uncertainty, "{hop}: p50 {p50} ns against a round trip of {round_trip_p50}");
    }
    (offset, uncertainty)
}

#[test]
#[cfg_attr(netns_unavailable, ignore = "needs root, iproute2 and util-linux (network namespaces)")]
fn a_clock_1000_s_ahead_is_fitted_and_the_crossing_hops_corrected() {
    let hosts = test_hosts("clk", None);
    let (offset, uncertainty) = fitted_offset_ns(&hosts, "remote-clock-same");
    assert!(offset.abs() <= uncertainty, "same clock: fitted offset {offset} ns ± {uncertainty}");
    drop(hosts);
    let shifted = test_hosts("ofs", Some(1000));
    let (offset, uncertainty) = fitted_offset_ns(&shifted, "remote-clock-shifted");
    assert!((offset - 1e12).abs() <= uncertainty, "shifted by 1000 s: fitted offset {offset} ns ± {uncertainty}");
}

#[test]
#[cfg_attr(netns_unavailable, ignore = "needs root, iproute2 and util-linux (network namespaces)")]
fn a_slow_lossy_link_lengthens_the_round_trip_and_makes_commands_late_without_hanging() {
    let hosts = test_hosts("slow", None);
    let slow = hosts.slow_link(std::time::Duration::from_millis(1), 0.01).expect("a slow link");
    let mut args: Vec<String> = ["pendulum", "--set", "duration_s=3"].map(String::from).to_vec();
    args.extend(placed(&hosts));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let run = run_from(launcher_on(&hosts), "remote-slow", &args);
    println!("{}", run.stdout());
    let network = &run.summary["network"];
    // Every frame back from the other host waits 1 ms on the way.
    let round_trip_min = network["round_trip_ns"]["min"].as_u64().unwrap();
    assert!(round_trip_min >= 1_000_000, "round trip min {round_trip_min} ns");
    // At 1 kHz a command that takes over a period is late: the plant counts it.
    let loops = run.summary["loops"].as_u64().unwrap();
    assert_eq!(loops, 3000);
    assert!(run.summary["deadline_misses"].as_u64().unwrap() > loops / 2, "{}", run.summary["deadline_misses"]);
    assert!(slow.dropped_packets() > 0 && slow.delayed_packets() > 0);
    assert_eq!(network["topics"]["command"]["malformed"], 0);
}

/// A fault on the link's bridges: the run goes on, and the summary says what happened.
fn faulted_run(tag: &str, fault: &str) -> (TestHosts, Run) {
    let hosts = test_hosts(tag, None);
    let mut args: Vec<String> = ["pendulum", "--set", "duration_s=4", "--fault", fault].map(String::from).to_vec();
    args.extend(placed(&hosts));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let run = run_from(launcher_on(&hosts), &format!("remote-{tag}"), &args);
    println!("{}", run.stdout());
    (hosts, run)
}

#[test]
#[cfg_attr(netns_unavailable, ignore = "needs root, iproute2 and util-linux (network namespaces)")]
fn a_killed_remote_bridge_is_restarted_and_its_outage_reported() {
    let (hosts, run) = faulted_run("kill", "kill bridge-remote at 1s");
    let s = run.summary();
    assert_eq!(s.restarts[&Role::BridgeRemote], 1);
    assert!(s.stale_ticks > 0, "the plant held its command while the link was down");
    let network = &run.summary["network"];
    assert_eq!(network["link"]["losses"], 1, "{network}");
    assert_eq!(network["link"]["reconnects"], 1, "{network}");
    assert_eq!(network["unreported_bridges"], 1, "the killed bridge sent no report");
    assert_eq!(network["topics"]["estimate"]["lost"], serde_json::Value::Null, "unknown without its report");
    assert!(run.summary["shared_memory"]["clean"].as_bool().unwrap(), "{}", run.summary["shared_memory"]);
    assert_eq!(hosts.remote_shm_entries(), Vec::<String>::new());
}

#[test]
#[cfg_attr(netns_unavailable, ignore = "needs root, iproute2 and util-linux (network namespaces)")]
fn a_silent_remote_bridge_is_lost_after_the_lease_and_found_again() {
    // SIGSTOP: the other host goes silent, as behind a cut cable; zenoh's lease (1 s) notices.
    let (_hosts, run) = faulted_run("stop", "stop bridge-remote at 1s for 1500ms");
    let s = run.summary();
    assert!(s.completed, "the run goes on without its controller's commands");
    assert!(s.stale_ticks > 0, "the plant applied its stale-command policy");
    let link = &run.summary["network"]["link"];
    assert!(link["losses"].as_u64().unwrap() >= 1, "{link}");
    assert_eq!(link["losses"], link["reconnects"], "it came back each time: {link}");
    let stop = &s.faults[0];
    assert_eq!(stop.detected_by, Some(DetectedBy::LinkLease), "{stop:?}");
    assert!(stop.resumed_after_ms.is_some(), "the link came back: {stop:?}");
    assert!(stop.effect.as_ref().is_some_and(|e| e.outage_ticks > 0), "{stop:?}");
}

#[test]
#[cfg_attr(netns_unavailable, ignore = "needs root, iproute2 and util-linux (network namespaces)")]
fn a_cut_link_is_detected_reported_with_its_outage_and_the_loop_recovers() {
    // The link passes nothing either way from loop 1000 to 1299; zenoh's session stays up.
    let (cut_s, rate_hz) = (0.3, 1000.0);
    let (_hosts, run) = faulted_run("cut", "cut bridge at 1s for 300ms");
    let s = run.summary();
    assert!(s.completed, "{:?}", s.stopped_because);
    let cut = &s.faults[0];
    assert_eq!(cut.detected_by, Some(DetectedBy::InputDeadline), "the controller across the link stalled: {cut:?}");
    assert!(cut.continued_after_ms.is_some() && cut.resumed_after_ms.is_some(), "mended and back: {cut:?}");
    let effect = cut.effect.as_ref().expect("the monitor followed the cut's loops");
    // Every loop of the cut goes without a fresh command, and a few more while the first
    // commands after it come back (the same slack as a stop's: the loop's own lateness).
    let cut_ticks = (cut_s * rate_hz) as u64;
    assert!((cut_ticks..=cut_ticks + cut_ticks / 10).contains(&effect.outage_ticks), "{effect:?}");
    // The loop recovered: fresh commands after the cut, every loop recorded to the end.
    assert!(effect.commands_back_at_s.is_some_and(|t| t >= 1.0 + cut_s), "{effect:?}");
    assert_eq!(run.summary["loops"], 4000);
    assert_eq!(run.summary["network"]["link"]["losses"], 0, "a cut leaves the session up");
    let command = &run.summary["network"]["topics"]["command"];
    assert!(command["received"].as_u64().unwrap() < 4000 - cut_ticks + 10, "{command}");
}
