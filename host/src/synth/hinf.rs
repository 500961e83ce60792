//! H∞ mixed-sensitivity synthesis for a SISO plant: the central controller of
//! Doyle–Glover–Khargonekar–Francis (1989) by γ-iteration on its two Riccati equations.
//!
//! # Problem
//! With e = r − y, u = K e and y = G u, minimise γ in
//! ‖[W_S·S; W_KS·KS; W_T·T]‖∞ < γ (S = 1/(1 + GK), T = 1 − S). W_S is the performance weight
//! ([`performance_weight`], from a bandwidth and the M_s limit), W_KS > 0 a constant actuator
//! weight (reference amplitude / actuator limit), W_T the multiplicative-uncertainty weight W_m
//! (optional). The generalised plant, states x = [x_G; x_S; x_T]:
//!
//! ```text
//! A  = [[A_G, 0, 0], [−B_S C_G, A_S, 0], [B_T C_G, 0, A_T]]
//! B1 = [0; B_S; 0]          B2 = [B_G; −B_S D_G; B_T D_G]
//! C1 = [[0, C_S, 0], [0, 0, 0], [D_T C_G, 0, C_T]]   D11 = 0   D12 = [0; W_KS; D_T D_G]
//! C2 = [−C_G, 0, 0]         D21 = 1                  D22 = −D_G
//! ```
//!
//! D11 = 0 requires a strictly proper W_S ([`performance_weight`] adds a far roll-off pole).
//!
//! # Method
//! For D22 = 0 (a plant feedthrough is handled by the loop shift K = K₀(1 + D22·K₀)⁻¹), with
//! R₁ = D12ᵀD12 and R₂ = D21D21ᵀ, γ is achievable iff (Zhou, Doyle & Glover 1996, ch. 17)
//! - X solves (A − B2R₁⁻¹D12ᵀC1)ᵀX + X(·) − X(B2R₁⁻¹B2ᵀ − γ⁻²B1B1ᵀ)X + C1ᵀ(I − D12R₁⁻¹D12ᵀ)C1 = 0,
//!   stabilising, X ⪰ 0;
//! - Y solves the dual equation (A − B1D21ᵀR₂⁻¹C2, C2ᵀR₂⁻¹C2 − γ⁻²C1ᵀC1,
//!   B1(I − D21ᵀR₂⁻¹D21)B1ᵀ), stabilising, Y ⪰ 0;
//! - ρ(XY) < γ².
//!
//! Both are solved by [`super::riccati::care_g`] (residual-checked). γ_opt is bracketed by
//! bisection on log γ; the controller is built at γ = (1 + backoff)·γ_upper (the central
//! controller is ill-conditioned at γ_opt itself):
//! F = −R₁⁻¹(B2ᵀX + D12ᵀC1), L = −(YC2ᵀ + B1D21ᵀ)R₂⁻¹, Z = (I − γ⁻²YX)⁻¹,
//! K = [A + γ⁻²B1B1ᵀX + B2F + ZL(C2 + γ⁻²D21B1ᵀX) | −ZL ; F | 0].
//!
//! # Unstable controllers near γ_opt
//! On a plant with a lightly damped resonance the central controller close to γ_opt can be
//! unstable although the closed loop is internally stable and meets its level: on the bundled
//! two-mass model (resonance 53.1 Hz, ζ 0.061; W_S at 8 Hz, W_KS = 5/0.3, W_T = W_m) it has an
//! unstable pair at 48.3 Hz at 1 % above γ_opt = 0.9603 and at 50.0 Hz at γ_opt; the pair
//! stays without W_T (51.3 Hz at 1 %), so the uncertainty weight is not the cause, and the
//! closed-loop norm matches the level (0.96984 vs 0.96997) with Riccati residuals < 1e-9, so
//! it is not numerical either. It is the central controller's Z = (I − γ⁻²YX)⁻¹ growing as
//! ρ(XY) → γ²: the pair moves into the left half plane as γ rises (stable from 5 % above
//! γ_opt with W_T, 20 % without; `cargo run --example hinf_study`). An unstable controller
//! cannot be balanced-truncated and leaves the loop conditionally stable (negative phase
//! margins at the crossovers around the resonance), so by default the level is raised until
//! the controller is stable ([`HinfOptions::stable_controller`]).
//!
//! # Independent check
//! The closed loop is rebuilt from G and K alone ([`crate::robust::loops::FeedbackLoop`]), the
//! weighted transfers W_S·S, W_KS·KS, W_T·T are stacked and their H∞ norm is computed by the
//! Hamiltonian bisection of [`crate::robust::norms::hinf_norm`]; the design is refused if that
//! norm exceeds γ or the loop is unstable.
use super::riccati::{care_g, RiccatiSolution};
use super::sym;
use crate::error::{Error, Result};
use crate::lti::{solve_square, StateSpace};
use crate::robust::loops::FeedbackLoop;
use crate::robust::norms::{balance, hinf_norm, HinfNorm};
use faer::Mat;
use std::f64::consts::PI;

/// Mixed-sensitivity weights (continuous, SISO).
#[derive(Debug, Clone)]
pub struct MixedSensitivityWeights {
    /// Performance weight W_S on S; strictly proper and stable.
    pub ws: StateSpace,
    /// Constant actuator weight W_KS > 0 on KS (e.g. reference amplitude / actuator limit).
    pub wks: f64,
    /// Robustness weight W_T on T (the multiplicative uncertainty weight W_m), stable.
    pub wt: Option<StateSpace>,
}

/// W_S(s) = (s/M_s + ω_B)/(s + ω_B·ε) · ω_h/(s + ω_h), ω_B = 2π·`bandwidth_hz`,
/// ω_h = `rolloff_factor`·ω_B: |S| ≤ γ/|W_S| asks for |S| ≲ ω/ω_B below the bandwidth, a
/// low-frequency floor ε (steady-state error), and a peak ≤ γ·M_s (up to ω_h, where the
/// roll-off that makes W_S strictly proper relaxes the weight).
pub fn performance_weight(
    bandwidth_hz: f64,
    ms: f64,
    eps: f64,
    rolloff_factor: f64,
) -> Result<StateSpace> {
    for (name, v, lo) in [
        ("bandwidth_hz", bandwidth_hz, 0.0),
        ("ms", ms, 1.0),
        ("eps", eps, 0.0),
        ("rolloff_factor", rolloff_factor, 1.0),
    ] {
        if !(v.is_finite() && v > lo) {
            return Err(Error::InvalidArgument(format!(
                "performance weight: {name} = {v} must be finite and > {lo}"
            )));
        }
    }
    let wb = 2.0 * PI * bandwidth_hz;
    let wh = rolloff_factor * wb;
    // (s/M + ω_B) ω_h / ((s + ω_B ε)(s + ω_h)).
    let tf = crate::lti::TransferFunction::new(
        vec![wh / ms, wb * wh],
        crate::lti::poly_mul(&[1.0, wb * eps], &[1.0, wh]),
        0.0,
    )?;
    tf.to_state_space()
}

/// The generalised plant P in the partition of the module docs.
#[derive(Debug, Clone)]
pub struct GeneralizedPlant {
    /// State matrix.
    pub a: Mat<f64>,
    /// Exogenous input (reference) matrix.
    pub b1: Mat<f64>,
    /// Control input matrix.
    pub b2: Mat<f64>,
    /// Performance output matrix (rows W_S·e, W_KS·u, W_T·y).
    pub c1: Mat<f64>,
    /// Measurement (control error) matrix.
    pub c2: Mat<f64>,
    /// Feedthrough u → z.
    pub d12: Mat<f64>,
    /// Feedthrough w → y.
    pub d21: Mat<f64>,
    /// Feedthrough u → y (−D_G).
    pub d22: f64,
}

fn check_weight(name: &str, w: &StateSpace) -> Result<()> {
    if !w.is_siso() || w.is_discrete() {
        return Err(Error::InvalidArgument(format!(
            "{name} must be a continuous SISO model"
        )));
    }
    if !w.is_stable(0.0)? {
        return Err(Error::InvalidArgument(format!(
            "{name} must be stable (its poles enter the generalised plant)"
        )));
    }
    Ok(())
}

/// Builds the generalised plant of the module docs for a continuous SISO `plant`.
pub fn generalized_plant(
    plant: &StateSpace,
    w: &MixedSensitivityWeights,
) -> Result<GeneralizedPlant> {
    plant.validate()?;
    if !plant.is_siso() || plant.is_discrete() {
        return Err(Error::InvalidArgument(format!(
            "H∞ mixed sensitivity needs a continuous SISO plant (got {}x{}, ts = {} s); convert \
             a discrete model with d2c_zoh first",
            plant.n_outputs(),
            plant.n_inputs(),
            plant.ts
        )));
    }
    check_weight("W_S", &w.ws)?;
    if w.ws.d[(0, 0)] != 0.0 {
        return Err(Error::InvalidArgument(
            "W_S must be strictly proper (D11 = 0); add a roll-off pole, see performance_weight"
                .into(),
        ));
    }
    if !(w.wks.is_finite() && w.wks > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "W_KS = {} must be finite and > 0 (it makes D12 full rank)",
            w.wks
        )));
    }
    let empty = StateSpace::gain(Mat::zeros(1, 1), 0.0)?;
    let wt = match &w.wt {
        Some(t) => {
            check_weight("W_T", t)?;
            t
        }
        None => &empty,
    };
    let (g, s) = (plant, &w.ws);
    let (ng, ns, nt) = (g.n_states(), s.n_states(), wt.n_states());
    let n = ng + ns + nt;
    let (dg, dt) = (g.d[(0, 0)], wt.d[(0, 0)]);
    let mut a = Mat::<f64>::zeros(n, n);
    let mut b1 = Mat::<f64>::zeros(n, 1);
    let mut b2 = Mat::<f64>::zeros(n, 1);
    let mut c1 = Mat::<f64>::zeros(3, n);
    let mut c2 = Mat::<f64>::zeros(1, n);
    for i in 0..ng {
        b2[(i, 0)] = g.b[(i, 0)];
        for j in 0..ng {
            a[(i, j)] = g.a[(i, j)];
        }
        c2[(0, i)] = -g.c[(0, i)];
        c1[(2, i)] = dt * g.c[(0, i)];
    }
    for i in 0..ns {
        let r = ng + i;
        b1[(r, 0)] = s.b[(i, 0)];
        b2[(r, 0)] = -s.b[(i, 0)] * dg;
        for j in 0..ng {
            a[(r, j)] = -s.b[(i, 0)] * g.c[(0, j)];
        }
        for j in 0..ns {
            a[(r, ng + j)] = s.a[(i, j)];
        }
        c1[(0, r)] = s.c[(0, i)];
    }
    for i in 0..nt {
        let r = ng + ns + i;
        b2[(r, 0)] = wt.b[(i, 0)] * dg;
        for j in 0..ng {
            a[(r, j)] = wt.b[(i, 0)] * g.c[(0, j)];
        }
        for j in 0..nt {
            a[(r, ng + ns + j)] = wt.a[(i, j)];
        }
        c1[(2, r)] = wt.c[(0, i)];
    }
    let d12 = Mat::from_fn(3, 1, |i, _| [0.0, w.wks, dt * dg][i]);
    // Diagonal (power-of-two, exact) state scaling balancing [[A, B1 B2], [C1; C2]]: plant and
    // weight realisations spanning many decades otherwise give Hamiltonians with norms near
    // 1e13 whose sign iteration loses all accuracy. The controller is invariant.
    let bb = crate::lti::dense::hstack(b1.as_ref(), b2.as_ref());
    let cc = crate::lti::dense::vstack(c1.as_ref(), c2.as_ref());
    let bal = balance(&StateSpace::new(a, bb, cc, Mat::zeros(4, 2), 0.0)?)?;
    let b1 = Mat::from_fn(n, 1, |i, _| bal.b[(i, 0)]);
    let b2 = Mat::from_fn(n, 1, |i, _| bal.b[(i, 1)]);
    let c1 = Mat::from_fn(3, n, |i, j| bal.c[(i, j)]);
    let c2 = Mat::from_fn(1, n, |_, j| bal.c[(3, j)]);
    Ok(GeneralizedPlant {
        a: bal.a,
        b1,
        b2,
        c1,
        c2,
        d12,
        d21: Mat::from_fn(1, 1, |_, _| 1.0),
        d22: -dg,
    })
}

/// The two Riccati solutions at one γ, when γ is achievable.
struct Level {
    x: RiccatiSolution,
    y: RiccatiSolution,
}

fn min_sym_eig(m: &Mat<f64>) -> Result<f64> {
    let ev = m
        .as_ref()
        .self_adjoint_eigenvalues(faer::Side::Lower)
        .map_err(|e| Error::Numerical(format!("symmetric eigenvalues failed: {e:?}")))?;
    Ok(ev.iter().copied().fold(f64::INFINITY, f64::min))
}

fn spectral_radius(m: &Mat<f64>) -> Result<f64> {
    Ok(crate::lti::eigenvalues(m.as_ref())?
        .iter()
        .map(|l| l.norm())
        .fold(0.0, f64::max))
}

/// Tests the three DGKF conditions at `gamma`; `Ok(None)` when γ is not achievable.
fn level(p: &GeneralizedPlant, gamma: f64) -> Result<Option<Level>> {
    let g2 = 1.0 / (gamma * gamma);
    let r1 = p.d12.transpose() * &p.d12;
    let r1i = solve_square(r1.as_ref(), Mat::<f64>::identity(1, 1).as_ref(), "D12ᵀD12")?;
    let r2 = &p.d21 * p.d21.transpose();
    let r2i = solve_square(r2.as_ref(), Mat::<f64>::identity(1, 1).as_ref(), "D21D21ᵀ")?;
    let nz = p.c1.nrows();
    let nw = p.b1.ncols();
    let ax = &p.a - &p.b2 * &r1i * p.d12.transpose() * &p.c1;
    let gx = sym(
        (&p.b2 * &r1i * p.b2.transpose() - &p.b1 * p.b1.transpose() * faer::Scale(g2)).as_ref(),
    );
    let px = Mat::<f64>::identity(nz, nz) - &p.d12 * &r1i * p.d12.transpose();
    let qx = sym((p.c1.transpose() * &px * &p.c1).as_ref());
    // A Riccati equation without a (reliable) stabilising solution means γ is not achievable
    // (or not certifiably so): the level is refused, never accepted on a doubtful X.
    let Ok(x) = care_g(ax.as_ref(), gx.as_ref(), qx.as_ref()) else {
        return Ok(None);
    };
    let ay = &p.a - &p.b1 * p.d21.transpose() * &r2i * &p.c2;
    let gy = sym(
        (p.c2.transpose() * &r2i * &p.c2 - p.c1.transpose() * &p.c1 * faer::Scale(g2)).as_ref(),
    );
    let py = Mat::<f64>::identity(nw, nw) - p.d21.transpose() * &r2i * &p.d21;
    let qy = sym((&p.b1 * &py * p.b1.transpose()).as_ref());
    let Ok(y) = care_g(ay.transpose(), gy.as_ref(), qy.as_ref()) else {
        return Ok(None);
    };
    let tol = |m: &Mat<f64>| -1e-9 * super::fro(m.as_ref()).max(1.0);
    if min_sym_eig(&x.x)? < tol(&x.x) || min_sym_eig(&y.x)? < tol(&y.x) {
        return Ok(None);
    }
    if !(spectral_radius(&(&x.x * &y.x))? < gamma * gamma * (1.0 - 1e-9)) {
        return Ok(None);
    }
    Ok(Some(Level { x, y }))
}

/// The central controller at an achievable level (module docs), for D22 = 0.
fn central_controller(p: &GeneralizedPlant, gamma: f64, lv: &Level) -> Result<StateSpace> {
    let n = p.a.nrows();
    let g2 = 1.0 / (gamma * gamma);
    let (x, y) = (&lv.x.x, &lv.y.x);
    let r1 = p.d12.transpose() * &p.d12;
    let r2 = &p.d21 * p.d21.transpose();
    let f = -solve_square(
        r1.as_ref(),
        (p.b2.transpose() * x + p.d12.transpose() * &p.c1).as_ref(),
        "R1",
    )?;
    let lt = solve_square(
        r2.as_ref(),
        (&p.c2 * y + &p.d21 * p.b1.transpose()).as_ref(),
        "R2",
    )?;
    let l = -lt.transpose().to_owned();
    let zinv = Mat::<f64>::identity(n, n) - y * x * faer::Scale(g2);
    let z = solve_square(
        zinv.as_ref(),
        Mat::<f64>::identity(n, n).as_ref(),
        "H∞ central controller: I − γ⁻²YX (γ too close to optimal)",
    )?;
    let zl = &z * &l;
    let ak = &p.a
        + &p.b1 * p.b1.transpose() * x * faer::Scale(g2)
        + &p.b2 * &f
        + &zl * (&p.c2 + &p.d21 * p.b1.transpose() * x * faer::Scale(g2));
    let bk = -zl;
    StateSpace::new(ak, bk, f, Mat::zeros(1, 1), 0.0)
}

/// Options of [`hinf_mixed_sensitivity`].
#[derive(Debug, Clone, Copy)]
pub struct HinfOptions {
    /// Relative width of the final γ bracket (default 1e-4).
    pub gamma_rel_tol: f64,
    /// The controller is built at (1 + backoff)·γ_upper (default 0.01).
    pub backoff: f64,
    /// Require a stable controller (default true): from (1 + backoff)·γ_upper the level is
    /// raised by factors of [`STABLE_LEVEL_STEP`] until the central controller is stable, up to
    /// [`STABLE_LEVEL_MAX`]·γ_upper (module docs, "Unstable controllers near γ_opt").
    pub stable_controller: bool,
}

impl Default for HinfOptions {
    fn default() -> Self {
        Self {
            gamma_rel_tol: 1e-4,
            backoff: 0.01,
            stable_controller: true,
        }
    }
}

/// Ratio between successive levels of the search for a stable central controller.
pub const STABLE_LEVEL_STEP: f64 = 1.01;
/// Highest level of that search, as a multiple of γ_upper.
pub const STABLE_LEVEL_MAX: f64 = 2.0;

/// An H∞ mixed-sensitivity design with its evidence.
#[derive(Debug, Clone)]
pub struct HinfDesign {
    /// The controller u = K·e (continuous, order = plant + weights).
    pub controller: StateSpace,
    /// Largest γ found not achievable (lower end of the bracket of γ_opt; 0 if none tested).
    pub gamma_lower: f64,
    /// Smallest γ found achievable (upper end of the bracket of γ_opt).
    pub gamma_upper: f64,
    /// The level the controller was built at.
    pub gamma: f64,
    /// Independent check: ‖[W_S S; W_KS KS; W_T T]‖∞ of the loop of G and K.
    pub closed_loop: HinfNorm,
    /// Relative residuals of the X and Y Riccati equations at `gamma`.
    pub riccati_residuals: (f64, f64),
    /// Number of γ levels tested.
    pub levels_tested: usize,
}

/// Stacks SISO models with a common input into one multi-output model (outputs in order).
pub fn stack_outputs(parts: &[&StateSpace]) -> Result<StateSpace> {
    let ts = parts.first().map_or(0.0, |p| p.ts);
    let n: usize = parts.iter().map(|p| p.n_states()).sum();
    let k = parts.len();
    let mut a = Mat::<f64>::zeros(n, n);
    let mut b = Mat::<f64>::zeros(n, 1);
    let mut c = Mat::<f64>::zeros(k, n);
    let mut d = Mat::<f64>::zeros(k, 1);
    let mut off = 0;
    for (row, p) in parts.iter().enumerate() {
        if !p.is_siso() || (p.ts - ts).abs() > 1e-12 * ts.max(1e-300) {
            return Err(Error::InvalidArgument(
                "stack_outputs: SISO models with equal sample times expected".into(),
            ));
        }
        let m = p.n_states();
        for i in 0..m {
            b[(off + i, 0)] = p.b[(i, 0)];
            c[(row, off + i)] = p.c[(0, i)];
            for j in 0..m {
                a[(off + i, off + j)] = p.a[(i, j)];
            }
        }
        d[(row, 0)] = p.d[(0, 0)];
        off += m;
    }
    StateSpace::new(a, b, c, d, ts)
}

/// ‖[W_S S; W_KS KS; W_T T]‖∞ of the loop of `plant` and `controller` (continuous), built
/// from G and K alone (independent of the generalised plant), and the loop itself.
pub fn weighted_closed_loop_norm(
    plant: &StateSpace,
    controller: &StateSpace,
    w: &MixedSensitivityWeights,
) -> Result<(HinfNorm, FeedbackLoop)> {
    let lp = FeedbackLoop::new(plant, controller)?;
    if !lp.is_stable()? {
        return Err(Error::Numerical(
            "H∞ design: the closed loop of G and K is unstable".into(),
        ));
    }
    let ws_s = lp.s.series(&w.ws)?;
    let wks = StateSpace::gain(Mat::from_fn(1, 1, |_, _| w.wks), 0.0)?;
    let wks_ks = lp.ks.series(&wks)?;
    let norm = match &w.wt {
        Some(t) => {
            let wt_t = lp.t.series(t)?;
            hinf_norm(&stack_outputs(&[&ws_s, &wks_ks, &wt_t])?)?
        }
        None => hinf_norm(&stack_outputs(&[&ws_s, &wks_ks])?)?,
    };
    Ok((norm, lp))
}

/// H∞ mixed-sensitivity design for a continuous SISO `plant` (see the module docs).
/// Errors: invalid plant/weights, no achievable γ up to 1e8, or a controller whose
/// independently computed closed-loop norm exceeds its γ.
pub fn hinf_mixed_sensitivity(
    plant: &StateSpace,
    w: &MixedSensitivityWeights,
    opt: HinfOptions,
) -> Result<HinfDesign> {
    if !(opt.gamma_rel_tol > 0.0 && opt.gamma_rel_tol < 0.5 && opt.backoff >= 0.0) {
        return Err(Error::InvalidArgument(format!(
            "H∞ options: gamma_rel_tol = {} must lie in (0, 0.5), backoff = {} >= 0",
            opt.gamma_rel_tol, opt.backoff
        )));
    }
    let p = generalized_plant(plant, w)?;
    let mut tested = 0usize;
    let mut test = |g: f64| -> Result<bool> {
        tested += 1;
        Ok(level(&p, g)?.is_some())
    };
    // Bracket: double or halve from 1 until the feasibility flips.
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    if test(hi)? {
        let mut g = hi;
        while g > 1e-8 {
            g *= 0.5;
            if test(g)? {
                hi = g;
            } else {
                lo = g;
                break;
            }
        }
    } else {
        lo = hi;
        loop {
            hi *= 2.0;
            if hi > 1e8 {
                return Err(Error::Numerical(
                    "H∞ synthesis: no achievable γ up to 1e8 (plant not stabilisable / \
                     detectable through the weights, or weights inconsistent)"
                        .into(),
                ));
            }
            if test(hi)? {
                break;
            }
            lo = hi;
        }
    }
    while lo > 0.0 && hi - lo > opt.gamma_rel_tol * hi {
        let mid = (lo * hi).sqrt();
        if test(mid)? {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    let mut gamma = hi * (1.0 + opt.backoff);
    let (lv, controller) = loop {
        tested += 1;
        let lv = level(&p, gamma)?.ok_or_else(|| {
            Error::Numerical(format!(
                "H∞ synthesis: γ = {gamma:.6e} above the achievable {hi:.6e} failed the \
                 Riccati tests (numerically fragile problem)"
            ))
        })?;
        let k0 = central_controller(&p, gamma, &lv)?;
        let controller = if p.d22 != 0.0 {
            k0.feedback(&StateSpace::gain(Mat::from_fn(1, 1, |_, _| p.d22), 0.0)?)?
        } else {
            k0
        };
        if !opt.stable_controller || controller.is_stable(0.0)? {
            break (lv, controller);
        }
        gamma *= STABLE_LEVEL_STEP;
        if gamma > STABLE_LEVEL_MAX * hi {
            return Err(Error::Numerical(format!(
                "H∞ synthesis: no stable central controller between (1 + {}) γ_opt and {} γ_opt \
                 (γ_opt ≈ {hi:.6e}); allow an unstable controller (stable_controller = false) \
                 or relax the weights",
                opt.backoff, STABLE_LEVEL_MAX
            )));
        }
    };
    let (closed_loop, _) = weighted_closed_loop_norm(plant, &controller, w)?;
    if closed_loop.gamma > gamma * (1.0 + 1e-6) {
        return Err(Error::Numerical(format!(
            "H∞ synthesis: the independent closed-loop norm {:.6e} exceeds the design level \
             {gamma:.6e}",
            closed_loop.gamma
        )));
    }
    Ok(HinfDesign {
        controller,
        gamma_lower: lo,
        gamma_upper: hi,
        gamma,
        closed_loop,
        riccati_residuals: (lv.x.residual_rel, lv.y.residual_rel),
        levels_tested: tested,
    })
}
