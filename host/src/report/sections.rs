//! The report's sections other than the gap, compensation and physical ones (which have
//! their own files), in page order; [`super::render_html`] calls them.
use super::*;

/// The document head, the verdict banner and the navigation.
pub(super) fn banner(h: &mut String, run: &PipelineRun) {
    let rs = &run.receipts;
    let failed: Vec<&str> = rs.failed().map(|r| r.name.as_str()).collect();
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
    if let Some(t) = run.tuned() {
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
         href=\"#compensation\">Compensation</a><a href=\"#physical\">Physical</a><a \
         href=\"#validation\">Validation</a>\
         <a href=\"#controller\">Controller</a><a href=\"#provenance\">Provenance</a></nav>\n<main>\n",
    );
}

/// The receipts table.
pub(super) fn receipts(h: &mut String, run: &PipelineRun) {
    let rs = &run.receipts;
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
}

/// Frequency response with the coherence gate, coherence, model order and modes.
pub(super) fn model(h: &mut String, run: &PipelineRun, figs: &[Figure]) {
    let sig = &run.config.signals;
    // Frequency response.
    h.push_str(
        "<section id=\"frequency-response\">\n<h2>Frequency response: data and model</h2>\n",
    );
    figure_html(h, figs, "bode");
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
    figure_html(h, figs, "coherence");
    h.push_str("</section>\n");

    // Order.
    h.push_str("<section id=\"order\">\n<h2>Model order and modes</h2>\n");
    figure_html(h, figs, "singular_values");
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
}

/// Robust stability (|T| against 1/|W_m|, the weight), sensitivity and the saturated step.
pub(super) fn design_loop(h: &mut String, run: &PipelineRun, figs: &[Figure]) {
    // Robustness.
    h.push_str("<section id=\"robustness\">\n<h2>Robust stability: |T| against 1/|W_m|</h2>\n");
    let has_rob = figure_html(h, figs, "robustness");
    figure_html(h, figs, "uncertainty");
    match &run.uncertainty {
        Ok(u) => {
            let (w, e) = (&u.weight, &u.envelope);
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
        Err(why) => {
            let _ = writeln!(
                h,
                "<p class=\"note\">No uncertainty weight: {}</p>",
                esc(&why.to_string())
            );
        }
    }
    if !has_rob && run.weight().is_some() {
        h.push_str("<p class=\"note\">No loop to check: no controller was tuned.</p>\n");
    }
    h.push_str("</section>\n");

    h.push_str("<section id=\"sensitivity\">\n<h2>Sensitivity |S|</h2>\n");
    if !figure_html(h, figs, "sensitivity") {
        h.push_str("<p class=\"note\">No loop: no controller was tuned.</p>\n");
    }
    h.push_str("</section>\n");

    h.push_str("<section id=\"step\">\n<h2>Saturated step response</h2>\n");
    if !figure_html(h, figs, "step") {
        h.push_str("<p class=\"note\">No step response: no controller was tuned, or the simulation failed (see the step receipts).</p>\n");
    }
    h.push_str("</section>\n");
}

/// The dual-amplitude nonlinearity audit.
pub(super) fn audit(h: &mut String, run: &PipelineRun, figs: &[Figure]) {
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
            figure_html(h, figs, "audit");
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
            kv_table(h, &rows);
        }
        None => h.push_str(
            "<p class=\"note\">Not run: give two or more <code>[[runs]]</code> at different \
             excitation amplitudes.</p>\n",
        ),
    }
    h.push_str("</section>\n");
}

/// Validation on fresh data.
pub(super) fn validation(h: &mut String, run: &PipelineRun, figs: &[Figure]) {
    // Validation.
    h.push_str("<section id=\"validation\">\n<h2>Validation on fresh data</h2>\n");
    if figure_html(h, figs, "validation") {
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
}

/// The controller.
pub(super) fn controller(h: &mut String, run: &PipelineRun) {
    // Controller.
    h.push_str("<section id=\"controller\">\n<h2>Controller</h2>\n");
    match &run.tuning {
        Ok(t) => {
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
            kv_table(h, &rows);
        }
        Err(e) => {
            let _ = writeln!(h, "<p><b>No controller.</b> {}</p>", esc(&e.0));
        }
    }
    h.push_str("</section>\n");
}

/// Provenance (inputs, preprocessing, settings) and the document end.
pub(super) fn provenance(h: &mut String, run: &PipelineRun) {
    let sig = &run.config.signals;
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
}
