//! `looplab`, the Python module: a stage of your own in Python, run by LoopLab's own runner.
//!
//! ```python
//! import looplab
//!
//! class Controller:
//!     def __init__(self, stage):     # stage.config, .role, .input_names, .output_names, .incarnation
//!         self.k = stage.config["parameters"]["gains"]   # the launch file's [parameters]
//!         self.stage = stage
//!     def step(self, t, x, u):       # x: this loop's input, u: its output (float64 memoryviews)
//!         r = self.stage.reference(t)[0]   # [reference], one value per entry (.reference_names)
//!         u[0] = -(self.k[0] * (x[0] - r) + self.k[1] * x[1])
//!
//! looplab.run(Controller)
//! ```
//!
//! A plant of your own in Python (`[plant] python = "my_plant.py:Pendulum"` in a declared
//! system's launch file; the launcher starts `looplab.run_plant("my_plant.py:Pendulum")`):
//!
//! ```python
//! class Pendulum:
//!     def __init__(self, plant):     # plant.config, .parameters, .state_names, .input_names, ...
//!         self.g = plant.parameters["g"]
//!     def derivative(self, t, x, u, dx):   # dx: a float64 memoryview to write ẋ into
//!         dx[0] = x[1]
//!         dx[1] = -self.g * x[0] + u[0]
//!     def outputs(self, t, x, u, y):       # optional: the declared outputs
//!         y[0] = x[0]
//! ```
//!
//! `run` hands the process to [`looplab_sdk::runtime::stage::user_stage::run_step`] with the GIL
//! released; the runner takes it back only to call the user's methods (see [`step`]).

mod plant;
mod step;

use std::process::ExitCode;

use looplab_sdk::model::reference::Signal;
use looplab_sdk::runtime::stage::user_plant::run_plant_holding;
use looplab_sdk::runtime::stage::user_stage::{StageInfo, run_step};
use pyo3::exceptions::PySystemExit;
use pyo3::prelude::*;

/// What the user's class is given when the stage starts.
#[pyclass(frozen, module = "looplab")]
struct Stage {
    /// The run's resolved launch file, as a dict (`config["parameters"]`: the launch file's free
    /// `[parameters]` table).
    #[pyo3(get)]
    config: Py<PyAny>,
    /// "controller", "estimator" or "sensors".
    #[pyo3(get)]
    role: String,
    /// The names of `x`'s numbers, in order.
    #[pyo3(get)]
    input_names: Vec<String>,
    /// The names of `u`'s numbers, in order.
    #[pyo3(get)]
    output_names: Vec<String>,
    /// 0 for the first start in the run, then one more per restart.
    #[pyo3(get)]
    incarnation: u32,
    /// What each of a declared system's references tracks ("state.position"), in order.
    #[pyo3(get)]
    reference_names: Vec<String>,
    references: Vec<Signal>,
}

#[pymethods]
impl Stage {
    /// Each reference at simulation time `t` (s), in the order of `reference_names`: the
    /// launch file's `[reference]`, as the metrics and limits judge against it.
    fn reference(&self, t: f64) -> Vec<f64> {
        self.references.iter().map(|r| r.at(t)).collect()
    }

    fn __repr__(&self) -> String {
        format!(
            "Stage(role={:?}, incarnation={}, input_names={:?}, output_names={:?})",
            self.role, self.incarnation, self.input_names, self.output_names
        )
    }
}

impl Stage {
    fn new(py: Python<'_>, info: &StageInfo) -> PyResult<Self> {
        Ok(Self {
            config: config_dict(py, &info.config.document)?,
            role: info.role.name().to_string(),
            input_names: info.input_names.clone(),
            output_names: info.output_names.clone(),
            incarnation: info.incarnation,
            reference_names: info.references.iter().map(|r| r.track.clone()).collect(),
            references: info.references.iter().map(|r| r.signal.clone()).collect(),
        })
    }
}

/// The launch file as a dict, through JSON: every TOML value has a JSON one, and json.loads
/// makes the plain dicts, lists, numbers and strings a user expects.
fn config_dict(py: Python<'_>, document: &toml::Table) -> PyResult<Py<PyAny>> {
    let text = serde_json::to_string(document)
        .map_err(|e| pyo3::exceptions::PyValueError::new_err(format!("the launch file as JSON: {e}")))?;
    Ok(py.import("json")?.call_method1("loads", (text,))?.unbind())
}

/// Python's own SIGINT handler would turn a Ctrl-C into a KeyboardInterrupt inside the next
/// call; with the default action the runner's handler alone sees it, as a stop request.
fn default_sigint(py: Python<'_>) -> PyResult<()> {
    let signal = py.import("signal")?;
    signal.call_method1("signal", (signal.getattr("SIGINT")?, signal.getattr("SIG_DFL")?))?;
    Ok(())
}

/// Returns if the runner succeeded, else raises SystemExit with its exit code (the reason is on
/// stderr already).
fn exit_with(code: ExitCode) -> PyResult<()> {
    if code == ExitCode::SUCCESS {
        return Ok(());
    }
    let status = (1..=u8::MAX).find(|&n| ExitCode::from(n) == code).unwrap_or(1);
    Err(PySystemExit::new_err(status))
}

/// Runs the plant the launcher started with an instance of `plant` as its model: a class, or
/// "my_plant.py:Pendulum" (the file from the current folder). Returns when the run ends, or
/// raises SystemExit with the plant's exit code if it failed (2: the class cannot be loaded).
#[pyfunction]
fn run_plant(py: Python<'_>, plant: Bound<'_, PyAny>) -> PyResult<()> {
    let cls = match plant.extract::<String>() {
        Ok(spec) => match plant::load_class(py, &spec) {
            Ok(cls) => cls,
            Err(why) => {
                eprintln!("plant: error: {why}");
                return Err(PySystemExit::new_err(2));
            }
        },
        Err(_) => plant,
    }
    .unbind();
    default_sigint(py)?;
    exit_with(py.detach(move || {
        run_plant_holding(
            move |info| Python::attach(|py| plant::PyPlantModel::make(py, cls.bind(py), info)),
            plant::hold,
        )
    }))
}

/// Checks that "my_plant.py:Pendulum" can be a plant: the file imports and has the class, with
/// `derivative`. Returns 0, or says why on stderr in one line and returns 2 (the launcher runs
/// this before anything starts).
#[pyfunction]
fn check_plant(py: Python<'_>, spec: &str) -> u8 {
    match plant::load_class(py, spec) {
        Ok(_) => 0,
        Err(why) => {
            eprintln!("{why}");
            2
        }
    }
}

/// What one plant step of the declared system `launch`'s Python plant costs, in ns: `ticks`
/// steps as the plant process takes them (LoopLab's RK4, the GIL once per step), zero input.
#[pyfunction]
#[pyo3(signature = (launch, ticks = 20000))]
fn plant_step_ns(py: Python<'_>, launch: &str, ticks: u64) -> PyResult<f64> {
    plant::step_ns(py, launch, ticks).map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(format!("{e:#}")))
}

/// Runs the stage the launcher started with an instance of `cls` as its computation: returns
/// when the run ends, or raises SystemExit with the stage's exit code if it failed (the reason
/// is on stderr already).
#[pyfunction]
fn run(py: Python<'_>, cls: Py<PyAny>) -> PyResult<()> {
    default_sigint(py)?;
    exit_with(py.detach(move || run_step(move |info| Python::attach(|py| step::PyStep::make(py, cls.bind(py), info)))))
}

#[pymodule]
fn looplab(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Stage>()?;
    m.add_class::<plant::Plant>()?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(run_plant, m)?)?;
    m.add_function(wrap_pyfunction!(check_plant, m)?)?;
    m.add_function(wrap_pyfunction!(plant_step_ns, m)?)?;
    m.add("MAX_FROZEN_BYTES", looplab_sdk::runtime::stage::user_stage::MAX_FROZEN_BYTES)?;
    Ok(())
}
