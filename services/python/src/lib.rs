use pyo3::prelude::*;

#[pymodule]
fn looplab(_m: &Bound<'_, PyModule>) -> PyResult<()> {
    Ok(())
}
