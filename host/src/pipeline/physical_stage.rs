//! The physical-parameter stage of the pipeline: a grey-box fit ([`crate::greybox`]) of a
//! physical structure on the identification run, giving parameters in physical units with
//! confidence intervals for the receipts, the report and the fleet.
//!
//! Configuration (`[physical]` in the pipeline TOML, optional):
//!
//! ```toml
//! [physical]
//! structure = "two-mass"        # stage, stage-velocity, dc-motor, two-mass, two-mass-position
//! known = { Kt = 1.0 }          # parameters given from elsewhere, SI units (see `--known`)
//! confidence = 0.95             # interval level, default 0.95
//! run = "high"                  # the run to fit, default the identification run
//! ```
//!
//! Units: the structure's equations are in SI units of the log's signals (see
//! [`crate::greybox::structure`]). A log in scaled units works when input and output carry the
//! same scale (e.g. torque in mN·m and speed in mrad/s with `Kt = 1`: every parameter is then
//! in SI units); the stage does not rescale.
use super::LogData;
use crate::error::{Error, Result};
use crate::greybox::{fit_log, GreyBoxFit, GreyBoxOptions, Structure};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The `[physical]` section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhysicalConfig {
    /// Structure name ([`Structure::parse`]).
    pub structure: String,
    /// Known parameters (name → SI value), held fixed. Default none.
    #[serde(default)]
    pub known: BTreeMap<String, f64>,
    /// Confidence level of the intervals, in (0, 1). Default 0.95.
    #[serde(default)]
    pub confidence: Option<f64>,
    /// Run to fit (a `[[runs]]` name). Default: the identification run.
    #[serde(default)]
    pub run: Option<String>,
}

impl PhysicalConfig {
    /// The grey-box options, checked (structure name, known names and values, the
    /// identifiability rule, the confidence level) without any data.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `[physical]` and what is wrong.
    pub fn options(&self) -> Result<GreyBoxOptions> {
        let section = |e: Error| match e {
            Error::InvalidArgument(m) => Error::InvalidArgument(format!("[physical]: {m}")),
            other => other,
        };
        let mut g = GreyBoxOptions::new(Structure::parse(&self.structure).map_err(section)?);
        for (name, value) in &self.known {
            g = g.with_known(name, *value);
        }
        if let Some(c) = self.confidence {
            g.confidence = c;
        }
        g.check().map_err(section)?;
        Ok(g)
    }
}

/// Result of [`run_physical_stage`].
#[derive(Debug, Clone, Serialize)]
pub struct PhysicalStage {
    /// The run fitted.
    pub run: String,
    /// The fit: parameters with units, intervals and status, fit quality, interval method.
    pub fit: GreyBoxFit,
}

/// Fits the configured structure on the run `cfg.run` (default `runs[nominal]`, the
/// identification run) after the pipeline's preprocessing. The grey-box fit draws its own
/// start from a black-box model of the structure's order on the same data (it does not reuse
/// the pipeline's identified model, whose order is chosen for control, not for the structure).
///
/// # Errors
/// [`Error::InvalidArgument`] for a bad `[physical]` section or an unknown run name;
/// [`Error::Data`] for a log that is not SISO or too short; [`Error::Numerical`] when the data
/// do not determine the parameters (the message names the combination).
pub fn run_physical_stage(
    cfg: &PhysicalConfig,
    runs: &[LogData],
    nominal: usize,
) -> Result<PhysicalStage> {
    let opts = cfg.options()?;
    let data = match &cfg.run {
        None => runs.get(nominal).ok_or_else(|| {
            Error::InvalidArgument(format!(
                "[physical]: identification run {nominal} does not exist ({} runs)",
                runs.len()
            ))
        })?,
        Some(name) => runs.iter().find(|r| &r.name == name).ok_or_else(|| {
            Error::InvalidArgument(format!(
                "[physical] run = {:?}: no run of that name (runs: {})",
                crate::error::excerpt(name),
                runs.iter()
                    .map(|r| r.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })?,
    };
    let fit = fit_log(&data.log, &opts)?;
    Ok(PhysicalStage {
        run: data.name.clone(),
        fit,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn config_is_checked_before_data() {
        let parse = |s: &str| toml::from_str::<PhysicalConfig>(s);
        let ok = parse("structure = \"two-mass\"\nknown = { Kt = 1.0 }").unwrap();
        assert!(ok.options().is_ok());
        let e = parse("structure = \"two-mass\"")
            .unwrap()
            .options()
            .unwrap_err();
        assert!(
            e.to_string().contains("[physical]: structure two-mass"),
            "{e}"
        );
        let e = parse("structure = \"three-mass\"")
            .unwrap()
            .options()
            .unwrap_err();
        assert!(e.to_string().contains("unknown structure"), "{e}");
        let e = parse("structure = \"stage\"\nknown = { mass = 1.0 }")
            .unwrap()
            .options()
            .unwrap_err();
        assert!(
            e.to_string().contains("has no parameter of that name"),
            "{e}"
        );
        assert!(parse("structure = \"stage\"\ntypo = 1").is_err());
    }
}

/// What the physical stage did in a run (`physical` in receipts.json).
#[derive(Debug, Clone, Serialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum PhysicalOutcome {
    /// The pipeline file has no `[physical]` section.
    Skipped,
    /// The structure was fitted: `run`, `fit` (parameters with unit, interval and status).
    Fitted(PhysicalStage),
    /// The fit failed; the rest of the run is unaffected.
    Failed {
        /// Why.
        error: String,
    },
}

impl PhysicalOutcome {
    /// Runs the stage when `cfg` is given; a failure is recorded, not propagated (the
    /// identified model and the receipts do not depend on it).
    pub fn of(cfg: Option<&PhysicalConfig>, runs: &[LogData], nominal: usize) -> Self {
        match cfg.map(|c| run_physical_stage(c, runs, nominal)) {
            None => PhysicalOutcome::Skipped,
            Some(Ok(stage)) => PhysicalOutcome::Fitted(stage),
            Some(Err(e)) => PhysicalOutcome::Failed {
                error: e.to_string(),
            },
        }
    }

    /// The line `ferrosid run` prints (empty when skipped): each parameter with its unit and
    /// interval, or `(known)` / `(undetermined)`.
    pub fn summary_line(&self) -> String {
        match self {
            PhysicalOutcome::Skipped => String::new(),
            PhysicalOutcome::Failed { error } => {
                format!("  physical parameters: failed ({error})\n")
            }
            PhysicalOutcome::Fitted(st) => {
                let params: Vec<String> = st
                    .fit
                    .parameters
                    .iter()
                    .map(|p| {
                        let v = super::fmt_num(p.value);
                        match (p.status, p.interval) {
                            (crate::greybox::ParameterStatus::Estimated, Some([lo, hi])) => {
                                format!(
                                    "{} {v} {} [{}, {}]",
                                    p.name,
                                    p.unit,
                                    super::fmt_num(lo),
                                    super::fmt_num(hi)
                                )
                            }
                            (crate::greybox::ParameterStatus::Known, _) => {
                                format!("{} {v} {} (known)", p.name, p.unit)
                            }
                            _ => format!("{} (undetermined)", p.name),
                        }
                    })
                    .collect();
                format!(
                    "  physical ({} on `{}`, {} % intervals, NRMSE {}): {}\n",
                    st.fit.structure.name(),
                    st.run,
                    super::fmt_num(100.0 * st.fit.confidence),
                    super::fmt_num(st.fit.nrmse),
                    params.join(", ")
                )
            }
        }
    }

    /// The fitted stage, if any.
    pub fn fitted(&self) -> Option<&PhysicalStage> {
        match self {
            PhysicalOutcome::Fitted(s) => Some(s),
            _ => None,
        }
    }
}
