//! `run.mcap`: the run as an MCAP recording that Foxglove and PlotJuggler open, one channel per
//! topic of the loop plus the per-loop latency and the faults. Messages are JSON with a JSON
//! Schema made from the scenario's vectors, so that a viewer plots each field by its name.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write as _};
use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result};
use mcap::records::MessageHeader;
use serde_json::{Value, json};

use crate::config::faults::FaultSpec;
use crate::config::launch::{LaunchConfig, Mode};
use crate::config::schema::Component;
use crate::contract::msg::Header;
use crate::contract::report::{FaultEffect, HOPS, MonitorReport};
use crate::contract::role::Role;
use crate::model::layout::Layout;
use crate::monitor::sinks::{JoinedLoop, RunSink, SinkSetup};

/// The first monitor's recording. An MCAP file cannot be appended to, so a restarted monitor
/// writes the next free `run.<n>.mcap` (n = 1, 2, …: its incarnation).
pub const FILE: &str = "run.mcap";

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
            Channel::State => "/state",
            Channel::Measurements => "/measurements",
            Channel::Estimate => "/estimate",
            Channel::Command => "/command",
            Channel::Loop => "/loop",
            Channel::Latency => "/latency",
            Channel::Faults => "/faults",
        }
    }
}

/// What the recording knows of each loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Detail {
    /// Everything the monitor received: every field a stage reads, which `looplab replay` plays
    /// back (`runtime::recorded`).
    Live,
    /// What a run folder's files keep (`looplab export`): no sensor sample times, sequence
    /// numbers or fresh and valid flags, no applied input in the messages, no lost flags or
    /// incarnations; `runtime::recorded` refuses it.
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
    fn new(layout: &Layout) -> Self {
        let keys = |components: &[Component]| components.iter().map(|c| key(c.name)).collect();
        Self {
            state: keys(&layout.state),
            sensors: layout
                .sensors
                .iter()
                .map(|(name, components)| {
                    let mut prefix = key(name);
                    prefix.extend_from_slice(br#"{"value":{"#);
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
    writer: Option<mcap::Writer<BufWriter<File>>>,
    path: PathBuf,
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
}

impl McapRecording {
    /// The monitor's recording: `run.mcap`, or for a restarted monitor the next `run.<n>.mcap`.
    pub fn open(setup: &SinkSetup) -> Result<Self> {
        let mut path = setup.run_dir.join(FILE);
        if setup.restarted {
            path =
                (1..).map(|n| setup.run_dir.join(format!("run.{n}.mcap"))).find(|p| !p.exists()).expect("a free name");
        }
        Self::create(&path, setup.config, setup.layout, Detail::Live)
    }

    /// A recording of a run of `config` into `path` (replaced if it exists).
    pub fn create(path: &Path, config: &LaunchConfig, layout: &Layout, detail: Detail) -> Result<Self> {
        let file = crate::runtime::run_file::open(path, crate::runtime::run_file::Existing::Replace)?;
        // zstd's fastest level, in this thread: it shrinks the file fivefold (pendulum, 1 kHz: 72 MB
        // a minute to 14 MB) for about 3 µs a loop, and no compression threads compete with the
        // loop's processes.
        let options = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .compression_level(1)
            .compression_threads(0);
        let mut writer =
            options.create(BufWriter::new(file)).with_context(|| format!("write to {}", path.display()))?;
        let wall_clock = config.mode == Mode::Realtime;
        let metadata = BTreeMap::from([(
            "log_time".to_string(),
            if wall_clock { "wall_clock" } else { "simulation" }.to_string(),
        )]);
        let schemas = schemas(layout, detail);
        let mut channel_ids = [0; Channel::ALL.len()];
        for (channel, schema) in Channel::ALL.iter().zip(&schemas) {
            let add = |writer: &mut mcap::Writer<_>| -> mcap::McapResult<u16> {
                let name = schema["title"].as_str().expect("every schema has a title");
                let schema_id =
                    writer.add_schema(name, "jsonschema", &serde_json::to_vec(schema).expect("a Value is JSON"))?;
                writer.add_channel(schema_id, channel.topic(), "json", &metadata)
            };
            channel_ids[*channel as usize] =
                add(&mut writer).with_context(|| format!("write to {}", path.display()))?;
        }
        let (from_ticks, _): (Vec<u64>, Vec<_>) = config.faults.iter().map(|f| f.ticks(config.rate_hz)).unzip();
        Ok(Self {
            writer: Some(writer),
            path: path.to_path_buf(),
            channel_ids,
            sequences: [0; Channel::ALL.len()],
            keys: Keys::new(layout),
            detail,
            wall_clock,
            rate_hz: config.rate_hz,
            dt_ns: (1e9 / config.rate_hz).round() as i64,
            faults: config.faults.clone(),
            fault_times: from_ticks.into_iter().map(|tick| (tick, None)).collect(),
            last_log_time: 0,
            buf: Vec::with_capacity(4096),
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

    /// Starts a message of loop k: `{"k":K,"t":T`.
    fn begin(&mut self, k: u64, t: f64) {
        self.buf.clear();
        self.buf.extend_from_slice(br#"{"k":"#);
        number(&mut self.buf, k);
        self.buf.extend_from_slice(br#","t":"#);
        number(&mut self.buf, t);
    }

    /// Marks the message in the buffer lost, when its header says so, and gives the incarnation
    /// of the process that sent it, after its first restart (a live recording only: the run
    /// folder's files keep neither). A replay finds where its stage restarted from these.
    fn lost(&mut self, header: &Header, sender: Role) {
        if self.detail != Detail::Live {
            return;
        }
        if header.lost != 0 {
            self.buf.extend_from_slice(br#","lost":true"#);
        }
        let incarnation = header.incarnations[sender.slot().expect("a loop process")];
        if incarnation != 0 {
            self.buf.extend_from_slice(br#","incarnation":"#);
            number(&mut self.buf, incarnation);
        }
    }

    /// `,"applied":{"u":1,…}`: the input the actuator applied (a live recording only: the files
    /// keep it once, in trajectory.csv's `applied.*`, which export puts nowhere).
    fn applied(&mut self, u_applied: &[f64]) {
        if self.detail == Detail::Live {
            self.buf.extend_from_slice(br#","applied":{"#);
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
        let header =
            MessageHeader { channel_id: self.channel_ids[i], sequence: self.sequences[i], log_time, publish_time };
        self.sequences[i] = self.sequences[i].wrapping_add(1);
        let writer = self.writer.as_mut().expect("no message after finish");
        writer.write_to_known_channel(&header, &self.buf).with_context(|| format!("write to {}", self.path.display()))
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
        let Some(mut writer) = self.writer.take() else { return Ok(()) };
        let context = || format!("write to {}", self.path.display());
        writer.finish().with_context(context)?;
        writer.into_inner().flush().with_context(context)
    }
}

/// Writes a number as JSON (a non-finite float, which JSON cannot hold, as null).
fn number(buf: &mut Vec<u8>, value: impl serde::Serialize) {
    serde_json::to_writer(buf, &value).expect("a number is JSON");
}

fn boolean(buf: &mut Vec<u8>, value: bool) {
    buf.extend_from_slice(if value { b"true" } else { b"false" });
}

/// `,"a":1,"b":2`, or without the first comma.
fn fields<T: serde::Serialize + Copy>(buf: &mut Vec<u8>, keys: &[Vec<u8>], values: &[T], leading_comma: bool) {
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
                    self.buf.extend_from_slice(br#","sample_time":"#);
                    number(&mut self.buf, reading.sample_time);
                    self.buf.extend_from_slice(br#","seq":"#);
                    number(&mut self.buf, reading.seq);
                    self.buf.extend_from_slice(br#","fresh":"#);
                    boolean(&mut self.buf, reading.fresh != 0);
                    self.buf.extend_from_slice(br#","valid":"#);
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
            self.buf.extend_from_slice(br#","deadline_miss":"#);
            boolean(&mut self.buf, record.deadline_miss != 0);
            self.buf.extend_from_slice(br#","rejected":"#);
            boolean(&mut self.buf, record.rejected != 0);
            if self.detail == Detail::Live {
                self.buf.extend_from_slice(br#","lost":"#);
                boolean(&mut self.buf, record.lost != 0);
                self.buf.extend_from_slice(br#","incarnations":{"#);
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
        match &mut self.writer {
            // Ends the chunk, so that a killed monitor's file is readable up to here.
            Some(writer) => writer.flush().with_context(|| format!("write to {}", self.path.display())),
            None => Ok(()),
        }
    }

    fn finish(&mut self, report: &MonitorReport) -> Result<()> {
        let effects: Vec<Option<FaultEffect>> = report.faults.iter().cloned().map(Some).collect();
        self.finish_with(&effects)
    }
}

/// The JSON Schemas of the channels, in [`Channel::ALL`]'s order. Every float may be null: a
/// non-finite value (a corrupted command's NaN), which JSON cannot hold.
fn schemas(layout: &Layout, detail: Detail) -> Vec<Value> {
    let float = || json!({"type": ["number", "null"]});
    // A component's field keeps its name (a viewer plots by name) and gives its unit here.
    let component = |c: &Component| {
        let mut field = float();
        if !matches!(c.unit, "1" | "") {
            field["description"] = c.unit.into();
        }
        (c.name.to_string(), field)
    };
    let integer = |description: &str| json!({"type": "integer", "description": description});
    let boolean = |description: &str| json!({"type": "boolean", "description": description});
    let object = |title: &str, properties: Vec<(String, Value)>| {
        let required: Vec<&String> = properties.iter().map(|(name, _)| name).collect();
        json!({
            "title": title,
            "type": "object",
            "required": required,
            "properties": properties.iter().cloned().collect::<serde_json::Map<_, _>>(),
        })
    };
    let loop_fields = || {
        vec![
            ("k".to_string(), integer("loop index: the plant tick the data derives from")),
            ("t".to_string(), json!({"type": "number", "description": "simulation time of tick k, s"})),
        ]
    };
    let vector = |title: &str, components: &[Component]| {
        let mut properties = loop_fields();
        properties.extend(components.iter().map(component));
        object(title, properties)
    };
    let live = detail == Detail::Live;
    let applied = || {
        let description = "the input the actuator applied over the last interval";
        let mut applied = object("looplab.Applied", layout.input.iter().map(component).collect());
        applied["description"] = description.into();
        ("applied".to_string(), applied)
    };
    // Only on a message whose header says an upstream stage dropped the loop's output.
    let lost = boolean("an upstream stage dropped this loop's output (lockstep drop fault); absent: not lost");
    // Only after the sending process's first restart.
    let incarnation = integer("the incarnation of the process that sent it; absent: 0");
    let with_lost = |mut schema: Value| {
        if live {
            schema["properties"]["lost"] = lost.clone();
            schema["properties"]["incarnation"] = incarnation.clone();
        }
        schema
    };

    let mut measurements = loop_fields();
    for (name, components) in &layout.sensors {
        let mut sensor =
            vec![("value".to_string(), object(&format!("{name} value"), components.iter().map(component).collect()))];
        if live {
            sensor.extend([
                ("sample_time".into(), json!({"type": "number", "description": "when the truth behind the value was sampled (simulation time), s"})),
                ("seq".into(), integer("samples this sensor delivered before this one")),
                ("fresh".into(), boolean("delivered at this tick (else held)")),
                ("valid".into(), boolean("the sensor's first sample has arrived")),
            ]);
        }
        measurements.push((name.clone(), object(&format!("looplab.Reading.{name}"), sensor)));
    }
    if live {
        measurements.push(applied());
    }
    let mut state = loop_fields();
    state.extend(layout.state.iter().map(component));
    if live {
        state.push(applied());
    }

    let ns = |description: &str| json!({"type": "integer", "description": format!("{description}, ns")});
    let mut record = loop_fields();
    record.push(("deadline_miss".into(), boolean("the command reached the plant after tick k+1 was due")));
    record.push(("rejected".into(), boolean("the plant rejected the command (non-finite or out of range)")));
    if live {
        record.push(("lost".into(), boolean("the command arrived marked lost (lockstep drop fault)")));
        let incarnations = HEADER_ROLES.iter().map(|r| (r.name().to_string(), integer("0 before the first restart")));
        record.push(("incarnations".into(), object("looplab.Incarnations", incarnations.collect())));
    }

    let mut latency = loop_fields();
    latency.push(("end_to_end_ns".into(), ns("plant publish of loop k to command k reaching the plant")));
    latency.extend(HOPS.iter().map(|(name, _, _)| (format!("{name}_ns"), ns(name))));
    let mut latency = object("looplab.Latency", latency);
    // Real time only.
    latency["properties"]["wake_latency_ns"] = ns("plant wake-up minus the tick's scheduled time");
    latency["properties"]["tick_period_error_ns"] = ns("time since the previous wake-up minus the period");

    let mut faults = vec![
        ("k".to_string(), integer("the tick of the injection")),
        ("t".to_string(), json!({"type": "number", "description": "simulation time of the injection, s"})),
        ("index".to_string(), integer("the fault's place in the launch file's [[faults]]")),
        ("fault".to_string(), json!({"type": "string", "description": "in the --fault form"})),
        ("kind".to_string(), json!({"type": "string"})),
        ("process".to_string(), json!({"type": "string"})),
        ("duration_s".to_string(), float()),
    ];
    let mut faults_schema = object("looplab.Fault", std::mem::take(&mut faults));
    // What the fault did (absent when the monitor has no record of it): FaultEffect's fields.
    let effect = serde_json::to_value(FaultEffect::default()).expect("a struct is JSON");
    for (name, value) in effect.as_object().expect("a struct is an object") {
        faults_schema["properties"][name] = match value {
            Value::Bool(_) => json!({"type": "boolean"}),
            Value::Number(_) => json!({"type": "integer"}),
            _ => float(),
        };
    }

    vec![
        with_lost(object("looplab.State", state)),
        with_lost(object("looplab.Measurements", measurements)),
        with_lost(vector("looplab.Estimate", &layout.estimate)),
        with_lost(vector("looplab.Command", &layout.input)),
        object("looplab.Loop", record),
        latency,
        faults_schema,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout() -> Layout {
        Layout::example()
    }

    #[test]
    fn schemas_name_every_component_of_the_layout() {
        let schemas = schemas(&layout(), Detail::Live);
        let titles: Vec<&str> = schemas.iter().map(|s| s["title"].as_str().unwrap()).collect();
        assert_eq!(
            titles,
            [
                "looplab.State",
                "looplab.Measurements",
                "looplab.Estimate",
                "looplab.Command",
                "looplab.Loop",
                "looplab.Latency",
                "looplab.Fault"
            ]
        );
        let float = json!({"type": ["number", "null"]});
        assert_eq!(schemas[0]["required"], json!(["k", "t", "theta", "omega", "applied"]));
        assert_eq!(schemas[0]["properties"]["applied"]["required"], json!(["u"]));
        assert_eq!(schemas[0]["properties"]["applied"]["properties"]["u"]["description"], "N·m");
        assert_eq!(schemas[0]["properties"]["omega"], json!({"type": ["number", "null"], "description": "rad/s"}));
        assert_eq!(schemas[0]["properties"]["k"]["type"], "integer");
        let imu = &schemas[1]["properties"]["imu"];
        assert_eq!(imu["required"], json!(["value", "sample_time", "seq", "fresh", "valid"]));
        assert_eq!(imu["properties"]["seq"]["type"], "integer");
        assert_eq!(imu["properties"]["valid"]["type"], "boolean");
        assert_eq!(imu["properties"]["value"]["required"], json!(["x", "y"]));
        assert_eq!(imu["properties"]["value"]["properties"]["x"]["description"], "m/s²");
        // A pure number has no unit to give.
        assert_eq!(imu["properties"]["value"]["properties"]["y"], float);
        assert_eq!(imu["properties"]["fresh"]["type"], "boolean");
        assert_eq!(schemas[1]["required"], json!(["k", "t", "encoder", "imu", "applied"]));
        assert_eq!(schemas[3]["required"], json!(["k", "t", "u"]));
        // `lost` is written only on a lost message.
        for schema in &schemas[..4] {
            assert_eq!(schema["properties"]["lost"]["type"], "boolean", "{}", schema["title"]);
            assert!(!schema["required"].as_array().unwrap().contains(&json!("lost")), "{}", schema["title"]);
        }
        let latency = &schemas[5];
        assert_eq!(latency["required"].as_array().unwrap().len(), 2 + 1 + HOPS.len());
        assert_eq!(latency["properties"]["plant_to_sensors_ns"]["type"], "integer");
        assert_eq!(schemas[6]["properties"]["within_limits"]["type"], "boolean");
        assert_eq!(schemas[6]["properties"]["recovery_s"], float);

        // A run folder's files keep no sample times, flags or incarnations, and export keeps the
        // applied input nowhere.
        let files = super::schemas(&layout(), Detail::Files);
        assert_eq!(files[0]["required"], json!(["k", "t", "theta", "omega"]));
        assert_eq!(files[1]["required"], json!(["k", "t", "encoder", "imu"]));
        assert_eq!(files[1]["properties"]["imu"]["required"], json!(["value"]));
        assert!(files[..4].iter().all(|schema| schema["properties"].get("lost").is_none()));
        assert_eq!(files[4]["required"], json!(["k", "t", "deadline_miss", "rejected"]));
    }

    #[test]
    fn no_built_in_vector_or_sensor_has_the_name_of_a_message_field() {
        // They would collide with the loop's `k`, `t` and `lost` in every message, and with
        // `applied` in /state and /measurements (whose sensors are fields too).
        for entry in crate::scenarios::ALL {
            let (config, scenario) = crate::scenarios::resolve(entry.name, &[]).unwrap();
            let layout = Layout::new(&config, scenario.as_ref());
            let components = layout.state.iter().chain(&layout.estimate).chain(&layout.input).map(|c| c.name);
            for name in components.chain(layout.sensors.iter().map(|(name, _)| name.as_str())) {
                assert!(!["k", "t", "lost", "applied"].contains(&name), "{}: a field is named {name}", entry.name);
            }
        }
    }
}

#[cfg(test)]
#[path = "recorded_tests.rs"]
mod recorded_tests;
