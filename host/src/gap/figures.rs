//! SVG figures of a gap diagnosis (rendered with [`crate::plot`]):
//!
//! * `gap_frequency.svg` — top: the multiplicative error |G_meas − G_sim|/|G_sim| of the nominal
//!   sim against the training logs' pooled H1 estimate (coherence-gated bins), the threshold,
//!   the bands above it and the coherence drops; bottom: the residual spectrum on the validation
//!   log, sqrt(S_rr/S_yy) per Welch bin (residual relative to output), for the nominal sim, the
//!   linear re-fit and the verdict's model.
//! * `gap_overlay.svg` — top: the validation output and the three free-run simulations over the
//!   first second (at most 2000 samples) after the warm-up; bottom: their residuals.
use super::diagnose::Diagnosis;
use crate::error::Result;
use crate::plot::{colors, render, Band, Kind, LegendAt, Panel, RefLine, Series};
use crate::spectral::Welch;

fn verdict_label(d: &Diagnosis) -> String {
    if d.report.verdict_effects.is_empty() {
        format!("linear model (verdict {})", d.report.verdict)
    } else {
        format!("linear + {}", d.report.verdict)
    }
}

/// The figures as (file name, SVG text).
pub fn figures(d: &Diagnosis) -> Result<Vec<(String, String)>> {
    let (u, y) = (&d.validation.0, &d.validation.1);
    let w = d.warmup;
    let ts = d.report.settings.ts;
    let y_nom = d.nominal.simulate_siso(u, None)?;
    let y_lin = d.linear.simulate(u)?;
    let y_best = d.verdict_model().simulate(u)?;
    let models: [(&str, &Vec<f64>, _); 3] = [
        ("nominal sim", &y_nom, colors::RED),
        ("linear re-fit", &y_lin, colors::ORANGE),
        ("", &y_best, colors::GREEN),
    ];
    let best_label = verdict_label(d);

    // Frequency figure.
    let wh = &d.report.where_;
    let mut top = Panel::new(
        "Where: multiplicative error of the nominal sim (training logs)",
        "frequency [Hz]",
        "|G_meas - G_sim| / |G_sim|",
        true,
        true,
    );
    top.series.push(Series::new(
        "gated bins",
        wh.freq_hz
            .iter()
            .zip(&wh.mult_error)
            .map(|(&f, &e)| (f, e))
            .collect(),
        colors::BLUE,
        Kind::Line(1),
    ));
    top.hlines.push(RefLine {
        at: d.report.settings.threshold,
        color: colors::GREY,
        label: Some(format!("threshold {}", d.report.settings.threshold)),
    });
    for b in &wh.coherence_drops_hz {
        top.bands.push(Band {
            x0: b[0],
            x1: b[1],
            color: colors::EXCLUDED,
        });
    }
    for b in &wh.bands_hz {
        top.bands.push(Band {
            x0: b[0],
            x1: b[1],
            color: colors::REGION,
        });
    }
    top.band_label = Some("above threshold (blue) / coherence drop (orange)".into());
    if wh.worst_hz.is_finite() {
        top.vlines.push(RefLine {
            at: wh.worst_hz,
            color: colors::PURPLE,
            label: Some(format!("worst {:.3} Hz", wh.worst_hz)),
        });
    }
    let ys = &y[w..];
    let welch = Welch::new(wh.nperseg.min(ys.len()));
    let fs = 1.0 / ts;
    let syy = welch.psd(ys, fs)?;
    let mut bottom = Panel::new(
        "How far: residual spectrum on the validation log",
        "frequency [Hz]",
        "sqrt(S_rr / S_yy)",
        true,
        true,
    );
    for (label, yh, color) in models.iter() {
        let r: Vec<f64> = ys.iter().zip(&yh[w..]).map(|(a, b)| a - b).collect();
        let srr = welch.psd(&r, fs)?;
        let pts = syy
            .freq_hz
            .iter()
            .zip(srr.density.iter().zip(&syy.density))
            .skip(1)
            .map(|(&f, (&pr, &py))| (f, if py > 0.0 { (pr / py).sqrt() } else { f64::NAN }))
            .collect();
        let label = if label.is_empty() {
            best_label.as_str()
        } else {
            label
        };
        bottom
            .series
            .push(Series::new(label, pts, *color, Kind::Line(1)));
    }
    bottom.legend = LegendAt::LowerRight;
    let freq_svg = render("gap_frequency", 900, &[(top, 380), (bottom, 380)])?;

    // Time-domain overlay.
    let n_show = (y.len() - w).min(((1.0 / ts).round() as usize).clamp(200, 2000));
    let t = |k: usize| (w + k) as f64 * ts;
    let mut over = Panel::new(
        "Validation log: measured output and free-run simulations",
        "time [s]",
        "y",
        false,
        false,
    );
    over.series.push(Series::new(
        "measured",
        (0..n_show).map(|k| (t(k), y[w + k])).collect(),
        colors::BLUE,
        Kind::Line(2),
    ));
    let mut resid = Panel::new("Residuals y - y_sim", "time [s]", "residual", false, false);
    for (label, yh, color) in models.iter() {
        let label = if label.is_empty() {
            best_label.as_str()
        } else {
            label
        };
        over.series.push(Series::new(
            label,
            (0..n_show).map(|k| (t(k), yh[w + k])).collect(),
            *color,
            Kind::Line(1),
        ));
        resid.series.push(Series::new(
            label,
            (0..n_show).map(|k| (t(k), y[w + k] - yh[w + k])).collect(),
            *color,
            Kind::Line(1),
        ));
    }
    let overlay_svg = render("gap_overlay", 900, &[(over, 380), (resid, 300)])?;
    Ok(vec![
        ("gap_frequency.svg".into(), freq_svg),
        ("gap_overlay.svg".into(), overlay_svg),
    ])
}
