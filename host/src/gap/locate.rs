//! WHERE the nominal sim and the plant disagree, from the training logs.
//!
//! * **Multiplicative error** e(f) = |(G_meas(f) − G_sim(f)) / G_sim(f)| at every frequency bin,
//!   with G_meas the Welch H1 estimate pooled over all training logs (cross- and auto-spectra
//!   summed over logs) and G_sim the nominal model's response at the same frequencies. Only bins
//!   that pass the project's gate ([`Etfe::gate`]: magnitude-squared coherence at least
//!   `coherence_min` and an excited input) are used.
//! * **Ranked bands** (`bands`): the nominal sim's residual on the training logs, pooled Welch
//!   PSD on the bins where the input has power, grouped into bands around its peaks and ranked
//!   by their share of that power ([`ranked_bands`]); **time regions** likewise over windows of
//!   each log ([`ranked_time_regions`]).
//! * **Bands** (`bands_hz`): runs of used bins where the input has power (PSD within
//!   [`EXCITED_REL`] of its peak) with e > `threshold`, runs two bins apart merged.
//! * **Worst** (`worst_hz`, `worst_error`): the used, powered bin with the largest e; the
//!   **worst band** is the run of such bins around it where e stays above half that peak.
//! * **Coherence drops** (`coherence_drops_hz`): runs of bins (DC excluded) rejected by that
//!   gate (low coherence or no input power); runs separated by at most two bins are merged.
//! * **Amplitude dependence** (`amplitude_dependent`, `amplitude_change`): filled in from
//!   [`crate::gap::evidence::amplitude_evidence`] by the diagnosis.
//! * **Residual regions**: the free-run residual of the linear re-fit on the training logs,
//!   RMS inside a region divided by its overall RMS. Regions: `near_zero_output` and
//!   `near_zero_output_rate` (the 20 % of samples where |ŷ − median ŷ| resp. |Δŷ| of the
//!   re-fit's output is smallest: near zero velocity for velocity resp. position outputs),
//!   `input_extremes` (the 10 % of samples with the largest |u|) and `near_zero_input` (the
//!   20 % with the smallest |u|). A ratio >= 1.3 is flagged as a concentration.
use super::diagnose::GapOptions;
use super::report::BandError;
use crate::error::{Error, Result};
use crate::lti::StateSpace;
use crate::spectral::{Etfe, Welch};
use serde::Serialize;
use std::path::PathBuf;

/// Residual RMS ratio at or above which a region is flagged.
pub const CONCENTRATION_RATIO: f64 = 1.3;

/// One time-domain region of the residual.
#[derive(Debug, Clone, Serialize)]
pub struct Region {
    /// Region name (see the module docs).
    pub region: String,
    /// RMS of the residual inside the region / overall RMS.
    pub rms_ratio: f64,
    /// Whether `rms_ratio >= CONCENTRATION_RATIO`.
    pub concentrates: bool,
}

/// Input PSD within this fraction of its peak (−20 dB) counts as "the input has power here".
pub use super::evidence::EXCITED_REL;

/// At most this many ranked bands / time regions are reported.
pub const MAX_RANKED: usize = 5;

/// A band whose share of the residual power is below this is not reported.
pub const MIN_BAND_SHARE: f64 = 0.02;

/// A band grows from its peak bin while the residual PSD stays above this fraction of the peak
/// (−10 dB).
pub const BAND_EDGE_REL: f64 = 0.1;

/// Time windows per log for the ranked time regions.
pub const TIME_WINDOWS: usize = 16;

/// One frequency band of the residual, with its share of the residual power.
#[derive(Debug, Clone, Serialize)]
pub struct BandShare {
    /// Lower edge, Hz.
    pub lo_hz: f64,
    /// Upper edge, Hz.
    pub hi_hz: f64,
    /// Frequency of the band's peak residual density, Hz.
    pub peak_hz: f64,
    /// Share of the residual power on the bins where the input has power.
    pub share: f64,
}

/// One time window of a log, with its share of the residual energy over all training logs.
#[derive(Debug, Clone, Serialize)]
pub struct TimeShare {
    /// The log (file name as given).
    pub log: String,
    /// Window start, s from the log's first sample.
    pub t_start_s: f64,
    /// Window end, s.
    pub t_end_s: f64,
    /// Share of the residual energy (a uniform residual gives 1/(windows·logs)).
    pub share: f64,
}

/// Bands of the residual PSD `srr` over the bins where the input has power (`powered`), ranked
/// by their share of that power: repeatedly the highest unassigned bin, grown over neighbouring
/// powered bins while the density stays above [`BAND_EDGE_REL`] of that peak; at most
/// [`MAX_RANKED`] bands of share >= [`MIN_BAND_SHARE`]. Returns the bands and the share of the
/// residual power (all bins above DC) that lies where the input has no power.
pub fn ranked_bands(freq: &[f64], srr: &[f64], powered: &[bool]) -> (Vec<BandShare>, f64) {
    let n = freq.len().min(srr.len()).min(powered.len());
    if n < 2 {
        return (Vec::new(), f64::NAN);
    }
    let df = freq[1] - freq[0];
    let ok = |k: usize| k >= 1 && powered[k] && srr[k].is_finite();
    let total: f64 = (1..n).filter(|&k| ok(k)).map(|k| srr[k]).sum();
    let all: f64 = (1..n).filter(|&k| srr[k].is_finite()).map(|k| srr[k]).sum();
    let outside = if all > 0.0 {
        1.0 - total / all
    } else {
        f64::NAN
    };
    if total.is_nan() || total <= 0.0 {
        return (Vec::new(), outside);
    }
    let mut taken = vec![false; n];
    let mut out = Vec::new();
    while out.len() < MAX_RANKED {
        let Some(k) = (1..n)
            .filter(|&k| ok(k) && !taken[k])
            .max_by(|&a, &b| srr[a].total_cmp(&srr[b]))
        else {
            break;
        };
        let edge = BAND_EDGE_REL * srr[k];
        let (mut a, mut b) = (k, k);
        while a > 1 && ok(a - 1) && !taken[a - 1] && srr[a - 1] >= edge {
            a -= 1;
        }
        while b + 1 < n && ok(b + 1) && !taken[b + 1] && srr[b + 1] >= edge {
            b += 1;
        }
        let p: f64 = (a..=b).map(|i| srr[i]).sum();
        for t in taken.iter_mut().take(b + 1).skip(a) {
            *t = true;
        }
        let share = p / total;
        if share < MIN_BAND_SHARE {
            break;
        }
        out.push(BandShare {
            lo_hz: (freq[a] - 0.5 * df).max(0.0),
            hi_hz: freq[b] + 0.5 * df,
            peak_hz: freq[k],
            share,
        });
    }
    (out, outside)
}

/// The [`TIME_WINDOWS`] windows of every log after `warmup` ranked by their share of the
/// residual energy over all logs; the top [`MAX_RANKED`].
pub fn ranked_time_regions(
    resid: &[Vec<f64>],
    paths: &[PathBuf],
    warmup: usize,
    ts: f64,
) -> Vec<TimeShare> {
    let total: f64 = resid
        .iter()
        .map(|r| r.iter().skip(warmup).map(|v| v * v).sum::<f64>())
        .sum();
    if total.is_nan() || total <= 0.0 {
        return Vec::new();
    }
    let mut all = Vec::new();
    for (l, r) in resid.iter().enumerate() {
        let n = r.len().saturating_sub(warmup);
        if n < TIME_WINDOWS {
            continue;
        }
        for w in 0..TIME_WINDOWS {
            let (a, b) = (
                warmup + w * n / TIME_WINDOWS,
                warmup + (w + 1) * n / TIME_WINDOWS,
            );
            let e: f64 = r[a..b].iter().map(|v| v * v).sum();
            all.push(TimeShare {
                log: paths
                    .get(l)
                    .map_or_else(|| format!("log {l}"), |p| p.display().to_string()),
                t_start_s: a as f64 * ts,
                t_end_s: b as f64 * ts,
                share: e / total,
            });
        }
    }
    all.sort_by(|a, b| b.share.total_cmp(&a.share));
    all.truncate(MAX_RANKED);
    all
}

/// The "where" part of the report (see the module docs for each field's definition).
#[derive(Debug, Clone, Serialize)]
pub struct Where {
    /// Frequency bands ranked by their share of the nominal sim's residual power on the
    /// training logs (bins where the input has power only); see [`ranked_bands`].
    pub bands: Vec<BandShare>,
    /// Share of that residual power where the input has no power (not in `bands`).
    pub residual_share_outside_input_band: f64,
    /// Time windows ranked by their share of the nominal sim's residual energy.
    pub time_regions: Vec<TimeShare>,
    /// Bands (Hz) where the multiplicative error exceeds the threshold.
    pub bands_hz: Vec<[f64; 2]>,
    /// Frequency of the largest multiplicative error, Hz (null when no bin is usable).
    pub worst_hz: f64,
    /// The largest multiplicative error (ratio, not %).
    pub worst_error: f64,
    /// Band around the worst frequency, Hz.
    pub worst_band_hz: [f64; 2],
    /// Bands (Hz) of coherence below the gate.
    pub coherence_drops_hz: Vec<[f64; 2]>,
    /// Whether low- and high-amplitude responses differ beyond the tolerance.
    pub amplitude_dependent: bool,
    /// Median relative difference of the low- and high-amplitude responses (null with a single
    /// training log).
    pub amplitude_change: f64,
    /// Residual concentration of the linear re-fit.
    pub residual_regions: Vec<Region>,
    /// Welch segment length used.
    pub nperseg: usize,
    /// Bin frequencies, Hz (for figures).
    #[serde(skip)]
    pub freq_hz: Vec<f64>,
    /// Multiplicative error per bin (NaN where not gated).
    #[serde(skip)]
    pub mult_error: Vec<f64>,
    /// Pooled coherence per bin.
    #[serde(skip)]
    pub coherence: Vec<f64>,
}

/// Pooled Welch H1 estimate (Hann, 50 % overlap, constant detrend: [`crate::spectral`]) over
/// the given records.
fn pooled_etfe(records: &[(&[f64], &[f64])], nperseg: usize, ts: f64) -> Result<Etfe> {
    let mut acc = Welch::new(nperseg).accumulator(1.0 / ts)?;
    for (u, y) in records {
        acc.add(u, y)?;
    }
    acc.finish()
}

/// Default Welch segment: the largest power of two <= n/8, clamped to 64..=4096.
pub fn default_nperseg(n: usize) -> usize {
    let mut p = 64;
    while p * 2 <= n / 8 && p < 4096 {
        p *= 2;
    }
    p
}

/// Runs of indices where `pred` holds, as (first, last) inclusive; runs separated by at most
/// `merge_gap` failing indices are merged.
fn runs(n: usize, pred: impl Fn(usize) -> bool, merge_gap: usize) -> Vec<(usize, usize)> {
    let mut out: Vec<(usize, usize)> = Vec::new();
    let mut k = 0;
    while k < n {
        if pred(k) {
            let s = k;
            while k + 1 < n && pred(k + 1) {
                k += 1;
            }
            match out.last_mut() {
                Some(last) if s - last.1 - 1 <= merge_gap => last.1 = k,
                _ => out.push((s, k)),
            }
        }
        k += 1;
    }
    out
}

fn quantile_threshold(v: &[f64], q: f64) -> f64 {
    let mut s: Vec<f64> = v.to_vec();
    s.sort_by(f64::total_cmp);
    if s.is_empty() {
        return f64::NAN;
    }
    s[((q * (s.len() - 1) as f64).round() as usize).min(s.len() - 1)]
}

/// RMS of the linear re-fit's residual (pooled training samples after the warm-up) in four
/// regions relative to its overall RMS: output near its median, output rate near zero (the
/// lowest 20 % of each), input at its extremes (top 10 % of |u|) and near zero (lowest 20 %).
fn residual_regions(
    u: &[Vec<f64>],
    y_lin: &[Vec<f64>],
    resid_lin: &[Vec<f64>],
    warmup: usize,
) -> Vec<Region> {
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    // Residual regions on the pooled training samples after the warm-up.
    let mut r_all = Vec::new();
    let mut yabs = Vec::new();
    let mut yrate = Vec::new();
    let mut uabs = Vec::new();
    for l in 0..u.len() {
        let yl = &y_lin[l];
        let mut s: Vec<f64> = yl[warmup..].to_vec();
        s.sort_by(f64::total_cmp);
        let med = s[s.len() / 2];
        for k in warmup.max(1)..u[l].len() {
            r_all.push(resid_lin[l][k]);
            yabs.push((yl[k] - med).abs());
            yrate.push((yl[k] - yl[k - 1]).abs());
            uabs.push(u[l][k].abs());
        }
    }
    let total_rms = rms(&r_all);
    let region = |name: &str, sel: &dyn Fn(usize) -> bool| -> Region {
        let v: Vec<f64> = (0..r_all.len())
            .filter(|&i| sel(i))
            .map(|i| r_all[i])
            .collect();
        let ratio = if v.is_empty() || total_rms == 0.0 {
            f64::NAN
        } else {
            rms(&v) / total_rms
        };
        Region {
            region: name.into(),
            rms_ratio: ratio,
            concentrates: ratio >= CONCENTRATION_RATIO,
        }
    };
    let t_y = quantile_threshold(&yabs, 0.2);
    let t_r = quantile_threshold(&yrate, 0.2);
    let t_ux = quantile_threshold(&uabs, 0.9);
    let t_u0 = quantile_threshold(&uabs, 0.2);
    vec![
        region("near_zero_output", &|i| yabs[i] <= t_y),
        region("near_zero_output_rate", &|i| yrate[i] <= t_r),
        region("input_extremes", &|i| uabs[i] >= t_ux),
        region("near_zero_input", &|i| uabs[i] <= t_u0),
    ]
}

/// Computes the "where" analysis (module docs). `y_lin` and `resid_lin` are the linear
/// re-fit's output and residual on each training log; `paths` name the logs in errors.
#[allow(clippy::too_many_arguments)]
pub fn locate(
    sim: &StateSpace,
    u: &[Vec<f64>],
    y: &[Vec<f64>],
    y_lin: &[Vec<f64>],
    resid_lin: &[Vec<f64>],
    resid_nom: &[Vec<f64>],
    warmup: usize,
    ts: f64,
    opts: &GapOptions,
    paths: &[PathBuf],
) -> Result<Where> {
    let shortest = u.iter().map(|v| v.len() - warmup).min().unwrap_or(0);
    let nperseg = opts.nperseg.unwrap_or_else(|| default_nperseg(shortest));
    if nperseg < 8 || nperseg > shortest {
        return Err(Error::Data {
            file: paths.first().cloned().unwrap_or_default(),
            msg: format!(
                "Welch segment of {nperseg} samples does not fit the shortest training log \
                 ({shortest} samples after the warm-up)"
            ),
        });
    }
    let recs: Vec<(&[f64], &[f64])> = u
        .iter()
        .zip(y)
        .map(|(u, y)| (&u[warmup..], &y[warmup..]))
        .collect();
    let pooled = pooled_etfe(&recs, nperseg, ts)?;
    let freq = pooled.freq_hz.clone();
    let g_meas = &pooled.h;
    let coh = pooled.coherence.clone();
    let gate = pooled.gate(opts.coherence_min);
    let g_sim = sim.freq_responses_siso_hz(&freq[1..])?;
    let mut mult = vec![f64::NAN; freq.len()];
    for k in 1..freq.len() {
        let gs = g_sim[k - 1];
        if gate[k] && gs.norm() > 0.0 && g_meas[k].re.is_finite() {
            mult[k] = ((g_meas[k] - gs) / gs).norm();
        }
    }
    let used = |k: usize| mult[k].is_finite();
    let to_hz = |r: &[(usize, usize)]| -> Vec<[f64; 2]> {
        r.iter().map(|&(a, b)| [freq[a], freq[b]]).collect()
    };
    // Where the input has power (pooled input PSD within EXCITED_REL of its peak).
    let top_uu = pooled.suu.iter().cloned().fold(0.0, f64::max);
    let powered: Vec<bool> = pooled
        .suu
        .iter()
        .map(|&p| top_uu > 0.0 && p >= EXCITED_REL * top_uu)
        .collect();
    let bands_hz = to_hz(&runs(
        freq.len(),
        |k| used(k) && powered[k] && mult[k] > opts.threshold,
        2,
    ));
    let worst = (1..freq.len())
        .filter(|&k| used(k) && powered[k])
        .max_by(|&a, &b| mult[a].total_cmp(&mult[b]));
    let (worst_hz, worst_error, worst_band_hz) = match worst {
        Some(k) => {
            let half = 0.5 * mult[k];
            let (mut a, mut b) = (k, k);
            while a > 1 && used(a - 1) && powered[a - 1] && mult[a - 1] > half {
                a -= 1;
            }
            while b + 1 < freq.len() && used(b + 1) && powered[b + 1] && mult[b + 1] > half {
                b += 1;
            }
            (freq[k], mult[k], [freq[a], freq[b]])
        }
        None => (f64::NAN, f64::NAN, [freq[1], freq[freq.len() - 1]]),
    };
    // Coherence drops (and unexcited bins) above DC; runs separated by at most two bins merged.
    let mut coherence_drops_hz: Vec<[f64; 2]> = Vec::new();
    for b in pooled
        .excluded_bands(opts.coherence_min)
        .into_iter()
        .filter(|b| b.f_hi_hz > 0.0)
    {
        match coherence_drops_hz.last_mut() {
            Some(last) if b.f_lo_hz - last[1] <= 3.0 * (freq[1] - freq[0]) * (1.0 + 1e-9) => {
                last[1] = b.f_hi_hz
            }
            _ => coherence_drops_hz.push([b.f_lo_hz, b.f_hi_hz]),
        }
    }

    let residual_regions = residual_regions(u, y_lin, resid_lin, warmup);
    // Ranked bands and time regions of the nominal sim's residual.
    let mut acc = Welch::new(nperseg).accumulator(1.0 / ts)?;
    for (ul, rl) in u.iter().zip(resid_nom) {
        acc.add(&ul[warmup..], &rl[warmup..])?;
    }
    let rspec = acc.finish()?;
    let (bands, residual_share_outside_input_band) = ranked_bands(&freq, &rspec.syy, &powered);
    let time_regions = ranked_time_regions(resid_nom, paths, warmup, ts);
    Ok(Where {
        bands,
        residual_share_outside_input_band,
        time_regions,
        bands_hz,
        worst_hz,
        worst_error,
        worst_band_hz,
        coherence_drops_hz,
        amplitude_dependent: false,
        amplitude_change: f64::NAN,
        residual_regions,
        nperseg,
        freq_hz: freq,
        mult_error: mult,
        coherence: coh,
    })
}

impl BandError {
    /// Band error of each model output in `yhat` (nominal, linear, verdict) against `y` on the
    /// samples after `warmup` (see [`BandError`]), from Welch PSDs ([`Welch::psd`]).
    pub fn compute(
        band_hz: [f64; 2],
        y: &[f64],
        yhat: &[&[f64]; 3],
        warmup: usize,
        ts: f64,
        nperseg: usize,
    ) -> Result<Self> {
        let y = &y[warmup..];
        let welch = Welch::new(nperseg.min(default_nperseg(y.len())).min(y.len()));
        let fs = 1.0 / ts;
        let syy = welch.psd(y, fs)?;
        let f = &syy.freq_hz;
        let mut inband: Vec<usize> = (0..f.len())
            .filter(|&k| f[k] >= band_hz[0] && f[k] <= band_hz[1])
            .collect();
        if inband.is_empty() {
            // A band narrower than one bin: use the nearest bin.
            let c = 0.5 * (band_hz[0] + band_hz[1]);
            let k = (0..f.len())
                .min_by(|&a, &b| (f[a] - c).abs().total_cmp(&(f[b] - c).abs()))
                .unwrap_or(0);
            inband.push(k);
        }
        let py: f64 = inband.iter().map(|&k| syy.density[k]).sum();
        let ratio = |yh: &[f64]| -> Result<f64> {
            let r: Vec<f64> = y.iter().zip(&yh[warmup..]).map(|(a, b)| a - b).collect();
            let s = welch.psd(&r, fs)?;
            let pr: f64 = inband.iter().map(|&k| s.density[k]).sum();
            Ok(if py > 0.0 { (pr / py).sqrt() } else { f64::NAN })
        };
        Ok(Self {
            band_hz,
            before: ratio(yhat[0])?,
            linear: ratio(yhat[1])?,
            after: ratio(yhat[2])?,
        })
    }
}
