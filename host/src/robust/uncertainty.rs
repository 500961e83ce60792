//! Multiplicative uncertainty: the envelope l_m(ω) of a family of measured responses around a
//! nominal model, and a stable, minimum-phase rational weight W_m(s) that overbounds it.
//!
//! # Envelope
//! l_m(ω_i) = max_k |(G_k(jω_i) − G0(jω_i)) / G0(jω_i)| over the family {G_k} (runs at several
//! amplitudes, several units, before/after thermal tests), so that every member is
//! G_k = G0·(1 + Δ_k) with |Δ_k(jω_i)| <= l_m(ω_i).
//!
//! # Weight fit (the optimisation problem)
//! W_m(s) = num(s)/den(s) of order n ∈ {1, 2, 3} (den monic), stable and minimum phase, chosen to
//! minimise the weighted mean log-overbound over log-frequency
//!
//! ```text
//! J = Σ_i w_i · ln(|W_m(jω_i)| / l_m(ω_i)) / Σ_i w_i,   subject to |W_m(jω_i)| >= l_m(ω_i) ∀i,
//! ```
//!
//! with trapezoidal weights w_i in ln ω (J approximates the average of ln(|W_m|/l_m) over
//! log-frequency). Two methods solve it ([`WeightFitMethod`]):
//!
//! * [`WeightFitMethod::Rational`] (default, `rational` submodule): |W_m(jω)|² = P(ω²)/Q(ω²) with
//!   P, Q polynomials of degree n in ω², so the overbound P(ω_i²) >= l_m(ω_i)²·Q(ω_i²) and the
//!   positivity of P and Q are *linear* constraints on the coefficients; J is minimised over
//!   that polyhedron by a primal log-barrier interior-point method (Newton steps, deterministic),
//!   then W_m is recovered by spectral factorisation (left-half-plane roots). Milliseconds.
//! * [`WeightFitMethod::NelderMead`] (the reference, `nelder_mead` submodule): Nelder–Mead over
//!   section parameters of a stable, minimum-phase W_m with the exact smallest feasible gain
//!   (about 1.4 s for order 3 on 300 bins). Kept so the tests can compare the two.
//!
//! Both start order n + 1 from the order-n optimum extended by an exactly cancelling pole/zero
//! pair, so a higher order is never looser. A final exact check evaluates |W_m(jω_i)| from the
//! polynomial coefficients and raises the gain if rounding left any ratio below 1.
//!
//! Units: `freq_hz` in Hz; W_m(s) is continuous with s in rad/s.
use crate::error::{Error, Result};
use crate::lti::{poly_eval, poly_roots, StateSpace, TransferFunction};
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

mod nelder_mead;
mod rational;

/// How the W_m fit is solved (module docs). Both minimise the same objective J under the same
/// overbound constraint.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WeightFitMethod {
    /// |W_m|² as a positive rational function of ω², interior-point method on the linear
    /// overbound constraints, spectral factorisation (default; milliseconds).
    #[default]
    Rational,
    /// Nelder–Mead over stable, minimum-phase section parameters (the reference; about a
    /// second for order 3 on 300 bins).
    NelderMead,
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
    /// Nelder–Mead evaluations per start (default 4000; [`WeightFitMethod::NelderMead`] only).
    pub max_evals: usize,
    /// Solution method (default [`WeightFitMethod::Rational`]).
    #[serde(default)]
    pub method: WeightFitMethod,
}

impl Default for WeightFitOptions {
    fn default() -> Self {
        Self {
            order: 2,
            min_level: 1e-3,
            max_evals: 4000,
            method: WeightFitMethod::Rational,
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
    let band = Band {
        freq_hz: freq_hz.to_vec(),
        nu,
        ln_l: env.iter().map(|l| l.ln()).collect(),
        env,
        weights,
        wsum,
        floored_bins,
        min_level: opts.min_level,
    };
    match opts.method {
        WeightFitMethod::Rational => rational::fit_orders(&band, opts.order),
        WeightFitMethod::NelderMead => nelder_mead::fit_orders(&band, opts),
    }
}

/// The fitting data shared by both methods: measured frequencies, the floored envelope and the
/// trapezoidal log-frequency weights of the objective.
struct Band {
    /// Measured frequencies (Hz).
    freq_hz: Vec<f64>,
    /// The same in rad/s.
    nu: Vec<f64>,
    /// Envelope after flooring (dimensionless, > 0).
    env: Vec<f64>,
    /// ln of `env`.
    ln_l: Vec<f64>,
    /// Trapezoidal weights in ln ω.
    weights: Vec<f64>,
    /// Σ weights.
    wsum: f64,
    floored_bins: usize,
    min_level: f64,
}

/// The weight `num/den` (s in rad/s, `den` monic) with its evidence on `band`: an exact check
/// from the coefficients raises the gain when rounding left any ratio |W_m|/l_m below 1, and
/// every root must lie in the open left half plane.
fn build_weight(
    order: usize,
    mut num: Vec<f64>,
    den: Vec<f64>,
    band: &Band,
    objective: &str,
) -> Result<UncertaintyWeight> {
    let env = &band.env;
    // Exact check from the coefficients; raise k if rounding left any ratio below 1.
    let ratios = |num: &[f64]| -> Vec<f64> {
        band.nu
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
        .zip(&band.weights)
        .map(|(r, w)| w * r.ln())
        .sum::<f64>()
        / band.wsum;
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
        freq_hz: band.freq_hz.clone(),
        envelope: env.to_vec(),
        overbound_ratio: r,
        worst_overbound_ratio: worst,
        min_overbound_ratio: rmin,
        constraint_holds: rmin >= 1.0,
        mean_overbound_db: 20.0 * j / std::f64::consts::LN_10,
        floored_bins: band.floored_bins,
        min_level: band.min_level,
        objective: objective.into(),
    })
}
