//! Discrete plant simulations that stand in for the hardware under QEMU.
//!
//! [`Axis`]: a flexible axis (gimbal, joint with a compliant transmission, magnetic-bearing
//! axis with a restoring stiffness) driven by a torque actuator through a zero-order hold,
//!
//! ```text
//! J θ'' + b θ' + k θ = K·u(t − d·T) − F_c·ω/√(ω² + ε²),   ω = θ',
//! ```
//!
//! with θ in rad (the measured output), u in actuator units, J in kg·m², b in N·m·s/rad, k in
//! N·m/rad, K in N·m per actuator unit, F_c the Coulomb friction torque in N·m (smoothed over
//! |ω| ≲ ε rad/s so the integrator stays well posed), d whole samples of transport delay and T
//! the sample time in s. The continuous dynamics are integrated by classical Runge–Kutta (RK4)
//! with `substeps` steps per sample, the input held constant over the sample (ZOH), so without
//! friction the sampled plant is the ZOH discretisation of
//! `G(s) = K / (J s² + b s + k)` times `z^-d` (RK4 error ~ (ωT/substeps)⁵ per step).
//! The measured output is `y[k] = θ(kT) + n[k]`, n white with RMS `noise_rms_rad`
//! (Irwin–Hall sum of four uniforms from a seeded SplitMix64: near-Gaussian, bounded).
//!
//! Scenarios of the power-up check: nominal; drifted inertia (e.g. J × 1.3); extra delay;
//! Coulomb friction.
//!
//! Two effects of the closed-loop image (`closedloop`), both as the gap diagnosis models them
//! (`ferrosid::gap::effect`), off by default:
//! * a dead zone of full width `dead_zone` on the command, before the actuator gain:
//!   `w = sign(u)·max(|u| − dead_zone/2, 0)`;
//! * stick-slip friction (`breakaway > 0`): Karnopp's law with sliding level `coulomb` and
//!   static level `breakaway` (N·m): each sub-step the mass is held at rest when the torque
//!   needed to hold it is at most the static limit (`breakaway` while stuck, `coulomb` while
//!   sliding), else it slides against `coulomb`. The sub-steps are semi-implicit Euler
//!   (velocity first, then position) instead of RK4, since the friction force is decided per
//!   sub-step; with `breakaway == coulomb` this is Coulomb friction with sticking.
//!
//! Optionally ([`Axis::with_torque_lag`]) the torque follows K·w through a first-order lag τ_T
//! (a motor's current loop), `τ_T T' = K·w − T`, and the body sees T: the friction then acts on
//! the body behind the lag, not on the command. The lag state is advanced exactly
//! (T ← a·T + (1 − a)·K·w, a = e^{−h/τ_T}) at each sub-step before the body's step (RK4 then
//! holds it over the sub-step).
use ferrosid_firmware::rng::SplitMix64;

/// Longest transport delay the simulation holds, samples.
pub const MAX_DELAY: usize = 64;
/// Most RK4 substeps per sample.
pub const MAX_SUBSTEPS: u32 = 256;

/// Physical parameters of an [`Axis`] (units in the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisParams {
    /// Inertia J, kg·m² (> 0).
    pub inertia: f32,
    /// Viscous damping b, N·m·s/rad (>= 0).
    pub damping: f32,
    /// Stiffness k, N·m/rad (>= 0).
    pub stiffness: f32,
    /// Actuator gain K, N·m per input unit (!= 0).
    pub gain: f32,
    /// Coulomb friction torque F_c, N·m (>= 0).
    pub coulomb: f32,
    /// Friction smoothing velocity ε, rad/s (> 0).
    pub coulomb_smoothing: f32,
    /// Extra transport delay, whole samples (`0..MAX_DELAY`).
    pub delay_samples: u32,
    /// RMS of the additive measurement noise, rad (>= 0).
    pub noise_rms: f32,
    /// Seed of the noise generator.
    pub seed: u64,
    /// RK4 steps per sample (`1..=MAX_SUBSTEPS`).
    pub substeps: u32,
    /// Full width of the dead zone on the command, input units (>= 0; 0: none).
    pub dead_zone: f32,
    /// Static (breakaway) friction torque, N·m (0: the smoothed Coulomb law; else >= coulomb,
    /// Karnopp stick-slip, see the module docs).
    pub breakaway: f32,
}

/// A parameter of [`AxisParams`] is out of range; names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InvalidParameter(pub &'static str);

/// The simulated axis (see the module docs).
#[derive(Debug, Clone)]
pub struct Axis {
    p: AxisParams,
    h: f32,
    theta: f32,
    omega: f32,
    stuck: bool,
    /// Torque-lag factor a = e^{−h/τ_T} per sub-step (0: no lag) and the torque T, N·m.
    lag_a: f32,
    torque: f32,
    line: [f32; MAX_DELAY],
    pos: usize,
    rng: SplitMix64,
}

impl Axis {
    /// An axis at rest, sampled every `ts_s` seconds.
    ///
    /// # Errors
    /// [`InvalidParameter`] naming the first parameter out of range (see [`AxisParams`]), or
    /// `"ts_s"` when the sample time is not finite and positive.
    pub fn new(p: AxisParams, ts_s: f32) -> Result<Self, InvalidParameter> {
        let ok = |v: f32, lo: f32| v.is_finite() && v >= lo;
        if !(ok(p.inertia, 0.0) && p.inertia > 0.0) {
            return Err(InvalidParameter("inertia"));
        }
        if !ok(p.damping, 0.0) {
            return Err(InvalidParameter("damping"));
        }
        if !ok(p.stiffness, 0.0) {
            return Err(InvalidParameter("stiffness"));
        }
        if !(p.gain.is_finite() && p.gain != 0.0) {
            return Err(InvalidParameter("gain"));
        }
        if !ok(p.coulomb, 0.0) {
            return Err(InvalidParameter("coulomb"));
        }
        if !(ok(p.coulomb_smoothing, 0.0) && p.coulomb_smoothing > 0.0) {
            return Err(InvalidParameter("coulomb_smoothing"));
        }
        if p.delay_samples as usize >= MAX_DELAY {
            return Err(InvalidParameter("delay"));
        }
        if !ok(p.noise_rms, 0.0) {
            return Err(InvalidParameter("noise"));
        }
        if !(1..=MAX_SUBSTEPS).contains(&p.substeps) {
            return Err(InvalidParameter("substeps"));
        }
        if !(ts_s.is_finite() && ts_s > 0.0) {
            return Err(InvalidParameter("ts_s"));
        }
        if !ok(p.dead_zone, 0.0) {
            return Err(InvalidParameter("dead_zone"));
        }
        if !(ok(p.breakaway, 0.0) && (p.breakaway == 0.0 || p.breakaway >= p.coulomb)) {
            return Err(InvalidParameter("breakaway"));
        }
        Ok(Self {
            p,
            h: ts_s / p.substeps as f32,
            theta: 0.0,
            omega: 0.0,
            stuck: true,
            lag_a: 0.0,
            torque: 0.0,
            line: [0.0; MAX_DELAY],
            pos: 0,
            rng: SplitMix64::new(p.seed),
        })
    }

    /// The axis with its torque lagging the command by a first-order lag of `tau_s` seconds
    /// (module docs; 0: no lag).
    ///
    /// # Errors
    /// `"lag"` when `tau_s` is not finite and >= 0.
    pub fn with_torque_lag(mut self, tau_s: f32) -> Result<Self, InvalidParameter> {
        if !(tau_s.is_finite() && tau_s >= 0.0) {
            return Err(InvalidParameter("lag"));
        }
        self.lag_a = if tau_s > 0.0 {
            libm::expf(-self.h / tau_s)
        } else {
            0.0
        };
        Ok(self)
    }

    /// The torque the body sees after the lag for this sub-step's command torque `tau`.
    fn lagged(&mut self, tau: f32) -> f32 {
        if self.lag_a > 0.0 {
            self.torque = self.lag_a * self.torque + (1.0 - self.lag_a) * tau;
            self.torque
        } else {
            tau
        }
    }

    /// The parameters.
    pub fn params(&self) -> &AxisParams {
        &self.p
    }

    /// The true angular velocity ω, rad/s (what friction opposes).
    pub fn velocity(&self) -> f32 {
        self.omega
    }

    /// Angular acceleration for state (θ, ω) under applied torque `tau` (N·m).
    fn accel(&self, theta: f32, omega: f32, tau: f32) -> f32 {
        let p = &self.p;
        let friction = if p.coulomb > 0.0 {
            let e = p.coulomb_smoothing;
            p.coulomb * omega / libm::sqrtf(omega * omega + e * e)
        } else {
            0.0
        };
        (tau - p.damping * omega - p.stiffness * theta - friction) / p.inertia
    }

    /// Near-Gaussian noise sample of unit variance (Irwin–Hall, four uniforms).
    fn unit_noise(&mut self) -> f32 {
        let mut s = 0.0f32;
        for _ in 0..4 {
            s += (self.rng.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0);
        }
        (s - 2.0) * 1.732_050_8
    }

    /// One sample period: returns the measured output `y[k] = θ(kT) + n[k]`, then applies the
    /// command `u` (after the transport delay) through the ZOH for one period.
    pub fn step(&mut self, u: f32) -> f32 {
        let y = self.measure();
        self.advance(u);
        y
    }

    /// The measured output `y[k] = θ(kT) + n[k]` (draws the noise sample; call once per
    /// period, before [`Axis::advance`]).
    pub fn measure(&mut self) -> f32 {
        let noise = if self.p.noise_rms > 0.0 {
            self.p.noise_rms * self.unit_noise()
        } else {
            0.0
        };
        self.theta + noise
    }

    /// Applies the command `u` (after the transport delay and the dead zone) through the ZOH
    /// for one period. A controller that computes u from this period's [`Axis::measure`]
    /// and applies it at once has no computation delay (the host's loop model).
    pub fn advance(&mut self, u: f32) {
        let d = self.p.delay_samples as usize;
        let u_applied = if d == 0 {
            u
        } else {
            let slot = self.pos % d;
            let old = self.line.get(slot).copied().unwrap_or(0.0);
            if let Some(s) = self.line.get_mut(slot) {
                *s = u;
            }
            self.pos = (slot + 1) % d;
            old
        };
        let half = 0.5 * self.p.dead_zone;
        let w = if half > 0.0 {
            if u_applied > half {
                u_applied - half
            } else if u_applied < -half {
                u_applied + half
            } else {
                0.0
            }
        } else {
            u_applied
        };
        let tau = self.p.gain * w;
        if self.p.breakaway > 0.0 {
            self.stick_slip_period(tau);
            return;
        }
        let h = self.h;
        let tau_cmd = tau;
        for _ in 0..self.p.substeps {
            let tau = self.lagged(tau_cmd);
            let (t0, w0) = (self.theta, self.omega);
            let k1t = w0;
            let k1w = self.accel(t0, w0, tau);
            let k2t = w0 + 0.5 * h * k1w;
            let k2w = self.accel(t0 + 0.5 * h * k1t, k2t, tau);
            let k3t = w0 + 0.5 * h * k2w;
            let k3w = self.accel(t0 + 0.5 * h * k2t, k3t, tau);
            let k4t = w0 + h * k3w;
            let k4w = self.accel(t0 + h * k3t, k4t, tau);
            self.theta = t0 + h / 6.0 * (k1t + 2.0 * k2t + 2.0 * k3t + k4t);
            self.omega = w0 + h / 6.0 * (k1w + 2.0 * k2w + 2.0 * k3w + k4w);
        }
    }

    /// One sample period of stick-slip friction under torque `tau` (module docs).
    fn stick_slip_period(&mut self, tau_cmd: f32) {
        let p = self.p;
        let h = self.h;
        let g = h / p.inertia;
        for _ in 0..p.substeps {
            let tau = self.lagged(tau_cmd);
            // Velocity at the end of the sub-step without friction; friction changes it by −g·F.
            let v_trial =
                self.omega + g * (tau - p.damping * self.omega - p.stiffness * self.theta);
            let hold = v_trial / g;
            let limit = if self.stuck { p.breakaway } else { p.coulomb };
            let f = if hold.abs() <= limit {
                self.stuck = true;
                hold
            } else {
                self.stuck = false;
                if hold > 0.0 {
                    p.coulomb
                } else {
                    -p.coulomb
                }
            };
            self.omega = v_trial - g * f;
            self.theta += h * self.omega;
        }
    }
}
