//! The pipeline report: one self-contained HTML file (inline CSS and SVG; no script, no
//! network access needed to view it) and the same figures as separate SVG files.
//!
//! Figures ([`figures`], one function each in [`charts`]; file names `figures/<name>.svg`):
//! * `bode` — magnitude and phase of the estimation run's ETFE (filled dots: bins passing the
//!   coherence gate; hollow grey: rejected bins; shaded: the excluded bands), the other logs'
//!   ETFEs (thin lines), and the identified model;
//! * `coherence` — magnitude-squared coherence of every log with the gate;
//! * `singular_values` — the N4SID singular values with the chosen order;
//! * `robustness` — |T| against 1/|W_m| (robust stability needs |T| < 1/|W_m|) with the
//!   measured 1/l_m;
//! * `uncertainty` — the envelope l_m and the fitted |W_m|;
//! * `sensitivity` — |S| with the M_s limit and the −3 dB line;
//! * `step` — the saturated closed-loop step: output with the reference, and the actuator
//!   command (applied and demanded) against the rails;
//! * `audit` — gain and phase shifts between amplitudes across the audit band, thresholds;
//! * `validation` — measured and simulated output on the validation log;
//! * `describing_function`, `limit_cycle` — the compensation stage's describing-function
//!   picture and simulated loop without/with the compensation ([`compensation_section`]).
//!
//! Figures that need missing data (no controller, one run, no validation log) are left out,
//! and the corresponding report section says why. Section ids (stable, tested):
//! `verdict`, `receipts`, `frequency-response`, `coherence`, `order`, `robustness`,
//! `sensitivity`, `step`, `audit`, `validation`, `gap`, `compensation`, `controller`,
//! `provenance`.
//!
//! The HTML is written by askama templates (`host/templates/report/`, one per section, the
//! page head in `banner.html` and its end in `provenance.html`); each section module here holds
//! the view its template reads (the run and the figures, with a few helpers) and appends the
//! rendered section. Every `{{ … }}` is escaped by [`escape::ReportHtml`]; SVG figures are
//! inlined with `|safe`.
/// `Deref` to [`View`] for a section template's wrapper `struct Name<'a>(View<'a>)`, so that
/// its template reads `run`, `figs` and `self.fig(…)` directly.
macro_rules! view_deref {
    ($t:ident) => {
        impl<'a> std::ops::Deref for $t<'a> {
            type Target = super::View<'a>;
            fn deref(&self) -> &super::View<'a> {
                &self.0
            }
        }
    };
}

mod captions;
mod charts;
mod compensation_section;
mod control_compare;
mod control_section;
pub(crate) mod escape;
mod filters;
mod gap_section;
mod physical_section;
mod sections;

pub use charts::figures;
use charts::*;
pub use escape::esc;

use crate::error::{Error, Result};
use crate::pipeline::{fmt_num, PipelineRun};
use crate::robust::receipts::ReceiptKind;

/// Names of all figures the report can contain (file stems in `figures/`).
pub const FIGURE_NAMES: [&str; 11] = [
    "bode",
    "coherence",
    "singular_values",
    "robustness",
    "uncertainty",
    "sensitivity",
    "step",
    "audit",
    "validation",
    "describing_function",
    "limit_cycle",
];

/// Width of every figure, px.
pub const FIG_WIDTH: u32 = 1000;

/// One rendered figure.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    /// File stem (`bode`, `coherence`, ...).
    pub name: &'static str,
    /// Caption for the report.
    pub caption: String,
    /// The SVG document.
    pub svg: String,
}

/// A receipt number with its unit, the dimensionless unit "1" left out.
fn with_unit(v: f64, unit: &str) -> String {
    let n = if v.is_finite() {
        fmt_num(v)
    } else if v.is_nan() {
        "undefined".into()
    } else if v > 0.0 {
        "∞".into()
    } else {
        "−∞".into()
    };
    if unit == "1" || unit.is_empty() {
        n
    } else {
        format!("{n} {unit}")
    }
}

fn receipt_value(run: &PipelineRun, kind: ReceiptKind) -> String {
    run.receipts
        .of_kind(kind)
        .map_or("-".to_string(), |r| with_unit(r.value, &r.unit))
}

/// What every section template reads: the run and its rendered figures.
#[derive(Clone, Copy)]
struct View<'a> {
    run: &'a PipelineRun,
    figs: &'a [Figure],
}

impl<'a> View<'a> {
    /// The figure `name`, if the run produced it.
    fn fig(&self, name: &str) -> Option<&'a Figure> {
        self.figs.iter().find(|f| f.name == name)
    }
}

/// Renders `t` at the end of `h`. askama drops a template file's final newline; every section
/// ends with one, so it is put back here.
fn append(h: &mut String, t: &impl askama::Template) -> Result<()> {
    t.render_into(h)
        .map_err(|e| Error::Numerical(format!("rendering the HTML report: {e}")))?;
    h.push('\n');
    Ok(())
}

/// The self-contained HTML report. `figs` are the figures of [`figures`] (inlined).
pub fn render_html(run: &PipelineRun, figs: &[Figure]) -> Result<String> {
    let mut h = String::with_capacity(512 * 1024);
    let v = View { run, figs };
    sections::banner(&mut h, run)?;
    sections::receipts(&mut h, run)?;
    sections::model(&mut h, v)?;
    sections::design_loop(&mut h, v)?;
    sections::audit(&mut h, v)?;
    gap_section::render(&mut h, &run.gap)?;
    compensation_section::render(&mut h, v)?;
    physical_section::render(&mut h, &run.physical)?;
    sections::validation(&mut h, v)?;
    sections::controller(&mut h, run)?;
    control_section::render(&mut h, v)?;
    control_compare::render(&mut h, run)?;
    sections::provenance(&mut h, run)?;
    Ok(h)
}

/// Polynomial in s, descending powers, as text ("2 s^2 + 3 s + 1").
fn poly_text(c: &[f64]) -> String {
    let n = c.len();
    let mut parts = Vec::new();
    for (i, &a) in c.iter().enumerate() {
        let p = n - 1 - i;
        let coef = fmt_num(a);
        parts.push(match p {
            0 => coef,
            1 => format!("{coef} s"),
            _ => format!("{coef} s^{p}"),
        });
    }
    parts.join(" + ").replace("+ -", "− ")
}
