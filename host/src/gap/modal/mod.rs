//! The linear part of every gap model: a stable discrete-time SISO model in real modal
//! (parallel) form, fitted by output-error least squares with variable projection.
//!
//! Structure (sample time `ts` seconds, input w, output y):
//! * each real pole p (|p| < 1) contributes a state x' = p·x + w;
//! * each complex pair r·e^{±jφ} (0 < r < 1, 0 < φ < π) contributes a rotation block
//!   [x1; x2]' = r·[[cos φ, −sin φ], [sin φ, cos φ]]·[x1; x2] + [1; 0]·w;
//! * y = Σ cᵢ·xᵢ + d·w + y₀ (residues c, feedthrough d, output offset y₀ in output units).
//!
//! This realises every SISO transfer function with distinct poles, and its states are in
//! quadrature per pair, so the least-squares regressors stay well conditioned even for lightly
//! damped or slow modes (a companion form would not).
//!
//! Fitting (variable projection, Golub & Pereyra 1973): for fixed poles the output is linear in
//! (c, d, y₀), solved by weighted linear least squares on the free-run states; the poles are
//! refined by Levenberg–Marquardt on the projected residual. Pole parameters are unconstrained
//! and always give a stable model: a real pole is sign·exp(−e^β); a pair has
//! r = exp(−e^ρ) and φ = π/(1 + e^−η).
//!
//! The fit cost used throughout the gap diagnosis is Σ_logs NRMSE², each log's squared error
//! summed after `warmup` samples and divided by (samples − warmup)·var(y) of that log.
use crate::error::{Error, Result};
use crate::lti::StateSpace;
use faer::Mat;
use num_complex::Complex64;

/// Distance from z = 1 within which a pole is taken as an integrator (an exact pole at 1).
pub const INTEGRATOR_TOL: f64 = 1e-9;

/// Stable SISO discrete-time model in real modal form (see the module docs), possibly with one
/// integrator (a real pole exactly at z = 1, fixed in every fit).
#[derive(Debug, Clone, PartialEq)]
pub struct ModalModel {
    /// Sample time in seconds (> 0).
    pub ts: f64,
    /// Real poles, each strictly inside (−1, 1), or exactly 1 (an integrator).
    pub real: Vec<f64>,
    /// Complex pairs (r, φ): poles r·e^{±jφ}, 0 < r < 1, 0 < φ < π (rad per sample).
    pub pairs: Vec<(f64, f64)>,
    /// Residues: one per real pole, then two per pair (n entries in all).
    pub residues: Vec<f64>,
    /// Feedthrough d (output units per input unit); fitted only when `use_d`.
    pub d: f64,
    /// Whether the feedthrough is a free parameter (false: d = 0, strictly proper).
    pub use_d: bool,
    /// Output offset y₀ (output units).
    pub offset: f64,
}

/// Training data for a fit: per log an input (already through any input-side effect), an
/// output, and the weight 1/((N − warmup)·var(y)) that turns squared errors into NRMSE².
#[derive(Debug, Clone)]
pub struct FitSet {
    /// Input of each log (the linear part's input w).
    pub w: Vec<Vec<f64>>,
    /// Measured output of each log.
    pub y: Vec<Vec<f64>>,
    /// NRMSE² weight of each log.
    pub weight: Vec<f64>,
    /// Samples at the start of each log excluded from the error (initial transient).
    pub warmup: usize,
    /// Drift window of the costs of augmented models ([`crate::gap::drift::scored_sse`]; a
    /// linear part with an integrator), `None`: plain squared errors.
    pub drift_window: Option<usize>,
}

impl FitSet {
    /// Builds the set; weights from the outputs. Errors when a log is not longer than the
    /// warm-up or has a constant output.
    pub fn new(w: Vec<Vec<f64>>, y: Vec<Vec<f64>>, warmup: usize) -> Result<Self> {
        let weight = nrmse_weights(&y, warmup)?;
        Ok(Self {
            w,
            y,
            weight,
            warmup,
            drift_window: None,
        })
    }

    /// Scored samples over all logs (each log's length less the warm-up).
    pub fn scored_samples(&self) -> usize {
        self.y
            .iter()
            .map(|y| y.len().saturating_sub(self.warmup))
            .sum()
    }

    /// Same outputs, weights and warm-up with a new input per log.
    pub fn with_input(&self, w: Vec<Vec<f64>>) -> Self {
        Self {
            w,
            y: self.y.clone(),
            weight: self.weight.clone(),
            warmup: self.warmup,
            drift_window: self.drift_window,
        }
    }
}

/// 1/((N − warmup)·var(y)) per log (var over the scored samples).
pub fn nrmse_weights(y: &[Vec<f64>], warmup: usize) -> Result<Vec<f64>> {
    y.iter()
        .map(|y| {
            if y.len() <= warmup + 1 {
                return Err(Error::InvalidArgument(format!(
                    "log of {} samples is not longer than the warm-up of {warmup} samples",
                    y.len()
                )));
            }
            let s = &y[warmup..];
            let n = s.len() as f64;
            let mean = s.iter().sum::<f64>() / n;
            let var = s.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
            if var.is_nan() || var <= 0.0 {
                return Err(Error::InvalidArgument(
                    "output is constant over the scored samples".into(),
                ));
            }
            Ok(1.0 / (n * var))
        })
        .collect()
}

/// NRMSE = RMS(y − ŷ) / RMS(y − mean y) over samples `warmup..`.
pub fn nrmse(y: &[f64], yhat: &[f64], warmup: usize) -> f64 {
    let n = y.len().min(yhat.len());
    if n <= warmup {
        return f64::NAN;
    }
    let s = &y[warmup..n];
    let mean = s.iter().sum::<f64>() / s.len() as f64;
    let den: f64 = s.iter().map(|v| (v - mean).powi(2)).sum();
    let num: f64 = s
        .iter()
        .zip(&yhat[warmup..n])
        .map(|(a, b)| (a - b).powi(2))
        .sum();
    (num / den).sqrt()
}

fn unit_interval_logit(x: f64) -> f64 {
    let x = x.clamp(1e-12, 1.0 - 1e-12);
    (x / (1.0 - x)).ln()
}

fn decay_param(mag: f64) -> f64 {
    let m = mag.clamp(1e-9, 1.0 - 1e-13);
    (-m.ln()).ln()
}

mod linear_fit;
mod stepper;
pub(crate) use linear_fit::solve_scaled;
pub use stepper::{FixedState, FixedSubStepper, Stepper, SubStep, SubStepper};

impl ModalModel {
    /// A model with the given poles (conjugate pairs: pass either or both members; real poles
    /// have |Im| <= 1e-9·|p|), zero residues and offset. One pole within [`INTEGRATOR_TOL`] of
    /// z = 1 is an integrator, kept exactly at 1 (and fixed by the fits). Errors for any other
    /// pole on or outside the unit circle (the diagnosis compares free-run simulations, which
    /// need a stable model) or a non-positive `ts`. Repeated poles are separated by a relative 1e-6 so their modes stay
    /// independent.
    pub fn from_poles(ts: f64, poles: &[Complex64], use_d: bool) -> Result<Self> {
        if !(ts.is_finite() && ts > 0.0) {
            return Err(Error::InvalidArgument(format!(
                "modal model: sample time {ts} s must be > 0"
            )));
        }
        let mut real = Vec::new();
        let mut pairs: Vec<(f64, f64)> = Vec::new();
        for &p in poles {
            let r = p.norm();
            if (p - Complex64::new(1.0, 0.0)).norm() <= INTEGRATOR_TOL {
                // An integrator (position output of a moving mass): kept exactly at z = 1.
                if !real.contains(&1.0) {
                    real.push(1.0);
                    continue;
                }
            }
            if r.is_nan() || r >= 1.0 {
                return Err(Error::Numerical(format!(
                    "unstable or marginally stable pole z = {p:.6} (|z| = {r:.6} >= 1)"
                )));
            }
            if p.im.abs() <= 1e-9 * r.max(1e-300) {
                let mut v = p.re;
                while real.iter().any(|&q: &f64| (q - v).abs() <= 1e-9) {
                    v *= 1.0 - 1e-6;
                }
                real.push(v);
            } else if p.im > 0.0 {
                let mut rr = r;
                let phi = p.im.atan2(p.re);
                while pairs
                    .iter()
                    .any(|&(q, f)| (q - rr).abs() <= 1e-9 && (f - phi).abs() <= 1e-9)
                {
                    rr *= 1.0 - 1e-6;
                }
                pairs.push((rr, phi));
            }
        }
        let n = real.len() + 2 * pairs.len();
        Ok(Self {
            ts,
            real,
            pairs,
            residues: vec![0.0; n],
            d: 0.0,
            use_d,
            offset: 0.0,
        })
    }

    /// Number of states n.
    pub fn n_states(&self) -> usize {
        self.real.len() + 2 * self.pairs.len()
    }

    /// The poles (z-plane), real ones first, each pair with its conjugate.
    pub fn poles(&self) -> Vec<Complex64> {
        let mut p: Vec<Complex64> = self.real.iter().map(|&v| Complex64::new(v, 0.0)).collect();
        for &(r, phi) in &self.pairs {
            p.push(Complex64::from_polar(r, phi));
            p.push(Complex64::from_polar(r, -phi));
        }
        p
    }

    /// Unconstrained pole parameters (see the module docs).
    pub fn pole_params(&self) -> Vec<f64> {
        let mut v: Vec<f64> = self.real.iter().map(|p| decay_param(p.abs())).collect();
        for &(r, phi) in &self.pairs {
            v.push(decay_param(r));
            v.push(unit_interval_logit(phi / std::f64::consts::PI));
        }
        v
    }

    /// Sets the poles from unconstrained parameters (signs of real poles are kept; an
    /// integrator stays at z = 1).
    pub fn set_pole_params(&mut self, theta: &[f64]) {
        let nr = self.real.len();
        for (i, p) in self.real.iter_mut().enumerate() {
            if *p == 1.0 {
                continue; // integrators stay put
            }
            let mag = (-theta[i].exp()).exp();
            *p = if *p < 0.0 { -mag } else { mag };
        }
        for (j, pr) in self.pairs.iter_mut().enumerate() {
            let rho = theta[nr + 2 * j];
            let eta = theta[nr + 2 * j + 1];
            pr.0 = (-rho.exp()).exp();
            pr.1 = std::f64::consts::PI / (1.0 + (-eta).exp());
        }
    }

    /// Zero state of the right size.
    pub fn zero_state(&self) -> Vec<f64> {
        vec![0.0; self.n_states()]
    }

    /// The per-sample update coefficients (rotation entries precomputed), for hot loops.
    pub fn stepper(&self) -> Stepper<'_> {
        Stepper {
            model: self,
            rot: self
                .pairs
                .iter()
                .map(|&(r, phi)| {
                    let (s, c) = phi.sin_cos();
                    (r * c, r * s)
                })
                .collect(),
        }
    }

    /// x ← A·x + B·w (convenience; loops should use [`Self::stepper`]).
    pub fn step(&self, x: &mut [f64], w: f64) {
        self.stepper().step(x, w);
    }

    /// C·x (the state part of the output, no feedthrough or offset).
    #[inline]
    pub fn state_output(&self, x: &[f64]) -> f64 {
        x.iter().zip(&self.residues).map(|(a, b)| a * b).sum()
    }

    /// C·B: the one-step response of the state output to the input.
    pub fn cb(&self) -> f64 {
        let nr = self.real.len();
        let mut acc: f64 = self.residues[..nr].iter().sum();
        for j in 0..self.pairs.len() {
            acc += self.residues[nr + 2 * j];
        }
        acc
    }

    /// Free-run output (from zero state) for input `w`, including feedthrough and offset.
    pub fn simulate(&self, w: &[f64]) -> Vec<f64> {
        macro_rules! fixed {
            ($($n:literal)*) => {
                match self.n_states() {
                    $($n => return self.simulate_fixed::<$n>(w),)*
                    _ => {}
                }
            };
        }
        if self.residues.len() == self.n_states() {
            fixed!(1 2 3 4 5 6 7 8 9 10 11 12 13 14);
        }
        let st = self.stepper();
        let mut x = self.zero_state();
        let mut y = Vec::with_capacity(w.len());
        for &wk in w {
            y.push(self.state_output(&x) + self.d * wk + self.offset);
            st.step(&mut x, wk);
        }
        y
    }

    /// [`Self::simulate`] for exactly `N` states: the state on the stack, the same
    /// arithmetic as [`Stepper::step`] and [`Self::state_output`] (so the same bits).
    fn simulate_fixed<const N: usize>(&self, w: &[f64]) -> Vec<f64> {
        let nr = self.real.len();
        let c: [f64; N] = std::array::from_fn(|i| self.residues[i]);
        let p: [f64; N] = std::array::from_fn(|i| if i < nr { self.real[i] } else { 0.0 });
        let rot = self.stepper().rot;
        let mut x = [0.0; N];
        let mut y = Vec::with_capacity(w.len());
        for &wk in w {
            let so: f64 = x.iter().zip(&c).map(|(a, b)| a * b).sum();
            y.push(so + self.d * wk + self.offset);
            for (xi, pi) in x[..nr].iter_mut().zip(&p[..nr]) {
                *xi = pi * *xi + wk;
            }
            for (xp, &(rc, rs)) in x[nr..].chunks_exact_mut(2).zip(&rot) {
                let (x1, x2) = (xp[0], xp[1]);
                xp[0] = rc * x1 - rs * x2 + wk;
                xp[1] = rs * x1 + rc * x2;
            }
        }
        y
    }

    /// The equivalent discrete [`StateSpace`] (block-diagonal modal realisation; the offset
    /// is not part of it).
    pub fn to_state_space(&self) -> Result<StateSpace> {
        let n = self.n_states();
        let nr = self.real.len();
        let mut a = Mat::<f64>::zeros(n, n);
        let mut b = Mat::<f64>::zeros(n, 1);
        for (i, &p) in self.real.iter().enumerate() {
            a[(i, i)] = p;
            b[(i, 0)] = 1.0;
        }
        for (j, &(r, phi)) in self.pairs.iter().enumerate() {
            let (s, c) = phi.sin_cos();
            let i = nr + 2 * j;
            a[(i, i)] = r * c;
            a[(i, i + 1)] = -r * s;
            a[(i + 1, i)] = r * s;
            a[(i + 1, i + 1)] = r * c;
            b[(i, 0)] = 1.0;
        }
        let c = Mat::from_fn(1, n, |_, j| self.residues[j]);
        let d = Mat::from_fn(1, 1, |_, _| self.d);
        StateSpace::new(a, b, c, d, self.ts)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::gap::simulator::uniform_noise;

    /// Direct-form recursion of the same transfer function, independent of the modal code.
    fn second_order_direct(u: &[f64], a1: f64, a2: f64, b1: f64, b2: f64) -> Vec<f64> {
        let mut y = vec![0.0; u.len()];
        for k in 0..u.len() {
            let mut v = 0.0;
            if k >= 1 {
                v += -a1 * y[k - 1] + b1 * u[k - 1];
            }
            if k >= 2 {
                v += -a2 * y[k - 2] + b2 * u[k - 2];
            }
            y[k] = v;
        }
        y
    }

    #[test]
    fn output_error_recovers_a_resonant_pair() {
        // True system: poles 0.97·e^{±j0.3}, numerator b1 z + b2.
        let (r, phi) = (0.97f64, 0.3f64);
        let (a1, a2) = (-2.0 * r * phi.cos(), r * r);
        let (b1, b2) = (0.5, 0.2);
        let u = uniform_noise(3000, 7);
        let y = second_order_direct(&u, a1, a2, b1, b2);
        // Start 10 % off in both radius decay and angle.
        let start = Complex64::from_polar(0.96, 0.33);
        let mut m = ModalModel::from_poles(1e-3, &[start], false).unwrap();
        let set = FitSet::new(vec![u.clone()], vec![y.clone()], 0).unwrap();
        let cost = m.fit_output_error(&set, 60).unwrap();
        assert!(cost < 1e-12, "cost {cost}");
        let (rr, pp) = m.pairs[0];
        assert!(
            (rr - r).abs() < 1e-7 && (pp - phi).abs() < 1e-7,
            "{rr} {pp}"
        );
        let yh = m.simulate(&u);
        assert!(nrmse(&y, &yh, 0) < 1e-7);
        // The state-space form agrees with the modal simulation.
        let ss = m.to_state_space().unwrap();
        let ys = ss.simulate_siso(&u, None).unwrap();
        for (a, b) in ys.iter().zip(&yh) {
            assert!((a - b).abs() < 1e-9 * (1.0 + b.abs()));
        }
    }

    #[test]
    fn drift_free_projection_minimises_the_drift_free_cost() {
        // An integrating plant (position of a damped mass) with a slow drift added to the
        // measured output: the drift-free step must set the residues so that the free run's
        // drift-free cost (scored_sse, the metric of every candidate) is at its minimum, and
        // the cost it returns must be that cost.
        use crate::gap::drift::scored_sse;
        let ts = 1e-3;
        let poles = [Complex64::new(1.0, 0.0), Complex64::new(0.98, 0.0)];
        let truth = {
            let mut m = ModalModel::from_poles(ts, &poles, false).unwrap();
            m.residues = vec![2e-3, -1.6e-3];
            m
        };
        let logs: Vec<Vec<f64>> = vec![uniform_noise(4000, 3), uniform_noise(3000, 11)];
        let ys: Vec<Vec<f64>> = logs
            .iter()
            .enumerate()
            .map(|(l, u)| {
                let y = truth.simulate(u);
                let noise = uniform_noise(u.len(), 40 + l as u64);
                y.iter()
                    .enumerate()
                    .zip(&noise)
                    .map(|((t, v), e)| v + 0.3 * (t as f64 * 2e-3).sin() + 1e-3 * e)
                    .collect()
            })
            .collect();
        let mut set = FitSet::new(logs.clone(), ys.clone(), 200).unwrap();
        set.drift_window = Some(200);
        let drift_cost = |m: &ModalModel| -> f64 {
            logs.iter()
                .zip(&ys)
                .zip(&set.weight)
                .map(|((u, y), wt)| wt * scored_sse(y, &m.simulate(u), 200, Some(200)))
                .sum()
        };
        let mut m = ModalModel::from_poles(ts, &poles, false).unwrap();
        let c = m.fit_linear_params(&set).unwrap();
        let free = drift_cost(&m);
        assert!(
            (c - free).abs() <= 1e-9 * free,
            "returned {c}, free run {free}"
        );
        for i in 0..2 {
            for d in [-1e-3, 1e-3] {
                let mut p = m.clone();
                p.residues[i] *= 1.0 + d;
                assert!(drift_cost(&p) > free, "residue {i} {d}: not a minimum");
            }
        }
        // The residues are those of the plant (the drift is not fitted) ...
        for (a, b) in m.residues.iter().zip(&truth.residues) {
            assert!((a - b).abs() < 0.05 * b.abs(), "{a} vs {b}");
        }
        // ... where the plain step fits part of the drift with them.
        set.drift_window = None;
        let mut plain = ModalModel::from_poles(ts, &poles, false).unwrap();
        plain.fit_linear_params(&set).unwrap();
        assert!(drift_cost(&plain) > 10.0 * free);
    }

    #[test]
    fn pole_params_roundtrip() {
        let poles = [
            Complex64::new(0.999, 0.0),
            Complex64::new(-0.5, 0.0),
            Complex64::from_polar(0.9, 2.5),
        ];
        let mut m = ModalModel::from_poles(0.01, &poles, false).unwrap();
        let th = m.pole_params();
        let before = m.clone();
        m.set_pole_params(&th);
        for (a, b) in m.poles().iter().zip(before.poles()) {
            assert!((a - b).norm() < 1e-12);
        }
    }

    #[test]
    fn output_derivative_matches_the_continuous_model() {
        // Mass-spring-damper x'' = (u − 40x − 0.8x')/0.5, output position: the derivative
        // of the output is the velocity state, checked against the continuous simulation.
        let (m, k, c) = (0.5, 40.0, 0.8);
        let a = faer::Mat::from_fn(2, 2, |i, j| match (i, j) {
            (0, 1) => 1.0,
            (1, 0) => -k / m,
            (1, 1) => -c / m,
            _ => 0.0,
        });
        let b = faer::Mat::from_fn(2, 1, |i, _| if i == 1 { 1.0 / m } else { 0.0 });
        let cm = faer::Mat::from_fn(1, 2, |_, j| if j == 0 { 1.0 } else { 0.0 });
        let cont = StateSpace::new(a, b, cm, faer::Mat::zeros(1, 1), 0.0).unwrap();
        let ts = 1e-3;
        let disc = cont.c2d_zoh(ts).unwrap();
        let vel = StateSpace::new(
            cont.a.clone(),
            cont.b.clone(),
            faer::Mat::from_fn(1, 2, |_, j| if j == 1 { 1.0 } else { 0.0 }),
            faer::Mat::zeros(1, 1),
            0.0,
        )
        .unwrap()
        .c2d_zoh(ts)
        .unwrap();
        let u = uniform_noise(2000, 3);
        let y = disc.simulate_siso(&u, None).unwrap();
        let v = vel.simulate_siso(&u, None).unwrap();
        let mut mm = ModalModel::from_poles(ts, &disc.poles().unwrap(), false).unwrap();
        let set = FitSet::new(vec![u.clone()], vec![y], 0).unwrap();
        mm.fit_linear_params(&set).unwrap();
        let sub = mm.substepper(1).unwrap();
        let mut x = mm.zero_state();
        for (k, &uk) in u.iter().enumerate() {
            // Velocity at the sample instant (before the new input acts): w = previous input.
            let w_prev = if k == 0 { 0.0 } else { u[k - 1] };
            let r = sub.rate(&x, w_prev);
            assert!(
                (r - v[k]).abs() < 1e-6 * (1.0 + v[k].abs()),
                "k {k}: {r} vs {}",
                v[k]
            );
            sub.step(&mut x, uk);
        }
    }

    #[test]
    fn unstable_pole_is_an_error() {
        let e = ModalModel::from_poles(0.01, &[Complex64::new(1.001, 0.0)], false).unwrap_err();
        assert!(e.to_string().contains("unstable"), "{e}");
        // One integrator is a model; a second pole at z = 1 is not.
        let one = Complex64::new(1.0, 0.0);
        let m = ModalModel::from_poles(0.01, &[one], false).unwrap();
        assert_eq!(m.real, vec![1.0]);
        assert!(ModalModel::from_poles(0.01, &[one, one], false).is_err());
    }

    /// Position output of a mass with viscous friction (poles 1 and e^{−(c/m)·ts}): the modal
    /// model with an exact integrator reproduces the plant's ZOH simulation, keeps the
    /// integrator through a pole update, and its output derivative is the velocity.
    #[test]
    fn integrator_reproduces_a_position_output_axis() {
        let (m, c) = (0.4, 1.3);
        let a = faer::Mat::from_fn(2, 2, |i, j| match (i, j) {
            (0, 1) => 1.0,
            (1, 1) => -c / m,
            _ => 0.0,
        });
        let b = faer::Mat::from_fn(2, 1, |i, _| if i == 1 { 1.0 / m } else { 0.0 });
        let pos = faer::Mat::from_fn(1, 2, |_, j| if j == 0 { 1.0 } else { 0.0 });
        let vel = faer::Mat::from_fn(1, 2, |_, j| if j == 1 { 1.0 } else { 0.0 });
        let cont = StateSpace::new(a.clone(), b.clone(), pos, faer::Mat::zeros(1, 1), 0.0).unwrap();
        let ts = 1e-3;
        let disc = cont.c2d_zoh(ts).unwrap();
        let vdisc = StateSpace::new(a, b, vel, faer::Mat::zeros(1, 1), 0.0)
            .unwrap()
            .c2d_zoh(ts)
            .unwrap();
        let u: Vec<f64> = uniform_noise(3000, 11);
        let y = disc.simulate_siso(&u, None).unwrap();
        let v = vdisc.simulate_siso(&u, None).unwrap();
        let mut mm = ModalModel::from_poles(ts, &disc.poles().unwrap(), false).unwrap();
        assert!(mm.real.contains(&1.0), "{:?}", mm.real);
        let set = FitSet::new(vec![u.clone()], vec![y.clone()], 0).unwrap();
        let cost = mm.fit_output_error(&set, 20).unwrap();
        assert!(cost < 1e-14, "cost {cost}");
        assert!(mm.real.contains(&1.0), "integrator moved: {:?}", mm.real);
        let sub = mm.substepper(4).unwrap();
        let mut x = mm.zero_state();
        for (k, &uk) in u.iter().enumerate() {
            let w_prev = if k == 0 { 0.0 } else { u[k - 1] };
            if k % 4 == 0 {
                // Full-step rate at the sample instant (4 sub-steps per sample below).
                let r = sub.rate(&x, w_prev);
                assert!(
                    (r - v[k]).abs() < 1e-6 * (1.0 + v[k].abs()),
                    "k {k}: {r} vs {}",
                    v[k]
                );
            }
            for _ in 0..4 {
                sub.step(&mut x, uk);
            }
        }
    }

    /// The fixed-size stepper gives the general one's bits (exact equality) for the next
    /// output, the next rate and the state, on a model with two real modes and two pairs
    /// driven by a varying input; a stepper of other mode counts is refused.
    #[test]
    fn the_fixed_substepper_gives_the_same_bits_as_the_general_one() {
        let mm = ModalModel {
            ts: 1e-3,
            real: vec![0.95, 0.6],
            pairs: vec![(0.97, 0.3), (0.9, 1.1)],
            residues: vec![0.3, -0.2, 0.7, 0.1, -0.4, 0.25],
            d: 0.0,
            use_d: false,
            offset: 0.0,
        };
        let sub = mm.substepper(4).unwrap();
        let fixed = sub.fixed::<2, 2>().unwrap();
        assert!(sub.fixed::<1, 2>().is_none() && sub.fixed::<2, 1>().is_none());
        let mut x = SubStep::zero_state(&sub);
        let mut xf = SubStep::zero_state(&fixed);
        for k in 0..400 {
            let w = (0.37 * k as f64).sin() + 0.2 * (k % 7) as f64;
            let (o, of) = (
                SubStep::free_next_output(&sub, &x),
                fixed.free_next_output(&xf),
            );
            let (r, rf) = (SubStep::free_next_rate(&sub, &x), fixed.free_next_rate(&xf));
            assert_eq!(o.to_bits(), of.to_bits(), "output at {k}");
            assert_eq!(r.to_bits(), rf.to_bits(), "rate at {k}");
            SubStep::step(&sub, &mut x, w);
            fixed.step(&mut xf, w);
        }
        assert!(x.iter().any(|v| v.abs() > 0.1), "the state moved: {x:?}");
    }
}
