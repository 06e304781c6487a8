//! `looplab`, the Python module: a stage of your own in Python, run by LoopLab's own runner.
//!
//! ```python
//! import looplab
//!
//! class Controller:
//!     def __init__(self, stage):     # stage.config, .role, .input_names, .output_names, .incarnation
//!         self.k = stage.config["controller"]["gains"]
//!     def step(self, t, x, u):       # x: this loop's input, u: its output (float64 memoryviews)
//!         u[0] = -(self.k[0] * x[0] + self.k[1] * x[1] + self.k[2] * x[2])
//!
//! looplab.run(Controller)
//! ```
//!
//! `run` hands the process to [`looplab_shared::runtime::user_stage::run_step`] with the GIL
//! released; the runner takes it back only to call the user's methods (see [`step`]).

mod step;

use std::process::ExitCode;

use looplab_shared::runtime::user_stage::{StageInfo, run_step};
use pyo3::exceptions::PySystemExit;
use pyo3::prelude::*;

/// What the user's class is given when the stage starts.
#[pyclass(frozen, get_all, module = "looplab")]
struct Stage {
    /// The run's resolved launch file, as a dict.
    config: Py<PyAny>,
    /// "controller", "estimator" or "sensors".
    role: String,
    /// The names of `x`'s numbers, in order.
    input_names: Vec<String>,
    /// The names of `u`'s numbers, in order.
    output_names: Vec<String>,
    /// 0 for the first start in the run, then one more per restart.
    incarnation: u32,
}

#[pymethods]
impl Stage {
    fn __repr__(&self) -> String {
        format!(
            "Stage(role={:?}, incarnation={}, input_names={:?}, output_names={:?})",
            self.role, self.incarnation, self.input_names, self.output_names
        )
    }
}

impl Stage {
    fn new(py: Python<'_>, info: &StageInfo) -> PyResult<Self> {
        // The launch file through JSON: every TOML value has a JSON one, and json.loads makes
        // the plain dicts, lists, numbers and strings a user expects.
        let text = serde_json::to_string(&info.config.document)
            .map_err(|e| pyo3::exceptions::PyValueError::new_err(format!("the launch file as JSON: {e}")))?;
        let config = py.import("json")?.call_method1("loads", (text,))?.unbind();
        Ok(Self {
            config,
            role: info.role.name().to_string(),
            input_names: info.input_names.clone(),
            output_names: info.output_names.clone(),
            incarnation: info.incarnation,
        })
    }
}

/// Runs the stage the launcher started with an instance of `cls` as its computation: returns
/// when the run ends, or raises SystemExit with the stage's exit code if it failed (the reason
/// is on stderr already).
#[pyfunction]
fn run(py: Python<'_>, cls: Py<PyAny>) -> PyResult<()> {
    // Python's own SIGINT handler would turn a Ctrl-C into a KeyboardInterrupt inside the next
    // step; with the default action the runner's handler alone sees it, as a stop request.
    let signal = py.import("signal")?;
    signal.call_method1("signal", (signal.getattr("SIGINT")?, signal.getattr("SIG_DFL")?))?;
    let code = py.detach(move || run_step(move |info| Python::attach(|py| step::PyStep::make(py, cls.bind(py), info))));
    if code == ExitCode::SUCCESS {
        return Ok(());
    }
    let status = (1..=u8::MAX).find(|&n| ExitCode::from(n) == code).unwrap_or(1);
    Err(PySystemExit::new_err(status))
}

#[pymodule]
fn looplab(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Stage>()?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add("MAX_FROZEN_BYTES", looplab_shared::runtime::user_stage::MAX_FROZEN_BYTES)?;
    Ok(())
}
