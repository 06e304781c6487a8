//! `looplab bench --plants [LAUNCH ...]`: what a plant costs per tick, and how fast the whole
//! loop runs in lockstep in one process, per plant: the built-in Rust pendulum, a declared
//! linear plant, and (where built here) the FMU and Python plants.
//!
//! - **step cost**: the scenario's `Box<dyn Plant>` stepped tick after tick with the input held
//!   (its initial input, else zero), exactly as the plant process calls it, restored to its
//!   initial state at the end of each run's worth of ticks (so an unstable plant stays in its
//!   physical range); the median of 5 timed batches, ns per tick.
//! - **plant tick, five processes**: a lockstep run through the five processes; per loop, from
//!   the command of tick k reaching the plant to the state of tick k+1 published (the step plus
//!   the plant's own handling), median, ns. The one figure for a plant that runs in a process of
//!   its own (a Python plant cannot be stepped in this one).
//! - **in-process loops/s**: `runtime::in_process` (plant, sensors, estimator, controller called in
//!   loop order in one thread, no IPC, nothing recorded) on the launch file in lockstep. A file
//!   whose stages run as processes of their own (`[stages.*] command`) cannot run there and says
//!   why.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use serde::Serialize;

use crate::config::launch::Override;
use crate::config::stages::StageCommand;
use crate::contract::msg::Stamp;
use crate::launcher::{Binaries, Outcome};
use crate::model::catalog::Catalog;
use crate::runtime::signals::{Interrupted, StopFlag};

/// A plant the bench measures by default.
pub struct PlantRow {
    pub label: &'static str,
    /// A scenario name or a launch file, relative to the source tree's root.
    pub target: &'static str,
    /// Builds what the row needs (an FMU) and returns the overrides that use it.
    pub prepare: Option<Prepare>,
}

/// Builds what a row needs into the bench's folder; the `--set` overrides that use it, or why not.
pub type Prepare = fn(&Path) -> Result<Vec<String>, String>;

/// The default rows, in order: adding a plant is one line. An FMU row names a declared pendulum
/// launch file and a `prepare` that builds the FMU into the bench's folder
/// (`declared::fmu::build_fmu`) and returns `plant.fmu=<path>`; a Python plant's row names its
/// launch file alone (it steps only in its own process: the five-process column).
pub const PLANT_ROWS: &[PlantRow] = &[
    PlantRow { label: "built-in Rust pendulum", target: "pendulum", prepare: None },
    PlantRow { label: "declared linear (launch/declared.toml)", target: "launch/declared.toml", prepare: None },
    PlantRow { label: "FMU pendulum, FMI 2.0 Model Exchange", target: FMU_PENDULUM, prepare: Some(fmu_model_exchange) },
    PlantRow { label: "FMU pendulum, FMI 2.0 Co-Simulation", target: FMU_PENDULUM, prepare: Some(fmu_co_simulation) },
    PlantRow { label: "Python pendulum", target: "services/examples/python-plant/pendulum_plant.toml", prepare: None },
];

/// The FMU pendulum with the built-in estimator and controller, so the rows differ in the plant only.
const FMU_PENDULUM: &str = "services/examples/fmu-plant/pendulum_fmu_state_feedback.toml";

fn fmu_model_exchange(out: &Path) -> Result<Vec<String>, String> {
    fmu_pendulum(out, "model-exchange")
}

fn fmu_co_simulation(out: &Path) -> Result<Vec<String>, String> {
    fmu_pendulum(out, "co-simulation")
}

/// Builds the project's pendulum FMU (FMI 2.0) into `out` and selects its `interface`.
fn fmu_pendulum(out: &Path, interface: &str) -> Result<Vec<String>, String> {
    use crate::scenarios::declared::fmu::{Version, build_fmu, pendulum_source};
    let fmu = out.join("pendulum.fmu");
    if !fmu.exists() {
        std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
        build_fmu(&pendulum_source(), Version::Fmi2, &fmu)?;
    }
    let path = toml::Value::String(fmu.display().to_string());
    Ok(vec![format!("plant.fmu={path}"), format!("plant.fmu_interface=\"{interface}\"")])
}

/// One plant's numbers.
#[derive(Debug, Clone, Serialize)]
pub struct PlantBench {
    pub label: String,
    pub target: String,
    /// What the plant says it is (its title).
    pub title: String,
    pub step_ticks: u64,
    /// The median of 5 batches, ns per tick; None: it cannot be stepped in this process (why).
    pub step_ns_per_tick: Option<f64>,
    pub step_refused: Option<String>,
    /// Five processes, lockstep: command k in to state k+1 out at the plant, median, ns.
    pub five_process_plant_tick_ns: f64,
    pub five_process_loops_per_s: f64,
    pub in_process_loops_per_s: Option<f64>,
    /// Why it has no in-process figure.
    pub in_process_refused: Option<String>,
}

/// The source tree's root (the bench is a developer's tool: it runs from a checkout).
fn source_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The target as `Catalog::resolve` takes it: a name, or a file found from here or the source tree.
fn locate(target: &str) -> Result<String, String> {
    if !target.ends_with(".toml") || Path::new(target).is_file() {
        return Ok(target.to_owned());
    }
    let in_tree = source_root().join(target);
    if in_tree.is_file() { Ok(in_tree.display().to_string()) } else { Err(format!("{target} is missing")) }
}

/// Steps `target`'s plant `ticks` times; ns per tick (median of 5 batches) and its title.
pub fn step_cost(catalog: &Catalog, target: &str, overrides: &[Override], ticks: u64) -> Result<(f64, String)> {
    let (config, scenario) = catalog.resolve(target, overrides)?;
    if let Some(plant) = &config.stages.plant {
        return Ok((python_step_cost(plant, target, overrides, ticks)?, scenario.title()));
    }
    let mut plant = scenario.plant();
    let input = match plant.initial_input() {
        Some(u) => u.to_vec(),
        None => vec![0.0; scenario.input_names().len()],
    };
    let (dt, run_ticks) = (config.dt(), config.loops().max(1));
    let batch = (ticks / 5).max(1);
    let mut k: u64 = 0;
    let mut per_tick = Vec::with_capacity(5);
    for _ in 0..5 {
        let mut elapsed = Duration::ZERO;
        let mut start = Instant::now();
        for _ in 0..batch {
            if k == run_ticks {
                // A fresh plant for the next run, built off the clock (a co-simulation FMU cannot
                // be set back to its initial state).
                elapsed += start.elapsed();
                plant = scenario.plant();
                k = 0;
                start = Instant::now();
            }
            plant.step(k as f64 * dt, &input, dt)?;
            std::hint::black_box(plant.state());
            k += 1;
        }
        elapsed += start.elapsed();
        per_tick.push(elapsed.as_nanos() as f64 / batch as f64);
    }
    per_tick.sort_by(f64::total_cmp);
    Ok((per_tick[2], scenario.title()))
}

/// A Python plant steps only in a python3 process with the `looplab` module: there, as its plant
/// process steps it (`looplab.plant_step_ns`). Overrides are not passed on: it measures the file.
fn python_step_cost(plant: &StageCommand, target: &str, overrides: &[Override], ticks: u64) -> Result<f64> {
    anyhow::ensure!(
        overrides.is_empty(),
        "a Python plant's step is measured from its launch file alone, without --set"
    );
    let launch = std::fs::canonicalize(target).with_context(|| format!("{target}: cannot find it"))?;
    let output = std::process::Command::new(&plant.command[0])
        .args(["-c", "import sys, looplab; print(looplab.plant_step_ns(sys.argv[1], int(sys.argv[2])))"])
        .arg(&launch)
        .arg(ticks.min(200_000).to_string())
        .current_dir(&plant.dir)
        .output()
        .with_context(|| format!("cannot start {}", plant.command[0]))?;
    let stderr = String::from_utf8_lossy(&output.stderr);
    anyhow::ensure!(output.status.success(), "python3: {}", stderr.trim().lines().last().unwrap_or("failed"));
    let text = String::from_utf8_lossy(&output.stdout);
    text.trim().parse().with_context(|| format!("python3 printed {text:?}, not a number of ns"))
}

/// Lockstep loops per second of `target` in one process over `loops` loops; Err(why) where the
/// launch file cannot run in one process.
pub fn in_process(
    catalog: &Catalog,
    target: &str,
    overrides: &[Override],
    loops: u64,
    stop: &StopFlag,
) -> Result<Result<f64, String>> {
    let (probe, _) = catalog.resolve(target, overrides)?;
    let mut all = overrides.to_vec();
    all.push(Override::parse("mode=lockstep")?);
    all.push(Override::parse(&format!("duration_s={}", loops as f64 / probe.rate_hz))?);
    let (config, scenario) = catalog.resolve(target, &all)?;
    if let Some(why) = crate::runtime::in_process::refusal(&config) {
        return Ok(Err(why));
    }
    let start = Instant::now();
    let reports = crate::runtime::in_process::run(&config, scenario.as_ref(), stop, |_| Ok(()))?;
    Ok(Ok(reports.plant.loops as f64 / start.elapsed().as_secs_f64()))
}

/// A lockstep run of `target` through the five processes over `loops` loops, in `dir`: the
/// plant's median tick (command k in → state k+1 out, ns) and the loops per second.
pub fn five_process(
    catalog: &Catalog,
    target: &str,
    overrides: &[Override],
    loops: u64,
    binaries: &Binaries,
    dir: &Path,
) -> Result<(f64, f64)> {
    let (probe, _) = catalog.resolve(target, overrides)?;
    let mut all = overrides.to_vec();
    all.push(Override::parse("mode=lockstep")?);
    all.push(Override::parse(&format!("duration_s={}", loops as f64 / probe.rate_hz))?);
    let (config, scenario) = catalog.resolve(target, &all)?;
    let dir = crate::launcher::create_run_dir(Some(dir), "bench")?;
    let (summary, outcome) = crate::launcher::run_once(&config, scenario.as_ref(), binaries, &dir, true)?;
    if outcome == Outcome::Interrupted {
        return Err(Interrupted.into());
    }
    let traces = super::traces(&dir)?;
    let (receive, publish) = (Stamp::PlantReceive as usize, Stamp::PlantPublish as usize);
    let mut ticks: Vec<u64> = traces.windows(2).map(|w| w[1][publish].saturating_sub(w[0][receive])).collect();
    if ticks.is_empty() {
        anyhow::bail!("{target}: the lockstep run recorded fewer than two whole loops");
    }
    ticks.sort_unstable();
    Ok((ticks[ticks.len() / 2] as f64, summary.loops_per_s))
}

/// How many ticks and loops each measurement takes.
#[derive(Debug, Clone, Copy)]
struct Sizes {
    step_ticks: u64,
    in_process_loops: u64,
    five_process_loops: u64,
}

/// One plant's row; Err: it could not be measured here (a file that does not resolve, a run
/// that failed), and the table says why.
fn measure(
    catalog: &Catalog,
    (label, target, path): (String, String, String),
    overrides: &[Override],
    sizes: Sizes,
    (binaries, dir): (&Binaries, &Path),
    stop: &StopFlag,
) -> Result<PlantBench> {
    let title = catalog.resolve(&path, overrides)?.1.title();
    // A plant that cannot be built in this process (a Python plant) fails its first step.
    let step = step_cost(catalog, &path, overrides, sizes.step_ticks).map(|(ns, _)| ns).map_err(|e| format!("{e:#}"));
    let (plant_tick, five_rate) = five_process(catalog, &path, overrides, sizes.five_process_loops, binaries, dir)?;
    let in_process = in_process(catalog, &path, overrides, sizes.in_process_loops, stop)?;
    if stop.requested() {
        return Err(Interrupted.into());
    }
    Ok(PlantBench {
        label,
        target,
        title,
        step_ticks: sizes.step_ticks,
        step_ns_per_tick: step.as_ref().ok().copied(),
        step_refused: step.err(),
        five_process_plant_tick_ns: plant_tick,
        five_process_loops_per_s: five_rate,
        in_process_loops_per_s: in_process.as_ref().ok().copied(),
        in_process_refused: in_process.err(),
    })
}

/// Measures `targets` (none: [`PLANT_ROWS`]), prints the table and writes `plants.json` in `out`.
pub fn run(catalog: &Catalog, targets: &[String], quick: bool, out: &Path, stop: &StopFlag) -> Result<Vec<PlantBench>> {
    let sizes = if quick {
        Sizes { step_ticks: 200_000, in_process_loops: 50_000, five_process_loops: 2_000 }
    } else {
        Sizes { step_ticks: 2_000_000, in_process_loops: 500_000, five_process_loops: 20_000 }
    };
    let binaries = crate::launcher::locate_binaries()?;
    let rows: Vec<(String, String, Option<Prepare>)> = if targets.is_empty() {
        PLANT_ROWS.iter().map(|r| (r.label.to_owned(), r.target.to_owned(), r.prepare)).collect()
    } else {
        targets.iter().map(|t| (t.clone(), t.clone(), None)).collect()
    };
    let mut results = Vec::new();
    let mut skipped = Vec::new();
    for (i, (label, target, prepare)) in rows.into_iter().enumerate() {
        let ready = locate(&target).and_then(|path| Ok((path, prepare.map_or(Ok(Vec::new()), |p| p(out))?)));
        let (path, sets) = match ready {
            Ok(ready) => ready,
            Err(why) => {
                skipped.push(format!("{label}: {why}"));
                continue;
            }
        };
        let overrides: Vec<Override> = sets.iter().map(|s| Override::parse(s)).collect::<Result<_, _>>()?;
        let dir = out.join(format!("lockstep-{i}"));
        match measure(catalog, (label.clone(), target, path), &overrides, sizes, (&binaries, &dir), stop) {
            Ok(row) => results.push(row),
            Err(e) if e.is::<Interrupted>() => return Err(e),
            Err(e) => skipped.push(format!("{label}: {e:#}")),
        }
    }
    crate::runtime::storage::run_file::write(
        &out.join("plants.json"),
        serde_json::to_string_pretty(&results)?.as_bytes(),
    )?;
    say_raw!("{}", render(&results, &skipped));
    Ok(results)
}

fn render(rows: &[PlantBench], skipped: &[String]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "\n  plants, lockstep: the step alone, the plant's tick in five processes, loops/s");
    let _ = writeln!(
        s,
        "    {:<42}{:>13}{:>16}{:>15}{:>15}",
        "plant", "step ns/tick", "5-proc tick ns", "5-proc loop/s", "1-proc loop/s"
    );
    for r in rows {
        let step = r.step_ns_per_tick.map_or("-".into(), |ns| format!("{ns:.1}"));
        let loops = r.in_process_loops_per_s.map_or("refused".into(), |rate| format!("{rate:.0}"));
        let _ = writeln!(
            s,
            "    {:<42}{:>13}{:>16.0}{:>15.0}{:>15}",
            r.label, step, r.five_process_plant_tick_ns, r.five_process_loops_per_s, loops
        );
        if let Some(why) = &r.step_refused {
            let _ = writeln!(s, "      step alone: {why}");
        }
        if let Some(why) = &r.in_process_refused {
            let _ = writeln!(s, "      in one process: {why}");
        }
    }
    for why in skipped {
        let _ = writeln!(s, "    skipped: {why}");
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The pendulum's plant steps and its loop runs in one process: positive, finite numbers.
    #[test]
    fn the_pendulum_has_a_step_cost_and_an_in_process_rate() {
        let catalog = crate::scenarios::builtin();
        let (ns, title) = step_cost(&catalog, "pendulum", &[], 5_000).unwrap();
        assert!(ns.is_finite() && ns > 0.0, "{ns}");
        assert!(title.contains("pendulum"), "{title}");
        let stop = StopFlag::install().unwrap();
        let rate = in_process(&catalog, "pendulum", &[], 2_000, &stop).unwrap().unwrap();
        assert!(rate.is_finite() && rate > 0.0, "{rate}");
    }

    /// A launch file whose controller is a process of its own is refused in one process, saying why.
    #[test]
    fn a_stage_command_is_refused_in_one_process() {
        let catalog = crate::scenarios::builtin();
        // Resolving checks only that the program exists; it never runs here.
        let sets = [Override::parse(r#"stages.controller.command=["/bin/true"]"#).unwrap()];
        let why = in_process(&catalog, "pendulum", &sets, 100, &StopFlag::install().unwrap()).unwrap().unwrap_err();
        assert!(why.contains("stages.controller.command"), "{why}");
    }

    #[test]
    fn a_missing_launch_file_is_skipped_with_its_name() {
        assert_eq!(locate("launch/nope.toml").unwrap_err(), "launch/nope.toml is missing");
        assert_eq!(locate("pendulum").unwrap(), "pendulum");
    }
}
