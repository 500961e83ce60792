//! The pipeline report: one self-contained HTML file (inline CSS and SVG; no script, no
//! network access needed to view it) and the same figures as separate SVG files.
//!
//! Figures ([`figures`], file names `figures/<name>.svg`):
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
//! * `validation` — measured and simulated output on the validation log.
//!
//! Figures that need missing data (no controller, one run, no validation log) are left out,
//! and the corresponding report section says why. Section ids (stable, tested):
//! `verdict`, `receipts`, `frequency-response`, `coherence`, `order`, `robustness`,
//! `sensitivity`, `step`, `audit`, `validation`, `controller`, `provenance`.
mod gap_section;

use crate::error::Result;
use crate::pipeline::document::{weight_high_gain, weight_low_gain};
use crate::pipeline::{fmt_num, log_grid, PipelineRun};
use crate::robust::receipts::ReceiptKind;
use crate::plot::{self, colors, Band, Kind, LegendAt, Panel, RefLine, Series};
use num_complex::Complex64;
use std::fmt::Write as _;

/// Names of all figures the report can contain (file stems in `figures/`).
pub const FIGURE_NAMES: [&str; 9] = [
    "bode",
    "coherence",
    "singular_values",
    "robustness",
    "uncertainty",
    "sensitivity",
    "step",
    "audit",
    "validation",
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

fn db(x: f64) -> f64 {
    20.0 * x.log10()
}

fn wrap_deg(x: f64) -> f64 {
    let mut d = x % 360.0;
    if d > 180.0 {
        d -= 360.0;
    }
    if d <= -180.0 {
        d += 360.0;
    }
    d
}

/// Unwrapped phase (degrees) of `h` along increasing frequency.
fn unwrap_deg(h: &[Complex64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(h.len());
    let mut prev: Option<f64> = None;
    for z in h {
        let p = z.arg().to_degrees();
        let v = match prev {
            None => p,
            Some(q) => q + wrap_deg(p - q),
        };
        out.push(v);
        prev = Some(v);
    }
    out
}

/// Model response on a merged grid (dense log grid ∪ ETFE bins), with unwrapped phase.
struct ModelCurve {
    f: Vec<f64>,
    mag: Vec<f64>,
    phase: Vec<f64>,
}

impl ModelCurve {
    fn phase_at(&self, f: f64) -> f64 {
        match self.f.binary_search_by(|x| x.total_cmp(&f)) {
            Ok(i) => self.phase[i],
            Err(i) => self.phase[i.min(self.phase.len() - 1)],
        }
    }
}

fn model_curve(run: &PipelineRun) -> Result<ModelCurve> {
    let nom = &run.nominal_run().etfe;
    let nyq = 0.5 * nom.fs;
    let f_lo = nom.fs / nom.nperseg as f64;
    let mut f = log_grid(f_lo * 0.5, nyq * 0.999, 700);
    f.extend(nom.freq_hz.iter().copied().filter(|&x| x > 0.0 && x < nyq));
    f.sort_by(|a, b| a.total_cmp(b));
    f.dedup();
    let g = run.model().freq_responses_siso_hz(&f)?;
    let mut phase = unwrap_deg(&g);
    // Put the lowest-frequency phase in (−180°, 180°].
    if let Some(&p0) = phase.first() {
        let shift = wrap_deg(p0) - p0;
        phase.iter_mut().for_each(|p| *p += shift);
    }
    Ok(ModelCurve {
        mag: g.iter().map(|z| z.norm()).collect(),
        f,
        phase,
    })
}

fn excluded(run: &PipelineRun) -> Vec<Band> {
    let nom = &run.nominal_run().etfe;
    let df = nom.fs / nom.nperseg as f64;
    nom.excluded_bands(run.config.etfe.coherence_gate)
        .iter()
        .filter(|b| b.f_hi_hz > 0.0)
        .map(|b| Band {
            x0: (b.f_lo_hz - 0.5 * df).max(0.5 * df),
            x1: b.f_hi_hz + 0.5 * df,
            color: colors::EXCLUDED,
        })
        .collect()
}

fn fig_bode(run: &PipelineRun) -> Result<Figure> {
    let gate_thr = run.config.etfe.coherence_gate;
    let mc = model_curve(run)?;
    let nom = run.nominal_run();
    let gate = nom.etfe.gate(gate_thr);
    let x_range = Some((mc.f[0], *mc.f.last().unwrap_or(&1.0)));
    let bands = excluded(run);
    let fc = run.receipts_crossover_hz;
    let mut mag = Panel::new(
        "",
        "",
        &format!(
            "magnitude (dB, {}/{})",
            run.config.signals.output_unit, run.config.signals.input_unit
        ),
        true,
        false,
    );
    let mut ph = Panel::new("", "frequency (Hz)", "phase (deg)", true, false);
    for p in [&mut mag, &mut ph] {
        p.x_range = x_range;
        p.bands = bands.clone();
        p.band_label = Some(format!("excluded by gate (coh < {gate_thr})"));
        p.vlines.push(RefLine {
            at: fc,
            color: colors::GREY,
            label: Some(format!("crossover {} Hz", fmt_num(fc))),
        });
    }
    // Other logs as thin lines.
    let others: Vec<_> = run
        .runs
        .iter()
        .chain(run.validation.iter())
        .filter(|l| l.name != nom.name)
        .collect();
    for (k, l) in others.iter().enumerate() {
        let col = colors::CYCLE[(k + 1) % colors::CYCLE.len()];
        // Only bins passing the gate; a rejected bin breaks the line (NaN).
        let g = l.etfe.gate(gate_thr);
        let (mut pm_pts, mut pp_pts) = (Vec::new(), Vec::new());
        for (i, (&f, &gated)) in l.etfe.freq_hz.iter().zip(&g).enumerate() {
            if f <= 0.0 {
                continue;
            }
            if !gated {
                pm_pts.push((f, f64::NAN));
                pp_pts.push((f, f64::NAN));
                continue;
            }
            let h = l.etfe.h[i];
            let pm = mc.phase_at(f);
            pm_pts.push((f, db(h.norm())));
            pp_pts.push((f, pm + wrap_deg(h.arg().to_degrees() - pm)));
        }
        mag.series.push(Series::new(
            &format!("ETFE `{}` (gated bins)", l.name),
            pm_pts,
            col,
            Kind::Line(1),
        ));
        ph.series.push(Series::new("", pp_pts, col, Kind::Line(1)));
    }
    let (mut in_m, mut out_m, mut in_p, mut out_p) = (vec![], vec![], vec![], vec![]);
    for (i, &f) in nom.etfe.freq_hz.iter().enumerate() {
        if f <= 0.0 {
            continue;
        }
        let h = nom.etfe.h[i];
        let pm = mc.phase_at(f);
        let p = pm + wrap_deg(h.arg().to_degrees() - pm);
        if gate[i] {
            in_m.push((f, db(h.norm())));
            in_p.push((f, p));
        } else {
            out_m.push((f, db(h.norm())));
            out_p.push((f, p));
        }
    }
    mag.series.push(Series::new(
        &format!("ETFE `{}` (coh ≥ {gate_thr})", nom.name),
        in_m,
        colors::BLUE,
        Kind::Points(3),
    ));
    mag.series.push(Series::new(
        "ETFE, rejected bins",
        out_m,
        colors::LIGHT_GREY,
        Kind::Hollow(3),
    ));
    ph.series
        .push(Series::new("", in_p, colors::BLUE, Kind::Points(3)));
    ph.series
        .push(Series::new("", out_p, colors::LIGHT_GREY, Kind::Hollow(3)));
    mag.series.push(Series::new(
        &format!("model, order {}", run.ident.order),
        mc.f.iter()
            .zip(&mc.mag)
            .map(|(&f, &m)| (f, db(m)))
            .collect(),
        colors::RED,
        Kind::Line(2),
    ));
    ph.series.push(Series::new(
        "",
        mc.f.iter().zip(&mc.phase).map(|(&f, &p)| (f, p)).collect(),
        colors::RED,
        Kind::Line(2),
    ));
    mag.legend = LegendAt::UpperRight;
    ph.legend = LegendAt::None;
    // Magnitude range from the model and the gated bins (rejected bins may be wild).
    let ys: Vec<f64> = mag
        .series
        .iter()
        .filter(|s| s.color != colors::LIGHT_GREY)
        .flat_map(|s| s.points.iter().map(|p| p.1))
        .filter(|v| v.is_finite())
        .collect();
    if let (Some(lo), Some(hi)) = (
        ys.iter().copied().reduce(f64::min),
        ys.iter().copied().reduce(f64::max),
    ) {
        mag.y_range = Some((lo - 5.0, hi + 5.0));
    }
    let svg = plot::render("bode", FIG_WIDTH, &[(mag, 380), (ph, 330)])?;
    Ok(Figure {
        name: "bode",
        caption: format!(
            "Bode plot of the estimation run `{}`: Welch H1 estimate (filled dots pass the \
             coherence gate {gate_thr}, hollow grey dots are rejected, shaded bands are \
             excluded from fitting and validation), the other logs' estimates (thin lines) and \
             the identified model of order {} (red). ETFE phase is drawn on the model's branch.",
            nom.name, run.ident.order
        ),
        svg,
    })
}

fn fig_coherence(run: &PipelineRun) -> Result<Figure> {
    let gate = run.config.etfe.coherence_gate;
    let mut p = Panel::new("", "frequency (Hz)", "coherence γ²", true, false);
    p.y_range = Some((0.0, 1.05));
    p.bands = excluded(run);
    p.band_label = Some(format!(
        "excluded (`{}` below gate)",
        run.nominal_run().name
    ));
    p.hlines.push(RefLine {
        at: gate,
        color: colors::RED,
        label: Some(format!("gate {gate}")),
    });
    for (k, l) in run.runs.iter().chain(run.validation.iter()).enumerate() {
        let pts: Vec<(f64, f64)> = l
            .etfe
            .freq_hz
            .iter()
            .zip(&l.etfe.coherence)
            .filter(|(f, _)| **f > 0.0)
            .map(|(&f, &c)| (f, c))
            .collect();
        let col = if l.name == run.nominal_run().name {
            colors::BLUE
        } else {
            colors::CYCLE[(k + 1) % colors::CYCLE.len()]
        };
        p.series.push(Series::new(
            &format!("`{}`", l.name),
            pts,
            col,
            Kind::Line(if l.name == run.nominal_run().name {
                2
            } else {
                1
            }),
        ));
    }
    p.legend = LegendAt::LowerLeft;
    Ok(Figure {
        name: "coherence",
        caption: format!(
            "Magnitude-squared coherence of every log; bins below {gate} (dashed) are not used \
             for fitting or validation."
        ),
        svg: plot::render("coherence", FIG_WIDTH, &[(p, 360)])?,
    })
}

fn fig_order(run: &PipelineRun) -> Result<Figure> {
    let sv = &run.ident.singular_values;
    let n = run.ident.order;
    let mut p = Panel::new("", "index i", "singular value σᵢ", false, true);
    let pts: Vec<(f64, f64)> = sv
        .iter()
        .enumerate()
        .map(|(i, &s)| ((i + 1) as f64, s))
        .collect();
    p.x_range = Some((0.5, sv.len() as f64 + 0.5));
    p.series
        .push(Series::new("", pts.clone(), colors::BLUE, Kind::Line(1)));
    p.series.push(Series::new(
        "kept (model states)",
        pts.iter().take(n).copied().collect(),
        colors::BLUE,
        Kind::Points(4),
    ));
    p.series.push(Series::new(
        "discarded",
        pts.iter().skip(n).copied().collect(),
        colors::GREY,
        Kind::Hollow(4),
    ));
    p.vlines.push(RefLine {
        at: n as f64 + 0.5,
        color: colors::RED,
        label: Some(format!("chosen order n = {n}")),
    });
    Ok(Figure {
        name: "singular_values",
        caption: format!(
            "N4SID singular values (RMS-normalised data) and the chosen order n = {n}: {}",
            run.ident.order_reason
        ),
        svg: plot::render("singular_values", FIG_WIDTH, &[(p, 330)])?,
    })
}

fn fig_robustness(run: &PipelineRun) -> Result<Option<Figure>> {
    let (Some(c), Some(w)) = (&run.curves, &run.weight) else {
        return Ok(None);
    };
    let Some(inv) = &c.inv_wm_mag else {
        return Ok(None);
    };
    let mut p = Panel::new("", "frequency (Hz)", "magnitude", true, true);
    p.series.push(Series::new(
        "|T| (complementary sensitivity)",
        c.freq_hz
            .iter()
            .zip(&c.t_mag)
            .map(|(&f, &t)| (f, t))
            .collect(),
        colors::BLUE,
        Kind::Line(2),
    ));
    p.series.push(Series::new(
        &format!("1/|W_m| (order {})", w.order),
        c.freq_hz.iter().zip(inv).map(|(&f, &v)| (f, v)).collect(),
        colors::RED,
        Kind::Line(2),
    ));
    if let Some(e) = &run.envelope {
        p.series.push(Series::new(
            "1/l_m measured",
            e.measured_points()
                .iter()
                .map(|&(f, l)| (f, 1.0 / l.max(w.min_level)))
                .collect(),
            colors::ORANGE,
            Kind::Hollow(2),
        ));
    }
    p.vlines.push(RefLine {
        at: run.receipts_crossover_hz,
        color: colors::GREY,
        label: None,
    });
    let hi = p
        .series
        .iter()
        .flat_map(|s| s.points.iter().map(|q| q.1))
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold(0.0, f64::max);
    p.y_range = Some(((hi * 1e-5).max(1e-9), hi * 2.0));
    p.legend = LegendAt::LowerLeft;
    let value = receipt_value(run, ReceiptKind::RobustStability);
    Ok(Some(Figure {
        name: "robustness",
        caption: format!(
            "Robust stability against the measured multiplicative uncertainty holds when |T| stays \
             below 1/|W_m| at every frequency: ‖W_m T‖∞ = {value}."
        ),
        svg: plot::render("robustness", FIG_WIDTH, &[(p, 380)])?,
    }))
}

fn fig_uncertainty(run: &PipelineRun) -> Result<Option<Figure>> {
    let (Some(e), Some(w)) = (&run.envelope, &run.weight) else {
        return Ok(None);
    };
    let mut p = Panel::new("", "frequency (Hz)", "relative uncertainty", true, true);
    let lo = e.freq_hz.first().copied().unwrap_or(1.0) * 0.5;
    let hi = e.freq_hz.last().copied().unwrap_or(10.0) * 1.2;
    let grid = log_grid(lo, hi, 400);
    p.series.push(Series::new(
        "l_m measured",
        e.measured_points()
            .iter()
            .map(|&(f, l)| (f, l.max(w.min_level)))
            .collect(),
        colors::BLUE,
        Kind::Points(3),
    ));
    p.series.push(Series::new(
        "assumed outside the measured band",
        {
            let pts = e.assumed_points();
            let step = pts.len().div_ceil(40).max(1);
            pts.iter()
                .step_by(step)
                .map(|&(f, l)| (f, l.max(w.min_level)))
                .collect()
        },
        colors::GREY,
        Kind::Hollow(3),
    ));
    p.series.push(Series::new(
        &format!("|W_m| fitted, order {}", w.order),
        grid.iter().map(|&f| (f, w.magnitude_hz(f))).collect(),
        colors::RED,
        Kind::Line(2),
    ));
    p.legend = LegendAt::UpperLeft;
    Ok(Some(Figure {
        name: "uncertainty",
        caption: format!(
            "Envelope l_m = max_k |(G_k − G0)/G0| over the family ({}) and the fitted weight \
             |W_m| (overbound at every bin; loosest ratio {}, mean overbound {} dB).",
            e.family.join(", "),
            fmt_num(w.worst_overbound_ratio),
            fmt_num(w.mean_overbound_db)
        ),
        svg: plot::render("uncertainty", FIG_WIDTH, &[(p, 360)])?,
    }))
}

fn fig_sensitivity(run: &PipelineRun) -> Result<Option<Figure>> {
    let Some(c) = &run.curves else {
        return Ok(None);
    };
    let ms = run.config.control.ms_max;
    let mut p = Panel::new("", "frequency (Hz)", "|S| (dB)", true, false);
    p.series.push(Series::new(
        "|S| (sensitivity)",
        c.freq_hz
            .iter()
            .zip(&c.s_mag)
            .map(|(&f, &s)| (f, db(s)))
            .collect(),
        colors::BLUE,
        Kind::Line(2),
    ));
    p.hlines.push(RefLine {
        at: db(ms),
        color: colors::RED,
        label: Some(format!("M_s limit {} ({} dB)", ms, fmt_num(db(ms)))),
    });
    p.hlines.push(RefLine {
        at: -3.0103,
        color: colors::GREEN,
        label: Some("−3 dB (disturbance-rejection bandwidth)".into()),
    });
    p.vlines.push(RefLine {
        at: run.receipts_crossover_hz,
        color: colors::GREY,
        label: None,
    });
    let lo = c
        .s_mag
        .iter()
        .map(|&s| db(s))
        .filter(|v| v.is_finite())
        .fold(0.0, f64::min);
    p.y_range = Some((lo.max(-80.0) - 3.0, db(ms).max(0.0) + 4.0));
    p.legend = LegendAt::LowerRight;
    let value = receipt_value(run, ReceiptKind::SensitivityPeak);
    Ok(Some(Figure {
        name: "sensitivity",
        caption: format!(
            "Sensitivity |S| of the implemented (sampled) loop; peak M_s = {value}, limit {ms}."
        ),
        svg: plot::render("sensitivity", FIG_WIDTH, &[(p, 340)])?,
    }))
}

fn thin(t: &[f64], y: &[f64], max: usize) -> Vec<(f64, f64)> {
    let step = t.len().div_ceil(max.max(1)).max(1);
    t.iter()
        .zip(y)
        .step_by(step)
        .map(|(&a, &b)| (a, b))
        .collect()
}

fn fig_step(run: &PipelineRun) -> Result<Option<Figure>> {
    let Some(s) = run.loop_report.as_ref().and_then(|r| r.step.as_ref()) else {
        return Ok(None);
    };
    // Show the transient, not the whole simulated span: three settling times, at least six
    // crossover periods.
    let t_end = s.t.last().copied().unwrap_or(1.0);
    let t_show = match s.settling_time_s {
        Some(ts) => (3.0 * ts).max(6.0 / run.receipts_crossover_hz).min(t_end),
        None => t_end,
    };
    let k_show =
        s.t.iter()
            .take_while(|&&t| t <= t_show)
            .count()
            .max(2)
            .min(s.t.len());
    let (tt, yy, uu, ud) = (
        &s.t[..k_show],
        &s.y[..k_show],
        &s.u[..k_show],
        &s.u_demand[..k_show],
    );
    let sig = &run.config.signals;
    let mut py = Panel::new(
        "",
        "",
        &format!("output ({})", sig.output_unit),
        false,
        false,
    );
    py.series.push(Series::new(
        "y (plant output)",
        thin(tt, yy, 3000),
        colors::BLUE,
        Kind::Line(2),
    ));
    py.hlines.push(RefLine {
        at: s.amplitude,
        color: colors::GREY,
        label: Some(format!("reference {}", fmt_num(s.amplitude))),
    });
    let ymax = yy.iter().copied().fold(s.amplitude, f64::max);
    let ymin = yy.iter().copied().fold(0.0, f64::min);
    py.y_range = Some((ymin - 0.05 * (ymax - ymin), ymax + 0.1 * (ymax - ymin)));
    py.legend = LegendAt::LowerRight;
    let mut pu = Panel::new(
        "",
        "time (s)",
        &format!("actuator ({})", sig.input_unit),
        false,
        false,
    );
    pu.series.push(Series::new(
        "u applied (after the clamp)",
        thin(tt, uu, 3000),
        colors::ORANGE,
        Kind::Line(2),
    ));
    pu.series.push(Series::new(
        "u demanded by the controller",
        thin(tt, ud, 3000),
        colors::PURPLE,
        Kind::Dashed(1),
    ));
    let lim = s.actuator_limit;
    for (at, label) in [
        (lim, Some(format!("rails ±{}", fmt_num(lim)))),
        (-lim, None),
    ] {
        pu.hlines.push(RefLine {
            at,
            color: colors::RED,
            label,
        });
    }
    let umax = s
        .u_demand
        .iter()
        .chain(&s.u)
        .map(|v| v.abs())
        .fold(lim, f64::max)
        .min(lim * 3.0);
    pu.y_range = Some((-1.1 * umax, 1.1 * umax));
    pu.legend = LegendAt::UpperRight;
    for p in [&mut py, &mut pu] {
        p.x_range = Some((0.0, t_show));
    }
    Ok(Some(Figure {
        name: "step",
        caption: format!(
            "Closed-loop step of {} {} through a hard actuator saturation at ±{} {}; {} (peak \
             demand {} of the rail), overshoot {} %, settling {}.",
            fmt_num(s.amplitude),
            sig.output_unit,
            fmt_num(lim),
            sig.input_unit,
            if s.hits_rail {
                "the command hits the rail"
            } else {
                "the command stays inside the rails"
            },
            fmt_num(s.peak_demand_ratio),
            fmt_num(s.overshoot_pct),
            s.settling_time_s
                .map_or("not reached".to_string(), |t| format!("{} s", fmt_num(t)))
        ),
        svg: plot::render("step", FIG_WIDTH, &[(py, 300), (pu, 300)])?,
    }))
}

fn fig_audit(run: &PipelineRun) -> Result<Option<Figure>> {
    let Some(a) = &run.audit else {
        return Ok(None);
    };
    let o = &a.options;
    let bands: Vec<Band> = a
        .shift_bands
        .iter()
        .map(|b| Band {
            x0: b.f_lo_hz,
            x1: b.f_hi_hz.max(b.f_lo_hz * 1.0001),
            color: colors::EXCLUDED,
        })
        .collect();
    let mut pg = Panel::new("", "", "gain shift (dB)", true, false);
    let mut pp = Panel::new("", "frequency (Hz)", "phase shift (deg)", true, false);
    pg.series.push(Series::new(
        "worst shift between amplitudes",
        a.bins.iter().map(|b| (b.f_hz, b.gain_shift_db)).collect(),
        colors::BLUE,
        Kind::Line(2),
    ));
    pp.series.push(Series::new(
        "",
        a.bins.iter().map(|b| (b.f_hz, b.phase_shift_deg)).collect(),
        colors::BLUE,
        Kind::Line(2),
    ));
    for (p, thr) in [
        (&mut pg, o.max_gain_shift_db),
        (&mut pp, o.max_phase_shift_deg),
    ] {
        p.hlines.push(RefLine {
            at: thr,
            color: colors::RED,
            label: Some(format!("threshold ±{}", fmt_num(thr))),
        });
        p.hlines.push(RefLine {
            at: -thr,
            color: colors::RED,
            label: None,
        });
        let m = p.series[0]
            .points
            .iter()
            .map(|q| q.1.abs())
            .filter(|v| v.is_finite())
            .fold(thr, f64::max);
        p.y_range = Some((-1.2 * m, 1.2 * m));
        // The audit band, cut to the bins that exist (a huge band factor means "all bins").
        let (blo, bhi) = a.bins.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), b| {
            (lo.min(b.f_hz), hi.max(b.f_hz))
        });
        p.x_range = Some(if blo.is_finite() && bhi > blo {
            (a.band_hz.0.max(blo / 1.2), a.band_hz.1.min(bhi * 1.2))
        } else {
            a.band_hz
        });
        p.bands = bands.clone();
        p.band_label = Some("flagged".into());
        p.vlines.push(RefLine {
            at: o.crossover_hz,
            color: colors::GREY,
            label: None,
        });
    }
    pp.legend = LegendAt::None;
    Ok(Some(Figure {
        name: "audit",
        caption: format!(
            "Nonlinearity audit: the largest gain and phase shift between the runs ({}) at each \
             bin of the audit band {}–{} Hz; verdict: {}.",
            a.runs
                .iter()
                .map(|(l, amp)| format!("`{l}` at {}", fmt_num(*amp)))
                .collect::<Vec<_>>()
                .join(", "),
            fmt_num(a.band_hz.0),
            fmt_num(a.band_hz.1),
            verdict_text(a.verdict)
        ),
        svg: plot::render("audit", FIG_WIDTH, &[(pg, 300), (pp, 300)])?,
    }))
}

fn verdict_text(v: crate::robust::audit::Verdict) -> &'static str {
    match v {
        crate::robust::audit::Verdict::LinearEnough => "linear enough",
        crate::robust::audit::Verdict::NotLinear => "not linear",
    }
}

fn fig_validation(run: &PipelineRun) -> Result<Option<Figure>> {
    let (Some(v), Some(fit)) = (&run.validation, &run.validation_fit) else {
        return Ok(None);
    };
    let ts = v.log.ts;
    let n = v.log.len();
    // A readable window of about 300 samples from the middle of the log (the fit is over all).
    let w = n.min(300);
    let k0 = (n - w) / 2;
    let t: Vec<f64> = (k0..k0 + w).map(|k| k as f64 * ts).collect();
    let mut p = Panel::new(
        "",
        "time (s)",
        &format!("output ({})", run.config.signals.output_unit),
        false,
        false,
    );
    p.series.push(Series::new(
        "measured",
        t.iter()
            .copied()
            .zip(v.log.y()[k0..k0 + w].iter().copied())
            .collect(),
        colors::GREY,
        Kind::Line(3),
    ));
    p.series.push(Series::new(
        &format!("model (free run), fit {} %", fmt_num(fit.fit_percent[0])),
        t.iter()
            .copied()
            .zip(fit.y_sim[0][k0..k0 + w].iter().copied())
            .collect(),
        colors::RED,
        Kind::Line(1),
    ));
    p.legend = LegendAt::UpperRight;
    let m = v.log.y()[k0..k0 + w]
        .iter()
        .map(|x| x.abs())
        .fold(0.0, f64::max);
    p.y_range = Some((-1.15 * m, 1.6 * m));
    p.x_range = Some((t[0], *t.last().unwrap_or(&1.0)));
    Ok(Some(Figure {
        name: "validation",
        caption: format!(
            "Free-run simulation of the model on the validation log `{}` (after preprocessing), \
             initial state estimated, shown for {} of its {} samples: fit {} % over the whole log \
             (NRMSE {}).",
            v.name,
            w,
            n,
            fmt_num(fit.fit_percent[0]),
            fmt_num(fit.nrmse[0])
        ),
        svg: plot::render("validation", FIG_WIDTH, &[(p, 320)])?,
    }))
}

/// Renders every figure the run supports, in report order.
pub fn figures(run: &PipelineRun) -> Result<Vec<Figure>> {
    let mut out = vec![fig_bode(run)?, fig_coherence(run)?, fig_order(run)?];
    for f in [
        fig_robustness(run)?,
        fig_uncertainty(run)?,
        fig_sensitivity(run)?,
        fig_step(run)?,
        fig_audit(run)?,
        fig_validation(run)?,
    ]
    .into_iter()
    .flatten()
    {
        out.push(f);
    }
    Ok(out)
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
