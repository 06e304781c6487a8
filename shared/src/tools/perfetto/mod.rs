//! `looplab export RUN_DIR --perfetto`: the run as a Perfetto trace (`run.perfetto-trace`, a
//! protobuf `Trace` of `TracePacket`s with TrackEvents) from its loops.csv and summary.json, to
//! open in ui.perfetto.dev.
//!
//! What it holds, every time in CLOCK_MONOTONIC ns (the clock of the loop's stamps; the trace's
//! clock is MONOTONIC, `BUILTIN_CLOCK_MONOTONIC` = 3, so that it lines up with a kernel trace of
//! the same machine):
//! - a track per process (plant, sensors, estimator, controller, monitor), with its process
//!   descriptor (the pid of its first incarnation; none in an in-process run), and under it a
//!   track of its steps (a slice per loop from its input's receive stamp to its output's publish
//!   stamp: `sensors_compute` and so on, the report's hop names; the plant's `plant_step` goes from
//!   command k in to state k+1 out, the hold until the tick included) and a track of the hop into
//!   it (`plant_to_sensors`: the writer's publish stamp to the reader's receive stamp). A slice
//!   that would overlap the one before it on its track (a stalled reader: states k and k+1 both
//!   on their way) goes on an overflow track beside it, `… (overlap n)`, as Perfetto wants the
//!   slices of one track nested;
//! - a flow per loop through its slices, plant to plant (flow id k + 1);
//! - counter tracks under the plant: end to end per loop (at its state's publish), the tick's
//!   wake-up error (wake − scheduled, the report's `plant_wake_latency`), and one per column of
//!   loops.csv this reader does not know whose cells are whole numbers (a run-queue wait, say),
//!   written where its value changes: under a process when its name starts with the process's
//!   (`estimator_…`), at that process's receive stamp, else at the loop's start;
//! - instants: each deadline miss (at the tick's deadline, named after loops.csv's `cause` column
//!   when it has one), each fault's injection, detection, restart and resumption, each restart's
//!   death and readiness, and the launcher's timeline.
//!
//! - the kernel's scheduler events when the run was traced (`--trace-sched`: its `sched.trace`),
//!   as Perfetto's own recorder writes them (ftrace bundles per CPU: the viewer's CPU tracks and
//!   thread states): every sched_switch, and the wake-ups of the run's own processes (`sched`
//!   says why only those, and how their times and states are written).
//!
//! summary.json gives the launcher's times in wall-clock ms after tick 0; tick 0's
//! CLOCK_MONOTONIC time is the plant's schedule (`tick_scheduled_ns` − k × period, exact in real
//! time). Lockstep has no schedule: there tick 0 is taken as the first state's publish stamp, a
//! little after the plant's start, so the launcher's events are placed to within that.

mod sched;
mod wire;

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use anyhow::Context as _;

use crate::contract::msg::LoopTrace;
use crate::contract::report::HOPS;
use crate::contract::role::Role;
use crate::contract::run_format::files;
use crate::launcher::sched_trace::TRACE_FILE as SCHED_TRACE;
use crate::launcher::summary::Summary;
use crate::tools::ToolError;
use crate::tools::run_folder::{RunFolder, Table};

/// The trace's file name in the run folder.
pub const FILE: &str = "run.perfetto-trace";

/// The run folder's files the trace is made from.
const FILES: [&str; 2] = [files::LOOPS, files::SUMMARY];

/// The field numbers written, by message (perfetto/protos/perfetto/trace/…; checked against
/// Perfetto's own descriptors by the integration test).
mod field {
    /// Trace.packet (repeated TracePacket).
    pub const TRACE_PACKET: u32 = 1;
    /// TracePacket.clock_snapshot (ClockSnapshot).
    pub const CLOCK_SNAPSHOT: u32 = 6;
    /// TracePacket.timestamp (uint64).
    pub const TIMESTAMP: u32 = 8;
    /// TracePacket.trusted_packet_sequence_id (uint32).
    pub const SEQUENCE_ID: u32 = 10;
    /// TracePacket.track_event (TrackEvent).
    pub const TRACK_EVENT: u32 = 11;
    /// TracePacket.interned_data (InternedData).
    pub const INTERNED_DATA: u32 = 12;
    /// TracePacket.sequence_flags (uint32, SequenceFlags).
    pub const SEQUENCE_FLAGS: u32 = 13;
    /// TracePacket.trace_packet_defaults (TracePacketDefaults).
    pub const PACKET_DEFAULTS: u32 = 59;
    /// TracePacket.track_descriptor (TrackDescriptor).
    pub const TRACK_DESCRIPTOR: u32 = 60;
    /// TracePacketDefaults.timestamp_clock_id (uint32).
    pub const DEFAULTS_CLOCK_ID: u32 = 58;
    /// ClockSnapshot.clocks (repeated Clock).
    pub const SNAPSHOT_CLOCKS: u32 = 1;
    /// ClockSnapshot.primary_trace_clock (BuiltinClock).
    pub const SNAPSHOT_PRIMARY_CLOCK: u32 = 2;
    /// ClockSnapshot.Clock.clock_id (uint32).
    pub const CLOCK_ID: u32 = 1;
    /// ClockSnapshot.Clock.timestamp (uint64).
    pub const CLOCK_TIMESTAMP: u32 = 2;
    /// InternedData.event_names (repeated EventName).
    pub const INTERNED_EVENT_NAMES: u32 = 2;
    /// InternedData.debug_annotation_names (repeated DebugAnnotationName).
    pub const INTERNED_ANNOTATION_NAMES: u32 = 3;
    /// EventName.iid and DebugAnnotationName.iid (uint64).
    pub const INTERNED_IID: u32 = 1;
    /// EventName.name and DebugAnnotationName.name (string).
    pub const INTERNED_NAME: u32 = 2;
    /// TrackDescriptor.uuid (uint64).
    pub const TRACK_UUID: u32 = 1;
    /// TrackDescriptor.name (string).
    pub const TRACK_NAME: u32 = 2;
    /// TrackDescriptor.process (ProcessDescriptor).
    pub const TRACK_PROCESS: u32 = 3;
    /// TrackDescriptor.parent_uuid (uint64).
    pub const TRACK_PARENT: u32 = 5;
    /// TrackDescriptor.counter (CounterDescriptor).
    pub const TRACK_COUNTER: u32 = 8;
    /// TrackDescriptor.child_ordering (ChildTracksOrdering).
    pub const TRACK_CHILD_ORDERING: u32 = 11;
    /// TrackDescriptor.sibling_order_rank (int32).
    pub const TRACK_ORDER_RANK: u32 = 12;
    /// TrackDescriptor.description (string).
    pub const TRACK_DESCRIPTION: u32 = 14;
    /// ProcessDescriptor.pid (int32).
    pub const PROCESS_PID: u32 = 1;
    /// ProcessDescriptor.process_name (string).
    pub const PROCESS_NAME: u32 = 6;
    /// CounterDescriptor.unit (Unit).
    pub const COUNTER_UNIT: u32 = 3;
    /// TrackEvent.debug_annotations (repeated DebugAnnotation).
    pub const EVENT_ANNOTATIONS: u32 = 4;
    /// TrackEvent.type (Type).
    pub const EVENT_TYPE: u32 = 9;
    /// TrackEvent.name_iid (uint64).
    pub const EVENT_NAME_IID: u32 = 10;
    /// TrackEvent.track_uuid (uint64).
    pub const EVENT_TRACK: u32 = 11;
    /// TrackEvent.name (string).
    pub const EVENT_NAME: u32 = 23;
    /// TrackEvent.counter_value (int64).
    pub const EVENT_COUNTER_VALUE: u32 = 30;
    /// TrackEvent.flow_ids (repeated fixed64).
    pub const EVENT_FLOW_IDS: u32 = 47;
    /// TrackEvent.terminating_flow_ids (repeated fixed64).
    pub const EVENT_TERMINATING_FLOW_IDS: u32 = 48;
    /// DebugAnnotation.name_iid (uint64).
    pub const ANNOTATION_NAME_IID: u32 = 1;
    /// DebugAnnotation.uint_value (uint64).
    pub const ANNOTATION_UINT: u32 = 3;
    /// DebugAnnotation.string_value (string).
    pub const ANNOTATION_STRING: u32 = 6;
}

/// ClockSnapshot.Clock.BuiltinClocks.MONOTONIC, BOOTTIME.
const CLOCK_MONOTONIC: u64 = 3;
const CLOCK_BOOTTIME: u64 = 6;
/// TracePacket.SequenceFlags.
const SEQ_INCREMENTAL_STATE_CLEARED: u64 = 1;
const SEQ_NEEDS_INCREMENTAL_STATE: u64 = 2;
/// TrackEvent.Type.
const TYPE_SLICE_BEGIN: u64 = 1;
const TYPE_SLICE_END: u64 = 2;
const TYPE_INSTANT: u64 = 3;
const TYPE_COUNTER: u64 = 4;
/// CounterDescriptor.Unit.UNIT_TIME_NS.
const UNIT_TIME_NS: u64 = 1;
/// TrackDescriptor.ChildTracksOrdering.EXPLICIT.
const ORDER_EXPLICIT: u64 = 3;
/// The one packet sequence of the file.
const SEQUENCE: u64 = 1;
/// Interned debug annotation names.
const ANNOTATION_K: u64 = 1;
const ANNOTATION_CAUSE: u64 = 2;

/// The columns of loops.csv this reader knows; any other is used if it is there (`cause`, or a
/// number per loop as a counter) and skipped if not.
const KNOWN_COLUMNS: [&str; 7] =
    ["k", "t_s", "end_to_end_ns", "deadline_miss", "rejected", "tick_scheduled_ns", "tick_wake_ns"];
/// The column naming why a loop missed its deadline, when loops.csv has it.
pub const CAUSE_COLUMN: &str = "cause";

/// The loop processes, in loop order, each with the hop into it and its own step (indices into
/// `HOPS`; the plant's step is not a hop of the report).
const LOOP_ROLES: [(Role, usize, Option<usize>); 4] = [
    (Role::Plant, 6, None),
    (Role::Sensors, 0, Some(1)),
    (Role::Estimator, 2, Some(3)),
    (Role::Controller, 4, Some(5)),
];

/// Writes the run folder's trace to `out` (default `run_dir/run.perfetto-trace`), replacing one
/// there (it is made from the files alone); returns its path.
pub fn write_perfetto(run_dir: &Path, out: Option<&Path>) -> Result<PathBuf, ToolError> {
    let folder = RunFolder::open(run_dir, &FILES)?;
    let summary = folder.summary()?;
    let loops = folder.table(files::LOOPS)?;
    let sched_path = run_dir.join(SCHED_TRACE);
    let sched = match std::fs::read_to_string(&sched_path) {
        Ok(text) => Some(text),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => return Err(anyhow::Error::new(e).context(format!("read {}", sched_path.display())).into()),
    };
    let bytes = trace(&summary, &loops, sched.as_deref())?;
    let path = out.map_or_else(|| run_dir.join(FILE), Path::to_path_buf);
    let partial = path.with_extension("perfetto-trace.partial");
    std::fs::write(&partial, &bytes).with_context(|| format!("write {}", partial.display()))?;
    std::fs::rename(&partial, &path).with_context(|| format!("write {}", path.display()))?;
    Ok(path)
}

/// The trace of a run: its summary, its loops.csv and its scheduler trace (sched.trace's text)
/// if it has one.
pub fn trace(summary: &Summary, loops: &Table, sched: Option<&str>) -> Result<Vec<u8>, ToolError> {
    let columns = Columns::read(loops)?;
    let mut trace = Builder::new(summary);
    trace.loops(&columns);
    trace.launcher_events(summary, &columns);
    let Some(text) = sched else { return Ok(trace.encode(false)) };
    let pids: HashSet<u32> = summary.processes.iter().map(|p| p.pid).collect();
    let events = sched::SchedEvents::parse(text, &pids, &summary.machine.kernel);
    let mut out = trace.encode(true);
    events.encode(&mut out, field::TRACE_PACKET, field::SEQUENCE_ID, SEQUENCE);
    Ok(out)
}

/// loops.csv's columns, by name.
struct Columns {
    k: Vec<Option<u64>>,
    /// The stamps in `LoopTrace::STAMP_NAMES`' order.
    stamps: Vec<Vec<Option<u64>>>,
    end_to_end: Vec<Option<u64>>,
    deadline_miss: Vec<Option<u64>>,
    scheduled: Vec<Option<u64>>,
    wake: Vec<Option<u64>>,
    period: Vec<Option<u64>>,
    cause: Option<Vec<Option<String>>>,
    /// Any other column whose cells are whole numbers: (name, cells).
    extra: Vec<(String, Vec<Option<i64>>)>,
}

impl Columns {
    fn read(table: &Table) -> Result<Self, ToolError> {
        let stamp_columns: Vec<String> = LoopTrace::STAMP_NAMES.iter().map(|s| format!("{s}_ns")).collect();
        let known = |name: &str| {
            KNOWN_COLUMNS.contains(&name)
                || name == "tick_period_ns"
                || name == CAUSE_COLUMN
                || stamp_columns.iter().any(|s| s == name)
        };
        let extra = table
            .header()
            .filter(|name| !known(name))
            .filter_map(|name| table.column::<i64>(name).ok().map(|cells| (name.to_string(), cells)))
            .collect();
        let has_cause = table.header().any(|name| name == CAUSE_COLUMN);
        Ok(Columns {
            k: table.column("k")?,
            stamps: table.stamps()?,
            end_to_end: table.column("end_to_end_ns")?,
            deadline_miss: table.column("deadline_miss")?,
            scheduled: table.column("tick_scheduled_ns")?,
            wake: table.column("tick_wake_ns")?,
            period: table.column("tick_period_ns")?,
            cause: if has_cause { Some(table.column(CAUSE_COLUMN)?) } else { None },
            extra,
        })
    }

    fn rows(&self) -> usize {
        self.k.len()
    }

    /// Stamp `i` of `row`, where it is set.
    fn stamp(&self, row: usize, i: usize) -> Option<u64> {
        self.stamps[i][row].filter(|&ns| ns > 0)
    }

    /// Where the tick's schedule is known (real time).
    fn scheduled(&self, row: usize) -> Option<u64> {
        self.scheduled[row].filter(|&ns| ns > 0)
    }

    /// The loop's start: its state's publish stamp, else its scheduled tick.
    fn start(&self, row: usize) -> Option<u64> {
        self.stamp(row, 0).or_else(|| self.scheduled(row))
    }
}

/// One event of the trace, before it is encoded.
#[derive(Clone, Copy)]
struct Event {
    ts: u64,
    /// Emission order: breaks ties in time so that a track's begin, end and next begin at the
    /// same nanosecond stay in that order.
    order: u32,
    track: u32,
    kind: Kind,
}

#[derive(Clone, Copy)]
enum Kind {
    /// A slice begins: its interned name, the loop's flow (and whether it ends there), its k.
    Begin {
        name: u32,
        flow: Option<(u64, bool)>,
        k: Option<u64>,
    },
    End,
    /// An instant: its interned name, or a string of `Builder::texts`; its k and cause.
    Instant {
        name: Name,
        k: Option<u64>,
        cause: Option<u32>,
    },
    Counter(i64),
}

#[derive(Clone, Copy)]
enum Name {
    Interned(u32),
    Text(u32),
}

/// A track, as its descriptor says.
struct Track {
    uuid: u32,
    parent: Option<u32>,
    name: String,
    description: Option<String>,
    pid: Option<u32>,
    counter: bool,
    rank: i32,
}

/// A track of slices that never overlap: one lane, and overflow lanes made as needed.
struct Lanes {
    name: String,
    parent: u32,
    rank: i32,
    /// (uuid, the last slice's end) per lane.
    lanes: Vec<(u32, u64)>,
}

struct Builder {
    tracks: Vec<Track>,
    events: Vec<Event>,
    /// Interned event names, iid = index + 1.
    names: Vec<String>,
    name_ids: HashMap<String, u32>,
    /// Instant names that are not interned (the launcher's timeline: each one different).
    texts: Vec<String>,
    /// The process track of each role.
    roles: HashMap<Role, u32>,
    deadline_ns: u64,
    period_ns: u64,
}

impl Builder {
    fn new(summary: &Summary) -> Self {
        let period_ns = if summary.rate_hz > 0.0 { crate::contract::clock::period_ns(summary.rate_hz) } else { 0 };
        let mut builder = Builder {
            tracks: vec![],
            events: vec![],
            names: vec![],
            name_ids: HashMap::new(),
            texts: vec![],
            roles: HashMap::new(),
            deadline_ns: summary.deadline_us.map_or(period_ns, |us| (us * 1e3).round() as u64),
            period_ns,
        };
        for (rank, role) in Role::ALL.into_iter().enumerate() {
            // The pid of the first incarnation: a restarted process has another, which the
            // restart's instants name.
            let pid = summary.processes.iter().find(|p| p.name == role).map(|p| p.pid);
            let description = (!summary.ran_in_process()).then(|| {
                let pids: Vec<String> =
                    summary.processes.iter().filter(|p| p.name == role).map(|p| p.pid.to_string()).collect();
                format!("{role}: pid {} by incarnation", pids.join(", "))
            });
            let uuid = builder.track(None, role.name().to_string(), description, pid, rank as i32);
            builder.roles.insert(role, uuid);
        }
        builder
    }

    fn track(
        &mut self,
        parent: Option<u32>,
        name: String,
        description: Option<String>,
        pid: Option<u32>,
        rank: i32,
    ) -> u32 {
        let uuid = self.tracks.len() as u32 + 1;
        self.tracks.push(Track { uuid, parent, name, description, pid, counter: false, rank });
        uuid
    }

    fn counter_track(&mut self, parent: u32, name: String, rank: i32) -> u32 {
        let uuid = self.track(Some(parent), name, None, None, rank);
        self.tracks[uuid as usize - 1].counter = true;
        uuid
    }

    fn intern(&mut self, name: &str) -> u32 {
        if let Some(&iid) = self.name_ids.get(name) {
            return iid;
        }
        self.names.push(name.to_string());
        let iid = self.names.len() as u32;
        self.name_ids.insert(name.to_string(), iid);
        iid
    }

    fn push(&mut self, ts: u64, track: u32, kind: Kind) {
        let order = self.events.len() as u32;
        self.events.push(Event { ts, order, track, kind });
    }

    fn lanes(&self, parent: Role, name: &str, rank: i32) -> Lanes {
        Lanes { name: name.to_string(), parent: self.roles[&parent], rank, lanes: vec![] }
    }

    /// A slice on `lanes`, on the first lane it does not overlap.
    fn slice(&mut self, lanes: &mut Lanes, begin: u64, end: u64, name: u32, flow: Option<(u64, bool)>, k: Option<u64>) {
        let lane = match lanes.lanes.iter().position(|&(_, last_end)| last_end <= begin) {
            Some(lane) => lane,
            None => {
                let n = lanes.lanes.len();
                let title = if n == 0 { lanes.name.clone() } else { format!("{} (overlap {n})", lanes.name) };
                let uuid = self.track(Some(lanes.parent), title, None, None, lanes.rank + n as i32);
                lanes.lanes.push((uuid, 0));
                n
            }
        };
        let (uuid, last_end) = &mut lanes.lanes[lane];
        *last_end = end;
        let uuid = *uuid;
        self.push(begin, uuid, Kind::Begin { name, flow, k });
        self.push(end, uuid, Kind::End);
    }

    /// The loops: slices and flows, counters, deadline misses.
    fn loops(&mut self, c: &Columns) {
        // Per loop process: the hop into it and its step, each a track of lanes.
        let mut hop_lanes: Vec<Lanes> = vec![];
        let mut step_lanes: Vec<Lanes> = vec![];
        let mut hop_names = vec![];
        let mut step_names = vec![];
        for (role, hop, step) in LOOP_ROLES {
            hop_lanes.push(self.lanes(role, HOPS[hop].0, 20));
            hop_names.push(self.intern(HOPS[hop].0));
            let step_name = step.map_or("plant_step", |s| HOPS[s].0);
            step_lanes.push(self.lanes(role, step_name, 10));
            step_names.push(self.intern(step_name));
        }
        let plant = self.roles[&Role::Plant];
        let end_to_end = self.counter_track(plant, "end to end (ns)".into(), 30);
        let tick_error = self.counter_track(plant, "tick wake-up error (ns)".into(), 40);
        let misses = self.track(Some(plant), "deadline misses".into(), None, None, 50);
        let miss = self.intern("deadline miss");
        let extra: Vec<(Option<(Role, usize)>, u32)> = c
            .extra
            .iter()
            .enumerate()
            .map(|(i, (name, _))| {
                let role = LOOP_ROLES.iter().map(|(r, ..)| *r).find(|r| name.starts_with(&format!("{}_", r.name())));
                // Its process's receive stamp (the plant's: its state's publish).
                let at = role.map(|r| (r, if r == Role::Plant { 0 } else { stamp_index(r, "receive") }));
                let parent = role.map_or(plant, |r| self.roles[&r]);
                (at, self.counter_track(parent, format!("{name} (ns)"), 60 + i as i32))
            })
            .collect();

        let tick0 = self.tick0(c);
        let mut last_extra = vec![None; extra.len()];
        for row in 0..c.rows() {
            let k = c.k[row];
            let stamps: Option<Vec<u64>> = (0..LoopTrace::STAMP_NAMES.len()).map(|i| c.stamp(row, i)).collect();
            if let Some(s) = &stamps {
                let flow = k.map(|k| k + 1);
                // The plant's step: command k in, state k + 1 out (the next row, when it is loop k + 1).
                let next_publish = (row + 1 < c.rows() && c.k[row + 1] == k.map(|k| k + 1))
                    .then(|| c.stamp(row + 1, 0))
                    .flatten()
                    .filter(|&next| next >= s[7]);
                // Hops and steps in loop order, each [from, to] with a saturating end as the report's.
                for (i, (from, to)) in HOPS.iter().map(|(_, from, to)| (*from, *to)).enumerate() {
                    let (lanes, name) = if i % 2 == 0 {
                        (&mut hop_lanes[(i / 2 + 1) % 4], hop_names[(i / 2 + 1) % 4])
                    } else {
                        (&mut step_lanes[i / 2 + 1], step_names[i / 2 + 1])
                    };
                    let last = i == HOPS.len() - 1 && next_publish.is_none();
                    let slice_k = (i % 2 == 1).then_some(k).flatten();
                    self.slice(lanes, s[from], s[to].max(s[from]), name, flow.map(|f| (f, last)), slice_k);
                }
                if let Some(next) = next_publish {
                    self.slice(&mut step_lanes[0], s[7], next, step_names[0], flow.map(|f| (f, true)), k);
                }
            }
            if let (Some(e2e), Some(start)) = (c.end_to_end[row], c.stamp(row, 0)) {
                self.push(start, end_to_end, Kind::Counter(e2e as i64));
            }
            // As the report's plant_wake_latency: ticks woken for on the clock (period > 0).
            if let (Some(scheduled), Some(wake), Some(1..)) = (c.scheduled(row), c.wake[row], c.period[row]) {
                self.push(wake, tick_error, Kind::Counter(wake as i64 - scheduled as i64));
            }
            if c.deadline_miss[row] == Some(1) {
                // At the deadline: after the tick's scheduled time (a skipped tick's row has none:
                // its place in the schedule; in lockstep the loop's start).
                let tick = k.zip(tick0).filter(|_| self.period_ns > 0).map(|(k, tick0)| tick0 + k * self.period_ns);
                let at = c.scheduled(row).or(tick).or_else(|| c.start(row));
                let cause = c.cause.as_ref().and_then(|cause| cause[row].clone()).filter(|cause| !cause.is_empty());
                let name = match &cause {
                    Some(cause) => self.intern(&format!("deadline miss: {cause}")),
                    None => miss,
                };
                let cause = cause.map(|cause| self.text(cause));
                if let Some(at) = at {
                    self.push(at + self.deadline_ns, misses, Kind::Instant { name: Name::Interned(name), k, cause });
                }
            }
            // Written where the value changes (a counter holds its value until the next): most
            // loops wait in no queue, and a trace of zeros would be most of the file.
            for (((_, cells), (at, track)), last) in c.extra.iter().zip(&extra).zip(&mut last_extra) {
                let ts = at.map_or_else(|| c.start(row), |(_, i)| c.stamp(row, i));
                if let (Some(value), Some(ts)) = (cells[row], ts)
                    && *last != Some(value)
                {
                    self.push(ts, *track, Kind::Counter(value));
                    *last = Some(value);
                }
            }
        }
    }

    fn text(&mut self, text: String) -> u32 {
        self.texts.push(text);
        self.texts.len() as u32 - 1
    }

    /// What the launcher saw: each fault's injection, detection, restart and resumption, each
    /// restart's steps, the timeline. summary.json has them in wall-clock ms after tick 0.
    fn launcher_events(&mut self, summary: &Summary, c: &Columns) {
        let Some(tick0) = self.tick0(c) else { return };
        let at = |ms: f64| (tick0 as f64 + ms * 1e6).round().max(0.0) as u64;
        let launcher =
            self.track(None, "launcher".into(), Some("what the launcher saw, its timeline".into()), None, 10);
        let event_tracks: HashMap<Role, u32> = Role::ALL
            .into_iter()
            .enumerate()
            .map(|(i, role)| {
                (role, self.track(Some(self.roles[&role]), "faults and restarts".into(), None, None, 90 + i as i32))
            })
            .collect();
        let track_of = |role: Role| event_tracks.get(&role).copied().unwrap_or(launcher);
        let mut instants: Vec<(u64, u32, String)> = vec![];
        for fault in &summary.faults {
            let track = track_of(fault.process);
            // A fault applied by the stage itself (delay, drop, corrupt) has no launcher time:
            // it takes effect at its loop, whose tick is at_s after tick 0.
            let injected = fault.injected_at_ms.map_or_else(|| at(fault.at_s * 1e3), at);
            instants.push((injected, track, format!("inject: {}", fault.fault)));
            let Some(injected_ms) = fault.injected_at_ms else { continue };
            let after = |ms: Option<f64>| ms.map(|ms| at(injected_ms + ms));
            if let Some(ns) = after(fault.detected_after_ms) {
                let by = fault
                    .detected_by
                    .and_then(|by| serde_json::to_value(by).ok()?.as_str().map(|by| format!(" by {by}")));
                instants.push((ns, track, format!("detected: {}{}", fault.fault, by.unwrap_or_default())));
            }
            for (ms, what) in [
                (fault.restarted_after_ms, "restarted"),
                (fault.continued_after_ms, "continued"),
                (fault.resumed_after_ms, "resumed"),
            ] {
                if let Some(ns) = after(ms) {
                    instants.push((ns, track, format!("{what}: {}", fault.fault)));
                }
            }
        }
        for restart in &summary.restart_steps {
            let track = track_of(restart.process);
            let n = restart.incarnation;
            instants.push((
                at(restart.died_at_ms),
                track,
                format!("{} died (restart as incarnation {n})", restart.process),
            ));
            if let Some(ready) = restart.ready_after_ms {
                instants.push((
                    at(restart.died_at_ms + ready),
                    track,
                    format!("{} ready (incarnation {n})", restart.process),
                ));
            }
        }
        for entry in &summary.timeline {
            instants.push((at(entry.at_ms), launcher, entry.event.clone()));
        }
        for (ts, track, text) in instants {
            let name = Name::Text(self.text(text));
            self.push(ts, track, Kind::Instant { name, k: None, cause: None });
        }
    }

    /// Tick 0 in CLOCK_MONOTONIC ns: from the plant's schedule in real time, else the first
    /// state's publish stamp.
    fn tick0(&self, c: &Columns) -> Option<u64> {
        let scheduled = (0..c.rows()).find_map(|row| Some((c.scheduled(row)?, c.k[row]?)));
        match scheduled {
            Some((ns, k)) => ns.checked_sub(k * self.period_ns),
            None => (0..c.rows()).find_map(|row| c.stamp(row, 0)),
        }
    }

    /// The trace's bytes: the sequence's first packet (its incremental state cleared: the clock
    /// and the interned names), the tracks, then every event in time order. With `ftrace`, the
    /// clock snapshot gives BOOTTIME, the clock Perfetto reads ftrace events on, MONOTONIC's
    /// reading (`sched`).
    fn encode(mut self, ftrace: bool) -> Vec<u8> {
        self.events.sort_unstable_by_key(|e| (e.ts, e.order));
        let mut out = Vec::with_capacity(self.events.len() * 40 + 4096);
        let first_ts = self.events.first().map_or(0, |e| e.ts);
        packet(&mut out, |p| {
            wire::uint(p, field::SEQUENCE_ID, SEQUENCE);
            wire::uint(p, field::SEQUENCE_FLAGS, SEQ_INCREMENTAL_STATE_CLEARED);
            wire::message(p, field::PACKET_DEFAULTS, |d| wire::uint(d, field::DEFAULTS_CLOCK_ID, CLOCK_MONOTONIC));
            wire::message(p, field::INTERNED_DATA, |d| {
                for (i, name) in self.names.iter().enumerate() {
                    wire::message(d, field::INTERNED_EVENT_NAMES, |n| {
                        wire::uint(n, field::INTERNED_IID, i as u64 + 1);
                        wire::bytes(n, field::INTERNED_NAME, name.as_bytes());
                    });
                }
                for (iid, name) in [(ANNOTATION_K, "k"), (ANNOTATION_CAUSE, CAUSE_COLUMN)] {
                    wire::message(d, field::INTERNED_ANNOTATION_NAMES, |n| {
                        wire::uint(n, field::INTERNED_IID, iid);
                        wire::bytes(n, field::INTERNED_NAME, name.as_bytes());
                    });
                }
            });
            // The trace's own clock is MONOTONIC, the loop's stamps' clock.
            wire::message(p, field::CLOCK_SNAPSHOT, |s| {
                wire::message(s, field::SNAPSHOT_CLOCKS, |c| {
                    wire::uint(c, field::CLOCK_ID, CLOCK_MONOTONIC);
                    wire::uint(c, field::CLOCK_TIMESTAMP, first_ts);
                });
                // The scheduler's events are MONOTONIC too, read by Perfetto as BOOTTIME: one to one.
                if ftrace {
                    wire::message(s, field::SNAPSHOT_CLOCKS, |c| {
                        wire::uint(c, field::CLOCK_ID, CLOCK_BOOTTIME);
                        wire::uint(c, field::CLOCK_TIMESTAMP, first_ts);
                    });
                }
                wire::uint(s, field::SNAPSHOT_PRIMARY_CLOCK, CLOCK_MONOTONIC);
            });
        });
        for track in &self.tracks {
            packet(&mut out, |p| {
                wire::uint(p, field::SEQUENCE_ID, SEQUENCE);
                wire::message(p, field::TRACK_DESCRIPTOR, |d| {
                    wire::uint(d, field::TRACK_UUID, track.uuid.into());
                    if let Some(parent) = track.parent {
                        wire::uint(d, field::TRACK_PARENT, parent.into());
                    }
                    wire::bytes(d, field::TRACK_NAME, track.name.as_bytes());
                    if let Some(description) = &track.description {
                        wire::bytes(d, field::TRACK_DESCRIPTION, description.as_bytes());
                    }
                    if let Some(pid) = track.pid {
                        wire::message(d, field::TRACK_PROCESS, |p| {
                            wire::uint(p, field::PROCESS_PID, pid.into());
                            wire::bytes(p, field::PROCESS_NAME, track.name.as_bytes());
                        });
                    }
                    if track.counter {
                        wire::message(d, field::TRACK_COUNTER, |c| wire::uint(c, field::COUNTER_UNIT, UNIT_TIME_NS));
                    }
                    wire::uint(d, field::TRACK_CHILD_ORDERING, ORDER_EXPLICIT);
                    wire::int(d, field::TRACK_ORDER_RANK, track.rank.into());
                });
            });
        }
        for event in &self.events {
            packet(&mut out, |p| {
                wire::uint(p, field::TIMESTAMP, event.ts);
                wire::uint(p, field::SEQUENCE_ID, SEQUENCE);
                // Its clock (the defaults) and its names are the sequence's incremental state.
                wire::uint(p, field::SEQUENCE_FLAGS, SEQ_NEEDS_INCREMENTAL_STATE);
                wire::message(p, field::TRACK_EVENT, |e| self.track_event(e, event));
            });
        }
        out
    }

    fn track_event(&self, e: &mut Vec<u8>, event: &Event) {
        let kind = match event.kind {
            Kind::Begin { .. } => TYPE_SLICE_BEGIN,
            Kind::End => TYPE_SLICE_END,
            Kind::Instant { .. } => TYPE_INSTANT,
            Kind::Counter(_) => TYPE_COUNTER,
        };
        wire::uint(e, field::EVENT_TYPE, kind);
        wire::uint(e, field::EVENT_TRACK, event.track.into());
        let k_annotation = |e: &mut Vec<u8>, k: Option<u64>| {
            if let Some(k) = k {
                wire::message(e, field::EVENT_ANNOTATIONS, |a| {
                    wire::uint(a, field::ANNOTATION_NAME_IID, ANNOTATION_K);
                    wire::uint(a, field::ANNOTATION_UINT, k);
                });
            }
        };
        match event.kind {
            Kind::Begin { name, flow, k } => {
                wire::uint(e, field::EVENT_NAME_IID, name.into());
                if let Some((flow, last)) = flow {
                    let field = if last { field::EVENT_TERMINATING_FLOW_IDS } else { field::EVENT_FLOW_IDS };
                    wire::fixed64(e, field, flow);
                }
                k_annotation(e, k);
            }
            Kind::End => {}
            Kind::Instant { name, k, cause } => {
                match name {
                    Name::Interned(iid) => wire::uint(e, field::EVENT_NAME_IID, iid.into()),
                    Name::Text(i) => wire::bytes(e, field::EVENT_NAME, self.texts[i as usize].as_bytes()),
                }
                k_annotation(e, k);
                if let Some(cause) = cause {
                    wire::message(e, field::EVENT_ANNOTATIONS, |a| {
                        wire::uint(a, field::ANNOTATION_NAME_IID, ANNOTATION_CAUSE);
                        wire::bytes(a, field::ANNOTATION_STRING, self.texts[cause as usize].as_bytes());
                    });
                }
            }
            Kind::Counter(value) => wire::int(e, field::EVENT_COUNTER_VALUE, value),
        }
    }
}

/// One `Trace.packet`.
fn packet(out: &mut Vec<u8>, body: impl FnOnce(&mut Vec<u8>)) {
    wire::message(out, field::TRACE_PACKET, body);
}

/// The index of `role`'s `what` ("receive", "publish") stamp in `LoopTrace::STAMP_NAMES`.
fn stamp_index(role: Role, what: &str) -> usize {
    let name = format!("{}_{what}", role.name());
    LoopTrace::STAMP_NAMES.iter().position(|s| *s == name).unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::launcher::summary::tests::summary;

    /// A field of a message: its number and its varint, fixed64 or bytes.
    #[derive(Debug, Clone, Copy, PartialEq)]
    enum Value<'a> {
        Varint(u64),
        Fixed(u64),
        Bytes(&'a [u8]),
    }

    /// A message's fields, in order (a reader just for these tests; the integration test reads
    /// the file with Perfetto's own descriptors).
    fn fields(mut bytes: &[u8]) -> Vec<(u32, Value<'_>)> {
        fn varint(bytes: &mut &[u8]) -> u64 {
            let (mut value, mut shift) = (0u64, 0);
            loop {
                let byte = bytes[0];
                *bytes = &bytes[1..];
                value |= u64::from(byte & 0x7f) << shift;
                shift += 7;
                if byte < 0x80 {
                    return value;
                }
            }
        }
        let mut out = vec![];
        while !bytes.is_empty() {
            let key = varint(&mut bytes);
            let value = match key & 7 {
                0 => Value::Varint(varint(&mut bytes)),
                1 => {
                    let (value, rest) = bytes.split_at(8);
                    bytes = rest;
                    Value::Fixed(u64::from_le_bytes(value.try_into().unwrap()))
                }
                2 => {
                    let len = varint(&mut bytes) as usize;
                    let (value, rest) = bytes.split_at(len);
                    bytes = rest;
                    Value::Bytes(value)
                }
                wire => panic!("wire type {wire}"),
            };
            out.push(((key >> 3) as u32, value));
        }
        out
    }

    fn get<'a>(fields: &[(u32, Value<'a>)], number: u32) -> Option<Value<'a>> {
        fields.iter().find(|(n, _)| *n == number).map(|(_, v)| *v)
    }

    fn bytes_of<'a>(fields: &[(u32, Value<'a>)], number: u32) -> &'a [u8] {
        match get(fields, number) {
            Some(Value::Bytes(b)) => b,
            other => panic!("field {number}: {other:?}"),
        }
    }

    /// Loop 1's command comes late: state 2 is out before it, so its hop into the plant overlaps
    /// loop 2's and goes on an overflow track; loop 1 missed its deadline, for a cause.
    const LOOPS: &str = "k,t_s,plant_publish_ns,sensors_receive_ns,sensors_publish_ns,estimator_receive_ns,\
estimator_publish_ns,controller_receive_ns,controller_publish_ns,plant_receive_ns,end_to_end_ns,deadline_miss,\
rejected,tick_scheduled_ns,tick_wake_ns,tick_period_ns,cause,controller_runqueue_wait_ns\n\
0,0,1000,1100,1200,1300,1400,1500,1600,1700,700,0,0,1000,1000,0,,5\n\
1,0.001,2000,2100,2200,2300,2400,2500,3500,3600,1600,1,0,2000,2010,1010,controller preempted,900\n\
2,0.002,3000,3100,3200,3300,3400,3500,3510,3900,900,0,0,3000,3005,995,,\n";

    #[test]
    fn a_run_is_slices_flows_counters_and_instants_on_nested_tracks() {
        let mut s = summary();
        s.rate_hz = 1000.0;
        s.deadline_us = Some(1.0);
        let table = Table::parse("loops.csv", LOOPS).unwrap();
        let bytes = trace(&s, &table, None).unwrap();
        let packets: Vec<Vec<(u32, Value)>> = fields(&bytes)
            .into_iter()
            .map(|(n, v)| match (n, v) {
                (field::TRACE_PACKET, Value::Bytes(p)) => fields(p),
                other => panic!("not a packet: {other:?}"),
            })
            .collect();
        // The first packet clears the sequence's incremental state and sets its clock.
        let first = &packets[0];
        assert_eq!(get(first, field::SEQUENCE_FLAGS), Some(Value::Varint(SEQ_INCREMENTAL_STATE_CLEARED)));
        let defaults = fields(bytes_of(first, field::PACKET_DEFAULTS));
        assert_eq!(get(&defaults, field::DEFAULTS_CLOCK_ID), Some(Value::Varint(CLOCK_MONOTONIC)));
        let names: Vec<String> = fields(bytes_of(first, field::INTERNED_DATA))
            .iter()
            .filter(|(n, _)| *n == field::INTERNED_EVENT_NAMES)
            .map(|(_, v)| match v {
                Value::Bytes(b) => String::from_utf8(bytes_of(&fields(b), field::INTERNED_NAME).to_vec()).unwrap(),
                _ => panic!(),
            })
            .collect();
        assert!(names.contains(&"deadline miss: controller preempted".to_string()), "{names:?}");
        let tracks: HashMap<u64, String> = packets
            .iter()
            .filter_map(|p| match get(p, field::TRACK_DESCRIPTOR) {
                Some(Value::Bytes(d)) => {
                    let d = fields(d);
                    let Some(Value::Varint(uuid)) = get(&d, field::TRACK_UUID) else { panic!() };
                    Some((uuid, String::from_utf8(bytes_of(&d, field::TRACK_NAME).to_vec()).unwrap()))
                }
                _ => None,
            })
            .collect();
        assert!(tracks.values().any(|t| t == "controller_to_plant (overlap 1)"), "{tracks:?}");
        assert!(tracks.values().any(|t| t == "controller_runqueue_wait_ns (ns)"), "{tracks:?}");
        // Every event in time order, each on a described track; per track, slices nest.
        let (mut last_ts, mut open, mut counts) = (0, HashMap::<u64, u32>::new(), HashMap::<(String, u64), u32>::new());
        let mut flows = vec![];
        for p in &packets[1 + tracks.len()..] {
            assert_eq!(get(p, field::SEQUENCE_FLAGS), Some(Value::Varint(SEQ_NEEDS_INCREMENTAL_STATE)));
            let Some(Value::Varint(ts)) = get(p, field::TIMESTAMP) else { panic!("no timestamp") };
            assert!(ts >= last_ts);
            last_ts = ts;
            let e = fields(bytes_of(p, field::TRACK_EVENT));
            let (Some(Value::Varint(kind)), Some(Value::Varint(track))) =
                (get(&e, field::EVENT_TYPE), get(&e, field::EVENT_TRACK))
            else {
                panic!()
            };
            let depth = open.entry(track).or_default();
            match kind {
                TYPE_SLICE_BEGIN => {
                    *depth += 1;
                    assert_eq!(*depth, 1, "slices overlap on {}", tracks[&track]);
                }
                TYPE_SLICE_END => *depth -= 1,
                _ => {}
            }
            *counts.entry((tracks[&track].clone(), kind)).or_default() += 1;
            flows.extend(e.iter().filter(|(n, _)| matches!(*n, 47 | 48)).map(|(n, v)| (*n, *v)));
        }
        assert!(open.values().all(|&d| d == 0));
        let count = |track: &str, kind| counts.get(&(track.to_string(), kind)).copied().unwrap_or(0);
        assert_eq!(count("sensors_compute", TYPE_SLICE_BEGIN), 3);
        assert_eq!(
            count("controller_to_plant", TYPE_SLICE_BEGIN) + count("controller_to_plant (overlap 1)", TYPE_SLICE_BEGIN),
            3
        );
        // The plant's step: loop 0 (1700 to 2000); loop 1's command came after state 2 went out.
        assert_eq!(count("plant_step", TYPE_SLICE_BEGIN), 1);
        assert_eq!(count("deadline misses", TYPE_INSTANT), 1);
        assert_eq!(count("end to end (ns)", TYPE_COUNTER), 3);
        assert_eq!(count("tick wake-up error (ns)", TYPE_COUNTER), 2, "tick 0 is not a timer's wake-up");
        assert_eq!(count("controller_runqueue_wait_ns (ns)", TYPE_COUNTER), 2);
        // A flow per loop: 8 slices of loop 0 (its plant step ends it), 7 of loops 1 and 2.
        let ending = flows.iter().filter(|(n, _)| *n == 48).count();
        assert_eq!((flows.len(), ending), (8 + 7 + 7, 3));
    }

    /// The scheduler's events of a traced run: a bundle per CPU, after the loop's packets, on the
    /// loop's clock (BOOTTIME, which Perfetto reads them on, given MONOTONIC's reading).
    #[test]
    fn a_traced_runs_scheduler_events_are_ftrace_bundles_per_cpu() {
        const SCHED: &str = "\
# entries-in-buffer/entries-written: 3/3   #P:2
 looplab-estimat-200     [000] d..2.     0.000001: sched_wakeup: comm=looplab-control pid=300 prio=120 target_cpu=001
         my hog-400   [001] d..2.     0.000002: sched_switch: prev_comm=my hog prev_pid=400 prev_prio=49 prev_state=R+ ==> next_comm=looplab-control next_pid=300 next_prio=120
 looplab-control-300     [001] d..2.     0.000003: sched_switch: prev_comm=looplab-control prev_pid=300 prev_prio=120 prev_state=S ==> next_comm=swapper/1 next_pid=0 next_prio=120
";
        let mut s = summary();
        s.rate_hz = 1000.0;
        s.machine.kernel = "6.1.0-13-amd64".into();
        let table = Table::parse("loops.csv", LOOPS).unwrap();
        let plain = trace(&s, &table, None).unwrap();
        let bytes = trace(&s, &table, Some(SCHED)).unwrap();
        let packets: Vec<Vec<(u32, Value)>> = fields(&bytes)
            .into_iter()
            .map(|(_, v)| match v {
                Value::Bytes(p) => fields(p),
                other => panic!("not a packet: {other:?}"),
            })
            .collect();
        let clocks: Vec<(u64, u64)> = fields(bytes_of(&packets[0], field::CLOCK_SNAPSHOT))
            .iter()
            .filter(|(n, _)| *n == field::SNAPSHOT_CLOCKS)
            .map(|(_, c)| match c {
                Value::Bytes(c) => match (get(&fields(c), 1), get(&fields(c), 2)) {
                    (Some(Value::Varint(id)), Some(Value::Varint(ts))) => (id, ts),
                    other => panic!("{other:?}"),
                },
                _ => panic!(),
            })
            .collect();
        assert_eq!(clocks, [(CLOCK_MONOTONIC, 1000), (CLOCK_BOOTTIME, 1000)]);
        // The loop's packets as before (but the clock), then the kernel's release, then a bundle per CPU.
        let loop_packets = fields(&plain).len();
        let system = fields(bytes_of(&packets[loop_packets], 45));
        let utsname = fields(bytes_of(&system, 1));
        assert_eq!(bytes_of(&utsname, 3), b"6.1.0-13-amd64");
        let bundles: Vec<Vec<(u32, Value)>> =
            packets[loop_packets + 1..].iter().map(|p| fields(bytes_of(p, 1))).collect();
        assert_eq!(bundles.len(), 2);
        assert_eq!(get(&bundles[0], 1), Some(Value::Varint(0)));
        assert_eq!(get(&bundles[1], 1), Some(Value::Varint(1)));
        let events: Vec<Vec<(u32, Value)>> = bundles[1]
            .iter()
            .filter(|(n, _)| *n == 2)
            .map(|(_, e)| match e {
                Value::Bytes(e) => fields(e),
                _ => panic!(),
            })
            .collect();
        assert_eq!(events.len(), 2);
        assert_eq!(get(&events[0], 1), Some(Value::Varint(2_000)), "µs in ns, as printed");
        assert_eq!(get(&events[0], 2), Some(Value::Varint(400)));
        let switch = fields(bytes_of(&events[0], 4));
        assert_eq!(bytes_of(&switch, 1), b"my hog");
        assert_eq!(get(&switch, 4), Some(Value::Varint(0x100)), "preempted, 4.14 and later");
        assert_eq!(bytes_of(&switch, 5), b"looplab-control");
        assert_eq!(get(&switch, 6), Some(Value::Varint(300)));
        let wakeup: Vec<Vec<(u32, Value)>> = bundles[0]
            .iter()
            .filter(|(n, _)| *n == 2)
            .map(|(_, e)| match e {
                Value::Bytes(e) => fields(bytes_of(&fields(e), 17)),
                _ => panic!(),
            })
            .collect();
        assert_eq!(wakeup.len(), 1);
        assert_eq!(get(&wakeup[0], 2), Some(Value::Varint(300)));
        assert_eq!(get(&wakeup[0], 5), Some(Value::Varint(1)));
    }

    #[test]
    fn a_folder_without_the_files_is_bad_input() {
        let dir = std::env::temp_dir().join(format!("looplab-perfetto-none-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let Err(ToolError::BadInput(why)) = write_perfetto(&dir, None) else { panic!("not bad input") };
        assert!(why.ends_with("not a run folder (it has no loops.csv)"), "{why}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
