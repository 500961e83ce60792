//! The compensated control step in f64: the discretised PID of [`crate::robust::pid`] followed
//! by the compensation block of [`ferrosid_codegen::Compensation`], exactly the normative law
//! of `ferrosid_codegen::compensation` (the firmware runs the same law in f32):
//!
//! ```text
//! e      = r − y
//! u_pid  = PID(e)            i ← i + k_i(e + e₁), d ← a_d·d + b_d(e − e₁), v = k_p·e + i + d,
//!                            u_pid = roll-off(v) (identity when absent)
//! w      = velocity estimate (output y | filtered backward difference of y | reference r)
//! u_ff   = coulomb·clamp(w/smoothing_velocity, −1, 1) + viscous·w
//!          or the lag-aware form (`FrictionFeedforward::lag_aware`, the law in
//!          `ferrosid_codegen::compensation`): velocity predicted `horizon_s` past the sample,
//!          sign of the lagged PID command while stuck, the lag's deadbeat inverse
//! u_c    = u_pid + u_ff
//! u_dz   = u_c + (width/2)·clamp(u_c/smoothing, −1, 1)
//! o      = clamp(o + (gap/2)/smoothing·(u_dz − u_dz₁), −gap/2, gap/2);  u_bl = u_dz + o
//! u      = clamp(u_bl, u_min, u_max)
//! i     ← i + ts/tracking_time_s·(u − u_bl)                         (back-calculation)
//! ```
//! Every absent part is the identity; with `enabled = false` (or no compensation) the step is
//! the plain PID, equal to [`DiscretePid::update`] without a limit (tested). Units: r, y in
//! output units; every command in plant input units; velocities in output units per second
//! (or output units when the output is a velocity).
use crate::error::{Error, Result};
use crate::robust::pid::{DiscretePid, DiscretePidState};
use ferrosid_codegen::{Compensation, VelocitySource as CompVelocity};

/// State of [`ControlStep`] between samples.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct StepState {
    pid: DiscretePidState,
    y_prev: Option<f64>,
    w_filt: f64,
    u_c: f64,
    inverses: InverseState,
    w_prev: f64,
    t_lag: f64,
    f_prev: f64,
}

/// State of the dead-zone and backlash inverses of a [`Compensation`] between samples.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct InverseState {
    u_dz1: f64,
    o: f64,
}

impl InverseState {
    /// u_bl for the command `u_c`: the dead-zone inverse, then the backlash inverse (module
    /// docs); each the identity when `c` has none.
    pub(crate) fn apply(&mut self, c: &Compensation, u_c: f64) -> f64 {
        let mut u_dz = u_c;
        if let Some(dz) = &c.dead_zone_inverse {
            u_dz += 0.5 * dz.width * (u_c / dz.smoothing).clamp(-1.0, 1.0);
        }
        let mut u_bl = u_dz;
        if let Some(bl) = &c.backlash_inverse {
            let h = 0.5 * bl.gap;
            self.o = (self.o + h / bl.smoothing * (u_dz - self.u_dz1)).clamp(-h, h);
            u_bl += self.o;
        }
        self.u_dz1 = u_dz;
        u_bl
    }
}

/// One controller with its (optional) compensation, stepped once per sample.
#[derive(Debug, Clone)]
pub struct ControlStep {
    pid: DiscretePid,
    comp: Option<Compensation>,
    st: StepState,
}

impl ControlStep {
    /// The PID `pid` with `comp` applied when it is `Some` and `enabled`. Errors (through the
    /// crate's error enum, naming the field) when the compensation fails
    /// [`Compensation::validate_at`] at the controller's sample time.
    pub fn new(pid: &DiscretePid, comp: Option<&Compensation>) -> Result<Self> {
        if let Some(c) = comp {
            c.validate_at(pid.ts)
                .map_err(|e| Error::InvalidArgument(format!("compensation: {e}")))?;
        }
        Ok(Self {
            pid: pid.clone(),
            comp: comp.filter(|c| c.enabled).cloned(),
            st: StepState::default(),
        })
    }

    /// u_c of the last step: the PID command plus the friction feedforward, before the
    /// dead-zone and backlash inverses and the clamp (the plain PID command when uncompensated).
    pub fn pre_inverse_command(&self) -> f64 {
        self.st.u_c
    }

    /// Whether a compensation is active.
    pub fn compensated(&self) -> bool {
        self.comp.is_some()
    }

    /// The command for reference `r` and measurement `y` (module docs).
    pub fn step(&mut self, r: f64, y: f64) -> f64 {
        let p = &self.pid;
        let s = &mut self.st;
        let u_pid = p.update(&mut s.pid, r - y, None);
        s.u_c = u_pid;
        let Some(c) = &self.comp else {
            return u_pid;
        };
        let mut u_c = u_pid;
        if let Some(ff) = &c.friction_feedforward {
            let w = match ff.velocity {
                CompVelocity::Output => y,
                CompVelocity::Reference => r,
                CompVelocity::OutputDifference { filter_hz } => {
                    let raw = (y - s.y_prev.unwrap_or(y)) / p.ts;
                    let alpha = 1.0 - (-2.0 * std::f64::consts::PI * filter_hz * p.ts).exp();
                    s.w_filt += alpha * (raw - s.w_filt);
                    s.w_filt
                }
            };
            match &ff.lag_aware {
                None => {
                    u_c +=
                        ff.coulomb * (w / ff.smoothing_velocity).clamp(-1.0, 1.0) + ff.viscous * w;
                }
                Some(la) => {
                    let pole = (-p.ts / la.lag_s).exp();
                    let estimate_delay = match ff.velocity {
                        CompVelocity::OutputDifference { filter_hz } => {
                            let alpha =
                                1.0 - (-2.0 * std::f64::consts::PI * filter_hz * p.ts).exp();
                            0.5 * p.ts + p.ts * (1.0 - alpha) / alpha
                        }
                        CompVelocity::Output | CompVelocity::Reference => 0.0,
                    };
                    let dw = if s.y_prev.is_some() {
                        w - s.w_prev
                    } else {
                        0.0
                    };
                    s.w_prev = w;
                    let wp = w + (la.horizon_s + estimate_delay) / p.ts * dw;
                    s.t_lag = pole * s.t_lag + (1.0 - pole) * u_pid;
                    let sw = if wp.abs() >= ff.smoothing_velocity {
                        wp.signum()
                    } else {
                        (s.t_lag / la.stick_band).clamp(-1.0, 1.0)
                    };
                    let f = ff.coulomb * sw + ff.viscous * wp;
                    u_c += f + pole / (1.0 - pole) * (f - s.f_prev);
                    s.f_prev = f;
                }
            }
        }
        s.y_prev = Some(y);
        s.u_c = u_c;
        let u_bl = s.inverses.apply(c, u_c);
        match &c.anti_windup {
            Some(aw) => {
                let u = u_bl.clamp(aw.u_min, aw.u_max);
                s.pid
                    .add_to_integrator(p.ts / aw.tracking_time_s * (u - u_bl));
                u
            }
            None => u_bl,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robust::pid::{DiscretePidState, Pid, Rolloff};
    use ferrosid_codegen::{
        AntiWindup, CompensationProvenance, DeadZoneInverse, FrictionFeedforward,
    };

    fn pid() -> DiscretePid {
        Pid {
            kp: 0.8,
            ki: 40.0,
            kd: 0.002,
            tau_f: 0.0005,
            rolloff: Some(Rolloff {
                corner_hz: 200.0,
                zeta: 0.7,
            }),
        }
        .discretize(1e-3, Some(30.0))
        .unwrap()
    }

    fn provenance() -> CompensationProvenance {
        CompensationProvenance {
            effect: "deadzone".into(),
            place: "drive".into(),
            verdict: "deadzone".into(),
            source: "test".into(),
            nrmse_before: None,
            nrmse_after: None,
        }
    }

    #[test]
    fn without_compensation_it_is_the_discrete_pid() {
        let p = pid();
        let mut a = ControlStep::new(&p, None).unwrap();
        let mut st = DiscretePidState::default();
        for k in 0..500 {
            let y = (0.07 * k as f64).sin() + 0.3 * (0.9 * k as f64).cos();
            let ua = a.step(0.5, y);
            let ub = p.update(&mut st, 0.5 - y, None);
            assert!(
                (ua - ub).abs() <= 1e-12 * ub.abs().max(1.0),
                "k {k}: {ua} vs {ub}"
            );
        }
    }

    #[test]
    fn dead_zone_inverse_and_anti_windup_by_hand() {
        // P-only controller kp = 1: u_pid = e.
        let p = Pid {
            kp: 1.0,
            ki: 0.0,
            kd: 0.0,
            tau_f: 0.0,
            rolloff: None,
        }
        .discretize(1e-3, None)
        .unwrap();
        let comp = Compensation {
            enabled: true,
            provenance: provenance(),
            friction_feedforward: None,
            dead_zone_inverse: Some(DeadZoneInverse {
                width: 0.4,
                smoothing: 0.1,
            }),
            backlash_inverse: None,
            anti_windup: Some(AntiWindup {
                u_min: -1.0,
                u_max: 1.0,
                tracking_time_s: 0.01,
            }),
        };
        let mut c = ControlStep::new(&p, Some(&comp)).unwrap();
        // e = 0.05: 0.05 + 0.2·0.5 = 0.15.
        assert!((c.step(0.05, 0.0) - 0.15).abs() < 1e-12);
        // e = 0.5: 0.5 + 0.2 = 0.7.
        assert!((c.step(0.5, 0.0) - 0.7).abs() < 1e-12);
        // e = 3: 3.2 clamped at 1.
        assert_eq!(c.step(3.0, 0.0), 1.0);
        // Disabled: plain PID.
        let off = Compensation {
            enabled: false,
            ..comp.clone()
        };
        let mut c = ControlStep::new(&p, Some(&off)).unwrap();
        assert!((c.step(3.0, 0.0) - 3.0).abs() < 1e-12);
    }

    #[test]
    fn friction_feedforward_ramps_through_zero_and_bad_values_are_refused() {
        // A zero PID: the command is the feedforward alone.
        let p = DiscretePid {
            ts: 1e-3,
            prewarp_hz: None,
            kp: 0.0,
            ki_d: 0.0,
            a_d: 0.0,
            b_d: 0.0,
            rolloff: None,
            num: vec![0.0],
            den: vec![1.0],
        };
        let mut comp = Compensation {
            enabled: true,
            provenance: provenance(),
            friction_feedforward: Some(FrictionFeedforward {
                coulomb: 0.2,
                viscous: 0.01,
                smoothing_velocity: 0.5,
                velocity: CompVelocity::Output,
                lag_aware: None,
            }),
            dead_zone_inverse: None,
            backlash_inverse: None,
            anti_windup: None,
        };
        let mut c = ControlStep::new(&p, Some(&comp)).unwrap();
        // w = y = 0.25: 0.2·0.5 + 0.01·0.25.
        assert!((c.step(0.0, 0.25) - (0.1 + 0.0025)).abs() < 1e-9);
        // w = −2: −0.2 − 0.02.
        assert!((c.step(0.0, -2.0) + 0.22).abs() < 1e-9);
        comp.friction_feedforward.as_mut().unwrap().coulomb = f64::NAN;
        let e = ControlStep::new(&p, Some(&comp)).unwrap_err().to_string();
        assert!(e.contains("friction_feedforward.coulomb"), "{e}");
    }
}
