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
mod charts;
mod compensation_section;
mod control_compare;
mod control_section;
mod gap_section;
mod physical_section;
mod sections;

pub use charts::figures;
use charts::*;

use crate::error::Result;
use crate::pipeline::document::{weight_high_gain, weight_low_gain};
use crate::pipeline::{fmt_num, PipelineRun};
use crate::robust::receipts::ReceiptKind;
use std::fmt::Write as _;

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

/// HTML-escapes text.
pub fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for ch in s.chars() {
        match ch {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            // Control characters are not allowed in XML/HTML text: shown as U+FFFD.
            c if c.is_control() && !matches!(c, '\n' | '\t') => o.push('\u{FFFD}'),
            c => o.push(c),
        }
    }
    o
}

const CSS: &str = r#"
:root { --pass: #1b7f3b; --fail: #b3261e; --ink: #1d1d1f; --muted: #5f6368; --line: #dadce0; }
* { box-sizing: border-box; }
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, "DejaVu Sans", sans-serif;
       color: var(--ink); margin: 0; background: #f6f7f9; line-height: 1.45; }
main { max-width: 1080px; margin: 0 auto; padding: 0 20px 40px; }
header.banner { color: #fff; padding: 22px 28px; }
header.banner.pass { background: var(--pass); }
header.banner.fail { background: var(--fail); }
header.banner h1 { margin: 0 0 4px; font-size: 22px; font-weight: 600; }
header.banner .verdict { font-size: 30px; font-weight: 700; margin: 4px 0; letter-spacing: .5px; }
header.banner .facts { margin: 6px 0 0; font-size: 15px; opacity: .95; }
nav { max-width: 1080px; margin: 0 auto; padding: 10px 20px; font-size: 14px; }
nav a { color: #1a73e8; margin-right: 14px; text-decoration: none; }
section { background: #fff; border: 1px solid var(--line); border-radius: 8px; padding: 16px 22px;
          margin: 16px 0; }
h2 { font-size: 19px; margin: 0 0 10px; }
h3 { font-size: 16px; margin: 14px 0 6px; }
table { border-collapse: collapse; width: 100%; font-size: 14px; }
th, td { text-align: left; padding: 5px 8px; border-bottom: 1px solid var(--line); vertical-align: top; }
th { background: #f1f3f4; font-weight: 600; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
td.detail { color: var(--muted); font-size: 12.5px; }
.badge { display: inline-block; padding: 1px 9px; border-radius: 10px; color: #fff; font-weight: 600;
         font-size: 12.5px; }
.badge.pass { background: var(--pass); }
.badge.fail { background: var(--fail); }
tr.fail td { background: #fdecea; }
figure { margin: 10px 0 18px; }
figure svg { width: 100%; height: auto; display: block; }
figcaption { color: var(--muted); font-size: 13.5px; margin-top: 4px; }
.note { color: var(--muted); font-size: 14px; }
code, pre { font-family: ui-monospace, "DejaVu Sans Mono", Menlo, Consolas, monospace; font-size: 12.5px; }
pre { background: #f6f8fa; border: 1px solid var(--line); padding: 10px; overflow-x: auto; }
td.hash { font-family: ui-monospace, "DejaVu Sans Mono", monospace; font-size: 11.5px; word-break: break-all; }
"#;

fn figure_html(out: &mut String, figs: &[Figure], name: &str) -> bool {
    match figs.iter().find(|f| f.name == name) {
        Some(f) => {
            let _ = write!(
                out,
                "<figure id=\"fig-{}\">\n{}<figcaption>{}</figcaption>\n</figure>\n",
                f.name,
                f.svg,
                esc(&f.caption)
            );
            true
        }
        None => false,
    }
}

fn kv_table(out: &mut String, rows: &[(&str, String)]) {
    out.push_str("<table>\n");
    for (k, v) in rows {
        let _ = writeln!(out, "<tr><th>{}</th><td>{}</td></tr>", esc(k), esc(v));
    }
    out.push_str("</table>\n");
}

/// The self-contained HTML report. `figs` are the figures of [`figures`] (inlined).
pub fn render_html(run: &PipelineRun, figs: &[Figure]) -> Result<String> {
    let mut h = String::with_capacity(512 * 1024);
    sections::banner(&mut h, run);
    sections::receipts(&mut h, run);
    sections::model(&mut h, run, figs);
    sections::design_loop(&mut h, run, figs);
    sections::audit(&mut h, run, figs);
    gap_section::render(&mut h, &run.gap);
    compensation_section::render(&mut h, run, figs);
    physical_section::render(&mut h, &run.physical);
    sections::validation(&mut h, run, figs);
    sections::controller(&mut h, run);
    control_section::render(&mut h, run, figs);
    control_compare::render(&mut h, run);
    sections::provenance(&mut h, run);
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
