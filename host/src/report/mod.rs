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
mod physical_section;
mod gap_section;

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
    let rs = &run.receipts;
    let failed: Vec<&str> = rs.failed().map(|r| r.name.as_str()).collect();
    let sig = &run.config.signals;
    let mut h = String::with_capacity(512 * 1024);
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>{} — ferrosid report</title>\n<style>{CSS}</style>\n</head>\n<body>\n",
        esc(&run.title)
    );
    // Verdict banner.
    let verdict = if rs.all_pass {
        format!("PASS — all {} receipts hold", rs.receipts.len())
    } else {
        format!(
            "FAIL — {} of {} receipts fail: {}",
            failed.len(),
            rs.receipts.len(),
            failed.join(", ")
        )
    };
    let mut facts = vec![format!(
        "model order {} at {} Hz",
        run.ident.order,
        fmt_num(1.0 / run.model().ts)
    )];
    if let Some(t) = &run.tuned {
        facts.push(format!(
            "PID crossover {} Hz (target {} Hz)",
            fmt_num(t.design.crossover_hz),
            fmt_num(t.target_crossover_hz)
        ));
    } else {
        facts.push("no controller: tuning infeasible".into());
    }
    if rs.of_kind(ReceiptKind::SensitivityPeak).is_some() {
        facts.push(format!(
            "M_s {}",
            receipt_value(run, ReceiptKind::SensitivityPeak)
        ));
    }
    if rs.of_kind(ReceiptKind::RobustStability).is_some() {
        facts.push(format!(
            "‖W_m T‖∞ {}",
            receipt_value(run, ReceiptKind::RobustStability)
        ));
    }
    if let Some(f) = &run.validation_fit {
        facts.push(format!("validation fit {} %", fmt_num(f.fit_percent[0])));
    }
    let _ = write!(
        h,
        "<header id=\"verdict\" class=\"banner {}\">\n<h1>{}</h1>\n<div class=\"verdict\">{}</div>\n\
         <div class=\"facts\">{}</div>\n</header>\n",
        if rs.all_pass { "pass" } else { "fail" },
        esc(&run.title),
        esc(&verdict),
        esc(&facts.join(" · "))
    );
    h.push_str(
        "<nav><a href=\"#receipts\">Receipts</a><a href=\"#frequency-response\">Frequency \
         response</a><a href=\"#coherence\">Coherence</a><a href=\"#order\">Order</a><a \
         href=\"#robustness\">Robustness</a><a href=\"#sensitivity\">Sensitivity</a><a \
         href=\"#step\">Step</a><a href=\"#audit\">Audit</a><a href=\"#gap\">Gap</a><a \
         href=\"#validation\">Validation</a>\
         <a href=\"#controller\">Controller</a><a href=\"#provenance\">Provenance</a></nav>\n<main>\n",
    );

    // Receipts table.
    h.push_str(
        "<section id=\"receipts\">\n<h2>Receipts</h2>\n<table>\n<tr><th>receipt</th><th>value</th>\
         <th>limit</th><th>result</th><th>how / where</th></tr>\n",
    );
    for r in &rs.receipts {
        let _ = writeln!(
            h,
            "<tr class=\"{}\"><td><b>{}</b><br><span class=\"note\">{}</span></td><td \
             class=\"num\">{}</td><td class=\"num\">{} {}</td><td><span class=\"badge \
             {}\">{}</span></td><td class=\"detail\">{}</td></tr>",
            if r.pass { "pass" } else { "fail" },
            esc(&r.name),
            esc(&r.description),
            esc(&with_unit(r.value, &r.unit)),
            esc(r.comparison.symbol()),
            esc(&with_unit(r.limit, &r.unit)),
            if r.pass { "pass" } else { "fail" },
            if r.pass { "PASS" } else { "FAIL" },
            esc(&r.detail)
        );
    }
    h.push_str("</table>\n</section>\n");

    // Frequency response.
    h.push_str(
        "<section id=\"frequency-response\">\n<h2>Frequency response: data and model</h2>\n",
    );
    figure_html(&mut h, figs, "bode");
    let nom = run.nominal_run();
    let bands = nom.etfe.excluded_bands(run.config.etfe.coherence_gate);
    let _ = writeln!(
        h,
        "<p class=\"note\">Welch H1: {} Hz sampling, segments of {} samples (resolution {} Hz), \
         {} averages on `{}`. Bands excluded by the coherence gate {}: {}.</p>",
        fmt_num(nom.etfe.fs),
        nom.etfe.nperseg,
        fmt_num(nom.etfe.fs / nom.etfe.nperseg as f64),
        nom.etfe.n_averages,
        esc(&nom.name),
        run.config.etfe.coherence_gate,
        if bands.is_empty() {
            "none".to_string()
        } else {
            esc(&bands
                .iter()
                .map(|b| {
                    format!(
                        "{}–{} Hz (min γ² {})",
                        fmt_num(b.f_lo_hz),
                        fmt_num(b.f_hi_hz),
                        fmt_num(b.min_coherence)
                    )
                })
                .collect::<Vec<_>>()
                .join("; "))
        }
    );
    h.push_str("</section>\n");

    h.push_str("<section id=\"coherence\">\n<h2>Coherence</h2>\n");
    figure_html(&mut h, figs, "coherence");
    h.push_str("</section>\n");

    // Order.
    h.push_str("<section id=\"order\">\n<h2>Model order and modes</h2>\n");
    figure_html(&mut h, figs, "singular_values");
    h.push_str("<table>\n<tr><th>mode</th><th>natural frequency (Hz)</th><th>damping ζ</th><th>discrete pole z</th></tr>\n");
    for (i, m) in run.modes.iter().enumerate() {
        let _ = writeln!(
            h,
            "<tr><td>{}{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{} {} {}j</td></tr>",
            i + 1,
            if m.oscillatory { " (pair)" } else { " (real)" },
            fmt_num(m.natural_hz),
            fmt_num(m.damping),
            fmt_num(m.z[0]),
            if m.z[1] < 0.0 { "−" } else { "±" },
            fmt_num(m.z[1].abs())
        );
    }
    h.push_str("</table>\n");
    let _ = writeln!(
        h,
        "<p class=\"note\">Static gain {} {}/{}. Identification warnings: {}</p>",
        fmt_num(run.dc_gain),
        esc(&sig.output_unit),
        esc(&sig.input_unit),
        if run.ident.warnings.is_empty() {
            "none".to_string()
        } else {
            esc(&run.ident.warnings.join("; "))
        }
    );
    h.push_str("</section>\n");

    // Robustness.
    h.push_str("<section id=\"robustness\">\n<h2>Robust stability: |T| against 1/|W_m|</h2>\n");
    let has_rob = figure_html(&mut h, figs, "robustness");
    figure_html(&mut h, figs, "uncertainty");
    match (&run.weight, &run.envelope) {
        (Some(w), Some(e)) => {
            let _ = writeln!(
                h,
                "<p class=\"note\">W_m(s) = ({}) / ({}), s in rad/s; |W_m(0)| = {}, |W_m(∞)| = \
                 {}. Fitted on {} measured bins from {} to {} Hz; the decade below is assumed at l_m = {} \
                 ({} points){}. Objective: {}</p>",
                esc(&poly_text(&w.num)),
                esc(&poly_text(&w.den)),
                fmt_num(weight_low_gain(&w.num, &w.den)),
                fmt_num(weight_high_gain(&w.num, &w.den)),
                e.measured,
                fmt_num(e.freq_hz.get(e.below).copied().unwrap_or(f64::NAN)),
                fmt_num(e.f_top_hz),
                fmt_num(e.level.first().copied().unwrap_or(f64::NAN)),
                e.below,
                if e.beyond() > 0 {
                    format!(
                        "; {} points above it, up to 100 × Nyquist, set to {} (no trustworthy data \
                         there)",
                        e.beyond(),
                        fmt_num(run.config.uncertainty.beyond_band_level)
                    )
                } else {
                    String::new()
                },
                esc(&w.objective)
            );
        }
        _ => {
            let _ = writeln!(
                h,
                "<p class=\"note\">No uncertainty weight: {}</p>",
                esc(run.weight_note.as_deref().unwrap_or("not available"))
            );
        }
    }
    if !has_rob && run.weight.is_some() {
        h.push_str("<p class=\"note\">No loop to check: no controller was tuned.</p>\n");
    }
    h.push_str("</section>\n");

    h.push_str("<section id=\"sensitivity\">\n<h2>Sensitivity |S|</h2>\n");
    if !figure_html(&mut h, figs, "sensitivity") {
        h.push_str("<p class=\"note\">No loop: no controller was tuned.</p>\n");
    }
    h.push_str("</section>\n");

    h.push_str("<section id=\"step\">\n<h2>Saturated step response</h2>\n");
    if !figure_html(&mut h, figs, "step") {
        h.push_str("<p class=\"note\">No step response: no controller was tuned, or the simulation failed (see the step receipts).</p>\n");
    }
    h.push_str("</section>\n");

    // Audit.
    h.push_str("<section id=\"audit\">\n<h2>Nonlinearity audit</h2>\n");
    match &run.audit {
        Some(a) => {
            let _ = writeln!(
                h,
                "<p><b>Verdict: {}</b>{}</p>",
                verdict_text(a.verdict),
                if a.reasons.is_empty() {
                    String::new()
                } else {
                    format!(" — {}", esc(&a.reasons.join("; ")))
                }
            );
            figure_html(&mut h, figs, "audit");
            let rows = vec![
                (
                    "runs (amplitude)",
                    a.runs
                        .iter()
                        .map(|(l, amp)| format!("{l} ({})", fmt_num(*amp)))
                        .collect::<Vec<_>>()
                        .join(", "),
                ),
                (
                    "audit band",
                    format!(
                        "{}–{} Hz, {} bins",
                        fmt_num(a.band_hz.0),
                        fmt_num(a.band_hz.1),
                        a.bins_examined
                    ),
                ),
                (
                    "worst gain shift",
                    format!(
                        "{} dB at {} Hz ({} vs {})",
                        fmt_num(a.worst_gain_shift_db.value),
                        fmt_num(a.worst_gain_shift_db.f_hz),
                        a.worst_gain_shift_db.run_b,
                        a.worst_gain_shift_db.run_a
                    ),
                ),
                (
                    "worst phase shift",
                    format!(
                        "{} deg at {} Hz ({} vs {})",
                        fmt_num(a.worst_phase_shift_deg.value),
                        fmt_num(a.worst_phase_shift_deg.f_hz),
                        a.worst_phase_shift_deg.run_b,
                        a.worst_phase_shift_deg.run_a
                    ),
                ),
                (
                    "flagged bands",
                    if a.shift_bands.is_empty() {
                        "none".into()
                    } else {
                        a.shift_bands
                            .iter()
                            .map(|b| {
                                format!(
                                    "{}–{} Hz: {} dB, {} deg (min γ² {})",
                                    fmt_num(b.f_lo_hz),
                                    fmt_num(b.f_hi_hz),
                                    fmt_num(b.worst_gain_shift_db.value),
                                    fmt_num(b.worst_phase_shift_deg.value),
                                    fmt_num(b.min_coherence)
                                )
                            })
                            .collect::<Vec<_>>()
                            .join("; ")
                    },
                ),
                (
                    "coherence drops near crossover",
                    if a.coherence_drops.is_empty() {
                        "none".into()
                    } else {
                        a.coherence_drops
                            .iter()
                            .map(|d| {
                                format!(
                                    "{}–{} Hz: γ² {} in `{}`",
                                    fmt_num(d.f_lo_hz),
                                    fmt_num(d.f_hi_hz),
                                    fmt_num(d.min_coherence),
                                    d.run
                                )
                            })
                            .collect::<Vec<_>>()
                            .join("; ")
                    },
                ),
            ];
            kv_table(&mut h, &rows);
        }
        None => h.push_str(
            "<p class=\"note\">Not run: give two or more <code>[[runs]]</code> at different \
             excitation amplitudes.</p>\n",
        ),
    }
    h.push_str("</section>\n");

    gap_section::render(&mut h, &run.gap);
    compensation_section::render(&mut h, run, figs);
    physical_section::render(&mut h, &run.physical);

    // Validation.
    h.push_str("<section id=\"validation\">\n<h2>Validation on fresh data</h2>\n");
    if figure_html(&mut h, figs, "validation") {
        if let Some(r) = &run.residuals {
            let _ = writeln!(
                h,
                "<p class=\"note\">Residual tests ({}, lags up to {}, 99 % bound ±{}): \
                 whiteness {} ({} % of lags outside), independence from the input {} ({} % \
                 outside).</p>",
                match r.kind {
                    crate::validate::ResidualKind::OneStepPrediction => {
                        "one-step-prediction residual of the Kalman predictor"
                    }
                    crate::validate::ResidualKind::OutputError => "output-error residual",
                },
                r.max_lag,
                fmt_num(r.bound),
                if r.whiteness_ok { "passes" } else { "fails" },
                fmt_num(100.0 * r.frac_auto_outside),
                if r.independence_ok { "passes" } else { "fails" },
                fmt_num(100.0 * r.frac_cross_outside)
            );
        }
    } else {
        h.push_str("<p class=\"note\">No <code>[validation]</code> log: the model was not checked on fresh data.</p>\n");
    }
    h.push_str("</section>\n");

    // Controller.
    h.push_str("<section id=\"controller\">\n<h2>Controller</h2>\n");
    match (&run.tuned, &run.tuning_error) {
        (Some(t), _) => {
            let p = &t.pid;
            let mut rows = vec![
                ("K(s)", "(Kp + Ki/s + Kd·s/(τ_f·s + 1))·R(s)".to_string()),
                ("Kp", fmt_num(p.kp)),
                ("Ki (1/s)", fmt_num(p.ki)),
                ("Kd (s)", fmt_num(p.kd)),
                ("τ_f (s)", fmt_num(p.tau_f)),
                (
                    "roll-off R(s)",
                    p.rolloff.map_or("none".into(), |r| {
                        format!("corner {} Hz, ζ {}", fmt_num(r.corner_hz), fmt_num(r.zeta))
                    }),
                ),
                (
                    "design",
                    format!(
                        "crossover {} Hz (target {} Hz), phase-margin target {} deg",
                        fmt_num(t.design.crossover_hz),
                        fmt_num(t.target_crossover_hz),
                        fmt_num(t.design.phase_margin_target_deg)
                    ),
                ),
            ];
            if let Some(d) = &t.discrete {
                rows.push((
                    "firmware law",
                    format!(
                        "ts {} s, Tustin prewarped at {} Hz: kp {}, ki_d {}, a_d {}, b_d {}",
                        fmt_num(d.ts),
                        d.prewarp_hz.map_or("-".into(), fmt_num),
                        fmt_num(d.kp),
                        fmt_num(d.ki_d),
                        fmt_num(d.a_d),
                        fmt_num(d.b_d)
                    ),
                ));
            }
            rows.push(("method", t.method.clone()));
            kv_table(&mut h, &rows);
        }
        (None, Some(e)) => {
            let _ = writeln!(h, "<p><b>No controller.</b> {}</p>", esc(e));
        }
        _ => {}
    }
    h.push_str("</section>\n");

    // Provenance.
    h.push_str("<section id=\"provenance\">\n<h2>Provenance</h2>\n<table>\n<tr><th>role</th><th>name</th><th>file</th><th>samples</th><th>fs (Hz)</th><th>SHA-256</th></tr>\n");
    for f in std::iter::once(&run.pipeline_file).chain(run.inputs.iter()) {
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td>{}</td><td><code>{}</code>{}</td><td class=\"num\">{}</td><td \
             class=\"num\">{}</td><td class=\"hash\">{}</td></tr>",
            esc(&f.role),
            esc(&f.name),
            esc(&f.path),
            if f.warnings.is_empty() {
                String::new()
            } else {
                format!(
                    "<br><span class=\"note\">warning: {}</span>",
                    esc(&f.warnings.join("; "))
                )
            },
            if f.samples > 0 {
                f.samples.to_string()
            } else {
                "-".into()
            },
            if f.fs_hz > 0.0 {
                fmt_num(f.fs_hz)
            } else {
                "-".into()
            },
            esc(&f.sha256)
        );
    }
    h.push_str("</table>\n<h3>Preprocessing</h3>\n<ul>\n");
    for l in run.runs.iter().chain(run.validation.iter()) {
        let steps: Vec<String> = l
            .preprocessing
            .steps
            .iter()
            .map(|s| match s {
                crate::preprocess::StepRecord::RemoveMean { .. } => "mean removed".to_string(),
                crate::preprocess::StepRecord::RemoveTrend { .. } => "trend removed".to_string(),
                crate::preprocess::StepRecord::Decimate { factor, .. } => {
                    format!("decimated by {factor}")
                }
            })
            .collect();
        let _ = writeln!(
            h,
            "<li><code>{}</code>: {} samples → {}; {}; excitation amplitude {} {}{}</li>",
            esc(&l.name),
            l.preprocessing.samples_in,
            l.preprocessing.samples_out,
            if steps.is_empty() {
                "no preprocessing".to_string()
            } else {
                steps.join(", ")
            },
            fmt_num(l.amplitude),
            esc(&sig.input_unit),
            if l.amplitude_is_rms {
                " (input RMS)"
            } else {
                ""
            }
        );
    }
    h.push_str("</ul>\n<h3>Settings (all defaults filled in)</h3>\n<pre>");
    let settings = toml::to_string(&run.config).unwrap_or_else(|e| format!("<{e}>"));
    h.push_str(&esc(&settings));
    let _ = write!(
        h,
        "</pre>\n<p class=\"note\">Written by ferrosid {}. The same logs and settings give a \
         byte-identical report and receipts.json.</p>\n</section>\n</main>\n</body>\n</html>\n",
        env!("CARGO_PKG_VERSION")
    );
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
