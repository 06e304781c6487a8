//! What a run's stages exchange, as the launcher resolved it: the state, input and estimate
//! (names and units), each signal a sensor can measure, and the input's limits. The launcher
//! writes them into the run's `launch.toml` (`[vectors]`), so that a stage of the user's own
//! (`runtime::stage::user_stage`, a Python plant) reads them from the run and serves any catalog's
//! scenario without that catalog. The table is the launcher's: one in a launch file given to
//! `looplab run` is replaced by the resolved one.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::config::error::LaunchError;
use crate::config::launch::declared::leak_components;
use crate::config::launch::types::{LaunchConfig, Origins, deserialize_at};
use crate::config::schema::{Component, ScenarioSchema, SignalLayout};

/// The top-level key of the table.
pub const KEY: &str = "vectors";

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct VectorsTable {
    /// The scenario the vectors are of (a report names it; a stage has no catalog to ask).
    scenario: String,
    state: Vec<Named>,
    input: Vec<Named>,
    estimate: Vec<Named>,
    /// One `[min, max]` per input component.
    input_limits: Vec<[f64; 2]>,
    signals: BTreeMap<String, Vec<Named>>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Named {
    name: String,
    unit: String,
}

fn named(components: &[Component]) -> Vec<Named> {
    components.iter().map(|c| Named { name: c.name.to_owned(), unit: c.unit.to_owned() }).collect()
}

fn leaked(named: Vec<Named>) -> &'static [Component] {
    leak_components(named.into_iter().map(|n| (n.name, n.unit)))
}

/// The run's `launch.toml`, which its processes load: `config`'s document, its folders relative
/// to `run_dir` (`run_paths`), and the run's vectors (`[vectors]`: `config`'s schema and
/// `input_limits`).
pub fn run_toml(config: &LaunchConfig, input_limits: &[(f64, f64)], run_dir: &std::path::Path) -> String {
    let schema = &config.schema;
    let table = VectorsTable {
        scenario: schema.name.to_owned(),
        state: named(schema.state),
        input: named(schema.input),
        estimate: named(schema.estimate),
        input_limits: input_limits.iter().map(|&(min, max)| [min, max]).collect(),
        signals: schema.signals.iter().map(|s| (s.name.to_owned(), named(s.components))).collect(),
    };
    let mut document = config.document.clone();
    crate::config::launch::run_paths::make_relative(&mut document, run_dir);
    let value = toml::Value::try_from(table).expect("names and finite numbers always serialise");
    document.insert(KEY.to_owned(), value);
    toml::to_string(&document).expect("a TOML table always serialises")
}

/// The run's vectors as a resolved `launch.toml` holds them.
pub struct RunVectors {
    /// What the file is checked against in place of a catalog's entry (no defaults: the file
    /// was checked when the launcher resolved it).
    pub schema: ScenarioSchema,
    pub input_limits: Vec<(f64, f64)>,
}

/// Takes `[vectors]` out of `document`; None where it has none.
pub(super) fn take(document: &mut toml::Table, origins: &Origins) -> Result<Option<RunVectors>, LaunchError> {
    let Some(value) = document.remove(KEY) else { return Ok(None) };
    let table: VectorsTable = deserialize_at(origins, KEY, value)?;
    if table.input_limits.len() != table.input.len() {
        return Err(origins.error(
            "vectors.input_limits",
            format!("has {} limits for {} inputs", table.input_limits.len(), table.input.len()),
        ));
    }
    let schema = ScenarioSchema {
        name: table.scenario.leak(),
        file: "",
        text: "",
        state: leaked(table.state),
        input: leaked(table.input),
        estimate: leaked(table.estimate),
        signals: table
            .signals
            .into_iter()
            .map(|(name, components)| SignalLayout { name: name.leak(), components: leaked(components) })
            .collect(),
    };
    let input_limits = table.input_limits.iter().map(|&[min, max]| (min, max)).collect();
    Ok(Some(RunVectors { schema, input_limits }))
}
