//! Friction feedforward, dead-zone inverse, backlash inverse and back-calculation anti-windup
//! (the law is in the module docs of [`super`]).
use super::{check, check_positive, clamp, ControlOutput, ControlState};
use crate::Error;

/// Velocity estimate w of the friction feedforward (velocity units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum VelocitySource {
    /// The measured output is the velocity: w = y.
    Output,
    /// Filtered backward difference: `w += alpha·((y − y_prev)/ts − w)` (first step: 0).
    OutputDifference {
        /// Filter coefficient 1 − exp(−2π·f_c·ts), in (0, 1].
        alpha: f32,
    },
    /// The reference is a velocity set-point: w = r.
    Reference,
}

/// Coulomb + viscous friction feedforward with a linear ramp through zero velocity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrictionFeedforward {
    /// Coulomb level, input units (>= 0).
    pub coulomb: f32,
    /// Viscous coefficient, input units per velocity unit (>= 0).
    pub viscous: f32,
    /// Half-width of the ramp, velocity units (> 0).
    pub smoothing_velocity: f32,
    /// Where w comes from.
    pub velocity: VelocitySource,
    /// The lag-aware form (the friction sits behind a first-order actuator lag), if any.
    pub lag_aware: Option<LagAware>,
}

/// Lag-aware delivery of the friction feedforward (law in the module docs of [`super`];
/// `ferrosid_codegen::LagAwareFriction` on the host).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LagAware {
    /// exp(−ts/lag), in [0, 1): the actuator lag's pole per sample.
    pub pole: f32,
    /// Prediction time of the velocity, s (>= 0): the horizon plus the estimate's own delay.
    pub prediction_s: f32,
    /// Drive-torque band of the stuck branch, input units (> 0).
    pub stick_band: f32,
}

/// Inverse of a dead zone of full width `width` (input units, > 0), ramped over `smoothing`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeadZoneInverse {
    /// Full width, input units (> 0).
    pub width: f32,
    /// Ramp half-width around zero command, input units (> 0).
    pub smoothing: f32,
}

/// Inverse of backlash (total play `gap`) at the drive: a play operator on the command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BacklashInverse {
    /// Total play, input units (> 0).
    pub gap: f32,
    /// Command travel over which the ±gap/2 offset builds up, input units (> 0).
    pub smoothing: f32,
}

/// Actuator limits and back-calculation anti-windup.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AntiWindup {
    /// Lowest command, input units.
    pub u_min: f32,
    /// Highest command, input units (> u_min).
    pub u_max: f32,
    /// Back-calculation gain per sample ts/T_t, in (0, 1].
    pub gain: f32,
}

/// The compensation parts (each optional).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompensationConfig {
    /// Friction feedforward.
    pub friction_feedforward: Option<FrictionFeedforward>,
    /// Dead-zone inverse.
    pub dead_zone_inverse: Option<DeadZoneInverse>,
    /// Backlash inverse.
    pub backlash_inverse: Option<BacklashInverse>,
    /// Actuator limits and anti-windup.
    pub anti_windup: Option<AntiWindup>,
}

impl CompensationConfig {
    /// No part (for struct-update syntax).
    pub const NONE: CompensationConfig = CompensationConfig {
        friction_feedforward: None,
        dead_zone_inverse: None,
        backlash_inverse: None,
        anti_windup: None,
    };
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct PreparedFf {
    coulomb: f32,
    viscous: f32,
    inv_smoothing: f32,
    source: VelocitySource,
    inv_ts: f32,
    lag: Option<PreparedLag>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct PreparedLag {
    pole: f32,
    one_minus_pole: f32,
    /// p/(1 − p).
    lead: f32,
    /// prediction_s/ts.
    pred_over_ts: f32,
    inv_stick_band: f32,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct PreparedBand {
    half: f32,
    inv_smoothing: f32,
}

/// A validated [`CompensationConfig`] with reciprocals precomputed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Prepared {
    ff: Option<PreparedFf>,
    dz: Option<PreparedBand>,
    bl: Option<PreparedBand>,
    aw: Option<AntiWindup>,
}

impl Prepared {
    pub(crate) fn new(c: &CompensationConfig, ts_s: f32) -> Result<Self, Error> {
        let ff = match &c.friction_feedforward {
            Some(f) => {
                check("friction_feedforward.coulomb", f.coulomb)?;
                check("friction_feedforward.viscous", f.viscous)?;
                if f.coulomb < 0.0 {
                    return Err(Error::InvalidControlParameter {
                        what: "friction_feedforward.coulomb",
                    });
                }
                if f.viscous < 0.0 {
                    return Err(Error::InvalidControlParameter {
                        what: "friction_feedforward.viscous",
                    });
                }
                check_positive(
                    "friction_feedforward.smoothing_velocity",
                    f.smoothing_velocity,
                )?;
                if let VelocitySource::OutputDifference { alpha } = f.velocity {
                    if !(alpha > 0.0 && alpha <= 1.0) {
                        return Err(Error::InvalidControlParameter {
                            what: "friction_feedforward.velocity.alpha",
                        });
                    }
                }
                let lag = match &f.lag_aware {
                    Some(l) => {
                        if !(l.pole >= 0.0 && l.pole < 1.0) {
                            return Err(Error::InvalidControlParameter {
                                what: "friction_feedforward.lag_aware.pole",
                            });
                        }
                        check(
                            "friction_feedforward.lag_aware.prediction_s",
                            l.prediction_s,
                        )?;
                        if l.prediction_s < 0.0 {
                            return Err(Error::InvalidControlParameter {
                                what: "friction_feedforward.lag_aware.prediction_s",
                            });
                        }
                        check_positive("friction_feedforward.lag_aware.stick_band", l.stick_band)?;
                        let lead = l.pole / (1.0 - l.pole);
                        let inv_stick_band = 1.0 / l.stick_band;
                        if !(lead <= 1e4 && (inv_stick_band * f.coulomb).is_finite()) {
                            return Err(Error::InvalidControlParameter {
                                what: "friction_feedforward.lag_aware (lead or band beyond f32)",
                            });
                        }
                        Some(PreparedLag {
                            pole: l.pole,
                            one_minus_pole: 1.0 - l.pole,
                            lead,
                            pred_over_ts: l.prediction_s / ts_s,
                            inv_stick_band,
                        })
                    }
                    None => None,
                };
                Some(PreparedFf {
                    coulomb: f.coulomb,
                    viscous: f.viscous,
                    inv_smoothing: 1.0 / f.smoothing_velocity,
                    source: f.velocity,
                    inv_ts: 1.0 / ts_s,
                    lag,
                })
            }
            None => None,
        };
        let dz = match &c.dead_zone_inverse {
            Some(d) => {
                check_positive("dead_zone_inverse.width", d.width)?;
                check_positive("dead_zone_inverse.smoothing", d.smoothing)?;
                Some(PreparedBand {
                    half: 0.5 * d.width,
                    inv_smoothing: 1.0 / d.smoothing,
                })
            }
            None => None,
        };
        let bl = match &c.backlash_inverse {
            Some(b) => {
                check_positive("backlash_inverse.gap", b.gap)?;
                check_positive("backlash_inverse.smoothing", b.smoothing)?;
                Some(PreparedBand {
                    half: 0.5 * b.gap,
                    // (gap/2)/smoothing: the offset's slope per unit of command travel.
                    inv_smoothing: 0.5 * b.gap / b.smoothing,
                })
            }
            None => None,
        };
        if let Some(a) = &c.anti_windup {
            check("anti_windup.u_min", a.u_min)?;
            check("anti_windup.u_max", a.u_max)?;
            if a.u_min >= a.u_max {
                return Err(Error::InvalidControlParameter {
                    what: "anti_windup.u_max",
                });
            }
            if !(a.gain > 0.0 && a.gain <= 1.0) {
                return Err(Error::InvalidControlParameter {
                    what: "anti_windup.gain",
                });
            }
        }
        for v in [
            ff.map_or(0.0, |f| f.inv_smoothing * f.coulomb),
            bl.map_or(0.0, |b| b.inv_smoothing),
            dz.map_or(0.0, |d| d.inv_smoothing),
        ] {
            if !v.is_finite() {
                return Err(Error::InvalidControlParameter {
                    what: "compensation smoothing band (too small for f32)",
                });
            }
        }
        Ok(Prepared {
            ff,
            dz,
            bl,
            aw: c.anti_windup,
        })
    }

    /// Applies the parts to `out.u` (the PID's command), updating their state in `st` and the
    /// next integrator value `i_next` (back-calculation).
    #[inline(always)]
    pub(crate) fn apply(
        &self,
        st: &mut ControlState,
        r: f32,
        y: f32,
        out: &mut ControlOutput,
        i_next: &mut f32,
    ) {
        let mut u = out.u_pid;
        if let Some(f) = &self.ff {
            let w = match f.source {
                VelocitySource::Output => y,
                VelocitySource::OutputDifference { alpha } => {
                    let raw = if st.has_y1 {
                        (y - st.y1) * f.inv_ts
                    } else {
                        0.0
                    };
                    st.w += alpha * (raw - st.w);
                    st.w
                }
                VelocitySource::Reference => r,
            };
            let ff = match &f.lag {
                None => f.coulomb * clamp(w * f.inv_smoothing, -1.0, 1.0) + f.viscous * w,
                Some(l) => {
                    // Velocity predicted where the feedforward reaches the body.
                    let dw = if st.has_y1 { w - st.w_prev } else { 0.0 };
                    st.w_prev = w;
                    let wp = w + l.pred_over_ts * dw;
                    // The PID's command after the actuator lag, at the next sample.
                    st.t_lag = l.pole * st.t_lag + l.one_minus_pole * out.u_pid;
                    let s = if wp * f.inv_smoothing >= 1.0 {
                        1.0
                    } else if wp * f.inv_smoothing <= -1.0 {
                        -1.0
                    } else {
                        clamp(st.t_lag * l.inv_stick_band, -1.0, 1.0)
                    };
                    let fv = f.coulomb * s + f.viscous * wp;
                    // Deadbeat inverse of the lag: the force is fv one sample later.
                    let ff = fv + l.lead * (fv - st.f_prev);
                    st.f_prev = fv;
                    ff
                }
            };
            out.u_ff = ff;
            u += ff;
        }
        if let Some(d) = &self.dz {
            u += d.half * clamp(u * d.inv_smoothing, -1.0, 1.0);
        }
        if let Some(b) = &self.bl {
            st.o = clamp(st.o + b.inv_smoothing * (u - st.udz1), -b.half, b.half);
            st.udz1 = u;
            u += st.o;
        }
        out.u_unclamped = u;
        if let Some(a) = &self.aw {
            let sat = clamp(u, a.u_min, a.u_max);
            *i_next += a.gain * (sat - u);
            u = sat;
        }
        out.u = u;
    }
}
