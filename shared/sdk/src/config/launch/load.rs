//! Loading: a scenario name or a launch file, with overrides, resolved into a checked
//! [`LaunchConfig`]; and the resolved file each loop process reads back.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::config::error::LaunchError;
use crate::config::faults::{FaultSpec, Supervision};
use crate::config::gate::Gate;
use crate::config::hosts::Hosts;
use crate::config::launch::checks::{
    check_common, check_fault, check_finite, check_realtime, check_sensors, check_supervision, check_wait,
};
use crate::config::launch::overrides::{Override, merge, set_dotted};
use crate::config::launch::types::{LaunchConfig, Mode, Origins, SensorSpec, deserialize_at};
use crate::config::launch::{declared, run_vectors};
use crate::config::python_plant;
use crate::config::realtime::RealtimeSettings;
use crate::config::replay::ReplaySpec;
use crate::config::schema::ScenarioSchema;
use crate::config::stages::Stages;
use crate::config::wait::WaitSettings;

/// The top-level keys every launch file shares, in [`CommonKeys`]'s order; the rest belong to
/// the scenario. Read from the struct itself (serde names its fields to the deserialiser it
/// reads from), so the list and the struct cannot disagree.
pub fn common_keys() -> &'static [&'static str] {
    use serde::de::{Error as _, Visitor, value::Error};

    /// A deserialiser that only keeps the field names a struct asks it for.
    struct FieldNames(Option<&'static [&'static str]>);

    impl<'de> serde::Deserializer<'de> for &mut FieldNames {
        type Error = Error;
        fn deserialize_struct<V: Visitor<'de>>(
            self,
            _name: &'static str,
            fields: &'static [&'static str],
            _visitor: V,
        ) -> Result<V::Value, Error> {
            self.0 = Some(fields);
            Err(Error::custom("only the field names were wanted"))
        }
        fn deserialize_any<V: Visitor<'de>>(self, _visitor: V) -> Result<V::Value, Error> {
            Err(Error::custom("not a struct"))
        }
        serde::forward_to_deserialize_any! {
            bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes byte_buf option
            unit unit_struct newtype_struct seq tuple tuple_struct map enum identifier ignored_any
        }
    }

    static KEYS: std::sync::OnceLock<&'static [&'static str]> = std::sync::OnceLock::new();
    KEYS.get_or_init(|| {
        let mut names = FieldNames(None);
        let _ = CommonKeys::deserialize(&mut names);
        names.0.expect("CommonKeys is a struct")
    })
}

/// `schema`'s own top-level sections: those of its defaults that every launch file does not
/// share.
pub fn sections(schema: &ScenarioSchema) -> Vec<String> {
    schema.defaults().keys().filter(|k| !common_keys().contains(&k.as_str())).cloned().collect()
}

/// The keys every scenario shares, as the document has them.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct CommonKeys {
    /// Empty: a declared system.
    #[serde(default)]
    scenario: String,
    mode: Mode,
    rate_hz: f64,
    /// None: one loop period.
    #[serde(default)]
    deadline_us: Option<f64>,
    /// None: only the deadline misses are explained.
    #[serde(default)]
    explain_over_us: Option<f64>,
    /// false: no probe beside the loop.
    #[serde(default)]
    probe: bool,
    /// false: no scheduler trace.
    #[serde(default)]
    trace_sched: bool,
    duration_s: f64,
    seed: u64,
    #[serde(default)]
    sensors: BTreeMap<String, SensorSpec>,
    #[serde(default)]
    faults: Vec<FaultSpec>,
    #[serde(default)]
    supervision: Supervision,
    #[serde(default)]
    wait: WaitSettings,
    #[serde(default)]
    realtime: RealtimeSettings,
    /// Read by `Hosts::parse`, for errors that name the key.
    #[serde(default)]
    hosts: toml::Table,
    /// Read by `Stages::parse`, likewise.
    #[serde(default)]
    stages: toml::Table,
    #[serde(default)]
    replay: Option<ReplaySpec>,
    /// A free table for stages of the user's own (their `config["parameters"]`).
    #[serde(default)]
    parameters: toml::Table,
    #[serde(default)]
    gate: GateSection,
}

/// `[gate]`: what fails the run (`config::gate`).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct GateSection {
    #[serde(default)]
    fail_on: Vec<String>,
}

/// The names of the scenarios of `catalog`, for error messages.
fn names(catalog: &[ScenarioSchema]) -> String {
    catalog.iter().map(|s| s.name).collect::<Vec<_>>().join(", ")
}

fn find<'a>(catalog: &'a [ScenarioSchema], name: &str) -> Option<&'a ScenarioSchema> {
    catalog.iter().find(|s| s.name == name)
}

/// Resolves what the user asked to run, a scenario name or a launch-file path, with overrides,
/// into a checked configuration for one of the scenarios of `catalog` (the scenarios layer
/// passes its registry, and builds the scenario the configuration describes).
pub fn resolve_config(
    target: &str,
    overrides: &[Override],
    catalog: &[ScenarioSchema],
) -> Result<LaunchConfig, LaunchError> {
    let scenario_names = || names(catalog);
    // A scenario's name wins over a file of that name; anything else that looks like a path is one.
    let looks_like_path = find(catalog, target).is_none()
        && !Path::new(target).is_dir()
        && (target.ends_with(".toml") || target.contains('/') || Path::new(target).is_file());
    let (origin, document, launch_folder) = if looks_like_path {
        let text = read_launch_text(Path::new(target), Links::Follow).map_err(|e| LaunchError::new(target, None, e))?;
        let user: toml::Table = toml::from_str(&text).map_err(|e| toml_error(target, &text, &e))?;
        if declared::is_declared(&user) {
            let mut document: toml::Table = toml::from_str(declared::DECLARED_DEFAULTS).expect("the defaults parse");
            merge(&mut document, user);
            let folder = Path::new(target).parent().map(Path::to_path_buf);
            if !overrides.is_empty() {
                from_document(document.clone(), target, &[], catalog, folder.as_deref(), false)?;
            }
            let config = from_document(document, target, overrides, catalog, folder.as_deref(), false)?;
            return check_stages(config);
        }
        let name = match user.get("scenario") {
            Some(toml::Value::String(name)) => name.clone(),
            Some(_) => {
                return Err(LaunchError::new(
                    target,
                    Some("scenario"),
                    format!("must be a string; allowed: {}", scenario_names()),
                ));
            }
            None => {
                return Err(LaunchError::new(
                    target,
                    Some("scenario"),
                    format!(
                        "missing; allowed: {} (or no scenario and a [system] table: a system of your own)",
                        scenario_names()
                    ),
                ));
            }
        };
        let schema = find(catalog, &name).ok_or_else(|| {
            LaunchError::new(
                target,
                Some("scenario"),
                format!("unknown scenario \"{name}\"; allowed: {}", scenario_names()),
            )
        })?;
        let mut document = schema.defaults();
        merge(&mut document, user);
        (target.to_owned(), document, Path::new(target).parent().map(Path::to_path_buf))
    } else if Path::new(target).is_dir() {
        return Err(LaunchError::new(
            target,
            None,
            format!("is a folder; give a launch file (.toml) or a scenario name: {}", scenario_names()),
        ));
    } else {
        let schema = find(catalog, target).ok_or_else(|| {
            LaunchError::new(
                "command line",
                None,
                format!(
                    "unknown scenario \"{target}\"; allowed: {} (or a path to a .toml launch file)",
                    scenario_names()
                ),
            )
        })?;
        (schema.file.to_owned(), schema.defaults(), None)
    };
    // The file is checked as written too: a bad value in it is reported even where a `--set`
    // replaces it (`mode = 3.7` in the file with `--mode realtime`).
    if looks_like_path && !overrides.is_empty() {
        from_document(document.clone(), &origin, &[], catalog, launch_folder.as_deref(), false)?;
    }
    let config = from_document(document, &origin, overrides, catalog, launch_folder.as_deref(), false)?;
    check_stages(config)
}

/// How long a check of the user's code may take: as long as its process may take to be ready.
fn ready_timeout(config: &LaunchConfig) -> std::time::Duration {
    // Positive, finite and at most an hour (checked at load).
    std::time::Duration::from_secs_f64(config.supervision.ready_timeout_s)
}

/// A user's stage that cannot start (or whose `build` fails) is bad input, found before anything
/// starts.
fn check_stages(config: LaunchConfig) -> Result<LaunchConfig, LaunchError> {
    for (role, stage) in &config.stages.commands {
        let built = stage.build().map_err(|message| config.error(&format!("stages.{role}.build"), message))?;
        if built == Some(crate::config::stage_build::Built::Ran) {
            tell!("{role}: built with `{}`", stage.build.join(" "));
        }
        stage
            .check(ready_timeout(&config))
            .map_err(|message| config.error(&format!("stages.{role}.command"), message))?;
        let has_reference = match config.document.get("reference") {
            None => false,
            Some(toml::Value::Table(t)) => !t.is_empty(),
            Some(_) => true,
        };
        if stage.with_reference && !(config.is_declared() && has_reference) {
            return Err(config.error(
                &format!("stages.{role}.with_reference"),
                "appends a declared system's [reference] to the controller's input; this launch file has none",
            ));
        }
    }
    Ok(config)
}

/// A Python plant that cannot start is bad input, found before anything starts. Checked once the
/// scenario is built, so that what is wrong with the rest of `[plant]` is said first.
pub fn check_python_plant(config: &LaunchConfig) -> Result<(), LaunchError> {
    match &config.stages.plant {
        Some(plant) => python_plant::check(plant, ready_timeout(config))
            .map_err(|message| config.error(python_plant::KEY, message)),
        None => Ok(()),
    }
}

/// Reads a resolved launch file written by the launcher (what each loop process does).
pub fn load_resolved_config(path: &Path, catalog: &[ScenarioSchema]) -> Result<LaunchConfig, LaunchError> {
    let (document, origin) = read_resolved(path)?;
    from_document(document, &origin, &[], catalog, path.parent(), false)
}

/// Reads a run's `launch.toml` as a stage of the user's own does: with no catalog, the vectors
/// the launcher resolved (`[vectors]`) in place of the scenario's entry, and the input's limits.
pub fn load_run_config(path: &Path) -> Result<LaunchConfig, LaunchError> {
    let (document, origin) = read_resolved(path)?;
    from_document(document, &origin, &[], &[], path.parent(), true)
}

fn read_resolved(path: &Path) -> Result<(toml::Table, String), LaunchError> {
    let origin = path.display().to_string();
    // The launcher wrote it as a file; a link there was planted (in a run folder of another user's).
    let text = read_launch_text(path, Links::Refuse).map_err(|e| LaunchError::new(&origin, None, e))?;
    let document = toml::from_str(&text).map_err(|e| toml_error(&origin, &text, &e))?;
    Ok((document, origin))
}

/// The largest launch file read, bytes: far above any real one (the longest shipped is 12 KB).
pub const MAX_LAUNCH_FILE: u64 = 1 << 20;

/// Whether a launch file may be a symbolic link: the user's may, a run's never.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Links {
    Follow,
    Refuse,
}

/// A launch file's text: a regular file of at most [`MAX_LAUNCH_FILE`] bytes. A FIFO is opened
/// without blocking and refused, as is a device (`/dev/zero` would be read forever).
fn read_launch_text(path: &Path, links: Links) -> Result<String, String> {
    use std::io::Read as _;
    use std::os::unix::fs::OpenOptionsExt as _;
    let cannot = |e: std::io::Error| format!("cannot read the launch file: {e}");
    let no_follow = if links == Links::Refuse { libc::O_NOFOLLOW } else { 0 };
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK | libc::O_CLOEXEC | no_follow)
        .open(path)
        .map_err(|e| match e.raw_os_error() {
            Some(libc::ELOOP) if links == Links::Refuse => {
                "cannot read the launch file: it is a symbolic link, which the launcher never writes".to_owned()
            }
            _ => cannot(e),
        })?;
    let metadata = file.metadata().map_err(cannot)?;
    if !metadata.is_file() {
        return Err("cannot read the launch file: it is not a regular file (a FIFO, a device or a folder)".into());
    }
    if metadata.len() > MAX_LAUNCH_FILE {
        return Err(format!(
            "cannot read the launch file: it is {} bytes, more than a launch file's {MAX_LAUNCH_FILE}",
            metadata.len()
        ));
    }
    let mut text = String::new();
    file.take(MAX_LAUNCH_FILE).read_to_string(&mut text).map_err(cannot)?;
    Ok(text)
}

/// `launch_folder`: the launch file's folder, where a stage's command given in it starts (one
/// given on the command line starts in the current folder). `from_run`: a run's `launch.toml`
/// read without a catalog ([`load_run_config`]).
fn from_document(
    mut document: toml::Table,
    origin: &str,
    overrides: &[Override],
    catalog: &[ScenarioSchema],
    launch_folder: Option<&Path>,
    from_run: bool,
) -> Result<LaunchConfig, LaunchError> {
    let mut origins = Origins { file: origin.to_owned(), set_keys: BTreeMap::new() };
    for o in overrides {
        let key =
            set_dotted(&mut document, o).map_err(|message| LaunchError::new(o.origin(), Some(&o.key), message))?;
        origins.set_keys.insert(key, o.origin());
    }
    // TOML allows nan and inf; no key of a launch file means either, and the checks below
    // (and the physics) can then assume finite numbers.
    document.iter().try_for_each(|(key, value)| check_finite(&origins, key, value))?;
    // The launcher's own table: taken out of every file, read only from a run's.
    let run_vectors = run_vectors::take(&mut document, &origins)?.filter(|_| from_run);
    if from_run && run_vectors.is_none() {
        return Err(origins.error(
            run_vectors::KEY,
            "missing: a stage of your own reads the run's vectors from the launch.toml `looplab run` writes; start \
             it with the looplab of the same version",
        ));
    }

    let declared_schema;
    let schema = if declared::is_declared(&document) {
        declared_schema = declared::declared_schema(&document, &origins)?;
        &declared_schema
    } else {
        let scenario_name = match document.get("scenario") {
            Some(toml::Value::String(s)) => s.clone(),
            _ => {
                return Err(origins.error("scenario", format!("missing or not a string; allowed: {}", names(catalog))));
            }
        };
        match (&run_vectors, find(catalog, &scenario_name)) {
            (Some(run), _) => &run.schema,
            (None, Some(schema)) => schema,
            (None, None) => {
                return Err(origins
                    .error("scenario", format!("unknown scenario \"{scenario_name}\"; allowed: {}", names(catalog))));
            }
        }
    };
    schema.check_fits()?;

    // Top-level keys: the shared ones, then the scenario's sections; anything else is a typo. A
    // run's file was checked so when the launcher resolved it, and its vectors name no sections.
    let sections = sections(schema);
    let allowed: BTreeSet<&str> = common_keys().iter().copied().chain(sections.iter().map(String::as_str)).collect();
    for key in document.keys() {
        if run_vectors.is_none() && !allowed.contains(key.as_str()) {
            return Err(origins.error(
                key,
                format!(
                    "unknown key; allowed at the top level: {}",
                    allowed.iter().copied().collect::<Vec<_>>().join(", ")
                ),
            ));
        }
    }
    let mut common_table = toml::Table::new();
    for &key in common_keys() {
        if let Some(v) = document.get(key) {
            common_table.insert(key.to_owned(), v.clone());
        }
    }
    let common: CommonKeys = deserialize_at(&origins, "", toml::Value::Table(common_table))?;
    let hosts = Hosts::parse(&common.hosts, |key, message| origins.error(key, message))?;
    let current = std::env::current_dir().unwrap_or_default();
    let launch_folder = launch_folder.map(|f| current.join(f));
    let mut stages = Stages::parse(
        &common.stages,
        |key| match &launch_folder {
            Some(folder) if origins.of(key) == origins.file => folder.clone(),
            _ => current.clone(),
        },
        |key, message| origins.error(key, message),
    )?;
    if let Some(toml::Value::Table(table)) = document.get_mut("stages") {
        stages.write_dirs(table);
    }
    // A declared plant's model path is relative to the launch file's folder; the loop processes
    // read the resolved file from the run folder, so the folder is written into it (as a
    // stage's `dir`), absolute (a relative `folder` is relative to the file that gives it).
    if schema.name == declared::DECLARED
        && let Some(toml::Value::Table(plant)) = document.get_mut("plant")
    {
        let base = match &launch_folder {
            Some(folder) if origins.of("plant.folder") == origins.file => folder.clone(),
            _ => current.clone(),
        };
        let folder = match plant.get("folder") {
            Some(toml::Value::String(folder)) => crate::config::stages::joined(&base, Path::new(folder)),
            _ => base,
        };
        plant.insert("folder".into(), toml::Value::String(folder.display().to_string()));
    }
    // A built-in scenario's [plant] is its own; only a declared system's may name a Python class,
    // found in the plant's folder, and the launcher starts it there.
    if schema.name == declared::DECLARED {
        let folder = document.get("plant").and_then(|p| p.get("folder")).and_then(|f| f.as_str()).map(PathBuf::from);
        stages.plant = python_plant::parse(&document, folder.unwrap_or_else(|| current.clone()))
            .map_err(|message| origins.error(python_plant::KEY, message))?;
    }

    // In an open-loop replay the processes that play the recording back are LoopLab's own,
    // whatever the file runs in their place.
    if let Some(replay) = &common.replay {
        stages.commands.retain(|role, _| !replay.plays_back(*role));
        if replay.plays_back(crate::contract::role::Role::Plant) {
            stages.plant = None;
        }
    }

    let mut sensors: BTreeMap<String, SensorSpec> = common.sensors.into_iter().filter(|(_, s)| s.enabled).collect();
    for (name, sensor) in &mut sensors {
        if schema.name == declared::DECLARED {
            sensor.signal = name.clone();
        } else if !sensor.reads.is_empty() {
            return Err(origins.error(
                &format!("sensors.{name}.reads"),
                "is for a declared system (no scenario, a [system] table); a scenario's sensor names its signal",
            ));
        }
    }
    let gates = (common.gate.fail_on.iter().enumerate())
        .map(|(i, text)| Gate::parse(text).map_err(|message| origins.error(&format!("gate.fail_on.{i}"), message)))
        .collect::<Result<_, _>>()?;
    let config = LaunchConfig {
        gates,
        scenario: if schema.name == declared::DECLARED { declared::DECLARED.to_owned() } else { common.scenario },
        mode: common.mode,
        rate_hz: common.rate_hz,
        deadline_us: common.deadline_us,
        explain_over_us: common.explain_over_us,
        probe: common.probe,
        trace_sched: common.trace_sched,
        duration_s: common.duration_s,
        seed: common.seed,
        sensors,
        faults: common.faults,
        supervision: common.supervision,
        wait: common.wait,
        realtime: common.realtime,
        hosts,
        stages,
        replay: common.replay,
        document,
        schema: schema.clone(),
        input_limits: run_vectors.map(|run| run.input_limits),
        origins,
    };
    check_common(&config)?;
    check_sensors(&config)?;
    check_supervision(&config.supervision, &config)?;
    check_wait(&config.wait, &config)?;
    check_realtime(&config)?;
    if let Some(replay) = &config.replay {
        replay.check().map_err(|(key, message)| config.error(&key, message))?;
    }
    for (i, fault) in config.faults.iter().enumerate() {
        check_fault(fault, &config, &format!("faults.{i}"))?;
    }
    Ok(config)
}

/// A TOML syntax error on one line: where, and what.
fn toml_error(origin: &str, text: &str, e: &toml::de::Error) -> LaunchError {
    let message = e.message().lines().collect::<Vec<_>>().join(", ");
    let place = e.span().map(|span| {
        let before = &text[..span.start.min(text.len())];
        let line = before.matches('\n').count() + 1;
        let column = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
        format!("line {line}, column {column}: ")
    });
    LaunchError::new(origin, None, format!("not valid TOML: {}{message}", place.unwrap_or_default()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scenario whose estimate is larger than a message carries cannot be resolved: the error
    /// names the scenario and the vector (and no child process ever starts).
    #[test]
    fn the_common_keys_are_the_common_tables_fields_as_serde_names_them() {
        let keys = [
            "scenario",
            "mode",
            "rate_hz",
            "deadline_us",
            "explain_over_us",
            "probe",
            "trace_sched",
            "duration_s",
            "seed",
            "sensors",
            "faults",
            "supervision",
            "wait",
            "realtime",
            "hosts",
            "stages",
            "replay",
            "parameters",
            "gate",
        ];
        assert_eq!(common_keys(), keys);
    }

    #[test]
    fn a_scenario_whose_vectors_do_not_fit_the_messages_is_an_error_at_resolution() {
        use crate::config::schema::Component;
        const E60: &[Component] = &[Component::new("e", "1"); 60];
        let schema = ScenarioSchema {
            name: "made-up",
            file: "launch/made-up.toml",
            text: "scenario = \"made-up\"\nmode = \"lockstep\"\nrate_hz = 100.0\nduration_s = 1.0\nseed = 1\n",
            state: &[],
            input: &[],
            estimate: E60,
            signals: vec![],
        };
        let e = resolve_config("made-up", &[], std::slice::from_ref(&schema)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "scenario made-up: the estimate has 60 components, more than the 48 a message carries"
        );
        let fits = ScenarioSchema { estimate: &E60[..48], ..schema };
        let c = resolve_config("made-up", &[], &[fits]).unwrap();
        assert_eq!((c.scenario.as_str(), c.loops()), ("made-up", 100));
    }
}
