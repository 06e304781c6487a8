//! The user's Python plant class as LoopLab's [`PlantModel`].
//!
//! LoopLab's RK4 calls `derivative(t, x, u, dx)` four times per sub-step: each call copies the
//! state and input into two views, calls the bound method and copies `dx` back: no conversion,
//! no lookup, the same views every call. The plant process holds the GIL for a whole plant step
//! ([`hold`]), so a derivative call does not take it again.

use anyhow::{Result, anyhow, bail};
use looplab_sdk::model::plant_model::{PlantModel, Stepping};
use looplab_sdk::runtime::stage::user_plant::PlantInfo;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyModule};

use crate::step::{Numbers, python_error};

/// What the user's plant class is given when the plant starts.
#[pyclass(frozen, get_all, module = "looplab")]
pub struct Plant {
    /// The run's resolved launch file, as a dict.
    config: Py<PyAny>,
    /// `[plant.parameters]`, name → value.
    parameters: Py<PyAny>,
    /// The names of `x`'s numbers (the declared state), in order.
    state_names: Vec<String>,
    /// The names of `u`'s numbers (the declared input), in order.
    input_names: Vec<String>,
    /// The names of `y`'s numbers (the declared outputs), in order.
    output_names: Vec<String>,
    /// The loop period, s.
    dt: f64,
    /// 0 for the first start in the run, then one more per restart.
    incarnation: u32,
}

#[pymethods]
impl Plant {
    fn __repr__(&self) -> String {
        format!(
            "Plant(incarnation={}, dt={}, state_names={:?}, input_names={:?}, output_names={:?})",
            self.incarnation, self.dt, self.state_names, self.input_names, self.output_names
        )
    }
}

impl Plant {
    fn new(py: Python<'_>, info: &PlantInfo) -> PyResult<Self> {
        let parameters = PyDict::new(py);
        for (name, value) in &info.spec.parameters {
            parameters.set_item(name, value)?;
        }
        Ok(Self {
            config: crate::config_dict(py, &info.config.document)?,
            parameters: parameters.into_any().unbind(),
            state_names: info.spec.state.clone(),
            input_names: info.spec.input.clone(),
            output_names: info.spec.outputs.clone(),
            dt: info.spec.dt,
            incarnation: info.incarnation,
        })
    }
}

/// Runs one plant step with the GIL held (see [`looplab_sdk::runtime::stage::user_plant::Hold`]).
pub fn hold(step: &mut dyn FnMut() -> Result<()>) -> Result<()> {
    Python::attach(|_| step())
}

pub struct PyPlantModel {
    /// What it is, for the report: `pendulum_plant.Pendulum`.
    name: String,
    derivative: Py<PyAny>,
    outputs: Option<Py<PyAny>>,
    initial_state: Option<Py<PyAny>>,
    /// The launch file's initial values (None: the class's own, or 0).
    initial: Vec<Option<f64>>,
    x: Numbers,
    u: Numbers,
    dx: Numbers,
    y: Numbers,
    /// Zeros: `dx` and `y` start at zero every call, whatever the last call left there.
    zeros: Vec<f64>,
}

// SAFETY: the views' memory is leaked (never freed) and only touched by the plant's thread while
// it holds the GIL; the Python objects are `Py`, which are Send.
unsafe impl Send for PyPlantModel {}

impl PyPlantModel {
    /// Makes the user's object from `cls(plant)` and finds its methods once.
    pub fn make(py: Python<'_>, cls: &Bound<'_, PyAny>, info: &PlantInfo) -> Result<Box<dyn PlantModel>> {
        let made = (|| -> PyResult<_> {
            let plant = Bound::new(py, Plant::new(py, info)?)?;
            let user = cls.call1((plant,))?;
            let method = |name: &str| -> PyResult<Option<Py<PyAny>>> {
                Ok(if user.hasattr(name)? { Some(user.getattr(name)?.unbind()) } else { None })
            };
            Ok((method("derivative")?, method("outputs")?, method("initial_state")?))
        })();
        let (derivative, outputs, initial_state) = made.map_err(|e| python_error(py, e))?;
        let name = class_name(cls);
        let derivative = derivative.ok_or_else(|| anyhow!("{name} has no derivative(self, t, x, u, dx) method"))?;
        let spec = info.spec;
        if outputs.is_none() && !spec.outputs.is_empty() {
            bail!(
                "the launch file declares outputs ({}) and {name} has no outputs(self, t, x, u, y)",
                spec.outputs.join(", ")
            );
        }
        let views = |len, writable| Numbers::new(py, len, writable).map_err(|e| python_error(py, e));
        let (n, m, p) = (spec.state.len(), spec.input.len(), spec.outputs.len());
        Ok(Box::new(Self {
            name,
            derivative,
            outputs,
            initial_state,
            initial: spec.initial.clone(),
            x: views(n, false)?,
            u: views(m, false)?,
            dx: views(n, true)?,
            y: views(p, true)?,
            zeros: vec![0.0; n.max(p)],
        }))
    }
}

/// `module.Class` of a class.
fn class_name(cls: &Bound<'_, PyAny>) -> String {
    let part = |attr: &str| cls.getattr(attr).and_then(|v| v.extract::<String>()).unwrap_or_else(|_| "?".into());
    format!("{}.{}", part("__module__"), part("__qualname__"))
}

impl PlantModel for PyPlantModel {
    fn describe(&self) -> String {
        format!("{}, a Python class integrated by LoopLab's RK4", self.name)
    }

    fn stepping(&self) -> Stepping {
        Stepping::Derivative
    }

    fn initial_state(&mut self) -> Result<Vec<f64>> {
        let n = self.initial.len();
        let own: Vec<f64> = match &self.initial_state {
            None => vec![0.0; n],
            Some(method) => Python::attach(|py| -> Result<Vec<f64>> {
                let values = method.call0(py).map_err(|e| python_error(py, e))?;
                values
                    .extract::<Vec<f64>>(py)
                    .map_err(|_| anyhow!("{}.initial_state() must return {n} numbers", self.name))
            })?,
        };
        if own.len() != n {
            bail!("{}.initial_state() returned {} numbers; the state has {n}", self.name, own.len());
        }
        Ok(self.initial.iter().zip(own).map(|(given, own)| given.unwrap_or(own)).collect())
    }

    fn derivative(&mut self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) -> Result<()> {
        Python::attach(|py| {
            self.x.set(py, x);
            self.u.set(py, u);
            self.dx.set(py, &self.zeros[..dx.len()]);
            let args = (t, self.x.view.bind(py), self.u.view.bind(py), self.dx.view.bind(py));
            self.derivative.call1(py, args).map_err(|e| python_error(py, e))?;
            self.dx.get(py, dx);
            Ok(())
        })
    }

    fn do_step(&mut self, _t: f64, _dt: f64, _u: &[f64], _x: &mut [f64]) -> Result<()> {
        bail!("{} is integrated by LoopLab (derivative); it does not step itself", self.name)
    }

    fn outputs(&mut self, t: f64, x: &[f64], u: &[f64], y: &mut [f64]) -> Result<()> {
        let Some(outputs) = &self.outputs else { return Ok(()) };
        if y.is_empty() {
            return Ok(());
        }
        Python::attach(|py| {
            self.x.set(py, x);
            self.u.set(py, u);
            self.y.set(py, &self.zeros[..y.len()]);
            let args = (t, self.x.view.bind(py), self.u.view.bind(py), self.y.view.bind(py));
            outputs.call1(py, args).map_err(|e| python_error(py, e))?;
            self.y.get(py, y);
            Ok(())
        })
    }

    fn set_state(&mut self, _x: &[f64]) -> Result<()> {
        // The state vector is LoopLab's: the class computes from the x it is given.
        Ok(())
    }
}

/// The class `spec` ("my_plant.py:Pendulum") names, its file imported from the current folder
/// (the launch file's). Err: one line saying what is wrong.
pub fn load_class<'py>(py: Python<'py>, spec: &str) -> std::result::Result<Bound<'py, PyAny>, String> {
    let (file, class) = spec.rsplit_once(':').ok_or_else(|| format!("\"{spec}\" names no class (file.py:Class)"))?;
    let path = std::path::absolute(file).map_err(|e| format!("{file}: {e}"))?;
    if !path.is_file() {
        let here = std::env::current_dir().map(|d| d.display().to_string()).unwrap_or_default();
        return Err(format!("{file} is not found in {here}"));
    }
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let folder = path.parent().map(|p| p.display().to_string()).unwrap_or_default();
    let imported = (|| -> PyResult<Bound<'py, PyModule>> {
        // Its folder first on the path, so that the modules beside it import too.
        py.import("sys")?.getattr("path")?.call_method1("insert", (0, folder))?;
        let util = py.import("importlib.util")?;
        let module_spec = util.call_method1("spec_from_file_location", (&stem, &path))?;
        let module = util.call_method1("module_from_spec", (&module_spec,))?;
        py.import("sys")?.getattr("modules")?.set_item(&stem, &module)?;
        module_spec.getattr("loader")?.call_method1("exec_module", (&module,))?;
        Ok(module.cast_into::<PyModule>()?)
    })();
    let module = imported.map_err(|e| {
        let why = python_error(py, e);
        format!("{file} does not import: {why}")
    })?;
    let Ok(cls) = module.getattr(class) else {
        let classes: Vec<String> = module
            .dict()
            .iter()
            .filter(|(_, v)| {
                v.is_instance_of::<pyo3::types::PyType>() && class_name(v).starts_with(&format!("{stem}."))
            })
            .map(|(k, _)| k.to_string())
            .collect();
        let has = if classes.is_empty() { "none".to_string() } else { classes.join(", ") };
        return Err(format!("{file} has no class {class} (its classes: {has})"));
    };
    if !cls.is_instance_of::<pyo3::types::PyType>() {
        return Err(format!("{file}: {class} is not a class"));
    }
    if !cls.hasattr("derivative").unwrap_or(false) {
        return Err(format!("class {class} in {file} has no derivative(self, t, x, u, dx) method"));
    }
    Ok(cls)
}

/// What one plant step of the declared system `launch`'s Python plant costs, in ns: the model
/// stepped `ticks` times from its initial state with a zero input, by the plant process's own
/// [`DeclaredPlant`], the GIL taken once per step as there (`looplab bench` and the report).
pub fn step_ns(py: Python<'_>, launch: &str, ticks: u64) -> Result<f64> {
    use looplab_sdk::config::{launch::resolve_config, python_plant};
    use looplab_sdk::model::{declared_plant::DeclaredPlant, plant_model::ModelSpec, scenario::Plant as _};
    // A declared system needs no catalog.
    let config = resolve_config(launch, &[], &[]).map_err(|e| anyhow!("{e}"))?;
    let Some(python) = &config.stages.plant else { bail!("{launch}: its plant is not a Python class") };
    let (file, class) = python_plant::spec(python).rsplit_once(':').expect("checked when the file loaded");
    let cls = load_class(py, &format!("{}:{class}", python.dir.join(file).display())).map_err(|e| anyhow!(e))?;
    let plant_section = config.plant_section().map_err(|e| anyhow!("{e}"))?;
    let spec = ModelSpec::declared(&config, &config.system().map_err(|e| anyhow!("{e}"))?, &plant_section);
    let info = PlantInfo { config: &config, spec: &spec, incarnation: 0 };
    let model = PyPlantModel::make(py, &cls, &info)?;
    let (inputs, dt) = (spec.input.len(), spec.dt);
    let mut plant = DeclaredPlant::new(model, spec.outputs.len(), inputs, plant_section.substeps)?;
    let u = vec![0.0; inputs];
    py.detach(move || {
        let start = std::time::Instant::now();
        for k in 0..ticks {
            hold(&mut || plant.step(k as f64 * dt, &u, dt))?;
        }
        Ok(start.elapsed().as_nanos() as f64 / ticks.max(1) as f64)
    })
}
