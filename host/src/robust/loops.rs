//! The one-degree-of-freedom SISO feedback loop and its classical margins.
//!
//! ```text
//!   r ──(+)── e ──► K ── u ──► G ──┬──► y
//!        ▲−                         │
//!        └──────────────────────────┘
//! ```
//!
//! Loop transfer L = G·K; sensitivity S = 1/(1 + L) (r → e, output disturbance → y);
//! complementary sensitivity T = L/(1 + L) (r → y, measurement noise → −y); control sensitivity
//! KS = K/(1 + L) (r or noise → u); input-disturbance sensitivity GS = G/(1 + L). All share the
//! closed-loop state [x_G; x_K] (a non-minimal realisation of S and KS is harmless for norms).
//!
//! Margins ([`margins`]): crossings are bracketed on a dense logarithmic grid augmented with
//! points around every lightly damped pole and zero of L (so narrow resonances are not
//! stepped over), then refined by bisection to relative width 1e-13. Gain crossovers solve
//! |L(jω)| = 1; phase crossovers solve Im L(jω) = 0 with Re L(jω) < 0 (no phase unwrapping
//! needed). For discrete loops the Nyquist frequency π/ts, where L is real, is tested
//! explicitly.
use super::norms::balance;
use crate::error::{Error, Result};
use crate::lti::{FreqEvaluator, StateSpace};
use num_complex::Complex64;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// A SISO feedback loop: plant G and controller K with the same sample time, and the closed
/// loop transfers built from them (see the module docs).
#[derive(Debug, Clone)]
pub struct FeedbackLoop {
    /// Plant G (1×1).
    pub plant: StateSpace,
    /// Controller K (1×1), same `ts` as the plant.
    pub controller: StateSpace,
    /// L = G·K (states [x_K; x_G]).
    pub l: StateSpace,
    /// S = 1/(1 + L).
    pub s: StateSpace,
    /// T = L/(1 + L).
    pub t: StateSpace,
    /// KS = K/(1 + G·K) (reference or noise to actuator command).
    pub ks: StateSpace,
    /// GS = G/(1 + K·G) (input disturbance to output).
    pub gs: StateSpace,
}

impl FeedbackLoop {
    /// Builds the loop. Errors when either model is not SISO, the sample times differ, or the
    /// loop is algebraically ill-posed (1 + D_G·D_K = 0).
    pub fn new(plant: &StateSpace, controller: &StateSpace) -> Result<Self> {
        if !plant.is_siso() || !controller.is_siso() {
            return Err(Error::InvalidArgument(format!(
                "feedback loop needs SISO models, got plant {}x{} and controller {}x{}",
                plant.n_outputs(),
                plant.n_inputs(),
                controller.n_outputs(),
                controller.n_inputs()
            )));
        }
        // Every transfer is balanced (diagonal state scaling, exact in floating point) so that
        // pole and norm computations see well-scaled matrices.
        let l = balance(&controller.series(plant)?)?;
        let one = StateSpace::identity(1, plant.ts)?;
        let s = balance(&one.feedback(&l)?)?;
        let t = balance(&l.feedback(&one)?)?;
        let ks = balance(&controller.feedback(plant)?)?;
        let gs = balance(&plant.feedback(controller)?)?;
        Ok(Self {
            plant: plant.clone(),
            controller: controller.clone(),
            l,
            s,
            t,
            ks,
            gs,
        })
    }

    /// True for a discrete-time loop.
    pub fn is_discrete(&self) -> bool {
        self.plant.is_discrete()
    }

    /// Closed-loop poles (eigenvalues of the closed-loop state matrix), least stable first.
    pub fn closed_loop_poles(&self) -> Result<Vec<Complex64>> {
        self.t.poles()
    }

    /// Stability abscissa of the closed loop: the largest real part of the closed-loop poles
    /// (rad/s; continuous) or the largest pole modulus (discrete). Stable iff < 0 resp. < 1.
    /// A loop without states returns −∞ (continuous) or 0 (discrete).
    pub fn stability_abscissa(&self) -> Result<f64> {
        let p = self.closed_loop_poles()?;
        Ok(if self.is_discrete() {
            p.iter().map(|z| z.norm()).fold(0.0, f64::max)
        } else {
            p.iter().map(|s| s.re).fold(f64::NEG_INFINITY, f64::max)
        })
    }

    /// True when every closed-loop pole is strictly inside the stability region.
    pub fn is_stable(&self) -> Result<bool> {
        let a = self.stability_abscissa()?;
        Ok(if self.is_discrete() { a < 1.0 } else { a < 0.0 })
    }
}

/// Gain and phase margins of a loop transfer L, with every crossing found.
///
/// `gain_margin` is the factor by which the loop gain may change before a phase crossover
/// becomes a closed-loop pole on the stability boundary; of all phase crossovers the one with
/// the smallest |log gain margin| is reported (it may be < 1, a gain-reduction margin, for
/// conditionally stable loops). `phase_margin_deg` is the smallest of 180° + ∠L(jω) (wrapped to
/// (−180°, 180°]) over all gain crossovers. Infinite margins (no crossing) serialise as JSON
/// `null` and are documented by the `*_hz` fields being `None`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Margins {
    /// Gain margin as a factor (∞ when L never crosses the negative real axis).
    pub gain_margin: f64,
    /// 20·log10(gain_margin), dB.
    pub gain_margin_db: f64,
    /// Frequency (Hz) of the phase crossover that sets `gain_margin`.
    pub phase_crossover_hz: Option<f64>,
    /// Phase margin in degrees (∞ when |L| never crosses 1). For a stable closed loop, the
    /// smallest phase change (lag or lead) at any gain crossover that puts L on −1:
    /// 180° − |∠L|, never negative. For an unstable closed loop, 180° + ∠L wrapped to
    /// (−180°, 180°] (negative at a crossover past −180°).
    pub phase_margin_deg: f64,
    /// Frequency (Hz) of the gain crossover that sets `phase_margin_deg`.
    pub gain_crossover_hz: Option<f64>,
    /// Delay margin in seconds: the smallest (180° + ∠L)/ω_gc in radians (the phase lag a delay
    /// must add to reach −1) over gain crossovers with positive phase margin (∞ when there is
    /// none).
    pub delay_margin_s: f64,
    /// Every gain crossover frequency found, Hz, increasing.
    pub gain_crossovers_hz: Vec<f64>,
    /// Every phase crossover frequency found, Hz, increasing.
    pub phase_crossovers_hz: Vec<f64>,
}

/// Frequency grid (rad/s) for crossing searches on `sys`: `points_per_decade` log-spaced
/// points over the span of its pole/zero moduli widened by 100× each way and including
/// `[w_lo, w_hi]` when given, capped at the Nyquist frequency for discrete models, plus points
/// around every lightly damped pole of `sys` (±0.25…3 half-power widths). Sorted, > 0.
pub fn analysis_grid(
    sys: &StateSpace,
    extra_range_rad_s: Option<(f64, f64)>,
    points_per_decade: usize,
) -> Result<Vec<f64>> {
    let poles = sys.poles()?;
    let discrete = sys.is_discrete();
    let to_s = |z: Complex64| -> Complex64 {
        if discrete {
            z.ln() / sys.ts
        } else {
            z
        }
    };
    let mods: Vec<Complex64> = poles
        .iter()
        .filter(|z| !discrete || z.norm() > 1e-12)
        .map(|&z| to_s(z))
        .collect();
    // Moduli far below the largest are integrators computed slightly off zero: ignore them.
    let top = mods.iter().map(|s| s.norm()).fold(0.0, f64::max);
    let mags: Vec<f64> = mods
        .iter()
        .map(|s| s.norm())
        .filter(|m| *m > 1e-7 * top && *m > 1e-12)
        .collect();
    let (mut lo, mut hi) = if mags.is_empty() {
        (1e-2, 1e3)
    } else {
        (
            mags.iter().copied().fold(f64::INFINITY, f64::min) / 100.0,
            mags.iter().copied().fold(0.0, f64::max) * 100.0,
        )
    };
    if let Some((a, b)) = extra_range_rad_s {
        lo = lo.min(a);
        hi = hi.max(b);
    }
    let nyq = if discrete { PI / sys.ts } else { f64::INFINITY };
    hi = hi.min(nyq * (1.0 - 1e-9));
    lo = lo.min(hi / 10.0);
    let decades = (hi / lo).log10().max(0.1);
    let n = ((decades * points_per_decade as f64).ceil() as usize).max(10);
    let mut grid = super::norms::logspace(lo, hi, n);
    for s in mods
        .iter()
        .filter(|s| s.im > 0.0 && s.norm() > 1e-7 * top && s.norm() > 1e-12)
    {
        let wn = s.norm();
        let zeta = (-s.re / wn).clamp(1e-6, 1.0);
        for k in [-3.0, -2.0, -1.0, -0.5, -0.25, 0.0, 0.25, 0.5, 1.0, 2.0, 3.0] {
            let w = wn * (1.0 + k * zeta);
            if w > 0.0 && w < hi {
                grid.push(w);
            }
        }
    }
    grid.sort_by(f64::total_cmp);
    grid.dedup_by(|a, b| (*a - *b).abs() <= 1e-12 * *b);
    Ok(grid)
}

/// Refines a root of `f` (sign change between `a` and `b`, a < b) by bisection in log ω
/// until the relative width is 1e-13.
pub(crate) fn bisect_root<F: Fn(f64) -> Result<f64>>(f: F, mut a: f64, mut b: f64) -> Result<f64> {
    let mut fa = f(a)?;
    for _ in 0..200 {
        if b - a <= 1e-13 * b {
            break;
        }
        let m = if a > 0.0 {
            (a * b).sqrt()
        } else {
            0.5 * (a + b)
        };
        let m = if m <= a || m >= b { 0.5 * (a + b) } else { m };
        let fm = f(m)?;
        if (fm <= 0.0) == (fa <= 0.0) {
            a = m;
            fa = fm;
        } else {
            b = m;
        }
    }
    Ok(0.5 * (a + b))
}

/// Frequencies (rad/s) in the grid range where `f` changes sign, refined by bisection.
pub(crate) fn sign_changes<F: Fn(f64) -> Result<f64>>(f: &F, grid: &[f64]) -> Result<Vec<f64>> {
    let mut out = Vec::new();
    let mut prev: Option<(f64, f64)> = None;
    for &w in grid {
        // A grid point that lands on a pole (an undamped mode) is skipped.
        let Ok(v) = f(w) else { continue };
        if let Some((wp, vp)) = prev {
            if (vp <= 0.0) != (v <= 0.0) {
                out.push(bisect_root(f, wp, w)?);
            }
        }
        prev = Some((w, v));
    }
    Ok(out)
}

/// Whether the unity negative-feedback loop around the SISO loop transfer `l` is stable
/// (closed-loop A = A − B·C/(1 + D)); `false` when the loop is ill-posed (D = −1) or its poles
/// cannot be computed.
fn closed_loop_stable(l: &StateSpace) -> bool {
    let den = 1.0 + l.d[(0, 0)];
    if !(den.abs() > 0.0) {
        return false;
    }
    let a_cl = &l.a - &l.b * &l.c * faer::Scale(1.0 / den);
    StateSpace::new(a_cl, l.b.clone(), l.c.clone(), l.d.clone(), l.ts)
        .and_then(|cl| cl.is_stable(0.0))
        .unwrap_or(false)
}

/// Gain and phase margins of the SISO loop transfer `l` (see [`Margins`]). `extra_range_rad_s`
/// widens the search grid (e.g. around the intended crossover).
pub fn margins(l: &StateSpace, extra_range_rad_s: Option<(f64, f64)>) -> Result<Margins> {
    if !l.is_siso() {
        return Err(Error::InvalidArgument(
            "margins need a SISO loop transfer".into(),
        ));
    }
    let ev = FreqEvaluator::new(l);
    let h = |w: f64| -> Result<Complex64> { Ok(ev.at_rad_s(w)?[(0, 0)]) };
    let grid = analysis_grid(l, extra_range_rad_s, 400)?;
    let ln_mag = |w: f64| -> Result<f64> { Ok(h(w)?.norm().ln()) };
    let gcs = sign_changes(&ln_mag, &grid)?;
    let im = |w: f64| -> Result<f64> {
        let v = h(w)?;
        Ok(v.im / v.norm().max(f64::MIN_POSITIVE))
    };
    let mut pcs: Vec<f64> = sign_changes(&im, &grid)?
        .into_iter()
        .filter(|&w| {
            h(w).map(|v| v.re < 0.0 && v.im.abs() <= 1e-6 * v.norm())
                .unwrap_or(false)
        })
        .collect();
    if l.is_discrete() {
        let nyq = PI / l.ts;
        if let Ok(v) = h(nyq) {
            if v.re < 0.0 && v.im.abs() <= 1e-9 * v.norm() {
                pcs.push(nyq);
            }
        }
    }
    let mut gm = f64::INFINITY;
    let mut w_pc = None;
    for &w in &pcs {
        let g = 1.0 / h(w)?.norm();
        if w_pc.is_none() || g.ln().abs() < gm.ln().abs() {
            gm = g;
            w_pc = Some(w);
        }
    }
    let stable = closed_loop_stable(l);
    let mut pm = f64::INFINITY;
    let mut w_gc = None;
    let mut dm = f64::INFINITY;
    for &w in &gcs {
        let arg = h(w)?.arg().to_degrees();
        // Phase lag that puts L(jω) on −1, in (0, 360].
        let lag = 180.0 + arg;
        let p = if stable {
            // The smallest phase change, lag or lead, that makes the loop touch −1: at a
            // crossover where ∠L lies above 0° (after a resonance, e.g. an H∞ loop) a lead of
            // 180° − ∠L gets there first.
            180.0 - arg.abs()
        } else if lag > 180.0 {
            lag - 360.0
        } else {
            lag
        };
        if w_gc.is_none() || p < pm {
            pm = p;
            w_gc = Some(w);
        }
        if p > 0.0 && w > 0.0 {
            dm = dm.min(lag.to_radians() / w);
        }
    }
    let hz = |w: f64| w / (2.0 * PI);
    Ok(Margins {
        gain_margin: gm,
        gain_margin_db: 20.0 * gm.log10(),
        phase_crossover_hz: w_pc.map(hz),
        phase_margin_deg: pm,
        gain_crossover_hz: w_gc.map(hz),
        delay_margin_s: dm,
        gain_crossovers_hz: gcs.iter().map(|&w| hz(w)).collect(),
        phase_crossovers_hz: pcs.iter().map(|&w| hz(w)).collect(),
    })
}
