//! The user's Python object as LoopLab's [`Step`].
//!
//! Per loop the runner copies the input into `x`, the output (zeros, or a sensors stage's
//! prefilled readings) into `u`, calls the bound `step`, and copies `u` back, all with the GIL
//! held (so a thread of the user's that kept `u` cannot write it meanwhile): no conversion, no
//! lookup, the same two views every call.

use std::ptr::NonNull;

use anyhow::{Result, anyhow};
use looplab_sdk::runtime::stage::user_stage::{StageInfo, Step};
use pyo3::ffi;
use pyo3::prelude::*;
use pyo3::types::PyBytes;

use crate::Stage;

pub struct PyStep {
    step: Py<PyAny>,
    freeze: Option<Py<PyAny>>,
    thaw: Option<Py<PyAny>>,
    x: Numbers,
    u: Numbers,
}

impl PyStep {
    /// Makes the user's object from `cls(stage)` and finds its methods once.
    pub fn make(py: Python<'_>, cls: &Bound<'_, PyAny>, info: &StageInfo) -> Result<Box<dyn Step>> {
        let made = (|| -> PyResult<_> {
            let stage = Bound::new(py, Stage::new(py, info)?)?;
            let user = cls.call1((stage,))?;
            let method = |name: &str| -> PyResult<Option<Py<PyAny>>> {
                Ok(if user.hasattr(name)? { Some(user.getattr(name)?.unbind()) } else { None })
            };
            Ok((method("step")?, method("freeze")?, method("thaw")?))
        })();
        let (step, freeze, thaw) = made.map_err(|e| python_error(py, e))?;
        let step = step.ok_or_else(|| anyhow!("the stage's class has no step(self, t, x, u) method"))?;
        let x = Numbers::new(py, info.input_names.len(), false).map_err(|e| python_error(py, e))?;
        let u = Numbers::new(py, info.output_names.len(), true).map_err(|e| python_error(py, e))?;
        Ok(Box::new(Self { step, freeze, thaw, x, u }))
    }
}

impl Step for PyStep {
    fn step(&mut self, t: f64, input: &[f64], output: &mut [f64]) -> Result<()> {
        Python::attach(|py| {
            self.x.set(py, input);
            self.u.set(py, output);
            self.step.call1(py, (t, self.x.view.bind(py), self.u.view.bind(py))).map_err(|e| python_error(py, e))?;
            self.u.get(py, output);
            Ok(())
        })
    }

    fn freeze(&self) -> Result<Option<Vec<u8>>> {
        let Some(freeze) = &self.freeze else { return Ok(None) };
        Python::attach(|py| {
            let frozen = freeze.call0(py).map_err(|e| python_error(py, e))?;
            if frozen.is_none(py) {
                return Ok(None);
            }
            let bytes = frozen.bind(py).cast::<PyBytes>().map_err(|_| {
                let kind = frozen.bind(py).get_type().name().map_or("?".to_string(), |n| n.to_string());
                anyhow!("freeze must return bytes (or None), not {kind}")
            })?;
            Ok(Some(bytes.as_bytes().to_vec()))
        })
    }

    fn thaw(&mut self, frozen: &[u8]) -> Result<()> {
        let Some(thaw) = &self.thaw else { return Ok(()) };
        Python::attach(|py| {
            thaw.call1(py, (PyBytes::new(py, frozen),)).map_err(|e| python_error(py, e))?;
            Ok(())
        })
    }
}

/// Prints the exception's traceback on stderr (the stage's log) and returns its last line
/// (`ValueError: boom`) as the error, which the report and the timeline show.
pub(crate) fn python_error(py: Python<'_>, err: PyErr) -> anyhow::Error {
    // traceback, not PyErr_Print: that one ends the process at once on a SystemExit, before
    // the runner has said goodbye.
    let formatted = (|| -> PyResult<(String, String)> {
        let traceback = py.import("traceback")?;
        let (kind, value) = (err.get_type(py), err.value(py));
        let lines: Vec<String> =
            traceback.call_method1("format_exception", (&kind, value, err.traceback(py)))?.extract()?;
        let last: Vec<String> = traceback.call_method1("format_exception_only", (&kind, value))?.extract()?;
        Ok((lines.concat(), last.concat()))
    })();
    match formatted {
        Ok((full, last)) => {
            // Ignored if stderr is gone (a launcher that died): the error still goes up.
            let _ = std::io::Write::write_all(&mut std::io::stderr(), full.as_bytes());
            anyhow!("{}", last.trim_end().lines().last().unwrap_or_default())
        }
        Err(_) => anyhow!("{err}"),
    }
}

// memoryobject.h's flags for PyMemoryView_FromMemory (pyo3's ffi has them only outside abi3).
const PYBUF_READ: std::ffi::c_int = 0x100;
const PYBUF_WRITE: std::ffi::c_int = 0x200;

/// A run of f64s that Python sees as a float64 memoryview (format 'd'), made once: numpy
/// (`numpy.asarray(x)`) wraps it without copying.
pub(crate) struct Numbers {
    data: NonNull<f64>,
    len: usize,
    pub(crate) view: Py<PyAny>,
}

impl Numbers {
    pub(crate) fn new(py: Python<'_>, len: usize, writable: bool) -> PyResult<Self> {
        // Leaked on purpose: a few numbers per process, and a view the user keeps (self.x = x)
        // must never point at freed memory, whenever Python lets go of it.
        let data = NonNull::from(Box::leak(vec![0.0f64; len].into_boxed_slice())).cast::<f64>();
        let flags = if writable { PYBUF_WRITE } else { PYBUF_READ };
        let bytes = (len * size_of::<f64>()) as ffi::Py_ssize_t;
        // SAFETY: the memory is valid for `bytes` bytes for the rest of the process.
        let raw = unsafe { ffi::PyMemoryView_FromMemory(data.as_ptr().cast(), bytes, flags) };
        // SAFETY: a new reference, or null with the exception set.
        let raw = unsafe { Bound::from_owned_ptr_or_err(py, raw)? };
        let view = raw.call_method1("cast", ("d",))?.unbind();
        Ok(Self { data, len, view })
    }

    /// Writes the numbers, with the GIL held (`_py`): Python writes a view only with it, so no
    /// thread of the user's that kept the view writes it meanwhile.
    pub(crate) fn set(&mut self, _py: Python<'_>, from: &[f64]) {
        // SAFETY: `len` f64s, ours; Python touches them only with the GIL, which this thread holds.
        unsafe { std::slice::from_raw_parts_mut(self.data.as_ptr(), self.len) }.copy_from_slice(from);
    }

    /// Reads the numbers, with the GIL held (as [`set`](Self::set)).
    pub(crate) fn get(&self, _py: Python<'_>, into: &mut [f64]) {
        // SAFETY: as in `set`.
        into.copy_from_slice(unsafe { std::slice::from_raw_parts(self.data.as_ptr(), self.len) });
    }
}
