//! Fast free-run steppers of a [`ModalModel`]: [`Stepper`] (one step per sample, rotation
//! coefficients precomputed) and [`SubStepper`] (m exact ZOH sub-steps per sample, for effects
//! that switch inside a sample).
use super::ModalModel;
use num_complex::Complex64;
/// A [`ModalModel`] with its rotation coefficients r·cos φ, r·sin φ precomputed.
#[derive(Debug, Clone)]
pub struct Stepper<'a> {
    pub(super) model: &'a ModalModel,
    pub(super) rot: Vec<(f64, f64)>,
}

impl Stepper<'_> {
    /// x ← A·x + B·w.
    #[inline]
    pub fn step(&self, x: &mut [f64], w: f64) {
        let nr = self.model.real.len();
        for (xi, p) in x[..nr].iter_mut().zip(&self.model.real) {
            *xi = p * *xi + w;
        }
        for (j, &(rc, rs)) in self.rot.iter().enumerate() {
            let i = nr + 2 * j;
            let (x1, x2) = (x[i], x[i + 1]);
            x[i] = rc * x1 - rs * x2 + w;
            x[i + 1] = rs * x1 + rc * x2;
        }
    }

    /// C·A·x: the state part of the next output when w = 0.
    #[inline]
    pub fn free_next_output(&self, x: &[f64]) -> f64 {
        let m = self.model;
        let nr = m.real.len();
        let mut acc = 0.0;
        for ((c, p), xi) in m.residues.iter().zip(&m.real).zip(&x[..nr]) {
            acc += c * p * xi;
        }
        for (j, &(rc, rs)) in self.rot.iter().enumerate() {
            let i = nr + 2 * j;
            let (x1, x2) = (x[i], x[i + 1]);
            acc += m.residues[i] * (rc * x1 - rs * x2) + m.residues[i + 1] * (rs * x1 + rc * x2);
        }
        acc
    }
}

/// The model advanced in `m` equal sub-steps of `ts/m`, assuming it is the zero-order-hold
/// discretisation of a continuous model (so each mode λ becomes λ^(1/m) with input gain
/// (λ^(1/m) − 1)/(λ − 1), and m sub-steps with a constant input reproduce one full step
/// exactly). Used where an effect must act inside the sample period (friction).
#[derive(Debug, Clone)]
pub struct SubStepper {
    /// Real sub-step poles.
    real: Vec<f64>,
    /// Real-mode input gains.
    real_b: Vec<f64>,
    /// Rotation entries (r·cos φ, r·sin φ) of each sub-step pair.
    rot: Vec<(f64, f64)>,
    /// Complex input gain (Re, Im) of each pair.
    rot_b: Vec<(f64, f64)>,
    /// Residues (copied).
    c: Vec<f64>,
    /// C·A_c: the output's time derivative per state (continuous-time equivalent, 1/s).
    dc: Vec<f64>,
    /// C·B_c: the output derivative's direct dependence on the held input.
    dcb: f64,
}

impl SubStepper {
    /// x ← A_h·x + B_h·w.
    #[inline]
    pub fn step(&self, x: &mut [f64], w: f64) {
        let nr = self.real.len();
        for ((xi, p), b) in x[..nr].iter_mut().zip(&self.real).zip(&self.real_b) {
            *xi = p * *xi + b * w;
        }
        for (j, (&(rc, rs), &(br, bi))) in self.rot.iter().zip(&self.rot_b).enumerate() {
            let i = nr + 2 * j;
            let (x1, x2) = (x[i], x[i + 1]);
            x[i] = rc * x1 - rs * x2 + br * w;
            x[i + 1] = rs * x1 + rc * x2 + bi * w;
        }
    }

    /// C·A_h·x.
    #[inline]
    pub fn free_next_output(&self, x: &[f64]) -> f64 {
        let nr = self.real.len();
        let mut acc = 0.0;
        for ((c, p), xi) in self.c.iter().zip(&self.real).zip(&x[..nr]) {
            acc += c * p * xi;
        }
        for (j, &(rc, rs)) in self.rot.iter().enumerate() {
            let i = nr + 2 * j;
            let (x1, x2) = (x[i], x[i + 1]);
            acc += self.c[i] * (rc * x1 - rs * x2) + self.c[i + 1] * (rs * x1 + rc * x2);
        }
        acc
    }

    /// Time derivative of the state output, C·(A_c·x + B_c·w), for the held input `w`
    /// (output units per second).
    #[inline]
    pub fn rate(&self, x: &[f64], w: f64) -> f64 {
        x.iter().zip(&self.dc).map(|(a, b)| a * b).sum::<f64>() + self.dcb * w
    }

    /// C·A_c·A_h·x: the output derivative after one sub-step with zero input.
    #[inline]
    pub fn free_next_rate(&self, x: &[f64]) -> f64 {
        let nr = self.real.len();
        let mut acc = 0.0;
        for ((c, p), xi) in self.dc.iter().zip(&self.real).zip(&x[..nr]) {
            acc += c * p * xi;
        }
        for (j, &(rc, rs)) in self.rot.iter().enumerate() {
            let i = nr + 2 * j;
            let (x1, x2) = (x[i], x[i + 1]);
            acc += self.dc[i] * (rc * x1 - rs * x2) + self.dc[i + 1] * (rs * x1 + rc * x2);
        }
        acc
    }

    /// Change of the output derivative after one sub-step per unit of held input:
    /// C·A_c·B_h + C·B_c.
    pub fn rate_gain(&self) -> f64 {
        let nr = self.real.len();
        let mut acc = self.dcb;
        for i in 0..nr {
            acc += self.dc[i] * self.real_b[i];
        }
        for (j, &(br, bi)) in self.rot_b.iter().enumerate() {
            acc += self.dc[nr + 2 * j] * br + self.dc[nr + 2 * j + 1] * bi;
        }
        acc
    }

    /// C·B_h: one-sub-step response of the state output to the input.
    pub fn cb(&self) -> f64 {
        let nr = self.real.len();
        let mut acc = 0.0;
        for i in 0..nr {
            acc += self.c[i] * self.real_b[i];
        }
        for (j, &(br, bi)) in self.rot_b.iter().enumerate() {
            acc += self.c[nr + 2 * j] * br + self.c[nr + 2 * j + 1] * bi;
        }
        acc
    }
}

/// The sub-step operations a hot loop needs, implemented by [`SubStepper`] (any state count)
/// and by [`FixedSubStepper`] (the mode counts known at compile time, the state on the stack)
/// with the same arithmetic in the same order, so both give the same bits.
pub trait SubStep {
    /// The state vector.
    type State: Clone;
    /// The zero state.
    fn zero_state(&self) -> Self::State;
    /// x ← A_h·x + B_h·w.
    fn step(&self, x: &mut Self::State, w: f64);
    /// C·A_h·x.
    fn free_next_output(&self, x: &Self::State) -> f64;
    /// C·A_c·A_h·x.
    fn free_next_rate(&self, x: &Self::State) -> f64;
}

impl SubStep for SubStepper {
    type State = Vec<f64>;
    fn zero_state(&self) -> Vec<f64> {
        vec![0.0; self.c.len()]
    }
    #[inline]
    fn step(&self, x: &mut Vec<f64>, w: f64) {
        SubStepper::step(self, x, w)
    }
    #[inline]
    fn free_next_output(&self, x: &Vec<f64>) -> f64 {
        SubStepper::free_next_output(self, x)
    }
    #[inline]
    fn free_next_rate(&self, x: &Vec<f64>) -> f64 {
        SubStepper::free_next_rate(self, x)
    }
}

/// The state of a [`FixedSubStepper`]: the real modes, then each pair.
#[derive(Debug, Clone, Copy)]
pub struct FixedState<const NR: usize, const NP: usize> {
    real: [f64; NR],
    pairs: [[f64; 2]; NP],
}

/// A [`SubStepper`] of `NR` real modes and `NP` pairs (see [`SubStep`]).
#[derive(Debug, Clone)]
pub struct FixedSubStepper<const NR: usize, const NP: usize> {
    real: [f64; NR],
    real_b: [f64; NR],
    rot: [(f64, f64); NP],
    rot_b: [(f64, f64); NP],
    c_real: [f64; NR],
    c_pairs: [[f64; 2]; NP],
    dc_real: [f64; NR],
    dc_pairs: [[f64; 2]; NP],
}

impl SubStepper {
    /// This stepper with its mode counts fixed at compile time, or `None` when it has not
    /// exactly `NR` real modes and `NP` pairs.
    pub fn fixed<const NR: usize, const NP: usize>(&self) -> Option<FixedSubStepper<NR, NP>> {
        if self.real.len() != NR || self.rot.len() != NP || self.c.len() != NR + 2 * NP {
            return None;
        }
        let pair = |v: &[f64], j: usize| [v[NR + 2 * j], v[NR + 2 * j + 1]];
        Some(FixedSubStepper {
            real: std::array::from_fn(|i| self.real[i]),
            real_b: std::array::from_fn(|i| self.real_b[i]),
            rot: std::array::from_fn(|j| self.rot[j]),
            rot_b: std::array::from_fn(|j| self.rot_b[j]),
            c_real: std::array::from_fn(|i| self.c[i]),
            c_pairs: std::array::from_fn(|j| pair(&self.c, j)),
            dc_real: std::array::from_fn(|i| self.dc[i]),
            dc_pairs: std::array::from_fn(|j| pair(&self.dc, j)),
        })
    }
}

impl<const NR: usize, const NP: usize> FixedSubStepper<NR, NP> {
    /// Σ_real k·p·x + Σ_pairs k₁·(A x)₁ + k₂·(A x)₂ in [`SubStepper`]'s order.
    #[inline(always)]
    fn weighted_next(
        &self,
        k_real: &[f64; NR],
        k_pairs: &[[f64; 2]; NP],
        x: &FixedState<NR, NP>,
    ) -> f64 {
        let mut acc = 0.0;
        for i in 0..NR {
            acc += k_real[i] * self.real[i] * x.real[i];
        }
        for j in 0..NP {
            let (rc, rs) = self.rot[j];
            let [x1, x2] = x.pairs[j];
            acc += k_pairs[j][0] * (rc * x1 - rs * x2) + k_pairs[j][1] * (rs * x1 + rc * x2);
        }
        acc
    }
}

impl<const NR: usize, const NP: usize> SubStep for FixedSubStepper<NR, NP> {
    type State = FixedState<NR, NP>;
    fn zero_state(&self) -> Self::State {
        FixedState {
            real: [0.0; NR],
            pairs: [[0.0; 2]; NP],
        }
    }
    #[inline(always)]
    fn step(&self, x: &mut Self::State, w: f64) {
        for i in 0..NR {
            x.real[i] = self.real[i] * x.real[i] + self.real_b[i] * w;
        }
        for j in 0..NP {
            let ((rc, rs), (br, bi)) = (self.rot[j], self.rot_b[j]);
            let [x1, x2] = x.pairs[j];
            x.pairs[j] = [rc * x1 - rs * x2 + br * w, rs * x1 + rc * x2 + bi * w];
        }
    }
    #[inline(always)]
    fn free_next_output(&self, x: &Self::State) -> f64 {
        self.weighted_next(&self.c_real, &self.c_pairs, x)
    }
    #[inline(always)]
    fn free_next_rate(&self, x: &Self::State) -> f64 {
        self.weighted_next(&self.dc_real, &self.dc_pairs, x)
    }
}

impl ModalModel {
    /// The [`SubStepper`] with `m` sub-steps per sample, or `None` when a real pole is <= 0
    /// (no real ZOH sub-step exists) or `m == 0`.
    pub fn substepper(&self, m: usize) -> Option<SubStepper> {
        if m == 0 || self.real.iter().any(|&p| p <= 0.0) {
            return None;
        }
        let inv = 1.0 / m as f64;
        let real: Vec<f64> = self.real.iter().map(|p| p.powf(inv)).collect();
        let real_b = self
            .real
            .iter()
            .zip(&real)
            .map(|(&p, &ph)| {
                if m == 1 {
                    1.0
                } else if p == 1.0 {
                    inv // integrator: each sub-step adds w/m
                } else {
                    (ph - 1.0) / (p - 1.0)
                }
            })
            .collect();
        let ts = self.ts;
        // Continuous-time equivalent of each mode (the model is taken as a ZOH
        // discretisation): real p = e^{s·ts}; pair r·e^{±jφ} = e^{(σ ± jω)·ts}. With the
        // discrete input gain normalised to 1, the continuous one is b = s/(λ − 1).
        let nr = self.real.len();
        let mut dc = vec![0.0; self.n_states()];
        let mut dcb = 0.0;
        for (i, &p) in self.real.iter().enumerate() {
            if p == 1.0 {
                // x' = w/ts: the output derivative depends on the input only.
                dcb += self.residues[i] / ts;
                continue;
            }
            let sp = p.ln() / ts;
            dc[i] = self.residues[i] * sp;
            dcb += self.residues[i] * sp / (p - 1.0);
        }
        for (j, &(r, phi)) in self.pairs.iter().enumerate() {
            let (sig, om) = (r.ln() / ts, phi / ts);
            let i = nr + 2 * j;
            let (c1, c2) = (self.residues[i], self.residues[i + 1]);
            dc[i] = c1 * sig + c2 * om;
            dc[i + 1] = -c1 * om + c2 * sig;
            let bc = Complex64::new(sig, om) / (Complex64::from_polar(r, phi) - 1.0);
            dcb += c1 * bc.re + c2 * bc.im;
        }
        let mut rot = Vec::new();
        let mut rot_b = Vec::new();
        for &(r, phi) in &self.pairs {
            let lam = Complex64::from_polar(r, phi);
            let lh = Complex64::from_polar(r.powf(inv), phi * inv);
            let beta = if m == 1 {
                Complex64::new(1.0, 0.0)
            } else {
                (lh - 1.0) / (lam - 1.0)
            };
            rot.push((lh.re, lh.im));
            rot_b.push((beta.re, beta.im));
        }
        Some(SubStepper {
            real,
            real_b,
            rot,
            rot_b,
            c: self.residues.clone(),
            dc,
            dcb,
        })
    }
}
