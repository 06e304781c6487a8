//! `run.mcap`: the run as an MCAP recording that Foxglove and PlotJuggler open, one channel per
//! topic of the loop plus the per-loop latency and the faults. Messages are JSON with a JSON
//! Schema made from the scenario's vectors, so that a viewer plots each field by its name.

mod file;
mod schemas;

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::Result;
use serde_json::{Value, json};

use crate::config::faults::FaultSpec;
use crate::config::launch::{LaunchConfig, Mode};
use crate::config::schema::Component;
use crate::contract::msg::Header;
use crate::contract::report::{FaultEffect, HOPS, MonitorReport};
use crate::contract::role::Role;
use crate::contract::run_format::{FORMAT_VERSION, FORMAT_VERSION_KEY, channel, field, files};
use crate::model::layout::VectorLayout;
use crate::monitor::sinks::text::{push_int, push_json_f64};
use crate::monitor::sinks::{FileEnd, JoinedLoop, RunSink, SinkSetup};
pub use file::Compression;
use file::McapFile;
use schemas::schemas;

/// The first monitor's recording ([`files::restarted_recording`] names a restarted monitor's).
pub const FILE: &str = files::RECORDING;

/// The recording's channels, in the order they are added.
#[derive(Debug, Clone, Copy)]
enum Channel {
    State,
    Measurements,
    Estimate,
    Command,
    Loop,
    Latency,
    Faults,
}

impl Channel {
    const ALL: [Channel; 7] = [
        Channel::State,
        Channel::Measurements,
        Channel::Estimate,
        Channel::Command,
        Channel::Loop,
        Channel::Latency,
        Channel::Faults,
    ];

    fn topic(self) -> &'static str {
        match self {
            Channel::State => channel::STATE,
            Channel::Measurements => channel::MEASUREMENTS,
            Channel::Estimate => channel::ESTIMATE,
            Channel::Command => channel::COMMAND,
            Channel::Loop => channel::LOOP,
            Channel::Latency => channel::LATENCY,
            Channel::Faults => channel::FAULTS,
        }
    }
}

/// What the recording knows of each loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Detail {
    /// Everything the monitor received: every field a stage reads, which `looplab replay` plays
    /// back (`runtime::replay::recording_reader`).
    Live,
    /// What a run folder's files keep (`looplab export`): no sensor sample times, sequence
    /// numbers or fresh and valid flags, no applied input in the messages, no lost flags or
    /// incarnations; `runtime::replay::recording_reader` refuses it.
    Files,
}

/// JSON object keys, written once: `"name":`.
struct Keys {
    state: Vec<Vec<u8>>,
    /// Per sensor: `"name":{"value":{` and its components.
    sensors: Vec<(Vec<u8>, Vec<Vec<u8>>)>,
    estimate: Vec<Vec<u8>>,
    input: Vec<Vec<u8>>,
    /// The loop header's incarnations, and the hops.
    incarnations: Vec<Vec<u8>>,
    hops: Vec<Vec<u8>>,
}

/// The processes whose incarnations a loop header holds, in its order.
const HEADER_ROLES: [Role; 4] = [Role::Plant, Role::Sensors, Role::Estimator, Role::Controller];

fn key(name: &str) -> Vec<u8> {
    let mut key = serde_json::to_vec(name).expect("a string is JSON");
    key.push(b':');
    key
}

impl Keys {
    fn new(layout: &VectorLayout) -> Self {
        let keys = |components: &[Component]| components.iter().map(|c| key(c.name)).collect();
        Self {
            state: keys(&layout.state),
            sensors: layout
                .sensors
                .iter()
                .map(|(name, components)| {
                    let mut prefix = key(name);
                    prefix.push(b'{');
                    prefix.extend_from_slice(&key(field::VALUE));
                    prefix.push(b'{');
                    (prefix, keys(components))
                })
                .collect(),
            estimate: keys(&layout.estimate),
            input: keys(&layout.input),
            incarnations: HEADER_ROLES.iter().map(|r| key(r.name())).collect(),
            hops: HOPS.iter().map(|(name, _, _)| key(&format!("{name}_ns"))).collect(),
        }
    }
}

/// A run's MCAP recording: the monitor's sink, and what `looplab export` writes.
pub struct McapRecording {
    /// None once finished.
    file: Option<McapFile>,
    channel_ids: [u16; Channel::ALL.len()],
    sequences: [u32; Channel::ALL.len()],
    keys: Keys,
    detail: Detail,
    /// Real time: log times are the plant's publish stamps; lockstep: simulation time.
    wall_clock: bool,
    rate_hz: f64,
    dt_ns: i64,
    faults: Vec<FaultSpec>,
    /// Per fault: its first tick, and the log time of the first loop at or after it.
    fault_times: Vec<(u64, Option<u64>)>,
    /// The newest log time written (a wall-clock loop without a stamp takes it).
    last_log_time: u64,
    /// The message being written, reused.
    buf: Vec<u8>,
    /// The loop being written's `{"k":K,"t":T`, which each of its messages starts with.
    loop_prefix: ((u64, u64), Vec<u8>),
}

impl McapRecording {
    /// The monitor's recording: `run.mcap`, or for a restarted monitor the next `run.<n>.mcap`.
    pub fn open(setup: &SinkSetup) -> Result<Self> {
        let mut path = setup.run_dir.join(FILE);
        if setup.restarted {
            path = (1..)
                .map(|n| setup.run_dir.join(files::restarted_recording(n)))
                .find(|p| !p.exists())
                .expect("a free name");
        }
        let compression = if setup.spare_core { Compression::OnThread } else { Compression::Inline };
        Self::create_with(&path, setup.config, setup.layout, Detail::Live, compression)
    }

    /// A recording of a run of `config` into `path` (replaced if it exists).
    pub fn create(path: &Path, config: &LaunchConfig, layout: &VectorLayout, detail: Detail) -> Result<Self> {
        Self::create_with(path, config, layout, detail, Compression::Inline)
    }

    fn create_with(
        path: &Path,
        config: &LaunchConfig,
        layout: &VectorLayout,
        detail: Detail,
        compression: Compression,
    ) -> Result<Self> {
        // zstd's fastest level: it shrinks the file fivefold (pendulum, 1 kHz: 72 MB a minute to
        // 14 MB) for about 1.5 µs a loop.
        let mut file = McapFile::create(path, compression)?;
        let wall_clock = config.mode == Mode::Realtime;
        let metadata = BTreeMap::from([
            ("log_time".to_string(), if wall_clock { "wall_clock" } else { "simulation" }.to_string()),
            (FORMAT_VERSION_KEY.to_string(), FORMAT_VERSION.to_string()),
        ]);
        let schemas = schemas(layout, detail);
        let mut channel_ids = [0; Channel::ALL.len()];
        for (channel, schema) in Channel::ALL.iter().zip(&schemas) {
            let name = schema["title"].as_str().expect("every schema has a title");
            let schema_id =
                file.add_schema(name, "jsonschema", &serde_json::to_vec(schema).expect("a Value is JSON"))?;
            channel_ids[*channel as usize] = file.add_channel(schema_id, channel.topic(), "json", &metadata)?;
        }
        let (from_ticks, _): (Vec<u64>, Vec<_>) = config.faults.iter().map(|f| f.ticks(config.rate_hz)).unzip();
        Ok(Self {
            file: Some(file),
            channel_ids,
            sequences: [0; Channel::ALL.len()],
            keys: Keys::new(layout),
            detail,
            wall_clock,
            rate_hz: config.rate_hz,
            dt_ns: config.period_ns() as i64,
            faults: config.faults.clone(),
            fault_times: from_ticks.into_iter().map(|tick| (tick, None)).collect(),
            last_log_time: 0,
            buf: Vec::with_capacity(4096),
            loop_prefix: ((u64::MAX, 0), vec![]),
        })
    }

    /// Simulation time of tick k, ns.
    fn simulation_ns(&self, k: u64) -> u64 {
        (k as f64 * 1e9 / self.rate_hz).round() as u64
    }

    /// The log time of loop k (a message's header has its plant publish stamp).
    fn log_time(&self, k: u64, header: &Header) -> u64 {
        match (self.wall_clock, header.trace.plant_publish) {
            (false, _) => self.simulation_ns(k),
            (true, 0) => self.last_log_time,
            (true, stamp) => stamp,
        }
    }

    /// Starts a message of loop k: `{"k":K,"t":T` (written once per loop: every message has it).
    fn begin(&mut self, k: u64, t: f64) {
        let (written_for, prefix) = &mut self.loop_prefix;
        if *written_for != (k, t.to_bits()) {
            *written_for = (k, t.to_bits());
            prefix.clear();
            prefix.push(b'{');
            prefix.extend_from_slice(&key(field::K));
            push_int(prefix, k);
            comma_key(prefix, field::T);
            push_json_f64(prefix, t);
        }
        self.buf.clear();
        self.buf.extend_from_slice(prefix);
    }

    /// Marks the message in the buffer lost, when its header says so, and gives the incarnation
    /// of the process that sent it, after its first restart (a live recording only: the run
    /// folder's files keep neither). A replay finds where its stage restarted from these.
    fn lost(&mut self, header: &Header, sender: Role) {
        if self.detail != Detail::Live {
            return;
        }
        if header.lost != 0 {
            comma_key(&mut self.buf, field::LOST);
            boolean(&mut self.buf, true);
        }
        let incarnation = header.incarnations[sender.slot().expect("a loop process")];
        if incarnation != 0 {
            comma_key(&mut self.buf, field::INCARNATION);
            push_int(&mut self.buf, incarnation);
        }
    }

    /// `,"applied":{"u":1,…}`: the input the actuator applied (a live recording only: the files
    /// keep it once, in trajectory.csv's `applied.*`, which export puts nowhere).
    fn applied(&mut self, u_applied: &[f64]) {
        if self.detail == Detail::Live {
            comma_key(&mut self.buf, field::APPLIED);
            self.buf.push(b'{');
            fields(&mut self.buf, &self.keys.input, u_applied, false);
            self.buf.push(b'}');
        }
    }

    /// Ends the message in the buffer and writes it. Publish time: when the message's stage
    /// published it in real time; the log time in lockstep, where wall-clock stamps mean nothing.
    fn put(&mut self, channel: Channel, log_time: u64, published: u64) -> Result<()> {
        self.buf.push(b'}');
        let publish_time = if self.wall_clock && published != 0 { published } else { log_time };
        let i = channel as usize;
        let sequence = self.sequences[i];
        self.sequences[i] = sequence.wrapping_add(1);
        let file = self.file.as_mut().expect("no message after finish");
        file.write(self.channel_ids[i], sequence, log_time, publish_time, &self.buf)
    }

    /// One fault with what it did (None: the monitor has no record of it), at the time it happened.
    fn write_fault(&mut self, index: usize, spec: &FaultSpec, effect: Option<&FaultEffect>) -> Result<()> {
        let (tick, seen_at) = self.fault_times[index];
        let log_time = match (self.wall_clock, seen_at) {
            (false, _) => self.simulation_ns(tick),
            (true, Some(time)) => time,
            (true, None) => self.last_log_time,
        };
        let mut message = json!({
            "k": tick,
            "t": spec.at_s,
            "index": index,
            "fault": spec.describe(),
            "kind": spec.kind.name(),
            "process": spec.process,
            "duration_s": spec.duration_s,
        });
        if let (Some(effect), Value::Object(fields)) = (effect, &mut message) {
            let Value::Object(effect) = serde_json::to_value(effect)? else { unreachable!("a struct is an object") };
            fields.extend(effect);
        }
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, &message)?;
        self.buf.pop(); // `put` closes the object
        self.put(Channel::Faults, log_time, log_time)
    }

    /// Writes each fault of the launch file with its effect (`effects` in the same order), then
    /// the file's summary.
    pub fn finish_with(&mut self, effects: &[Option<FaultEffect>]) -> Result<()> {
        let faults = std::mem::take(&mut self.faults);
        for (i, spec) in faults.iter().enumerate() {
            self.write_fault(i, spec, effects.get(i).and_then(Option::as_ref))?;
        }
        match self.file.take() {
            Some(file) => file.finish(),
            None => Ok(()),
        }
    }
}

/// A number as JSON writes it (a non-finite float, which JSON cannot hold, as null).
trait JsonNumber: Copy {
    fn push_to(self, buf: &mut Vec<u8>);
}

impl JsonNumber for f64 {
    fn push_to(self, buf: &mut Vec<u8>) {
        push_json_f64(buf, self);
    }
}

macro_rules! json_integer {
    ($($t:ty),*) => {$(
        impl JsonNumber for $t {
            fn push_to(self, buf: &mut Vec<u8>) {
                push_int(buf, self);
            }
        }
    )*};
}
json_integer!(u32, u64, i64);

fn number(buf: &mut Vec<u8>, value: impl JsonNumber) {
    value.push_to(buf);
}

fn boolean(buf: &mut Vec<u8>, value: bool) {
    buf.extend_from_slice(if value { b"true" } else { b"false" });
}

/// `,"name":` for a field of the run format (plain ASCII names).
fn comma_key(buf: &mut Vec<u8>, name: &str) {
    buf.extend_from_slice(b",\"");
    buf.extend_from_slice(name.as_bytes());
    buf.extend_from_slice(b"\":");
}

/// `,"a":1,"b":2`, or without the first comma.
fn fields<T: JsonNumber>(buf: &mut Vec<u8>, keys: &[Vec<u8>], values: &[T], leading_comma: bool) {
    for (i, (key, value)) in keys.iter().zip(values).enumerate() {
        if leading_comma || i > 0 {
            buf.push(b',');
        }
        buf.extend_from_slice(key);
        number(buf, *value);
    }
}

impl RunSink for McapRecording {
    fn loop_joined(&mut self, joined: &JoinedLoop) -> Result<()> {
        let (k, t, parts) = (joined.k, joined.t, joined.parts);
        let any_header = [
            parts.state.map(|m| m.header),
            parts.measurements.map(|m| m.header),
            parts.estimate.map(|m| m.header),
            parts.command.map(|m| m.header),
            parts.record.map(|m| m.header),
        ];
        if let Some(header) = any_header.iter().flatten().next() {
            let log_time = self.log_time(k, header);
            for (tick, seen_at) in &mut self.fault_times {
                if k >= *tick && seen_at.is_none() {
                    *seen_at = Some(log_time);
                }
            }
            self.last_log_time = self.last_log_time.max(log_time);
        }
        if let Some(state) = &parts.state {
            self.begin(k, t);
            fields(&mut self.buf, &self.keys.state, &state.x, true);
            self.applied(&state.u_applied);
            self.lost(&state.header, Role::Plant);
            self.put(Channel::State, self.log_time(k, &state.header), state.header.trace.plant_publish)?;
        }
        if let Some(m) = &parts.measurements {
            self.begin(k, t);
            for ((prefix, components), reading) in self.keys.sensors.iter().zip(&m.readings) {
                self.buf.push(b',');
                self.buf.extend_from_slice(prefix);
                fields(&mut self.buf, components, &reading.value, false);
                self.buf.push(b'}');
                if self.detail == Detail::Live {
                    comma_key(&mut self.buf, field::SAMPLE_TIME);
                    number(&mut self.buf, reading.sample_time);
                    comma_key(&mut self.buf, field::SEQ);
                    number(&mut self.buf, reading.seq);
                    comma_key(&mut self.buf, field::FRESH);
                    boolean(&mut self.buf, reading.fresh != 0);
                    comma_key(&mut self.buf, field::VALID);
                    boolean(&mut self.buf, reading.valid != 0);
                }
                self.buf.push(b'}');
            }
            self.applied(&m.u_applied);
            self.lost(&m.header, Role::Sensors);
            self.put(Channel::Measurements, self.log_time(k, &m.header), m.header.trace.sensors_publish)?;
        }
        if let Some(estimate) = &parts.estimate {
            self.begin(k, t);
            fields(&mut self.buf, &self.keys.estimate, &estimate.x, true);
            self.lost(&estimate.header, Role::Estimator);
            self.put(Channel::Estimate, self.log_time(k, &estimate.header), estimate.header.trace.estimator_publish)?;
        }
        if let Some(command) = &parts.command {
            self.begin(k, t);
            fields(&mut self.buf, &self.keys.input, &command.u, true);
            self.lost(&command.header, Role::Controller);
            self.put(Channel::Command, self.log_time(k, &command.header), command.header.trace.controller_publish)?;
        }
        if let (Some(record), Some(end_to_end), Some(hops)) = (&parts.record, parts.end_to_end_ns(), parts.hops_ns()) {
            let log_time = self.log_time(k, &record.header);
            let arrived = record.header.trace.plant_receive;
            self.begin(k, t);
            comma_key(&mut self.buf, field::DEADLINE_MISS);
            boolean(&mut self.buf, record.deadline_miss != 0);
            comma_key(&mut self.buf, field::REJECTED);
            boolean(&mut self.buf, record.rejected != 0);
            if self.detail == Detail::Live {
                comma_key(&mut self.buf, field::LOST);
                boolean(&mut self.buf, record.lost != 0);
                comma_key(&mut self.buf, field::INCARNATIONS);
                self.buf.push(b'{');
                fields(&mut self.buf, &self.keys.incarnations, &record.header.incarnations, false);
                self.buf.push(b'}');
            }
            self.put(Channel::Loop, log_time, arrived)?;

            self.begin(k, t);
            self.buf.extend_from_slice(br#","end_to_end_ns":"#);
            number(&mut self.buf, end_to_end);
            fields(&mut self.buf, &self.keys.hops, &hops, true);
            if let Some(timing) = joined.tick_timing() {
                self.buf.extend_from_slice(br#","wake_latency_ns":"#);
                number(&mut self.buf, timing.wake_ns as i64 - timing.scheduled_ns as i64);
                if timing.period_ns > 0 {
                    self.buf.extend_from_slice(br#","tick_period_error_ns":"#);
                    number(&mut self.buf, timing.period_ns as i64 - self.dt_ns);
                }
            }
            self.put(Channel::Latency, log_time, arrived)?;
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        match &mut self.file {
            // Ends the chunk, so that a killed monitor's file is readable up to here.
            Some(file) => file.flush(),
            None => Ok(()),
        }
    }

    fn end(&self) -> Result<FileEnd> {
        match &self.file {
            Some(file) => file.end(),
            None => Err(anyhow::anyhow!("the recording is finished")),
        }
    }

    fn finish(&mut self, report: &MonitorReport) -> Result<()> {
        let effects: Vec<Option<FaultEffect>> = report.faults.iter().cloned().map(Some).collect();
        self.finish_with(&effects)
    }
}

#[cfg(test)]
#[path = "recording_reader_tests.rs"]
mod recording_reader_tests;
