//! Fixed-memory MPC step for the M4F: the condensed QP of the host design
//! (`ferrosid::synth::mpc`) solved by ADMM with a fixed iteration budget and a warm start.
//!
//! QP in U (horizon N): ½ Uᵀ H U + fᵀ U with f = G_x·x − g_r·r − 2ρ_Δ·e₁·u_prev, subject to the
//! box u_min ≤ U ≤ u_max and the rate limit |U_i − U_{i−1}| ≤ Δu_max (U_{−1} = u_prev), i.e.
//! l ≤ M U ≤ h with M = [I; D], D the first difference. The host precomputes
//! K = (H + σI + ρMᵀM)⁻¹, G_x and g_r; each iteration here is
//! U ← K(σU − f + Mᵀ(ρz − λ)), z ← clamp(MU + λ/ρ, l, h), λ ← λ + ρ(MU − z),
//! with M and Mᵀ applied through their structure (O(N)), so an iteration costs N² + O(N)
//! multiply–adds. All storage is `[f32; N]` / `[[f32; N]; N]` arrays fixed at compile time.
//! The applied input is the box- and rate-clamped first entry: always inside the rails.

/// Precomputed QP data for horizon `N` and `NX` plant states (from the host design).
#[derive(Debug, Clone, PartialEq)]
pub struct MpcQp<const N: usize, const NX: usize> {
    /// K = (H + σI + ρMᵀM)⁻¹, N×N.
    pub k: [[f32; N]; N],
    /// G_x = 2q·ΓᵀΦ (N×NX): f's dependence on the state.
    pub gx: [[f32; NX]; N],
    /// g_r = 2q·Γᵀ·1 (N): f's dependence on the reference.
    pub gr: [f32; N],
    /// 2ρ_Δ (input-rate weight, doubled).
    pub two_r_rate: f32,
    /// ADMM proximal weight σ.
    pub sigma: f32,
    /// ADMM penalty ρ (> 0).
    pub rho: f32,
    /// Input box, input units.
    pub u_min: f32,
    /// Upper input limit.
    pub u_max: f32,
    /// Largest input change per sample.
    pub du_max: f32,
    /// ADMM iterations per control step.
    pub iterations: u16,
}

/// The ADMM iterate kept between control steps (warm start).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MpcWarm<const N: usize> {
    /// Input sequence U.
    pub u: [f32; N],
    /// z for the box rows.
    pub z_box: [f32; N],
    /// z for the rate rows.
    pub z_rate: [f32; N],
    /// Multipliers of the box rows.
    pub l_box: [f32; N],
    /// Multipliers of the rate rows.
    pub l_rate: [f32; N],
}

impl<const N: usize> Default for MpcWarm<N> {
    fn default() -> Self {
        Self {
            u: [0.0; N],
            z_box: [0.0; N],
            z_rate: [0.0; N],
            l_box: [0.0; N],
            l_rate: [0.0; N],
        }
    }
}

fn clamp(v: f32, lo: f32, hi: f32) -> f32 {
    if v < lo {
        lo
    } else if v > hi {
        hi
    } else {
        v
    }
}

impl<const N: usize, const NX: usize> MpcQp<N, NX> {
    /// The linear term f for state `x`, reference `r` and previous input `u_prev`.
    pub fn linear_term(&self, x: &[f32; NX], r: f32, u_prev: f32) -> [f32; N] {
        let mut f = [0.0f32; N];
        for (i, fi) in f.iter_mut().enumerate() {
            let mut s = -self.gr[i] * r;
            for (g, xv) in self.gx[i].iter().zip(x.iter()) {
                s += g * xv;
            }
            *fi = s;
        }
        if N > 0 {
            f[0] -= self.two_r_rate * u_prev;
        }
        f
    }

    /// Runs the ADMM budget on the QP with linear term `f` from the warm start `w`.
    pub fn solve(&self, w: &mut MpcWarm<N>, f: &[f32; N], u_prev: f32, iterations: u16) {
        let rho = self.rho;
        // One division per call: a VDIV.F32 takes 14 cycles on the M4F, a VMUL 1.
        let inv_rho = 1.0 / rho;
        let mut rhs = [0.0f32; N];
        for _ in 0..iterations {
            // rhs = σU − f + Mᵀ(ρz − λ), Mᵀ[a; b] = a + Dᵀb, (Dᵀb)_j = b_j − b_{j+1}.
            for j in 0..N {
                let a = rho * w.z_box[j] - w.l_box[j];
                let b = rho * w.z_rate[j] - w.l_rate[j];
                let b_next = if j + 1 < N {
                    rho * w.z_rate[j + 1] - w.l_rate[j + 1]
                } else {
                    0.0
                };
                rhs[j] = self.sigma * w.u[j] - f[j] + a + b - b_next;
            }
            for (ui, krow) in w.u.iter_mut().zip(self.k.iter()) {
                let mut s = 0.0f32;
                for (kv, rv) in krow.iter().zip(rhs.iter()) {
                    s += kv * rv;
                }
                *ui = s;
            }
            for i in 0..N {
                let mb = w.u[i];
                let zb = clamp(mb + w.l_box[i] * inv_rho, self.u_min, self.u_max);
                w.l_box[i] += rho * (mb - zb);
                w.z_box[i] = zb;
                // Rate row i: U_i − U_{i−1}; row 0 is U_0 with bounds shifted by u_prev.
                let (mr, lo, hi) = if i == 0 {
                    (w.u[0], u_prev - self.du_max, u_prev + self.du_max)
                } else {
                    (w.u[i] - w.u[i - 1], -self.du_max, self.du_max)
                };
                let zr = clamp(mr + w.l_rate[i] * inv_rho, lo, hi);
                w.l_rate[i] += rho * (mr - zr);
                w.z_rate[i] = zr;
            }
        }
    }

    /// One control step: solve from the warm start, return the input to apply (inside the box
    /// and within Δu_max of `u_prev`), and shift the warm start one sample ahead.
    pub fn step(&self, w: &mut MpcWarm<N>, x: &[f32; NX], r: f32, u_prev: f32) -> f32 {
        if N == 0 {
            return clamp(u_prev, self.u_min, self.u_max);
        }
        let f = self.linear_term(x, r, u_prev);
        self.solve(w, &f, u_prev, self.iterations);
        let u = clamp(w.z_box[0], u_prev - self.du_max, u_prev + self.du_max);
        let u = clamp(u, self.u_min, self.u_max);
        for arr in [
            &mut w.u,
            &mut w.z_box,
            &mut w.z_rate,
            &mut w.l_box,
            &mut w.l_rate,
        ] {
            arr.rotate_left(1);
            if N >= 2 {
                arr[N - 1] = arr[N - 2];
            }
        }
        u
    }
}

#[cfg(test)]
mod tests;
