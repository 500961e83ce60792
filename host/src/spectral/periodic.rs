//! Period-synchronous averaging for periodic excitation (see the [parent module](super)).
use num_complex::Complex64;
use realfft::RealFftPlanner;
use serde::Serialize;

use super::{
    bin_hz, check_fs, check_signal, coherence_gate, excluded_bands, fft, max_abs, pair,
    power_of_two_scale, ExcludedBand,
};
use crate::data::Log;
use crate::error::{Error, Result};
use crate::io::require_len;

// ---------------------------------------------------------------------------------------------

/// Period-synchronous averaging settings for periodic excitation.
///
/// The record is cut into consecutive periods of `period` samples starting at sample
/// `skip_periods * period` (earlier periods are treated as transient); samples after the last
/// complete period are ignored. Each period's DFT is taken with a rectangular window, scaled by
/// `1/period` (a cosine of amplitude A on line k gives `|X[k]| = A/2`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PeriodicAveraging {
    /// Samples per period (>= 2).
    pub period: usize,
    /// Leading periods discarded as transient.
    pub skip_periods: usize,
    /// Use at most this many periods after the skipped ones (`None`: all complete periods).
    pub max_periods: Option<usize>,
    /// Line detection: a line k >= 1 is excited when `|Ū[k]|^2 >= min_relative_power *
    /// max_k |Ū[k]|^2` (default 1e-6, i.e. -60 dB) ...
    pub min_relative_power: f64,
    /// ... and `|Ū[k]|^2 >= min_snr * var(Ū[k])` (default 10; the variance of the mean from the
    /// spread over periods, so noise-only lines of a noisy measured input are rejected).
    pub min_snr: f64,
    /// Explicit excited lines (DFT bin indices 1..=period/2) instead of detection.
    pub lines: Option<Vec<usize>>,
}

impl PeriodicAveraging {
    /// Defaults: no skipped period, all periods, detection at -60 dB and SNR 10.
    pub fn new(period: usize) -> Self {
        Self {
            period,
            skip_periods: 0,
            max_periods: None,
            min_relative_power: 1e-6,
            min_snr: 10.0,
            lines: None,
        }
    }
}

/// Per-bin statistics over periods, for all one-sided bins `0..=period/2`.
#[derive(Debug, Clone, PartialEq)]
pub struct PeriodSpectra {
    /// Bin frequencies in Hz (`k * fs / period`).
    pub freq_hz: Vec<f64>,
    /// Mean input DFT over periods (scaled by 1/period).
    pub u: Vec<Complex64>,
    /// Mean output DFT over periods (scaled by 1/period).
    pub y: Vec<Complex64>,
    /// Noise variance of the mean `u` (sample variance over periods / n_periods).
    pub var_u: Vec<f64>,
    /// Noise variance of the mean `y` (sample variance over periods / n_periods).
    pub var_y: Vec<f64>,
    /// Noise covariance of the means, `cov(Ȳ, Ū) = E[(Ȳ - E Ȳ) conj(Ū - E Ū)]`.
    pub cov_yu: Vec<Complex64>,
}

/// Frequency response at the excited lines from period-synchronous averaging.
#[derive(Debug, Clone, PartialEq)]
pub struct PeriodicFrf {
    /// Sample rate in Hz.
    pub fs: f64,
    /// Samples per period.
    pub period: usize,
    /// Periods averaged.
    pub n_periods: usize,
    /// Leading periods skipped as transient.
    pub skipped_periods: usize,
    /// Samples after the last complete period that were not used.
    pub unused_samples: usize,
    /// Excited lines (DFT bin indices into [`PeriodSpectra`]).
    pub lines: Vec<usize>,
    /// Frequencies of the excited lines in Hz.
    pub freq_hz: Vec<f64>,
    /// `H = Ȳ/Ū` at the excited lines.
    pub h: Vec<Complex64>,
    /// Noise variance of `H` (first-order propagation of the variances and covariance of the
    /// means: `|H|^2 (var_y/|Ȳ|^2 + var_u/|Ū|^2 - 2 Re(cov_yu / (Ȳ conj Ū)))`).
    pub var_h: Vec<f64>,
    /// Magnitude-squared coherence of the periods at each line (Welch with a rectangular window,
    /// one segment per period, no overlap): 1 for noise-free periodic data.
    pub coherence: Vec<f64>,
    /// Statistics of all bins (non-excited ones show noise and nonlinear distortion).
    pub spectra: PeriodSpectra,
}

impl PeriodicFrf {
    /// Lines usable for fitting/validation: `coherence >= threshold`.
    pub fn gate(&self, threshold: f64) -> Vec<bool> {
        coherence_gate(&self.coherence, threshold)
    }

    /// Runs of consecutive excited lines below the coherence threshold.
    pub fn excluded_bands(&self, threshold: f64) -> Vec<ExcludedBand> {
        excluded_bands(&self.freq_hz, &self.coherence, threshold)
    }
}

impl PeriodicAveraging {
    /// Period-synchronous FRF of `u` → `y` (equal lengths, finite) at `fs` Hz. Needs at least
    /// two periods after the skipped ones (the noise variance comes from their spread).
    ///
    /// The signals are normalised internally by exact powers of two ([`power_of_two_scale`])
    /// and the results scaled back, so the estimate does not depend on the signals' units.
    pub fn frf(&self, u: &[f64], y: &[f64], fs: f64) -> Result<PeriodicFrf> {
        let (gu, gy) = (
            power_of_two_scale(max_abs(u)),
            power_of_two_scale(max_abs(y)),
        );
        if gu == 1.0 && gy == 1.0 {
            return self.frf_unscaled(u, y, fs);
        }
        let us: Vec<f64> = u.iter().map(|v| v * gu).collect();
        let ys: Vec<f64> = y.iter().map(|v| v * gy).collect();
        let mut r = self.frf_unscaled(&us, &ys, fs)?;
        let gh = gu / gy;
        for h in &mut r.h {
            *h *= gh;
        }
        for v in &mut r.var_h {
            *v *= gh * gh;
        }
        let sp = &mut r.spectra;
        for z in &mut sp.u {
            *z /= gu;
        }
        for z in &mut sp.y {
            *z /= gy;
        }
        for v in &mut sp.var_u {
            *v = *v / gu / gu;
        }
        for v in &mut sp.var_y {
            *v = *v / gy / gy;
        }
        for z in &mut sp.cov_yu {
            *z = *z / gu / gy;
        }
        Ok(r)
    }

    fn frf_unscaled(&self, u: &[f64], y: &[f64], fs: f64) -> Result<PeriodicFrf> {
        let used = self.used_periods(u, y, fs)?;
        let p = self.period;
        let m = PeriodMoments::of(used.u, used.y, p)?;
        let lines = self.excited_lines(&m)?;
        let est = LineEstimates::at(&lines, &m);
        let freq_all: Vec<f64> = (0..m.mean_u.len()).map(|k| bin_hz(k, p, fs)).collect();
        Ok(PeriodicFrf {
            fs,
            period: p,
            n_periods: used.n_periods,
            skipped_periods: self.skip_periods,
            unused_samples: used.unused_samples,
            freq_hz: lines.iter().map(|&k| freq_all[k]).collect(),
            lines,
            h: est.h,
            var_h: est.var_h,
            coherence: est.coherence,
            spectra: PeriodSpectra {
                freq_hz: freq_all,
                u: m.mean_u,
                y: m.mean_y,
                var_u: m.var_u,
                var_y: m.var_y,
                cov_yu: m.cov_yu,
            },
        })
    }

    /// Checks the settings and signals and cuts out the whole periods to average.
    fn used_periods<'a>(&self, u: &'a [f64], y: &'a [f64], fs: f64) -> Result<UsedPeriods<'a>> {
        let p = self.period;
        if p < 2 {
            return Err(Error::InvalidArgument(format!(
                "period must be >= 2 samples, got {p}"
            )));
        }
        check_fs(fs)?;
        if !(self.min_relative_power >= 0.0 && self.min_snr >= 0.0) {
            return Err(Error::InvalidArgument(
                "line-detection thresholds must be >= 0".into(),
            ));
        }
        if u.len() != y.len() {
            return Err(Error::InvalidArgument(format!(
                "input and output lengths differ: {} vs {}",
                u.len(),
                y.len()
            )));
        }
        let start = self.skip_periods.saturating_mul(p);
        let avail = u.len().saturating_sub(start) / p;
        let np = self.max_periods.map_or(avail, |m| m.min(avail));
        if np < 2 {
            return Err(Error::InvalidArgument(format!(
                "period-synchronous averaging needs at least 2 periods of {p} samples after \
                 skipping {}, the record of {} samples has {avail}",
                self.skip_periods,
                u.len()
            )));
        }
        let used = UsedPeriods {
            u: &u[start..start + np * p],
            y: &y[start..start + np * p],
            n_periods: np,
            unused_samples: u.len() - start - np * p,
        };
        check_signal(used.u, "input", p)?;
        check_signal(used.y, "output", p)?;
        Ok(used)
    }

    /// The excited lines: the caller's (checked against `1..nb`), or those whose mean input
    /// power reaches both thresholds.
    fn excited_lines(&self, m: &PeriodMoments) -> Result<Vec<usize>> {
        let nb = m.mean_u.len();
        let lines: Vec<usize> = match &self.lines {
            Some(l) => {
                if let Some(&bad) = l.iter().find(|&&k| k == 0 || k >= nb) {
                    return Err(Error::InvalidArgument(format!(
                        "excited line {bad} outside 1..={}",
                        nb - 1
                    )));
                }
                let mut l = l.clone();
                l.sort_unstable();
                l.dedup();
                l
            }
            None => {
                let pmax = m.mean_u[1..]
                    .iter()
                    .map(|z| z.norm_sqr())
                    .fold(0.0_f64, f64::max);
                (1..nb)
                    .filter(|&k| {
                        let pk = m.mean_u[k].norm_sqr();
                        pk > 0.0
                            && pk >= self.min_relative_power * pmax
                            && pk >= self.min_snr * m.var_u[k]
                    })
                    .collect()
            }
        };
        if lines.is_empty() {
            return Err(Error::Data {
                file: "<signal>".into(),
                msg: format!(
                    "no excited lines found: is the input periodic with period {} samples?",
                    self.period
                ),
            });
        }
        Ok(lines)
    }

    /// Period-synchronous FRF for channels `input` → `output` of a log; errors name the file.
    pub fn frf_log(&self, log: &Log, input: usize, output: usize) -> Result<PeriodicFrf> {
        let (u, y) = pair(log, input, output)?;
        let need = self
            .period
            .saturating_mul(self.skip_periods.saturating_add(2));
        require_len(
            log,
            need,
            &format!(
                "period-synchronous averaging (2 periods of {} samples after skipping {})",
                self.period, self.skip_periods
            ),
        )?;
        self.frf(u, y, log.fs()).map_err(|e| match e {
            Error::Data { msg, .. } => Error::Data {
                file: log.path.clone(),
                msg,
            },
            other => other,
        })
    }
}

/// The whole periods a period-synchronous FRF averages.
struct UsedPeriods<'a> {
    u: &'a [f64],
    y: &'a [f64],
    n_periods: usize,
    unused_samples: usize,
}

/// Per-bin mean spectra over periods (DFT scaled by `1/period`) and the variances and
/// covariance *of the means* (sample moments / number of periods).
struct PeriodMoments {
    n_periods: usize,
    mean_u: Vec<Complex64>,
    mean_y: Vec<Complex64>,
    var_u: Vec<f64>,
    var_y: Vec<f64>,
    cov_yu: Vec<Complex64>,
}

impl PeriodMoments {
    /// Welford updates over the periods of `u`, `y` (numerically stable mean, variance and
    /// co-moment); `u.len()` is a multiple of `p` with at least two periods.
    fn of(u: &[f64], y: &[f64], p: usize) -> Result<Self> {
        let np = u.len() / p;
        let mut planner = RealFftPlanner::<f64>::new();
        let r2c = planner.plan_fft_forward(p);
        let mut buf = r2c.make_input_vec();
        let mut su = r2c.make_output_vec();
        let mut sy = r2c.make_output_vec();
        let mut scratch = r2c.make_scratch_vec();
        let nb = p / 2 + 1;
        let zero = Complex64::new(0.0, 0.0);
        let (mut mu, mut my) = (vec![zero; nb], vec![zero; nb]);
        let (mut m2u, mut m2y, mut cyu) = (vec![0.0; nb], vec![0.0; nb], vec![zero; nb]);
        let inv_p = 1.0 / p as f64;
        for q in 0..np {
            let r = q * p..(q + 1) * p;
            buf.copy_from_slice(&u[r.clone()]);
            fft(&r2c, &mut buf, &mut su, &mut scratch)?;
            buf.copy_from_slice(&y[r]);
            fft(&r2c, &mut buf, &mut sy, &mut scratch)?;
            let cnt = (q + 1) as f64;
            for k in 0..nb {
                let (a, b) = (su[k] * inv_p, sy[k] * inv_p);
                let du = a - mu[k];
                let dy = b - my[k];
                mu[k] += du / cnt;
                my[k] += dy / cnt;
                let du_new = a - mu[k];
                m2u[k] += (du * du_new.conj()).re;
                m2y[k] += (dy * (b - my[k]).conj()).re;
                cyu[k] += dy * du_new.conj();
            }
        }
        let npf = np as f64;
        // Variance of the mean = sample variance / n_periods.
        let denom = (npf - 1.0) * npf;
        Ok(PeriodMoments {
            n_periods: np,
            mean_u: mu,
            mean_y: my,
            var_u: m2u.iter().map(|v| v / denom).collect(),
            var_y: m2y.iter().map(|v| v / denom).collect(),
            cov_yu: cyu.iter().map(|v| v / denom).collect(),
        })
    }
}

/// `H = Ȳ/Ū`, its variance (first-order propagation with the U–Y covariance) and the
/// coherence of the periods, at each excited line.
struct LineEstimates {
    h: Vec<Complex64>,
    var_h: Vec<f64>,
    coherence: Vec<f64>,
}

impl LineEstimates {
    fn at(lines: &[usize], m: &PeriodMoments) -> Self {
        let npf = m.n_periods as f64;
        let mut e = LineEstimates {
            h: Vec::with_capacity(lines.len()),
            var_h: Vec::with_capacity(lines.len()),
            coherence: Vec::with_capacity(lines.len()),
        };
        for &k in lines {
            let (uk, yk) = (m.mean_u[k], m.mean_y[k]);
            let (var_u, var_y, cov_yu) = (m.var_u[k], m.var_y[k], m.cov_yu[k]);
            if uk.norm_sqr() == 0.0 {
                e.h.push(Complex64::new(f64::NAN, f64::NAN));
                e.var_h.push(f64::NAN);
                e.coherence.push(0.0);
                continue;
            }
            let hk = yk / uk;
            let vh = if yk.norm_sqr() > 0.0 {
                hk.norm_sqr()
                    * (var_y / yk.norm_sqr() + var_u / uk.norm_sqr()
                        - 2.0 * (cov_yu / (yk * uk.conj())).re)
            } else {
                // H = 0: dH = dY / U.
                var_y / uk.norm_sqr()
            }
            .max(0.0);
            // Coherence of the periods from the sums of products:
            // sum conj(U_q) Y_q = (n-1) n cov* + n conj(Ū) Ȳ, etc. (all / n).
            let cross = cov_yu * (npf - 1.0) + yk * uk.conj();
            let puu = var_u * (npf - 1.0) + uk.norm_sqr();
            let pyy = var_y * (npf - 1.0) + yk.norm_sqr();
            let coh = if puu > 0.0 && pyy > 0.0 {
                (cross.norm_sqr() / (puu * pyy)).min(1.0)
            } else {
                0.0
            };
            e.h.push(hk);
            e.var_h.push(vh);
            e.coherence.push(coh);
        }
        e
    }
}
