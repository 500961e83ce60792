//! Validation of an identified discrete model on data it was not fitted to.
//!
//! - [`simulation_fit`]: free-run simulation (initial state estimated by least squares unless
//!   given) with NRMSE = ‖y − ŷ‖ / ‖y − ȳ‖ and fit % = 100·(1 − NRMSE), per output.
//! - [`compare_with_etfe`]: model versus an empirical transfer function estimate (Welch ETFE,
//!   from [`crate::spectral`] or elsewhere, passed as plain slices) at every coherence-gated bin
//!   up to twice a crossover frequency: phase error in degrees wrapped to (−180, 180] and
//!   magnitude error in dB, with a pass/fail against a phase bound (checklist default ±5°).
//! - [`residual_test`]: whiteness of the residual (autocorrelation, lags 1..=M) and its
//!   independence of past inputs (cross-correlation, lags 0..=M), against the 99 % bounds
//!   ±2.58/√N. The residual is the one-step-ahead prediction error of the Kalman predictor
//!   when a gain K is supplied ([`ResidualKind::OneStepPrediction`]); without K it is the
//!   output (simulation) error ([`ResidualKind::OutputError`]), whose autocorrelation only
//!   tests whether the noise is white, while the cross-correlation still tests the model.
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use crate::data::Log;
use crate::error::{Error, Result};
use crate::lti::StateSpace;
use crate::n4sid::{estimate_x0, one_step_predictor};
use faer::MatRef;
use num_complex::Complex64;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Default phase-error bound of the seed checklist, degrees.
pub const PHASE_BOUND_DEG: f64 = 5.0;
/// Two-sided 99 % quantile of the standard normal, for correlation bounds ±z/√N.
pub const Z99: f64 = 2.58;
/// A correlation test passes when at most this fraction of lags falls outside the bounds
/// (1 % is expected by chance at 99 % confidence; 5 % leaves room for sampling spread).
pub const MAX_FRACTION_OUTSIDE: f64 = 0.05;

/// How the initial state of a validation simulation is chosen.
#[derive(Debug, Clone, PartialEq)]
pub enum InitialState {
    /// x0 = 0.
    Zero,
    /// Least-squares estimate from the validation data ([`estimate_x0`]).
    Estimate,
    /// Given x0 (length n).
    Given(Vec<f64>),
}

/// Free-run simulation fit per output channel.
#[derive(Debug, Clone, Serialize)]
pub struct SimulationFit {
    /// ‖y − ŷ‖ / ‖y − ȳ‖ per output (0 = perfect, 1 = as good as the mean).
    pub nrmse: Vec<f64>,
    /// 100·(1 − NRMSE) per output, percent (can be negative).
    pub fit_percent: Vec<f64>,
    /// Initial state used.
    pub x0: Vec<f64>,
    /// Simulated outputs ŷ, one channel per output.
    #[serde(skip)]
    pub y_sim: Vec<Vec<f64>>,
}

fn check_signals<U: AsRef<[f64]>, Y: AsRef<[f64]>>(
    source: &Path,
    model: &StateSpace,
    u: &[U],
    y: &[Y],
) -> Result<usize> {
    let data = |msg: String| Error::Data {
        file: PathBuf::from(source),
        msg,
    };
    if !model.is_discrete() {
        return Err(Error::InvalidArgument(
            "validation needs a discrete-time model (discretise with c2d_zoh)".into(),
        ));
    }
    if u.len() != model.n_inputs() || y.len() != model.n_outputs() {
        return Err(data(format!(
            "model is {}x{} (outputs x inputs) but the data have {} output and {} input \
             channels",
            model.n_outputs(),
            model.n_inputs(),
            y.len(),
            u.len()
        )));
    }
    let len = u[0].as_ref().len();
    if len == 0 {
        return Err(data("no samples".into()));
    }
    for (kind, chans) in [
        ("input", u.iter().map(|c| c.as_ref()).collect::<Vec<_>>()),
        ("output", y.iter().map(|c| c.as_ref()).collect::<Vec<_>>()),
    ] {
        for (j, ch) in chans.iter().enumerate() {
            if ch.len() != len {
                return Err(data(format!(
                    "{kind} channel {j} has {} samples, input channel 0 has {len} (mismatched \
                     lengths)",
                    ch.len()
                )));
            }
            if let Some(k) = ch.iter().position(|v| !v.is_finite()) {
                return Err(data(format!("{kind} channel {j} sample {k} is not finite")));
            }
        }
    }
    Ok(len)
}

/// Free-run simulation fit of a discrete `model` on validation data: `u[j]` input channels,
/// `y[i]` output channels (equal lengths). Errors for a constant output channel (NRMSE
/// undefined).
pub fn simulation_fit<U: AsRef<[f64]>, Y: AsRef<[f64]>>(
    model: &StateSpace,
    u: &[U],
    y: &[Y],
    x0: InitialState,
) -> Result<SimulationFit> {
    simulation_fit_named(Path::new("<in-memory data>"), model, u, y, x0)
}

/// [`simulation_fit`] on a [`Log`]; errors name the log's file.
pub fn simulation_fit_log(
    model: &StateSpace,
    log: &Log,
    x0: InitialState,
) -> Result<SimulationFit> {
    let u: Vec<&[f64]> = log.inputs.iter().map(|c| c.data.as_slice()).collect();
    let y: Vec<&[f64]> = log.outputs.iter().map(|c| c.data.as_slice()).collect();
    simulation_fit_named(&log.path, model, &u, &y, x0)
}

/// Free-run simulation fit of `model` on a *raw* log (offsets not removed) through the model's
/// operating point ([`crate::operating_point`]): the model sees `u − u0` and its output is
/// compared with `y − y0`, initial state estimated. This is how a model file is validated on
/// fresh data as recorded; an offset between the operating points shows up as a worse fit.
/// The log must be at the model's sample rate (raw logs of a decimated model are not).
///
/// # Errors
/// As [`simulation_fit`]; errors name the log's file.
pub fn simulation_fit_operating_point(
    model: &StateSpace,
    op: &crate::data::OperatingPoint,
    log: &Log,
) -> Result<SimulationFit> {
    let u: Vec<Vec<f64>> = log
        .inputs
        .iter()
        .enumerate()
        .map(|(j, c)| c.data.iter().map(|v| v - op.input_offset(j)).collect())
        .collect();
    let y_raw: Vec<&[f64]> = log.outputs.iter().map(|c| c.data.as_slice()).collect();
    let y = crate::operating_point::output_deviation(Some(op), &y_raw);
    simulation_fit_named(&log.path, model, &u, &y, InitialState::Estimate)
}

fn simulation_fit_named<U: AsRef<[f64]>, Y: AsRef<[f64]>>(
    source: &Path,
    model: &StateSpace,
    u: &[U],
    y: &[Y],
    x0: InitialState,
) -> Result<SimulationFit> {
    check_signals(source, model, u, y)?;
    let x0 = match x0 {
        InitialState::Zero => vec![0.0; model.n_states()],
        InitialState::Estimate => estimate_x0(model, u, y)?,
        InitialState::Given(x) => x,
    };
    let y_sim = model.simulate(u, Some(&x0))?;
    let mut nrmse = Vec::with_capacity(y.len());
    for (i, (yi, si)) in y.iter().zip(&y_sim).enumerate() {
        let yi = yi.as_ref();
        // Exact power-of-two normalisation: the ratio num/den is unchanged, and the squares
        // neither overflow nor underflow for outputs near 1e±300.
        let g = crate::spectral::power_of_two_scale(crate::spectral::max_abs(yi));
        let mean = yi.iter().map(|v| v * g).sum::<f64>() / yi.len() as f64;
        let den: f64 = yi
            .iter()
            .map(|v| (v * g - mean).powi(2))
            .sum::<f64>()
            .sqrt();
        let num: f64 = yi
            .iter()
            .zip(si)
            .map(|(a, b)| (a * g - b * g).powi(2))
            .sum::<f64>()
            .sqrt();
        if !(den > 0.0) {
            return Err(Error::Data {
                file: PathBuf::from(source),
                msg: format!("output channel {i} is constant: the fit is undefined"),
            });
        }
        nrmse.push(num / den);
    }
    let fit_percent = nrmse.iter().map(|e| 100.0 * (1.0 - e)).collect();
    Ok(SimulationFit {
        nrmse,
        fit_percent,
        x0,
        y_sim,
    })
}

/// One frequency bin of a model-versus-ETFE comparison.
#[derive(Debug, Clone, Serialize)]
pub struct EtfeBin {
    /// Bin frequency, Hz.
    pub freq_hz: f64,
    /// |G_model|.
    pub model_mag: f64,
    /// ∠G_model, degrees in (−180, 180].
    pub model_phase_deg: f64,
    /// |H_etfe|.
    pub etfe_mag: f64,
    /// ∠H_etfe, degrees in (−180, 180].
    pub etfe_phase_deg: f64,
    /// 20·log10(|G_model| / |H_etfe|), dB.
    pub mag_err_db: f64,
    /// ∠(G_model / H_etfe), degrees wrapped to (−180, 180].
    pub phase_err_deg: f64,
}

/// Model versus ETFE at the coherence-gated bins in (0, 2·crossover].
#[derive(Debug, Clone, Serialize)]
pub struct EtfeComparison {
    /// Compared bins, ascending frequency.
    pub bins: Vec<EtfeBin>,
    /// Upper frequency limit 2·crossover, Hz.
    pub f_max_hz: f64,
    /// Bins in (0, f_max] left out by the coherence gate.
    pub gated_out: usize,
    /// Largest |phase error| over the compared bins, degrees.
    pub max_abs_phase_err_deg: f64,
    /// Largest |magnitude error| over the compared bins, dB.
    pub max_abs_mag_err_db: f64,
    /// The phase bound applied, degrees.
    pub phase_bound_deg: f64,
    /// True when every compared bin is within ±`phase_bound_deg`.
    pub within_bound: bool,
}

fn wrap_deg(x: f64) -> f64 {
    // atan2-based angles are in [−180, 180]; map −180 to 180.
    let mut d = x % 360.0;
    if d > 180.0 {
        d -= 360.0;
    }
    if d <= -180.0 {
        d += 360.0;
    }
    d
}

/// Compares the (output, input) channel of `model` with an ETFE given as plain slices:
/// `freq_hz[k]` (Hz), `h[k]` the estimate and `gate[k]` true for bins that passed the
/// coherence gate. Only gated bins with 0 < f <= 2·`crossover_hz` are compared. Errors for
/// mismatched lengths, non-finite values, a non-positive crossover, or when no bin qualifies.
#[allow(clippy::too_many_arguments)]
pub fn compare_with_etfe(
    model: &StateSpace,
    output: usize,
    input: usize,
    freq_hz: &[f64],
    h: &[Complex64],
    gate: &[bool],
    crossover_hz: f64,
    phase_bound_deg: f64,
) -> Result<EtfeComparison> {
    if freq_hz.len() != h.len() || freq_hz.len() != gate.len() {
        return Err(Error::InvalidArgument(format!(
            "ETFE slices differ in length: {} frequencies, {} values, {} gate flags",
            freq_hz.len(),
            h.len(),
            gate.len()
        )));
    }
    if output >= model.n_outputs() || input >= model.n_inputs() {
        return Err(Error::InvalidArgument(format!(
            "channel (output {output}, input {input}) outside the {}x{} model",
            model.n_outputs(),
            model.n_inputs()
        )));
    }
    if !(crossover_hz.is_finite() && crossover_hz > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "crossover frequency {crossover_hz} Hz must be finite and > 0"
        )));
    }
    if !(phase_bound_deg.is_finite() && phase_bound_deg > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "phase bound {phase_bound_deg}° must be finite and > 0"
        )));
    }
    let f_max = 2.0 * crossover_hz;
    let ev = model.freq_evaluator();
    let mut bins = Vec::new();
    let mut gated_out = 0;
    for k in 0..freq_hz.len() {
        let f = freq_hz[k];
        if !(f.is_finite() && h[k].re.is_finite() && h[k].im.is_finite()) {
            return Err(Error::InvalidArgument(format!(
                "ETFE bin {k} (f = {f} Hz) is not finite"
            )));
        }
        if !(f > 0.0 && f <= f_max) {
            continue;
        }
        if !gate[k] {
            gated_out += 1;
            continue;
        }
        let g = ev.at_rad_s(2.0 * std::f64::consts::PI * f)?[(output, input)];
        if h[k].norm() == 0.0 || g.norm() == 0.0 {
            return Err(Error::Numerical(format!(
                "zero response at {f} Hz (model {:.3e}, ETFE {:.3e}): the error is undefined",
                g.norm(),
                h[k].norm()
            )));
        }
        let ratio = g / h[k];
        bins.push(EtfeBin {
            freq_hz: f,
            model_mag: g.norm(),
            model_phase_deg: wrap_deg(g.arg().to_degrees()),
            etfe_mag: h[k].norm(),
            etfe_phase_deg: wrap_deg(h[k].arg().to_degrees()),
            mag_err_db: 20.0 * ratio.norm().log10(),
            phase_err_deg: wrap_deg(ratio.arg().to_degrees()),
        });
    }
    if bins.is_empty() {
        return Err(Error::InvalidArgument(format!(
            "no coherence-gated ETFE bin in (0, {f_max}] Hz ({gated_out} bins gated out): \
             nothing to compare"
        )));
    }
    bins.sort_by(|a, b| a.freq_hz.total_cmp(&b.freq_hz));
    let max_abs_phase_err_deg = bins
        .iter()
        .map(|b| b.phase_err_deg.abs())
        .fold(0.0, f64::max);
    let max_abs_mag_err_db = bins.iter().map(|b| b.mag_err_db.abs()).fold(0.0, f64::max);
    Ok(EtfeComparison {
        bins,
        f_max_hz: f_max,
        gated_out,
        max_abs_phase_err_deg,
        max_abs_mag_err_db,
        phase_bound_deg,
        within_bound: max_abs_phase_err_deg <= phase_bound_deg,
    })
}

/// Which residual the correlation tests used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum ResidualKind {
    /// e(t) = y(t) − ŷ(t|t−1) from the Kalman predictor (whiteness is a model test).
    OneStepPrediction,
    /// e(t) = y(t) − ŷ_sim(t) (whiteness only tests the noise; cross-correlation tests G).
    OutputError,
}

/// Residual auto- and cross-correlation test at 99 % confidence.
#[derive(Debug, Clone, Serialize)]
pub struct ResidualTest {
    /// Residual used.
    pub kind: ResidualKind,
    /// Largest lag M.
    pub max_lag: usize,
    /// Samples N.
    pub n_samples: usize,
    /// Bound 2.58/√N on the normalised correlations.
    pub bound: f64,
    /// `autocorr[i][τ−1]`: normalised autocorrelation of residual i at lag τ = 1..=M.
    pub autocorr: Vec<Vec<f64>>,
    /// `crosscorr[i][j][τ]`: normalised correlation of residual i at time t with input j at
    /// time t − τ, τ = 0..=M.
    pub crosscorr: Vec<Vec<Vec<f64>>>,
    /// Fraction of autocorrelation lags outside ±bound.
    pub frac_auto_outside: f64,
    /// Fraction of cross-correlation lags outside ±bound.
    pub frac_cross_outside: f64,
    /// `frac_auto_outside <= MAX_FRACTION_OUTSIDE`.
    pub whiteness_ok: bool,
    /// `frac_cross_outside <= MAX_FRACTION_OUTSIDE`.
    pub independence_ok: bool,
}

/// `x` minus its mean.
pub(crate) fn demeaned(x: &[f64]) -> Vec<f64> {
    let m = x.iter().sum::<f64>() / x.len() as f64;
    x.iter().map(|v| v - m).collect()
}

/// Normalised correlation Σ_t a(t+τ)·b(t) / √(Σa²·Σb²).
fn xcorr(a: &[f64], b: &[f64], tau: usize, norm: f64) -> f64 {
    let n = a.len();
    if tau >= n {
        return 0.0;
    }
    a[tau..]
        .iter()
        .zip(&b[..n - tau])
        .map(|(x, y)| x * y)
        .sum::<f64>()
        / norm
}

/// [`xcorr`] at every lag of `taus`, the same sums to the bit (each lag's products added in
/// the order of `t`, from −0.0 as `Iterator::sum` starts), but [`LAG_LANES`] lags at a time:
/// one pass over the data per group of lags, whose independent sums the processor overlaps
/// (one sum alone waits for each addition to finish before the next).
fn xcorr_lags(a: &[f64], b: &[f64], taus: std::ops::Range<usize>, norm: f64) -> Vec<f64> {
    const LAG_LANES: usize = 8;
    let n = a.len().min(b.len());
    let mut out = Vec::with_capacity(taus.len());
    let mut tau = taus.start;
    while tau < taus.end {
        if taus.end - tau < LAG_LANES || tau + LAG_LANES > n || a.len() != b.len() {
            out.push(xcorr(a, b, tau, norm));
            tau += 1;
            continue;
        }
        // Lag tau + j sums t = 0..n − tau − j; the first n − tau − (LAG_LANES − 1) terms are
        // common to the group, the rest are each lag's tail.
        let common = n - tau - (LAG_LANES - 1);
        let mut acc = lag_group(&a[tau..], &b[..common]);
        for (j, s) in acc.iter_mut().enumerate() {
            for t in common..n - tau - j {
                *s += a[t + tau + j] * b[t];
            }
        }
        out.extend(acc.iter().map(|s| s / norm));
        tau += LAG_LANES;
    }
    out
}

/// The common part of [`xcorr_lags`]' group: `acc[j] = Σ_t a[t + j]·b[t]` over the `t` of
/// `b`, each sum from −0.0 in the order of `t`. With AVX2 the 8 lags are two registers (the
/// same products and additions per lag: the same bits).
fn lag_group(a: &[f64], b: &[f64]) -> [f64; 8] {
    #[cfg(target_arch = "x86_64")]
    if let Some(avx) = crate::n4sid::linalg::Avx::new() {
        return avx.run(
            #[inline(always)]
            || {
                let (mut lo, mut hi) = (avx.splat(-0.0), avx.splat(-0.0));
                for (t, &bt) in b.iter().enumerate() {
                    let w: &[f64; 8] = a[t..t + 8].try_into().expect("window of 8 samples");
                    let bv = avx.splat(bt);
                    lo = avx.add(lo, avx.mul(avx.load(w, 0), bv));
                    hi = avx.add(hi, avx.mul(avx.load(w, 4), bv));
                }
                let (lo, hi) = (avx.lanes(lo), avx.lanes(hi));
                [lo[0], lo[1], lo[2], lo[3], hi[0], hi[1], hi[2], hi[3]]
            },
        );
    }
    let mut acc = [-0.0f64; 8];
    for (t, &bt) in b.iter().enumerate() {
        let w: &[f64; 8] = a[t..t + 8].try_into().expect("window of 8 samples");
        for j in 0..8 {
            acc[j] += w[j] * bt;
        }
    }
    acc
}

/// Residual tests of a discrete `model` on data `u`, `y` up to lag `max_lag` (1..N/4).
/// With `kalman_gain` (n×p) the one-step-ahead predictor residual is used, else the output
/// error; the initial state is estimated by least squares in both cases.
pub fn residual_test<U: AsRef<[f64]>, Y: AsRef<[f64]>>(
    model: &StateSpace,
    kalman_gain: Option<MatRef<'_, f64>>,
    u: &[U],
    y: &[Y],
    max_lag: usize,
) -> Result<ResidualTest> {
    let len = check_signals(Path::new("<in-memory data>"), model, u, y)?;
    if max_lag == 0 || max_lag > len / 4 {
        return Err(Error::InvalidArgument(format!(
            "max_lag {max_lag} must be in 1..={} (a quarter of the {len} samples)",
            len / 4
        )));
    }
    let (kind, resid): (ResidualKind, Vec<Vec<f64>>) = match kalman_gain {
        Some(k) => {
            let pred = one_step_predictor(model, k)?;
            let mut inputs: Vec<&[f64]> = u.iter().map(|c| c.as_ref()).collect();
            inputs.extend(y.iter().map(|c| c.as_ref()));
            let x0 = estimate_x0(&pred, &inputs, y)?;
            let yhat = pred.simulate(&inputs, Some(&x0))?;
            (
                ResidualKind::OneStepPrediction,
                y.iter()
                    .zip(&yhat)
                    .map(|(a, b)| a.as_ref().iter().zip(b).map(|(p, q)| p - q).collect())
                    .collect(),
            )
        }
        None => {
            let x0 = estimate_x0(model, u, y)?;
            let ysim = model.simulate(u, Some(&x0))?;
            (
                ResidualKind::OutputError,
                y.iter()
                    .zip(&ysim)
                    .map(|(a, b)| a.as_ref().iter().zip(b).map(|(p, q)| p - q).collect())
                    .collect(),
            )
        }
    };
    // Normalised by exact powers of two: correlations are ratios, so unchanged, and the sums
    // of products neither overflow nor underflow for signals near 1e±300.
    let normalised = |x: Vec<f64>| -> Vec<f64> {
        let g = crate::spectral::power_of_two_scale(crate::spectral::max_abs(&x));
        x.into_iter().map(|v| v * g).collect()
    };
    let e: Vec<Vec<f64>> = resid.iter().map(|r| normalised(demeaned(r))).collect();
    let uc: Vec<Vec<f64>> = u.iter().map(|c| normalised(demeaned(c.as_ref()))).collect();
    let bound = Z99 / (len as f64).sqrt();
    let mut autocorr = Vec::new();
    let mut crosscorr = Vec::new();
    let (mut auto_out, mut auto_n, mut cross_out, mut cross_n) = (0usize, 0usize, 0usize, 0usize);
    for ei in &e {
        let ee: f64 = ei.iter().map(|v| v * v).sum();
        if !(ee > 0.0) {
            return Err(Error::Numerical(
                "residual is identically zero: correlation tests are undefined".into(),
            ));
        }
        let ac: Vec<f64> = xcorr_lags(ei, ei, 1..max_lag + 1, ee);
        auto_out += ac.iter().filter(|r| r.abs() > bound).count();
        auto_n += ac.len();
        autocorr.push(ac);
        let mut per_input = Vec::new();
        for uj in &uc {
            let uu: f64 = uj.iter().map(|v| v * v).sum();
            if !(uu > 0.0) {
                return Err(Error::Data {
                    file: PathBuf::from("<in-memory data>"),
                    msg: "an input channel is constant: cross-correlation undefined".into(),
                });
            }
            let norm = (ee * uu).sqrt();
            let cc: Vec<f64> = xcorr_lags(ei, uj, 0..max_lag + 1, norm);
            cross_out += cc.iter().filter(|r| r.abs() > bound).count();
            cross_n += cc.len();
            per_input.push(cc);
        }
        crosscorr.push(per_input);
    }
    let frac_auto_outside = auto_out as f64 / auto_n as f64;
    let frac_cross_outside = cross_out as f64 / cross_n as f64;
    Ok(ResidualTest {
        kind,
        max_lag,
        n_samples: len,
        bound,
        autocorr,
        crosscorr,
        frac_auto_outside,
        frac_cross_outside,
        whiteness_ok: frac_auto_outside <= MAX_FRACTION_OUTSIDE,
        independence_ok: frac_cross_outside <= MAX_FRACTION_OUTSIDE,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The grouped lags equal one sum per lag to the bit, for lengths and lag ranges around
    /// the group size (short data, partial groups, lags up to the length).
    #[test]
    fn grouped_lags_equal_one_sum_per_lag() {
        let mut uniform = crate::n4sid::linalg::test_uniform(0x9e37_79b9_7f4a_7c15);
        let mut next = || uniform() - 0.5;
        for n in [1usize, 7, 8, 9, 16, 17, 100, 1000] {
            let a: Vec<f64> = (0..n).map(|_| next() * 1e3).collect();
            let b: Vec<f64> = (0..n).map(|_| next()).collect();
            for (lo, hi) in [(0, 1), (0, 9), (1, 26), (0, 26), (3, n), (0, n + 2)] {
                let got = xcorr_lags(&a, &b, lo..hi, 0.7);
                let want: Vec<f64> = (lo..hi).map(|tau| xcorr(&a, &b, tau, 0.7)).collect();
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&got), bits(&want), "n {n}, lags {lo}..{hi}");
            }
        }
    }
}
