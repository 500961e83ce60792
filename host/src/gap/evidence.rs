//! Evidence that a gap is nonlinear, computed from the data whatever the verdict (reported in
//! `evidence`; the verdict `unexplained` cites it):
//!
//! * **Amplitude dependence** ([`amplitude_evidence`]): the training logs with the smallest
//!   and largest input RMS are compared three ways —
//!   - the median relative difference |G_low − G_high|/|G_high| of their Welch H1 estimates over
//!     the bins coherent in both (`amplitude_change`, the earlier test);
//!   - the same difference in the band around each lightly damped mode of the linear re-fit
//!     (`resonance_change`: bins within f_n·(1 ± max(2ζ, 2 bins/f_n)), the largest median over
//!     the modes): a mode that moves by a few per cent changes the response near it by far more
//!     than the median over all bins shows;
//!   - **mode shifts**: the linear re-fit is refitted (output error, poles free) on each of the
//!     two logs alone, at most [`MODE_FIT_SAMPLES`] samples after the warm-up, and every complex
//!     pair's natural frequency and damping ratio are compared. A shift is `significant` when the
//!     mode lies where the input has power (PSD within [`EXCITED_REL`] of its peak), is lightly
//!     damped (ζ < [`LIGHT_DAMPING`]) and its frequency moves by at least
//!     max([`MIN_FREQ_SHIFT`], ζ/4) relative, or its damping ratio by at least half and by 0.005.
//!
//!   `amplitude_dependent` = any of: median change > tol, resonance change > tol, a
//!   significant mode shift (tol = `amplitude_tol`, default 0.1).
//! * **Nonlinear distortion** ([`distortion`]): for every log whose input repeats (a multisine,
//!   [`detect_period`]), the period-synchronous spectra ([`PeriodicAveraging`]) give the excited
//!   lines; the output power on the *non-excited* lines from the first line up to three times
//!   the last excited one (below the band too: even-order products and slow odd ones land
//!   there) (minus the noise power estimated there from the period-to-period
//!   scatter) cannot come from any linear model driven by that input. Reported as shares of the
//!   output's periodic power, split into odd and even lines (for an odd multisine, power on the
//!   odd detection lines is odd nonlinear distortion and on the even lines even distortion, as
//!   in the best-linear-approximation method of Pintelon & Schoukens), with
//!   `nrmse_bound` = sqrt(non-excited power / output variance), a lower bound on any linear
//!   model's NRMSE on that log. `significant` when that power is at least
//!   [`DISTORTION_NOISE_RATIO`] times the noise power on the same lines and its share at least
//!   [`MIN_DISTORTION_SHARE`].
use super::locate::{default_nperseg, Region};
use super::modal::{FitSet, ModalModel};
use super::noise::detect_period;
use super::select::{DwellEvidence, LatticeEvidence};
use crate::error::Result;
use crate::spectral::{PeriodicAveraging, Welch};
use serde::Serialize;

/// Input PSD within this fraction of its peak (−20 dB) counts as "the input has power here".
pub const EXCITED_REL: f64 = 1e-2;

/// A line of a periodic input is excited when its power is within this fraction (−30 dB) of the
/// strongest line's (and 10 times its own noise variance): weaker lines of a measured input
/// (shaker-structure interaction) count as not excited.
pub const EXCITED_LINE_REL: f64 = 1e-3;

/// Damping ratio below which a mode counts as lightly damped for the mode-shift test.
pub const LIGHT_DAMPING: f64 = 0.3;

/// Complex pairs of the linear model damped more than this are not listed as modes.
pub const MAX_REPORTED_DAMPING: f64 = 0.95;

/// Smallest relative frequency shift of a mode that counts (1 %).
pub const MIN_FREQ_SHIFT: f64 = 0.01;

/// Samples (after the warm-up) of each log used for its own mode fit.
pub const MODE_FIT_SAMPLES: usize = 16_384;

/// Non-excited-line power must be this many times the noise power on those lines.
pub const DISTORTION_NOISE_RATIO: f64 = 4.0;

/// ... and at least this share of the output's periodic power (−30 dB).
pub const MIN_DISTORTION_SHARE: f64 = 1e-3;

/// One mode of the linear re-fit as seen in the low- and the high-amplitude training log.
#[derive(Debug, Clone, Serialize)]
pub struct ModeShift {
    /// Natural frequency fitted on the low-amplitude log, Hz.
    pub freq_low_hz: f64,
    /// Natural frequency fitted on the high-amplitude log, Hz.
    pub freq_high_hz: f64,
    /// Damping ratio on the low-amplitude log.
    pub damping_low: f64,
    /// Damping ratio on the high-amplitude log.
    pub damping_high: f64,
    /// (freq_high − freq_low)/freq_low.
    pub freq_shift_rel: f64,
    /// Whether the input has power at the mode's frequency.
    pub in_band: bool,
    /// Whether the shift counts (module docs).
    pub significant: bool,
}

/// The amplitude-dependence evidence (module docs).
#[derive(Debug, Clone, Serialize)]
pub struct AmplitudeEvidence {
    /// Any of the three tests fired.
    pub amplitude_dependent: bool,
    /// Median |G_low − G_high|/|G_high| over coherent bins (NaN: not assessed).
    pub amplitude_change: f64,
    /// Largest median relative difference in a band around a lightly damped in-band mode
    /// (NaN: no such mode).
    pub resonance_change: f64,
    /// Frequency of the mode where `resonance_change` was found, Hz.
    pub resonance_change_hz: f64,
    /// Every complex mode of the linear re-fit, low vs high log.
    pub mode_shifts: Vec<ModeShift>,
    /// Why it was not assessed (one training log, no coherent bins), if so.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub not_assessed: Option<String>,
}

/// Distortion on the non-excited lines of one periodic log (module docs).
#[derive(Debug, Clone, Serialize)]
pub struct LineDistortion {
    /// Which log (file name as given).
    pub log: String,
    /// Period, samples.
    pub period_samples: usize,
    /// Periods averaged.
    pub periods: usize,
    /// Excited lines (count) and the range of their frequencies, Hz.
    pub excited_lines: usize,
    /// Lowest and highest excited frequency, Hz.
    pub excited_band_hz: [f64; 2],
    /// `odd` when only odd lines are excited (an odd multisine), else `full`.
    pub grid: String,
    /// Share of the output's periodic power on non-excited odd lines (noise removed).
    pub odd_share: f64,
    /// Share on non-excited even lines (noise removed).
    pub even_share: f64,
    /// Share of the noise power estimated on those lines.
    pub noise_share: f64,
    /// sqrt(non-excited power / output variance): lower bound on a linear model's NRMSE.
    pub nrmse_bound: f64,
    /// Whether the distortion clears the noise (module docs).
    pub significant: bool,
}

/// Nonlinear-distortion evidence: one entry per periodic log, or the reason there is none.
#[derive(Debug, Clone, Serialize)]
pub struct DistortionEvidence {
    /// Per periodic log.
    pub logs: Vec<LineDistortion>,
    /// Why nothing was computed (no log with a repeating input), if so.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub absent: Option<String>,
}

impl DistortionEvidence {
    /// Whether any log shows significant distortion.
    pub fn significant(&self) -> bool {
        self.logs.iter().any(|l| l.significant)
    }
}

/// Everything the report's `evidence` holds (module docs).
#[derive(Debug, Clone, Serialize)]
pub struct Evidence {
    /// Amplitude dependence (its fields appear at the top level of `evidence`).
    #[serde(flatten)]
    pub amplitude: AmplitudeEvidence,
    /// Output power on non-excited lines of periodic logs.
    pub nonlinear_distortion: DistortionEvidence,
    /// Concentration of the linear model's residual (copied from `where`).
    pub residual_regions: Vec<Region>,
    /// Lattice of the measured outputs (a quantizing sensor), when found.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lattice: Option<Lattice>,
    /// Dwells at zero velocity while the input pushes (static friction), when found.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dwell: Option<Dwell>,
}

/// The lattice evidence ([`crate::gap::select::lattice_evidence`]) as reported.
#[derive(Debug, Clone, Serialize)]
pub struct Lattice {
    /// Step, output units.
    pub step: f64,
    /// Share of the samples on the lattice.
    pub share_on_lattice: f64,
    /// Occupied levels.
    pub levels: usize,
    /// Step over the output standard deviation.
    pub step_over_std: f64,
}

impl From<LatticeEvidence> for Lattice {
    fn from(l: LatticeEvidence) -> Self {
        Self {
            step: l.step,
            share_on_lattice: l.share_on_lattice,
            levels: l.levels,
            step_over_std: l.step_over_std,
        }
    }
}

/// The dwell evidence ([`crate::gap::select::dwell_evidence`]) as reported.
#[derive(Debug, Clone, Serialize)]
pub struct Dwell {
    /// Dwells found.
    pub dwells: usize,
    /// Share of the scored samples in dwells.
    pub dwell_share: f64,
    /// Median |input| when a dwell ends (breakaway), input units.
    pub breakaway: f64,
    /// Median largest |input| held without moving, input units.
    pub hold_max: f64,
    /// Which signal stood for the velocity.
    pub velocity: String,
}

impl From<&DwellEvidence> for Dwell {
    fn from(d: &DwellEvidence) -> Self {
        Self {
            dwells: d.dwells,
            dwell_share: d.dwell_share,
            breakaway: d.breakaway,
            hold_max: d.hold_max,
            velocity: d.velocity.name().to_string(),
        }
    }
}

impl Evidence {
    /// Whether any test points at a nonlinearity: amplitude dependence, significant distortion
    /// on non-excited lines, a residual concentration, or dwells at zero velocity.
    pub fn nonlinear(&self) -> bool {
        self.amplitude.amplitude_dependent
            || self.nonlinear_distortion.significant()
            || self.residual_regions.iter().any(|r| r.concentrates)
            || self.dwell.is_some()
    }

    /// Short phrases naming the tests that fired (for the text report and notes).
    pub fn findings(&self) -> Vec<String> {
        let mut v = Vec::new();
        let a = &self.amplitude;
        if a.amplitude_change.is_finite() && a.amplitude_dependent {
            v.push(format!(
                "low and high amplitude responses differ ({:.1}% median, {:.1}% near the \
                 {:.2} Hz mode)",
                100.0 * a.amplitude_change,
                100.0 * a.resonance_change,
                a.resonance_change_hz
            ));
        }
        for m in a.mode_shifts.iter().filter(|m| m.significant) {
            v.push(format!(
                "mode moves {:.3} → {:.3} Hz ({:+.1}%), damping {:.4} → {:.4}",
                m.freq_low_hz,
                m.freq_high_hz,
                100.0 * m.freq_shift_rel,
                m.damping_low,
                m.damping_high
            ));
        }
        for d in self
            .nonlinear_distortion
            .logs
            .iter()
            .filter(|d| d.significant)
        {
            v.push(format!(
                "{}: {:.2}% of the output power on non-excited lines (odd {:.2}%, even {:.2}%), \
                 no linear model below NRMSE {}",
                d.log,
                100.0 * (d.odd_share + d.even_share),
                100.0 * d.odd_share,
                100.0 * d.even_share,
                if d.nrmse_bound >= 1e-4 {
                    format!("{:.4}", d.nrmse_bound)
                } else {
                    format!("{:.1e}", d.nrmse_bound)
                }
            ));
        }
        if let Some(l) = &self.lattice {
            v.push(format!(
                "outputs sit on a lattice of step {:.4e} ({:.1}% of the output std, {} levels)",
                l.step,
                100.0 * l.step_over_std,
                l.levels
            ));
        }
        if let Some(d) = &self.dwell {
            v.push(format!(
                "{} dwells at zero velocity ({:.1}% of the time), breakaway {:.4e}",
                d.dwells,
                100.0 * d.dwell_share,
                d.breakaway
            ));
        }
        for r in self.residual_regions.iter().filter(|r| r.concentrates) {
            v.push(format!(
                "residual concentrates at {} (x{:.2} of its RMS)",
                r.region, r.rms_ratio
            ));
        }
        v
    }
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// Continuous natural frequency (Hz) and damping ratio of the discrete pole r·e^{jφ}.
pub fn pair_freq_damping(r: f64, phi: f64, ts: f64) -> (f64, f64) {
    let s = num_complex::Complex64::new(r.ln(), phi) / ts;
    let wn = s.norm();
    (
        wn / (2.0 * std::f64::consts::PI),
        if wn > 0.0 { -s.re / wn } else { 1.0 },
    )
}

/// Whether frequency `f` (Hz) lies where the PSD `suu` (bins `freq`) is within [`EXCITED_REL`]
/// of its peak (nearest bin).
fn excited_at(freq: &[f64], suu: &[f64], f: f64) -> bool {
    let top = suu.iter().cloned().fold(0.0, f64::max);
    if freq.len() < 2 || top.is_nan() || top <= 0.0 {
        return false;
    }
    let df = freq[1] - freq[0];
    let k = ((f / df).round() as usize).min(freq.len() - 1);
    suu[k] >= EXCITED_REL * top
}

/// The amplitude-dependence evidence (module docs) from the training logs `u`, `y`, the
/// linear re-fit `lin`, the Welch segment `nperseg`, the coherence gate and tolerance.
#[allow(clippy::too_many_arguments)]
pub fn amplitude_evidence(
    u: &[Vec<f64>],
    y: &[Vec<f64>],
    lin: &ModalModel,
    warmup: usize,
    ts: f64,
    nperseg: usize,
    coherence_min: f64,
    tol: f64,
) -> Result<AmplitudeEvidence> {
    let mut out = AmplitudeEvidence {
        amplitude_dependent: false,
        amplitude_change: f64::NAN,
        resonance_change: f64::NAN,
        resonance_change_hz: f64::NAN,
        mode_shifts: Vec::new(),
        not_assessed: None,
    };
    if u.len() < 2 {
        out.not_assessed = Some("one training log: needs two of different amplitude".into());
        return Ok(out);
    }
    let mut order: Vec<usize> = (0..u.len()).collect();
    order.sort_by(|&a, &b| rms(&u[a]).total_cmp(&rms(&u[b])));
    let (lo, hi) = (order[0], order[order.len() - 1]);
    let fs = 1.0 / ts;
    let welch = Welch::new(nperseg);
    let etfe = |l: usize| welch.etfe(&u[l][warmup..], &y[l][warmup..], fs);
    let (sl, sh) = (etfe(lo)?, etfe(hi)?);
    let freq = &sl.freq_hz;
    let (cl, ch) = (sl.gate(coherence_min), sh.gate(coherence_min));
    let both: Vec<usize> = (1..freq.len()).filter(|&k| cl[k] && ch[k]).collect();
    let rel = |k: usize| ((sl.h[k] - sh.h[k]) / sh.h[k]).norm();
    let median = |mut d: Vec<f64>| -> f64 {
        d.retain(|v| v.is_finite());
        if d.is_empty() {
            return f64::NAN;
        }
        d.sort_by(f64::total_cmp);
        d[d.len() / 2]
    };
    out.amplitude_change = median(both.iter().map(|&k| rel(k)).collect());
    if both.is_empty() {
        out.not_assessed = Some("no frequency bin is coherent in both training logs".into());
    }
    // Pooled input PSD of the two logs, for "in band".
    let suu: Vec<f64> = sl.suu.iter().zip(&sh.suu).map(|(a, b)| a + b).collect();
    let df = freq.get(1).copied().unwrap_or(1.0);

    // Mode shifts: refit the linear re-fit on each log alone.
    let fit_one = |l: usize| -> Option<ModalModel> {
        let keep = (warmup + MODE_FIT_SAMPLES).min(u[l].len());
        let set = FitSet::new(
            vec![u[l][..keep].to_vec()],
            vec![y[l][..keep].to_vec()],
            warmup,
        )
        .ok()?;
        let mut m = lin.clone();
        m.fit_output_error(&set, 30)?;
        Some(m)
    };
    let (ml, mh) = (fit_one(lo), fit_one(hi));
    for (j, &(r, phi)) in lin.pairs.iter().enumerate() {
        let (f0, z0) = pair_freq_damping(r, phi, ts);
        // Resonance-band change around the re-fit's mode.
        if z0 < LIGHT_DAMPING && excited_at(freq, &suu, f0) {
            let half = (2.0 * z0 * f0).max(2.0 * df);
            let d: Vec<f64> = both
                .iter()
                .filter(|&&k| (freq[k] - f0).abs() <= half)
                .map(|&k| rel(k))
                .collect();
            let m = median(d);
            if m.is_finite() && (out.resonance_change.is_nan() || m > out.resonance_change) {
                out.resonance_change = m;
                out.resonance_change_hz = f0;
            }
        }
        let (Some(ml), Some(mh)) = (&ml, &mh) else {
            continue;
        };
        // Each log's fit started from the same pairs, whose parameters move continuously: pair
        // j of a log's fit is pair j of the linear model. Overdamped pairs are not modes.
        if z0 > MAX_REPORTED_DAMPING {
            continue;
        }
        let nearest = |m: &ModalModel| -> Option<(f64, f64)> {
            m.pairs.get(j).map(|&(r, p)| pair_freq_damping(r, p, ts))
        };
        let (Some((fl, zl)), Some((fh, zh))) = (nearest(ml), nearest(mh)) else {
            continue;
        };
        // A pair that became two real poles in either fit is no mode to follow.
        if zl >= 1.0 - 1e-9 || zh >= 1.0 - 1e-9 {
            continue;
        }
        let shift = (fh - fl) / fl;
        let zm = 0.5 * (zl + zh);
        let in_band = excited_at(freq, &suu, 0.5 * (fl + fh));
        let significant = in_band
            && zm < LIGHT_DAMPING
            && (shift.abs() >= MIN_FREQ_SHIFT.max(0.25 * zm)
                || ((zh - zl).abs() >= 0.5 * zm && (zh - zl).abs() >= 0.005));
        out.mode_shifts.push(ModeShift {
            freq_low_hz: fl,
            freq_high_hz: fh,
            damping_low: zl,
            damping_high: zh,
            freq_shift_rel: shift,
            in_band,
            significant,
        });
    }
    out.amplitude_dependent = out.amplitude_change > tol
        || out.resonance_change > tol
        || out.mode_shifts.iter().any(|m| m.significant);
    Ok(out)
}

/// Nonlinear-distortion evidence (module docs) over the logs `(name, u, y)`, `warmup` samples
/// (rounded up to whole periods, at least one period when three or more exist) skipped.
pub fn distortion(logs: &[(String, &[f64], &[f64])], warmup: usize, ts: f64) -> DistortionEvidence {
    let mut out = Vec::new();
    for (name, u, y) in logs {
        let Some(p) = detect_period(u) else {
            continue;
        };
        let total = u.len() / p;
        let mut skip = warmup.div_ceil(p);
        if total >= 3 {
            skip = skip.max(1);
        }
        let mut pa = PeriodicAveraging::new(p);
        pa.skip_periods = skip;
        pa.min_relative_power = EXCITED_LINE_REL;
        let Ok(frf) = pa.frf(u, y, 1.0 / ts) else {
            continue;
        };
        let sp = &frf.spectra;
        let nb = sp.y.len();
        let lines = &frf.lines;
        let (Some(&k_lo), Some(&k_hi)) = (lines.first(), lines.last()) else {
            continue;
        };
        let mut excited = vec![false; nb];
        for &k in lines {
            excited[k] = true;
        }
        let k_top = (3 * k_hi).min(nb - 1);
        // Power per one-sided line of the period mean: 2|Ȳ_k|² (Nyquist and DC once).
        let w = |k: usize| if k == 0 || 2 * k == p { 1.0 } else { 2.0 };
        let mut total_pow = 0.0;
        for k in 1..nb {
            total_pow += w(k) * sp.y[k].norm_sqr();
        }
        let (mut odd, mut even, mut noise) = (0.0, 0.0, 0.0);
        for (k, &exc) in excited.iter().enumerate().take(k_top + 1).skip(1) {
            if exc {
                continue;
            }
            let nv = w(k) * sp.var_y[k];
            let pw = (w(k) * sp.y[k].norm_sqr() - nv).max(0.0);
            noise += nv;
            if k % 2 == 1 {
                odd += pw;
            } else {
                even += pw;
            }
        }
        let grid = if lines.iter().all(|k| k % 2 == 1) {
            "odd"
        } else {
            "full"
        };
        let start = skip * p;
        let yv = &y[start..start + frf.n_periods * p];
        let mean = yv.iter().sum::<f64>() / yv.len() as f64;
        let var = yv.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / yv.len() as f64;
        let share = |v: f64| if total_pow > 0.0 { v / total_pow } else { 0.0 };
        out.push(LineDistortion {
            log: name.clone(),
            period_samples: p,
            periods: frf.n_periods,
            excited_lines: lines.len(),
            excited_band_hz: [sp.freq_hz[k_lo], sp.freq_hz[k_hi]],
            grid: grid.into(),
            odd_share: share(odd),
            even_share: share(even),
            noise_share: share(noise),
            nrmse_bound: if var > 0.0 {
                ((odd + even) / var).sqrt()
            } else {
                f64::NAN
            },
            significant: odd + even >= DISTORTION_NOISE_RATIO * noise
                && share(odd + even) >= MIN_DISTORTION_SHARE,
        });
    }
    let absent = out.is_empty().then(|| {
        "no log has a repeating (multisine) input with two whole periods after the warm-up".into()
    });
    DistortionEvidence { logs: out, absent }
}

/// Default Welch segment for a set of logs after the warm-up (as the "where" analysis).
pub fn nperseg_for(u: &[Vec<f64>], warmup: usize) -> usize {
    default_nperseg(u.iter().map(|v| v.len() - warmup).min().unwrap_or(0))
}
