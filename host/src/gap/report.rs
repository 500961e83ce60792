//! The gap report: JSON schema (serde) and the human-readable table.
use super::locate::Where;
use crate::error::Result;
use crate::lti::StateSpaceData;
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// One fitted candidate effect, as reported.
#[derive(Debug, Clone, Serialize)]
pub struct EffectReport {
    /// Effect name (`coulomb_friction`, ...).
    pub effect: String,
    /// Fitted parameters (units: see [`crate::gap::effect`]).
    pub params: BTreeMap<String, f64>,
    /// Validation NRMSE of the linear part augmented with this effect.
    pub gap_after: f64,
    /// Relative improvement over the linear re-fit on the validation log,
    /// (gap_linear − gap_after)/gap_linear.
    pub improvement: f64,
    /// RMS over the training logs of their NRMSE.
    pub train_nrmse: f64,
    /// For friction: which model signal stood for the velocity (`output`, `output_derivative`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub velocity_from: Option<String>,
}

/// The linear re-fit.
#[derive(Debug, Clone, Serialize)]
pub struct LinearReport {
    /// Discrete model (modal realisation) at the logs' sample time.
    pub model: StateSpaceData,
    /// Output offset fitted with it (output units).
    pub offset: f64,
    /// Continuous-equivalent poles as (natural frequency Hz, damping ratio), one per real pole
    /// or complex pair.
    pub poles_hz: Vec<(f64, f64)>,
    /// RMS over the training logs of their NRMSE.
    pub train_nrmse: f64,
}

/// Settings the diagnosis ran with.
#[derive(Debug, Clone, Serialize)]
pub struct Settings {
    /// Sample time, s.
    pub ts: f64,
    /// Samples excluded at the start of every log.
    pub warmup_samples: usize,
    /// Verdict margin (relative NRMSE improvement over the linear re-fit).
    pub margin: f64,
    /// Parsimony margin for stiction over Coulomb friction.
    pub nested_margin: f64,
    /// Multiplicative-error threshold of the "where" bands.
    pub threshold: f64,
    /// Coherence gate.
    pub coherence_min: f64,
    /// Amplitude-dependence tolerance.
    pub amplitude_tol: f64,
}

/// Residual power in the worst band relative to the output power there, on the validation log:
/// sqrt(Σ_band S_rr / Σ_band S_yy) from Welch spectra, for the nominal sim, the linear re-fit
/// and the verdict's model.
#[derive(Debug, Clone, Serialize)]
pub struct BandError {
    /// The band, Hz.
    pub band_hz: [f64; 2],
    /// Nominal sim.
    pub before: f64,
    /// Linear re-fit.
    pub linear: f64,
    /// Verdict model (linear re-fit when the verdict is `none`).
    pub after: f64,
}

/// The full report (`ferrosid gap --json`).
#[derive(Debug, Clone, Serialize)]
pub struct GapReport {
    /// Top effect, or `none`.
    pub verdict: String,
    /// Where the sim and the plant disagree.
    #[serde(rename = "where")]
    pub where_: Where,
    /// Validation NRMSE of the nominal sim.
    pub gap_before: f64,
    /// Validation NRMSE of the linear re-fit.
    pub gap_linear: f64,
    /// Validation NRMSE of the verdict's model (= gap_linear when the verdict is `none`).
    pub gap_after: f64,
    /// Frequency-domain error in the worst band.
    pub band_error: BandError,
    /// Every candidate, ranked best first on the validation log.
    pub effects: Vec<EffectReport>,
    /// The linear re-fit.
    pub linear: LinearReport,
    /// Settings used.
    pub settings: Settings,
    /// Non-fatal remarks (skipped starts, candidates without a fit).
    pub notes: Vec<String>,
}

fn bands(b: &[[f64; 2]]) -> String {
    if b.is_empty() {
        return "none".into();
    }
    b.iter()
        .map(|[lo, hi]| format!("{lo:.3}–{hi:.3} Hz"))
        .collect::<Vec<_>>()
        .join(", ")
}

impl GapReport {
    /// JSON text (pretty-printed).
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_string_pretty(self)
            .map_err(|e| crate::error::Error::Numerical(format!("serialising the gap report: {e}")))
    }

    /// Human-readable report.
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        let w = &self.where_;
        let pct = |v: f64| format!("{:+.0}%", -100.0 * v);
        let _ = writeln!(s, "Sim-to-real gap diagnosis — verdict: {}", self.verdict);
        let _ = writeln!(s);
        let _ = writeln!(s, "WHERE (training logs vs nominal sim)");
        let _ = writeln!(
            s,
            "  multiplicative error > {:.0}%: {}",
            100.0 * self.settings.threshold,
            bands(&w.bands_hz)
        );
        let _ = writeln!(
            s,
            "  worst: {:.3} Hz (error {:.0}%), band {}",
            w.worst_hz,
            100.0 * w.worst_error,
            bands(&[w.worst_band_hz])
        );
        let _ = writeln!(
            s,
            "  coherence < {:.2}: {}",
            self.settings.coherence_min,
            bands(&w.coherence_drops_hz)
        );
        if w.amplitude_change.is_finite() {
            let _ = writeln!(
                s,
                "  amplitude dependent: {} (low vs high response differ by {:.1}% median, \
                 tolerance {:.0}%)",
                if w.amplitude_dependent { "yes" } else { "no" },
                100.0 * w.amplitude_change,
                100.0 * self.settings.amplitude_tol
            );
        } else {
            let _ = writeln!(
                s,
                "  amplitude dependent: not assessed (needs two training logs of different \
                 amplitude with coherent bins in common)"
            );
        }
        for r in &w.residual_regions {
            let _ = writeln!(
                s,
                "  residual of the linear re-fit, {:<24} x{:.2} of its overall RMS{}",
                r.region,
                r.rms_ratio,
                if r.concentrates {
                    "  <- concentrates"
                } else {
                    ""
                }
            );
        }
        let _ = writeln!(s);
        let _ = writeln!(s, "HOW FAR (free-run NRMSE on the validation log)");
        let _ = writeln!(s, "  nominal sim      {:.4}", self.gap_before);
        let _ = writeln!(
            s,
            "  linear re-fit    {:.4}  ({} vs nominal)",
            self.gap_linear,
            pct((self.gap_before - self.gap_linear) / self.gap_before)
        );
        if self.verdict != "none" {
            let _ = writeln!(
                s,
                "  + {:<14} {:.4}  ({} vs linear)",
                self.verdict,
                self.gap_after,
                pct((self.gap_linear - self.gap_after) / self.gap_linear)
            );
        }
        let b = &self.band_error;
        let _ = writeln!(
            s,
            "  worst band {}: residual/output {:.3} nominal, {:.3} linear, {:.3} after",
            bands(&[b.band_hz]),
            b.before,
            b.linear,
            b.after
        );
        let _ = writeln!(s);
        let _ = writeln!(
            s,
            "WHICH (ranked on the validation log; verdict needs >= {:.0}% over the linear \
             re-fit)",
            100.0 * self.settings.margin
        );
        let _ = writeln!(
            s,
            "  {:<4} {:<17} {:>10} {:>10} {:>11}  parameters",
            "rank", "effect", "val NRMSE", "vs linear", "train NRMSE"
        );
        for (i, e) in self.effects.iter().enumerate() {
            let p: Vec<String> = e
                .params
                .iter()
                .map(|(k, v)| format!("{k}={v:.4e}"))
                .chain(e.velocity_from.iter().map(|v| format!("velocity={v}")))
                .collect();
            let _ = writeln!(
                s,
                "  {:<4} {:<17} {:>10.4} {:>10} {:>11.5}  {}",
                i + 1,
                e.effect,
                e.gap_after,
                pct(e.improvement),
                e.train_nrmse,
                p.join(", ")
            );
        }
        for n in &self.notes {
            let _ = writeln!(s, "note: {n}");
        }
        s
    }
}
