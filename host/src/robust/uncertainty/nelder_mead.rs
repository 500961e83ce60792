//! The reference W_m fit: Nelder–Mead over stable, minimum-phase section parameters.
//!
//! W_m(s) = k · N(s)/D(s) of order n ∈ {1, 2, 3}, with N and D monic of degree n, built from
//! ⌊n/2⌋ quadratic sections s² + 2ζωs + ω² (ζ ∈ [0.02, 1000], ω > 0 — a section with ζ >= 1 is
//! two real roots) and n mod 2 real sections s + a (a > 0), for the zeros and for the poles.
//! Every parameter vector therefore gives a stable, minimum-phase W_m by construction. For fixed
//! poles and zeros the smallest feasible gain is exact,
//! ln k* = max_i [ln l_m(ω_i) − ln|N/D(jω_i)|], so the constraint is eliminated and the reduced
//! (non-smooth) objective over the section parameters (log ω, log ζ, log a) is minimised by
//! Nelder–Mead ([`crate::optim::nelder_mead`], restarted on a shrinking simplex) from many
//! starts. Order n + 1 is started from the order-n optimum extended by an exactly cancelling
//! pole/zero pair.
//!
//! This was the only method before the rational fit (1.41 s for order 3 on 300 bins); it is kept as
//! [`super::WeightFitMethod::NelderMead`] so the tests can compare the rational fit with it.
use super::{build_weight, Band, UncertaintyWeight, WeightFitOptions};
use crate::error::{Error, Result};
use crate::lti::poly_mul;
use crate::optim::nelder_mead;

const OBJECTIVE: &str = "minimise Σ_i w_i·ln(|W_m(jω_i)|/l_m(ω_i)) / Σ_i w_i (w_i: trapezoidal \
                         weights in ln ω) subject to |W_m(jω_i)| >= l_m(ω_i) at every measured \
                         frequency; W_m stable and minimum phase by its section parametrisation; \
                         Nelder–Mead on the section parameters (reference method)";

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

/// The reduced objective over the section parameters of one band.
struct Problem<'a> {
    nu: &'a [f64],
    ln_l: &'a [f64],
    weights: &'a [f64],
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
            .zip(self.ln_l)
            .zip(self.weights)
            .map(|((s, l), w)| w * (s + ln_k - l))
            .sum::<f64>()
            / self.wsum;
        (j, ln_k)
    }
}

/// Fits W_m of every order 1..=`opts.order` by Nelder–Mead (module docs), increasing order.
pub(super) fn fit_orders(band: &Band, opts: &WeightFitOptions) -> Result<Vec<UncertaintyWeight>> {
    let nu = &band.nu;
    let m = nu.len();
    let prob = Problem {
        nu,
        ln_l: &band.ln_l,
        weights: &band.weights,
        wsum: band.wsum,
    };
    let (w_lo, w_hi) = (nu[0], nu[m - 1]);
    let grid: Vec<f64> = crate::robust::norms::logspace(w_lo / 10.0, w_hi * 10.0, 7)
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
        let k = ln_k.exp();
        let num: Vec<f64> = lay.poly(&p[..h]).iter().map(|c| c * k).collect();
        let fit = build_weight(order, num, lay.poly(&p[h..]), band, OBJECTIVE)?;
        fits.push(fit);
        prev = Some((zq, zr, pq, pr));
    }
    Ok(fits)
}
