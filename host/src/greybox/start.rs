//! Start values of the physical parameters, mapped directly from the poles and zeros of a
//! black-box model of the same data (no hand-made start).
//!
//! The discrete black-box model's poles and zeros map to continuous ones by s = ln(z)/T
//! (zeros beyond 0.8 of Nyquist, the sampling zeros of the zero-order hold, are dropped). Each
//! structure's transfer function is written with those roots and one unknown gain; the gain is
//! the least-squares ratio of the black-box response to that shape over the band, and the
//! parameters follow in closed form with the known ones (see each function).
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use super::structure::{Measured, Structure};
use crate::error::{Error, Result};
use crate::lti::StateSpace;
use num_complex::Complex64;
use std::f64::consts::PI;

/// Continuous poles and (non-sampling) zeros of a discrete SISO model, rad/s.
struct Roots {
    poles: Vec<Complex64>,
    zeros: Vec<Complex64>,
}

fn continuous_roots(bb: &StateSpace) -> Result<Roots> {
    let ts = bb.ts;
    let to_s = |z: Complex64| z.ln() / ts;
    let nyquist = PI / ts;
    let poles: Vec<Complex64> = bb.poles()?.into_iter().map(to_s).collect();
    let zeros: Vec<Complex64> = bb
        .to_transfer_function()?
        .zeros()?
        .into_iter()
        .filter(|z| z.norm() > 1e-12)
        .map(to_s)
        .filter(|s| s.is_finite() && s.im.abs() < 0.8 * nyquist && s.norm() < 0.8 * nyquist)
        .collect();
    if poles.iter().any(|p| !p.is_finite()) {
        return Err(Error::Numerical(
            "grey-box start: the black-box model has a pole at z = 0 (no continuous equivalent)"
                .into(),
        ));
    }
    Ok(Roots { poles, zeros })
}

/// The complex pair (upper member) of largest imaginary part, if any.
fn complex_pair(roots: &[Complex64]) -> Option<Complex64> {
    roots
        .iter()
        .copied()
        .filter(|r| r.im > 1e-9 * r.norm().max(1.0))
        .max_by(|a, b| a.im.total_cmp(&b.im))
}

/// ω_n (rad/s) and ζ of a root pair with upper member `r`.
fn natural(r: Complex64) -> (f64, f64) {
    let w = r.norm();
    (w, (-r.re / w).max(1e-4))
}

/// Least-squares gain g minimising Σ |G_bb(jω) − g·H(jω)|² / |G_bb|² over `grid_hz`.
fn gain(bb: &StateSpace, grid_hz: &[f64], shape: impl Fn(Complex64) -> Complex64) -> Result<f64> {
    let g = bb.freq_responses_siso_hz(grid_hz)?;
    let (mut num, mut den) = (0.0, 0.0);
    for (f, gk) in grid_hz.iter().zip(g) {
        let h = shape(Complex64::new(0.0, 2.0 * PI * f));
        let w = 1.0 / gk.norm_sqr().max(f64::MIN_POSITIVE);
        num += w * (h.conj() * gk).re;
        den += w * h.norm_sqr();
    }
    let g = num / den;
    if !(g.is_finite() && g > 0.0) {
        return Err(Error::Numerical(format!(
            "grey-box start: the black-box response does not match the structure's shape \
             (gain {g:.3e}); is the input/output pair right?"
        )));
    }
    Ok(g)
}

/// Start values (SI, structure order) from the discrete black-box model `bb` of the structure's
/// order, the known parameters (`known[i]`), and a frequency grid inside the excited band.
pub(super) fn start_values(
    structure: Structure,
    bb: &StateSpace,
    known: &[Option<f64>],
    grid_hz: &[f64],
) -> Result<Vec<f64>> {
    let roots = continuous_roots(bb)?;
    let k = |name: &str| structure.index_of(name).and_then(|i| known[i]);
    let mut p = match structure {
        Structure::Stage(out) => stage(out, &roots, bb, grid_hz, k("m"), k("k"), k("Kf"))?,
        Structure::DcMotor => {
            let (r, l) = k("R").zip(k("L")).ok_or_else(|| {
                Error::InvalidArgument("grey-box start: dc-motor needs R and L known".into())
            })?;
            dc_motor(&roots, bb, grid_hz, r, l)?
        }
        Structure::TwoMass(out) => {
            two_mass(out, &roots, bb, grid_hz, [k("Jm"), k("Jl"), k("Kt")], false)?
        }
        Structure::TwoMassLag => two_mass(
            Measured::Velocity,
            &roots,
            bb,
            grid_hz,
            [k("Jm"), k("Jl"), k("Kt")],
            true,
        )?,
    };
    for (v, kv) in p.iter_mut().zip(known) {
        if let Some(kv) = kv {
            *v = *kv;
        }
    }
    // Dampings may come out ~0 or slightly negative from noise; the fit is in log-parameters.
    let floor = p
        .iter()
        .copied()
        .filter(|v| *v > 0.0)
        .fold(f64::INFINITY, f64::min);
    for v in &mut p {
        if !(*v > 0.0) {
            *v = 1e-6 * floor.min(1.0);
        }
    }
    Ok(p)
}

/// Stage: K_f/(m s² + c s + k) = g/(s² + a₁ s + a₀) (times s for velocity), g = K_f/m,
/// a₁ = c/m, a₀ = k/m; the known parameter fixes m.
fn stage(
    out: Measured,
    roots: &Roots,
    bb: &StateSpace,
    grid: &[f64],
    m: Option<f64>,
    k: Option<f64>,
    kf: Option<f64>,
) -> Result<Vec<f64>> {
    let mut poles = roots.poles.clone();
    poles.sort_by(|a, b| a.norm().total_cmp(&b.norm()));
    let (a1, a0) = match poles.as_slice() {
        [p1, p2, ..] => (-(p1 + p2).re, (p1 * p2).re),
        _ => {
            return Err(Error::Numerical(
                "grey-box start: stage needs two poles".into(),
            ))
        }
    };
    if !(a0 > 0.0) {
        return Err(Error::Numerical(format!(
            "grey-box start: the black-box poles {:.3e}, {:.3e} rad/s are not a stage's \
             (no stiffness: k/m = {a0:.3e})",
            poles[0], poles[1]
        )));
    }
    let vel = out == Measured::Velocity;
    let g = gain(bb, grid, |s| {
        let h = 1.0 / (s * s + a1 * s + a0);
        if vel {
            h * s
        } else {
            h
        }
    })?;
    let mass = m
        .or(kf.map(|kf| kf / g))
        .or(k.map(|k| k / a0))
        .ok_or_else(|| {
            Error::InvalidArgument("grey-box start: stage needs one of m, k, Kf known".into())
        })?;
    Ok(vec![mass, a1 * mass, a0 * mass, g * mass])
}

/// DC motor: K/(LJ s² + (Lb + RJ) s + Rb + K²) = g/(s² + a₁ s + a₀) with g = K/(LJ),
/// a₁ = b/J + R/L, a₀ = (Rb + K²)/(LJ). With R and L known: β = b/J = a₁ − R/L, κ = K/J = gL,
/// J = (a₀L − Rβ)/κ², K = κJ, b = βJ.
fn dc_motor(roots: &Roots, bb: &StateSpace, grid: &[f64], r: f64, l: f64) -> Result<Vec<f64>> {
    let (a1, a0) = match roots.poles.as_slice() {
        [p1, p2, ..] => (-(p1 + p2).re, (p1 * p2).re),
        _ => {
            return Err(Error::Numerical(
                "grey-box start: dc-motor needs two poles".into(),
            ))
        }
    };
    let g = gain(bb, grid, |s| 1.0 / (s * s + a1 * s + a0))?;
    let beta = (a1 - r / l).max(1e-6 * a1.abs());
    let kappa = g * l;
    let mut j = (a0 * l - r * beta) / (kappa * kappa);
    if !(j > 0.0) {
        // Noise put a₀L below Rβ: take the friction-free reading (β → 0).
        j = a0 * l / (kappa * kappa);
    }
    if !(j.is_finite() && j > 0.0) {
        return Err(Error::Numerical(format!(
            "grey-box start: no positive inertia fits the black-box poles (a0 = {a0:.3e})"
        )));
    }
    Ok(vec![r, l, kappa * j, j, beta * j])
}

/// Two-mass axis, motor-side sensor: with ω_a (anti-resonance) and ω_r (resonance),
/// ω_r²/ω_a² = (J_m + J_l)/J_m and ω_a² = k/J_l; the rigid-body gain g = K_t/(J_m + J_l) comes
/// from the response over the band, the real pole p₀ ≈ −b/(J_m + J_l), and c = 2ζ_a ω_a J_l.
/// With `lag` (velocity output), the fastest real pole is −1/τ and τ is appended.
fn two_mass(
    out: Measured,
    roots: &Roots,
    bb: &StateSpace,
    grid: &[f64],
    [jm, jl, kt]: [Option<f64>; 3],
    lag: bool,
) -> Result<Vec<f64>> {
    let res = complex_pair(&roots.poles).ok_or_else(|| {
        Error::Numerical(
            "grey-box start: the black-box model has no resonance (complex pole pair): the \
             two-mass structure needs its resonance inside the excited band"
                .into(),
        )
    })?;
    let anti = roots
        .zeros
        .iter()
        .copied()
        .filter(|z| z.im > 0.0 && z.norm() < res.norm())
        .max_by(|a, b| a.im.total_cmp(&b.im))
        .ok_or_else(|| {
            Error::Numerical(
                "grey-box start: the black-box model has no anti-resonance (complex zero pair \
                 below the resonance): is the sensor on the motor side?"
                    .into(),
            )
        })?;
    let (wr, zr) = natural(res);
    let (wa, za) = natural(anti);
    let mut real: Vec<f64> = roots
        .poles
        .iter()
        .filter(|p| p.im.abs() <= 1e-9 * p.norm().max(1.0))
        .map(|p| p.re)
        .collect();
    real.sort_by(|a, b| a.abs().total_cmp(&b.abs()));
    // Position output: the pole nearest 0 is the integrator of the angle.
    let p0 = match out {
        Measured::Velocity => real.first().copied(),
        Measured::Position => real.get(1).copied(),
    }
    .unwrap_or(0.0)
    .min(0.0);
    let tau = if lag {
        let fastest = real.last().copied().filter(|_| real.len() >= 2);
        let p = fastest.ok_or_else(|| {
            Error::Numerical(
                "grey-box start: two-mass-lag needs two real poles in the black-box model (the \
                 rigid body and the lag); the model has another complex pair instead"
                    .into(),
            )
        })?;
        if !(p < 0.0) {
            return Err(Error::Numerical(format!(
                "grey-box start: the fastest real pole {p:.3e} rad/s is not a stable lag"
            )));
        }
        Some(-1.0 / p)
    } else {
        None
    };
    let pos = out == Measured::Position;
    let g = gain(bb, grid, |s| {
        let mut h = (wr * wr / (wa * wa)) * (s * s + 2.0 * za * wa * s + wa * wa)
            / ((s - p0) * (s * s + 2.0 * zr * wr * s + wr * wr));
        if let Some(t) = tau {
            h /= t * s + 1.0;
        }
        if pos {
            h / s
        } else {
            h
        }
    })?;
    let split = (wa * wa) / (wr * wr); // J_m / J_total
    let j_total = kt
        .map(|kt| kt / g)
        .or(jm.map(|jm| jm / split))
        .or(jl.map(|jl| jl / (1.0 - split)))
        .ok_or_else(|| {
            Error::InvalidArgument("grey-box start: two-mass needs one of Kt, Jm, Jl known".into())
        })?;
    let j_m = j_total * split;
    let j_l = j_total - j_m;
    let mut p = vec![
        j_m,
        j_l,
        j_l * wa * wa,
        2.0 * za * wa * j_l,
        -p0 * j_total,
        g * j_total,
    ];
    p.extend(tau);
    Ok(p)
}
