//! H∞ norm of a stable LTI model by bisection on the imaginary-axis eigenvalues of the
//! Hamiltonian matrix, with the frequency of the peak.
//!
//! Method (Boyd, Balakrishnan & Kabamba 1989; the two-step quadratically convergent variant of
//! Bruinsma & Steinbuch 1990): for a stable continuous model G = (A, B, C, D) and
//! γ > σ̄(D), let R = γ²I − DᵀD and A_γ = A + B R⁻¹ DᵀC. Then γ is a singular value of
//! G(jω) if and only if jω is an eigenvalue of the Hamiltonian
//!
//! ```text
//! H(γ) = [ A_γ                    B R⁻¹ Bᵀ ]
//!        [ −Cᵀ(I + D R⁻¹ Dᵀ)C     −A_γᵀ    ]
//! ```
//!
//! Starting from a lower bound γ_lb (largest σ̄ at ω = 0, ω = ∞ and at the pole moduli), each
//! step tests γ = (1 + 2ε)·γ_lb: if H(γ) has no imaginary-axis eigenvalue, γ is an upper bound
//! and the search stops; otherwise σ̄(G) exceeds γ between consecutive crossing frequencies
//! ω_i < ω_{i+1}, and σ̄ at their midpoints gives the next lower bound. If the midpoints raise
//! the bound by less than ε the crossings were rounding artefacts (the test for "on the axis"
//! is deliberately generous, so a genuine crossing is never missed) and γ is accepted.
//!
//! Discrete models are mapped to continuous time by the norm-preserving bilinear (Cayley)
//! transform z = (1 + s)/(1 − s) ([`bilinear_to_continuous`]), with ω_c = tan(θ/2) where
//! θ = ω·ts is the normalised discrete frequency.
//!
//! Units: frequencies in rad/s (`_rad_s`) and Hz (`_hz`); discrete peaks lie in [0, π/ts].
use crate::error::{Error, Result};
use crate::lti::{eigenvalues, FreqEvaluator, StateSpace};
use faer::Mat;
use num_complex::Complex64;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// The H∞ norm of a stable model, bracketed: `gamma_lower <= ‖G‖∞ <= gamma`, with
/// `gamma <= (1 + 2·rel_tol)·gamma_lower`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HinfNorm {
    /// Certified upper bound of ‖G‖∞ (no Hamiltonian eigenvalue on the imaginary axis at this
    /// level). This is the value to compare against limits.
    pub gamma: f64,
    /// Attained lower bound: σ̄(G) at `peak_w_rad_s`.
    pub gamma_lower: f64,
    /// Frequency of the peak in rad/s (physical frequency for discrete models, in [0, π/ts]).
    /// `f64::INFINITY` when the supremum is the high-frequency gain σ̄(D) of a continuous model
    /// (serialised as JSON `null`).
    pub peak_w_rad_s: f64,
    /// `peak_w_rad_s / 2π`, Hz.
    pub peak_f_hz: f64,
    /// Number of Hamiltonian eigenvalue problems solved.
    pub iterations: usize,
    /// Relative tolerance ε of the bracket.
    pub rel_tol: f64,
}

/// Default relative tolerance of [`hinf_norm`].
pub const DEFAULT_HINF_REL_TOL: f64 = 1e-9;

/// Largest singular value of a complex matrix (|g| for 1×1).
pub fn sigma_max(g: &Mat<Complex64>) -> Result<f64> {
    if g.nrows() == 1 && g.ncols() == 1 {
        return Ok(g[(0, 0)].norm());
    }
    let sv = g
        .singular_values()
        .map_err(|e| Error::Numerical(format!("complex SVD did not converge: {e:?}")))?;
    Ok(sv.into_iter().fold(0.0, f64::max))
}

/// Norm-preserving bilinear (Cayley) map of a discrete model to continuous time,
/// z = (1 + s)/(1 − s): with M = (I + A)⁻¹, A_c = M(A − I), B_c = √2·M·B, C_c = √2·C·M,
/// D_c = D − C·M·B. G_d(e^{jθ}) = G_c(j·tan(θ/2)); a Schur-stable A gives a Hurwitz A_c.
/// Errors when A has an eigenvalue at −1 (it then maps to s = ∞). The result has `ts = 0`.
pub fn bilinear_to_continuous(sys: &StateSpace) -> Result<StateSpace> {
    if !sys.is_discrete() {
        return Err(Error::InvalidArgument(
            "bilinear_to_continuous: the model is already continuous (ts = 0)".into(),
        ));
    }
    let n = sys.n_states();
    let ipa = &sys.a + Mat::<f64>::identity(n, n);
    let minv = crate::lti::solve_square(
        ipa.as_ref(),
        Mat::<f64>::identity(n, n).as_ref(),
        "bilinear map: I + A (A has an eigenvalue at z = −1?)",
    )?;
    let s2 = std::f64::consts::SQRT_2;
    let ac = &minv * (&sys.a - Mat::<f64>::identity(n, n));
    let mb = &minv * &sys.b;
    let bc = &mb * faer::Scale(s2);
    let cc = (&sys.c * &minv) * faer::Scale(s2);
    let dc = &sys.d - &sys.c * &mb;
    StateSpace::new(ac, bc, cc, dc, 0.0)
}

/// Diagonal similarity scaling (powers of two, so exact in floating point) of the states that
/// balances the row and column norms of the system matrix [[A, B], [C, 0]] (Parlett–Reinsch
/// iteration applied to the state block, as in MATLAB's `ssbal`). The transfer function is
/// unchanged; badly scaled realisations (e.g. companion forms with coefficients spanning many
/// decades) become well conditioned for eigenvalue problems such as the Hamiltonian test.
pub fn balance(sys: &StateSpace) -> Result<StateSpace> {
    let (n, m, p) = (sys.n_states(), sys.n_inputs(), sys.n_outputs());
    let mut a = sys.a.clone();
    let mut b = sys.b.clone();
    let mut c = sys.c.clone();
    for _sweep in 0..100 {
        let mut changed = false;
        for i in 0..n {
            let col: f64 = (0..n)
                .filter(|&k| k != i)
                .map(|k| a[(k, i)].abs())
                .sum::<f64>()
                + (0..p).map(|k| c[(k, i)].abs()).sum::<f64>();
            let row: f64 = (0..n)
                .filter(|&k| k != i)
                .map(|k| a[(i, k)].abs())
                .sum::<f64>()
                + (0..m).map(|k| b[(i, k)].abs()).sum::<f64>();
            if col == 0.0 || row == 0.0 {
                continue;
            }
            // Find f = 2^k with col·f ≈ row/f.
            let mut f = 1.0f64;
            let (mut cc, mut rr) = (col, row);
            while cc < rr / 2.0 {
                cc *= 2.0;
                rr /= 2.0;
                f *= 2.0;
            }
            while cc > rr * 2.0 {
                cc /= 2.0;
                rr *= 2.0;
                f /= 2.0;
            }
            if (cc + rr) < 0.95 * (col + row) {
                changed = true;
                for k in 0..n {
                    a[(k, i)] *= f;
                    a[(i, k)] /= f;
                }
                for k in 0..p {
                    c[(k, i)] *= f;
                }
                for k in 0..m {
                    b[(i, k)] /= f;
                }
            }
        }
        if !changed {
            break;
        }
    }
    StateSpace::new(a, b, c, sys.d.clone(), sys.ts)
}

fn check_stable(sys: &StateSpace) -> Result<()> {
    let poles = sys.poles()?;
    if let Some(p) = poles.first() {
        let unstable = if sys.is_discrete() {
            p.norm() >= 1.0
        } else {
            p.re >= 0.0
        };
        if unstable {
            return Err(Error::Numerical(format!(
                "H∞ norm is infinite: the model is not stable (pole at {p:.6e} {})",
                if sys.is_discrete() {
                    "on or outside the unit circle"
                } else {
                    "in the closed right half plane"
                }
            )));
        }
    }
    Ok(())
}

/// H∞ norm (peak gain over frequency) of a stable continuous or discrete model with the default
/// relative tolerance [`DEFAULT_HINF_REL_TOL`]. See the module docs for the method.
///
/// Errors: an unstable model (the norm is infinite; the message names the pole), or a failed
/// eigenvalue iteration.
pub fn hinf_norm(sys: &StateSpace) -> Result<HinfNorm> {
    hinf_norm_tol(sys, DEFAULT_HINF_REL_TOL)
}

/// [`hinf_norm`] with an explicit relative tolerance `rel_tol` in (0, 0.1].
pub fn hinf_norm_tol(sys: &StateSpace, rel_tol: f64) -> Result<HinfNorm> {
    if !(rel_tol > 0.0 && rel_tol <= 0.1) {
        return Err(Error::InvalidArgument(format!(
            "H∞ relative tolerance {rel_tol} must lie in (0, 0.1]"
        )));
    }
    sys.validate()?;
    // Balance first: series connections of fast-sampled companion forms (poles clustered near
    // z = 1) are badly scaled, and their unbalanced eigenvalues can be off by orders of
    // magnitude more than the balanced ones.
    let balanced = balance(sys)?;
    let sys = &balanced;
    check_stable(sys)?;
    if sys.is_discrete() {
        let ts = sys.ts;
        let cont = bilinear_to_continuous(sys)?;
        let mut r = hinf_continuous(&cont, rel_tol)?;
        let theta = 2.0 * r.peak_w_rad_s.atan(); // atan(∞) = π/2 → θ = π (Nyquist)
        r.peak_w_rad_s = theta / ts;
        r.peak_f_hz = r.peak_w_rad_s / (2.0 * PI);
        Ok(r)
    } else {
        hinf_continuous(sys, rel_tol)
    }
}

fn hamiltonian(sys: &StateSpace, gamma: f64) -> Result<Mat<f64>> {
    let (n, m, p) = (sys.n_states(), sys.n_inputs(), sys.n_outputs());
    let (a, b, c, d) = (&sys.a, &sys.b, &sys.c, &sys.d);
    let r = Mat::<f64>::identity(m, m) * faer::Scale(gamma * gamma) - d.transpose() * d;
    let rinv = crate::lti::solve_square(
        r.as_ref(),
        Mat::<f64>::identity(m, m).as_ref(),
        "Hamiltonian: γ²I − DᵀD",
    )?;
    let ag = a + &(&(b * &rinv) * &(d.transpose() * c));
    let g = &(b * &rinv) * b.transpose();
    let q = c.transpose() * &(&(Mat::<f64>::identity(p, p) + &(&(d * &rinv) * d.transpose())) * c);
    Ok(Mat::from_fn(2 * n, 2 * n, |i, j| match (i < n, j < n) {
        (true, true) => ag[(i, j)],
        (true, false) => g[(i, j - n)],
        (false, true) => -q[(i - n, j)],
        (false, false) => -ag[(j - n, i - n)],
    }))
}

fn hinf_continuous(sys: &StateSpace, rel_tol: f64) -> Result<HinfNorm> {
    let balanced = balance(sys)?;
    let sys = &balanced;
    let ev = FreqEvaluator::new(sys);
    let sig = |w: f64| -> Result<f64> { sigma_max(&ev.at_rad_s(w)?) };
    let sd = sigma_max(&Mat::from_fn(sys.n_outputs(), sys.n_inputs(), |i, j| {
        Complex64::new(sys.d[(i, j)], 0.0)
    }))?;
    // Initial lower bound: ω = ∞ (σ̄(D)), ω = 0, and the pole moduli.
    let (mut lb, mut w_lb) = (sd, f64::INFINITY);
    let consider = |w: f64, lb: &mut f64, w_lb: &mut f64| -> Result<()> {
        let s = sig(w)?;
        if s > *lb {
            *lb = s;
            *w_lb = w;
        }
        Ok(())
    };
    if sys.n_states() == 0 {
        return Ok(HinfNorm {
            gamma: sd,
            gamma_lower: sd,
            peak_w_rad_s: 0.0,
            peak_f_hz: 0.0,
            iterations: 0,
            rel_tol,
        });
    }
    consider(0.0, &mut lb, &mut w_lb)?;
    for p in sys.poles()? {
        if p.im >= 0.0 {
            consider(p.norm(), &mut lb, &mut w_lb)?;
        }
    }
    if lb.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        // σ̄ vanished at every point tried so far: scan a grid spanning the pole moduli before
        // concluding that G is identically zero.
        let mags: Vec<f64> = sys
            .poles()?
            .iter()
            .map(|p| p.norm())
            .filter(|m| *m > 0.0)
            .collect();
        let lo = mags.iter().copied().fold(f64::INFINITY, f64::min).min(1.0) * 1e-3;
        let hi = mags.iter().copied().fold(0.0, f64::max).max(1.0) * 1e3;
        for w in logspace(lo, hi, 200) {
            consider(w, &mut lb, &mut w_lb)?;
        }
        if lb.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return Ok(HinfNorm {
                gamma: 0.0,
                gamma_lower: 0.0,
                peak_w_rad_s: 0.0,
                peak_f_hz: 0.0,
                iterations: 0,
                rel_tol,
            });
        }
    }
    // Probe frequencies for the safety net below: around every mode (±2 half-power widths)
    // and a coarse logarithmic sweep over the pole moduli.
    let poles = sys.poles()?;
    let mags: Vec<f64> = poles
        .iter()
        .map(|p| p.norm())
        .filter(|m| *m > 0.0)
        .collect();
    let mut probes: Vec<f64> = Vec::new();
    if !mags.is_empty() {
        let lo = mags.iter().copied().fold(f64::INFINITY, f64::min) * 0.1;
        let hi = mags.iter().copied().fold(0.0, f64::max) * 10.0;
        probes.extend(logspace(lo, hi, 120));
    }
    for p in poles.iter().filter(|p| p.im > 0.0) {
        let zeta = (-p.re / p.norm()).max(1e-6);
        for k in [-2.0, -1.0, -0.5, -0.25, 0.25, 0.5, 1.0, 2.0] {
            let w = p.norm() * (1.0 + k * zeta);
            if w > 0.0 {
                probes.push(w);
            }
        }
    }
    let mut iterations = 0usize;
    let mut restarts = 0usize;
    loop {
        let r = bisect(sys, &ev, lb, w_lb, rel_tol, &mut iterations)?;
        // Safety net against an eigenvalue misplaced off the imaginary axis by rounding: if a
        // probe frequency beats the certified bound, restart the bisection from there.
        let mut beaten = None;
        for &w in &probes {
            let s = sig(w)?;
            if s > r.gamma && beaten.is_none_or(|(bs, _)| s > bs) {
                beaten = Some((s, w));
            }
        }
        match beaten {
            Some((s, w)) if restarts < 5 => {
                restarts += 1;
                lb = s;
                w_lb = w;
            }
            Some((s, w)) => {
                return Err(Error::Numerical(format!(
                    "H∞ bisection inconsistent: σ̄ = {s:.9e} at ω = {w:.6e} rad/s exceeds the \
                     certified bound {:.9e} after {restarts} restarts (ill-conditioned model)",
                    r.gamma
                )))
            }
            None => return Ok(r),
        }
    }
}

/// The Boyd–Balakrishnan / Bruinsma–Steinbuch iteration from the lower bound `lb` attained at
/// `w_lb`.
fn bisect(
    sys: &StateSpace,
    ev: &FreqEvaluator,
    mut lb: f64,
    mut w_lb: f64,
    rel_tol: f64,
    iterations: &mut usize,
) -> Result<HinfNorm> {
    let sig = |w: f64| -> Result<f64> { sigma_max(&ev.at_rad_s(w)?) };
    let mut bracket: Option<(f64, f64)> = None;
    loop {
        if *iterations >= 200 {
            return Err(Error::Numerical(
                "H∞ bisection did not converge in 200 Hamiltonian steps".into(),
            ));
        }
        *iterations += 1;
        let gamma = (1.0 + 2.0 * rel_tol) * lb;
        let h = hamiltonian(sys, gamma)?;
        let hn = crate::lti::norm1(h.as_ref()).max(f64::MIN_POSITIVE);
        let eig = eigenvalues(h.as_ref())?;
        let mut ws: Vec<f64> = eig
            .iter()
            .filter(|l| l.re.abs() <= 1e-7 * hn.max(l.norm()))
            .map(|l| l.im.abs())
            .collect();
        ws.sort_by(f64::total_cmp);
        ws.dedup_by(|a, b| (*a - *b).abs() <= 1e-12 * a.abs().max(b.abs()));
        if ws.is_empty() {
            return finish(ev, gamma, lb, w_lb, bracket, *iterations, rel_tol);
        }
        let (old_lb, mut new_lb, mut new_w) = (lb, lb, w_lb);
        let mut new_bracket = bracket;
        let mut pts: Vec<(f64, (f64, f64))> = ws.iter().map(|&w| (w, (w, w))).collect();
        for pair in ws.windows(2) {
            pts.push((0.5 * (pair[0] + pair[1]), (pair[0], pair[1])));
        }
        for (w, br) in pts {
            let s = sig(w)?;
            if s > new_lb {
                new_lb = s;
                new_w = w;
                new_bracket = Some(br);
            }
        }
        lb = new_lb;
        w_lb = new_w;
        bracket = new_bracket;
        if new_lb <= old_lb * (1.0 + rel_tol) {
            return finish(ev, gamma.max(lb), lb, w_lb, bracket, *iterations, rel_tol);
        }
    }
}

/// Polishes the peak frequency by golden-section search inside the last bracketing interval
/// and packs the result.
fn finish(
    ev: &FreqEvaluator,
    gamma: f64,
    mut lb: f64,
    mut w_lb: f64,
    bracket: Option<(f64, f64)>,
    iterations: usize,
    rel_tol: f64,
) -> Result<HinfNorm> {
    if let Some((a, b)) = bracket {
        if b > a {
            // Maximise σ̄ on the last bracketing interval (golden section on −σ̄; a failed
            // evaluation counts as the worst value).
            let (w, neg) = crate::optim::golden_section(
                |w| {
                    ev.at_rad_s(w)
                        .ok()
                        .and_then(|g| sigma_max(&g).ok())
                        .map_or(f64::NAN, |s| -s)
                },
                a,
                b,
                80,
            );
            if -neg > lb {
                lb = -neg;
                w_lb = w;
            }
        }
    }
    let gamma = gamma.max(lb);
    Ok(HinfNorm {
        gamma,
        gamma_lower: lb,
        peak_w_rad_s: w_lb,
        peak_f_hz: w_lb / (2.0 * PI),
        iterations,
        rel_tol,
    })
}

/// Largest σ̄(G) over a frequency grid `w_rad_s` (rad/s) and the grid frequency where it
/// occurs: an independent, grid-limited lower bound on ‖G‖∞ used as a cross-check.
pub fn peak_gain_on_grid(sys: &StateSpace, w_rad_s: &[f64]) -> Result<(f64, f64)> {
    let ev = FreqEvaluator::new(sys);
    let mut best = (0.0f64, f64::NAN);
    for &w in w_rad_s {
        let s = sigma_max(&ev.at_rad_s(w)?)?;
        if s > best.0 || best.1.is_nan() {
            best = (s, w);
        }
    }
    if best.1.is_nan() {
        return Err(Error::InvalidArgument(
            "peak_gain_on_grid: empty frequency grid".into(),
        ));
    }
    Ok(best)
}

/// `n` logarithmically spaced frequencies from `lo` to `hi` inclusive (same unit as inputs).
pub fn logspace(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    if n == 0 {
        return Vec::new();
    }
    if n == 1 {
        return vec![lo];
    }
    let (a, b) = (lo.ln(), hi.ln());
    (0..n)
        .map(|k| (a + (b - a) * k as f64 / (n - 1) as f64).exp())
        .collect()
}
