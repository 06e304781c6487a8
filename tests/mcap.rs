//! `run.mcap`, read back with the `mcap` crate's reader: one message per loop and channel as
//! `summary.json` counts them, every value of `trajectory.csv` exactly, the log time's clock in
//! each channel's metadata, and `looplab export` writing the same from the run folder's files.

use crate::common;

use std::collections::BTreeMap;
use std::path::Path;

use common::{fresh_dir, looplab, run};
use looplab_shared::model::layout::column_name;
use serde_json::Value;

const TOPICS: [&str; 7] = ["/state", "/measurements", "/estimate", "/command", "/loop", "/latency", "/faults"];

/// One message: its log time, publish time and JSON.
struct Message {
    log_time: u64,
    publish_time: u64,
    data: Vec<u8>,
    json: Value,
}

/// A recording as its channels' messages, in file order, and each channel's metadata and schema.
struct Recording {
    messages: BTreeMap<String, Vec<Message>>,
    metadata: BTreeMap<String, BTreeMap<String, String>>,
    schemas: BTreeMap<String, Value>,
}

impl Recording {
    fn read(path: &Path) -> Self {
        let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        // The summary section: the file was finished.
        let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary section");
        let (mut metadata, mut schemas) = (BTreeMap::new(), BTreeMap::new());
        for channel in summary.channels.values() {
            let schema = channel.schema.as_ref().expect("every channel has a schema");
            assert_eq!((schema.encoding.as_str(), channel.message_encoding.as_str()), ("jsonschema", "json"));
            let schema: Value = serde_json::from_slice(&schema.data).expect("the schema is JSON");
            schemas.insert(channel.topic.clone(), schema);
            metadata.insert(channel.topic.clone(), channel.metadata.clone());
        }
        let mut messages: BTreeMap<String, Vec<Message>> = TOPICS.iter().map(|t| (t.to_string(), vec![])).collect();
        for message in mcap::MessageStream::new(&bytes).unwrap() {
            let message = message.unwrap();
            let json = serde_json::from_slice(&message.data).expect("a message is JSON");
            messages.get_mut(&message.channel.topic).expect("a known topic").push(Message {
                log_time: message.log_time,
                publish_time: message.publish_time,
                data: message.data.into_owned(),
                json,
            });
        }
        Self { messages, metadata, schemas }
    }

    fn count(&self, topic: &str) -> u64 {
        self.messages[topic].len() as u64
    }
}

/// A CSV file: its header in order and its rows.
fn csv(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().split(',').map(str::to_owned).collect();
    (header, lines.map(|l| l.split(',').map(str::to_owned).collect()).collect())
}

/// Where each column of trajectory.csv is in the recording, from the channels' schemas: a field
/// keeps the component's name and gives its unit as its description, and the column is that
/// name with the unit (`theta_dot` in rad/s: `theta_dot_rad_per_s`); the applied input is the
/// state's `applied` (a live recording only). Column → (topic, path).
fn columns_in(recording: &Recording) -> BTreeMap<String, (&'static str, Vec<String>)> {
    let fields = |schema: &Value| -> Vec<(String, String)> {
        let properties = schema["properties"].as_object().unwrap();
        let unit = |field: &Value| field["description"].as_str().unwrap_or("").to_string();
        properties
            .iter()
            .filter(|(name, _)| !["k", "t", "lost", "incarnation", "applied"].contains(&name.as_str()))
            .map(|(n, f)| (n.clone(), unit(f)))
            .collect()
    };
    let mut columns = BTreeMap::new();
    for (topic, prefix) in [("/state", ""), ("/estimate", "est."), ("/command", "cmd.")] {
        for (name, unit) in fields(&recording.schemas[topic]) {
            columns.insert(column_name(&format!("{prefix}{name}"), &unit), (topic, vec![name]));
        }
    }
    let applied = &recording.schemas["/state"]["properties"]["applied"];
    if !applied.is_null() {
        for (name, unit) in fields(applied) {
            columns.insert(column_name(&format!("applied.{name}"), &unit), ("/state", vec!["applied".into(), name]));
        }
    }
    let measurements = &recording.schemas["/measurements"];
    for (sensor, _) in fields(measurements) {
        let components = fields(&measurements["properties"][&sensor]["properties"]["value"]);
        let one = components.len() == 1;
        for (component, unit) in components {
            let name = if one { format!("meas.{sensor}") } else { format!("meas.{sensor}.{component}") };
            columns
                .insert(column_name(&name, &unit), ("/measurements", vec![sensor.clone(), "value".into(), component]));
        }
    }
    columns
}

/// Every value of trajectory.csv equals the recording's, exactly, in the field its column names
/// (see [`columns_in`]); `t_s` is the recording's `t`, k / rate exactly. The applied input's
/// columns (`applied.*`) are in the monitor's recording only (`with_applied`): export's keeps
/// the plant's state vector alone.
fn assert_trajectory_matches(dir: &Path, recording: &Recording, rate_hz: f64, with_applied: bool) {
    let (header, rows) = csv(&dir.join("trajectory.csv"));
    assert_eq!(header[..2], ["k", "t_s"]);
    let columns = columns_in(recording);
    let recorded = header.iter().filter(|name| with_applied || !name.starts_with("applied.")).count();
    assert!(header.iter().any(|name| name.starts_with("applied.")), "no applied.* column in {header:?}");
    assert_eq!(columns.len(), recorded - 2, "{header:?} against {:?}", columns.keys());
    for (column, name) in
        header.iter().enumerate().skip(2).filter(|(_, name)| with_applied || !name.starts_with("applied."))
    {
        let (topic, path) = columns.get(name).unwrap_or_else(|| panic!("{name} is in no schema: {:?}", columns.keys()));
        let messages = &recording.messages[*topic];
        assert_eq!(messages.len(), rows.len(), "{name}");
        for (row, message) in rows.iter().zip(messages) {
            let json = &message.json;
            let k: u64 = row[0].parse().unwrap();
            assert_eq!(json["k"].as_u64(), Some(k));
            assert_eq!(json["t"].as_f64(), Some(row[1].parse().unwrap()));
            assert_eq!(row[1].parse::<f64>().unwrap(), k as f64 / rate_hz);
            let value = path.iter().fold(json, |json, key| &json[key.as_str()]);
            let expected: f64 = row[column].parse().unwrap();
            assert_eq!(value.as_f64(), Some(expected), "{name} at k = {}", row[0]);
        }
    }
}

/// Messages per channel as summary.json counts them, for a whole lockstep run.
fn assert_counts(summary: &Value, recording: &Recording) {
    let loops = summary["loops"].as_u64().unwrap();
    let records = summary["monitor"]["records"].as_u64().unwrap();
    assert_eq!(records, loops);
    for topic in ["/state", "/measurements", "/estimate", "/command", "/loop", "/latency"] {
        assert_eq!(recording.count(topic), loops, "{topic}");
    }
    assert_eq!(recording.count("/faults"), summary["faults"].as_array().unwrap().len() as u64);
}

fn assert_clock(recording: &Recording, clock: &str) {
    for topic in TOPICS {
        assert_eq!(recording.metadata[topic].get("log_time").map(String::as_str), Some(clock), "{topic}");
    }
}

#[test]
fn a_lockstep_run_records_every_loop_and_fault_and_export_writes_the_same() {
    let r = run(
        "mcap-lockstep",
        &[
            "--mode",
            "lockstep",
            "--duration",
            "2",
            "--fault",
            "delay controller by 3 ticks at 0.5s for 0.2s",
            "--fault",
            "drop estimator 50% at 1s for 0.1s",
        ],
    );
    let live = Recording::read(&r.dir.join("run.mcap"));
    assert_eq!(r.summary["loops"], 2000);
    assert_counts(&r.summary, &live);
    assert_clock(&live, "simulation");
    assert_trajectory_matches(&r.dir, &live, 1000.0, true);

    // Log time: simulation time of tick k (1 kHz: k ms); publish time the same in lockstep.
    for topic in ["/state", "/loop"] {
        for message in &live.messages[topic] {
            assert_eq!(message.log_time, message.json["k"].as_u64().unwrap() * 1_000_000, "{topic}");
            assert_eq!(message.publish_time, message.log_time);
        }
    }
    // The loop record and the latencies, as loops.csv has them.
    let (header, loops) = csv(&r.dir.join("loops.csv"));
    let column = |name: &str| header.iter().position(|c| c == name).unwrap();
    let lost = live.messages["/loop"].iter().filter(|m| m.json["lost"] == true).count();
    assert!(lost > 0, "the dropped estimates reach the plant marked lost");
    assert_eq!(lost as u64, r.summary["lost_commands"].as_u64().unwrap());
    for (row, latency) in loops.iter().zip(&live.messages["/latency"]) {
        assert_eq!(latency.json["end_to_end_ns"].as_u64(), Some(row[column("end_to_end_ns")].parse().unwrap()));
        let hop = |from: &str, to: &str| -> u64 {
            row[column(to)].parse::<u64>().unwrap() - row[column(from)].parse::<u64>().unwrap()
        };
        assert_eq!(
            latency.json["controller_to_plant_ns"].as_u64(),
            Some(hop("controller_publish_ns", "plant_receive_ns"))
        );
    }
    // Each fault at its tick, with what the summary says it did.
    for (message, fault) in live.messages["/faults"].iter().zip(r.summary["faults"].as_array().unwrap()) {
        assert_eq!(message.json["fault"], fault["fault"]);
        assert_eq!(message.json["t"], fault["at_s"]);
        assert_eq!(message.log_time, (fault["at_s"].as_f64().unwrap() * 1e9).round() as u64);
        assert_eq!(message.json["outage_ticks"], fault["effect"]["outage_ticks"]);
        assert_eq!(message.json["within_limits"], fault["effect"]["within_limits"]);
    }
    let encoder = &live.messages["/measurements"][5].json["encoder"];
    assert_eq!((encoder["fresh"].as_bool(), encoder["sample_time"].as_f64()), (Some(true), Some(0.005)));
    assert_eq!((encoder["valid"].as_bool(), encoder["seq"].as_u64()), (Some(true), Some(5)));

    // The export from the files: the same vectors, latencies and faults byte for byte, at the
    // same times; the files keep no sample times, fresh or lost flags.
    std::fs::remove_file(r.dir.join("run.mcap")).unwrap();
    let out = looplab().arg("export").arg(&r.dir).arg("--mcap").output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let exported = Recording::read(&r.dir.join("run.mcap"));
    assert_counts(&r.summary, &exported);
    assert_clock(&exported, "simulation");
    assert_trajectory_matches(&r.dir, &exported, 1000.0, false);
    for topic in ["/latency", "/faults"] {
        let (a, b) = (&live.messages[topic], &exported.messages[topic]);
        assert!(a.iter().zip(b).all(|(a, b)| a.data == b.data && a.log_time == b.log_time), "{topic}");
    }
    // The vectors the same, less what only the monitor saw: the applied input and lost flags.
    for topic in ["/state", "/estimate", "/command"] {
        let (a, b) = (&live.messages[topic], &exported.messages[topic]);
        let files_keep = |json: &Value| {
            let mut json = json.clone();
            json.as_object_mut().unwrap().retain(|key, _| key != "applied" && key != "lost" && key != "incarnation");
            json
        };
        assert!(a.iter().zip(b).all(|(a, b)| files_keep(&a.json) == b.json && a.log_time == b.log_time), "{topic}");
    }
    let lost_estimates = live.messages["/estimate"].iter().filter(|m| m.json["lost"] == true).count();
    assert_eq!(lost_estimates, lost, "the dropped estimates are marked lost");
    assert_eq!(exported.messages["/measurements"][5].json["encoder"].get("fresh"), None);
    assert_eq!(exported.messages["/state"][5].json.get("applied"), None);
    assert_eq!(exported.messages["/loop"][5].json.get("lost"), None);
    // A recording there is never overwritten, unless --force says so.
    std::fs::write(r.dir.join("run.mcap"), "the monitor's").unwrap();
    let out = looplab().arg("export").arg(&r.dir).arg("--mcap").output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!((out.status.code(), stderr.lines().count()), (Some(2), 1), "{stderr}");
    assert!(stderr.contains("run.mcap exists") && stderr.contains("--force"), "{stderr}");
    assert_eq!(std::fs::read_to_string(r.dir.join("run.mcap")).unwrap(), "the monitor's");
    let out = looplab().arg("export").arg(&r.dir).args(["--mcap", "--force"]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(Recording::read(&r.dir.join("run.mcap")).messages["/state"].len(), live.messages["/state"].len());

    // The cells are read by the names a run of the launch file writes: a header without one of
    // them (here one from before the units) is one clear error naming the file and the column,
    // and no file.
    std::fs::remove_file(r.dir.join("run.mcap")).unwrap();
    let trajectory = std::fs::read_to_string(r.dir.join("trajectory.csv")).unwrap();
    std::fs::write(r.dir.join("trajectory.csv"), trajectory.replacen("k,t_s,", "k,t,", 1)).unwrap();
    let out = looplab().arg("export").arg(&r.dir).arg("--mcap").output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(stderr.contains(r#"trajectory.csv has no column "t_s""#), "{stderr}");
    assert!(!r.dir.join("run.mcap").exists());
}

#[test]
fn a_real_time_run_logs_the_plants_clock() {
    let r = run("mcap-realtime", &["--mode", "realtime", "--duration", "0.2"]);
    let recording = Recording::read(&r.dir.join("run.mcap"));
    assert_clock(&recording, "wall_clock");
    // Every message of loop k is logged at the plant's publish stamp of loop k, and published
    // when its stage published it.
    let (header, loops) = csv(&r.dir.join("loops.csv"));
    let column = |name: &str| header.iter().position(|c| c == name).unwrap();
    let stamps: BTreeMap<u64, (u64, u64)> = loops
        .iter()
        .filter(|row| !row[column("plant_publish_ns")].is_empty())
        .map(|row| {
            let stamp = |name: &str| row[column(name)].parse::<u64>().unwrap();
            (stamp("k"), (stamp("plant_publish_ns"), stamp("controller_publish_ns")))
        })
        .collect();
    assert!(stamps.len() >= 100, "{} loop records", stamps.len());
    assert_eq!(recording.count("/loop"), r.summary["monitor"]["records"].as_u64().unwrap());
    for message in &recording.messages["/command"] {
        let k = message.json["k"].as_u64().unwrap();
        if let Some(&(plant_publish, controller_publish)) = stamps.get(&k) {
            assert_eq!((message.log_time, message.publish_time), (plant_publish, controller_publish), "loop {k}");
        }
    }
}

#[test]
fn a_restarted_monitor_writes_the_next_recording() {
    let r = run("mcap-restart", &["--mode", "lockstep", "--duration", "2", "--fault", "kill monitor at 1s"]);
    // The killed monitor's file has no summary section (what it holds depends on when it last
    // flushed, in wall-clock time).
    let first = std::fs::read(r.dir.join("run.mcap")).unwrap();
    assert!(!matches!(mcap::Summary::read(&first), Ok(Some(_))), "no summary section");
    // The restarted monitor's file is whole and holds every loop from its first on; the loops
    // missing from the report end just before it.
    let second = Recording::read(&r.dir.join("run.1.mcap"));
    let monitor = &r.summary["monitor"];
    let records = monitor["records"].as_u64().unwrap();
    assert_eq!(records + monitor["missing_loops"].as_u64().unwrap(), 2000);
    let first_k = second.messages["/state"][0].json["k"].as_u64().unwrap();
    assert_eq!(second.count("/loop"), 2000 - first_k);
    let missing = monitor["missing"].as_array().unwrap();
    if let Some(last) = missing.last() {
        assert_eq!(last[1].as_u64().unwrap() + 1, first_k, "{missing:?}");
    }
    assert!(!r.dir.join("run.2.mcap").exists());
}

#[test]
fn export_of_what_is_not_a_run_folder_is_one_clear_error() {
    let rejects = |dir: &Path, expected: &str| {
        let out = looplab().arg("export").arg(dir).arg("--mcap").output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{stderr}");
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(stderr.contains(expected), "{stderr}");
    };
    let dir = fresh_dir("mcap-not-a-run");
    rejects(&dir, "no such run folder");
    std::fs::create_dir_all(&dir).unwrap();
    rejects(&dir, "not a run folder (it has no launch.toml)");
    assert!(!dir.join("run.mcap").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}
