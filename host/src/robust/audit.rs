//! Dual/multi-amplitude nonlinearity audit: overlay frequency responses measured at different
//! excitation amplitudes and report where, near the intended crossover, they disagree.
//!
//! For every bin inside the audit band [f_c/`band_factor`, f_c·`band_factor`] (a decade each
//! side by default) and every pair of runs (a, b), the gain shift 20·log10(|H_b|/|H_a|) dB and
//! the phase shift ∠(H_b/H_a) (wrapped to (−180°, 180°]) are computed; the pair with the largest
//! absolute shift is kept per bin. Bins whose worst gain shift exceeds `max_gain_shift_db` or
//! worst phase shift exceeds `max_phase_shift_deg` are flagged and consecutive flagged bins are
//! merged into bands. Separately, bins inside the coherence window
//! [f_c/`coherence_band_factor`, f_c·`coherence_band_factor`] where any run's magnitude-squared
//! coherence is below `min_coherence` are reported as coherence drops. Any flagged band or
//! coherence drop makes the verdict [`Verdict::NotLinear`]; shifts are counted at every bin
//! (low-coherence bins included), and each band carries its minimum coherence so a reader can
//! tell noise from nonlinearity.
//!
//! Runs must share the same frequency grid (same Welch settings); amplitudes are only labels.
use crate::error::{Error, Result};
use num_complex::Complex64;
use serde::{Deserialize, Serialize};

/// One measured frequency response (e.g. an ETFE) at one excitation amplitude.
#[derive(Debug, Clone, PartialEq)]
pub struct FrfRun {
    /// Label used in the evidence (e.g. file name or "0.5 A").
    pub label: String,
    /// Excitation amplitude (plant input units), for ordering and reporting.
    pub amplitude: f64,
    /// Bin frequencies, Hz, strictly increasing.
    pub freq_hz: Vec<f64>,
    /// Frequency response H(f) at each bin (output units per input unit).
    pub h: Vec<Complex64>,
    /// Magnitude-squared coherence at each bin, in [0, 1].
    pub coherence: Vec<f64>,
}

impl FrfRun {
    /// A run from a Welch H1 estimate ([`crate::spectral::Etfe`]); bins where H is NaN (no
    /// input power) are kept and skipped by the audit.
    pub fn from_etfe(label: &str, amplitude: f64, etfe: &crate::spectral::Etfe) -> Self {
        Self {
            label: label.into(),
            amplitude,
            freq_hz: etfe.freq_hz.clone(),
            h: etfe.h.clone(),
            coherence: etfe.coherence.clone(),
        }
    }
    /// A run from a period-synchronous estimate ([`crate::spectral::PeriodicFrf`], excited
    /// lines only; runs must use the same excitation so the lines agree).
    pub fn from_periodic(label: &str, amplitude: f64, frf: &crate::spectral::PeriodicFrf) -> Self {
        Self {
            label: label.into(),
            amplitude,
            freq_hz: frf.freq_hz.clone(),
            h: frf.h.clone(),
            coherence: frf.coherence.clone(),
        }
    }
}

/// Thresholds of [`audit_nonlinearity`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AuditOptions {
    /// Intended crossover frequency f_c, Hz.
    pub crossover_hz: f64,
    /// Audit band half-width as a factor: [f_c/k, f_c·k] (default 10, a decade each side).
    pub band_factor: f64,
    /// Largest tolerated gain shift between runs, dB (default 3).
    pub max_gain_shift_db: f64,
    /// Largest tolerated phase shift between runs, degrees (default 15).
    pub max_phase_shift_deg: f64,
    /// Smallest tolerated coherence near crossover (default 0.6).
    pub min_coherence: f64,
    /// Coherence window half-width as a factor: [f_c/k, f_c·k] (default 3).
    pub coherence_band_factor: f64,
}

impl AuditOptions {
    /// Defaults (a decade each side, 3 dB, 15°, coherence 0.6 within a factor 3) around
    /// `crossover_hz`.
    pub fn new(crossover_hz: f64) -> Self {
        Self {
            crossover_hz,
            band_factor: 10.0,
            max_gain_shift_db: 3.0,
            max_phase_shift_deg: 15.0,
            min_coherence: 0.6,
            coherence_band_factor: 3.0,
        }
    }
}

/// Verdict of the audit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// No flagged band and no coherence drop near crossover.
    LinearEnough,
    /// At least one flagged band or coherence drop (see the evidence).
    NotLinear,
}

/// A worst-case shift and where it occurred.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WorstShift {
    /// Signed shift of `run_b` relative to `run_a` (dB for gain, degrees for phase).
    pub value: f64,
    /// Bin frequency, Hz.
    pub f_hz: f64,
    /// Reference run label.
    pub run_a: String,
    /// Compared run label.
    pub run_b: String,
}

/// A band of consecutive bins whose gain or phase shift exceeds the thresholds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShiftBand {
    /// Lowest bin frequency in the band, Hz.
    pub f_lo_hz: f64,
    /// Highest bin frequency in the band, Hz.
    pub f_hi_hz: f64,
    /// Number of bins.
    pub bins: usize,
    /// Largest absolute gain shift in the band (signed), dB, with its location and runs.
    pub worst_gain_shift_db: WorstShift,
    /// Largest absolute phase shift in the band (signed), degrees.
    pub worst_phase_shift_deg: WorstShift,
    /// Smallest coherence of any run in the band.
    pub min_coherence: f64,
}

/// A band of consecutive bins near crossover where some run's coherence is low.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CoherenceDrop {
    /// Lowest bin frequency, Hz.
    pub f_lo_hz: f64,
    /// Highest bin frequency, Hz.
    pub f_hi_hz: f64,
    /// Number of bins.
    pub bins: usize,
    /// Smallest coherence in the band.
    pub min_coherence: f64,
    /// Where it occurs, Hz.
    pub at_hz: f64,
    /// The run with that coherence.
    pub run: String,
}

/// Per-bin evidence inside the audit band (for plots).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AuditBin {
    /// Bin frequency, Hz.
    pub f_hz: f64,
    /// Worst signed gain shift over run pairs, dB.
    pub gain_shift_db: f64,
    /// Worst signed phase shift over run pairs, degrees.
    pub phase_shift_deg: f64,
    /// Smallest coherence over runs.
    pub min_coherence: f64,
    /// True when the shift thresholds are exceeded here.
    pub flagged: bool,
}

/// The audit result: verdict plus evidence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NonlinearityAudit {
    /// LinearEnough or NotLinear.
    pub verdict: Verdict,
    /// Human-readable reasons for the verdict (empty when linear enough).
    pub reasons: Vec<String>,
    /// Thresholds used.
    pub options: AuditOptions,
    /// Audit band actually examined, Hz (lo, hi).
    pub band_hz: (f64, f64),
    /// Run labels and amplitudes, in input order.
    pub runs: Vec<(String, f64)>,
    /// Number of bins inside the audit band that were compared.
    pub bins_examined: usize,
    /// Bins inside the band skipped because some run's response is not finite there.
    pub bins_skipped: usize,
    /// Flagged shift bands.
    pub shift_bands: Vec<ShiftBand>,
    /// Coherence drops near crossover.
    pub coherence_drops: Vec<CoherenceDrop>,
    /// Largest gain shift anywhere in the band (even when within limits).
    pub worst_gain_shift_db: WorstShift,
    /// Largest phase shift anywhere in the band.
    pub worst_phase_shift_deg: WorstShift,
    /// Per-bin evidence inside the band.
    pub bins: Vec<AuditBin>,
}

fn check_options(o: &AuditOptions) -> Result<()> {
    let pos = |name: &str, v: f64| -> Result<()> {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(Error::InvalidArgument(format!(
                "nonlinearity audit: {name} = {v} must be finite and > 0"
            )))
        }
    };
    pos("crossover_hz", o.crossover_hz)?;
    pos("max_gain_shift_db", o.max_gain_shift_db)?;
    pos("max_phase_shift_deg", o.max_phase_shift_deg)?;
    if !(o.band_factor.is_finite() && o.band_factor > 1.0) {
        return Err(Error::InvalidArgument(format!(
            "nonlinearity audit: band_factor = {} must be > 1",
            o.band_factor
        )));
    }
    if !(o.coherence_band_factor.is_finite() && o.coherence_band_factor >= 1.0) {
        return Err(Error::InvalidArgument(format!(
            "nonlinearity audit: coherence_band_factor = {} must be >= 1",
            o.coherence_band_factor
        )));
    }
    if !(0.0..=1.0).contains(&o.min_coherence) {
        return Err(Error::InvalidArgument(format!(
            "nonlinearity audit: min_coherence = {} must lie in [0, 1]",
            o.min_coherence
        )));
    }
    Ok(())
}

fn check_runs(runs: &[FrfRun]) -> Result<()> {
    if runs.len() < 2 {
        return Err(Error::InvalidArgument(format!(
            "nonlinearity audit needs at least 2 runs at different amplitudes, got {}",
            runs.len()
        )));
    }
    let f0 = &runs[0].freq_hz;
    for r in runs {
        let n = r.freq_hz.len();
        if r.h.len() != n || r.coherence.len() != n {
            return Err(Error::InvalidArgument(format!(
                "run `{}`: {} frequencies, {} responses and {} coherence values (must agree)",
                r.label,
                n,
                r.h.len(),
                r.coherence.len()
            )));
        }
        if n != f0.len()
            || r.freq_hz
                .iter()
                .zip(f0)
                .any(|(a, b)| (a - b).abs() > 1e-9 * a.abs().max(b.abs()))
        {
            return Err(Error::InvalidArgument(format!(
                "run `{}` has a different frequency grid from run `{}` (use the same Welch \
                 settings for every amplitude)",
                r.label, runs[0].label
            )));
        }
        for i in 0..n {
            let f = r.freq_hz[i];
            if !f.is_finite()
                || (i > 0 && f.partial_cmp(&r.freq_hz[i - 1]) != Some(std::cmp::Ordering::Greater))
            {
                return Err(Error::InvalidArgument(format!(
                    "run `{}`: frequency bin {i} = {f} Hz is not finite or not increasing",
                    r.label
                )));
            }
            let c = r.coherence[i];
            if !(c.is_finite() && (-1e-9..=1.0 + 1e-9).contains(&c)) {
                return Err(Error::InvalidArgument(format!(
                    "run `{}`: coherence at bin {i} ({f} Hz) = {c} is outside [0, 1]",
                    r.label
                )));
            }
        }
    }
    Ok(())
}

/// Runs the audit (see the module docs). Bins where some run's response is not finite (NaN
/// marks bins without input power in [`crate::spectral::Etfe`]) are skipped and counted in
/// `bins_skipped`. Errors: fewer than two runs, mismatched grids or lengths, non-finite
/// frequencies, coherence outside [0, 1], a zero response inside the band, no usable bin inside
/// the band, or invalid options.
pub fn audit_nonlinearity(runs: &[FrfRun], opts: &AuditOptions) -> Result<NonlinearityAudit> {
    check_options(opts)?;
    check_runs(runs)?;
    let fc = opts.crossover_hz;
    let (lo, hi) = (fc / opts.band_factor, fc * opts.band_factor);
    let (idx, bins_skipped) = usable_bins(runs, lo, hi)?;
    let (bins, worst_pairs) = worst_shift_per_bin(runs, &idx, opts);
    let shift_bands = merge_flagged_bins(&bins, &worst_pairs);
    let coherence_drops = coherence_drops(runs, opts);
    let worst = |pick: fn(&(WorstShift, WorstShift)) -> &WorstShift| {
        worst_pairs
            .iter()
            .map(pick)
            .max_by(|a, b| a.value.abs().total_cmp(&b.value.abs()))
            .cloned()
            .ok_or_else(|| Error::Numerical("nonlinearity audit: no bins".into()))
    };
    let wg = worst(|p| &p.0)?;
    let wp = worst(|p| &p.1)?;
    let reasons = reasons(&shift_bands, &coherence_drops, opts);
    Ok(NonlinearityAudit {
        verdict: if reasons.is_empty() {
            Verdict::LinearEnough
        } else {
            Verdict::NotLinear
        },
        reasons,
        options: *opts,
        band_hz: (lo, hi),
        runs: runs
            .iter()
            .map(|r| (r.label.clone(), r.amplitude))
            .collect(),
        bins_examined: idx.len(),
        bins_skipped,
        shift_bands,
        coherence_drops,
        worst_gain_shift_db: wg,
        worst_phase_shift_deg: wp,
        bins,
    })
}

/// The bins inside the audit band [`lo`, `hi`] Hz where every run has a finite response, and
/// how many in-band bins were skipped for lack of one (e.g. NaN where the input had no power).
/// Errors when none is left or a run's response is exactly zero at one of them.
fn usable_bins(runs: &[FrfRun], lo: f64, hi: f64) -> Result<(Vec<usize>, usize)> {
    let freq = &runs[0].freq_hz;
    let in_band: Vec<usize> = (0..freq.len())
        .filter(|&i| freq[i] >= lo && freq[i] <= hi)
        .collect();
    let finite = |i: usize| {
        runs.iter()
            .all(|r| r.h[i].re.is_finite() && r.h[i].im.is_finite())
    };
    let idx: Vec<usize> = in_band.iter().copied().filter(|&i| finite(i)).collect();
    let bins_skipped = in_band.len() - idx.len();
    if idx.is_empty() {
        return Err(Error::InvalidArgument(format!(
            "nonlinearity audit: no usable frequency bin inside the audit band {lo:.4}..{hi:.4} \
             Hz (measured {:.4}..{:.4} Hz, {bins_skipped} bins without a finite response)",
            freq.first().copied().unwrap_or(f64::NAN),
            freq.last().copied().unwrap_or(f64::NAN)
        )));
    }
    for r in runs {
        for &i in &idx {
            if r.h[i].norm() == 0.0 {
                return Err(Error::InvalidArgument(format!(
                    "run `{}`: response is exactly zero at {} Hz inside the audit band",
                    r.label, freq[i]
                )));
            }
        }
    }
    Ok((idx, bins_skipped))
}

/// At each bin of `idx`, the pair of runs with the largest gain shift and the pair with the
/// largest phase shift; the bin is flagged when either exceeds its threshold.
fn worst_shift_per_bin(
    runs: &[FrfRun],
    idx: &[usize],
    opts: &AuditOptions,
) -> (Vec<AuditBin>, Vec<(WorstShift, WorstShift)>) {
    let freq = &runs[0].freq_hz;
    let mut bins = Vec::with_capacity(idx.len());
    let mut worst_pairs: Vec<(WorstShift, WorstShift)> = Vec::with_capacity(idx.len());
    for &i in idx {
        let mut wg = WorstShift {
            value: 0.0,
            f_hz: freq[i],
            run_a: runs[0].label.clone(),
            run_b: runs[1].label.clone(),
        };
        let mut wp = wg.clone();
        for a in 0..runs.len() {
            for b in (a + 1)..runs.len() {
                let ratio = runs[b].h[i] / runs[a].h[i];
                let g = 20.0 * ratio.norm().log10();
                let p = ratio.arg().to_degrees();
                if g.abs() > wg.value.abs() {
                    wg.value = g;
                    wg.run_a = runs[a].label.clone();
                    wg.run_b = runs[b].label.clone();
                }
                if p.abs() > wp.value.abs() {
                    wp.value = p;
                    wp.run_a = runs[a].label.clone();
                    wp.run_b = runs[b].label.clone();
                }
            }
        }
        let cmin = runs
            .iter()
            .map(|r| r.coherence[i])
            .fold(f64::INFINITY, f64::min);
        let flagged =
            wg.value.abs() > opts.max_gain_shift_db || wp.value.abs() > opts.max_phase_shift_deg;
        bins.push(AuditBin {
            f_hz: freq[i],
            gain_shift_db: wg.value,
            phase_shift_deg: wp.value,
            min_coherence: cmin,
            flagged,
        });
        worst_pairs.push((wg, wp));
    }
    (bins, worst_pairs)
}

/// Consecutive flagged bins merged into bands, each with its worst shifts and least coherence.
fn merge_flagged_bins(
    bins: &[AuditBin],
    worst_pairs: &[(WorstShift, WorstShift)],
) -> Vec<ShiftBand> {
    let mut shift_bands: Vec<ShiftBand> = Vec::new();
    let mut k = 0;
    while k < bins.len() {
        if !bins[k].flagged {
            k += 1;
            continue;
        }
        let start = k;
        while k < bins.len() && bins[k].flagged {
            k += 1;
        }
        let range = start..k;
        let pick = |key: &dyn Fn(usize) -> f64| -> usize {
            range
                .clone()
                .max_by(|&x, &y| key(x).abs().total_cmp(&key(y).abs()))
                .unwrap_or(start)
        };
        let ig = pick(&|j| worst_pairs[j].0.value);
        let ip = pick(&|j| worst_pairs[j].1.value);
        shift_bands.push(ShiftBand {
            f_lo_hz: bins[start].f_hz,
            f_hi_hz: bins[k - 1].f_hz,
            bins: k - start,
            worst_gain_shift_db: worst_pairs[ig].0.clone(),
            worst_phase_shift_deg: worst_pairs[ip].1.clone(),
            min_coherence: bins[range.clone()]
                .iter()
                .map(|b| b.min_coherence)
                .fold(f64::INFINITY, f64::min),
        });
    }
    shift_bands
}

/// Runs of consecutive bins inside the coherence window where some run's coherence is below
/// `min_coherence`, each with its lowest value, where and in which run.
fn coherence_drops(runs: &[FrfRun], opts: &AuditOptions) -> Vec<CoherenceDrop> {
    let fc = opts.crossover_hz;
    let (clo, chi) = (
        fc / opts.coherence_band_factor,
        fc * opts.coherence_band_factor,
    );
    let freq = &runs[0].freq_hz;
    let mut coherence_drops: Vec<CoherenceDrop> = Vec::new();
    let low: Vec<bool> = (0..freq.len())
        .map(|i| {
            freq[i] >= clo
                && freq[i] <= chi
                && runs.iter().any(|r| r.coherence[i] < opts.min_coherence)
        })
        .collect();
    let mut i = 0;
    while i < low.len() {
        if !low[i] {
            i += 1;
            continue;
        }
        let start = i;
        while i < low.len() && low[i] {
            i += 1;
        }
        let mut best = (f64::INFINITY, start, 0usize);
        for j in start..i {
            for (ri, r) in runs.iter().enumerate() {
                if r.coherence[j] < best.0 {
                    best = (r.coherence[j], j, ri);
                }
            }
        }
        coherence_drops.push(CoherenceDrop {
            f_lo_hz: freq[start],
            f_hi_hz: freq[i - 1],
            bins: i - start,
            min_coherence: best.0,
            at_hz: freq[best.1],
            run: runs[best.2].label.clone(),
        });
    }
    coherence_drops
}

/// One sentence per flagged band and per coherence drop (empty: linear enough).
fn reasons(
    shift_bands: &[ShiftBand],
    coherence_drops: &[CoherenceDrop],
    opts: &AuditOptions,
) -> Vec<String> {
    let mut reasons = Vec::new();
    for b in shift_bands {
        reasons.push(format!(
            "{:.4}–{:.4} Hz ({} bins): gain shift {:+.2} dB at {:.4} Hz ({} vs {}), phase shift \
             {:+.1}° at {:.4} Hz ({} vs {}); limits {} dB / {}°",
            b.f_lo_hz,
            b.f_hi_hz,
            b.bins,
            b.worst_gain_shift_db.value,
            b.worst_gain_shift_db.f_hz,
            b.worst_gain_shift_db.run_b,
            b.worst_gain_shift_db.run_a,
            b.worst_phase_shift_deg.value,
            b.worst_phase_shift_deg.f_hz,
            b.worst_phase_shift_deg.run_b,
            b.worst_phase_shift_deg.run_a,
            opts.max_gain_shift_db,
            opts.max_phase_shift_deg
        ));
    }
    for d in coherence_drops {
        reasons.push(format!(
            "coherence {:.3} < {} at {:.4} Hz (run {}) in {:.4}–{:.4} Hz near crossover",
            d.min_coherence, opts.min_coherence, d.at_hz, d.run, d.f_lo_hz, d.f_hi_hz
        ));
    }
    reasons
}
