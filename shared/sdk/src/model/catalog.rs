//! The scenarios a launcher and its loop processes can run, as a value: each binary is handed
//! its catalog (`cli::main_with`, `runtime::stage::child::process_main_with`), so a crate outside this
//! one can run its own scenarios beside the built-in ones (`scenarios::builtin()`).

use std::path::Path;

use crate::config::launch::{self, LaunchConfig, LaunchError, Override};
use crate::config::schema::ScenarioSchema;
use crate::model::scenario::{Scenario, ScenarioEntry};

/// Builds the scenario a declared system's configuration describes (no `scenario`, a
/// `[system]` table); `check_model`: load the plant's model once to find its errors now (the
/// launcher resolving a file), not in each loop process.
pub type DeclaredBuild = fn(&LaunchConfig, bool) -> Result<Box<dyn Scenario>, LaunchError>;

/// Scenarios by name, each name once, in the order they were added, and what builds a declared
/// system, if this catalog runs them.
#[derive(Debug, Clone, Default)]
pub struct Catalog {
    entries: Vec<ScenarioEntry>,
    declared: Option<DeclaredBuild>,
}

impl Catalog {
    /// A catalog of `entries`; a later entry replaces an earlier one of the same name.
    pub fn new(entries: impl IntoIterator<Item = ScenarioEntry>) -> Self {
        entries.into_iter().fold(Self::default(), Self::with)
    }

    /// This catalog with `entry` added, or in place of the entry of the same name.
    ///
    /// Panics if the entry's defaults do not name it (`scenario = "<name>"`): resolving its
    /// name would then run the scenario the defaults name instead.
    pub fn with(mut self, entry: ScenarioEntry) -> Self {
        let named = entry.defaults().get("scenario").and_then(|v| v.as_str()).map(str::to_owned);
        assert!(
            named.as_deref() == Some(entry.name),
            "the defaults of scenario \"{}\" ({}) must say scenario = \"{}\", not {named:?}",
            entry.name,
            entry.file,
            entry.name
        );
        match self.entries.iter_mut().find(|e| e.name == entry.name) {
            Some(same_name) => *same_name = entry,
            None => self.entries.push(entry),
        }
        self
    }

    /// This catalog, running declared systems with `build`.
    pub fn with_declared(mut self, build: DeclaredBuild) -> Self {
        self.declared = Some(build);
        self
    }

    pub fn entries(&self) -> &[ScenarioEntry] {
        &self.entries
    }

    /// The entry of this name.
    pub fn find(&self, name: &str) -> Option<&ScenarioEntry> {
        self.entries.iter().find(|e| e.name == name)
    }

    /// The names, comma-separated, for error messages.
    pub fn names(&self) -> String {
        self.entries.iter().map(|e| e.name).collect::<Vec<_>>().join(", ")
    }

    /// What the configuration layer checks launch files against.
    pub fn schemas(&self) -> Vec<ScenarioSchema> {
        self.entries.iter().map(ScenarioEntry::schema).collect()
    }

    /// Resolves what the user asked to run, a scenario name or a launch-file path, with
    /// overrides, into a checked configuration and the scenario it describes.
    pub fn resolve(
        &self,
        target: &str,
        overrides: &[Override],
    ) -> Result<(LaunchConfig, Box<dyn Scenario>), LaunchError> {
        let (config, scenario) = self.build(launch::resolve_config(target, overrides, &self.schemas())?, true)?;
        launch::check_python_plant(&config)?;
        Ok((config, scenario))
    }

    /// Reads a resolved launch file written by the launcher (what each loop process does).
    pub fn load_resolved(&self, path: &Path) -> Result<(LaunchConfig, Box<dyn Scenario>), LaunchError> {
        self.build(launch::load_resolved_config(path, &self.schemas())?, false)
    }

    fn build(&self, config: LaunchConfig, check_model: bool) -> Result<(LaunchConfig, Box<dyn Scenario>), LaunchError> {
        if config.is_declared() {
            let build = self.declared.ok_or_else(|| {
                config.error("system", "this build of LoopLab runs no declared systems (its catalog has no builder)")
            })?;
            let scenario = build(&config, check_model)?;
            return Ok((config, scenario));
        }
        let entry = self.find(&config.scenario).expect("the configuration names a scenario of the catalog");
        let scenario = entry.build(&config)?;
        Ok((config, scenario))
    }
}
