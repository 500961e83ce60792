//! `ferrosid._native`: the library operations of ferrosid for Python. Every function maps its
//! arguments to the library's typed options, calls the same library function as the command
//! line (`ferrosid::ops::*`, `ferrosid::pipeline::run_pipeline`, the pipeline's stages through
//! `ferrosid::pipeline::arrays`, `ferrosid::fleet`) with the GIL released, and returns the
//! report as the CLI's JSON text (plus the report's inline SVG where there is one); the Python
//! package (`python/ferrosid/`) wraps them in typed result
//! objects. Errors become `ferrosid.FerrosidError` subclasses carrying the library's message
//! and the CLI's exit-code category; a panic is caught at the boundary and becomes a
//! `FerrosidError` too, never an abort of the interpreter.
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

mod fleet;
mod ops;
mod pipeline;
mod stages;

pyo3::create_exception!(
    _native,
    FerrosidError,
    PyException,
    "An error of ferrosid: `category` and `exit_code` as the command line's exit status."
);
pyo3::create_exception!(
    _native,
    DataError,
    FerrosidError,
    "Unusable input data (exit code 3)."
);
pyo3::create_exception!(
    _native,
    UsageError,
    FerrosidError,
    "An invalid argument or option (exit code 2)."
);
pyo3::create_exception!(
    _native,
    NumericalError,
    FerrosidError,
    "A numerical failure that could not be trusted (exit code 4)."
);

/// The Python exception for a library error: the class by the CLI's exit code, the message
/// as the CLI prints it, and attributes `category` and `exit_code`.
pub(crate) fn to_py_err(py: Python<'_>, e: &ferrosid::Error) -> PyErr {
    let code = ferrosid::cli::exit_code_for(e);
    let msg = e.to_string();
    let (err, category) = match code {
        2 => (UsageError::new_err(msg), "usage"),
        3 => (DataError::new_err(msg), "data"),
        _ => (NumericalError::new_err(msg), "numerical"),
    };
    let value = err.value(py);
    // Setting attributes on a fresh exception instance cannot fail in practice; if it did,
    // the exception still carries its class and message.
    let _ = value.setattr("category", category);
    let _ = value.setattr("exit_code", code);
    err
}

/// Runs `f` without the GIL, turning a library error into its Python exception and a panic
/// into a `FerrosidError` (the last net: the library reports bad input as errors).
pub(crate) fn run_released<T: Send>(
    py: Python<'_>,
    f: impl FnOnce() -> ferrosid::Result<T> + Send,
) -> PyResult<T> {
    let r = py.allow_threads(|| std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)));
    match r {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(to_py_err(py, &e)),
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            let err = FerrosidError::new_err(format!(
                "internal error (a bug in ferrosid, please report it): {what}"
            ));
            let _ = err.value(py).setattr("category", "internal");
            let _ = err.value(py).setattr("exit_code", 101);
            Err(err)
        }
    }
}

/// JSON text exactly as the CLI prints it (pretty, trailing newline).
pub(crate) fn json_text<T: serde::Serialize>(v: &T) -> ferrosid::Result<String> {
    ferrosid::pipeline::json_pretty(v)
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("FerrosidError", py.get_type::<FerrosidError>())?;
    m.add("DataError", py.get_type::<DataError>())?;
    m.add("UsageError", py.get_type::<UsageError>())?;
    m.add("NumericalError", py.get_type::<NumericalError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(ops::frf, m)?)?;
    m.add_function(wrap_pyfunction!(ops::identify, m)?)?;
    m.add_function(wrap_pyfunction!(ops::read_log, m)?)?;
    m.add_function(wrap_pyfunction!(pipeline::run_pipeline, m)?)?;
    m.add_function(wrap_pyfunction!(stages::audit, m)?)?;
    m.add_function(wrap_pyfunction!(stages::fit_wm, m)?)?;
    m.add_function(wrap_pyfunction!(stages::tune_pid, m)?)?;
    m.add_function(wrap_pyfunction!(stages::gap, m)?)?;
    m.add_function(wrap_pyfunction!(fleet::fleet_units, m)?)?;
    m.add_function(wrap_pyfunction!(fleet::fleet_unit, m)?)?;
    m.add_function(wrap_pyfunction!(fleet::fleet_summary, m)?)?;
    Ok(())
}
