//! The unmodelled effects the gap diagnosis knows, and the primitives that realise them.
//!
//! Where each effect sits (the same convention for the benchmark simulator, `ferrosid_sim::plant`
//! in the dev crate `sim/`, and for the augmented models fitted by the diagnosis):
//!
//! | effect | parameters (units) | location |
//! |---|---|---|
//! | `coulomb_friction` | `level` (input units) | force node of the driven mass, opposing its velocity; sticks when the drive cannot overcome `level` |
//! | `stiction` | `level`, `breakaway` (input units, `breakaway >= level`) | as above; a stuck mass breaks away only when the drive exceeds `breakaway`, then slides against `level` (Karnopp) |
//! | `backlash` | `gap` (input units) | play operator on the actuator input: the input reaches the plant only after the command has taken up the play (total play `gap`, ±`gap`/2 about the last engaged value) |
//! | `deadzone` | `width` (input units) | static dead band on the input: w = sign(u)·max(\|u\| − width/2, 0) |
//! | `saturation` | `limit` (input units) | w = clamp(u, −limit, limit) |
//! | `time_delay` | `seconds` | pure delay of the input |
//! | `resonance` | `freq_hz` (Hz), `damping` (ratio) | extra mode in series with the input, ω²/(s² + 2ζωs + ω²), unit DC gain |
//! | `quantization` | `step` (output units) | sensor rounding y = step·round(y/step) |
//! | `slew_rate` | `rate` (input units per second) | rate limit on the command in continuous time: the drive output ramps at most `rate`; the linear part receives its average over each sample |
//! | `state_limit` | `limit` (input units) | a level that saturates inside the plant: the state of the linear part's slowest stable real mode (the body's velocity behind an integrator, a body's speed) is held within the level a constant input `limit` settles it at; while it is held, every mode sees the input that holds it there (see [`crate::gap::state_limit::state_clamp`]) |
//! | `current_limit` | `limit` (input units) | the drive's current (torque) limit: the input may exceed the one that holds the slowest stable real mode's present state by at most `limit`, which bounds that mode's change per sample (an acceleration limit; for a voltage-driven motor `limit` = R·I_max, see [`crate::gap::state_limit::rate_clamp`]) |
//!
//! The same kind may act at several places ([`crate::gap::place`]): `saturation` at the sensor
//! clips the output (`limit` then in output units), `backlash` in the drivetrain of a two-mass
//! structure is a dead zone on the shaft twist (`gap` then in the structure's position units,
//! see [`crate::gap::structure`]), friction on the load acts on the second inertia.
//!
//! Friction parameters are in input units: the input that balances the friction force in steady
//! state (for a voltage-driven DC motor, friction torque × R / k_t).
use crate::error::{Error, Result};
use crate::lti::StateSpace;
use faer::Mat;
use std::fmt;

/// The kinds of effect, in the order they are reported when tied.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum EffectKind {
    /// Coulomb (sliding) friction with sticking.
    CoulombFriction,
    /// Static friction above the sliding level (stick-slip).
    Stiction,
    /// Play in the actuator command path.
    Backlash,
    /// Dead band around zero input.
    Deadzone,
    /// Input amplitude limit.
    Saturation,
    /// Pure input delay.
    TimeDelay,
    /// Unmodelled lightly damped mode.
    Resonance,
    /// Output quantization (sensor resolution).
    Quantization,
    /// Rate limit in the command path.
    SlewRate,
    /// Saturating level inside the plant.
    StateLimit,
    /// Limit on how hard the drive may push the body beyond what holds its speed (a voltage
    /// drive's current limit: the current follows voltage − back-EMF).
    CurrentLimit,
}

impl EffectKind {
    /// Every kind, in report order.
    pub const ALL: [EffectKind; 11] = [
        EffectKind::CoulombFriction,
        EffectKind::Stiction,
        EffectKind::Backlash,
        EffectKind::Deadzone,
        EffectKind::Saturation,
        EffectKind::TimeDelay,
        EffectKind::Resonance,
        EffectKind::Quantization,
        EffectKind::SlewRate,
        EffectKind::StateLimit,
        EffectKind::CurrentLimit,
    ];

    /// The name used in reports and JSON (`coulomb_friction`, ...).
    pub fn name(self) -> &'static str {
        match self {
            EffectKind::CoulombFriction => "coulomb_friction",
            EffectKind::Stiction => "stiction",
            EffectKind::Backlash => "backlash",
            EffectKind::Deadzone => "deadzone",
            EffectKind::Saturation => "saturation",
            EffectKind::TimeDelay => "time_delay",
            EffectKind::Resonance => "resonance",
            EffectKind::Quantization => "quantization",
            EffectKind::SlewRate => "slew_rate",
            EffectKind::StateLimit => "state_limit",
            EffectKind::CurrentLimit => "current_limit",
        }
    }

    /// Parses a report name back into a kind.
    pub fn from_name(s: &str) -> Option<Self> {
        Self::ALL.iter().copied().find(|k| k.name() == s)
    }

    /// Whether the kind clamps a state of the linear part's body mode (its level: a state
    /// limit; its rate: a current limit), realised on the drive input every mode sees.
    pub fn is_state_clamp(self) -> bool {
        matches!(self, EffectKind::StateLimit | EffectKind::CurrentLimit)
    }

    /// Whether the kind is friction (Coulomb or stiction).
    pub fn is_friction(self) -> bool {
        matches!(self, EffectKind::CoulombFriction | EffectKind::Stiction)
    }

    /// Number of parameters.
    pub fn n_params(self) -> usize {
        match self {
            EffectKind::Stiction | EffectKind::Resonance => 2,
            _ => 1,
        }
    }
}

impl fmt::Display for EffectKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One effect with its parameters (units in the module table).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Effect {
    /// Sliding friction `level` (input units).
    CoulombFriction {
        /// Sliding friction, input units.
        level: f64,
    },
    /// Sliding friction `level` and static (breakaway) friction, input units; with a Stribeck
    /// velocity > 0 the sliding force decays from the breakaway to the level over it
    /// ([`StickSlip::with_stribeck_velocity`]), else it drops to the level at once (Karnopp).
    Stiction {
        /// Sliding friction, input units.
        level: f64,
        /// Breakaway (static) friction, input units, >= level.
        breakaway: f64,
        /// Stribeck velocity in the velocity units the friction sees (the output's, per second
        /// for a position output); 0: none (a Karnopp switch).
        stribeck_velocity: f64,
    },
    /// Total play `gap` in input units.
    Backlash {
        /// Total play, input units.
        gap: f64,
    },
    /// Full dead-band width in input units.
    Deadzone {
        /// Full width of the dead band, input units.
        width: f64,
    },
    /// Symmetric input limit.
    Saturation {
        /// Largest |input| reaching the plant, input units.
        limit: f64,
    },
    /// Input delay in seconds.
    TimeDelay {
        /// Delay in seconds.
        seconds: f64,
    },
    /// Series mode at `freq_hz` (Hz, undamped natural frequency) with damping ratio `damping`.
    Resonance {
        /// Natural frequency, Hz.
        freq_hz: f64,
        /// Damping ratio (dimensionless).
        damping: f64,
    },
    /// Output quantization step in output units.
    Quantization {
        /// Step, output units.
        step: f64,
    },
    /// Command rate limit.
    SlewRate {
        /// Largest change of the command per second, input units/s.
        rate: f64,
    },
    /// Saturating level inside the plant.
    StateLimit {
        /// Level, input units: the constant input that settles the limited state at it.
        limit: f64,
    },
    /// Current (torque) limit of the drive.
    CurrentLimit {
        /// Largest excess of the input over the one that holds the body's present speed,
        /// input units (for a voltage-driven motor, R·I_max volts).
        limit: f64,
    },
}

impl Effect {
    /// Its kind.
    pub fn kind(&self) -> EffectKind {
        match self {
            Effect::CoulombFriction { .. } => EffectKind::CoulombFriction,
            Effect::Stiction { .. } => EffectKind::Stiction,
            Effect::Backlash { .. } => EffectKind::Backlash,
            Effect::Deadzone { .. } => EffectKind::Deadzone,
            Effect::Saturation { .. } => EffectKind::Saturation,
            Effect::TimeDelay { .. } => EffectKind::TimeDelay,
            Effect::Resonance { .. } => EffectKind::Resonance,
            Effect::Quantization { .. } => EffectKind::Quantization,
            Effect::SlewRate { .. } => EffectKind::SlewRate,
            Effect::StateLimit { .. } => EffectKind::StateLimit,
            Effect::CurrentLimit { .. } => EffectKind::CurrentLimit,
        }
    }

    /// Named parameters, in a fixed order.
    pub fn params(&self) -> Vec<(&'static str, f64)> {
        match *self {
            Effect::CoulombFriction { level } => vec![("level", level)],
            Effect::Stiction {
                level,
                breakaway,
                stribeck_velocity,
            } => {
                let mut v = vec![("level", level), ("breakaway", breakaway)];
                if stribeck_velocity > 0.0 {
                    v.push(("stribeck_velocity", stribeck_velocity));
                }
                v
            }
            Effect::Backlash { gap } => vec![("gap", gap)],
            Effect::Deadzone { width } => vec![("width", width)],
            Effect::Saturation { limit } => vec![("limit", limit)],
            Effect::TimeDelay { seconds } => vec![("seconds", seconds)],
            Effect::Resonance { freq_hz, damping } => {
                vec![("freq_hz", freq_hz), ("damping", damping)]
            }
            Effect::Quantization { step } => vec![("step", step)],
            Effect::SlewRate { rate } => vec![("rate", rate)],
            Effect::StateLimit { limit } | Effect::CurrentLimit { limit } => {
                vec![("limit", limit)]
            }
        }
    }

    /// Checks that the parameters are finite and in range (levels, widths, limits, steps > 0;
    /// delay >= 0; breakaway >= level; 0 < damping; freq_hz > 0).
    pub fn validate(&self) -> Result<()> {
        let bad = |what: &str| Err(Error::InvalidArgument(format!("{}: {what}", self.kind())));
        for (n, v) in self.params() {
            if !v.is_finite() {
                return bad(&format!("parameter {n} = {v} is not finite"));
            }
        }
        match *self {
            Effect::CoulombFriction { level } if level <= 0.0 => bad("level must be > 0"),
            Effect::Stiction {
                level,
                breakaway,
                stribeck_velocity,
            } if level <= 0.0
                || breakaway < level
                || !(stribeck_velocity >= 0.0 && stribeck_velocity.is_finite()) =>
            {
                bad("need 0 < level <= breakaway and stribeck_velocity >= 0")
            }
            Effect::Backlash { gap } if gap <= 0.0 => bad("gap must be > 0"),
            Effect::Deadzone { width } if width <= 0.0 => bad("width must be > 0"),
            Effect::Saturation { limit } if limit <= 0.0 => bad("limit must be > 0"),
            Effect::TimeDelay { seconds } if seconds < 0.0 => bad("seconds must be >= 0"),
            Effect::Resonance { freq_hz, damping } if freq_hz <= 0.0 || damping <= 0.0 => {
                bad("need freq_hz > 0 and damping > 0")
            }
            Effect::Quantization { step } if step <= 0.0 => bad("step must be > 0"),
            Effect::SlewRate { rate } if rate <= 0.0 => bad("rate must be > 0"),
            Effect::StateLimit { limit } | Effect::CurrentLimit { limit } if limit <= 0.0 => {
                bad("limit must be > 0")
            }
            _ => Ok(()),
        }
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.kind())?;
        let p: Vec<String> = self
            .params()
            .iter()
            .map(|(n, v)| format!("{n}={v:.4}"))
            .collect();
        write!(f, " {{{}}}", p.join(", "))
    }
}

/// Dead band of full width `width`: sign(u)·max(|u| − width/2, 0).
#[inline]
pub fn deadzone(u: f64, width: f64) -> f64 {
    let h = 0.5 * width;
    if u > h {
        u - h
    } else if u < -h {
        u + h
    } else {
        0.0
    }
}

/// clamp(u, −limit, limit).
#[inline]
pub fn saturation(u: f64, limit: f64) -> f64 {
    u.clamp(-limit, limit)
}

/// step·round(y/step) (ties away from zero).
#[inline]
pub fn quantize(y: f64, step: f64) -> f64 {
    step * (y / step).round()
}

/// Rate limiter: the output moves toward the input by at most `max_step` per sample, starting
/// at 0.
#[derive(Debug, Clone, Copy)]
pub struct RateLimiter {
    max_step: f64,
    out: f64,
}

impl RateLimiter {
    /// Limiter with the largest change per sample `max_step` (>= 0) and output 0.
    pub fn new(max_step: f64) -> Self {
        Self { max_step, out: 0.0 }
    }
    /// Next output for input `u`.
    #[inline]
    pub fn apply(&mut self, u: f64) -> f64 {
        self.out += (u - self.out).clamp(-self.max_step, self.max_step);
        self.out
    }
    /// The limit acting in continuous time on `u` held over one sample (an analog drive, or a
    /// digital one updated much faster than the log): the output ramps toward `u` at
    /// `max_step` per sample until it reaches it; returns the ramp's **average over the
    /// sample**, which is what a plant sampled with a zero-order hold responds to (to first
    /// order in ts). With d = u − out: |d| ≥ max_step gives out + max_step·sign(d)/2 (a ramp
    /// over the whole sample: half a sample behind [`Self::apply`]); else u − d·|d|/(2·max_step).
    #[inline]
    pub fn apply_averaged(&mut self, u: f64) -> f64 {
        let m = self.max_step;
        let d = u - self.out;
        let avg = if d.abs() >= m {
            self.out + 0.5 * m * d.signum()
        } else {
            u - 0.5 * d * d.abs() / m
        };
        self.out += d.clamp(-m, m);
        avg
    }
}

/// Play (backlash) operator with total play `gap`, starting engaged at 0: the output follows
/// the input only once the input is more than `gap`/2 away from it.
#[derive(Debug, Clone, Copy)]
pub struct Play {
    half: f64,
    out: f64,
}

impl Play {
    /// Operator with total play `gap` (>= 0) and output 0.
    pub fn new(gap: f64) -> Self {
        Self {
            half: 0.5 * gap,
            out: 0.0,
        }
    }
    /// Next output for input `u`.
    #[inline]
    pub fn apply(&mut self, u: f64) -> f64 {
        if u - self.out > self.half {
            self.out = u - self.half;
        } else if self.out - u > self.half {
            self.out = u + self.half;
        }
        self.out
    }
}

/// Karnopp-type stick-slip friction for a time-stepped model.
///
/// Each step the caller gives `v_trial`, the velocity the driven mass would reach at the end of
/// the step with no friction, and `g`, the change of that velocity per unit of friction force
/// over the step (end velocity = v_trial − g·F). The friction force F returned
/// * holds the mass exactly at rest (end velocity 0) when the force needed, |v_trial/g|, is at
///   most the static limit (`breakaway` while stuck, `level` while sliding);
/// * otherwise slides: F = level·sign(v_trial/g).
///
/// With `breakaway == level` this is Coulomb friction with sticking, free of the chatter of an
/// explicit sign(v) law.
///
/// With a Stribeck velocity v_s > 0 ([`Self::with_stribeck_velocity`]) the sliding force
/// follows the Stribeck curve F(s) = level + (breakaway − level)·exp(−(s/v_s)²) of the speed s
/// at the end of the step instead of the constant level (Armstrong-Hélouvry's static + Coulomb
/// + Stribeck law); s is taken under the sliding level, s = |v_trial| − |g|·level (the largest
/// end speed, so one evaluation per step), and a curve that would reverse the velocity within
/// the step holds the mass instead. v_s → 0 is the Karnopp law above.
#[derive(Debug, Clone, Copy)]
pub struct StickSlip {
    level: f64,
    breakaway: f64,
    stribeck_velocity: f64,
    stuck: bool,
}

impl StickSlip {
    /// Friction with sliding `level` and static `breakaway` (>= level), starting at rest.
    pub fn new(level: f64, breakaway: f64) -> Self {
        Self {
            level,
            breakaway: breakaway.max(level),
            stribeck_velocity: 0.0,
            stuck: true,
        }
    }
    /// The same law with the sliding force on a Stribeck curve of velocity `v_s` (velocity
    /// units of the `v_trial` given to [`Self::force`]); `v_s` <= 0 or not finite: none.
    pub fn with_stribeck_velocity(mut self, v_s: f64) -> Self {
        self.stribeck_velocity = if v_s.is_finite() && v_s > 0.0 {
            v_s
        } else {
            0.0
        };
        self
    }
    /// The law of a friction effect (Coulomb friction or stiction), starting at rest.
    pub fn of(effect: &Effect) -> Option<Self> {
        match *effect {
            Effect::CoulombFriction { level } => Some(Self::new(level, level)),
            Effect::Stiction {
                level,
                breakaway,
                stribeck_velocity,
            } => Some(Self::new(level, breakaway).with_stribeck_velocity(stribeck_velocity)),
            _ => None,
        }
    }
    /// Friction force for this step (see the type docs). Returns 0 when `g` is 0 or either
    /// argument is NaN.
    #[inline]
    pub fn force(&mut self, v_trial: f64, g: f64) -> f64 {
        if g == 0.0 || g.is_nan() || v_trial.is_nan() {
            return 0.0;
        }
        let hold = v_trial / g; // one division per step; callers keep g fixed
        let limit = if self.stuck {
            self.breakaway
        } else {
            self.level
        };
        if hold.abs() <= limit {
            self.stuck = true;
            return hold;
        }
        self.stuck = false;
        if self.stribeck_velocity > 0.0 {
            let s = (g * (hold.abs() - self.level)).abs() / self.stribeck_velocity;
            let f = self.level + (self.breakaway - self.level) * (-s * s).exp();
            if f >= hold.abs() {
                self.stuck = true;
                return hold;
            }
            return f * hold.signum();
        }
        self.level * hold.signum()
    }
    /// Whether the mass is currently held at rest.
    pub fn is_stuck(&self) -> bool {
        self.stuck
    }
}

/// Delays `u` by `delay_samples` (>= 0, fractional allowed) with linear interpolation between
/// samples; samples before the start of the log are 0.
pub fn delay_signal(u: &[f64], delay_samples: f64) -> Vec<f64> {
    let d = delay_samples.max(0.0);
    let whole = d.floor() as usize;
    let frac = d - d.floor();
    let at = |i: isize| -> f64 {
        if i < 0 {
            0.0
        } else {
            u.get(i as usize).copied().unwrap_or(0.0)
        }
    };
    (0..u.len())
        .map(|k| {
            let i = k as isize - whole as isize;
            (1.0 - frac) * at(i) + frac * at(i - 1)
        })
        .collect()
}

/// The continuous unit-DC-gain mode ω²/(s² + 2ζωs + ω²) (ω = 2π·freq_hz rad/s) as a state
/// space with states (position, velocity).
pub fn resonance_mode(freq_hz: f64, damping: f64) -> Result<StateSpace> {
    let w = 2.0 * std::f64::consts::PI * freq_hz;
    let a = Mat::from_fn(2, 2, |i, j| match (i, j) {
        (0, 1) => 1.0,
        (1, 0) => -w * w,
        (1, 1) => -2.0 * damping * w,
        _ => 0.0,
    });
    let b = Mat::from_fn(2, 1, |i, _| if i == 1 { w * w } else { 0.0 });
    let c = Mat::from_fn(1, 2, |_, j| if j == 0 { 1.0 } else { 0.0 });
    StateSpace::new(a, b, c, Mat::zeros(1, 1), 0.0)
}

/// Natural frequency, in cycles per sample, at or above which [`resonance_filter`] passes its
/// input unchanged: such a mode settles within 1e-3 of a sample period, below the resolution
/// of a sampled model. Fits stay below 0.45 cycles per sample; this is the null of the
/// `resonance` candidate (a model with it reproduces the model without it).
pub const NULL_RESONANCE_CYCLES_PER_SAMPLE: f64 = 1e3;

/// Filters `u` (held over each sample period of `ts` seconds, as a DAC holds it) through
/// [`resonance_mode`] and returns, per sample period, the mean of the mode's continuous output
/// over that period — the held input that best represents it to a linear part discretised by
/// ZOH. (Taking the output at the sample instants instead would add about half a sample of
/// delay to the cascade.) Exact: the period integral is the ZOH discretisation of the mode
/// augmented with an integrator of its output.
pub fn resonance_filter(u: &[f64], ts: f64, freq_hz: f64, damping: f64) -> Result<Vec<f64>> {
    if freq_hz * ts >= NULL_RESONANCE_CYCLES_PER_SAMPLE {
        // Settles within a tiny fraction of a sample: the identity (the null resonance).
        return Ok(u.to_vec());
    }
    let m = resonance_mode(freq_hz, damping)?;
    // Augmented state (x0, x1, z) with z' = x0.
    let a = Mat::from_fn(3, 3, |i, j| match (i, j) {
        (0, _) | (1, _) if j < 2 => m.a[(i, j)],
        (2, 0) => 1.0,
        _ => 0.0,
    });
    let b = Mat::from_fn(3, 1, |i, _| if i < 2 { m.b[(i, 0)] } else { 0.0 });
    let c = Mat::from_fn(1, 3, |_, j| if j == 2 { 1.0 } else { 0.0 });
    let sys = StateSpace::new(a, b, c, Mat::zeros(1, 1), 0.0)?.c2d_zoh(ts)?;
    let (a, b) = (&sys.a, &sys.b);
    let (a00, a01, a10, a11) = (a[(0, 0)], a[(0, 1)], a[(1, 0)], a[(1, 1)]);
    let (a20, a21) = (a[(2, 0)], a[(2, 1)]);
    let (b0, b1, b2) = (b[(0, 0)], b[(1, 0)], b[(2, 0)]);
    let (mut x0, mut x1) = (0.0f64, 0.0f64);
    Ok(u.iter()
        .map(|&uk| {
            let mean = (a20 * x0 + a21 * x1 + b2 * uk) / ts;
            let n0 = a00 * x0 + a01 * x1 + b0 * uk;
            let n1 = a10 * x0 + a11 * x1 + b1 * uk;
            x0 = n0;
            x1 = n1;
            mean
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn static_maps() {
        assert_eq!(deadzone(0.4, 1.0), 0.0);
        assert!((deadzone(1.2, 1.0) - 0.7).abs() < 1e-15);
        assert!((deadzone(-1.2, 1.0) + 0.7).abs() < 1e-15);
        assert_eq!(saturation(3.0, 2.0), 2.0);
        assert_eq!(saturation(-3.0, 2.0), -2.0);
        assert!((quantize(0.26, 0.1) - 0.3).abs() < 1e-12);
        assert!((quantize(-0.26, 0.1) + 0.3).abs() < 1e-12);
    }

    #[test]
    fn play_operator_holds_inside_the_gap() {
        let mut p = Play::new(1.0);
        // Up to 2: output lags by 0.5.
        assert!((p.apply(2.0) - 1.5).abs() < 1e-15);
        // Reverse by less than the gap: held.
        assert!((p.apply(1.2) - 1.5).abs() < 1e-15);
        // Reverse beyond: follows from the other side.
        assert!((p.apply(0.0) - 0.5).abs() < 1e-15);
    }

    #[test]
    fn stick_slip_holds_then_breaks_away() {
        let mut f = StickSlip::new(1.0, 2.0);
        // Stuck: needs 1.5 < breakaway to hold.
        let g = 0.1;
        assert!((f.force(0.15, g) - 1.5).abs() < 1e-12);
        assert!(f.is_stuck());
        // Needs 2.5 > breakaway: slides against level 1.
        assert!((f.force(0.25, g) - 1.0).abs() < 1e-12);
        assert!(!f.is_stuck());
        // Sliding: a need of 1.5 > level keeps sliding.
        assert!((f.force(-0.15, g) + 1.0).abs() < 1e-12);
        // Need 0.5 <= level: sticks.
        assert!((f.force(0.05, g) - 0.5).abs() < 1e-12);
        assert!(f.is_stuck());
    }

    /// The Stribeck curve against its closed form: breaking loose at the breakaway, sliding at
    /// level + (breakaway − level)·exp(−(s/v_s)²) of the end speed s = |g|·(|hold| − level), held
    /// when the curve would reverse the velocity within the step; v_s = 0 is the Karnopp law.
    #[test]
    fn stribeck_curve_decays_from_the_breakaway_to_the_level() {
        let (level, breakaway, vs, g) = (1.0, 2.0, 0.5, 0.1);
        let curve = |hold: f64| {
            let s = g * (hold - level) / vs;
            level + (breakaway - level) * (-s * s).exp()
        };
        let mut f = StickSlip::new(level, breakaway).with_stribeck_velocity(vs);
        // At rest, a need of 1.9 < breakaway holds.
        assert!((f.force(0.19, g) - 1.9).abs() < 1e-12 && f.is_stuck());
        // A need of 2.5 breaks loose; the force is the curve at the end speed, below the need.
        let f1 = f.force(0.25, g);
        assert!((f1 - curve(2.5)).abs() < 1e-12 && !f.is_stuck(), "{f1}");
        assert!(f1 > level && f1 < breakaway);
        // Fast: the curve has decayed to the level.
        let f2 = f.force(100.0, g);
        assert!((f2 - level).abs() < 1e-9 && (f2 - curve(1000.0)).abs() < 1e-12);
        // Sliding slowly with a need of 1.05 > level but below the curve (1.99...): held.
        assert!(curve(1.05) > 1.05);
        assert!((f.force(-0.105, g) + 1.05).abs() < 1e-12 && f.is_stuck());
        // No (or an invalid) Stribeck velocity: the Karnopp law.
        for v in [0.0, -1.0, f64::NAN] {
            let mut k = StickSlip::new(level, breakaway).with_stribeck_velocity(v);
            let mut r = StickSlip::new(level, breakaway);
            for x in [0.15, 0.25, -0.15, 0.05, 3.0] {
                assert_eq!(k.force(x, g), r.force(x, g));
            }
        }
        // The law of an effect.
        let e = Effect::Stiction {
            level,
            breakaway,
            stribeck_velocity: vs,
        };
        let mut from_effect = StickSlip::of(&e).unwrap();
        assert_eq!(from_effect.force(0.25, g), curve(2.5));
        assert!(StickSlip::of(&Effect::Backlash { gap: 1.0 }).is_none());
        assert_eq!(
            e.params(),
            vec![
                ("level", 1.0),
                ("breakaway", 2.0),
                ("stribeck_velocity", 0.5)
            ]
        );
        assert!(Effect::Stiction {
            level,
            breakaway,
            stribeck_velocity: f64::NAN
        }
        .validate()
        .is_err());
    }

    #[test]
    fn rate_limiter_moves_at_most_one_step() {
        let mut r = RateLimiter::new(0.5);
        assert_eq!(r.apply(2.0), 0.5);
        assert_eq!(r.apply(2.0), 1.0);
        assert_eq!(r.apply(1.2), 1.2);
        assert_eq!(r.apply(-5.0), 0.7);
    }

    /// Against a continuous rate limiter integrated in 10,000 Euler sub-steps per sample
    /// (independent of the closed form): averages within 1e-3 of a step, the end value exact.
    #[test]
    fn averaged_rate_limiter_is_the_sample_mean_of_the_continuous_ramp() {
        let m = 0.5;
        let (mut r, mut out) = (RateLimiter::new(m), 0.0f64);
        let sub = 10_000;
        for &u in &[2.0, 2.0, 1.2, 1.15, -5.0, -4.9, 0.3, 0.3] {
            let mut acc = 0.0;
            for _ in 0..sub {
                out += (u - out).clamp(-m / sub as f64, m / sub as f64);
                acc += out;
            }
            let avg = r.apply_averaged(u);
            assert!(
                (avg - acc / sub as f64).abs() < 1e-3 * m,
                "u {u}: {avg} vs {}",
                acc / sub as f64
            );
            assert!((r.out - out).abs() < 1e-9);
        }
    }

    #[test]
    fn delay_interpolates() {
        let u = [1.0, 2.0, 3.0, 4.0];
        let d = delay_signal(&u, 1.5);
        assert_eq!(d, vec![0.0, 0.5, 1.5, 2.5]);
    }

    /// Independent reference: Euler-free fine simulation (exact ZOH of the mode at 1/256 of
    /// the sample time) averaged over each sample period by the trapezoid rule.
    #[test]
    fn resonance_filter_is_the_sample_period_mean_of_the_mode() {
        let ts = 1e-3;
        let sub = 256;
        let fine = resonance_mode(90.0, 0.03)
            .unwrap()
            .c2d_zoh(ts / sub as f64)
            .unwrap();
        let u: Vec<f64> = (0..3000)
            .map(|k| (0.37 * k as f64).sin() + 0.5 * (0.011 * k as f64).cos())
            .collect();
        let (mut x0, mut x1) = (0.0f64, 0.0f64);
        let mut reference = Vec::new();
        for &uk in &u {
            let mut acc = 0.5 * x0;
            for j in 0..sub {
                let n0 = fine.a[(0, 0)] * x0 + fine.a[(0, 1)] * x1 + fine.b[(0, 0)] * uk;
                let n1 = fine.a[(1, 0)] * x0 + fine.a[(1, 1)] * x1 + fine.b[(1, 0)] * uk;
                x0 = n0;
                x1 = n1;
                acc += if j + 1 == sub { 0.5 * x0 } else { x0 };
            }
            reference.push(acc / sub as f64);
        }
        let y = resonance_filter(&u, ts, 90.0, 0.03).unwrap();
        let scale = reference.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (k, (a, b)) in y.iter().zip(&reference).enumerate() {
            // Trapezoid error O((ts/256)^2) relative to the output scale.
            assert!((a - b).abs() < 1e-4 * scale, "sample {k}: {a} vs {b}");
        }
    }

    #[test]
    fn resonance_filter_has_unit_dc_gain_and_peaks() {
        // Step response settles at 1; sine at the natural frequency is amplified ~ 1/(2ζ).
        let ts = 1e-3;
        let u = vec![1.0; 20000];
        let y = resonance_filter(&u, ts, 50.0, 0.05).unwrap();
        assert!((y[19999] - 1.0).abs() < 1e-9);
        let n = 20000;
        let u: Vec<f64> = (0..n)
            .map(|k| (2.0 * std::f64::consts::PI * 50.0 * k as f64 * ts).sin())
            .collect();
        let y = resonance_filter(&u, ts, 50.0, 0.05).unwrap();
        let peak = y[n - 2000..].iter().fold(0.0f64, |m, v| m.max(v.abs()));
        // |H(jω_n)| = 1/(2ζ) = 10 exactly in continuous time; ZOH at 20 samples/period: ±3 %.
        assert!((peak - 10.0).abs() < 0.3, "peak {peak}");
    }
}
