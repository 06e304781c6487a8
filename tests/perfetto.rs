//! `looplab export RUN_DIR --perfetto`, read back by a reader that shares nothing with the writer:
//! Python's `protobuf` with Perfetto's own definitions (`perfetto_trace_pb2`, generated from
//! Perfetto's perfetto_trace.proto, as the `perfetto` package on PyPI ships it), in a virtual
//! environment under target/ made once. The reader checks Perfetto's rules (one packet sequence,
//! its incremental state cleared first, the clock, interned names and tracks defined before use,
//! no field Perfetto does not define, slices nested per track) and hands back what it found; the
//! test checks it against the run: each hop's p50 and p99 from the slices, through the report's
//! own definition (the monitor's `Distribution`), equal summary.json's, and one miss instant per
//! deadline miss.
//!
//! Perfetto's own parser (trace_processor) is not used: its Python package downloads the binary at
//! run time from outside the package registries, and no registry ships it.

use crate::common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use common::{Role, fresh_dir, looplab, profile_dir, run};
use looplab_shared::contract::report::HOPS;
use looplab_shared::monitor::distribution::Distribution;
use serde_json::Value;

/// What the virtual environment holds, pinned: Perfetto's Python package (its generated
/// descriptors) and the protobuf runtime it was generated for (6.31 or later, before 7).
const REQUIREMENTS: [&str; 2] = ["perfetto==0.59.1", "protobuf==6.33.6"];

/// The virtual environment's python, made (once per target folder) with the pinned packages.
fn python() -> &'static Path {
    static PYTHON: OnceLock<PathBuf> = OnceLock::new();
    PYTHON.get_or_init(|| {
        let venv = profile_dir().parent().expect("the target folder").join("perfetto-venv");
        let python = venv.join("bin/python");
        let marker = venv.join("looplab-requirements.txt");
        let wanted = REQUIREMENTS.join("\n");
        if std::fs::read_to_string(&marker).ok().as_deref() != Some(wanted.as_str()) {
            let _ = std::fs::remove_dir_all(&venv);
            let made = Command::new("python3").args(["-m", "venv"]).arg(&venv).status().expect("python3");
            assert!(made.success(), "python3 -m venv {}", venv.display());
            let pip = Command::new(venv.join("bin/pip"))
                .args(["install", "--quiet", "--disable-pip-version-check"])
                .args(REQUIREMENTS)
                .output()
                .expect("pip");
            assert!(pip.status.success(), "pip install {REQUIREMENTS:?}:\n{}", String::from_utf8_lossy(&pip.stderr));
            std::fs::write(&marker, &wanted).unwrap();
        }
        python
    })
}

/// The reader: the trace parsed with Perfetto's `Trace` message, checked against Perfetto's rules
/// (each violation a line of `errors`), summarised as JSON on stdout.
const READER: &str = r#"
import json, sys
from collections import defaultdict
from google.protobuf.unknown_fields import UnknownFieldSet
from perfetto.protos.perfetto.trace import perfetto_trace_pb2 as pb

trace = pb.Trace()
trace.ParseFromString(open(sys.argv[1], "rb").read())
errors = []
def error(text):
    if len(errors) < 20:
        errors.append(text)

def unknown(message, where):
    # A field number or wire type Perfetto does not define for that message.
    if len(UnknownFieldSet(message)) > 0:
        error(f"{where}: fields Perfetto does not define")
    for field, value in message.ListFields():
        if field.type == field.TYPE_MESSAGE:
            for item in (value if hasattr(value, "__len__") else [value]):
                unknown(item, f"{where}.{field.name}")

packets = trace.packet
sequences = {p.trusted_packet_sequence_id for p in packets}
if sequences != {1}:
    error(f"packet sequences {sequences}")
first = packets[0]
if not first.sequence_flags & pb.TracePacket.SEQ_INCREMENTAL_STATE_CLEARED:
    error("the first packet does not clear the incremental state")
if first.trace_packet_defaults.timestamp_clock_id != pb.BUILTIN_CLOCK_MONOTONIC:
    error("the sequence's clock is not MONOTONIC")
if first.clock_snapshot.primary_trace_clock != pb.BUILTIN_CLOCK_MONOTONIC:
    error("the trace's clock is not MONOTONIC")
names = {n.iid: n.name for n in first.interned_data.event_names}
annotation_names = {n.iid: n.name for n in first.interned_data.debug_annotation_names}

clocks = {c.clock_id: c.timestamp for c in first.clock_snapshot.clocks}
ftrace = {"switches": 0, "wakeups": 0, "cpus": set(), "comms": {}, "woken": set(), "switch_ins": defaultdict(list)}
last_ftrace_ts = {}
first_event_ts = None
tracks, open_slices = {}, defaultdict(list)
slices = defaultdict(list)            # slice name -> durations
slices_per_track = defaultdict(int)
counters = defaultdict(int)
instants = defaultdict(list)
flow_slices = defaultdict(int)        # flow id -> slices on it
ended_flows = set()
last_ts = 0
for i, p in enumerate(packets):
    unknown(p, f"packet {i}")
    if p.HasField("track_descriptor"):
        d = p.track_descriptor
        if d.HasField("parent_uuid") and d.parent_uuid not in tracks:
            error(f"track {d.name}: parent {d.parent_uuid} not defined before it")
        tracks[d.uuid] = {"name": d.name, "parent": d.parent_uuid if d.HasField("parent_uuid") else None,
                          "pid": d.process.pid if d.HasField("process") else None,
                          "counter": d.HasField("counter")}
        continue
    if p.HasField("ftrace_events"):
        # The kernel's scheduler events, as Perfetto's recorder writes them.
        b = p.ftrace_events
        if not b.HasField("cpu"):
            error(f"packet {i}: an ftrace bundle without its CPU")
        ftrace["cpus"].add(b.cpu)
        for e in b.event:
            if e.timestamp < last_ftrace_ts.get(b.cpu, 0):
                error(f"packet {i}: CPU {b.cpu}'s events go back in time")
            last_ftrace_ts[b.cpu] = e.timestamp
            if e.HasField("sched_switch"):
                s = e.sched_switch
                ftrace["switches"] += 1
                ftrace["comms"][s.prev_pid] = s.prev_comm
                ftrace["comms"][s.next_pid] = s.next_comm
                ftrace["switch_ins"][s.next_pid].append(e.timestamp)
            elif e.HasField("sched_wakeup"):
                ftrace["wakeups"] += 1
                ftrace["woken"].add(e.sched_wakeup.pid)
            else:
                error(f"packet {i}: an ftrace event neither a switch nor a wake-up")
        continue
    if not p.HasField("track_event"):
        continue
    e = p.track_event
    if first_event_ts is None:
        first_event_ts = p.timestamp
    if not p.sequence_flags & pb.TracePacket.SEQ_NEEDS_INCREMENTAL_STATE:
        error(f"packet {i} uses the sequence's state without saying so")
    if p.timestamp < last_ts:
        error(f"packet {i} goes back in time")
    last_ts = p.timestamp
    if e.track_uuid not in tracks:
        error(f"packet {i}: track {e.track_uuid} not defined")
        continue
    track = tracks[e.track_uuid]["name"]
    name = names.get(e.name_iid) if e.HasField("name_iid") else (e.name if e.HasField("name") else None)
    if e.HasField("name_iid") and e.name_iid not in names:
        error(f"packet {i}: name {e.name_iid} not interned")
    for a in e.debug_annotations:
        if a.name_iid not in annotation_names:
            error(f"packet {i}: annotation name {a.name_iid} not interned")
    for flow in list(e.flow_ids) + list(e.terminating_flow_ids):
        if flow in ended_flows:
            error(f"flow {flow} goes on after it ended")
        flow_slices[flow] += 1
    ended_flows.update(e.terminating_flow_ids)
    if e.type == pb.TrackEvent.TYPE_SLICE_BEGIN:
        if open_slices[e.track_uuid]:
            error(f"slices overlap on {track} at {p.timestamp}")
        open_slices[e.track_uuid].append((p.timestamp, name))
    elif e.type == pb.TrackEvent.TYPE_SLICE_END:
        if not open_slices[e.track_uuid]:
            error(f"an end without a begin on {track}")
            continue
        begin, begin_name = open_slices[e.track_uuid].pop()
        slices[begin_name].append(p.timestamp - begin)
        slices_per_track[track] += 1
    elif e.type == pb.TrackEvent.TYPE_COUNTER:
        if not tracks[e.track_uuid]["counter"]:
            error(f"a counter value on {track}, not a counter track")
        counters[track] += 1
    elif e.type == pb.TrackEvent.TYPE_INSTANT:
        instants[track].append(name)
for uuid, stack in open_slices.items():
    if stack:
        error(f"slices left open on {tracks[uuid]['name']}")

if ftrace["switches"] and clocks.get(pb.BUILTIN_CLOCK_BOOTTIME) != clocks.get(pb.BUILTIN_CLOCK_MONOTONIC):
    error(f"ftrace events, read as BOOTTIME, are not given MONOTONIC's time: {clocks}")
# Per pid, its switch-ins within the loop's events' span: where the two clocks line up.
switch_ins_in_span = {pid: sum(first_event_ts <= t <= last_ts for t in ts)
                      for pid, ts in ftrace.pop("switch_ins").items()} if first_event_ts is not None else {}
ftrace.update(cpus=sorted(ftrace["cpus"]), woken=sorted(ftrace["woken"]), switch_ins_in_span=switch_ins_in_span)
json.dump({"errors": errors, "ftrace": ftrace, "packets": len(packets), "tracks": list(tracks.values()), "slices": slices,
           "slices_per_track": slices_per_track, "counters": counters, "instants": instants,
           "flows": len(flow_slices), "flow_slices": sum(flow_slices.values()), "ended_flows": len(ended_flows)},
          sys.stdout)
"#;

/// The trace at `path` as the reader found it.
fn read_trace(path: &Path) -> Value {
    let output = Command::new(python()).arg("-c").arg(READER).arg(path).output().expect("the reader");
    assert!(output.status.success(), "the reader failed:\n{}", String::from_utf8_lossy(&output.stderr));
    serde_json::from_slice(&output.stdout).expect("the reader writes JSON")
}

#[test]
fn a_real_time_run_exports_a_perfetto_trace_that_perfettos_definitions_read_back() {
    let r = run("perfetto", &["pendulum", "--duration", "2", "--fault", "kill estimator at 1s"]);
    let s = r.summary();
    let out = fresh_dir("perfetto-trace").with_extension("perfetto-trace");
    let export = looplab().args(["export"]).arg(&r.dir).arg("--perfetto").arg("--out").arg(&out).output().unwrap();
    assert!(export.status.success(), "{}", String::from_utf8_lossy(&export.stderr));
    assert_eq!(String::from_utf8_lossy(&export.stdout).trim(), format!("wrote {}", out.display()));
    let trace = read_trace(&out);
    assert_eq!(trace["errors"], serde_json::json!([]), "Perfetto's rules");

    // A process track per process, with its first incarnation's pid.
    let tracks = trace["tracks"].as_array().unwrap();
    for role in Role::ALL {
        let pid = s.processes.iter().find(|p| p.name == role).unwrap().pid;
        assert!(
            tracks.iter().any(|t| t["name"] == role.name() && t["pid"] == pid && t["parent"].is_null()),
            "no process track for {role} (pid {pid}): {tracks:?}"
        );
    }

    // Each hop and step: its slices' p50 and p99, by the report's definition, are the report's.
    let slices: BTreeMap<String, Vec<u64>> = serde_json::from_value(trace["slices"].clone()).unwrap();
    for (hop, ..) in HOPS {
        let mut distribution = Distribution::default();
        slices[hop].iter().for_each(|&ns| distribution.record(ns));
        let (mine, reported) = (distribution.stats(), &s.latency_ns.hops[hop]);
        assert_eq!(
            (mine.count, mine.p50, mine.p99),
            (reported.count, reported.p50, reported.p99),
            "{hop}: the trace's slices against summary.json"
        );
    }
    assert_eq!(trace["counters"]["end to end (ns)"], s.latency_ns.end_to_end.count);
    assert!(trace["counters"]["tick wake-up error (ns)"].as_u64().unwrap() > 0);

    // A flow per loop through its slices, plant to plant; each ends.
    let loops = s.latency_ns.end_to_end.count;
    assert_eq!((trace["flows"].as_u64(), trace["ended_flows"].as_u64()), (Some(loops), Some(loops)));
    let loop_slices = HOPS.len() as u64 * loops + trace["slices"]["plant_step"].as_array().unwrap().len() as u64;
    assert_eq!(trace["flow_slices"], loop_slices);

    // One instant per deadline miss (the kill makes some), and the fault and the restart.
    assert!(s.deadline_misses > 0, "the kill made no deadline miss");
    let instants = &trace["instants"];
    let misses = instants["deadline misses"].as_array().unwrap();
    assert_eq!(misses.len() as u64, s.deadline_misses);
    assert!(misses.iter().all(|m| m.as_str().unwrap().starts_with("deadline miss")));
    let estimator: Vec<&str> =
        instants["faults and restarts"].as_array().unwrap().iter().map(|i| i.as_str().unwrap()).collect();
    for what in
        ["inject: kill estimator at 1s", "detected: kill estimator at 1s by the process exited", "estimator ready"]
    {
        assert!(estimator.iter().any(|i| i.starts_with(what)), "no {what:?} in {estimator:?}");
    }
    assert_eq!(instants["launcher"].as_array().unwrap().len(), s.timeline.len());
    let _ = std::fs::remove_file(&out);
}

/// A run with `--trace-sched` (it needs root, as the explain test's traced run: the suite runs as
/// root) exports the kernel's scheduler events: every sched_switch of sched.trace, the wake-ups of
/// the run's own processes, each process's pid and name, on the loop's clock.
#[test]
fn a_traced_runs_export_holds_the_kernels_scheduler_events() {
    let r = run("perfetto-sched", &["pendulum", "--duration", "2", "--trace-sched"]);
    let s = r.summary();
    let sched = std::fs::read_to_string(r.dir.join("sched.trace")).expect("sched.trace (the test runs as root)");
    let out = fresh_dir("perfetto-sched-trace").with_extension("perfetto-trace");
    let export = looplab().args(["export"]).arg(&r.dir).arg("--perfetto").arg("--out").arg(&out).output().unwrap();
    assert!(export.status.success(), "{}", String::from_utf8_lossy(&export.stderr));
    let trace = read_trace(&out);
    assert_eq!(trace["errors"], serde_json::json!([]), "Perfetto's rules");
    let ftrace = &trace["ftrace"];

    // Every switch; the wake-ups of the run's processes, and only theirs.
    let pids: Vec<u32> = s.processes.iter().map(|p| p.pid).collect();
    let switches = sched.lines().filter(|l| l.contains(": sched_switch: ")).count() as u64;
    let wakeups = sched
        .lines()
        .filter(|l| l.contains(": sched_wakeup: "))
        .filter_map(|l| l.split(" pid=").nth(1)?.split(' ').next()?.parse::<u32>().ok())
        .filter(|pid| pids.contains(pid))
        .count() as u64;
    assert!(switches > 1000, "{switches} switches in sched.trace");
    assert_eq!(ftrace["switches"], switches, "sched_switch events against sched.trace's lines");
    assert_eq!(ftrace["wakeups"], wakeups, "the run's processes' wake-ups");
    let woken: Vec<u32> = serde_json::from_value(ftrace["woken"].clone()).unwrap();
    assert!(woken.iter().all(|pid| pids.contains(pid)), "{woken:?} woken, the run's pids {pids:?}");
    assert!(!ftrace["cpus"].as_array().unwrap().is_empty());

    // Each of the loop's processes by its pid and its name, switched in on every loop within the
    // loop's own events (the same clock).
    let loops = s.latency_ns.end_to_end.count;
    for role in Role::ALL {
        let pid = s.processes.iter().find(|p| p.name == role).unwrap().pid;
        let comm = ftrace["comms"][pid.to_string()].as_str().unwrap_or_default();
        assert!(comm.starts_with("looplab-"), "{role} (pid {pid}) is {comm:?} in the trace");
        if role == Role::Plant {
            let ins = ftrace["switch_ins_in_span"][pid.to_string()].as_u64().unwrap_or(0);
            assert!(ins * 10 >= loops * 9, "the plant switched in {ins} times in the span of {loops} loops");
        }
    }
    let _ = std::fs::remove_file(&out);
}
