//! `runtime::replay::recording_reader::load` against what this sink writes: every field a stage reads comes
//! back bit for bit. Here, a layer above the reader, because the tests write with the monitor's
//! own sink (tests/recorded.rs reads back real runs).

use std::path::Path;

use crate::config::launch::{LaunchConfig, Mode};
use crate::contract::msg::{Command, Estimate, Header, LoopRecord, Measurements, PlantState, SensorReading};
use crate::model::layout::VectorLayout;
use crate::monitor::join::LoopParts;
use crate::monitor::sinks::mcap::{Detail, McapRecording};
use crate::monitor::sinks::{JoinedLoop, RunSink};
use crate::runtime::replay::recording_reader::{RecordedLoop, load};

/// Floats JSON text gets wrong unless written shortest-round-trip and parsed exactly.
const AWKWARD: [f64; 10] = [
    1e-300,
    0.1 + 0.2,
    -0.0,
    5e-324,                     // the smallest subnormal
    2.225_073_858_507_201e-308, // the largest subnormal
    f64::MAX,
    f64::MIN_POSITIVE,
    -1.0 / 3.0,
    123_456_789.012_345_68,
    f64::NAN,
];

fn awkward(i: usize) -> f64 {
    AWKWARD[i % AWKWARD.len()]
}

/// Equal bits, or both NaN: a non-finite value is written as null and comes back as NaN.
fn same(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

fn assert_same(got: &[f64], expected: &[f64], what: &str) {
    assert_eq!(got.len(), expected.len(), "{what}");
    for (i, (g, e)) in got.iter().zip(expected).enumerate() {
        assert!(same(*g, *e), "{what}[{i}]: {g:e} ({:#x}), written {e:e} ({:#x})", g.to_bits(), e.to_bits());
    }
}

fn lockstep_pendulum(duration_s: f64) -> LaunchConfig {
    let (mut config, _) = crate::scenarios::resolve("pendulum", &[]).unwrap();
    config.mode = Mode::Lockstep;
    config.duration_s = duration_s;
    config
}

/// Loop k's parts, every float awkward (shifted by `shift`, so that two files differ), its
/// header's `lost` and incarnations set, and its trace stamped (which the reader drops).
fn awkward_loop(k: u64, layout: &VectorLayout, shift: usize) -> LoopParts {
    let n = k as usize + shift;
    let header = Header {
        k,
        t: k as f64 / 1000.0,
        lost: u32::from(k % 3 == 1),
        incarnations: [1, 2, 3, 4],
        trace: crate::contract::msg::LoopTrace::from_stamps([k + 1; 8]),
        ..Header::default()
    };
    let mut state = PlantState { header, ..PlantState::default() };
    state.x.iter_mut().enumerate().for_each(|(i, x)| *x = awkward(n + i));
    state.u_applied.iter_mut().enumerate().for_each(|(i, u)| *u = awkward(n + 3 + i));
    let mut measurements = Measurements { header, ..Measurements::default() };
    for (s, reading) in measurements.readings.iter_mut().take(layout.sensors.len()).enumerate() {
        *reading = SensorReading {
            sample_time: awkward(n + s + 5),
            seq: k * 7 + s as u64 + u64::from(s == 1) * (u64::MAX - 100),
            fresh: u32::from((k + s as u64).is_multiple_of(2)),
            valid: u32::from(k > 0),
            ..SensorReading::default()
        };
        reading.value.iter_mut().enumerate().for_each(|(i, v)| *v = awkward(n + s + i + 1));
    }
    measurements.u_applied.iter_mut().enumerate().for_each(|(i, u)| *u = awkward(n + 4 + i));
    let mut estimate = Estimate { header, ..Estimate::default() };
    estimate.x.iter_mut().enumerate().for_each(|(i, x)| *x = awkward(n + 6 + i));
    let mut command = Command { header, ..Command::default() };
    command.u.iter_mut().enumerate().for_each(|(i, u)| *u = awkward(n + 7 + i));
    let record = LoopRecord {
        header,
        deadline_miss: u32::from(k.is_multiple_of(4)),
        rejected: u32::from(k.is_multiple_of(5)),
        lost: header.lost,
        ..LoopRecord::default()
    };
    LoopParts {
        state: Some(state),
        measurements: Some(measurements),
        estimate: Some(estimate),
        command: Some(command),
        record: Some(record),
    }
}

/// Writes loops `ks` of [`awkward_loop`] to `path` through the monitor's sink.
fn write(path: &Path, detail: Detail, ks: std::ops::Range<u64>, shift: usize, finish: bool) -> Vec<LoopParts> {
    let layout = VectorLayout::example();
    let mut recording = McapRecording::create(path, &lockstep_pendulum(1.0), &layout, detail).unwrap();
    let written: Vec<LoopParts> = ks.map(|k| awkward_loop(k, &layout, shift)).collect();
    for parts in &written {
        let (k, t) = (parts.state.unwrap().header.k, parts.state.unwrap().header.t);
        recording.loop_joined(&JoinedLoop { k, t, parts, cause: None }).unwrap();
    }
    if finish {
        recording.finish_with(&[]).unwrap();
    } else {
        recording.flush().unwrap();
    }
    written
}

/// What the reader restores of a header: k, t, lost, and the incarnations of the processes
/// the message has passed.
fn assert_header(got: &Header, written: &Header, processes: usize, what: &str) {
    assert_eq!((got.k, got.t.to_bits(), got.lost), (written.k, written.t.to_bits(), written.lost), "{what}");
    let mut incarnations = [0; 4];
    incarnations[..processes].copy_from_slice(&written.incarnations[..processes]);
    assert_eq!(got.incarnations, incarnations, "{what}");
    assert_eq!(got.trace, Default::default(), "{what}: a replay stamps its own trace");
}

/// Every field the reader restores, against what was written.
fn assert_loop(got: &RecordedLoop, written: &LoopParts, layout: &VectorLayout) {
    let k = written.state.unwrap().header.k;
    let (n_state, n_input, n_estimate) = (layout.state.len(), layout.input.len(), layout.estimate.len());

    let (state, w) = (got.state.expect("a state"), written.state.unwrap());
    assert_header(&state.header, &w.header, 1, &format!("state {k}"));
    assert_same(&state.x[..n_state], &w.x[..n_state], &format!("state {k}"));
    assert_same(&state.u_applied[..n_input], &w.u_applied[..n_input], &format!("state {k} applied"));

    let (m, w) = (got.measurements.expect("measurements"), written.measurements.unwrap());
    assert_header(&m.header, &w.header, 2, &format!("measurements {k}"));
    for (s, (name, components)) in layout.sensors.iter().enumerate() {
        let (r, wr) = (&m.readings[s], &w.readings[s]);
        assert_same(&r.value[..components.len()], &wr.value[..components.len()], &format!("{name} {k}"));
        assert_same(&[r.sample_time], &[wr.sample_time], &format!("{name} {k} sample time"));
        assert_eq!((r.seq, r.fresh, r.valid), (wr.seq, wr.fresh, wr.valid), "{name} {k}");
    }
    assert_same(&m.u_applied[..n_input], &w.u_applied[..n_input], &format!("measurements {k} applied"));

    let (e, w) = (got.estimate.expect("an estimate"), written.estimate.unwrap());
    assert_header(&e.header, &w.header, 3, &format!("estimate {k}"));
    assert_same(&e.x[..n_estimate], &w.x[..n_estimate], &format!("estimate {k}"));

    let (c, w) = (got.command.expect("a command"), written.command.unwrap());
    assert_header(&c.header, &w.header, 4, &format!("command {k}"));
    assert_same(&c.u[..n_input], &w.u[..n_input], &format!("command {k}"));

    let (r, w) = (got.record.expect("a loop record"), written.record.unwrap());
    assert_header(&r.header, &w.header, 4, &format!("record {k}"));
    assert_eq!((r.deadline_miss, r.rejected, r.lost), (w.deadline_miss, w.rejected, w.lost), "record {k}");
}

#[test]
fn awkward_floats_and_every_flag_come_back_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let layout = VectorLayout::example();
    let written = write(&dir.path().join("run.mcap"), Detail::Live, 0..20, 0, true);
    let recorded = load(dir.path(), &layout, 22).unwrap();
    // As far as the recording goes, not the 22 planned.
    assert_eq!(recorded.len(), 20);
    for (got, written) in recorded.iter().zip(&written) {
        assert_loop(got, written, &layout);
    }
    // Awkward values did reach every field (the reader is not comparing defaults).
    assert_eq!(recorded[2].state.unwrap().x[0].to_bits(), (-0.0f64).to_bits());
    assert!(recorded[9].state.unwrap().x[0].is_nan());
    assert_eq!(recorded[0].estimate.unwrap().x[0], f64::MIN_POSITIVE);
    assert_eq!(recorded[1].command.unwrap().header.lost, 1);
    // Loops past the run's are not kept.
    assert_eq!(load(dir.path(), &layout, 5).unwrap().len(), 5);
}

#[test]
fn a_restarted_monitors_file_fills_in_and_the_first_message_of_a_loop_wins() {
    let dir = tempfile::tempdir().unwrap();
    let layout = VectorLayout::example();
    let first = write(&dir.path().join("run.mcap"), Detail::Live, 0..15, 0, true);
    let mut second = write(&dir.path().join("run.1.mcap"), Detail::Live, 10..20, 1, true);
    let recorded = load(dir.path(), &layout, 20).unwrap();
    for (k, got) in recorded.iter().enumerate() {
        let written = if k < 15 { &first[k] } else { &second[k - 10] };
        assert_loop(got, written, &layout);
    }

    // A loop without a record takes the incarnations of the processes before each message from
    // the nearest earlier loop's; its sender's is its own.
    let dir = tempfile::tempdir().unwrap();
    for (k, parts) in second.iter_mut().enumerate() {
        let record = parts.record.as_mut().unwrap();
        match k {
            3 => parts.record = None,
            _ => record.header.incarnations = [k as u32, 1, 1, 1],
        }
    }
    let mut recording =
        McapRecording::create(&dir.path().join("run.mcap"), &lockstep_pendulum(1.0), &layout, Detail::Live).unwrap();
    for parts in &second {
        let k = parts.state.unwrap().header.k;
        recording.loop_joined(&JoinedLoop { k, t: k as f64 / 1000.0, parts, cause: None }).unwrap();
    }
    recording.finish_with(&[]).unwrap();
    let recorded = load(dir.path(), &layout, 20).unwrap();
    assert!(recorded[13].record.is_none());
    let own = |k: usize, slot: usize| -> u32 {
        let parts = &second[k];
        let header = match slot {
            0 => parts.state.unwrap().header,
            2 => parts.estimate.unwrap().header,
            _ => parts.command.unwrap().header,
        };
        header.incarnations[slot]
    };
    assert_eq!(recorded[13].command.unwrap().header.incarnations, [2, 1, 1, own(3, 3)]);
    assert_eq!(recorded[13].state.unwrap().header.incarnations, [own(3, 0), 0, 0, 0]);
    assert_eq!(recorded[14].estimate.unwrap().header.incarnations, [4, 1, own(4, 2), 0]);
}

#[test]
fn a_killed_monitors_file_reads_up_to_where_it_last_flushed() {
    let dir = tempfile::tempdir().unwrap();
    let layout = VectorLayout::example();
    let path = dir.path().join("run.mcap");
    let mut recording = McapRecording::create(&path, &lockstep_pendulum(1.0), &layout, Detail::Live).unwrap();
    let written: Vec<LoopParts> = (0..20).map(|k| awkward_loop(k, &layout, 0)).collect();
    let mut flushed_at = 0;
    for (k, parts) in written.iter().enumerate() {
        recording.loop_joined(&JoinedLoop { k: k as u64, t: k as f64 / 1000.0, parts, cause: None }).unwrap();
        if k == 9 {
            recording.flush().unwrap();
            flushed_at = std::fs::metadata(&path).unwrap().len();
        }
    }
    recording.finish_with(&[]).unwrap();
    // Killed in the middle of writing the next chunk.
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..flushed_at as usize + 40]).unwrap();
    let recorded = load(dir.path(), &layout, 20).unwrap();
    for (got, written) in recorded.iter().zip(&written).take(10) {
        assert_loop(got, written, &layout);
    }
    assert!(recorded[10..].iter().all(|l| l.state.is_none() && l.record.is_none()));
}

#[test]
fn what_replay_cannot_play_back_is_one_line_naming_the_file() {
    let layout = VectorLayout::example();
    let error = |dir: &Path| {
        let message = format!("{:#}", load(dir, &layout, 10).unwrap_err());
        assert_eq!(message.lines().count(), 1, "{message}");
        message
    };
    let dir = tempfile::tempdir().unwrap();
    assert_eq!(
        error(dir.path()),
        format!("{} has no run.mcap; replay needs the recording a run writes", dir.path().display())
    );

    let path = dir.path().join("run.mcap");
    write(&path, Detail::Files, 0..5, 0, true);
    assert_eq!(
        error(dir.path()),
        format!(
            "{}: written by `looplab export`, which keeps no sample times or flags: record the run again",
            path.display()
        )
    );

    // A recording from before the input applied was kept.
    let mut writer = mcap::Writer::new(std::io::BufWriter::new(std::fs::File::create(&path).unwrap())).unwrap();
    let schema = writer.add_schema("looplab.State", "jsonschema", br#"{"type":"object"}"#).unwrap();
    let channel = writer.add_channel(schema, "/state", "json", &Default::default()).unwrap();
    let header = mcap::records::MessageHeader { channel_id: channel, sequence: 0, log_time: 0, publish_time: 0 };
    writer.write_to_known_channel(&header, br#"{"k":3,"t":0.003,"theta":1,"omega":2}"#).unwrap();
    writer.finish().unwrap();
    drop(writer);
    assert_eq!(
        error(dir.path()),
        format!(
            "{}: /state of loop 3 has no \"applied\": recorded by an older LoopLab, which left out fields a stage \
             reads; record it again with this version",
            path.display()
        )
    );

    std::fs::write(&path, "not a recording").unwrap();
    let message = error(dir.path());
    assert!(message.starts_with(&format!("{}: not an MCAP recording", path.display())), "{message}");
}

#[test]
fn every_channel_says_its_run_format_version_and_another_version_is_refused() {
    use crate::contract::run_format::{FORMAT_VERSION, FORMAT_VERSION_KEY};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    write(&path, Detail::Live, 0..3, 0, true);
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().expect("a finished file has a summary");
    assert_eq!(summary.channels.len(), 7);
    for channel in summary.channels.values() {
        assert_eq!(channel.metadata.get(FORMAT_VERSION_KEY), Some(&FORMAT_VERSION.to_string()), "{}", channel.topic);
    }
    // Another version's recording: the same bytes with the version's digit changed.
    let ours = format!("{FORMAT_VERSION_KEY}\x01\0\0\0{FORMAT_VERSION}");
    let theirs = format!("{FORMAT_VERSION_KEY}\x01\0\0\0{}", FORMAT_VERSION + 1);
    assert_eq!(ours.len(), theirs.len(), "one digit either way");
    let needle = ours.as_bytes();
    let mut changed = bytes.clone();
    let mut replaced = 0;
    let mut i = 0;
    while i + needle.len() <= changed.len() {
        if &changed[i..i + needle.len()] == needle {
            changed[i..i + needle.len()].copy_from_slice(theirs.as_bytes());
            replaced += 1;
        }
        i += 1;
    }
    assert_eq!(replaced, 14, "each channel's record, in the data and in the summary");
    std::fs::write(&path, changed).unwrap();
    let e = format!("{:#}", load(dir.path(), &VectorLayout::example(), 3).unwrap_err());
    let expected = format!("run format version {}; this LoopLab reads version {FORMAT_VERSION}", FORMAT_VERSION + 1);
    assert!(e.contains(&expected), "{e}");
}
