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
        let (f, lo, hi) = self.qp_data(x0, r, u_prev);
        self.solve(st, &f, &lo, &hi, self.spec.iterations);
        let du = self.spec.du_max;
        let u_now = st.z[0]
            .clamp(u_prev - du, u_prev + du)
            .clamp(self.spec.u_min, self.spec.u_max);
        shift(st, self.spec.horizon);
        u_now
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

/// Shifts a solution one sample ahead (the warm start for the next control step).
fn shift(st: &mut MpcState, nh: usize) {
    st.u.rotate_left(1);
    if nh >= 2 {
        st.u[nh - 1] = st.u[nh - 2];
    }
    for v in [&mut st.z, &mut st.lambda] {
        v[..nh].rotate_left(1);
        v[nh..].rotate_left(1);
    }
}
