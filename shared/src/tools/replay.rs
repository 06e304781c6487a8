//! `looplab replay RUN_DIR --stage ROLE[=PROGRAM ARGS]`: runs one stage on the inputs recorded
//! in a run folder, loop by loop, in lockstep, and writes a new run folder.
//!
//! Open loop (the default), the plant, and every stage but the replayed one, play the
//! recording back (`runtime::replay::playback`): the stage gets exactly the messages its recording got,
//! and its outputs go nowhere that changes what comes next. Closed loop (`--closed-loop`), the
//! whole loop runs again from the recording's initial state, the recorded plant replaced by the
//! scenario's (or the declared system's) model: a lockstep run of the recording's launch file
//! with the stage changed, which reproduces a lockstep recording exactly.
//!
//! A real-time recording is replayed in lockstep too, as what the stage saw: the loops it
//! skipped in the recording (it was dead or stopped, or a newer input overtook them) are withheld
//! from it again, it restarts at the loops where its recording restarted (a `kill` fault there,
//! thawing what it froze, as a restarted process does), and a `delay` fault, which in real
//! time held its outputs but did not change them, is left out; the loops it held are reported.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context as _;
use serde::Serialize;

use crate::config::faults::{FaultKind, FaultSpec};
use crate::config::launch::{LaunchConfig, Mode, Override};
use crate::config::replay::{KEY, ReplaySpec};
use crate::contract::msg::Message;
use crate::contract::role::Role;
use crate::contract::run_format::files;
use crate::launcher::outcome::Outcome;
use crate::model::catalog::Catalog;
use crate::model::layout::VectorLayout;
use crate::runtime::replay::recording_reader::{self, RecordedLoop};
use crate::runtime::stage::faults::{AddedDelay, StageFaults};
use crate::tools::ToolError;

/// `looplab replay`'s options.
#[derive(Debug, Clone, clap::Args)]
#[command(after_help = "Examples:\n  looplab run pendulum --mode lockstep --out runs/golden\n  \
looplab replay runs/golden --stage estimator --out runs/same\n  \
looplab replay runs/golden --stage estimator --set 'estimator.bias-observer.poles=[-30, -35, -40]'\n  \
looplab replay runs/golden --stage 'estimator=python3 my_estimator.py'\n  \
looplab diff runs/golden runs/same\n\
Exit codes: 0 the replay ran (`looplab diff` judges its outputs), 1 it failed, 2 bad input.")]
pub struct ReplayArgs {
    /// The recorded run folder (its run.mcap holds every message of every loop)
    #[arg(value_name = "RUN_DIR")]
    pub recording: PathBuf,
    /// The stage to run: sensors, estimator or controller, as recorded (changed by --set), or
    /// with `=PROGRAM ARGS` a program of your own in its place, as `[stages.<role>] command`
    #[arg(long, value_name = "ROLE[=PROGRAM ARGS]")]
    pub stage: String,
    /// Override a key of the recording's launch file, as for `looplab run`. Repeatable
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Run everything downstream of the stage too (in a loop: every process), from the
    /// recording's initial state, instead of playing the recording back to it
    #[arg(long)]
    pub closed_loop: bool,
    /// Run in this one process instead of as processes over shared memory (same bytes)
    #[arg(long)]
    pub in_process: bool,
    /// The run folder to write (default: runs/<time>-replay-<scenario>)
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Judged on the replay's run, with the recording's [gate] fail_on
    #[command(flatten)]
    pub gates: crate::launcher::gate::GateArgs,
}

/// What a replay did, as `replay.json` keeps it.
#[derive(Debug, Clone, Serialize)]
pub struct ReplayReport {
    pub recording: PathBuf,
    pub run_dir: PathBuf,
    pub stage: Role,
    /// The program run in the stage's place, if one was.
    pub program: Option<Vec<String>>,
    pub closed_loop: bool,
    pub in_process: bool,
    /// The recording's mode.
    pub recorded_mode: Mode,
    pub loops: u64,
    pub seconds: f64,
    pub loops_per_s: f64,
    /// Loops the recorded stage did not compute (inclusive ranges), withheld from the replayed one.
    pub skipped: Vec<[u64; 2]>,
    /// Loops the replayed stage did not compute: the same, when the replay saw what the
    /// recording saw.
    pub skipped_in_replay: Vec<[u64; 2]>,
    /// Loops where the recorded stage restarted (a new incarnation's first loop).
    pub restarts: Vec<u64>,
    /// Loops whose output the recorded stage sent but whose state it had not kept when it was
    /// killed (real time): its successor thawed the loop before's, and so does the replay's,
    /// which is not given these loops.
    pub thawed_older: Vec<u64>,
    /// Loops whose outputs a `delay` fault held back in the recording (real time: the same
    /// outputs, later; lockstep: the outputs of earlier loops, replayed alike).
    pub delayed: Vec<[u64; 2]>,
    /// The stage's outputs against the recording's.
    pub outputs: OutputComparison,
    /// Closed loop: the plant's state against the recording's.
    pub state: Option<OutputComparison>,
    pub outcome: String,
    /// `--fail-on` and the recording's `[gate]`, judged on the replay's run.
    #[serde(skip)]
    pub gates: crate::launcher::gate::Judged,
}

/// The replayed stage's outputs against the recorded ones, over the loops both computed.
#[derive(Debug, Clone, Default, Serialize)]
pub struct OutputComparison {
    /// Loops where both have an output to compare.
    pub compared: u64,
    /// Of those, loops whose outputs are equal bit for bit.
    pub identical: u64,
    /// The first loop that differs.
    pub first_difference: Option<u64>,
    /// Per output field that differs: its column and the largest |difference|.
    pub largest: Vec<(String, f64)>,
}

/// What to give when a program or model the recording ran is not where its launch.toml says
/// (relative to the run folder).
const MOVED_HINT: &str = "give its folder with --set stages.ROLE.dir=FOLDER (a Python or FMU plant's: --set \
                          plant.folder=FOLDER), or run another with --stage ROLE=PROGRAM ARGS";

/// Runs the replay `args` asks for and writes its run folder; returns what it did.
pub fn replay(args: &ReplayArgs, catalog: &Catalog) -> Result<ReplayReport, ToolError> {
    let bad = |message: String| ToolError::BadInput(message);
    let recording = args
        .recording
        .canonicalize()
        .map_err(|e| bad(format!("{}: cannot open the recording: {e}", args.recording.display())))?;
    let launch_file = recording.join(files::LAUNCH);
    if std::fs::symlink_metadata(&launch_file).is_err() {
        return Err(bad(format!("{}: not a run folder (it has no launch.toml)", recording.display())));
    }
    let (role, program) = parse_stage(&args.stage).map_err(|e| bad(format!("--stage {}: {e}", args.stage)))?;
    let gates = args.gates.gates().map_err(bad)?;
    let target = launch_file.display().to_string();
    // As recorded, unchecked: a program the recording ran may not be where it was (a moved
    // golden run), and is needed only where the replay runs it.
    let (recorded_config, recorded_scenario) = catalog.load_resolved(&launch_file).map_err(|e| bad(e.to_string()))?;
    let layout = VectorLayout::new(&recorded_config, recorded_scenario.as_ref());
    let loops =
        recording_reader::load(&recording, &layout, recorded_config.loops()).map_err(|e| bad(format!("{e:#}")))?;
    let seen = RecordedStage::new(&recorded_config, role, &loops);

    let mut overrides = vec![set("mode", "lockstep".into())];
    // A recording that ended early (a run stopped or killed) is replayed as far as it goes.
    if (loops.len() as u64) < recorded_config.loops() {
        let seconds = loops.len() as f64 / recorded_config.rate_hz;
        let mut duration = set("duration_s", toml::Value::Float(seconds));
        duration.text = format!("duration_s = {seconds} (the recording's {} loops)", loops.len());
        overrides.push(duration);
    }
    for text in &args.set {
        overrides.push(Override::parse(text).map_err(|e| bad(e.to_string()))?);
    }
    if let Some(program) = &program {
        let dir = std::env::current_dir().context("the current folder").map_err(ToolError::Failed)?;
        let mut stage = toml::Table::new();
        stage.insert("command".into(), toml::Value::Array(program.iter().cloned().map(toml::Value::String).collect()));
        stage.insert("dir".into(), toml::Value::String(dir.display().to_string()));
        let mut stage = set(&format!("stages.{role}"), toml::Value::Table(stage));
        stage.text = format!("stages.{role}.command (from --stage {})", args.stage);
        overrides.push(stage);
    }
    if !args.closed_loop {
        let faults = seen.faults(&recorded_config);
        overrides.push(set("faults", toml::Value::try_from(&faults).expect("faults convert to TOML")));
    }
    let mut spec = ReplaySpec {
        recording: recording.clone(),
        stage: role.name().to_string(),
        closed_loop: args.closed_loop,
        skipped: if args.closed_loop { Vec::new() } else { seen.skipped.clone() },
        recorded_in_real_time: recorded_config.mode == Mode::Realtime && !args.closed_loop,
    };
    let resolve = |spec: &ReplaySpec| {
        let mut overrides = overrides.clone();
        overrides.push(set(KEY, toml::Value::try_from(spec).expect("a replay converts to TOML")));
        catalog.resolve(&target, &overrides).map_err(|e| {
            let moved = e.key.as_deref().is_some_and(|key| key.starts_with("stages.") || key.starts_with("plant."));
            bad(if moved { format!("{e} (a moved recording: {MOVED_HINT})") } else { e.to_string() })
        })
    };
    let (config, scenario) = resolve(&spec)?;
    if VectorLayout::new(&config, scenario.as_ref()) != layout {
        return Err(bad(format!(
            "--set: the replay's vectors or sensors differ from the recording's ({}); a replay feeds the stage \
             the recorded messages, so they must be the same",
            launch_file.display()
        )));
    }
    if args.in_process
        && let Some(why) = crate::runtime::in_process::refusal(&config)
    {
        return Err(bad(format!("--in-process: {why}; leave out --in-process to run the processes")));
    }
    let binaries = if args.in_process {
        None
    } else {
        Some(crate::launcher::locate_binaries().map_err(|e| bad(format!("{e:#}")))?)
    };
    let run_dir = crate::launcher::create_run_dir(args.out.as_deref(), &format!("replay-{}", config.scenario))
        .map_err(|e| bad(format!("{e:#}")))?;
    let attempt = |spec: &ReplaySpec, dir: &std::path::Path| -> Result<Attempt, ToolError> {
        let (config, scenario) = resolve(spec)?;
        let started = Instant::now();
        let (summary, outcome) = match &binaries {
            Some(binaries) => {
                crate::runtime::storage::run_storage::clean_abandoned_runs();
                let view = crate::launcher::LiveView::Quiet;
                crate::launcher::run_with(&config, scenario.as_ref(), binaries, dir, view)?
            }
            None => crate::launcher::in_process::run_in_process(&config, scenario.as_ref(), dir)?,
        };
        let seconds = started.elapsed().as_secs_f64();
        let replayed = recording_reader::load(dir, &layout, config.loops())?;
        let outputs = compare(output_columns(role, &layout), |l| output_values(role, &layout, l), &loops, &replayed);
        Ok(Attempt {
            skipped: RecordedStage::new(&config, role, &replayed).skipped,
            summary,
            outcome,
            seconds,
            replayed,
            outputs,
        })
    };
    let mut ran = attempt(&spec, &run_dir)?;
    // A real-time recording's stage killed after it sent an output and before it kept its state
    // (a window of about a microsecond) had its successor thaw the state of the loop before. The
    // same stage and settings then differ from the restart on: replayed again with that loop
    // withheld from the stage, they must match from there; if they do, that is what happened.
    let (mut thawed_older, mut tried) = (Vec::new(), Vec::new());
    let same_stage = program.is_none() && args.set.is_empty() && !args.closed_loop;
    while same_stage
        && recorded_config.mode == Mode::Realtime
        && let Some(first) = ran.outputs.first_difference
        && let Some(&restart) = seen.restarts.iter().rev().find(|&&r| r <= first)
        && !tried.contains(&restart)
        && let Some(last) = (0..restart).rev().find(|&k| !spec.skipped(k))
    {
        tried.push(restart);
        let mut older = spec.clone();
        older.skipped.push([last, last]);
        older.skipped.sort_unstable();
        let trial_dir = run_dir.with_extension("older-thaw");
        let _ = std::fs::remove_dir_all(&trial_dir);
        let trial = attempt(&older, &trial_dir)?;
        let _ = std::fs::remove_dir_all(&trial_dir);
        if trial.outputs.first_difference.is_some_and(|f| f <= first) {
            break;
        }
        // It is: the run folder gets that replay (lockstep: the same bytes as the trial's).
        std::fs::remove_dir_all(&run_dir).with_context(|| format!("clear {}", run_dir.display()))?;
        spec = older;
        ran = attempt(&spec, &run_dir)?;
        thawed_older.push(last);
    }
    let Attempt { summary, outcome, seconds, replayed, outputs, skipped } = ran;
    let gates: Vec<_> = config.gates.iter().cloned().chain(gates).collect();
    let gates = crate::launcher::gate::judge(&gates, &summary).map_err(|e| bad(format!("--fail-on {e}")))?;
    let report = ReplayReport {
        recording,
        run_dir: run_dir.clone(),
        stage: role,
        program,
        closed_loop: args.closed_loop,
        in_process: args.in_process,
        recorded_mode: recorded_config.mode,
        loops: summary.loops,
        seconds,
        loops_per_s: summary.loops as f64 / seconds,
        skipped: seen.skipped.clone(),
        skipped_in_replay: skipped,
        restarts: seen.restarts.clone(),
        thawed_older,
        delayed: seen.delayed.clone(),
        outputs,
        state: args.closed_loop.then(|| {
            let columns = layout.trajectory_columns()[2..2 + layout.state.len()].to_vec();
            compare(columns, |l| l.state.map(|s| s.x[..layout.state.len()].to_vec()), &loops, &replayed)
        }),
        outcome: match &outcome {
            Outcome::Completed => "completed".into(),
            other => format!("{other:?}"),
        },
        gates,
    };
    let json = serde_json::to_string_pretty(&report).expect("a report is JSON");
    std::fs::write(run_dir.join(files::REPLAY), json + "\n")
        .with_context(|| format!("write {}", run_dir.join(files::REPLAY).display()))?;
    if !matches!(outcome, Outcome::Completed) {
        return Err(ToolError::Failed(anyhow::anyhow!(
            "the replay did not complete ({}); see {}",
            report.outcome,
            run_dir.join(files::LOGS).display()
        )));
    }
    Ok(report)
}

/// One run of a replay.
struct Attempt {
    summary: crate::launcher::summary::Summary,
    outcome: Outcome,
    seconds: f64,
    replayed: Vec<RecordedLoop>,
    outputs: OutputComparison,
    /// The loops the replayed stage did not compute.
    skipped: Vec<[u64; 2]>,
}

fn set(key: &str, value: toml::Value) -> Override {
    Override { key: key.into(), text: format!("{key}=… (the replay's)"), value, append: false }
}

/// `estimator` or `estimator=python3 my_estimator.py`.
fn parse_stage(text: &str) -> Result<(Role, Option<Vec<String>>), String> {
    let (name, program) = match text.split_once('=') {
        Some((name, program)) => (name.trim(), Some(program)),
        None => (text.trim(), None),
    };
    let allowed = Role::STAGES.iter().map(|r| r.name()).collect::<Vec<_>>().join(", ");
    let role = name
        .parse::<Role>()
        .ok()
        .filter(|r| Role::STAGES.contains(r))
        .ok_or_else(|| format!("unknown stage \"{name}\"; allowed: {allowed}"))?;
    let program = match program {
        Some(text) => match shlex::split(text) {
            Some(words) if !words.is_empty() => Some(words),
            _ => return Err("expected a program and its arguments after `=`".into()),
        },
        None => None,
    };
    Ok((role, program))
}

/// What the recorded stage did, loop by loop.
struct RecordedStage {
    role: Role,
    mode: Mode,
    skipped: Vec<[u64; 2]>,
    restarts: Vec<u64>,
    delayed: Vec<[u64; 2]>,
}

impl RecordedStage {
    fn new(config: &LaunchConfig, role: Role, loops: &[RecordedLoop]) -> Self {
        let mut faults = StageFaults::for_role(config, role);
        let realtime = config.mode == Mode::Realtime;
        let slot = role.slot().expect("a stage has a slot");
        // Per loop: whether the stage computed an output (sent, or dropped by its own fault).
        let mut computed = Vec::with_capacity(loops.len());
        let mut delayed = Vec::new();
        let mut restarts = Vec::new();
        let mut incarnation = 0;
        for (k, l) in loops.iter().enumerate() {
            let k = k as u64;
            // Drawn for every loop, as the stage's runner does, so that each loop gets its draw.
            let dropped = faults.drops(k);
            let header = output_header(role, l);
            let input_lost = input_header(role, l).is_some_and(|h| h.lost != 0);
            computed.push(match header {
                Some(h) => !input_lost && (h.lost == 0 || !realtime || dropped),
                None => realtime && dropped && !input_lost,
            });
            if let Some(h) = header
                && h.incarnations[slot] > incarnation
            {
                incarnation = h.incarnations[slot];
                restarts.push(k);
            }
            if faults.delay(k).is_some_and(|d| !matches!(d, AddedDelay::Ticks(0))) {
                delayed.push(k);
            }
        }
        let skipped = ranges((0..loops.len() as u64).filter(|&k| !computed[k as usize]));
        Self { role, mode: config.mode, skipped, restarts, delayed: ranges(delayed.into_iter()) }
    }

    /// The replay's faults: the stage's own that change its outputs, and a `kill` where its
    /// recording restarted it (see the module's documentation).
    fn faults(&self, recorded: &LaunchConfig) -> Vec<FaultSpec> {
        let name = self.role.name();
        let mut faults: Vec<FaultSpec> = recorded
            .faults
            .iter()
            .filter(|f| f.process == name)
            .filter(|f| match f.kind {
                FaultKind::Drop | FaultKind::Corrupt => true,
                FaultKind::Delay => self.mode == Mode::Lockstep,
                FaultKind::Kill | FaultKind::Stop | FaultKind::Cut => false,
            })
            .cloned()
            .collect();
        faults.extend(self.restarts.iter().map(|&k| FaultSpec {
            kind: FaultKind::Kill,
            process: name.to_string(),
            at_s: k as f64 / recorded.rate_hz,
            duration_s: None,
            delay_s: None,
            delay_ticks: None,
            probability: None,
            value: None,
        }));
        faults
    }
}

/// The header of the stage's recorded output of one loop.
fn output_header(role: Role, l: &RecordedLoop) -> Option<crate::contract::msg::Header> {
    match role {
        Role::Sensors => l.measurements.map(|m| *m.header()),
        Role::Estimator => l.estimate.map(|m| *m.header()),
        _ => l.command.map(|m| *m.header()),
    }
}

/// The header of the stage's recorded input of one loop.
fn input_header(role: Role, l: &RecordedLoop) -> Option<crate::contract::msg::Header> {
    match role {
        Role::Sensors => l.state.map(|m| *m.header()),
        Role::Estimator => l.measurements.map(|m| *m.header()),
        _ => l.estimate.map(|m| *m.header()),
    }
}

/// The stage's output values of one loop, in trajectory.csv's column order; None if it sent
/// none or sent it marked lost.
fn output_values(role: Role, layout: &VectorLayout, l: &RecordedLoop) -> Option<Vec<f64>> {
    match role {
        Role::Sensors => l
            .measurements
            .filter(|m| m.header.lost == 0)
            .map(|m| layout.sensor_dims().iter().zip(&m.readings).flat_map(|(n, r)| r.value[..*n].to_vec()).collect()),
        Role::Estimator => l.estimate.filter(|m| m.header.lost == 0).map(|m| m.x[..layout.estimate.len()].to_vec()),
        _ => l.command.filter(|m| m.header.lost == 0).map(|m| m.u[..layout.input.len()].to_vec()),
    }
}

/// The columns of trajectory.csv that hold the stage's outputs.
fn output_columns(role: Role, layout: &VectorLayout) -> Vec<String> {
    let prefix = match role {
        Role::Sensors => "meas.",
        Role::Estimator => "est.",
        _ => "cmd.",
    };
    layout.trajectory_columns().into_iter().filter(|c| c.starts_with(prefix)).collect()
}

/// The values `values` picks from each loop (in the order of `columns`), recorded against
/// replayed, over the loops where both have them.
fn compare(
    columns: Vec<String>,
    values: impl Fn(&RecordedLoop) -> Option<Vec<f64>>,
    recorded: &[RecordedLoop],
    replayed: &[RecordedLoop],
) -> OutputComparison {
    let mut largest = vec![0.0f64; columns.len()];
    let mut comparison = OutputComparison::default();
    for (k, (a, b)) in recorded.iter().zip(replayed).enumerate() {
        let (Some(a), Some(b)) = (values(a), values(b)) else { continue };
        comparison.compared += 1;
        let same = a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()));
        if same {
            comparison.identical += 1;
            continue;
        }
        comparison.first_difference.get_or_insert(k as u64);
        for (i, (x, y)) in a.iter().zip(&b).enumerate() {
            let d = (x - y).abs();
            largest[i] = largest[i].max(if d.is_nan() { f64::INFINITY } else { d });
        }
    }
    comparison.largest = columns.into_iter().zip(largest).filter(|(_, d)| *d > 0.0).collect();
    comparison
}

/// Consecutive numbers as inclusive ranges.
fn ranges(numbers: impl Iterator<Item = u64>) -> Vec<[u64; 2]> {
    let mut out: Vec<[u64; 2]> = Vec::new();
    for k in numbers {
        match out.last_mut() {
            Some(last) if last[1] + 1 == k => last[1] = k,
            _ => out.push([k, k]),
        }
    }
    out
}

/// Ranges as text: `2000–2149, 5000`.
fn ranges_text(ranges: &[[u64; 2]]) -> String {
    let mut parts: Vec<String> =
        ranges.iter().take(6).map(|[a, b]| if a == b { a.to_string() } else { format!("{a}–{b}") }).collect();
    if ranges.len() > 6 {
        parts.push(format!("and {} more", ranges.len() - 6));
    }
    parts.join(", ")
}

fn count(ranges: &[[u64; 2]]) -> u64 {
    ranges.iter().map(|[a, b]| b - a + 1).sum()
}

/// One line: `what` against the recording's.
fn compared(out: &mut String, what: &str, o: &OutputComparison) {
    use std::fmt::Write as _;
    let _ = match o.first_difference {
        None => {
            writeln!(out, "  {what}: identical to the recording's, bit for bit, in all {} loops both have", o.compared)
        }
        Some(first) => writeln!(
            out,
            "  {what}: {} of {} loops differ from the recording's, the first at loop {first}; largest |difference|: {}",
            o.compared - o.identical,
            o.compared,
            o.largest.iter().map(|(c, d)| format!("{c} {d:.3e}")).collect::<Vec<_>>().join(", ")
        ),
    };
}

/// What `looplab replay` prints.
pub fn render(r: &ReplayReport) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let how = if r.in_process { "in this process" } else { "as processes over shared memory" };
    let mode = match r.recorded_mode {
        Mode::Lockstep => "lockstep",
        Mode::Realtime => "real-time",
    };
    let stage = r.stage.name();
    let _ = writeln!(out, "replay: the {stage} on the {mode} recording {}", r.recording.display());
    if let Some(program) = &r.program {
        let _ = writeln!(out, "  program: {}", program.join(" "));
    }
    if r.closed_loop {
        let _ = writeln!(
            out,
            "  closed loop: every process ran, from the recording's initial state, with the scenario's plant{}",
            if r.recorded_mode == Mode::Lockstep {
                " (exact for a lockstep recording of the same launch file)"
            } else {
                ": the lockstep counterpart of a real-time run, where timing no longer decides what a stage sees"
            }
        );
    } else {
        let others: Vec<&str> = Role::ALL.iter().filter(|p| p.in_loop() && **p != r.stage).map(|p| p.name()).collect();
        let _ = writeln!(out, "  open loop: the {} played the recording back", others.join(", "));
    }
    let _ = writeln!(out, "  {} loops in lockstep {how} in {:.2} s: {:.0} loops/s", r.loops, r.seconds, r.loops_per_s);
    if !r.skipped.is_empty() {
        let same = if r.skipped_in_replay == r.skipped { "skipped them again" } else { "did NOT skip the same loops" };
        let _ = writeln!(
            out,
            "  skipped: the recorded {stage} did not compute {} loops ({}); the replayed one {same}",
            count(&r.skipped),
            ranges_text(&r.skipped)
        );
    }
    if !r.restarts.is_empty() && !r.closed_loop {
        let loops: Vec<String> = r.restarts.iter().map(u64::to_string).collect();
        let _ = writeln!(
            out,
            "  restarts: the recorded {stage} restarted at loop {}; the replayed one restarted there too and thawed its \
             frozen state",
            loops.join(", ")
        );
    }
    for k in &r.thawed_older {
        let _ = writeln!(
            out,
            "  thawed one loop older: the recorded {stage} was killed after it sent loop {k}'s output and before it kept \
             its state, so its successor thawed loop {}'s; the replayed one was not given loop {k}, and thawed the same",
            k.saturating_sub(1)
        );
    }
    if !r.delayed.is_empty() && !r.closed_loop {
        let what = if r.recorded_mode == Mode::Realtime {
            "held back in the recording by a delay fault (real time: the same outputs, later); the replay computes \
             them without the hold"
        } else {
            "delayed by a delay fault, replayed alike"
        };
        let _ = writeln!(out, "  delayed: loops {} {what}", ranges_text(&r.delayed));
    }
    compared(&mut out, "outputs", &r.outputs);
    if let Some(state) = &r.state {
        compared(&mut out, "state", state);
    }
    let _ = writeln!(out, "  run folder: {} (replay.json)", r.run_dir.display());
    let _ = writeln!(out, "  compare: looplab diff {} {}", r.recording.display(), r.run_dir.display());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_join_consecutive_loops() {
        assert_eq!(ranges([1, 2, 3, 7, 9, 10].into_iter()), vec![[1, 3], [7, 7], [9, 10]]);
        assert_eq!(ranges_text(&[[1, 3], [7, 7]]), "1–3, 7");
        assert_eq!(count(&[[1, 3], [7, 7]]), 4);
    }

    #[test]
    fn a_stage_is_a_role_and_maybe_a_program() {
        assert_eq!(parse_stage("estimator").unwrap(), (Role::Estimator, None));
        assert_eq!(
            parse_stage("controller=python3 'my ctl.py' --gain 2").unwrap(),
            (Role::Controller, Some(vec!["python3".into(), "my ctl.py".into(), "--gain".into(), "2".into()]))
        );
        assert_eq!(
            parse_stage("plant").unwrap_err(),
            "unknown stage \"plant\"; allowed: sensors, estimator, controller"
        );
        assert!(parse_stage("estimator=").is_err());
    }
}
