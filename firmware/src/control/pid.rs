//! The discrete PID in the host's firmware form (`ferrosid::robust::pid::DiscretePid`).
use super::{check, ControlState};
use crate::Error;

/// Second-order section `u[k] = b0 v[k] + b1 v[k−1] + b2 v[k−2] − a1 u[k−1] − a2 u[k−2]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Biquad {
    /// `[b0, b1, b2]`.
    pub b: [f32; 3],
    /// `[1, a1, a2]` (a0 must be 1).
    pub a: [f32; 3],
}

/// Discrete PID gains (Tustin): `p = kp·e[k]`, `i[k] = i[k−1] + ki_d·(e[k] + e[k−1])`,
/// `d[k] = a_d·d[k−1] + b_d·(e[k] − e[k−1])`, `v = p + i + d`, `u = rolloff(v)` or `v`.
/// Gains map the error (output units) to the command (input units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PidConfig {
    /// Proportional gain.
    pub kp: f32,
    /// Trapezoidal integrator coefficient Ki·ts/2 (per sample).
    pub ki_d: f32,
    /// Derivative filter pole (|a_d| < 1).
    pub a_d: f32,
    /// Derivative gain per sample.
    pub b_d: f32,
    /// Optional roll-off section applied to v.
    pub rolloff: Option<Biquad>,
}

impl PidConfig {
    /// Every gain finite; the derivative pole inside the unit circle; the roll-off normalised
    /// (`a[0] == 1`) with finite coefficients.
    pub(crate) fn validate(&self) -> Result<(), Error> {
        check("pid.kp", self.kp)?;
        check("pid.ki_d", self.ki_d)?;
        check("pid.a_d", self.a_d)?;
        check("pid.b_d", self.b_d)?;
        if self.a_d.abs() >= 1.0 {
            return Err(Error::InvalidControlParameter { what: "pid.a_d" });
        }
        if let Some(bq) = &self.rolloff {
            for v in bq.b {
                check("pid.rolloff.b", v)?;
            }
            for v in bq.a {
                check("pid.rolloff.a", v)?;
            }
            if bq.a[0] != 1.0 {
                return Err(Error::InvalidControlParameter {
                    what: "pid.rolloff.a",
                });
            }
        }
        Ok(())
    }

    /// The PID part of a step: returns (u_pid, v, i_new, d_new) without touching the state.
    #[inline(always)]
    pub(crate) fn update(&self, st: &ControlState, e: f32) -> (f32, f32, f32, f32) {
        let i_new = st.i + self.ki_d * (e + st.e1);
        let d_new = self.a_d * st.d + self.b_d * (e - st.e1);
        let v = self.kp * e + i_new + d_new;
        let u = match &self.rolloff {
            Some(bq) => {
                bq.b[0] * v + bq.b[1] * st.v1 + bq.b[2] * st.v2 - bq.a[1] * st.u1 - bq.a[2] * st.u2
            }
            None => v,
        };
        (u, v, i_new, d_new)
    }
}
