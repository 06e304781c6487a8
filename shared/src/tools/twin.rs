//! A lockstep run's faults judged against its fault-free twin: the same launch file without its
//! faults, run in this process (byte-identical to the five processes: `tests/trajectory_hashes.rs`),
//! its plant state compared with the run's loop by loop. A fault that changed nothing the plant
//! did (a killed stage that thawed its state and went on) then reads "no effect", where the error
//! against zero would count the run's own tracking error as the fault's (`summary::AgainstTwin`).

use std::path::Path;

use crate::config::faults::FaultKind;
use crate::config::launch::{LaunchConfig, Mode, Override};
use crate::contract::run_format::files;
use crate::launcher::summary::{AgainstTwin, Summary};
use crate::model::catalog::Catalog;
use crate::model::layout::VectorLayout;
use crate::model::scenario::Scenario;
use crate::tools::ToolError;
use crate::tools::run_folder::RunFolder;

/// Where a lockstep run with faults (not a replay) gets its twin: every fault's `against_twin`
/// is filled in `summary` (and a note where it cannot be computed). `target` and `overrides`
/// resolved `config`, the run's.
pub fn judge_against_twin(
    catalog: &Catalog,
    (target, overrides): (&str, &[Override]),
    config: &LaunchConfig,
    scenario: &dyn Scenario,
    run_dir: &Path,
    summary: &mut Summary,
) -> Result<(), ToolError> {
    if config.mode != Mode::Lockstep || config.faults.is_empty() || config.replay.is_some() {
        return Ok(());
    }
    let mut overrides = overrides.to_vec();
    overrides.push(Override {
        key: "faults".into(),
        text: "faults=[] (the fault-free twin)".into(),
        value: toml::Value::Array(vec![]),
        append: false,
    });
    let (twin_config, twin_scenario) =
        catalog.resolve(target, &overrides).map_err(|e| ToolError::BadInput(e.to_string()))?;
    if let Some(why) = crate::runtime::in_process::refusal(&twin_config) {
        summary
            .notes
            .push(format!("the faults are judged against zero error, not against the same run without them: {why}"));
        return Ok(());
    }
    let twin_dir = run_dir.join("twin");
    std::fs::create_dir_all(twin_dir.join(files::LOGS)).map_err(|e| ToolError::Failed(e.into()))?;
    crate::launcher::in_process::run_in_process(&twin_config, twin_scenario.as_ref(), &twin_dir)?;
    let (run, twin) = (plant_states(run_dir, config, scenario)?, plant_states(&twin_dir, config, scenario)?);
    let _ = std::fs::remove_dir_all(&twin_dir);
    let loops = run.first().map_or(0, Vec::len);
    if twin.first().map_or(0, Vec::len) != loops {
        summary
            .notes
            .push("the faults are judged against zero error: the fault-free twin ran another number of loops".into());
        return Ok(());
    }
    let (run_error, twin_error) = (errors(config, scenario, &run), errors(config, scenario, &twin));
    let band = scenario.error_measure().recovery_band;
    let same = |k: usize| {
        run.iter().zip(&twin).all(|(a, b)| a[k].to_bits() == b[k].to_bits() || (a[k].is_nan() && b[k].is_nan()))
    };
    for (report, spec) in summary.faults.iter_mut().zip(&config.faults) {
        let (from, until) = spec.ticks(config.rate_hz);
        let from = (from as usize).min(loops);
        let end = match spec.kind {
            FaultKind::Kill => from,
            _ => until.map_or(loops, |u| (u as usize).min(loops)),
        };
        let departed = (from..loops).find(|&k| !same(k));
        let extra = |k: usize| run_error[k] - twin_error[k];
        let worst = (from..loops).map(extra).fold(0.0, f64::max);
        let last_outside = (end..loops).rev().find(|&k| crate::contract::limits::beyond(extra(k).abs(), band));
        report.against_twin = Some(AgainstTwin {
            departed_at_s: departed.map(|k| k as f64 / config.rate_hz),
            worst_extra_error: worst,
            recovery_s: match (departed, last_outside) {
                (None, _) | (_, None) => Some(0.0),
                (Some(_), Some(k)) if k + 1 == loops => None,
                (Some(_), Some(k)) => Some((k + 1 - end) as f64 / config.rate_hz),
            },
        });
    }
    Ok(())
}

/// The plant's state in a run folder's trajectory.csv: one column per state, one value per loop.
pub fn plant_states(dir: &Path, config: &LaunchConfig, scenario: &dyn Scenario) -> Result<Vec<Vec<f64>>, ToolError> {
    let layout = VectorLayout::new(config, scenario);
    let table = RunFolder::open(dir, &[files::TRAJECTORY])?.table(files::TRAJECTORY)?;
    layout.trajectory_columns()[2..2 + layout.state.len()].iter().map(|name| table.floats(name)).collect()
}

/// The scenario's error measure at every loop of `states` (as [`plant_states`] reads them).
pub fn errors(config: &LaunchConfig, scenario: &dyn Scenario, states: &[Vec<f64>]) -> Vec<f64> {
    let measure = scenario.error_measure();
    let loops = states.first().map_or(0, Vec::len);
    (0..loops)
        .map(|k| (measure.of_state)(k as f64 / config.rate_hz, &states.iter().map(|c| c[k]).collect::<Vec<_>>()))
        .collect()
}
