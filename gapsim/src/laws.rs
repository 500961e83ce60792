//! The effect laws of the independent simulator, with their parameters in physical units.
//!
//! Friction (a force opposing the velocity v of one body, N or N·m):
//! * [`FrictionLaw::Karnopp`]: switch model with a stick band. A body at rest stays at rest
//!   (velocity exactly zero, friction balancing the rest of the forces) while the force that
//!   would accelerate it stays within ±`breakaway`; sliding, it feels `coulomb`·sign(v). Coulomb
//!   friction with sticking is the case `breakaway == coulomb`.
//! * [`FrictionLaw::Stribeck`]: the same stick band with breakaway `stat`; sliding friction
//!   `(coulomb + (stat − coulomb)·exp(−(|v|/v_s)²))·sign(v) + viscous·v`.
//! * [`FrictionLaw::LuGre`]: bristle state z, ż = v − σ0·|v|·z/g(v),
//!   g(v) = coulomb + (stat − coulomb)·exp(−(v/v_s)²), F = σ0·z + σ1·ż + σ2·v (smooth; no stick
//!   mode, the bristles give presliding displacement).
//! * [`FrictionLaw::Dahl`]: ż = v − σ0·|v|·z/coulomb, F = σ0·z (rate-independent hysteresis
//!   reaching the Coulomb level).
//!
//! Steady sliding at constant v ≠ 0 gives the same force for Stribeck and LuGre (with
//! σ2 = viscous): g(v)·sign(v) + σ2·v (the bristle state settles at z = g(v)·sign(v)/σ0).
use std::f64::consts::PI;

/// A friction law and its parameters (forces in N or N·m, velocities in the body's units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FrictionLaw {
    /// Switch model with stick band (Coulomb friction when `breakaway == coulomb`).
    Karnopp {
        /// Sliding (Coulomb) level.
        coulomb: f64,
        /// Breakaway level (>= coulomb).
        breakaway: f64,
    },
    /// Stick band plus a Stribeck curve while sliding.
    Stribeck {
        /// Coulomb level.
        coulomb: f64,
        /// Static (breakaway) level.
        stat: f64,
        /// Stribeck velocity.
        v_s: f64,
        /// Viscous coefficient of the friction law (on top of the plant's).
        viscous: f64,
    },
    /// LuGre bristle model.
    LuGre {
        /// Coulomb level.
        coulomb: f64,
        /// Static level.
        stat: f64,
        /// Stribeck velocity.
        v_s: f64,
        /// Bristle stiffness (force per unit displacement).
        sigma0: f64,
        /// Bristle damping (force per unit velocity).
        sigma1: f64,
        /// Viscous coefficient.
        sigma2: f64,
    },
    /// Dahl model.
    Dahl {
        /// Coulomb level.
        coulomb: f64,
        /// Rest stiffness (force per unit displacement).
        sigma0: f64,
    },
}

impl FrictionLaw {
    /// The level a body at rest must overcome (breakaway / static level; Coulomb for Dahl).
    pub fn breakaway(&self) -> f64 {
        match *self {
            FrictionLaw::Karnopp { breakaway, .. } => breakaway,
            FrictionLaw::Stribeck { stat, .. } | FrictionLaw::LuGre { stat, .. } => stat,
            FrictionLaw::Dahl { coulomb, .. } => coulomb,
        }
    }

    /// The sliding (Coulomb) level.
    pub fn coulomb(&self) -> f64 {
        match *self {
            FrictionLaw::Karnopp { coulomb, .. }
            | FrictionLaw::Stribeck { coulomb, .. }
            | FrictionLaw::LuGre { coulomb, .. }
            | FrictionLaw::Dahl { coulomb, .. } => coulomb,
        }
    }

    /// Whether the law has a stick mode (switch model) rather than an internal state.
    pub fn has_stick_mode(&self) -> bool {
        matches!(
            self,
            FrictionLaw::Karnopp { .. } | FrictionLaw::Stribeck { .. }
        )
    }

    /// Whether the law has the bristle state z.
    pub fn has_state(&self) -> bool {
        !self.has_stick_mode()
    }

    /// Sliding friction magnitude at speed |v| > 0 for the switch-model laws.
    pub fn sliding(&self, speed: f64) -> f64 {
        match *self {
            FrictionLaw::Karnopp { coulomb, .. } => coulomb,
            FrictionLaw::Stribeck {
                coulomb,
                stat,
                v_s,
                viscous,
            } => coulomb + (stat - coulomb) * (-(speed / v_s).powi(2)).exp() + viscous * speed,
            FrictionLaw::LuGre {
                coulomb,
                stat,
                v_s,
                sigma2,
                ..
            } => coulomb + (stat - coulomb) * (-(speed / v_s).powi(2)).exp() + sigma2 * speed,
            FrictionLaw::Dahl { coulomb, .. } => coulomb,
        }
    }

    /// For the bristle laws: (ż, F) at velocity v and bristle state z.
    pub fn bristle(&self, v: f64, z: f64) -> (f64, f64) {
        match *self {
            FrictionLaw::LuGre {
                coulomb,
                stat,
                v_s,
                sigma0,
                sigma1,
                sigma2,
            } => {
                let g = coulomb + (stat - coulomb) * (-(v / v_s).powi(2)).exp();
                let zd = v - sigma0 * v.abs() * z / g;
                (zd, sigma0 * z + sigma1 * zd + sigma2 * v)
            }
            FrictionLaw::Dahl { coulomb, sigma0 } => {
                let zd = v - sigma0 * v.abs() * z / coulomb;
                (zd, sigma0 * z)
            }
            _ => (0.0, 0.0),
        }
    }

    /// Natural scale of the bristle state, for the integrator's tolerance.
    pub fn z_scale(&self) -> f64 {
        match *self {
            FrictionLaw::LuGre { stat, sigma0, .. } => stat / sigma0,
            FrictionLaw::Dahl { coulomb, sigma0 } => coulomb / sigma0,
            _ => 1.0,
        }
    }
}

/// The body friction acts on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Body {
    /// The driven (first / only) body.
    Motor,
    /// The load of a two-mass plant.
    Load,
}

/// A lightly damped second-order mode ω²/(s² + 2ζωs + ω²) (unit DC gain).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mode {
    /// Natural frequency, Hz.
    pub freq_hz: f64,
    /// Damping ratio.
    pub damping: f64,
}

impl Mode {
    /// Natural frequency, rad/s.
    pub fn omega(&self) -> f64 {
        2.0 * PI * self.freq_hz
    }
}

/// Every effect the simulator can place, each optional (physical units; see the fields).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Effects {
    /// Friction law and the body it acts on.
    pub friction: Option<(FrictionLaw, Body)>,
    /// Dead band of total width (input units) on the held command.
    pub drive_deadzone: Option<f64>,
    /// Symmetric amplitude limit (input units) on the held command.
    pub drive_saturation: Option<f64>,
    /// Total play (input units) of a play operator on the held command.
    pub drive_play: Option<f64>,
    /// Slew-rate limit of the drive output (input units per second).
    pub slew_rate: Option<f64>,
    /// Delay of the command (s, any real value >= 0).
    pub input_delay: f64,
    /// Mode between the drive and the plant.
    pub actuator_mode: Option<Mode>,
    /// Total backlash (rad of shaft twist) in the shaft of a two-mass plant.
    pub shaft_backlash: Option<f64>,
    /// Clamp of one plant state: (state index, limit in that state's units).
    pub state_limit: Option<(usize, f64)>,
    /// Mode between the plant output and the sensor.
    pub sensor_mode: Option<Mode>,
    /// Delay of the sampled output (s, any real value >= 0).
    pub output_delay: f64,
    /// Sensor range: outputs beyond ±limit read as ±limit (output units).
    pub sensor_clip: Option<f64>,
    /// Sensor resolution: the reading is step·round(reading/step), after the noise (output units).
    pub quant_step: Option<f64>,
}

/// Dead band of total width `width`: 0 inside ±width/2, shifted linear outside.
pub fn dead_band(u: f64, width: f64) -> f64 {
    let h = 0.5 * width;
    if u > h {
        u - h
    } else if u < -h {
        u + h
    } else {
        0.0
    }
}

/// Play (backlash) operator of total play `play`: the output follows the input only once the
/// input has moved `play`/2 away from it; `last` is the previous output.
pub fn play_operator(u: f64, last: f64, play: f64) -> f64 {
    let h = 0.5 * play;
    if u - last > h {
        u - h
    } else if last - u > h {
        u + h
    } else {
        last
    }
}

/// Mid-tread quantizer with step `step`.
pub fn quantizer(y: f64, step: f64) -> f64 {
    step * (y / step).round()
}
