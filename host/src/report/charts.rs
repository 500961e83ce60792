//! The report's figures ([`figures`]): one function per figure, each `None` when the run
//! lacks its data.
use super::captions::Caption;
use super::{receipt_value, Figure, FIG_WIDTH};
use crate::error::Result;
use crate::pipeline::{fmt_num, log_grid, PipelineRun};
use crate::plot::{self, colors, Band, Kind, LegendAt, Panel, RefLine, Series};
use crate::robust::receipts::ReceiptKind;
use num_complex::Complex64;

pub(super) fn db(x: f64) -> f64 {
    20.0 * x.log10()
}

pub(super) fn wrap_deg(x: f64) -> f64 {
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
pub(super) fn unwrap_deg(h: &[Complex64]) -> Vec<f64> {
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
pub(super) struct ModelCurve {
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

pub(super) fn model_curve(run: &PipelineRun) -> Result<ModelCurve> {
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

pub(super) fn excluded(run: &PipelineRun) -> Vec<Band> {
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

pub(super) fn fig_bode(run: &PipelineRun) -> Result<Figure> {
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
        caption: Caption::Bode {
            run: &nom.name,
            gate: gate_thr,
            order: run.ident.order,
        }
        .text()?,
        svg,
    })
}

pub(super) fn fig_coherence(run: &PipelineRun) -> Result<Figure> {
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
        caption: Caption::Coherence { gate }.text()?,
        svg: plot::render("coherence", FIG_WIDTH, &[(p, 360)])?,
    })
}

pub(super) fn fig_order(run: &PipelineRun) -> Result<Figure> {
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
        caption: Caption::SingularValues {
            order: n,
            reason: &run.ident.order_reason,
        }
        .text()?,
        svg: plot::render("singular_values", FIG_WIDTH, &[(p, 330)])?,
    })
}

pub(super) fn fig_robustness(run: &PipelineRun) -> Result<Option<Figure>> {
    let (Some(c), Some(w)) = (&run.curves, run.weight()) else {
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
    if let Some(e) = run.envelope() {
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
        caption: Caption::Robustness { value }.text()?,
        svg: plot::render("robustness", FIG_WIDTH, &[(p, 380)])?,
    }))
}

pub(super) fn fig_uncertainty(run: &PipelineRun) -> Result<Option<Figure>> {
    let (Some(e), Some(w)) = (run.envelope(), run.weight()) else {
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
        caption: Caption::Uncertainty {
            family: &e.family,
            worst_ratio: w.worst_overbound_ratio,
            mean_db: w.mean_overbound_db,
        }
        .text()?,
        svg: plot::render("uncertainty", FIG_WIDTH, &[(p, 360)])?,
    }))
}

pub(super) fn fig_sensitivity(run: &PipelineRun) -> Result<Option<Figure>> {
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
        caption: Caption::Sensitivity { value, ms }.text()?,
        svg: plot::render("sensitivity", FIG_WIDTH, &[(p, 340)])?,
    }))
}

pub(super) fn thin(t: &[f64], y: &[f64], max: usize) -> Vec<(f64, f64)> {
    let step = t.len().div_ceil(max.max(1)).max(1);
    t.iter()
        .zip(y)
        .step_by(step)
        .map(|(&a, &b)| (a, b))
        .collect()
}

pub(super) fn fig_step(run: &PipelineRun) -> Result<Option<Figure>> {
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
        caption: Caption::Step {
            s,
            output_unit: &sig.output_unit,
            input_unit: &sig.input_unit,
        }
        .text()?,
        svg: plot::render("step", FIG_WIDTH, &[(py, 300), (pu, 300)])?,
    }))
}

pub(super) fn fig_audit(run: &PipelineRun) -> Result<Option<Figure>> {
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
        caption: Caption::Audit {
            a,
            verdict: verdict_text(a.verdict),
        }
        .text()?,
        svg: plot::render("audit", FIG_WIDTH, &[(pg, 300), (pp, 300)])?,
    }))
}

pub(super) fn verdict_text(v: crate::robust::audit::Verdict) -> &'static str {
    match v {
        crate::robust::audit::Verdict::LinearEnough => "linear enough",
        crate::robust::audit::Verdict::NotLinear => "not linear",
    }
}

pub(super) fn fig_validation(run: &PipelineRun) -> Result<Option<Figure>> {
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
        caption: Caption::Validation {
            log: &v.name,
            shown: w,
            samples: n,
            fit_percent: fit.fit_percent[0],
            nrmse: fit.nrmse[0],
        }
        .text()?,
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
    out.extend(super::compensation_section::figures(run)?);
    out.extend(super::control_section::figures(run)?);
    Ok(out)
}
