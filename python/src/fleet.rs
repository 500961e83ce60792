//! The fleet's per-unit function and its summary for distributed engines (the Dask example
//! in python/examples/dask_fleet.py): [`ferrosid::fleet::discover_units`], the per-unit job
//! [`ferrosid::fleet::UnitJob::run`] (what `ferrosid fleet` runs on each unit) and
//! [`ferrosid::fleet::FleetSummary::new`] (how it summarises them). Unit results travel as
//! Python dicts converted field by field (pythonize), so floats arrive bit-exact and the
//! summary equals the one `ferrosid fleet --json` prints.
use crate::{json_text, run_released, to_py_err, UsageError};
use ferrosid::fleet::{discover_units, FleetSummary, Layout, UnitJob, UnitResult};
use ferrosid::pipeline::physical_stage::PhysicalConfig;
use ferrosid::pipeline::LoadedConfig;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

fn layout_of(s: &str) -> PyResult<Layout> {
    serde_json::from_value(serde_json::Value::String(s.into())).map_err(|_| {
        UsageError::new_err(format!(
            "layout {s:?}: expected \"subdirectories\" or \"prefix\""
        ))
    })
}

fn layout_name(l: Layout) -> &'static str {
    match l {
        Layout::Subdirectories => "subdirectories",
        Layout::Prefix => "prefix",
    }
}

/// The units of a fleet directory: (layout, serial numbers in order).
#[pyfunction]
pub fn fleet_units(py: Python<'_>, dir: PathBuf) -> PyResult<(String, Vec<String>)> {
    let (layout, serials) = run_released(py, || discover_units(&dir))?;
    Ok((layout_name(layout).into(), serials))
}

/// The pipeline on one unit of a fleet, as a dict (one entry of the summary's `units`).
/// `physical`: a `[physical]` section for every unit (structure, known, confidence, run),
/// as `ferrosid fleet --structure ... --known ...`.
#[pyfunction]
#[pyo3(signature = (dir, template, layout, serial, physical=None))]
pub fn fleet_unit<'py>(
    py: Python<'py>,
    dir: PathBuf,
    template: PathBuf,
    layout: &str,
    serial: String,
    physical: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let layout = layout_of(layout)?;
    let physical: Option<PhysicalConfig> = match physical {
        None => None,
        Some(d) => Some(crate::ops::options(py, "physical", Some(d))?),
    };
    let unit = run_released(py, || {
        if let Some(p) = &physical {
            p.options()?;
        }
        let template = LoadedConfig::load(&template)?;
        let job = UnitJob {
            dir: &dir,
            template: &template,
            layout,
            physical: physical.as_ref(),
        };
        Ok(job.run(&serial, None))
    })?;
    pythonize::pythonize(py, &unit).map_err(|e| UsageError::new_err(e.to_string()))
}

/// The fleet summary of unit results (dicts from [`fleet_unit`], any order) as the JSON text
/// of `ferrosid fleet --json`.
#[pyfunction]
pub fn fleet_summary(
    py: Python<'_>,
    template: PathBuf,
    layout: &str,
    units: Vec<Bound<'_, PyAny>>,
) -> PyResult<String> {
    let layout = layout_of(layout)?;
    let mut results = units
        .iter()
        .map(|u| pythonize::depythonize::<UnitResult>(u))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| UsageError::new_err(format!("not a fleet unit result: {e}")))?;
    results.sort_by(|a, b| a.serial.cmp(&b.serial));
    let template = LoadedConfig::load(&template).map_err(|e| to_py_err(py, &e))?;
    run_released(py, move || {
        let s = &template.config.signals;
        json_text(&FleetSummary::new(
            layout,
            results,
            &s.output_unit,
            &s.input_unit,
        ))
    })
}
