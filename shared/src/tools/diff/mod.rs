//! `looplab diff RUN_A RUN_B`: two runs of one scenario compared field by field, loop by loop.
//!
//! A field is a column of trajectory.csv (state, meas.*, est.*, cmd.*, applied.*) or a metric of
//! summary.json. Per field: the largest |B − A|, its RMS, the loops over tolerance and the first
//! of them. Loops are matched by `k`, so a loop one run has no row for reads as empty cells.
//! Latency is timing, not a trajectory: it is compared as distributions (p50, p99 and max,
//! B ÷ A) and judged only when `--tolerance latency=R` asks for it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::Context as _;
use serde::Serialize;

use crate::config::gate::GateKind;
use crate::contract::report::Stats;
use crate::contract::run_format::files;
use crate::launcher::gate::{self, Judged};
use crate::launcher::summary::Summary;
use crate::model::catalog::Catalog;
use crate::model::layout::VectorLayout;
use crate::tools::ToolError;
use crate::tools::compare::{metric_text, ratio_label};
use crate::tools::plot::figure::{Colour, Curve, Draw as _, FaultMark, Figure, Line, Panel};
use crate::tools::run_folder::{RunFolder, Table};

mod render;

/// The files of a run folder diff reads.
const INPUTS: [&str; 3] = [files::LAUNCH, files::TRAJECTORY, files::SUMMARY];

/// The name `--tolerance` takes for the latency's ratio.
pub const LATENCY: &str = "latency";

/// What counts as the same.
#[derive(Debug, Clone, Default)]
pub struct DiffOptions {
    /// `--tolerance FIELD=ABS`: an absolute tolerance for a column, a group or a metric; or
    /// `latency=R`, the largest ratio B ÷ A (and A ÷ B) of the latency's p50, p99 and max.
    pub tolerances: Vec<(String, f64)>,
    /// `--rtol R`: a relative tolerance on top, against RUN_A's value.
    pub rtol: f64,
    /// Where the figure of the differences over time goes (None: no figure).
    pub figure: Option<PathBuf>,
    /// Where diff.json goes (None: not written).
    pub json: Option<PathBuf>,
    /// `--fail-on`: judged on RUN_B's summary.
    pub gates: Vec<crate::config::gate::Gate>,
}

/// The groups of fields, in trajectory.csv's order, then the metrics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Group {
    State,
    Meas,
    Est,
    Cmd,
    Applied,
    Metrics,
}

impl Group {
    pub const ALL: [Group; 6] = [Group::State, Group::Meas, Group::Est, Group::Cmd, Group::Applied, Group::Metrics];

    /// The name `--tolerance` takes.
    pub fn name(self) -> &'static str {
        match self {
            Group::State => "state",
            Group::Meas => "meas",
            Group::Est => "est",
            Group::Cmd => "cmd",
            Group::Applied => "applied",
            Group::Metrics => "metrics",
        }
    }

    /// How the table and the figure title it.
    fn title(self) -> &'static str {
        match self {
            Group::State => "state",
            Group::Meas => "measurements (meas.*)",
            Group::Est => "estimate (est.*)",
            Group::Cmd => "command (cmd.*)",
            Group::Applied => "applied input (applied.*)",
            Group::Metrics => "metrics (summary.json)",
        }
    }

    /// The group of a trajectory.csv column by its prefix; None for the loop's `k` and `t_s`.
    pub fn of_column(name: &str) -> Option<Group> {
        let prefixed =
            [("meas.", Group::Meas), ("est.", Group::Est), ("cmd.", Group::Cmd), ("applied.", Group::Applied)];
        match prefixed.iter().find(|(prefix, _)| name.starts_with(prefix)) {
            Some((_, group)) => Some(*group),
            None if name == "k" || name == "t_s" => None,
            None => Some(Group::State),
        }
    }
}

/// A loop and its simulation time.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LoopAt {
    pub k: u64,
    pub t_s: f64,
}

/// One field compared over every loop (a metric: once).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FieldDiff {
    pub name: String,
    pub group: Group,
    /// The absolute tolerance that applied (`--rtol` adds to it).
    pub tolerance: f64,
    /// Loops with a value in both runs.
    pub compared: u64,
    /// Loops whose values are not the same (NaN and NaN are the same).
    pub differing: u64,
    /// The largest finite |B − A|, and where it is.
    pub max_abs: f64,
    pub max_at: Option<LoopAt>,
    /// Root mean square of the finite B − A over the loops with a value in both.
    pub rms: f64,
    /// Loops where one value is NaN or infinite and the other is not the same: no finite
    /// difference, always over tolerance.
    pub non_finite: u64,
    /// Loops whose cell is empty in A only (a part that did not arrive), and in B only.
    pub empty_only_in_a: u64,
    pub empty_only_in_b: u64,
    /// Loops over tolerance, and the first of them (a metric has no loop).
    pub over: u64,
    pub first_over: Option<LoopAt>,
    /// The metric's values (metrics only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub values: Option<(Option<f64>, Option<f64>)>,
    /// B − A per loop, NaN where there is no finite difference (the figure's curve).
    #[serde(skip)]
    pub delta: Vec<f64>,
    /// The tolerance at each loop, ABS + R·|A| (NaN where A has no value): the figure's band.
    #[serde(skip)]
    pub band: Vec<f64>,
    /// The field's unit, where the run's launch file says it ("rad/s"; None for a metric).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
}

impl FieldDiff {
    /// Any loop where the runs are not the same.
    pub fn differs(&self) -> bool {
        self.differing > 0 || self.empty_only_in_a > 0 || self.empty_only_in_b > 0
    }
}

/// How a pair of cells compares.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CellDiff {
    BothEmpty,
    EmptyOnlyInA,
    EmptyOnlyInB,
    /// Equal (NaN equals NaN).
    Same,
    /// B − A, finite, and whether it is over tolerance.
    Finite {
        delta: f64,
        over: bool,
    },
    /// One is NaN or infinite and they are not the same.
    NonFinite,
}

/// Compares A's cell against B's: over tolerance when |a − b| > abs + rtol·|a|.
pub fn compare_cells(a: Option<f64>, b: Option<f64>, abs: f64, rtol: f64) -> CellDiff {
    match (a, b) {
        (None, None) => CellDiff::BothEmpty,
        (None, Some(_)) => CellDiff::EmptyOnlyInA,
        (Some(_), None) => CellDiff::EmptyOnlyInB,
        (Some(a), Some(b)) if a == b || (a.is_nan() && b.is_nan()) => CellDiff::Same,
        (Some(a), Some(b)) => {
            let delta = b - a;
            if delta.is_finite() {
                CellDiff::Finite { delta, over: delta.abs() > abs + rtol * a.abs() }
            } else {
                CellDiff::NonFinite
            }
        }
    }
}

/// Compares one field over the loops `at` (k and t of each), A's and B's cells in loop order.
pub fn compare_field(
    name: &str,
    group: Group,
    at: &[LoopAt],
    a: &[Option<f64>],
    b: &[Option<f64>],
    tolerance: f64,
    rtol: f64,
) -> FieldDiff {
    let mut field = FieldDiff {
        name: name.to_string(),
        group,
        tolerance,
        compared: 0,
        differing: 0,
        max_abs: 0.0,
        max_at: None,
        rms: 0.0,
        non_finite: 0,
        empty_only_in_a: 0,
        empty_only_in_b: 0,
        over: 0,
        first_over: None,
        values: None,
        delta: Vec::with_capacity(at.len()),
        band: Vec::with_capacity(at.len()),
        unit: None,
    };
    let (mut squares, mut finite) = (0.0, 0u64);
    for ((at, a), b) in at.iter().zip(a).zip(b) {
        field.band.push(a.map_or(f64::NAN, |a| tolerance + rtol * a.abs()));
        let cell = compare_cells(*a, *b, tolerance, rtol);
        let (delta, over) = match cell {
            CellDiff::BothEmpty => (f64::NAN, false),
            CellDiff::EmptyOnlyInA => {
                field.empty_only_in_a += 1;
                (f64::NAN, true)
            }
            CellDiff::EmptyOnlyInB => {
                field.empty_only_in_b += 1;
                (f64::NAN, true)
            }
            CellDiff::Same => (0.0, false),
            CellDiff::Finite { delta, over } => (delta, over),
            CellDiff::NonFinite => {
                field.non_finite += 1;
                (f64::NAN, true)
            }
        };
        if a.is_some() && b.is_some() {
            field.compared += 1;
            if cell != CellDiff::Same {
                field.differing += 1;
            }
        }
        if delta.is_finite() {
            finite += 1;
            squares += delta * delta;
            if delta.abs() > field.max_abs {
                field.max_abs = delta.abs();
                field.max_at = Some(*at);
            }
        }
        if over {
            field.over += 1;
            field.first_over.get_or_insert(*at);
        }
        field.delta.push(delta);
    }
    if finite > 0 {
        field.rms = (squares / finite as f64).sqrt();
    }
    field
}

/// The latency of one hop (or end to end) in both runs: p50, p99 and max, ns, and B ÷ A.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LatencyRatio {
    pub name: String,
    pub a_ns: [Option<u64>; 3],
    pub b_ns: [Option<u64>; 3],
    /// B ÷ A; None where either is missing or A's is 0.
    pub ratio: [Option<f64>; 3],
    /// Within [1/R, R] at each of p50, p99, max (None: not judged).
    pub within: Option<[bool; 3]>,
}

/// The statistics compared, as summary.json names them.
pub const LATENCY_STATS: [&str; 3] = ["p50", "p99", "max"];

impl LatencyRatio {
    pub fn of(name: &str, a: Option<&Stats>, b: Option<&Stats>, tolerance: Option<f64>) -> Self {
        let pick = |s: Option<&Stats>| s.map_or([None; 3], |s| [s.p50, s.p99, s.max]);
        let (a_ns, b_ns) = (pick(a), pick(b));
        let ratio: [Option<f64>; 3] = std::array::from_fn(|i| match (a_ns[i], b_ns[i]) {
            (Some(a), Some(b)) if a > 0 => Some(b as f64 / a as f64),
            _ => None,
        });
        let within = tolerance.map(|r| {
            std::array::from_fn(|i| match ratio[i] {
                Some(q) => (1.0 / r..=r).contains(&q),
                // No ratio: the same only where both are missing or both 0.
                None => a_ns[i] == b_ns[i],
            })
        });
        LatencyRatio { name: name.to_string(), a_ns, b_ns, ratio, within }
    }

    fn over(&self) -> impl Iterator<Item = usize> + '_ {
        self.within.iter().flat_map(|w| (0..3).filter(move |i| !w[*i]))
    }
}

/// The differences between two runs.
#[derive(Debug, Clone, Default, Serialize)]
pub struct RunDiff {
    pub a: PathBuf,
    pub b: PathBuf,
    pub scenario: String,
    pub rate_hz: f64,
    pub modes: [String; 2],
    /// Loops compared (matched by k).
    pub loops: u64,
    pub rtol: f64,
    /// Every field: trajectory.csv's columns in its order, then the metrics.
    pub fields: Vec<FieldDiff>,
    /// End to end first, then each hop.
    pub latency: Vec<LatencyRatio>,
    /// `--tolerance latency=R`.
    pub latency_tolerance: Option<f64>,
    pub figure: Option<PathBuf>,
    #[serde(skip)]
    pub json: Option<PathBuf>,
    /// Each loop compared, for the figure.
    #[serde(skip)]
    at: Vec<LoopAt>,
    #[serde(skip)]
    faults: Vec<FaultMark>,
    /// `--fail-on`, judged on RUN_B.
    #[serde(skip)]
    pub gates: Judged,
}

impl RunDiff {
    /// Whether every field is within its tolerance (exit code 0).
    pub fn within_tolerance(&self) -> bool {
        self.fields.iter().all(|f| f.over == 0) && self.latency.iter().all(|l| l.over().next().is_none())
    }

    /// The exit code: a field over tolerance or a control gate failed: 3; latency over its
    /// ratio or a timing gate: 4; both: 5; else 0.
    pub fn exit_code(&self) -> u8 {
        let control = self.fields.iter().any(|f| f.over > 0) || self.gates.failed(GateKind::Control);
        let timing = self.latency.iter().any(|l| l.over().next().is_some()) || self.gates.failed(GateKind::Timing);
        gate::exit_code(control, timing).unwrap_or(crate::launcher::EXIT_OK)
    }

    /// The fields with a loop where the runs are not the same.
    pub fn differing(&self) -> impl Iterator<Item = &FieldDiff> {
        self.fields.iter().filter(|f| f.differs())
    }
}

/// The legend's name of the differences' curves.
pub const DELTA_LABEL: &str = "B − A (gaps: no finite difference)";
/// The legend's name of the tolerance band's curves.
pub const BAND_LABEL: &str = "tolerance ±(ABS + R·|A|)";

/// `FIELD=ABS` as `--tolerance` takes it.
pub fn parse_tolerance(text: &str) -> Result<(String, f64), ToolError> {
    let bad = |why: &str| ToolError::BadInput(format!("--tolerance {text}: {why}"));
    let (name, value) = text.split_once('=').ok_or_else(|| bad("give FIELD=ABS, for example est.theta_rad=1e-9"))?;
    let value: f64 = value.trim().parse().map_err(|_| bad(&format!("{:?} is not a number", value.trim())))?;
    let name = name.trim();
    if name.is_empty() {
        return Err(bad("give FIELD=ABS, for example est.theta_rad=1e-9"));
    }
    if !value.is_finite() || value < 0.0 {
        return Err(bad("a tolerance is a finite number, 0 or more"));
    }
    if name == LATENCY && value < 1.0 {
        return Err(bad("latency=R takes a ratio of 1 or more (2: B within half to twice A)"));
    }
    Ok((name.to_string(), value))
}

/// The absolute tolerance of a field: its own name's, else its group's, else 0; the last given
/// of each wins.
pub fn tolerance_for(name: &str, group: Group, tolerances: &[(String, f64)]) -> f64 {
    let last = |key: &str| tolerances.iter().rev().find(|(n, _)| n == key).map(|(_, v)| *v);
    last(name).or_else(|| last(group.name())).unwrap_or(0.0)
}

/// One run folder, read.
struct Run {
    summary: Summary,
    columns: Vec<String>,
    k: Vec<u64>,
    t: Vec<f64>,
    table: Table,
}

fn read_run(dir: &Path) -> Result<Run, ToolError> {
    let folder = RunFolder::open(dir, &INPUTS)?;
    let summary = folder.summary()?;
    let table = folder.table(files::TRAJECTORY)?;
    let columns: Vec<String> = table.header().map(String::from).collect();
    let k = table
        .column::<u64>("k")?
        .into_iter()
        .enumerate()
        .map(|(row, k)| k.ok_or_else(|| table.error_at(row, "no loop number k")))
        .collect::<Result<Vec<u64>, ToolError>>()?;
    let t = table.floats("t_s")?;
    Ok(Run { summary, columns, k, t, table })
}

/// Why the runs cannot be compared, if they cannot: one line.
fn incomparable(a: &Run, b: &Run) -> Option<String> {
    let (sa, sb) = (&a.summary, &b.summary);
    let why = if sa.scenario != sb.scenario {
        format!("RUN_A is scenario {}, RUN_B is {}", sa.scenario, sb.scenario)
    } else if sa.rate_hz != sb.rate_hz {
        format!("RUN_A runs at {} Hz, RUN_B at {} Hz", sa.rate_hz, sb.rate_hz)
    } else if sa.duration_s != sb.duration_s {
        format!("RUN_A lasts {} s, RUN_B {} s", sa.duration_s, sb.duration_s)
    } else if sa.loops != sb.loops {
        format!("RUN_A ran {} loops, RUN_B {}", sa.loops, sb.loops)
    } else if let Some(c) = a.columns.iter().find(|c| !b.columns.contains(c)) {
        format!("RUN_A's trajectory.csv has column {c}, RUN_B's has not")
    } else if let Some(c) = b.columns.iter().find(|c| !a.columns.contains(c)) {
        format!("RUN_B's trajectory.csv has column {c}, RUN_A's has not")
    } else {
        return None;
    };
    Some(format!("cannot compare: {why}"))
}

/// Each loop either run has a row for, in order of k: its time, A's row and B's row.
fn align(a: &Run, b: &Run) -> Vec<(LoopAt, Option<usize>, Option<usize>)> {
    let mut loops: BTreeMap<u64, (f64, Option<usize>, Option<usize>)> = BTreeMap::new();
    for (row, k) in a.k.iter().enumerate() {
        let entry = loops.entry(*k).or_insert((a.t[row], None, None));
        entry.1.get_or_insert(row);
    }
    for (row, k) in b.k.iter().enumerate() {
        let entry = loops.entry(*k).or_insert((b.t[row], None, None));
        entry.2.get_or_insert(row);
    }
    loops.into_iter().map(|(k, (t_s, ra, rb))| (LoopAt { k, t_s }, ra, rb)).collect()
}

/// Checks each `--tolerance` names a column, a group, a metric or the latency.
fn check_tolerances(tolerances: &[(String, f64)], columns: &[String], metrics: &[&String]) -> Result<(), ToolError> {
    for (name, value) in tolerances {
        let known = name == LATENCY
            || Group::ALL.iter().any(|g| g.name() == name)
            || columns.iter().any(|c| c == name && Group::of_column(c).is_some())
            || metrics.contains(&name);
        if !known {
            let example = columns.iter().find(|c| c.starts_with("est.")).map_or("est.theta_rad", |c| c.as_str());
            return Err(ToolError::BadInput(format!(
                "--tolerance {name}={value}: no field {name}; give a column of trajectory.csv (for example {example}), \
                 a group ({}), a metric of summary.json or latency",
                Group::ALL.map(Group::name).join(", ")
            )));
        }
    }
    Ok(())
}

/// The faults of both runs as markers: "A: kill estimator", "A, B: ..." where both had it.
fn fault_marks(a: &Summary, b: &Summary) -> Vec<FaultMark> {
    let mut marks: Vec<(f64, String, String)> = Vec::new();
    for (run, summary) in [("A", a), ("B", b)] {
        for f in &summary.faults {
            let what = format!("{} {}", <&str>::from(f.kind), f.process);
            match marks.iter_mut().find(|(t, w, _)| *t == f.at_s && *w == what) {
                Some(mark) => mark.2.push_str(&format!(", {run}")),
                None => marks.push((f.at_s, what, run.to_string())),
            }
        }
    }
    marks.into_iter().map(|(t, what, runs)| FaultMark { t, label: format!("{runs}: {what}") }).collect()
}

/// A --figure path the figure can be written to: a .png in a folder that exists.
fn checked_figure(path: &Path) -> Result<(), ToolError> {
    let bad = |why: &str| ToolError::BadInput(format!("--figure {}: {why}", path.display()));
    if !path.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")) {
        return Err(bad("the figure is a PNG; give a path ending in .png"));
    }
    let folder = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if !folder.is_dir() {
        return Err(bad(&format!("no folder {}", folder.display())));
    }
    Ok(())
}

/// Compares the runs in folders `a` and `b`. Runs that cannot be compared (other scenarios,
/// rates or lengths) are `ToolError::BadInput`, one line that says which. Writes the figure and
/// diff.json where `options` says.
pub fn diff_runs(a: &Path, b: &Path, options: &DiffOptions, catalog: &Catalog) -> Result<RunDiff, ToolError> {
    if !options.rtol.is_finite() || options.rtol < 0.0 {
        return Err(ToolError::BadInput(format!("--rtol {}: a finite number, 0 or more", options.rtol)));
    }
    let (run_a, run_b) = (read_run(a)?, read_run(b)?);
    if let Some(figure) = &options.figure {
        checked_figure(figure)?;
    }
    if let Some(why) = incomparable(&run_a, &run_b) {
        return Err(ToolError::BadInput(why));
    }
    let (sa, sb) = (&run_a.summary, &run_b.summary);
    let mut metric_names: Vec<&String> = sa.metrics.keys().chain(sb.metrics.keys()).collect();
    metric_names.sort();
    metric_names.dedup();
    check_tolerances(&options.tolerances, &run_a.columns, &metric_names)?;

    let loops = align(&run_a, &run_b);
    let at: Vec<LoopAt> = loops.iter().map(|(at, ..)| *at).collect();
    // The columns' units, from A's launch file; none where it cannot be read (the figure then
    // says B − A alone).
    let units: BTreeMap<String, &str> = RunFolder::open(a, &[files::LAUNCH])
        .and_then(|folder| folder.launch(catalog))
        .map(|(config, scenario)| VectorLayout::new(&config, scenario.as_ref()).trajectory_columns_with_units())
        .unwrap_or_default()
        .into_iter()
        .collect();
    let mut fields = Vec::new();
    for name in &run_a.columns {
        let Some(group) = Group::of_column(name) else { continue };
        let (column_a, column_b) = (run_a.table.column::<f64>(name)?, run_b.table.column::<f64>(name)?);
        let cells = |column: &[Option<f64>], row: Option<usize>| row.and_then(|r| column[r]);
        let cells_a: Vec<Option<f64>> = loops.iter().map(|(_, ra, _)| cells(&column_a, *ra)).collect();
        let cells_b: Vec<Option<f64>> = loops.iter().map(|(_, _, rb)| cells(&column_b, *rb)).collect();
        let tolerance = tolerance_for(name, group, &options.tolerances);
        let mut field = compare_field(name, group, &at, &cells_a, &cells_b, tolerance, options.rtol);
        field.unit = units.get(name).map(|unit| unit.to_string());
        fields.push(field);
    }
    for name in metric_names {
        let (va, vb) = (sa.metrics.get(name).copied(), sb.metrics.get(name).copied());
        let tolerance = tolerance_for(name, Group::Metrics, &options.tolerances);
        let mut field =
            compare_field(name, Group::Metrics, &[LoopAt { k: 0, t_s: 0.0 }], &[va], &[vb], tolerance, options.rtol);
        // A metric is of the whole run: no loop.
        field.max_at = None;
        field.first_over = None;
        field.delta.clear();
        field.band.clear();
        field.values = Some((va, vb));
        fields.push(field);
    }

    let latency_tolerance = options.tolerances.iter().rev().find(|(n, _)| n == LATENCY).map(|(_, r)| *r);
    let (la, lb) = (&sa.latency_ns, &sb.latency_ns);
    let mut latency =
        vec![LatencyRatio::of("end to end", Some(&la.end_to_end), Some(&lb.end_to_end), latency_tolerance)];
    let mut hops: Vec<&String> = la.hops.keys().chain(lb.hops.keys()).collect();
    hops.sort();
    hops.dedup();
    latency.extend(hops.into_iter().map(|h| LatencyRatio::of(h, la.hops.get(h), lb.hops.get(h), latency_tolerance)));

    let gates = gate::judge(&options.gates, sb).map_err(|e| ToolError::BadInput(format!("--fail-on {e}")))?;
    let diff = RunDiff {
        gates,
        a: a.to_path_buf(),
        b: b.to_path_buf(),
        scenario: sa.scenario.clone(),
        rate_hz: sa.rate_hz,
        modes: [sa.mode.name().to_string(), sb.mode.name().to_string()],
        loops: at.len() as u64,
        rtol: options.rtol,
        fields,
        latency,
        latency_tolerance,
        figure: options.figure.clone(),
        json: options.json.clone(),
        faults: fault_marks(sa, sb),
        at,
    };
    if let Some(path) = &options.figure {
        diff.figure().draw(path)?;
    }
    if let Some(path) = &options.json {
        #[derive(Serialize)]
        struct Written<'a> {
            within_tolerance: bool,
            verdict: String,
            #[serde(flatten)]
            diff: &'a RunDiff,
        }
        let written = Written { within_tolerance: diff.within_tolerance(), verdict: diff.verdict(), diff: &diff };
        let text = serde_json::to_string_pretty(&written).context("diff.json")?;
        crate::launcher::run_dir::write_atomically(path, &format!("{text}\n"))
            .with_context(|| format!("write {}", path.display()))?;
    }
    Ok(diff)
}

#[cfg(test)]
#[path = "tests.rs"]
mod tests;
