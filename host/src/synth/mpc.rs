//! Linear MPC design for the embedded target: condensed QP with input box and rate
//! constraints and an output-tracking cost, solved by ADMM with a fixed iteration budget and
//! a warm start, in a form that needs only matrix–vector products at run time.
//!
//! # Problem (discrete SISO plant x⁺ = A x + B u, y = C x, horizon N)
//! minimise Σ_{k=1..N} q·(y_k − r)² + Σ_{k=0..N−1} ρ_Δ·(u_k − u_{k−1})²
//! subject to u_min ≤ u_k ≤ u_max and |u_k − u_{k−1}| ≤ Δu_max, with u_{−1} the previous input.
//! Condensed: Y = Φ x₀ + Γ U (Φ_k = C A^k, Γ_{k,j} = C A^{k−1−j} B for j < k), ΔU = D U − e₁ u_{−1},
//! so the QP is ½ Uᵀ H U + fᵀ U with H = 2(q ΓᵀΓ + ρ_Δ DᵀD),
//! f = 2q Γᵀ(Φ x₀ − r·1) − 2ρ_Δ Dᵀ e₁ u_{−1}, and l ≤ M U ≤ h with M = [I; D].
//!
//! # Solver (ADMM, as in OSQP: Stellato et al. 2020, fixed step)
//! With K = (H + σI + ρ MᵀM)⁻¹ computed once at design time:
//! U ← K (σ U − f + Mᵀ(ρ z − λ)), z ← clamp(M U + λ/ρ, l, h), λ ← λ + ρ (M U − z).
//! Each iteration is two matrix–vector products and a clamp; memory is fixed by N; the
//! previous step's (U, z, λ) shifted by one sample is the warm start. The returned input is
//! the first entry of the clamped z (feasible by construction).
use crate::error::{Error, Result};
use crate::lti::{solve_square, StateSpace};
use crate::robust::step::StepResponse;
use faer::Mat;

/// Weights, limits and solver settings of [`MpcDesign::new`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MpcSpec {
    /// Prediction/control horizon N (samples, ≥ 1).
    pub horizon: usize,
    /// Output tracking weight q (> 0), per (output unit)².
    pub q: f64,
    /// Input-rate weight ρ_Δ (≥ 0), per (input unit)².
    pub r_rate: f64,
    /// Input box [u_min, u_max], input units.
    pub u_min: f64,
    /// Upper input limit.
    pub u_max: f64,
    /// Largest |u_k − u_{k−1}| per sample, input units (∞ for none).
    pub du_max: f64,
    /// ADMM penalty ρ (> 0).
    pub rho: f64,
    /// ADMM iterations per control step (the fixed budget).
    pub iterations: usize,
}

/// A condensed MPC with its precomputed ADMM matrices.
#[derive(Debug, Clone)]
pub struct MpcDesign {
    /// The settings.
    pub spec: MpcSpec,
    /// Φ (N×n): free response of the outputs y_1..y_N.
    pub phi: Mat<f64>,
    /// Γ (N×N): forced response.
    pub gamma: Mat<f64>,
    /// Hessian H (N×N).
    pub h: Mat<f64>,
    /// Constraint matrix M = [I; D] (2N×N).
    pub m: Mat<f64>,
    /// K = (H + σI + ρ MᵀM)⁻¹ (N×N).
    pub k: Mat<f64>,
    /// σ of the ADMM proximal term.
    pub sigma: f64,
}

/// ADMM iterate (warm start between control steps).
#[derive(Debug, Clone)]
pub struct MpcState {
    /// Input sequence U.
    pub u: Vec<f64>,
    /// Constrained copy z = clamp(M U).
    pub z: Vec<f64>,
    /// Scaled multipliers λ.
    pub lambda: Vec<f64>,
}

impl MpcDesign {
    /// Builds the condensed QP for the discrete SISO `plant` (D = 0 required: the input of step
    /// k cannot reach y_k without a model feedthrough).
    pub fn new(plant: &StateSpace, spec: MpcSpec) -> Result<Self> {
        if !plant.is_discrete() || !plant.is_siso() || plant.d[(0, 0)] != 0.0 {
            return Err(Error::InvalidArgument(
                "MPC needs a discrete SISO plant without feedthrough (D = 0)".into(),
            ));
        }
        let s = spec;
        if s.horizon == 0
            || !(s.q > 0.0 && s.r_rate >= 0.0 && s.rho > 0.0 && s.u_min < s.u_max)
            || !(s.du_max > 0.0)
            || s.iterations == 0
        {
            return Err(Error::InvalidArgument(format!(
                "MPC spec needs horizon >= 1, q > 0, r_rate >= 0, rho > 0, u_min < u_max, \
                 du_max > 0 and iterations >= 1; got {s:?}"
            )));
        }
        let (n, nh) = (plant.n_states(), s.horizon);
        let mut phi = Mat::<f64>::zeros(nh, n);
        let mut markov = vec![0.0; nh]; // C A^k B, k = 0..N−1
        let mut ak_b = plant.b.clone();
        let mut c_ak = plant.c.clone();
        for k in 0..nh {
            markov[k] = (&plant.c * &ak_b)[(0, 0)];
            ak_b = &plant.a * &ak_b;
            c_ak = &c_ak * &plant.a;
            for j in 0..n {
                phi[(k, j)] = c_ak[(0, j)];
            }
        }
        let gamma = Mat::from_fn(nh, nh, |k, j| if j <= k { markov[k - j] } else { 0.0 });
        let d = Mat::from_fn(nh, nh, |i, j| {
            if i == j {
                1.0
            } else if j + 1 == i {
                -1.0
            } else {
                0.0
            }
        });
        let h = (gamma.transpose() * &gamma * faer::Scale(s.q)
            + d.transpose() * &d * faer::Scale(s.r_rate))
            * faer::Scale(2.0);
        let m = Mat::from_fn(2 * nh, nh, |i, j| {
            if i < nh {
                if i == j {
                    1.0
                } else {
                    0.0
                }
            } else {
                d[(i - nh, j)]
            }
        });
        let sigma = 1e-6;
        let kk = &h
            + Mat::<f64>::identity(nh, nh) * faer::Scale(sigma)
            + m.transpose() * &m * faer::Scale(s.rho);
        let k = solve_square(
            kk.as_ref(),
            Mat::<f64>::identity(nh, nh).as_ref(),
            "MPC: ADMM matrix",
        )?;
        Ok(Self {
            spec: s,
            phi,
            gamma,
            h,
            m,
            k,
            sigma,
        })
    }

    /// The firmware form of the linear term (`ferrosid_firmware::mpc::MpcQp`):
    /// f = G_x·x − g_r·r − 2ρ_Δ·e₁·u_prev with G_x = 2q·ΓᵀΦ (N×n) and g_r = 2q·Γᵀ·1 (N).
    pub fn firmware_terms(&self) -> (Mat<f64>, Vec<f64>) {
        let (nh, q) = (self.spec.horizon, self.spec.q);
        let gx = self.gamma.transpose() * &self.phi * faer::Scale(2.0 * q);
        let gr = (0..nh)
            .map(|j| 2.0 * q * (0..nh).map(|k| self.gamma[(k, j)]).sum::<f64>())
            .collect();
        (gx, gr)
    }

    /// A cold start (all zeros).
    pub fn initial_state(&self) -> MpcState {
        let nh = self.spec.horizon;
        MpcState {
            u: vec![0.0; nh],
            z: vec![0.0; 2 * nh],
            lambda: vec![0.0; 2 * nh],
        }
    }

    /// The linear term f and the bounds (l, h) for state `x0`, reference `r` and previous
    /// input `u_prev`.
    pub fn qp_data(&self, x0: &[f64], r: f64, u_prev: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let (nh, s) = (self.spec.horizon, self.spec);
        let e: Vec<f64> = (0..nh)
            .map(|k| (0..x0.len()).map(|j| self.phi[(k, j)] * x0[j]).sum::<f64>() - r)
            .collect();
        let mut f: Vec<f64> = (0..nh)
            .map(|j| 2.0 * s.q * (0..nh).map(|k| self.gamma[(k, j)] * e[k]).sum::<f64>())
            .collect();
        f[0] -= 2.0 * s.r_rate * u_prev;
        let mut lo = vec![s.u_min; 2 * nh];
        let mut hi = vec![s.u_max; 2 * nh];
        for i in nh..2 * nh {
            lo[i] = -s.du_max;
            hi[i] = s.du_max;
        }
        // Row nh is u_0 − u_{−1}: shift its bounds by u_prev.
        lo[nh] += u_prev;
        hi[nh] += u_prev;
        (f, lo, hi)
    }

    /// Runs the fixed ADMM budget from `st` (warm start) and returns the input to apply now
    /// (feasible: inside the box and the rate limit). `st` is left shifted by one sample for
    /// the next call.
    pub fn step(&self, st: &mut MpcState, x0: &[f64], r: f64, u_prev: f64) -> f64 {
        self.step_detailed(st, x0, r, u_prev).0
    }

    /// [`Self::step`], also returning the ADMM primal iterate U₀ before the clamps (how far
    /// the fixed budget left the solution from the constraint set).
    pub fn step_detailed(&self, st: &mut MpcState, x0: &[f64], r: f64, u_prev: f64) -> (f64, f64) {
        let (f, lo, hi) = self.qp_data(x0, r, u_prev);
        self.solve(st, &f, &lo, &hi, self.spec.iterations);
        let raw = st.u[0];
        let du = self.spec.du_max;
        let u_now = st.z[0]
            .clamp(u_prev - du, u_prev + du)
            .clamp(self.spec.u_min, self.spec.u_max);
        shift(st, self.spec.horizon);
        (u_now, raw)
    }

    /// The unconstrained law (the exact QP optimum when no constraint is active):
    /// u₀ = −k_x·x + k_r·r + k_u·u_prev, from the first row of H⁻¹ (H is symmetric).
    pub fn unconstrained_law(&self) -> Result<UnconstrainedLaw> {
        let nh = self.spec.horizon;
        let hinv = solve_square(
            self.h.as_ref(),
            Mat::<f64>::identity(nh, nh).as_ref(),
            "MPC: Hessian",
        )?;
        let (gx, gr) = self.firmware_terms();
        let n = gx.ncols();
        let kx = (0..n)
            .map(|j| (0..nh).map(|i| hinv[(0, i)] * gx[(i, j)]).sum())
            .collect();
        let kr = (0..nh).map(|i| hinv[(0, i)] * gr[i]).sum();
        let ku = 2.0 * self.spec.r_rate * hinv[(0, 0)];
        Ok(UnconstrainedLaw { kx, kr, ku })
    }

    /// The closed loop of `plant` (the design model) under [`Self::unconstrained_law`], state
    /// [x; u_prev], input r, output y: x⁺ = (A − B k_x) x + B k_u u_prev + B k_r r,
    /// u_prev⁺ = −k_x x + k_u u_prev + k_r r.
    pub fn unconstrained_closed_loop(&self, plant: &StateSpace) -> Result<StateSpace> {
        let law = self.unconstrained_law()?;
        let n = plant.n_states();
        if law.kx.len() != n {
            return Err(Error::InvalidArgument(format!(
                "MPC: the plant has {n} states, the design {}",
                law.kx.len()
            )));
        }
        let a = Mat::from_fn(n + 1, n + 1, |i, j| match (i < n, j < n) {
            (true, true) => plant.a[(i, j)] - plant.b[(i, 0)] * law.kx[j],
            (true, false) => plant.b[(i, 0)] * law.ku,
            (false, true) => -law.kx[j],
            (false, false) => law.ku,
        });
        let b = Mat::from_fn(n + 1, 1, |i, _| {
            if i < n {
                plant.b[(i, 0)] * law.kr
            } else {
                law.kr
            }
        });
        let c = Mat::from_fn(1, n + 1, |_, j| if j < n { plant.c[(0, j)] } else { 0.0 });
        StateSpace::new(a, b, c, Mat::zeros(1, 1), plant.ts)
    }

    /// Closed-loop step of the reference `r` on `plant` (the design model, its state fed back
    /// exactly: a state-feedback MPC) for `samples` samples from rest, with the fixed ADMM
    /// budget and warm start per sample as on the target.
    pub fn closed_loop_step(
        &self,
        plant: &StateSpace,
        r: f64,
        samples: usize,
        settle_band: f64,
    ) -> Result<MpcStep> {
        self.closed_loop_step_with(plant, None, r, samples, settle_band)
    }

    /// [`Self::closed_loop_step`] with a diagnosed nonlinearity `effect` between the MPC and
    /// the plant (the laws of [`crate::gap::effect`], once per sample; the MPC still feeds
    /// back the plant's state and does not know the effect):
    /// * at the plant input, on the applied command u: `deadzone` (w = dead-zone(u)),
    ///   `backlash` (play operator), `saturation`, `slew_rate` (at most rate·ts per sample),
    ///   `time_delay` (rounded to whole samples);
    /// * `coulomb_friction` as a torque at the plant input against the sign of the output,
    ///   w = u − level·clamp(y/ε, −1, 1) with ε = 1e-3·|r| (a velocity output, as the bundled
    ///   example's speed);
    /// * `quantization` of the recorded measurement (the MPC feeds back the state, so it does
    ///   not act on the loop).
    ///
    /// `stiction`, `resonance` and `state_limit` need the sub-sampled plant of
    /// [`crate::limit_cycle`] and are refused (InvalidArgument naming the effect).
    /// [`MpcStep::plant_input`] records w.
    pub fn closed_loop_step_with(
        &self,
        plant: &StateSpace,
        effect: Option<&crate::gap::effect::Effect>,
        r: f64,
        samples: usize,
        settle_band: f64,
    ) -> Result<MpcStep> {
        use crate::gap::effect::{deadzone, quantize, saturation, Effect, Play, RateLimiter};
        let n = plant.n_states();
        if let Some(e) = effect {
            e.validate()?;
            if matches!(
                e,
                Effect::Stiction { .. } | Effect::Resonance { .. } | Effect::StateLimit { .. }
            ) {
                return Err(Error::InvalidArgument(format!(
                    "MPC step: the effect {} is not simulated here (it needs the sub-sampled \
                     plant of the limit-cycle simulation)",
                    e.kind()
                )));
            }
        }
        let mut play = match effect {
            Some(Effect::Backlash { gap }) => Some(Play::new(*gap)),
            _ => None,
        };
        let mut slew = match effect {
            Some(Effect::SlewRate { rate }) => Some(RateLimiter::new(rate * plant.ts)),
            _ => None,
        };
        let delay = match effect {
            Some(Effect::TimeDelay { seconds }) => (seconds / plant.ts).round() as usize,
            _ => 0,
        };
        let mut line = std::collections::VecDeque::from(vec![0.0; delay]);
        let eps = 1e-3 * r.abs();
        let mut w_all = Vec::with_capacity(samples);
        if plant.d[(0, 0)] != 0.0 || self.phi.ncols() != n {
            return Err(Error::InvalidArgument(
                "MPC step: the plant must be the design model (same states, D = 0)".into(),
            ));
        }
        if !(r.is_finite() && r != 0.0 && samples >= 2 && settle_band > 0.0 && settle_band < 1.0) {
            return Err(Error::InvalidArgument(format!(
                "MPC step: r = {r} must be finite and non-zero, samples {samples} >= 2, band                  {settle_band} in (0, 1)"
            )));
        }
        let mut st = self.initial_state();
        let mut x = vec![0.0; n];
        let mut u_prev = 0.0;
        let (mut t, mut y, mut u, mut raw) = (vec![], vec![], vec![], vec![]);
        let mut max_du = 0.0f64;
        for k in 0..samples {
            let yk: f64 = (0..n).map(|j| plant.c[(0, j)] * x[j]).sum();
            let (uk, rk) = self.step_detailed(&mut st, &x, r, u_prev);
            let wk = match effect {
                None => uk,
                Some(Effect::Deadzone { width }) => deadzone(uk, *width),
                Some(Effect::Saturation { limit }) => saturation(uk, *limit),
                Some(Effect::Backlash { .. }) => play.as_mut().map_or(uk, |p| p.apply(uk)),
                Some(Effect::SlewRate { .. }) => slew.as_mut().map_or(uk, |l| l.apply(uk)),
                Some(Effect::TimeDelay { .. }) => {
                    line.push_back(uk);
                    line.pop_front().unwrap_or(uk)
                }
                Some(Effect::CoulombFriction { level }) => uk - level * (yk / eps).clamp(-1.0, 1.0),
                Some(_) => uk,
            };
            let yk = match effect {
                Some(Effect::Quantization { step }) => quantize(yk, *step),
                _ => yk,
            };
            w_all.push(wk);
            if !(yk.is_finite() && rk.is_finite()) {
                return Err(Error::Numerical(format!(
                    "MPC step: the response diverged at sample {k}"
                )));
            }
            max_du = max_du.max((uk - u_prev).abs());
            let next: Vec<f64> = (0..n)
                .map(|i| (0..n).map(|j| plant.a[(i, j)] * x[j]).sum::<f64>() + plant.b[(i, 0)] * wk)
                .collect();
            x = next;
            t.push(k as f64 * plant.ts);
            y.push(yk);
            u.push(uk);
            raw.push(rk);
            u_prev = uk;
        }
        let s = self.spec;
        let lim = s.u_max.abs().max(s.u_min.abs());
        let step = summarise(plant.ts, r, lim, settle_band, t, y, u.clone(), u);
        let max_raw_excess = raw
            .iter()
            .map(|v| (v - s.u_max).max(s.u_min - v).max(0.0))
            .fold(0.0, f64::max);
        Ok(MpcStep {
            step,
            max_abs_du: max_du,
            max_raw_excess,
            raw_u0: raw,
            plant_input: w_all,
        })
    }

    /// `iterations` ADMM steps on the QP (f, lo, hi) from `st`.
    pub fn solve(&self, st: &mut MpcState, f: &[f64], lo: &[f64], hi: &[f64], iterations: usize) {
        let nh = self.spec.horizon;
        let rho = self.spec.rho;
        let mut rhs = vec![0.0; nh];
        for _ in 0..iterations {
            for j in 0..nh {
                let mt: f64 = (0..2 * nh)
                    .map(|i| self.m[(i, j)] * (rho * st.z[i] - st.lambda[i]))
                    .sum();
                rhs[j] = self.sigma * st.u[j] - f[j] + mt;
            }
            for i in 0..nh {
                st.u[i] = (0..nh).map(|j| self.k[(i, j)] * rhs[j]).sum();
            }
            for i in 0..2 * nh {
                let mu: f64 = (0..nh).map(|j| self.m[(i, j)] * st.u[j]).sum();
                st.z[i] = (mu + st.lambda[i] / rho).clamp(lo[i], hi[i]);
                st.lambda[i] += rho * (mu - st.z[i]);
            }
        }
    }
}

/// The MPC's linear law when no constraint is active ([`MpcDesign::unconstrained_law`]).
#[derive(Debug, Clone, PartialEq)]
pub struct UnconstrainedLaw {
    /// State gain k_x (n).
    pub kx: Vec<f64>,
    /// Reference gain k_r.
    pub kr: f64,
    /// Previous-input gain k_u.
    pub ku: f64,
}

/// A simulated MPC step ([`MpcDesign::closed_loop_step`]).
#[derive(Debug, Clone)]
pub struct MpcStep {
    /// The response (u_demand = u: the MPC's output is already constrained).
    pub step: StepResponse,
    /// Largest |u_k − u_{k−1}| applied.
    pub max_abs_du: f64,
    /// Largest distance of the raw ADMM iterate U₀ outside the box (0: inside).
    pub max_raw_excess: f64,
    /// The raw ADMM iterate U₀ per sample.
    pub raw_u0: Vec<f64>,
    /// The plant's input per sample (the command u after the effect; u without one).
    pub plant_input: Vec<f64>,
}

/// The summary numbers of a step, defined and computed as for
/// [`crate::robust::step::StepResponse`] ([`crate::robust::step::summarise`]).
#[allow(clippy::too_many_arguments)]
fn summarise(
    ts: f64,
    r: f64,
    lim: f64,
    band_rel: f64,
    t: Vec<f64>,
    y: Vec<f64>,
    u: Vec<f64>,
    v: Vec<f64>,
) -> StepResponse {
    let at_rail = v.iter().filter(|x| x.abs() >= lim).count();
    let mut out = StepResponse {
        ts,
        amplitude: r,
        actuator_limit: lim,
        hits_rail: false,
        samples_at_rail: at_rail,
        peak_demand_ratio: v.iter().map(|x| x.abs() / lim).fold(0.0, f64::max),
        overshoot_pct: 0.0,
        settling_time_s: None,
        rise_time_s: None,
        final_error: 0.0,
        t,
        y,
        u,
        u_demand: v,
    };
    crate::robust::step::summarise(&mut out, band_rel);
    out
}

/// Shifts a solution one sample ahead (the warm start for the next control step), the last
/// entry of each block repeated, exactly as the firmware (`ferrosid_firmware::mpc`) does.
fn shift(st: &mut MpcState, nh: usize) {
    let shift_block = |v: &mut [f64]| {
        v.rotate_left(1);
        if nh >= 2 {
            v[nh - 1] = v[nh - 2];
        }
    };
    shift_block(&mut st.u);
    shift_block(&mut st.z[..nh]);
    shift_block(&mut st.z[nh..]);
    shift_block(&mut st.lambda[..nh]);
    shift_block(&mut st.lambda[nh..]);
}
