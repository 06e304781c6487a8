//! The top layer: `looplab`'s command line. Parses the arguments and hands each command to the
//! layer that does it: `run` to the launcher, `sweep` and `bench` to the tools.

use std::io::IsTerminal as _;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::{Args, CommandFactory, Parser, Subcommand};

use crate::config::gate::Gate;
use crate::config::launch::{self, Override};
use crate::launcher::{self, EXIT_BAD_INPUT, EXIT_INTERRUPTED, report};
use crate::model::catalog::Catalog;
use crate::runtime::storage::run_storage;
use crate::scenarios;
use crate::tools::{self, ToolError, bench, compare, diff, export, perfetto, plot, replay, sweep};

#[derive(Debug, Parser)]
#[command(
    name = "looplab",
    version,
    about = "Run a closed control loop as separate processes over iceoryx2 shared memory, and measure it",
    long_about = "Run a closed control loop as separate processes over iceoryx2 shared memory, and measure it.\n\n\
The plant, sensors, estimator, controller and a monitor each run as their own process. LoopLab \
reports the latency of every hop and end to end, the plant's tick jitter, deadline misses, sensor \
data age and the scenario's control metrics, and writes a run folder with summary.json, \
trajectory.csv, loops.csv, latency.hlog, run.mcap (for Foxglove and PlotJuggler) and the resolved launch file.\n\n\
With no command, runs the default: the pendulum scenario, real time, 1 kHz, 10 s.",
    after_help = "Examples:\n  looplab\n  looplab list\n  looplab show pendulum\n  looplab run pendulum --mode lockstep --duration 30 \
--set sensors.encoder.bias=0.05 --set estimator.kind=no-bias\n  looplab run my-launch.toml --out /tmp/run1"
)]
pub struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run a scenario or a launch file and report latency, jitter and control metrics
    Run(RunArgs),
    /// List the scenarios and their launch files
    List,
    /// Print a scenario's launch file: every key, its default and what it means; or a launch
    /// file of your own resolved over its scenario's defaults: every key with its value
    Show {
        /// The scenario (see `looplab list`), or the path of a launch file
        scenario: String,
    },
    /// Run a scenario repeatedly in lockstep while one key varies; report the metrics per value
    /// and, for a controller delay, the measured delay margin against theory. A fault is judged
    /// against the same run without it. Exit 1 a run failed, 3 a control gate of --fail-on or
    /// [gate] failed on some value, 4 a timing gate, 5 both, 2 bad input
    Sweep(SweepCli),
    /// Print a finished run's report again, from its summary.json
    Report {
        /// The run folder (for the newest run: runs/latest)
        run_dir: PathBuf,
    },
    /// Compare finished runs side by side: latency per hop and end to end, deadline misses, loops,
    /// wait strategy, mode and the scenario's metrics, with ratios against the first run; draws
    /// their latency distributions on one chart (PNG)
    #[command(
        after_help = "Example: two wait strategies\n  looplab run --set wait.strategy=block --out runs/block\n  \
looplab run --set wait.strategy=adaptive --out runs/adaptive\n  looplab compare runs/block runs/adaptive"
    )]
    Compare {
        /// Two or more run folders (runs/<time>-<scenario>, runs/latest, a run's --out); ratios are
        /// against the first
        #[arg(value_name = "RUN_DIR")]
        runs: Vec<PathBuf>,
        /// Where to write the chart, a .png (default: compare-<A>-vs-<B>.png beside the first run
        /// folder)
        #[arg(long, value_name = "PATH")]
        out: Option<PathBuf>,
    },
    /// Compare two runs of one scenario field by field, loop by loop: state, measurements,
    /// estimate, command, applied input and metrics, with the largest difference, the RMS and the
    /// first loop over tolerance; latency as distributions (p50, p99, max ratios). Draws B − A over
    /// time and writes diff.json. Exit 0 within tolerance, 3 a field beyond (or a control gate of --fail-on on
    /// RUN_B), 4 the latency beyond its ratio (or a timing gate), 5 both, 2 bad input
    #[command(after_help = "Examples:\n  looplab diff runs/golden runs/latest\n  \
looplab diff runs/golden runs/latest --tolerance est=1e-9 --tolerance cmd.current_A=1e-6 --rtol 1e-9\n  \
looplab diff runs/golden runs/latest --tolerance latency=2 --no-figure\n\
A value is over tolerance when |B − A| > ABS + R·|A| (ABS: the field's own --tolerance, else its group's, else 0, \
exact). NaN equals NaN; a cell empty in one run only (a part that did not arrive) is over tolerance. \
Latency is judged only with --tolerance latency=R: each ratio B ÷ A within [1/R, R]. \
Runs of other scenarios, rates, durations, loop counts or columns cannot be compared (exit 2).")]
    Diff(DiffCli),
    /// Print a shell completion script: `looplab completions bash > /etc/bash_completion.d/looplab`
    Completions {
        /// bash, zsh, fish, elvish or powershell
        shell: clap_complete::Shell,
    },
    /// Print the manual page (roff): `looplab man > looplab.1; man ./looplab.1`
    Man,
    /// Remove what runs killed with SIGKILL left in shared memory (their launcher is gone): kill
    /// their orphaned processes, remove their files. `looplab run` does this too before it starts.
    Clean,
    /// Measure LoopLab's own latency against the transport's floor and a hand-written Unix-socket
    /// loop, per wait strategy, plus zero copy, the monitor's cost and lockstep speed; writes
    /// bench.json and PNG charts
    Bench(bench::BenchArgs),
    /// Measure the OS's own timer wake-up latency, as cyclictest does: a thread sleeps to
    /// absolute deadlines (clock_nanosleep, TIMER_ABSTIME) at an interval, at a priority, on a
    /// CPU; prints p50/p99/p99.9/max, and with --json writes them and every wake-up's lateness
    /// (a histogram in µs). The probe `run --probe` runs beside the loop, on its own
    #[command(after_help = "Example: as `cyclictest -q -i 1000 -l 10000 -p 1 -a 0 --default-system`\n  \
looplab probe --interval-us 1000 --loops 10000 --priority 1 --cpu 0\n\
Exit codes: 0 measured, 2 bad input or a setting the machine refused (--priority needs root or `ulimit -r`).")]
    Probe(ProbeCli),
    /// Write a file for an existing run folder from its files: --mcap writes run.mcap (for
    /// Foxglove or PlotJuggler), as every run does, for a run folder that has none; --perfetto
    /// writes run.perfetto-trace (open it in ui.perfetto.dev): each loop's stages and hops as
    /// slices per process, a flow per loop, latency counters, deadline misses, faults, restarts
    Export {
        /// The run folder (runs/<time>-<scenario> or a run's --out)
        run_dir: PathBuf,
        /// Write run.mcap
        #[arg(long, required_unless_present = "perfetto")]
        mcap: bool,
        /// Write run.perfetto-trace, a Perfetto trace in CLOCK_MONOTONIC time
        #[arg(long)]
        perfetto: bool,
        /// Where to write the Perfetto trace (default: RUN_DIR/run.perfetto-trace)
        #[arg(long, requires = "perfetto", value_name = "PATH")]
        out: Option<PathBuf>,
        /// Replace a run.mcap that is there already (the monitor's own keeps more than the files)
        #[arg(long)]
        force: bool,
    },
    /// Draw a run folder's figures as PNG into it (estimate.png, commands.png, sensors.png,
    /// tick-period.png, misses.png), or with --paper reproduce a paper's figure for a scenario
    #[command(
        after_help = "Examples:\n  looplab plot runs/latest\n  looplab plot --paper pendulum --out /tmp/paper-003\n\
--paper runs the paper's launch files in lockstep in this process (one run folder each, under --out) and draws: \
pendulum: paper 003's Figs. 3 and 4 (angle and flywheel speed without and with bias estimation); \
quadcopter: paper 001's Fig. 17 (the mass estimate as weight is added); \
tiltrotor: paper 004's Fig. 4 (the a-priori x error of NLLS-2L and NLPT-2L against the paper's ±3.81 cm); \
fip: paper 000's Figs. 2 and 4 (the estimated load speed and the thrust in the three disturbance cases, and b̂ \
against the stochastic b)."
    )]
    Plot {
        /// The run folder (runs/<time>-<scenario>, runs/latest or a run's --out)
        #[arg(required_unless_present = "paper", conflicts_with = "paper")]
        run_dir: Option<PathBuf>,
        /// Reproduce the paper figure of this scenario instead: pendulum, quadcopter, tiltrotor or fip
        #[arg(long, value_name = "SCENARIO")]
        paper: Option<String>,
        /// With --paper: the folder for the runs and figures, new or empty (default:
        /// runs/<time>-paper-<scenario>)
        #[arg(long, value_name = "DIR", requires = "paper")]
        out: Option<PathBuf>,
        /// The figures over time start at this simulation time, s (default: 0)
        #[arg(long, value_name = "SECONDS", conflicts_with = "paper")]
        from: Option<f64>,
        /// The figures over time end at this simulation time, s (default: the run's end)
        #[arg(long, value_name = "SECONDS", conflicts_with = "paper")]
        to: Option<f64>,
    },
    /// Run one stage on the inputs recorded in a run folder, loop by loop in lockstep, as processes
    /// over shared memory (or --in-process), and write a new run folder with its outputs beside the
    /// recorded rest; `looplab diff` then compares the two
    Replay(replay::ReplayArgs),
    /// (internal) the far end of the bench's ping-pong
    #[command(hide = true)]
    BenchEcho(bench::pingpong::EchoArgs),
    /// (internal) one stage of the bench's Unix-socket baseline loop
    #[command(hide = true)]
    BenchUdsStage(bench::uds_loop::StageArgs),
}

#[derive(Debug, Args)]
struct ProbeCli {
    /// The interval between deadlines, µs (10 to 1000000)
    #[arg(long, value_name = "US", default_value_t = 1000)]
    interval_us: u64,
    /// How many deadlines (1 to 100000000)
    #[arg(long, value_name = "N", default_value_t = 10_000)]
    loops: u64,
    /// SCHED_FIFO at this priority (1 to 99; root or `ulimit -r`); without it the normal policy
    /// with the timer slack tightened to 1 ns, as the loop's blocking waits have it
    #[arg(long, value_name = "P")]
    priority: Option<u32>,
    /// Pin the probe's thread to this CPU (one this process may run on)
    #[arg(long, value_name = "C")]
    cpu: Option<usize>,
    /// Lock the process's memory (mlockall), as cyclictest -m
    #[arg(long)]
    mlock: bool,
    /// Also write what it measured as JSON here: the summary and `histogram_us`, [µs, count]
    #[arg(long, value_name = "PATH")]
    json: Option<PathBuf>,
}

#[derive(Debug, Args)]
struct DiffCli {
    /// The reference run folder
    #[arg(value_name = "RUN_A")]
    a: PathBuf,
    /// The run folder compared against it
    #[arg(value_name = "RUN_B")]
    b: PathBuf,
    /// An absolute tolerance: FIELD=ABS for a column of trajectory.csv (est.theta_rad), a group
    /// (state, meas, est, cmd, applied, metrics) or a metric of summary.json; latency=R judges
    /// the latency's ratios. Repeatable
    #[arg(long = "tolerance", value_name = "FIELD=ABS")]
    tolerances: Vec<String>,
    /// A relative tolerance on top of the absolute one, against RUN_A's value
    #[arg(long, value_name = "R", default_value_t = 0.0, allow_negative_numbers = true)]
    rtol: f64,
    /// Where to draw B − A over time, a .png (default: RUN_B/diff.png); diff.json goes beside it
    /// with the same name
    #[arg(long, value_name = "PATH", conflicts_with = "no_figure")]
    figure: Option<PathBuf>,
    /// Draw no figure (diff.json still goes to RUN_B/diff.json)
    #[arg(long)]
    no_figure: bool,
    #[command(flatten)]
    gates: launcher::gate::GateArgs,
}

#[derive(Debug, Args)]
#[command(after_help = "Example: the pendulum's delay margin, measured against its linearised model:\n  \
looplab sweep pendulum --set sensors.encoder.quantum=0 --set sensors.wheel_speed.noise_std=0 \
--fault \"delay controller by 0 ticks at 2s\" --param faults.0.delay_ticks --from 25 --to 35 --duration 20\n\
A value is unstable when the swept fault's error (see `looplab show`, [limits]) passes the limit, or its peak in \
the run's last second is larger than in the fault's first second: the disturbance grew instead of dying out. \
Turn sensor noise and quantisation off to judge linear stability near the margin, as the theory does. \
Writes sweep.json and one run folder per value.")]
struct SweepCli {
    /// A scenario name or a launch file
    #[arg(default_value = "pendulum")]
    target: String,
    /// The dotted key to vary, as for --set; a number indexes a list (faults.0.delay_ticks)
    #[arg(long, value_name = "KEY")]
    param: String,
    #[arg(long, allow_negative_numbers = true)]
    from: f64,
    #[arg(long, allow_negative_numbers = true)]
    to: f64,
    #[arg(long, default_value_t = 1.0)]
    step: f64,
    #[command(flatten)]
    launch: LaunchArgs,
    /// Folder for sweep.json and the runs (default: runs/<time>-sweep-<scenario>)
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Runs at a time
    #[arg(long, default_value_t = 2)]
    jobs: usize,
    /// A metric of the scenario's summary to print as a column beside each value (for example
    /// etrack_mean_phase2 or lost). Repeatable
    #[arg(long = "metric", value_name = "NAME")]
    metrics: Vec<String>,
    /// Run each value as the five processes over shared memory, as `looplab run` does, instead of
    /// in this process (same trajectories, many times slower); needed for kill and stop faults
    #[arg(long)]
    processes: bool,
    #[command(flatten)]
    gates: launcher::gate::GateArgs,
}

/// The options `run` and `sweep` share: each becomes a launch-file override.
#[derive(Debug, Default, Args)]
struct LaunchArgs {
    /// Simulated duration in seconds (same as --set duration_s=S)
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true)]
    duration: Option<f64>,
    /// Loop rate in Hz (same as --set rate_hz=HZ)
    #[arg(long, value_name = "HZ", allow_negative_numbers = true)]
    rate: Option<f64>,
    /// Noise seed (same as --set seed=N)
    #[arg(long)]
    seed: Option<u64>,
    /// Give a cause to every loop over this end-to-end latency, µs, as every deadline miss gets
    /// one (same as --set explain_over_us=US)
    #[arg(long = "explain-over", value_name = "US", allow_negative_numbers = true)]
    explain_over: Option<f64>,
    /// Real time: run a probe beside the loop, a bare timer at the plant's priority and the
    /// loop's rate, and set its wake-up latency beside the plant's tick (same as --set probe=true)
    #[arg(long)]
    probe: bool,
    /// Record the kernel's scheduler events (root or CAP_SYS_ADMIN: tracefs) and name the task
    /// that ran while a loop process waited on the run queue; kept as sched.trace (same as --set
    /// trace_sched=true)
    #[arg(long = "trace-sched")]
    trace_sched: bool,
    /// Override any key of the launch file by its dotted path, for example
    /// --set sensors.encoder.bias=0.05 or --set estimator.kind=no-bias. Repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Inject a fault, added to the launch file's [[faults]]: KIND PROCESS [by AMOUNT]
    /// [P%] [nan|inf|out-of-range] [at TIME] [for DURATION]. Kinds: kill, stop (SIGSTOP, then
    /// SIGCONT), delay, drop, corrupt, cut (the link to another host). Examples: "kill estimator
    /// at 3s", "stop controller at 2s for 200ms", "delay controller by 3 ticks at 2s", "drop
    /// sensors 20% at 1s for 2s", "corrupt controller nan at 4s for 100ms", "cut bridge at 2s for
    /// 300ms". Repeatable.
    #[arg(long = "fault", value_name = "FAULT")]
    fault: Vec<String>,
}

#[derive(Debug, Args)]
#[command(
    after_help = "Keys: `looplab show <scenario>` prints the scenario's launch file, every key with its default \
and meaning; --set takes any of them.\n\
Run folder: summary.json, trajectory.csv, loops.csv, latency.hlog, run.mcap, launch.toml (resolved), logs/.\n\
Exit codes: 0 completed (or stopped with q in the dashboard), 1 the run failed (a process died, or files were left in shared memory), \
2 bad input, 3 a control gate of --fail-on or [gate] failed, 4 a timing gate, 5 both, \
130 interrupted (Ctrl-C or SIGTERM; the report is still written)."
)]
struct RunArgs {
    /// A scenario name (see `looplab list`) or the path of a launch file (.toml). A launch file
    /// overrides its scenario's defaults key by key.
    #[arg(default_value = "pendulum")]
    target: String,
    /// realtime: the plant ticks on a timer and counts deadline misses; lockstep: the plant
    /// waits for each command, deterministic and as fast as the loop allows
    #[arg(long, value_parser = ["realtime", "lockstep"])]
    mode: Option<String>,
    #[command(flatten)]
    launch: LaunchArgs,
    /// The run folder to write (default: runs/<time>-<scenario>); created if missing, must be
    /// empty if it exists
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// No live status line
    #[arg(long, short)]
    quiet: bool,
    /// Show the run live in the terminal: latency per hop and end to end, tick jitter, the
    /// processes, faults as they happen and the key signals; q stops the run in order, as Ctrl-C
    #[arg(long, conflicts_with_all = ["quiet", "in_process"])]
    dashboard: bool,
    /// Run the same plant, sensors, estimator and controller in this one process, in loop order,
    /// with no IPC and no monitor process (lockstep only; implies --mode lockstep): the run folder
    /// is the same and trajectory.csv byte-identical to the five-process run's, many times faster
    #[arg(long)]
    in_process: bool,
    /// After the run, draw its figures into the run folder, as `looplab plot` does
    #[arg(long)]
    plot: bool,
    /// The same as --fail-on limits: exit 3 when the control outcome is `limits exceeded` or
    /// `lost` (the report's `control:` line, summary.json's `limits`)
    #[arg(long)]
    fail_on_limits: bool,
    #[command(flatten)]
    gates: launcher::gate::GateArgs,
}

/// Judges `gates` on a finished run and says each one that failed or could not be judged, one
/// line each. Ok: the gates' exit code, if one failed; Err: a gate names what the run lacks (exit 2).
fn judge_gates(gates: &[Gate], summary: &launcher::Summary) -> Result<Option<u8>, ExitCode> {
    let judged = launcher::gate::judge(gates, summary).map_err(|e| bad_input(format!("--fail-on {e}")))?;
    judged.lines().for_each(|line| tell!("{line}"));
    Ok(judged.exit_code())
}

impl Default for RunArgs {
    fn default() -> Self {
        Self {
            target: "pendulum".into(),
            mode: None,
            launch: LaunchArgs::default(),
            out: None,
            quiet: false,
            dashboard: false,
            in_process: false,
            plot: false,
            fail_on_limits: false,
            gates: launcher::gate::GateArgs::default(),
        }
    }
}

/// `looplab`: the launcher with the built-in scenarios.
pub fn main() -> ExitCode {
    main_with(&scenarios::builtin())
}

/// The launcher with the scenarios of `catalog`: every command (`run`, `show`, `list`, `sweep`,
/// `bench`, `plot`, `export`) knows these. Its loop processes must load the same catalog: how a
/// crate of its own builds the six binaries is told at [`crate::runtime::stage::child::process_main_with`].
pub fn main_with(catalog: &Catalog) -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Some(Command::List) => {
            list(catalog);
            ExitCode::SUCCESS
        }
        Some(Command::Show { scenario }) => match catalog.find(&scenario) {
            Some(entry) => {
                say_raw!("{}", entry.text);
                ExitCode::SUCCESS
            }
            None if std::path::Path::new(&scenario).is_file() => show_file(&scenario, catalog),
            None => bad_input(format!(
                "unknown scenario \"{scenario}\"; allowed: {}, or the path of a launch file",
                catalog.names()
            )),
        },
        Some(Command::Run(args)) => run(args, catalog),
        Some(Command::Clean) => clean(),
        // Both written whole into memory first: clap_complete panics on a closed pipe
        // (`looplab completions fish | head -1`), and say_raw! ignores one.
        Some(Command::Completions { shell }) => {
            let mut text = vec![];
            clap_complete::generate(shell, &mut Cli::command(), "looplab", &mut text);
            say_raw!("{}", String::from_utf8_lossy(&text));
            ExitCode::SUCCESS
        }
        Some(Command::Man) => {
            let mut text = vec![];
            let rendered = render_man_pages(&mut text);
            say_raw!("{}", String::from_utf8_lossy(&text));
            report_failure(rendered.map_err(anyhow::Error::from))
        }
        Some(Command::Report { run_dir }) => match report::read_summary(&run_dir) {
            Ok(summary) => {
                say_raw!("{}", report::render(&summary));
                ExitCode::SUCCESS
            }
            Err(e) => bad_input(format!("{e:#}")),
        },
        Some(Command::Sweep(args)) => sweep(args, catalog),
        Some(Command::Bench(args)) => report_failure(bench::run(&args, catalog)),
        Some(Command::Export { run_dir, mcap, perfetto: write_trace, out, force }) => {
            let mcap_file = || export::write_mcap(&run_dir, catalog, force);
            let trace_file = || perfetto::write_perfetto(&run_dir, out.as_deref());
            let files: [(bool, &ExportFile<'_>); 2] = [(mcap, &mcap_file), (write_trace, &trace_file)];
            for (_, write) in files.into_iter().filter(|(wanted, _)| *wanted) {
                match write() {
                    Ok(path) => say!("wrote {}", path.display()),
                    Err(ToolError::BadInput(why)) => return bad_input(why),
                    Err(ToolError::Failed(e)) => return report_failure(Err(e)),
                }
            }
            ExitCode::SUCCESS
        }
        Some(Command::Plot { run_dir: Some(run_dir), from, to, .. }) => {
            let window = (from.is_some() || to.is_some()).then(|| from.unwrap_or(0.0)..to.unwrap_or(f64::INFINITY));
            figures(plot::run::plot_run(&run_dir, catalog, window))
        }
        Some(Command::Plot { paper: Some(scenario), out, .. }) => {
            figures(plot::paper::paper_figures(catalog, &scenario, out.as_deref()))
        }
        Some(Command::Plot { .. }) => bad_input("plot: give a run folder or --paper SCENARIO"),
        Some(Command::Compare { runs, out }) => match compare::compare(&runs, out.as_deref()) {
            Ok((table, chart)) => {
                say_raw!("{table}");
                say!("\nchart: {}", chart.display());
                ExitCode::SUCCESS
            }
            Err(ToolError::BadInput(why)) => bad_input(why),
            Err(ToolError::Failed(e)) => report_failure(Err(e)),
        },
        Some(Command::Diff(args)) => run_diff(args, catalog),
        Some(Command::Replay(args)) => match replay::replay(&args, catalog) {
            Ok(done) => {
                say_raw!("{}", replay::render(&done));
                done.gates.lines().for_each(|line| tell!("{line}"));
                done.gates.exit_code().map_or(ExitCode::SUCCESS, ExitCode::from)
            }
            Err(ToolError::BadInput(why)) => bad_input(why),
            Err(e) => {
                tell!("error: {e}");
                ExitCode::FAILURE
            }
        },
        Some(Command::Probe(args)) => probe(&args),
        Some(Command::BenchEcho(args)) => report_failure(bench::pingpong::echo_main(&args)),
        Some(Command::BenchUdsStage(args)) => report_failure(bench::uds_loop::stage_main(&args)),
        None => run(RunArgs::default(), catalog),
    }
}

/// `looplab show FILE`: the launch file resolved over its scenario's defaults, every key with
/// the value a run would use.
fn show_file(path: &str, catalog: &Catalog) -> ExitCode {
    match catalog.resolve(path, &[]) {
        Ok((config, _)) => {
            let about = if config.is_declared() {
                "as a declared system (LoopLab's launch/declared.toml explains every key)".to_owned()
            } else {
                format!("over the {0} scenario's defaults (`looplab show {0}` explains every key)", config.scenario)
            };
            say_raw!("# {path}, resolved {about}\n{}", toml::to_string(&config.document).unwrap_or_default());
            ExitCode::SUCCESS
        }
        Err(e) => bad_input(e),
    }
}

/// `looplab probe`: the probe alone; its report, and its JSON if asked.
fn probe(args: &ProbeCli) -> ExitCode {
    let options = launcher::probe::ProbeOptions {
        interval_us: args.interval_us,
        loops: args.loops,
        priority: args.priority,
        cpu: args.cpu,
        mlock: args.mlock,
    };
    let measured = match launcher::probe::run_alone(&options) {
        Ok(m) => m,
        Err(why) => return bad_input(why),
    };
    say!("{}", measured.render());
    if let Some(path) = &args.json {
        let written = serde_json::to_vec_pretty(&measured)
            .map_err(anyhow::Error::from)
            .and_then(|json| std::fs::write(path, json).map_err(anyhow::Error::from))
            .map_err(|e| e.context(format!("cannot write {}", path.display())));
        return report_failure(written);
    }
    ExitCode::SUCCESS
}

/// `looplab diff`: the table and the verdict; its exit code (`RunDiff::exit_code`), 2 bad input.
fn run_diff(args: DiffCli, catalog: &Catalog) -> ExitCode {
    let tolerances = match args.tolerances.iter().map(|t| diff::parse_tolerance(t)).collect() {
        Ok(t) => t,
        Err(e) => return bad_input(e),
    };
    let figure = (!args.no_figure).then(|| args.figure.clone().unwrap_or_else(|| args.b.join("diff.png")));
    let json = figure.as_ref().map_or_else(|| args.b.join("diff.json"), |f| f.with_extension("json"));
    let gates = match args.gates.gates() {
        Ok(gates) => gates,
        Err(e) => return bad_input(e),
    };
    let options = diff::DiffOptions { tolerances, rtol: args.rtol, figure, json: Some(json), gates };
    match diff::diff_runs(&args.a, &args.b, &options, catalog) {
        Ok(result) => {
            say_raw!("{}", result.render());
            if let Some(figure) = &result.figure {
                say!("figure: {}", figure.display());
            }
            if let Some(json) = &result.json {
                say!("diff.json: {}", json.display());
            }
            result.gates.lines().for_each(|line| tell!("{line}"));
            ExitCode::from(result.exit_code())
        }
        Err(ToolError::BadInput(why)) => bad_input(why),
        Err(ToolError::Failed(e)) => report_failure(Err(e)),
    }
}

/// Prints the figures written, or why none were.
fn figures(written: Result<Vec<PathBuf>, ToolError>) -> ExitCode {
    match written {
        Ok(paths) => {
            paths.iter().for_each(|path| say!("wrote {}", path.display()));
            ExitCode::SUCCESS
        }
        Err(ToolError::BadInput(why)) => bad_input(why),
        Err(ToolError::Failed(e)) => report_failure(Err(e)),
    }
}

/// Tells what the clean-up of runs whose launcher was killed found.
fn report_abandoned(done: &run_storage::Abandoned) {
    if !done.runs.is_empty() {
        tell!(
            "looplab: removed the shared-memory files of {} run(s) whose launcher was killed ({}){}",
            done.runs.len(),
            done.runs.join(", "),
            if done.killed > 0 { format!("; killed {} orphaned process(es)", done.killed) } else { String::new() }
        );
    }
    for path in &done.leftover {
        tell!("looplab: could not remove {path}");
    }
}

fn clean() -> ExitCode {
    let done = run_storage::clean_abandoned_runs();
    report_abandoned(&done);
    let (removed, left) = crate::scenarios::declared::fmu::remove_abandoned_unpack_folders();
    for folder in &removed {
        say!("looplab: removed {} (an FMU unpacked by a process that is gone)", folder.display());
    }
    for folder in &left {
        tell!("looplab: could not remove {}", folder.display());
    }
    if done.runs.is_empty() && removed.is_empty() {
        say!("nothing to clean: no abandoned run of this user in {}", run_storage::SHM_DIR);
    }
    if done.leftover.is_empty() && left.is_empty() { ExitCode::SUCCESS } else { ExitCode::FAILURE }
}

fn report_failure(result: Result<()>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if e.is::<crate::runtime::signals::Interrupted>() => {
            tell!("looplab: interrupted; stopped in order, nothing left behind");
            ExitCode::from(EXIT_INTERRUPTED)
        }
        Err(e) => {
            tell!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn list(catalog: &Catalog) {
    say!("Scenarios (looplab run <name>; defaults in the launch file named):");
    for s in catalog.entries() {
        say!("  {:<12} {}  [{}]", s.name, s.description, s.file);
    }
    say!(
        "A system of your own: a launch file with a [system] table and no `scenario` (its plant linear, an FMU or \
         Python; every key in launch/declared.toml): looplab run my_system.toml"
    );
}

/// One file `looplab export` writes: its path once written.
type ExportFile<'a> = dyn Fn() -> Result<PathBuf, ToolError> + 'a;

fn bad_input(message: impl std::fmt::Display) -> ExitCode {
    tell!("error: {message}");
    ExitCode::from(EXIT_BAD_INPUT)
}

fn sweep(args: SweepCli, catalog: &Catalog) -> ExitCode {
    let overrides = match overrides(None, &args.launch) {
        Ok(o) => o,
        Err(e) => return bad_input(e),
    };
    let gates = match args.gates.gates() {
        Ok(gates) => gates,
        Err(e) => return bad_input(e),
    };
    sweep::run(
        sweep::SweepArgs {
            target: args.target,
            param: args.param,
            from: args.from,
            to: args.to,
            step: args.step,
            overrides,
            out: args.out,
            jobs: args.jobs,
            processes: args.processes,
            metrics: args.metrics,
            gates,
        },
        catalog,
    )
}

/// looplab(1), then a page for each subcommand (looplab-run(1), ...), one after the other: `man -l`
/// shows them in turn.
fn render_man_pages(out: &mut Vec<u8>) -> std::io::Result<()> {
    let mut command = Cli::command();
    command.build();
    clap_mangen::Man::new(command.clone()).render(out)?;
    let source = format!("looplab {}", env!("CARGO_PKG_VERSION"));
    for sub in command.get_subcommands().filter(|sub| !sub.is_hide_set() && sub.get_name() != "help") {
        let name = format!("looplab-{}", sub.get_name());
        clap_mangen::Man::new(sub.clone().bin_name(name.clone())).title(name).source(source.clone()).render(out)?;
    }
    Ok(())
}

/// The launch-file overrides the command line gives, in the order they apply: the options,
/// then each --set, then each --fault.
fn overrides(mode: Option<&str>, launch: &LaunchArgs) -> Result<Vec<Override>, launch::LaunchError> {
    let mut texts: Vec<String> = Vec::new();
    if let Some(mode) = mode {
        texts.push(format!("mode={mode}"));
    }
    if let Some(d) = launch.duration {
        texts.push(format!("duration_s={d:?}"));
    }
    if let Some(r) = launch.rate {
        texts.push(format!("rate_hz={r:?}"));
    }
    if let Some(s) = launch.seed {
        texts.push(format!("seed={s}"));
    }
    if let Some(us) = launch.explain_over {
        texts.push(format!("explain_over_us={us:?}"));
    }
    if launch.probe {
        texts.push("probe=true".into());
    }
    if launch.trace_sched {
        texts.push("trace_sched=true".into());
    }
    texts.extend(launch.set.iter().cloned());
    texts.iter().map(|t| Override::parse(t)).chain(launch.fault.iter().map(|f| Override::fault(f))).collect()
}

fn run(args: RunArgs, catalog: &Catalog) -> ExitCode {
    // One process runs only lockstep: --in-process implies it unless --mode says otherwise.
    let mode = args.mode.as_deref().or(args.in_process.then_some("lockstep"));
    let overrides = match overrides(mode, &args.launch) {
        Ok(o) => o,
        Err(e) => return bad_input(e),
    };
    let (config, scenario) = match catalog.resolve(&args.target, &overrides) {
        Ok(r) => r,
        Err(e) => return bad_input(e),
    };
    let mut gates = match args.gates.gates() {
        Ok(gates) => config.gates.iter().cloned().chain(gates).collect::<Vec<_>>(),
        Err(e) => return bad_input(e),
    };
    if args.fail_on_limits {
        gates.push(Gate::parse("limits").expect("`limits` is a gate"));
    }
    if args.in_process
        && let Some(why) = crate::runtime::in_process::refusal(&config)
    {
        return bad_input(format!("--in-process: {why}; leave out --in-process to run the five processes"));
    }
    if let Some((key, why)) =
        crate::runtime::stage::realtime::refusal(&config, crate::runtime::transport::wait::available_cpus())
    {
        return bad_input(config.error(key, why));
    }
    if args.dashboard && !std::io::stdout().is_terminal() {
        return bad_input("--dashboard: standard output is not a terminal; run it in one, or leave out --dashboard");
    }
    // The in-process run needs no loop binaries.
    let binaries = if args.in_process {
        None
    } else {
        match launcher::locate_binaries() {
            Ok(b) => Some(b),
            Err(e) => return bad_input(format!("{e:#}")),
        }
    };
    let run_dir = match launcher::create_run_dir(args.out.as_deref(), &config.scenario) {
        Ok(d) => d,
        Err(e) => return bad_input(format!("{e:#}")),
    };
    let ran = match &binaries {
        Some(binaries) => {
            report_abandoned(&run_storage::clean_abandoned_runs());
            let view = match (args.dashboard, args.quiet) {
                (true, _) => launcher::LiveView::Dashboard,
                (false, true) => launcher::LiveView::Quiet,
                (false, false) => launcher::LiveView::StatusLine,
            };
            launcher::run_with(&config, scenario.as_ref(), binaries, &run_dir, view)
        }
        None => launcher::in_process::run_in_process(&config, scenario.as_ref(), &run_dir),
    };
    match ran {
        Ok((mut summary, outcome)) => {
            if outcome == launcher::Outcome::Completed {
                let twin = (args.target.as_str(), overrides.as_slice());
                let judged =
                    tools::twin::judge_against_twin(catalog, twin, &config, scenario.as_ref(), &run_dir, &mut summary)
                        .and_then(|()| launcher::summary::write(&summary, &run_dir).map_err(ToolError::Failed));
                if let Err(e) = judged {
                    tell!("error: the fault-free twin: {e}");
                    return ExitCode::FAILURE;
                }
            }
            say_raw!("{}", report::render(&summary));
            let (mut code, error) = launcher::exit_code(&outcome, &summary);
            if let Some(error) = error {
                tell!("error: {error}");
            }
            let gated = match judge_gates(&gates, &summary) {
                Ok(gated) => gated,
                Err(bad) => return bad,
            };
            // A run that failed otherwise keeps its code.
            if code == launcher::EXIT_OK
                && let Some(gated) = gated
            {
                code = gated;
            }
            let plotted =
                if args.plot { figures(plot::run::plot_run(&run_dir, catalog, None)) } else { ExitCode::SUCCESS };
            // A run that failed keeps its code; a failed plot fails a run that completed.
            if code == launcher::EXIT_OK { plotted } else { ExitCode::from(code) }
        }
        Err(e) => {
            tell!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
