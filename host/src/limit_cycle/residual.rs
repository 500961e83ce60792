//! The nonlinearity the loop still sees once the compensation acts: the describing function
//! of the diagnosed effect combined with its compensation, for the limit-cycle prediction of
//! the compensated loop ([`crate::limit_cycle::predict_with`]).
//!
//! * **Friction + feedforward** (velocity site): the feedforward adds
//!   coulomb·clamp(v/smoothing_velocity, −1, 1) + viscous·v at the plant input, opposite to the
//!   friction, so the residual's describing function is, by linearity of the first harmonic,
//!   N_friction(A) − (coulomb/smoothing_velocity)·N_sat(A; smoothing_velocity) − viscous
//!   (closed form; the velocity estimate is taken as the velocity itself — for a position
//!   output the filtered difference adds a lag this ignores). The lag-aware form's stuck
//!   branch takes, inside the band, the side of the drive torque, i.e. the side the body moves
//!   to next: its first harmonic is the relay coulomb·sign(v), and its residual
//!   N_friction(A) − 4·coulomb/(πA) − viscous (the relay of M − coulomb). This assumes the feedforward
//!   reaches the friction on time. The lag-aware form (`LagAwareFriction`) is built to do
//!   that behind an actuator lag, and the same expression is used for it; the plain
//!   feedforward behind a lag arrives late, which this residual does not see, and neither
//!   does it see the lag-aware form's stuck branch or a wrong lag: only the simulation shows
//!   those (host/tests/limit_cycle_coulomb_lag.rs), which is why the receipt counts both.
//! * **Dead zone / backlash + inverse** (drive site): the command passes the inverse of the
//!   law (dead-zone ramp, play offset) and then the effect; N is the first harmonic of that
//!   composite, by quadrature over two periods of 2048 points (the map is continuous, so the
//!   error is O(1/2048²)).
//! * Anything else (anti-windup, a part for another site): the effect's own N — anti-windup
//!   acts on the controller's integrator, outside the describing-function model; its effect is
//!   seen in the simulation only.
use super::describing::second_period_harmonic;
use super::{DescribingFunction, Nonlinearity, Site};
use crate::compensation::law::InverseState;
use ferrosid_codegen::Compensation;
use num_complex::Complex64;
use std::f64::consts::PI;

/// Quadrature points per period of the composite describing functions.
pub const RESIDUAL_QUADRATURE_POINTS: usize = 2048;

/// The residual nonlinearity of `nl` under `comp` (module docs).
#[derive(Debug, Clone)]
pub struct Residual {
    nl: Nonlinearity,
    comp: Option<Compensation>,
}

impl Residual {
    /// `nl` under `comp` (ignored when `None` or not enabled).
    pub fn new(nl: &Nonlinearity, comp: Option<&Compensation>) -> Self {
        Self {
            nl: *nl,
            comp: comp.filter(|c| c.enabled).cloned(),
        }
    }

    /// Whether the residual differs from the effect's own describing function, and it is
    /// computed by quadrature (true) rather than in closed form (false).
    pub fn is_numeric(&self) -> bool {
        self.comp.as_ref().is_some_and(|c| {
            self.nl.site == Site::Drive
                && (c.dead_zone_inverse.is_some() || c.backlash_inverse.is_some())
        })
    }

    /// N(A) of the residual.
    pub fn eval(&self, a: f64) -> Complex64 {
        let base = self.nl.df.eval(a);
        let Some(c) = &self.comp else {
            return base;
        };
        match self.nl.site {
            Site::Velocity => match &c.friction_feedforward {
                // Lag-aware: outside the band the force is coulomb·sign(v) on time; inside it
                // the stuck branch takes the side of the drive torque, which at a reversal is
                // the side the body moves to next, so to first harmonic the feedforward is the
                // relay coulomb·sign(v) and the residual the relay of M − coulomb.
                Some(ff) if ff.lag_aware.is_some() => {
                    base - DescribingFunction::Relay { level: ff.coulomb }.eval(a) - ff.viscous
                }
                Some(ff) => {
                    let vs = ff.smoothing_velocity;
                    let r = vs / a;
                    let level = match self.nl.df {
                        DescribingFunction::Relay { level }
                        | DescribingFunction::Stiction { level, .. } => Some(level),
                        _ => None,
                    };
                    match level {
                        // Relay minus ramp for A >> smoothing: the two 4M/(πA) terms cancel;
                        // the series of asin r + r√(1−r²) = 2r − r³/3 − r⁵/20 − … keeps the
                        // residual (2/(3π))·r²/A + (1/(10π))·r⁴/A per unit coulomb exact
                        // (relative error O(r⁶)) where the direct difference would cancel.
                        Some(m) if r < 1e-2 => {
                            let tail = (2.0 / (3.0 * PI)) * r * r / a
                                + (1.0 / (10.0 * PI)) * r.powi(4) / a;
                            Complex64::new(
                                4.0 / (PI * a) * (m - ff.coulomb) + ff.coulomb * tail - ff.viscous,
                                0.0,
                            )
                        }
                        _ => {
                            let sat = DescribingFunction::Saturation { limit: vs }.eval(a);
                            base - sat * (ff.coulomb / vs) - ff.viscous
                        }
                    }
                }
                None => base,
            },
            Site::Drive if self.is_numeric() => self.composite(a, c),
            _ => base,
        }
    }

    /// First harmonic of effect(inverse(A sin θ)) over the second of two periods.
    fn composite(&self, a: f64, c: &Compensation) -> Complex64 {
        if !(a.is_finite() && a > 0.0) {
            return Complex64::new(f64::NAN, f64::NAN);
        }
        let n = RESIDUAL_QUADRATURE_POINTS;
        let dth = 2.0 * PI / n as f64;
        let mut inverses = InverseState::default();
        let x: Vec<f64> = (0..2 * n)
            .map(|k| inverses.apply(c, a * ((k as f64 + 0.5) * dth).sin()))
            .collect();
        second_period_harmonic(&self.nl.df.respond(&x), a)
    }
}
