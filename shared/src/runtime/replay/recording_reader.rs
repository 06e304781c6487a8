//! A recorded run read back: every message of every loop as the monitor received it, from the
//! run folder's `run.mcap` (and a restarted monitor's `run.<n>.mcap`). What `looplab replay`
//! plays back into a stage.
//!
//! The recording keeps every field a stage reads (`monitor::sinks::mcap`, `Detail::Live`): the
//! state and the input applied, each sensor's value, sample time, sequence number and fresh and
//! valid flags, the estimate, the command, each message's `lost` flag and each loop's
//! incarnations. Floats are written shortest-round-trip and read back bit for bit (a
//! non-finite value, which JSON cannot hold, comes back as NaN). Timing (the loop trace, the
//! plant's tick timing and counters) is not played back: a replay stamps its own.

use std::path::Path;

use anyhow::{Context as _, Result, anyhow, bail};
use serde_json::{Map, Value};

use crate::config::schema::Component;
use crate::contract::msg::{Command, Estimate, Header, LoopRecord, Measurements, PlantState};
use crate::contract::role::Role;
use crate::contract::role::Topic;
use crate::contract::run_format::{FORMAT_VERSION, FORMAT_VERSION_KEY, channel, field, files};
use crate::model::layout::VectorLayout;

const FILE: &str = files::RECORDING;

/// One loop of a recording: each message the monitor received for it (None: none came).
/// Headers hold k, t, `lost` and the incarnations; the loop trace is zero.
#[derive(Debug, Clone, Copy, Default)]
pub struct RecordedLoop {
    pub state: Option<PlantState>,
    pub measurements: Option<Measurements>,
    pub estimate: Option<Estimate>,
    pub command: Option<Command>,
    pub record: Option<LoopRecord>,
}

/// Every loop of the run recorded in `run_dir` by its monitor(s), indexed by k, up to its last
/// recorded loop and at most `loops` (the run's planned loops; a loop nobody recorded is all
/// None). `layout` is the recording's
/// (from its own launch file). Fails with one line naming the file when the folder has no
/// `run.mcap`, when it was written by `looplab export` (no sample times or flags), or by a
/// version of LoopLab that did not record a field a stage reads.
pub fn load(run_dir: &Path, layout: &VectorLayout, loops: u64) -> Result<Vec<RecordedLoop>> {
    let first = run_dir.join(FILE);
    if std::fs::symlink_metadata(&first).is_err() {
        bail!("{} has no {FILE}; replay needs the recording a run writes", run_dir.display());
    }
    let loops = usize::try_from(loops).context("more loops than this machine can index")?;
    // Sized by what the files hold, up to the planned loops: a launch file's duration (up to a
    // week) is no measure of a recording that ended early.
    let mut recorded = Vec::new();
    let restarted = (1..).map(|n| run_dir.join(files::restarted_recording(n))).take_while(|p| p.exists());
    for path in std::iter::once(first).chain(restarted) {
        read_file(&path, layout, &mut recorded, loops)?;
    }
    fill_incarnations(&mut recorded);
    Ok(recorded)
}

/// The topic of a channel of the recording (`/state` …); None for the others (`/latency`,
/// `/faults`).
fn topic_of(name: &str) -> Option<Topic> {
    Topic::ALL.into_iter().find(|t| channel::of(*t) == name)
}

/// Adds one recording file's messages to `recorded`, where no earlier file (or message) has one
/// for that topic and loop.
fn read_file(path: &Path, layout: &VectorLayout, recorded: &mut Vec<RecordedLoop>, loops: usize) -> Result<()> {
    let bytes = crate::runtime::storage::run_file::read(path)?;
    refuse_export(path, &bytes)?;
    check_names(path, layout)?;
    // A file with its end magic was finished: it cannot end in the middle of a record.
    let finished = bytes.len() > 2 * mcap::MAGIC.len() && bytes.ends_with(mcap::MAGIC);
    check_chunks(path, &bytes, finished)?;
    let options = mcap::read::Options::IgnoreEndMagic | mcap::read::Options::ValidateChunkCrcs;
    let stream = mcap::MessageStream::new_with_options(&bytes, options)
        .map_err(|e| anyhow!("{}: not an MCAP recording ({e})", path.display()))?;
    let mut version_checked = false;
    for message in stream {
        let message = match message {
            Ok(message) => message,
            // A killed monitor's file ends where it last flushed: what came before is whole.
            Err(mcap::McapError::UnexpectedEof | mcap::McapError::UnexpectedEoc) if !finished => break,
            Err(mcap::McapError::UnexpectedEof | mcap::McapError::UnexpectedEoc) => {
                bail!("{}: corrupt: a record runs past the end of the file", path.display())
            }
            Err(e @ mcap::McapError::BadMagic) => bail!("{}: not an MCAP recording ({e})", path.display()),
            Err(e) => bail!("{}: unreadable ({e})", path.display()),
        };
        if !version_checked {
            check_version(path, message.channel.metadata.get(FORMAT_VERSION_KEY))?;
            version_checked = true;
        }
        let Some(topic) = topic_of(&message.channel.topic) else { continue };
        let json: Value = serde_json::from_slice(&message.data)
            .map_err(|e| anyhow!("{}: a {} message is not JSON ({e})", path.display(), message.channel.topic))?;
        let Value::Object(fields) = &json else {
            bail!("{}: a {} message is not a JSON object", path.display(), message.channel.topic);
        };
        let mut at = At { path, topic: &message.channel.topic, k: None };
        let k = at.unsigned(fields, field::K)?;
        at.k = Some(k);
        let Some(k_index) = usize::try_from(k).ok().filter(|&k| k < loops) else { continue };
        if recorded.len() <= k_index {
            recorded.resize(k_index + 1, RecordedLoop::default());
        }
        let slot = &mut recorded[k_index];
        let t = at.float(fields, field::T)?;
        let mut header = Header { k, t, lost: at.lost(fields)?, ..Header::default() };
        if let Some(sender) = topic.writer().slot() {
            header.incarnations[sender] = at.incarnation(fields)?;
        }
        match topic {
            Topic::State if slot.state.is_none() => slot.state = Some(at.state(fields, header, layout)?),
            Topic::Measurements if slot.measurements.is_none() => {
                slot.measurements = Some(at.measurements(fields, header, layout)?)
            }
            Topic::Estimate if slot.estimate.is_none() => {
                let mut estimate = Estimate { header, ..Estimate::default() };
                at.floats(fields, &layout.estimate, &mut estimate.x)?;
                slot.estimate = Some(estimate);
            }
            Topic::Command if slot.command.is_none() => {
                let mut command = Command { header, ..Command::default() };
                at.floats(fields, &layout.input, &mut command.u)?;
                slot.command = Some(command);
            }
            Topic::Loop if slot.record.is_none() => slot.record = Some(at.record(fields, header)?),
            _ => {}
        }
    }
    Ok(())
}

/// The most a chunk may hold uncompressed: the monitor's are well under a MiB.
const MAX_CHUNK_BYTES: u64 = 1 << 30;

/// Checks each whole chunk before its messages are read: it decompresses to the size it states
/// and matches its CRC, so that a changed byte is refused as such, not read as other numbers (and
/// blamed on the stage) or handed to a decoder that trusts it. In a finished file every record
/// is whole; a killed monitor's file ends where it last wrote, and the check ends there too.
fn check_chunks(path: &Path, bytes: &[u8], finished: bool) -> Result<()> {
    let corrupt = |why: String| anyhow!("{}: corrupt: {why}", path.display());
    let records = mcap::read::LinearReader::new_with_options(bytes, mcap::read::Options::IgnoreEndMagic.into())
        .map_err(|e| anyhow!("{}: not an MCAP recording ({e})", path.display()))?;
    for record in records {
        let (header, data) = match record {
            Ok(mcap::records::Record::Chunk { header, data }) => (header, data),
            Ok(_) => continue,
            Err(_) if !finished => return Ok(()),
            Err(mcap::McapError::UnexpectedEof | mcap::McapError::UnexpectedEoc) => {
                return Err(corrupt("a record runs past the end of the file".into()));
            }
            Err(e) => return Err(corrupt(e.to_string())),
        };
        if header.uncompressed_size > MAX_CHUNK_BYTES {
            return Err(corrupt(format!("a chunk says it holds {} bytes", header.uncompressed_size)));
        }
        let records = match header.compression.as_str() {
            "zstd" => zstd::bulk::decompress(&data, header.uncompressed_size as usize)
                .map_err(|e| corrupt(format!("a chunk does not decompress ({e})")))?,
            "" => data.into_owned(),
            other => bail!("{}: its chunks are compressed with {other:?}; LoopLab reads zstd", path.display()),
        };
        if records.len() as u64 != header.uncompressed_size
            || (header.uncompressed_crc != 0 && crc32fast::hash(&records) != header.uncompressed_crc)
        {
            return Err(corrupt("a chunk fails its CRC (the file changed after it was written)".into()));
        }
    }
    Ok(())
}

/// A recording of this run format's version: one written before the version was recorded is
/// of the first.
fn check_version(path: &Path, version: Option<&String>) -> Result<()> {
    match version.map(String::as_str) {
        None => Ok(()),
        Some(v) if v == FORMAT_VERSION.to_string() => Ok(()),
        Some(v) => bail!(
            "{}: run format version {v}; this LoopLab reads version {FORMAT_VERSION}: replay it with the LoopLab that \
             recorded it",
            path.display()
        ),
    }
}

/// `looplab export` writes its recording through the same sink from the run folder's files,
/// which keep no sensor sample times, flags or incarnations (its schemas leave them out). Its
/// file is always finished, so its summary names the channels.
fn refuse_export(path: &Path, bytes: &[u8]) -> Result<()> {
    let Ok(Some(summary)) = mcap::Summary::read(bytes) else { return Ok(()) };
    let loop_schema = summary.channels.values().find(|c| c.topic == channel::LOOP).and_then(|c| c.schema.as_ref());
    let Some(schema) = loop_schema.and_then(|s| serde_json::from_slice::<Value>(&s.data).ok()) else { return Ok(()) };
    if schema["properties"].get(field::INCARNATIONS).is_none() {
        bail!(
            "{}: written by `looplab export`, which keeps no sample times or flags: record the run again",
            path.display()
        );
    }
    Ok(())
}

/// A component named like a field of the message itself would be read as that field.
fn check_names(path: &Path, layout: &VectorLayout) -> Result<()> {
    let vectors = [
        ("state", &layout.state, &[field::APPLIED][..]),
        ("estimate", &layout.estimate, &[]),
        ("input", &layout.input, &[]),
    ];
    let sensors = layout.sensors.iter().map(|(name, _)| ("sensor", name.as_str(), &[field::APPLIED][..]));
    let components =
        vectors.iter().flat_map(|(what, components, also)| components.iter().map(move |c| (*what, c.name, *also)));
    for (what, name, also) in components.chain(sensors) {
        if [field::K, field::T, field::LOST, field::INCARNATION].contains(&name) || also.contains(&name) {
            bail!(
                "{}: the {what} {name:?} has the name of a field every message has; replay cannot tell them apart",
                path.display()
            );
        }
    }
    Ok(())
}

/// Where a value is read from, for the one line an error is.
struct At<'a> {
    path: &'a Path,
    topic: &'a str,
    k: Option<u64>,
}

impl At<'_> {
    fn place(&self) -> String {
        match self.k {
            Some(k) => format!("{}: {} of loop {k}", self.path.display(), self.topic),
            None => format!("{}: a {} message", self.path.display(), self.topic),
        }
    }

    fn get<'v>(&self, fields: &'v Map<String, Value>, key: &str) -> Result<&'v Value> {
        fields.get(key).ok_or_else(|| {
            anyhow!(
                "{} has no \"{key}\": recorded by an older LoopLab, which left out fields a stage reads; record it \
                 again with this version",
                self.place()
            )
        })
    }

    fn bad(&self, key: &str, what: &str) -> anyhow::Error {
        anyhow!("{}: \"{key}\" is not {what}", self.place())
    }

    /// A float; null (what the writer makes of a non-finite value) is NaN.
    fn float(&self, fields: &Map<String, Value>, key: &str) -> Result<f64> {
        match self.get(fields, key)? {
            Value::Null => Ok(f64::NAN),
            // With serde_json's float_roundtrip the number is the one written, bit for bit.
            Value::Number(n) => n.as_f64().ok_or_else(|| self.bad(key, "a number")),
            _ => Err(self.bad(key, "a number")),
        }
    }

    fn unsigned(&self, fields: &Map<String, Value>, key: &str) -> Result<u64> {
        self.get(fields, key)?.as_u64().ok_or_else(|| self.bad(key, "a whole number"))
    }

    fn flag(&self, fields: &Map<String, Value>, key: &str) -> Result<u32> {
        self.get(fields, key)?.as_bool().map(u32::from).ok_or_else(|| self.bad(key, "true or false"))
    }

    fn object<'v>(&self, fields: &'v Map<String, Value>, key: &str) -> Result<&'v Map<String, Value>> {
        self.get(fields, key)?.as_object().ok_or_else(|| self.bad(key, "an object"))
    }

    /// `"incarnation"` is written only after the sender's first restart.
    fn incarnation(&self, fields: &Map<String, Value>) -> Result<u32> {
        match fields.get(field::INCARNATION) {
            None => Ok(0),
            Some(_) => u32::try_from(self.unsigned(fields, field::INCARNATION)?)
                .map_err(|_| self.bad(field::INCARNATION, "an incarnation")),
        }
    }

    /// `"lost":true` is written only on a lost message.
    fn lost(&self, fields: &Map<String, Value>) -> Result<u32> {
        match fields.get(field::LOST) {
            None => Ok(0),
            Some(_) => self.flag(fields, field::LOST),
        }
    }

    /// The components of a vector into the front of `out`.
    fn floats(&self, fields: &Map<String, Value>, components: &[Component], out: &mut [f64]) -> Result<()> {
        for (component, value) in components.iter().zip(out.iter_mut()) {
            *value = self.float(fields, component.name)?;
        }
        Ok(())
    }

    fn state(&self, fields: &Map<String, Value>, header: Header, layout: &VectorLayout) -> Result<PlantState> {
        let mut state = PlantState { header, ..PlantState::default() };
        self.floats(fields, &layout.state, &mut state.x)?;
        self.floats(self.object(fields, field::APPLIED)?, &layout.input, &mut state.u_applied)?;
        Ok(state)
    }

    fn measurements(&self, fields: &Map<String, Value>, header: Header, layout: &VectorLayout) -> Result<Measurements> {
        let mut m = Measurements { header, ..Measurements::default() };
        for ((name, components), reading) in layout.sensors.iter().zip(m.readings.iter_mut()) {
            let sensor = self.object(fields, name)?;
            self.floats(self.object(sensor, field::VALUE)?, components, &mut reading.value)?;
            reading.sample_time = self.float(sensor, field::SAMPLE_TIME)?;
            reading.seq = self.unsigned(sensor, field::SEQ)?;
            reading.fresh = self.flag(sensor, field::FRESH)?;
            reading.valid = self.flag(sensor, field::VALID)?;
        }
        self.floats(self.object(fields, field::APPLIED)?, &layout.input, &mut m.u_applied)?;
        Ok(m)
    }

    /// The loop record: its flags and the incarnations that handled the loop (its header's,
    /// the command's); its `lost` is the command's.
    fn record(&self, fields: &Map<String, Value>, mut header: Header) -> Result<LoopRecord> {
        let lost = self.flag(fields, field::LOST)?;
        header.lost = lost;
        let incarnations = self.object(fields, field::INCARNATIONS)?;
        for role in Role::LOOP {
            let value = self.unsigned(incarnations, role.name())?;
            let slot = role.slot().expect("a loop process has a slot");
            header.incarnations[slot] = u32::try_from(value).map_err(|_| self.bad(role.name(), "an incarnation"))?;
        }
        Ok(LoopRecord {
            header,
            deadline_miss: self.flag(fields, field::DEADLINE_MISS)?,
            rejected: self.flag(fields, field::REJECTED)?,
            lost,
            ..LoopRecord::default()
        })
    }
}

/// Each message's incarnations: its sender's, from the message itself; those of the processes
/// before it, from its loop's record (or the nearest earlier loop's, when none came): the
/// measurements the plant's, the estimate the plant's and the sensors', the command the first
/// three.
fn fill_incarnations(recorded: &mut [RecordedLoop]) {
    let mut incarnations = [0; 4];
    for recorded in recorded {
        if let Some(record) = &recorded.record {
            incarnations = record.header.incarnations;
        }
        let passed = |header: &mut Header, processes: usize| {
            header.incarnations[..processes - 1].copy_from_slice(&incarnations[..processes - 1]);
        };
        if let Some(m) = &mut recorded.state {
            passed(&mut m.header, 1);
        }
        if let Some(m) = &mut recorded.measurements {
            passed(&mut m.header, 2);
        }
        if let Some(m) = &mut recorded.estimate {
            passed(&mut m.header, 3);
        }
        if let Some(m) = &mut recorded.command {
            passed(&mut m.header, 4);
        }
    }
}
