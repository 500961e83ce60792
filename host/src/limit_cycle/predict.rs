//! Limit-cycle prediction by harmonic balance: the intersections of the locus of −1/N(A) with
//! the linear part L(e^{jωT}) ([`crate::limit_cycle::lure`]), each with its frequency,
//! amplitude and stability.
//!
//! **Scan.** L is evaluated on a logarithmic frequency grid from `f_min` to the Nyquist
//! frequency (which is included: a discrete loop can oscillate at half the sample rate) and
//! −1/N on a logarithmic amplitude grid above the nonlinearity's threshold; both are polylines
//! in the complex plane and every crossing of a segment of one with a segment of the other is a
//! candidate. **Refine.** Newton's method on F(ω, ln A) = L(e^{jωT}) + 1/N(A) = 0 (two real
//! equations, Jacobian by central differences), kept when it converges inside the scanned box,
//! else the crossing's interpolated values are reported with `refined = false`. Candidates
//! that refine to the same solution are merged. The scan is finite (no iteration without a
//! bound) and non-finite evaluations are skipped, so the call cannot hang or return NaN.
//!
//! **Stability (Loeb criterion).** Perturb the amplitude of a solution (ω₀, A₀) by ΔA; the
//! harmonic-balance equation L(s) + 1/N(A) = 0, with s = σ + jω the complex frequency
//! (z = e^{sT}), moves its root by Δs = −(d(1/N)/dA)/(dL/ds)·ΔA, with dL/ds = −j·dL/dω. The
//! cycle is stable when a larger amplitude decays, Re Δs < 0 for ΔA > 0:
//! Re[(d(1/N)/dA) / (dL/ds)] > 0. (For a relay and a type-1 third-order plant the locus
//! crosses the negative real axis upwards and the cycle is stable, the classical result of
//! Gelb & Vander Velde §2.6; Slotine & Li §5.4.)
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use super::describing::DescribingFunction;
use super::lure::{LureLoop, Nonlinearity, Site};
use crate::error::{Error, Result};
use crate::gap::fit::VelocitySource;
use num_complex::Complex64;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Settings of [`predict`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PredictOptions {
    /// Frequency grid points (log-spaced, default 3000).
    pub n_freq: usize,
    /// Amplitude grid points (log-spaced, default 1200).
    pub n_amp: usize,
    /// Lowest frequency scanned, as a fraction of the Nyquist frequency (default 1e-5).
    pub f_min_rel: f64,
    /// Amplitude range scanned, in multiples of the nonlinearity's scale above its threshold
    /// (default 1e-6 … 1e6).
    pub amp_range: (f64, f64),
}

impl Default for PredictOptions {
    fn default() -> Self {
        Self {
            n_freq: 3000,
            n_amp: 1200,
            f_min_rel: 1e-5,
            amp_range: (1e-6, 1e6),
        }
    }
}

/// One predicted limit cycle.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PredictedLimitCycle {
    /// Oscillation frequency, Hz.
    pub freq_hz: f64,
    /// Amplitude of the sinusoid at the nonlinearity's input (units of that signal: command
    /// for `drive`, velocity for `velocity`, output for `sensor`).
    pub amplitude: f64,
    /// Stable by the Loeb criterion (a stable cycle is the one that shows up in practice; an
    /// unstable one separates decaying from growing oscillations).
    pub stable: bool,
    /// Amplitude of the plant output's fundamental, output units: A for `sensor`,
    /// |G(e^{jωT})|·|N(A)|·A for `drive`, A (velocity output) or A/ω (position output) for
    /// `velocity`.
    pub output_amplitude: f64,
    /// Site of the nonlinearity.
    pub site: Site,
    /// L(e^{jωT}) at the solution (re, im).
    pub loop_value: (f64, f64),
    /// N(A) at the solution (re, im).
    pub df_value: (f64, f64),
    /// Whether Newton's refinement converged (else grid interpolation).
    pub refined: bool,
}

fn cross(a: Complex64, b: Complex64) -> f64 {
    a.re * b.im - a.im * b.re
}

/// Intersection parameters (t, u) in [0, 1]² of segments p0→p1 and q0→q1, if they cross.
fn seg_intersect(p0: Complex64, p1: Complex64, q0: Complex64, q1: Complex64) -> Option<(f64, f64)> {
    let r = p1 - p0;
    let s = q1 - q0;
    let den = cross(r, s);
    if den.abs() <= 1e-300 {
        return None;
    }
    let t = cross(q0 - p0, s) / den;
    let u = cross(q0 - p0, r) / den;
    ((0.0..=1.0).contains(&t) && (0.0..=1.0).contains(&u)).then_some((t, u))
}

struct Solver<'a> {
    lp: &'a LureLoop,
    n_of: &'a dyn Fn(f64) -> Complex64,
    /// Relative step of the numerical derivatives in A (larger for quadrature-based N).
    h_a: f64,
    /// Convergence tolerance of Newton, relative to |L|.
    tol: f64,
    site: Site,
    w_lo: f64,
    w_hi: f64,
    a_lo: f64,
    a_hi: f64,
}

impl Solver<'_> {
    fn l(&self, w: f64) -> Option<Complex64> {
        self.lp
            .linear_part(self.site, w)
            .ok()
            .filter(|v| v.re.is_finite() && v.im.is_finite())
    }
    fn inv_n(&self, a: f64) -> Option<Complex64> {
        let n = (self.n_of)(a);
        (n.norm() > 0.0 && n.re.is_finite() && n.im.is_finite()).then(|| 1.0 / n)
    }
    fn f(&self, lw: f64, la: f64) -> Option<Complex64> {
        Some(self.l(lw.exp())? + self.inv_n(la.exp())?)
    }
    /// Newton on (ln ω, ln A); returns (ω, A) on convergence inside the box.
    fn newton(&self, w0: f64, a0: f64) -> Option<(f64, f64)> {
        let (mut x, mut y) = (w0.ln(), a0.ln());
        let (xl, xh, yl, yh) = (
            self.w_lo.ln(),
            self.w_hi.ln(),
            self.a_lo.ln(),
            self.a_hi.ln(),
        );
        for _ in 0..60 {
            let f = self.f(x, y)?;
            let scale = self.l(x.exp())?.norm().max(1e-300);
            if f.norm() <= self.tol * scale {
                return Some((x.exp(), y.exp()));
            }
            let h = 1e-6;
            let fx = (self.f((x + h).min(xh), y)? - self.f((x - h).max(xl), y)?)
                / ((x + h).min(xh) - (x - h).max(xl));
            let ha = self.h_a;
            let fy = (self.f(x, y + ha)? - self.f(x, y - ha)?) / (2.0 * ha);
            // Solve [fx fy]·[dx dy]ᵀ = −f (real 2×2).
            let det = fx.re * fy.im - fy.re * fx.im;
            if !(det.abs() > 1e-300) {
                return None;
            }
            let dx = (-f.re * fy.im + fy.re * f.im) / det;
            let dy = (-fx.re * f.im + fx.im * f.re) / det;
            let step = (dx * dx + dy * dy).sqrt();
            let damp = if step > 0.5 { 0.5 / step } else { 1.0 };
            x = (x + damp * dx).clamp(xl, xh);
            y = (y + damp * dy).clamp(yl, yh);
            if !(x.is_finite() && y.is_finite()) {
                return None;
            }
        }
        None
    }
    /// Loeb: stable iff Re[(d(1/N)/dA)/(dL/ds)] > 0 (module docs).
    fn stable(&self, w: f64, a: f64) -> Option<bool> {
        let hw = 1e-6 * w;
        let w_plus = (w + hw).min(self.w_hi);
        let w_minus = w - hw;
        let dl_dw = (self.l(w_plus)? - self.l(w_minus)?) / (w_plus - w_minus);
        let dl_ds = dl_dw * Complex64::new(0.0, -1.0);
        let ha = self.h_a * a;
        let dinv_da = (self.inv_n(a + ha)? - self.inv_n(a - ha)?) / (2.0 * ha);
        let r = dinv_da / dl_ds;
        r.re.is_finite().then_some(r.re > 0.0)
    }
}

/// The limit cycles the describing function predicts for `nl` in `lp` (see the module docs),
/// sorted by frequency. Errors only for invalid parameters (non-finite or out of range) or
/// options (grids of fewer than 8 points, a non-positive or non-finite range).
pub fn predict(
    lp: &LureLoop,
    nl: &Nonlinearity,
    opts: &PredictOptions,
) -> Result<Vec<PredictedLimitCycle>> {
    nl.df.validate()?;
    let df = nl.df;
    predict_with(lp, nl, &|a| df.eval(a), 1e-6, 1e-11, opts)
}

/// [`predict`] with the describing function given as a function of the amplitude (e.g. the
/// residual nonlinearity of a compensated loop, [`crate::limit_cycle::residual`]); `nl`
/// supplies the site, threshold and amplitude scale. `h_a` is the relative step of the
/// numerical derivatives in A and `tol` Newton's tolerance relative to |L| (use larger values,
/// e.g. 1e-3 and 1e-6, for a describing function computed by quadrature).
pub fn predict_with(
    lp: &LureLoop,
    nl: &Nonlinearity,
    n_of: &dyn Fn(f64) -> Complex64,
    h_a: f64,
    tol: f64,
    opts: &PredictOptions,
) -> Result<Vec<PredictedLimitCycle>> {
    nl.df.validate()?;
    let (r_lo, r_hi) = opts.amp_range;
    if opts.n_freq < 8
        || opts.n_amp < 8
        || !(opts.f_min_rel.is_finite() && opts.f_min_rel > 0.0 && opts.f_min_rel < 1.0)
        || !(r_lo.is_finite() && r_hi.is_finite() && r_lo > 0.0 && r_hi > r_lo)
    {
        return Err(Error::InvalidArgument(format!(
            "limit-cycle prediction options: need n_freq, n_amp >= 8, 0 < f_min_rel < 1 and \
             0 < amp_range.0 < amp_range.1 (got {opts:?})"
        )));
    }
    let w_hi = lp.nyquist_rad_s();
    let w_lo = w_hi * opts.f_min_rel;
    let scale = nl.df.scale();
    let thr = nl.df.threshold();
    // Saturation is linear (N = 1) up to its limit: scan above it.
    let base = match nl.df {
        DescribingFunction::Saturation { limit } => limit,
        _ => thr,
    };
    let a_lo = base + r_lo * scale;
    let a_hi = base + r_hi * scale;
    let sv = Solver {
        lp,
        n_of,
        h_a,
        tol,
        site: nl.site,
        w_lo,
        w_hi,
        a_lo,
        a_hi,
    };
    let logspace = |lo: f64, hi: f64, n: usize| -> Vec<f64> {
        let (l, h) = (lo.ln(), hi.ln());
        (0..n)
            .map(|i| {
                if i + 1 == n {
                    hi
                } else {
                    (l + (h - l) * i as f64 / (n - 1) as f64).exp()
                }
            })
            .collect()
    };
    let ws = logspace(w_lo, w_hi, opts.n_freq);
    let lw: Vec<Option<Complex64>> = ws.iter().map(|&w| sv.l(w)).collect();
    let amps = logspace(a_lo, a_hi, opts.n_amp);
    let cn: Vec<Option<Complex64>> = amps.iter().map(|&a| sv.inv_n(a).map(|v| -v)).collect();
    // Bounding box of the −1/N polyline, to skip L segments that cannot cross it.
    let (mut bx0, mut bx1, mut by0, mut by1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for c in cn.iter().flatten() {
        bx0 = bx0.min(c.re);
        bx1 = bx1.max(c.re);
        by0 = by0.min(c.im);
        by1 = by1.max(c.im);
    }
    let mut raw: Vec<(f64, f64)> = Vec::new();
    for i in 0..ws.len() - 1 {
        let (Some(p0), Some(p1)) = (lw[i], lw[i + 1]) else {
            continue;
        };
        if p0.re.max(p1.re) < bx0
            || p0.re.min(p1.re) > bx1
            || p0.im.max(p1.im) < by0
            || p0.im.min(p1.im) > by1
        {
            continue;
        }
        for j in 0..amps.len() - 1 {
            let (Some(q0), Some(q1)) = (cn[j], cn[j + 1]) else {
                continue;
            };
            if let Some((t, u)) = seg_intersect(p0, p1, q0, q1) {
                let w = (ws[i].ln() + t * (ws[i + 1].ln() - ws[i].ln())).exp();
                let a = (amps[j].ln() + u * (amps[j + 1].ln() - amps[j].ln())).exp();
                raw.push((w, a));
            }
        }
    }
    // At the Nyquist frequency a discrete L is real: when it is negative the locus ends on the
    // real axis, a touch the segment test can miss by rounding. Test a short vertical segment
    // through it.
    if let Some(ln) = lw.last().copied().flatten() {
        let eps = 1e-9 * ln.norm() + 1e-300;
        if ln.re < 0.0 && ln.im.abs() <= eps {
            let (p0, p1) = (ln - Complex64::new(0.0, eps), ln + Complex64::new(0.0, eps));
            for j in 0..amps.len() - 1 {
                if let (Some(q0), Some(q1)) = (cn[j], cn[j + 1]) {
                    if let Some((_, u)) = seg_intersect(p0, p1, q0, q1) {
                        let a = (amps[j].ln() + u * (amps[j + 1].ln() - amps[j].ln())).exp();
                        raw.push((w_hi, a));
                    }
                }
            }
        }
    }
    let mut out: Vec<PredictedLimitCycle> = Vec::new();
    for (w0, a0) in raw {
        let (w, a, refined) = match sv.newton(w0, a0) {
            Some((w, a)) if (w / w0).ln().abs() < 0.2 && (a / a0).ln().abs() < 0.5 => (w, a, true),
            _ => (w0, a0, false),
        };
        let dup = out.iter().any(|p| {
            (p.freq_hz * 2.0 * PI / w - 1.0).abs() < 1e-3 && (p.amplitude / a - 1.0).abs() < 1e-3
        });
        if dup {
            continue;
        }
        let (Some(l), Some(stable)) = (sv.l(w), sv.stable(w, a)) else {
            continue;
        };
        let n = n_of(a);
        let output_amplitude = match nl.site {
            Site::Sensor => a,
            Site::Drive => lp.plant_response(w).map_or(f64::NAN, |g| g.norm()) * n.norm() * a,
            Site::Velocity => match lp.velocity {
                VelocitySource::Output => a,
                VelocitySource::OutputDerivative => a / w,
            },
        };
        out.push(PredictedLimitCycle {
            freq_hz: w / (2.0 * PI),
            amplitude: a,
            output_amplitude,
            stable,
            site: nl.site,
            loop_value: (l.re, l.im),
            df_value: (n.re, n.im),
            refined,
        });
    }
    out.sort_by(|a, b| a.freq_hz.total_cmp(&b.freq_hz));
    Ok(out)
}
