//! Multiplicative uncertainty: the envelope l_m(ω) of a family of measured responses around a
//! nominal model, and a stable, minimum-phase rational weight W_m(s) that overbounds it.
//!
//! # Envelope
//! l_m(ω_i) = max_k |(G_k(jω_i) − G0(jω_i)) / G0(jω_i)| over the family {G_k} (runs at several
//! amplitudes, several units, before/after thermal tests), so that every member is
//! G_k = G0·(1 + Δ_k) with |Δ_k(jω_i)| <= l_m(ω_i).
//!
//! # Weight fit (the optimisation problem)
//! W_m(s) = k · N(s)/D(s) of order n ∈ {1, 2, 3}, with N and D monic of degree n, built from
//! ⌊n/2⌋ quadratic sections s² + 2ζωs + ω² (ζ ∈ [0.02, 1000], ω > 0 — a section with ζ >= 1 is
//! two real roots) and n mod 2 real sections s + a (a > 0), for the zeros and for the poles.
//! Every parameter vector therefore gives a stable, minimum-phase W_m by construction.
//!
//! Objective: minimise the weighted mean log-overbound over log-frequency
//!
//! ```text
//! J = Σ_i w_i · ln(|W_m(jω_i)| / l_m(ω_i)) / Σ_i w_i,   subject to |W_m(jω_i)| >= l_m(ω_i) ∀i,
//! ```
//!
//! with trapezoidal weights w_i in ln ω (J approximates the average of ln(|W_m|/l_m) over
//! log-frequency). For fixed poles and zeros the smallest feasible gain is exact,
//! ln k* = max_i [ln l_m(ω_i) − ln|N/D(jω_i)|], so the constraint is eliminated and the reduced
//! (non-smooth) objective over the section parameters (log ω, log ζ, log a) is minimised by
//! Nelder–Mead ([`crate::gap::optim::nelder_mead`], restarted on a shrinking simplex) from many
//! starts. Order n + 1 is started from the order-n optimum extended by an exactly cancelling
//! pole/zero pair, so a higher order is never looser. A final exact check evaluates |W_m(jω_i)| from the polynomial coefficients and raises k if
//! rounding left any ratio below 1.
//!
//! Units: `freq_hz` in Hz; W_m(s) is continuous with s in rad/s.
use crate::error::{Error, Result};
use crate::gap::optim::nelder_mead;
use crate::lti::{poly_eval, poly_mul, poly_roots, StateSpace, TransferFunction};
use num_complex::Complex64;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Envelope l_m(ω_i) = max_k |(G_k − G0)/G0| at each frequency bin. `g0` is the nominal response
/// and each `family[k]` a response at the same bins (same length).
///
/// Errors: empty family, length mismatch (names the member), non-finite values, or |G0| = 0
/// at a bin (relative uncertainty undefined; names the bin).
pub fn multiplicative_envelope<R: AsRef<[Complex64]>>(
    g0: &[Complex64],
    family: &[R],
) -> Result<Vec<f64>> {
    if family.is_empty() {
        return Err(Error::InvalidArgument(
            "multiplicative envelope: the family of responses is empty".into(),
        ));
    }
    if g0.is_empty() {
        return Err(Error::InvalidArgument(
            "multiplicative envelope: the nominal response has no bins".into(),
        ));
    }
    for (i, g) in g0.iter().enumerate() {
        if !(g.re.is_finite() && g.im.is_finite()) {
            return Err(Error::InvalidArgument(format!(
                "multiplicative envelope: nominal response bin {i} is not finite"
            )));
        }
        if g.norm() == 0.0 {
            return Err(Error::InvalidArgument(format!(
                "multiplicative envelope: nominal response is zero at bin {i}; relative \
                 uncertainty is undefined there"
            )));
        }
    }
    let mut l = vec![0.0f64; g0.len()];
    for (k, gk) in family.iter().enumerate() {
        let gk = gk.as_ref();
        if gk.len() != g0.len() {
            return Err(Error::InvalidArgument(format!(
                "multiplicative envelope: family member {k} has {} bins, the nominal has {}",
                gk.len(),
                g0.len()
            )));
        }
        for (i, (a, b)) in gk.iter().zip(g0).enumerate() {
            if !(a.re.is_finite() && a.im.is_finite()) {
                return Err(Error::InvalidArgument(format!(
                    "multiplicative envelope: family member {k} bin {i} is not finite"
                )));
            }
            l[i] = l[i].max(((a - b) / b).norm());
        }
    }
    Ok(l)
}

/// Options of [`fit_uncertainty_weight`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WeightFitOptions {
    /// Weight order n, 1..=3 (numerator and denominator degree).
    pub order: usize,
    /// Floor applied to the envelope before fitting (absolute, dimensionless; default 1e-3,
    /// i.e. 0.1 % relative uncertainty). Raising the envelope is conservative; floored bins are
    /// counted in [`UncertaintyWeight::floored_bins`].
    pub min_level: f64,
    /// Nelder–Mead evaluations per start (default 4000).
    pub max_evals: usize,
}

impl Default for WeightFitOptions {
    fn default() -> Self {
        Self {
            order: 2,
            min_level: 1e-3,
            max_evals: 4000,
        }
    }
}

/// A fitted multiplicative uncertainty weight W_m(s) = num(s)/den(s) (continuous time, s in
/// rad/s, descending powers, den monic), with the evidence of its fit.
///
/// Invariants: `num.len() == den.len() == order + 1`; all roots of num and den have negative
/// real parts (stable, minimum phase); `overbound_ratio[i] = |W_m(j2πf_i)| / envelope[i] >= 1`
/// at every measured frequency when `constraint_holds`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UncertaintyWeight {
    /// Order n (1..=3).
    pub order: usize,
    /// Numerator coefficients, descending powers of s (rad/s), length n + 1.
    pub num: Vec<f64>,
    /// Denominator coefficients, descending powers of s (rad/s), monic, length n + 1.
    pub den: Vec<f64>,
    /// Zeros of W_m as [re, im] in rad/s (all re < 0).
    pub zeros: Vec<[f64; 2]>,
    /// Poles of W_m as [re, im] in rad/s (all re < 0).
    pub poles: Vec<[f64; 2]>,
    /// Measured frequencies (Hz) the weight was fitted on.
    pub freq_hz: Vec<f64>,
    /// Envelope l_m at `freq_hz` after flooring at `min_level` (dimensionless).
    pub envelope: Vec<f64>,
    /// `|W_m(j2πf_i)| / envelope[i]` at every measured frequency.
    pub overbound_ratio: Vec<f64>,
    /// `max_i overbound_ratio[i]`: how loose the weight is at its loosest bin.
    pub worst_overbound_ratio: f64,
    /// `min_i overbound_ratio[i]` (>= 1 when the constraint holds).
    pub min_overbound_ratio: f64,
    /// True when |W_m| >= l_m at every measured frequency.
    pub constraint_holds: bool,
    /// The minimised objective J expressed in dB: 20·log10 of the log-frequency-weighted
    /// geometric mean of |W_m|/l_m.
    pub mean_overbound_db: f64,
    /// Number of envelope bins raised to the floor `min_level`.
    pub floored_bins: usize,
    /// Floor applied to the envelope.
    pub min_level: f64,
    /// Statement of the optimisation problem that was solved.
    pub objective: String,
}

impl UncertaintyWeight {
    /// W_m(jω) at `w_rad_s` (rad/s).
    pub fn freq_response(&self, w_rad_s: f64) -> Complex64 {
        let s = Complex64::new(0.0, w_rad_s);
        poly_eval(&self.num, s) / poly_eval(&self.den, s)
    }
    /// W_m(j2πf) at `f_hz` (Hz).
    pub fn freq_response_hz(&self, f_hz: f64) -> Complex64 {
        self.freq_response(2.0 * PI * f_hz)
    }
    /// |W_m(j2πf)| at `f_hz` (Hz).
    pub fn magnitude_hz(&self, f_hz: f64) -> f64 {
        self.freq_response_hz(f_hz).norm()
    }
    /// The weight as a continuous transfer function.
    pub fn to_transfer_function(&self) -> Result<TransferFunction> {
        TransferFunction::new(self.num.clone(), self.den.clone(), 0.0)
    }
    /// The weight as a continuous state-space model (controllable canonical form).
    pub fn to_state_space(&self) -> Result<StateSpace> {
        self.to_transfer_function()?.to_state_space()
    }
}

/// Parameter layout: for zeros then poles, ⌊n/2⌋ × (ln ω, ln ζ) then (n mod 2) × ln a.
#[derive(Debug, Clone, Copy)]
struct Layout {
    nq: usize,
    nr: usize,
    ln_w_lo: f64,
    ln_w_hi: f64,
}

const ZETA_MIN: f64 = 0.02;
const ZETA_MAX: f64 = 1000.0;

impl Layout {
    fn new(order: usize, w_lo: f64, w_hi: f64) -> Self {
        Self {
            nq: order / 2,
            nr: order % 2,
            ln_w_lo: (w_lo / 1e3).ln(),
            ln_w_hi: (w_hi * 1e3).ln(),
        }
    }
    fn half(&self) -> usize {
        2 * self.nq + self.nr
    }
    fn clamp_w(&self, v: f64) -> f64 {
        v.clamp(self.ln_w_lo, self.ln_w_hi).exp()
    }
    fn clamp_z(&self, v: f64) -> f64 {
        v.exp().clamp(ZETA_MIN, ZETA_MAX)
    }
    /// Sections (quadratics as (ω, ζ), reals as a) of one half of the parameter vector.
    fn sections(&self, p: &[f64]) -> (Vec<(f64, f64)>, Vec<f64>) {
        let q = (0..self.nq)
            .map(|i| (self.clamp_w(p[2 * i]), self.clamp_z(p[2 * i + 1])))
            .collect();
        let r = (0..self.nr)
            .map(|i| self.clamp_w(p[2 * self.nq + i]))
            .collect();
        (q, r)
    }
    /// ln|section product(jν)| for one half.
    fn ln_mag(&self, p: &[f64], nu: f64) -> f64 {
        let (q, r) = self.sections(p);
        let mut acc = 0.0;
        for (w, z) in q {
            let re = w * w - nu * nu;
            let im = 2.0 * z * w * nu;
            acc += 0.5 * (re * re + im * im).ln();
        }
        for a in r {
            acc += 0.5 * (nu * nu + a * a).ln();
        }
        acc
    }
    fn poly(&self, p: &[f64]) -> Vec<f64> {
        let (q, r) = self.sections(p);
        let mut poly = vec![1.0];
        for (w, z) in q {
            poly = poly_mul(&poly, &[1.0, 2.0 * z * w, w * w]);
        }
        for a in r {
            poly = poly_mul(&poly, &[1.0, a]);
        }
        poly
    }
}

/// Zeros (quadratics as (ω, ζ), reals as a) and poles of one fit, for warm starts.
type Sections = (Vec<(f64, f64)>, Vec<f64>, Vec<(f64, f64)>, Vec<f64>);

struct Problem<'a> {
    nu: &'a [f64],
    ln_l: Vec<f64>,
    weights: Vec<f64>,
    wsum: f64,
}

impl Problem<'_> {
    /// (J, ln k*) for parameters `p` of layout `lay`.
    fn eval(&self, lay: &Layout, p: &[f64]) -> (f64, f64) {
        let h = lay.half();
        let s: Vec<f64> = self
            .nu
            .iter()
            .map(|&nu| lay.ln_mag(&p[..h], nu) - lay.ln_mag(&p[h..], nu))
            .collect();
        let ln_k = self
            .ln_l
            .iter()
            .zip(&s)
            .map(|(l, s)| l - s)
            .fold(f64::NEG_INFINITY, f64::max);
        let j = s
            .iter()
            .zip(&self.ln_l)
            .zip(&self.weights)
            .map(|((s, l), w)| w * (s + ln_k - l))
            .sum::<f64>()
            / self.wsum;
        (j, ln_k)
    }
}

/// Fits W_m of order `opts.order` (see the module docs for the objective). `freq_hz` must be
/// strictly increasing, positive and finite; `envelope` finite and >= 0, same length, at
/// least 3 bins.
pub fn fit_uncertainty_weight(
    freq_hz: &[f64],
    envelope: &[f64],
    opts: &WeightFitOptions,
) -> Result<UncertaintyWeight> {
    let mut all = fit_uncertainty_weights(freq_hz, envelope, opts)?;
    all.pop()
        .ok_or_else(|| Error::Numerical("uncertainty weight: no fit produced".into()))
}

/// Fits W_m of every order 1..=`opts.order` (each started from the previous optimum), returned
/// in increasing order; `mean_overbound_db` is non-increasing along the list.
pub fn fit_uncertainty_weights(
    freq_hz: &[f64],
    envelope: &[f64],
    opts: &WeightFitOptions,
) -> Result<Vec<UncertaintyWeight>> {
    if !(1..=3).contains(&opts.order) {
        return Err(Error::InvalidArgument(format!(
            "uncertainty weight order {} must be 1, 2 or 3",
            opts.order
        )));
    }
    if !(opts.min_level.is_finite() && opts.min_level > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "uncertainty weight: min_level {} must be finite and > 0",
            opts.min_level
        )));
    }
    if opts.max_evals < 10 {
        return Err(Error::InvalidArgument(format!(
            "uncertainty weight: max_evals {} is too small (>= 10)",
            opts.max_evals
        )));
    }
    if freq_hz.len() != envelope.len() {
        return Err(Error::InvalidArgument(format!(
            "uncertainty weight: {} frequencies but {} envelope values",
            freq_hz.len(),
            envelope.len()
        )));
    }
    if freq_hz.len() < 3 {
        return Err(Error::InvalidArgument(format!(
            "uncertainty weight: need at least 3 frequency bins, got {}",
            freq_hz.len()
        )));
    }
    for (i, &f) in freq_hz.iter().enumerate() {
        if !(f.is_finite() && f > 0.0) {
            return Err(Error::InvalidArgument(format!(
                "uncertainty weight: frequency bin {i} = {f} Hz must be finite and > 0"
            )));
        }
        if i > 0 && f.partial_cmp(&freq_hz[i - 1]) != Some(std::cmp::Ordering::Greater) {
            return Err(Error::InvalidArgument(format!(
                "uncertainty weight: frequencies must increase strictly (bin {i}: {f} Hz after \
                 {} Hz)",
                freq_hz[i - 1]
            )));
        }
    }
    for (i, &l) in envelope.iter().enumerate() {
        if !(l.is_finite() && l >= 0.0) {
            return Err(Error::InvalidArgument(format!(
                "uncertainty weight: envelope bin {i} = {l} must be finite and >= 0"
            )));
        }
    }
    let floored_bins = envelope.iter().filter(|&&l| l < opts.min_level).count();
    let env: Vec<f64> = envelope.iter().map(|&l| l.max(opts.min_level)).collect();
    let nu: Vec<f64> = freq_hz.iter().map(|f| 2.0 * PI * f).collect();
    let ln_nu: Vec<f64> = nu.iter().map(|v| v.ln()).collect();
    let m = nu.len();
    let weights: Vec<f64> = (0..m)
        .map(|i| {
            let lo = if i == 0 { ln_nu[0] } else { ln_nu[i - 1] };
            let hi = if i + 1 == m {
                ln_nu[m - 1]
            } else {
                ln_nu[i + 1]
            };
            0.5 * (hi - lo)
        })
        .collect();
    let wsum: f64 = weights.iter().sum();
    let prob = Problem {
        nu: &nu,
        ln_l: env.iter().map(|l| l.ln()).collect(),
        weights,
        wsum,
    };
    let (w_lo, w_hi) = (nu[0], nu[m - 1]);
    let grid: Vec<f64> = super::norms::logspace(w_lo / 10.0, w_hi * 10.0, 7)
        .iter()
        .map(|w| w.ln())
        .collect();

    let mut fits = Vec::new();
    // Best parameters of the previous order (as sections) for warm starts.
    let mut prev: Option<Sections> = None;
    for order in 1..=opts.order {
        let lay = Layout::new(order, w_lo, w_hi);
        let mut starts: Vec<Vec<f64>> = Vec::new();
        let pack = |zq: &[(f64, f64)], zr: &[f64], pq: &[(f64, f64)], pr: &[f64]| -> Vec<f64> {
            let mut v = Vec::new();
            for half in [(zq, zr), (pq, pr)] {
                for &(w, z) in half.0 {
                    v.push(w.ln());
                    v.push(z.ln());
                }
                for &a in half.1 {
                    v.push(a.ln());
                }
            }
            v
        };
        // Cold starts over a grid of corner frequencies.
        for &gz in &grid {
            for &gp in &grid {
                let (wz, wp) = (gz.exp(), gp.exp());
                match order {
                    1 => starts.push(pack(&[], &[wz], &[], &[wp])),
                    2 => {
                        for z in [0.3, 1.0] {
                            starts.push(pack(&[(wz, z)], &[], &[(wp, z)], &[]));
                        }
                    }
                    _ => starts.push(pack(&[(wz, 0.7)], &[wz], &[(wp, 0.7)], &[wp])),
                }
            }
        }
        // Peak-informed starts: a lightly damped pole pair at the envelope's largest value
        // (resonance-shift envelopes are sharp bumps).
        if order >= 2 {
            let ipk = (0..m)
                .max_by(|&a, &b| prob.ln_l[a].total_cmp(&prob.ln_l[b]))
                .unwrap_or(0);
            let wpk = nu[ipk];
            for &gz in &grid {
                let wz = gz.exp();
                for zeta in [0.03, 0.1, 0.3] {
                    if order == 2 {
                        starts.push(pack(&[(wz, 0.7)], &[], &[(wpk, zeta)], &[]));
                    } else {
                        starts.push(pack(&[(wz, 0.7)], &[wz], &[(wpk, zeta)], &[w_hi]));
                    }
                }
            }
        }
        // Warm starts: previous optimum plus an exactly cancelling pair at c.
        if let Some((zq, zr, pq, pr)) = &prev {
            for &gc in &grid {
                let c = gc.exp();
                if order == 2 {
                    // real (z) + real (c) -> quadratic with ω = √(zc), ζ = (z + c)/(2√(zc)).
                    let to_q = |a: f64| ((a * c).sqrt(), (a + c) / (2.0 * (a * c).sqrt()));
                    starts.push(pack(&[to_q(zr[0])], &[], &[to_q(pr[0])], &[]));
                } else {
                    let mut zr2 = zr.clone();
                    zr2.push(c);
                    let mut pr2 = pr.clone();
                    pr2.push(c);
                    starts.push(pack(zq, &zr2, pq, &pr2));
                }
            }
        }
        let mut scored: Vec<(f64, Vec<f64>)> = starts
            .into_iter()
            .map(|p| (prob.eval(&lay, &p).0, p))
            .collect();
        scored.sort_by(|a, b| a.0.total_cmp(&b.0));
        let dim = 2 * lay.half();
        let mut best: Option<(f64, Vec<f64>)> = None;
        for (_, p0) in scored.into_iter().take(6) {
            // Nelder–Mead with restarts on a fresh, shrinking simplex from the best vertex, so
            // a collapsed simplex cannot stall the search. The best vertex never gets worse.
            let (mut x, mut fx) = (p0.clone(), prob.eval(&lay, &p0).0);
            for round in 0..4 {
                let step = vec![0.5 * 0.5f64.powi(round); dim];
                let (xn, fnew) =
                    nelder_mead(|p| prob.eval(&lay, p).0, &x, &step, opts.max_evals, 1e-13);
                if fnew < fx {
                    x = xn;
                    fx = fnew;
                }
            }
            let r = (fx, x);
            if best.as_ref().is_none_or(|b| r.0 < b.0) {
                best = Some(r);
            }
        }
        let (_, p) =
            best.ok_or_else(|| Error::Numerical("uncertainty weight: no start evaluated".into()))?;
        let h = lay.half();
        let (zq, zr) = lay.sections(&p[..h]);
        let (pq, pr) = lay.sections(&p[h..]);
        let (_, ln_k) = prob.eval(&lay, &p);
        let fit = build_weight(
            order,
            ln_k.exp(),
            &lay.poly(&p[..h]),
            &lay.poly(&p[h..]),
            freq_hz,
            &env,
            &prob,
            floored_bins,
            opts.min_level,
        )?;
        fits.push(fit);
        prev = Some((zq, zr, pq, pr));
    }
    Ok(fits)
}

#[allow(clippy::too_many_arguments)]
fn build_weight(
    order: usize,
    k: f64,
    zpoly: &[f64],
    ppoly: &[f64],
    freq_hz: &[f64],
    env: &[f64],
    prob: &Problem<'_>,
    floored_bins: usize,
    min_level: f64,
) -> Result<UncertaintyWeight> {
    let den = ppoly.to_vec();
    let mut num: Vec<f64> = zpoly.iter().map(|c| c * k).collect();
    // Exact check from the coefficients; raise k if rounding left any ratio below 1.
    let ratios = |num: &[f64]| -> Vec<f64> {
        prob.nu
            .iter()
            .zip(env)
            .map(|(&nu, &l)| {
                let s = Complex64::new(0.0, nu);
                (poly_eval(num, s) / poly_eval(&den, s)).norm() / l
            })
            .collect()
    };
    let mut r = ratios(&num);
    let rmin = r.iter().copied().fold(f64::INFINITY, f64::min);
    if rmin < 1.0 {
        let f = (1.0 + 4.0 * f64::EPSILON) / rmin;
        num.iter_mut().for_each(|c| *c *= f);
        r = ratios(&num);
    }
    let worst = r.iter().copied().fold(0.0, f64::max);
    let rmin = r.iter().copied().fold(f64::INFINITY, f64::min);
    if !(worst.is_finite() && rmin.is_finite()) {
        return Err(Error::Numerical(
            "uncertainty weight: fitted weight is not finite at a measured frequency".into(),
        ));
    }
    let j = r
        .iter()
        .zip(&prob.weights)
        .map(|(r, w)| w * r.ln())
        .sum::<f64>()
        / prob.wsum;
    let roots = |p: &[f64]| -> Result<Vec<[f64; 2]>> {
        Ok(poly_roots(p)?.iter().map(|z| [z.re, z.im]).collect())
    };
    let zeros = roots(&num)?;
    let poles = roots(&den)?;
    if let Some(z) = zeros
        .iter()
        .chain(&poles)
        .find(|z| z[0].partial_cmp(&0.0) != Some(std::cmp::Ordering::Less))
    {
        return Err(Error::Numerical(format!(
            "uncertainty weight: root {:.6e}{:+.6e}j is not in the open left half plane",
            z[0], z[1]
        )));
    }
    Ok(UncertaintyWeight {
        order,
        num,
        den,
        zeros,
        poles,
        freq_hz: freq_hz.to_vec(),
        envelope: env.to_vec(),
        overbound_ratio: r,
        worst_overbound_ratio: worst,
        min_overbound_ratio: rmin,
        constraint_holds: rmin >= 1.0,
        mean_overbound_db: 20.0 * j / std::f64::consts::LN_10,
        floored_bins,
        min_level,
        objective: "minimise Σ_i w_i·ln(|W_m(jω_i)|/l_m(ω_i)) / Σ_i w_i (w_i: trapezoidal \
                    weights in ln ω) subject to |W_m(jω_i)| >= l_m(ω_i) at every measured \
                    frequency; W_m stable and minimum phase by parametrisation"
            .into(),
    })
}
