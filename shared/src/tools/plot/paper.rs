//! `looplab plot --paper SCENARIO`: a figure of the paper behind a scenario, reproduced. Each
//! scenario declares its paper's figures beside its entry (`scenarios/<name>/paper.rs`): the
//! cases to run and how to draw them from the runs. This runs the cases' launch files in
//! lockstep in this process (a run folder each, under the output folder), reads the run folders
//! back and draws the figures there.

use std::path::{Path, PathBuf};

use anyhow::Context as _;

use crate::config::launch::Override;
use crate::launcher::create_run_dir;
use crate::launcher::in_process::run_in_process;
use crate::model::catalog::Catalog;
use crate::model::figure::{PaperCase, PaperTarget, RunColumns};
use crate::tools::ToolError;
use crate::tools::plot::figure::Draw as _;
use crate::tools::plot::run::RunData;

/// Runs `case` in this process into `out/<name>` and reads the run folder back.
fn run_case(case: &PaperCase, out: &Path, catalog: &Catalog) -> anyhow::Result<RunData> {
    let overrides = std::iter::once(&"mode=lockstep")
        .chain(case.overrides)
        .map(|text| Override::parse(text))
        .collect::<Result<Vec<_>, _>>()?;
    let resolved = match case.target {
        PaperTarget::Scenario(name) => catalog.resolve(name, &overrides),
        PaperTarget::File(file, text) => {
            let path = out.join(file);
            crate::runtime::storage::run_file::write(&path, text.as_bytes())?;
            catalog.resolve(&path.to_string_lossy(), &overrides)
        }
    };
    let (config, scenario) = resolved?;
    let dir = create_run_dir(Some(&out.join(case.name)), &config.scenario)?;
    say!("running {} ({}, {} s in lockstep) ...", case.name, scenario.title(), config.duration_s);
    run_in_process(&config, scenario.as_ref(), &dir)?;
    Ok(RunData::read(&dir, catalog)?)
}

/// Runs the experiments behind `scenario`'s paper figure into `out` (a new or empty folder; by
/// default `runs/<time>-paper-<scenario>`) and draws the figures there. Returns their paths.
pub fn paper_figures(catalog: &Catalog, scenario: &str, out: Option<&Path>) -> Result<Vec<PathBuf>, ToolError> {
    let Some(paper) = catalog.find(scenario).and_then(|entry| entry.paper) else {
        let with_figures: Vec<&str> = catalog.entries().iter().filter(|e| e.paper.is_some()).map(|e| e.name).collect();
        return Err(ToolError::BadInput(format!(
            "--paper {scenario}: no paper figure for it; allowed: {}",
            with_figures.join(", ")
        )));
    };
    let out = match out {
        Some(dir) => {
            if dir.exists() && std::fs::read_dir(dir).map(|mut d| d.next().is_some()).unwrap_or(true) {
                return Err(ToolError::BadInput(format!(
                    "--out {}: exists and is not an empty folder; give a new or empty folder",
                    dir.display()
                )));
            }
            dir.to_path_buf()
        }
        None => {
            PathBuf::from("runs").join(format!("{}-paper-{scenario}", chrono::Local::now().format("%Y%m%d-%H%M%S")))
        }
    };
    std::fs::create_dir_all(&out).with_context(|| format!("create {}", out.display()))?;
    let runs = paper.cases.iter().map(|case| run_case(case, &out, catalog)).collect::<anyhow::Result<Vec<_>>>()?;
    let columns: Vec<&dyn RunColumns> = runs.iter().map(|run| run as &dyn RunColumns).collect();
    let mut written = Vec::new();
    for (name, figure) in (paper.draw)(&columns)? {
        let path = out.join(name);
        figure.draw(&path)?;
        written.push(path);
    }
    Ok(written)
}
