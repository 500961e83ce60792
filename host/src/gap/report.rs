//! The gap report: JSON schema (serde) and the human-readable table.
use super::evidence::Evidence;
use super::locate::Where;
use super::noise::NoiseFloor;
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
    /// Where the effect sits: `drive`, `motor`, `drivetrain`, `load`, `state` or `sensor`.
    pub place: String,
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
    /// True when the fit went to the effect's no-effect limit (a dead zone of width ~0, a
    /// saturation limit far beyond the signal, ...): the augmented model reproduces the linear
    /// re-fit on training and validation (both NRMSEs within [`VANISHED_REL`] of its). The
    /// parameters are then meaningless extremes; the text report prints "vanished" instead.
    pub vanished: bool,
}

/// Relative NRMSE tolerance under which an effect counts as vanished (see
/// [`EffectReport::vanished`]).
pub const VANISHED_REL: f64 = 1e-6;

impl EffectReport {
    /// Whether this effect's fit reproduces the linear model (`train_linear`, `gap_linear`:
    /// the linear re-fit's training and validation NRMSE) within [`VANISHED_REL`].
    pub fn reproduces_linear(&self, train_linear: f64, gap_linear: f64) -> bool {
        let close = |a: f64, b: f64| (a - b).abs() <= VANISHED_REL * b.abs().max(f64::MIN_POSITIVE);
        close(self.train_nrmse, train_linear) && close(self.gap_after, gap_linear)
    }
}

/// One effect of the verdict.
#[derive(Debug, Clone, Serialize)]
pub struct VerdictEffect {
    /// Effect name.
    pub effect: String,
    /// Where it sits (see [`EffectReport::place`]).
    pub place: String,
    /// Fitted parameters.
    pub params: BTreeMap<String, f64>,
    /// Its own part of the shrink gap_linear − gap_after (forward-selection deltas; the shares
    /// of the verdict's effects sum to 1).
    pub share: f64,
}

/// The linear model the effects are compared with.
#[derive(Debug, Clone, Serialize)]
pub struct LinearReport {
    /// Discrete model (modal realisation) at the logs' sample time.
    pub model: StateSpaceData,
    /// Output offset fitted with it (output units).
    pub offset: f64,
    /// `refit` (the output-error re-fit) or `nominal` (the nominal sim in modal form, used when
    /// the re-fit does worse than the nominal on the validation log).
    pub source: String,
    /// Validation NRMSE of the output-error re-fit (= gap_linear when `source` is `refit`).
    pub gap_refit: f64,
    /// Continuous-equivalent poles as (natural frequency Hz, damping ratio), one per real pole
    /// or complex pair.
    pub poles_hz: Vec<(f64, f64)>,
    /// RMS over the training logs of their NRMSE.
    pub train_nrmse: f64,
    /// Sample alignment of the logs, samples: the logged output lags the zero-order-hold model
    /// by this much (negative: it leads); every log's input was shifted by it before anything
    /// was fitted or judged ([`crate::gap::align`]). 0 when no significant alignment was found.
    pub alignment_samples: f64,
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
    /// `none` needs gap_linear <= noise_factor × noise floor.
    pub noise_factor: f64,
    /// Share of the excess over the noise floor an effect must remove.
    pub min_excess_closed: f64,
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
    /// Output spikes found and masked before the noise floor and every fit
    /// ([`crate::gap::outliers`]); absent when there were none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub outliers: Option<crate::gap::outliers::Outliers>,
    /// `none`, `unexplained`, an effect name, or effect names joined by `+` (selection order).
    pub verdict: String,
    /// The verdict's effects with place, parameters and share (empty for `none` and
    /// `unexplained`).
    pub verdict_effects: Vec<VerdictEffect>,
    /// NRMSE a perfect model would still leave on the validation log.
    pub noise_floor: NoiseFloor,
    /// What makes the gap nonlinear (computed whatever the verdict).
    pub evidence: Evidence,
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

    /// Human-readable report: the verdict, then WHERE, EVIDENCE, HOW FAR and WHICH, then the
    /// notes.
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        self.verdict_text(&mut s);
        let _ = writeln!(s);
        self.where_text(&mut s);
        let _ = writeln!(s);
        self.evidence_text(&mut s);
        let _ = writeln!(s);
        self.how_far_text(&mut s);
        let _ = writeln!(s);
        self.which_text(&mut s);
        for n in &self.notes {
            let _ = writeln!(s, "note: {n}");
        }
        s
    }

    /// The verdict line and its effects with their shares.
    fn verdict_text(&self, s: &mut String) {
        let _ = writeln!(s, "Sim-to-real gap diagnosis — verdict: {}", self.verdict);
        for e in &self.verdict_effects {
            let p: Vec<String> = e
                .params
                .iter()
                .map(|(k, v)| format!("{k}={v:.4e}"))
                .collect();
            let _ = writeln!(
                s,
                "  {} at {} ({}), {:.0}% of the shrink",
                e.effect,
                e.place,
                p.join(", "),
                100.0 * e.share
            );
        }
    }

    /// WHERE: residual bands and time windows, error and coherence bands.
    fn where_text(&self, s: &mut String) {
        let w = &self.where_;
        let _ = writeln!(s, "WHERE (training logs vs nominal sim)");
        if w.bands.is_empty() {
            let _ = writeln!(
                s,
                "  residual bands: none (no residual where the input has power)"
            );
        } else {
            let _ = writeln!(
                s,
                "  residual power by band (where the input has power; {:.0}% of it lies \
                 outside):",
                100.0 * w.residual_share_outside_input_band
            );
            for b in &w.bands {
                let _ = writeln!(
                    s,
                    "    {:>9.3}–{:<9.3} Hz  peak {:>9.3} Hz  {:>5.1}%",
                    b.lo_hz,
                    b.hi_hz,
                    b.peak_hz,
                    100.0 * b.share
                );
            }
        }
        if let Some(t) = w.time_regions.first() {
            let windows = super::locate::TIME_WINDOWS;
            let _ = writeln!(
                s,
                "  residual energy by time window ({windows} per log; top {}):",
                w.time_regions.len()
            );
            for t in &w.time_regions {
                let _ = writeln!(
                    s,
                    "    {} {:.3}–{:.3} s  {:>5.1}%",
                    t.log,
                    t.t_start_s,
                    t.t_end_s,
                    100.0 * t.share
                );
            }
            let _ = t;
        }
        let _ = writeln!(
            s,
            "  multiplicative error > {:.0}%: {}",
            100.0 * self.settings.threshold,
            bands(&w.bands_hz)
        );
        if w.worst_hz.is_finite() && w.worst_error.is_finite() {
            let _ = writeln!(
                s,
                "  worst: {:.3} Hz (error {:.0}%), band {}",
                w.worst_hz,
                100.0 * w.worst_error,
                bands(&[w.worst_band_hz])
            );
        } else {
            let _ = writeln!(
                s,
                "  worst: none (no powered bin passes the coherence gate)"
            );
        }
        let _ = writeln!(
            s,
            "  coherence < {:.2}: {}",
            self.settings.coherence_min,
            bands(&w.coherence_drops_hz)
        );
    }

    /// EVIDENCE: amplitude dependence, distortion, lattice, dwells, residual regions.
    fn evidence_text(&self, s: &mut String) {
        let ev = &self.evidence;
        let a = &ev.amplitude;
        let _ = writeln!(s, "EVIDENCE of a nonlinearity");
        match &a.not_assessed {
            Some(why) if !a.amplitude_change.is_finite() => {
                let _ = writeln!(s, "  amplitude dependent: not assessed ({why})");
            }
            _ => {
                let _ = writeln!(
                    s,
                    "  amplitude dependent: {} (low vs high response: {:.1}% median, {} near \
                     resonances; tolerance {:.0}%)",
                    if a.amplitude_dependent { "yes" } else { "no" },
                    100.0 * a.amplitude_change,
                    if a.resonance_change.is_finite() {
                        format!(
                            "{:.1}% at {:.3} Hz",
                            100.0 * a.resonance_change,
                            a.resonance_change_hz
                        )
                    } else {
                        "no lightly damped mode in band".into()
                    },
                    100.0 * self.settings.amplitude_tol
                );
            }
        }
        for m in &a.mode_shifts {
            let _ = writeln!(
                s,
                "    mode {:>9.3} → {:<9.3} Hz ({:+.2}%), damping {:.4} → {:.4}{}",
                m.freq_low_hz,
                m.freq_high_hz,
                100.0 * m.freq_shift_rel,
                m.damping_low,
                m.damping_high,
                if m.significant {
                    "  <- shifts"
                } else if !m.in_band {
                    "  (outside the excited band)"
                } else {
                    ""
                }
            );
        }
        let nd = &ev.nonlinear_distortion;
        if let Some(why) = &nd.absent {
            let _ = writeln!(s, "  nonlinear distortion: not assessed ({why})");
        }
        for d in &nd.logs {
            let _ = writeln!(
                s,
                "  nonlinear distortion, {} ({} grid, {} lines {:.3}–{:.3} Hz, {} periods): \
                 non-excited lines hold {:.3}% (odd {:.3}%, even {:.3}%, noise {:.3}%) → no \
                 linear model below NRMSE {:.4}{}",
                d.log,
                d.grid,
                d.excited_lines,
                d.excited_band_hz[0],
                d.excited_band_hz[1],
                d.periods,
                100.0 * (d.odd_share + d.even_share),
                100.0 * d.odd_share,
                100.0 * d.even_share,
                100.0 * d.noise_share,
                d.nrmse_bound,
                if d.significant {
                    "  <- significant"
                } else {
                    ""
                }
            );
        }
        if let Some(l) = &ev.lattice {
            let _ = writeln!(
                s,
                "  output lattice: step {:.4e} ({:.1}% of the output std), {:.1}% of the samples \
                 on it, {} levels",
                l.step,
                100.0 * l.step_over_std,
                100.0 * l.share_on_lattice,
                l.levels
            );
        }
        if let Some(d) = &ev.dwell {
            let _ = writeln!(
                s,
                "  dwells at zero velocity ({}): {} dwells, {:.1}% of the time, breakaway \
                 {:.4e}, largest input held {:.4e}",
                d.velocity,
                d.dwells,
                100.0 * d.dwell_share,
                d.breakaway,
                d.hold_max
            );
        }
        for r in &ev.residual_regions {
            let _ = writeln!(
                s,
                "  residual of the linear model, {:<24} x{:.2} of its overall RMS{}",
                r.region,
                r.rms_ratio,
                if r.concentrates {
                    "  <- concentrates"
                } else {
                    ""
                }
            );
        }
    }

    /// HOW FAR: the free-run NRMSE ladder from the noise floor to the verdict's model.
    fn how_far_text(&self, s: &mut String) {
        let _ = writeln!(s, "HOW FAR (free-run NRMSE on the validation log)");
        let nf = &self.noise_floor;
        if nf.available() {
            let _ = writeln!(
                s,
                "  noise floor      {:.4}  ({} on the {} log{})",
                nf.nrmse,
                nf.method,
                nf.source,
                nf.period_samples
                    .map(|p| format!(", period {p} samples"))
                    .unwrap_or_default()
            );
        } else {
            let _ = writeln!(
                s,
                "  noise floor      not estimable (no repeating input, no off-band bins)"
            );
        }
        if let Some(o) = &self.outliers {
            let _ = writeln!(
                s,
                "  data quality     {} output spike(s), {:.2} % of the samples, masked before \
                 the floor and the fits",
                o.count,
                100.0 * o.share
            );
            for l in &o.logs {
                let _ = writeln!(
                    s,
                    "    {}: {} at {} s{} (largest {:+.4e})",
                    l.log,
                    l.count,
                    l.times_s
                        .iter()
                        .map(|t| format!("{t:.4}"))
                        .collect::<Vec<_>>()
                        .join(", "),
                    if l.count > l.times_s.len() {
                        ", …"
                    } else {
                        ""
                    },
                    l.largest
                );
            }
        }
        let _ = writeln!(s, "  nominal sim      {:.4}", self.gap_before);
        if self.linear.alignment_samples != 0.0 {
            let a = self.linear.alignment_samples;
            let _ = writeln!(
                s,
                "  alignment        {:+.2} samples (the logged output {} the zero-order-hold \
                 model by {:.2} samples = {:.3e} s; the logs are judged aligned)",
                a,
                if a > 0.0 { "lags" } else { "leads" },
                a.abs(),
                a.abs() * self.settings.ts
            );
        }
        let _ = writeln!(
            s,
            "  linear {:<9} {:.4}  ({} vs nominal{})",
            if self.linear.source == "refit" {
                "re-fit"
            } else {
                "(nominal)"
            },
            self.gap_linear,
            pct_change((self.gap_before - self.gap_linear) / self.gap_before),
            if self.linear.source == "refit" {
                String::new()
            } else {
                format!("; the re-fit left {:.4}", self.linear.gap_refit)
            }
        );
        if !self.verdict_effects.is_empty() {
            let _ = writeln!(
                s,
                "  + {:<14} {:.4}  ({} vs linear)",
                self.verdict,
                self.gap_after,
                pct_change((self.gap_linear - self.gap_after) / self.gap_linear)
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
    }

    /// WHICH: every candidate effect, ranked on the validation log.
    fn which_text(&self, s: &mut String) {
        let _ = writeln!(
            s,
            "WHICH (ranked on the validation log; an effect needs >= {:.0}% over the linear \
             model and {:.0}% of its excess over the noise floor; none needs the linear model \
             within {}x the floor)",
            100.0 * self.settings.margin,
            100.0 * self.settings.min_excess_closed,
            self.settings.noise_factor
        );
        let _ = writeln!(
            s,
            "  {:<4} {:<17} {:<10} {:>10} {:>10} {:>11}  parameters",
            "rank", "effect", "place", "val NRMSE", "vs linear", "train NRMSE"
        );
        for (i, e) in self.effects.iter().enumerate() {
            let p: Vec<String> = if e.vanished {
                vec!["vanished (fit at its no-effect limit: same as the linear model)".into()]
            } else {
                e.params
                    .iter()
                    .map(|(k, v)| format!("{k}={v:.4e}"))
                    .chain(e.velocity_from.iter().map(|v| format!("velocity={v}")))
                    .collect()
            };
            let _ = writeln!(
                s,
                "  {:<4} {:<17} {:<10} {:>10.4} {:>10} {:>11.5}  {}",
                i + 1,
                e.effect,
                e.place,
                e.gap_after,
                pct_change(e.improvement),
                e.train_nrmse,
                p.join(", ")
            );
        }
    }
}

/// A relative shrink as a signed change in percent ("-12%": the NRMSE went down 12 %).
fn pct_change(v: f64) -> String {
    format!("{:+.0}%", -100.0 * v)
}

#[cfg(test)]
mod vanished_tests {
    use super::EffectReport;

    fn effect(train: f64, val: f64) -> EffectReport {
        EffectReport {
            effect: "deadzone".into(),
            place: "drive".into(),
            params: [("width".to_string(), 3.3e-35)].into_iter().collect(),
            gap_after: val,
            improvement: 0.0,
            train_nrmse: train,
            velocity_from: None,
            vanished: false,
        }
    }

    #[test]
    fn an_effect_that_reproduces_the_linear_model_has_vanished() {
        assert!(effect(0.140450, 0.114100).reproduces_linear(0.140450, 0.114100));
        assert!(effect(0.140450 * (1.0 + 5e-7), 0.1141).reproduces_linear(0.140450, 0.1141));
        // A training gain of 1e-4 relative is an effect, however small.
        assert!(!effect(0.140436, 0.1141).reproduces_linear(0.140450, 0.1141));
        assert!(!effect(0.14045, 0.1146).reproduces_linear(0.14045, 0.1141));
    }
}
