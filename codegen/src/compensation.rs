//! The compensation block of the generated headers: friction feedforward, dead-zone inverse,
//! backlash inverse and back-calculation anti-windup, designed on the host from the gap
//! diagnosis (`ferrosid::compensation::design`) and applied by the firmware's control step
//! (`ferrosid_firmware::control`).
//!
//! Plain data (serde), like the rest of [`crate::CodegenInput`]. All magnitudes are in the
//! plant's INPUT units (the actuator command, e.g. N·m or V) unless stated; velocities are in
//! the units of the plant output per second (or of the output itself when it is a velocity).
//!
//! # The control law (normative: the f32 firmware and the f64 host simulation both run this)
//! Per sample k, with reference r, measured output y, sample time ts (s):
//!
//! ```text
//! e      = r − y
//! u_pid  = discrete PID of e (see crate::PidGains; integrator state i, roll-off if any)
//! w      = velocity estimate (see VelocitySource)
//! u_ff   = coulomb·clamp(w / smoothing_velocity, −1, 1) + viscous·w       (friction feedforward)
//!          (with `lag_aware`: the lag-aware form below instead)
//! u_c    = u_pid + u_ff
//! u_dz   = u_c + (width/2)·clamp(u_c / smoothing, −1, 1)                  (dead-zone inverse)
//! o[k]   = clamp(o[k−1] + (gap/2)/smoothing·(u_dz[k] − u_dz[k−1]), −gap/2, gap/2)
//! u_bl   = u_dz + o[k]                                                    (backlash inverse)
//! u      = clamp(u_bl, u_min, u_max)                                      (anti-windup present)
//! i     += ts/tracking_time_s · (u − u_bl)                                (back-calculation)
//! ```
//! **Lag-aware friction feedforward** ([`LagAwareFriction`], when the friction acts on a body
//! that the command reaches through a first-order actuator lag τ = `lag_s`, e.g. a current
//! loop). The plain feedforward arrives τ late and keeps pushing the old way after each
//! reversal; this form predicts the velocity, switches on the predicted drive torque while the
//! body is (nearly) stuck, and passes the result through the lag's deadbeat inverse so that it
//! is at the body one sample later:
//!
//! ```text
//! p      = exp(−ts/lag_s)
//! a      = (w − w[k−1])/ts                        (0 at the first step)
//! w_p    = w + (horizon_s + d_w)·a                (d_w: the estimate's own delay, ts/2 + ts(1−α)/α
//!                                                  for output_difference, 0 otherwise)
//! T̂      = p·T̂[k−1] + (1 − p)·u_pid               (the PID's command after the lag, next sample)
//! s      = sign(w_p)                  if |w_p| >= smoothing_velocity   (sliding)
//!          clamp(T̂/stick_band, −1, 1) otherwise                        (stuck: the torque's side)
//! f      = coulomb·s + viscous·w_p
//! u_ff   = f + p/(1 − p)·(f − f[k−1])             (f[−1] = 0; bounded: |u_ff| <= (1+p)/(1−p)·max|f|)
//! ```
//!
//! An absent block is the identity (and without `anti_windup` nothing is clamped). With
//! `enabled == false` the whole block is off and the law is the plain PID. Initial state:
//! o = 0, u_dz[−1] = 0, the velocity filter at 0, y[−1] = y[0] (first difference 0).
//!
//! The backlash offset o is a play operator on the command: it reaches its full ±gap/2 once
//! the command has moved `smoothing` input units in one direction, so it is independent of
//! the sample rate and ignores reversals smaller than `smoothing` (noise cannot make it chatter).
//!
//! ```
//! # use ferrosid_codegen::*;
//! let comp: Compensation = serde_json::from_str(r#"{
//!   "enabled": true,
//!   "provenance": {"effect": "coulomb_friction", "place": "drive", "verdict": "explained",
//!                  "source": "ferrosid gap on a.csv", "nrmse_before": 0.2, "nrmse_after": 0.05},
//!   "friction_feedforward": {"coulomb": 0.02, "viscous": 0.0, "smoothing_velocity": 0.5,
//!                            "velocity": {"kind": "output"}},
//!   "dead_zone_inverse": null, "backlash_inverse": null,
//!   "anti_windup": {"u_min": -1.0, "u_max": 1.0, "tracking_time_s": 0.01}
//! }"#).unwrap();
//! comp.validate()?;
//! # Ok::<(), ferrosid_codegen::Error>(())
//! ```
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::input::check_f32;

/// Where the compensation came from (documentation in the headers; no effect on the law).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CompensationProvenance {
    /// The diagnosed effects (`ferrosid gap` EffectKind names joined by `+`, e.g.
    /// `coulomb_friction+backlash`), or `""`.
    pub effect: String,
    /// Where each acts, in the same order (`drive`, `motor`, `drivetrain`, `sensor`, ... joined
    /// by `+`, e.g. `motor+drive`), or `""` when unknown.
    pub place: String,
    /// The gap verdict (e.g. `explained`, `none`, `unexplained`).
    pub verdict: String,
    /// What produced it, e.g. `ferrosid gap on a.csv,b.csv`.
    pub source: String,
    /// NRMSE of the linear model on the logs (fraction, >= 0), if known.
    #[serde(default)]
    pub nrmse_before: Option<f64>,
    /// NRMSE with the diagnosed effect added (fraction, >= 0), if known.
    #[serde(default)]
    pub nrmse_after: Option<f64>,
}

/// Where the friction feedforward takes its velocity estimate w from.
///
/// JSON: `{"kind": "output"}`, `{"kind": "output_difference", "filter_hz": 50.0}`,
/// `{"kind": "reference"}`. Deserialised through a flat struct, not serde's internally tagged
/// enum: that buffers the map and then refuses numbers when another crate in the build turns
/// on serde_json's `arbitrary_precision` (defmt-decoder does, in the workspace's test build).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum VelocitySource {
    /// The measured output is the velocity: w = y.
    Output,
    /// The output is a position: w is the backward difference (y[k] − y[k−1])/ts through a
    /// first-order low-pass `w[k] = w[k−1] + α·(raw − w[k−1])`, α = 1 − exp(−2π·filter_hz·ts).
    OutputDifference {
        /// Corner of the low-pass, Hz (> 0, below the Nyquist frequency of the control rate).
        filter_hz: f64,
    },
    /// The reference is a velocity set-point: w = r (no measurement noise in the feedforward).
    Reference,
}

/// The flat JSON form of [`VelocitySource`].
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct VelocitySourceRepr {
    kind: VelocityKind,
    #[serde(default)]
    filter_hz: Option<f64>,
}

#[derive(Deserialize)]
#[serde(rename_all = "snake_case")]
enum VelocityKind {
    Output,
    OutputDifference,
    Reference,
}

impl<'de> Deserialize<'de> for VelocitySource {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        use serde::de::Error as _;
        let r = VelocitySourceRepr::deserialize(d)?;
        match (r.kind, r.filter_hz) {
            (VelocityKind::Output, None) => Ok(VelocitySource::Output),
            (VelocityKind::Reference, None) => Ok(VelocitySource::Reference),
            (VelocityKind::OutputDifference, Some(filter_hz)) => {
                Ok(VelocitySource::OutputDifference { filter_hz })
            }
            (VelocityKind::OutputDifference, None) => Err(D::Error::custom(
                "velocity kind output_difference needs filter_hz (Hz)",
            )),
            (_, Some(_)) => Err(D::Error::custom(
                "velocity filter_hz belongs to kind output_difference only",
            )),
        }
    }
}

/// Coulomb + viscous friction feedforward with a linear ramp through zero velocity.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FrictionFeedforward {
    /// Coulomb friction level, input units (>= 0).
    pub coulomb: f64,
    /// Viscous coefficient, input units per velocity unit (>= 0).
    pub viscous: f64,
    /// Half-width of the ramp, velocity units (> 0): the Coulomb term is
    /// `coulomb·clamp(w/smoothing_velocity, −1, 1)`, continuous through w = 0 (no chatter).
    pub smoothing_velocity: f64,
    /// The velocity estimate used.
    pub velocity: VelocitySource,
    /// The lag-aware form of the law (module docs), when the friction sits behind an actuator
    /// lag; `None`: the plain feedforward.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lag_aware: Option<LagAwareFriction>,
}

/// Delivery of the friction feedforward through a first-order actuator lag (module docs: the
/// lag-aware law).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LagAwareFriction {
    /// First-order lag τ between the command and the force on the body, s (> 0).
    pub lag_s: f64,
    /// How far past the sample instant the velocity is predicted, s (>= 0, at most
    /// [`MAX_HORIZON_LAGS`] × `lag_s`): where the feedforward reaches the body, one sample
    /// for the deadbeat inverse.
    pub horizon_s: f64,
    /// Input units (> 0): inside the velocity band the Coulomb term follows the predicted drive
    /// torque, `clamp(T̂/stick_band, −1, 1)`, so a stuck body breaks away as soon as the
    /// controller pushes (a residual dead zone of about ±stick_band remains).
    pub stick_band: f64,
}

/// Largest prediction horizon of [`LagAwareFriction`], in multiples of its lag.
pub const MAX_HORIZON_LAGS: f64 = 10.0;

/// Inverse of a symmetric dead zone of full width `width` centred on zero.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DeadZoneInverse {
    /// Full width of the dead zone, input units (> 0): commands with |u| < width/2 do nothing.
    pub width: f64,
    /// Input units (> 0): for |u_c| < smoothing the added ±width/2 ramps linearly from 0.
    pub smoothing: f64,
}

/// Inverse of backlash (total play `gap`) between the drive and the load.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BacklashInverse {
    /// Total play, input units (> 0).
    pub gap: f64,
    /// Input units (> 0): command travel over which the ±gap/2 offset builds up (play operator).
    pub smoothing: f64,
}

/// Actuator limits and back-calculation anti-windup.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AntiWindup {
    /// Lowest command the actuator accepts, input units.
    pub u_min: f64,
    /// Highest command the actuator accepts, input units (> u_min).
    pub u_max: f64,
    /// Back-calculation tracking time constant T_t, s (> 0): the integrator is pulled towards
    /// the saturated command at rate (u − u_unsat)/T_t.
    pub tracking_time_s: f64,
}

/// The compensation block (see the module docs for the law).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Compensation {
    /// Whether the firmware applies it; false when the diagnosis was `none`/`unexplained`
    /// (the numbers are still written, for inspection).
    pub enabled: bool,
    /// Where it came from.
    pub provenance: CompensationProvenance,
    /// Friction feedforward, if any.
    #[serde(default)]
    pub friction_feedforward: Option<FrictionFeedforward>,
    /// Dead-zone inverse, if any.
    #[serde(default)]
    pub dead_zone_inverse: Option<DeadZoneInverse>,
    /// Backlash inverse, if any (only when `provenance.place` names `drive`).
    #[serde(default)]
    pub backlash_inverse: Option<BacklashInverse>,
    /// Actuator limits with anti-windup, if any.
    #[serde(default)]
    pub anti_windup: Option<AntiWindup>,
}

/// Largest magnitude accepted for a compensation parameter: far beyond any physical command,
/// and small enough that derived quantities (reciprocals, products) stay finite in f32.
pub const MAX_COMPENSATION_VALUE: f64 = 1e15;
/// Smallest accepted smoothing band / width / time (its reciprocal must stay a finite f32).
pub const MIN_COMPENSATION_BAND: f64 = 1e-15;

fn field(name: &str) -> String {
    format!("compensation.{name}")
}

/// Finite, fits f32, |v| <= MAX_COMPENSATION_VALUE.
fn check_value(name: &str, v: f64) -> Result<()> {
    let f = field(name);
    check_f32(&f, v)?;
    if v.abs() > MAX_COMPENSATION_VALUE {
        return Err(Error::input(
            f,
            format!("{v:e} is beyond {MAX_COMPENSATION_VALUE:e} (absurd for a command)"),
        ));
    }
    Ok(())
}

fn check_nonneg(name: &str, v: f64) -> Result<()> {
    check_value(name, v)?;
    if v < 0.0 {
        return Err(Error::input(field(name), format!("{v} must be >= 0")));
    }
    Ok(())
}

fn check_band(name: &str, v: f64) -> Result<()> {
    check_value(name, v)?;
    if v < MIN_COMPENSATION_BAND {
        return Err(Error::input(
            field(name),
            format!("{v:e} must be > 0 (at least {MIN_COMPENSATION_BAND:e})"),
        ));
    }
    Ok(())
}

impl Compensation {
    /// Checks every number: finite, within ±[`MAX_COMPENSATION_VALUE`] (so it fits the headers'
    /// `float`), levels >= 0, widths, smoothing bands and times > 0, `u_min < u_max`,
    /// NRMSEs >= 0; a backlash inverse only where `provenance.place` names `drive`; an enabled block has
    /// at least one part. The error names the field (`compensation.dead_zone_inverse.width`).
    ///
    /// The velocity filter's corner is checked against the control rate by
    /// [`Compensation::validate_at`] (the codegen does that with the model's sample time).
    pub fn validate(&self) -> Result<()> {
        let pv = &self.provenance;
        for (name, v) in [
            ("provenance.nrmse_before", pv.nrmse_before),
            ("provenance.nrmse_after", pv.nrmse_after),
        ] {
            if let Some(v) = v {
                check_nonneg(name, v)?;
            }
        }
        if let Some(ff) = &self.friction_feedforward {
            check_nonneg("friction_feedforward.coulomb", ff.coulomb)?;
            check_nonneg("friction_feedforward.viscous", ff.viscous)?;
            check_band(
                "friction_feedforward.smoothing_velocity",
                ff.smoothing_velocity,
            )?;
            if let VelocitySource::OutputDifference { filter_hz } = ff.velocity {
                check_band("friction_feedforward.velocity.filter_hz", filter_hz)?;
            }
            if let Some(la) = &ff.lag_aware {
                check_band("friction_feedforward.lag_aware.lag_s", la.lag_s)?;
                check_nonneg("friction_feedforward.lag_aware.horizon_s", la.horizon_s)?;
                if la.horizon_s > MAX_HORIZON_LAGS * la.lag_s {
                    return Err(Error::input(
                        field("friction_feedforward.lag_aware.horizon_s"),
                        format!(
                            "{} s is more than {MAX_HORIZON_LAGS} lags ({} s): a prediction that \
                             far ahead extrapolates noise, not the velocity",
                            la.horizon_s, la.lag_s
                        ),
                    ));
                }
                check_band("friction_feedforward.lag_aware.stick_band", la.stick_band)?;
            }
        }
        if let Some(dz) = &self.dead_zone_inverse {
            check_band("dead_zone_inverse.width", dz.width)?;
            check_band("dead_zone_inverse.smoothing", dz.smoothing)?;
        }
        if let Some(bl) = &self.backlash_inverse {
            check_band("backlash_inverse.gap", bl.gap)?;
            check_band("backlash_inverse.smoothing", bl.smoothing)?;
            if !pv.place.split('+').any(|p| p == "drive") {
                return Err(Error::input(
                    field("backlash_inverse"),
                    format!(
                        "a backlash inverse needs the play at the drive (provenance.place = \
                         \"drive\"), here the place is {:?}: play elsewhere cannot be undone \
                         from the command",
                        pv.place
                    ),
                ));
            }
        }
        if let Some(aw) = &self.anti_windup {
            check_value("anti_windup.u_min", aw.u_min)?;
            check_value("anti_windup.u_max", aw.u_max)?;
            if aw.u_min >= aw.u_max {
                return Err(Error::input(
                    field("anti_windup.u_max"),
                    format!("{} must be > u_min = {}", aw.u_max, aw.u_min),
                ));
            }
            check_band("anti_windup.tracking_time_s", aw.tracking_time_s)?;
        }
        if self.enabled
            && self.friction_feedforward.is_none()
            && self.dead_zone_inverse.is_none()
            && self.backlash_inverse.is_none()
            && self.anti_windup.is_none()
        {
            return Err(Error::input(
                field("enabled"),
                "true, but no part (friction_feedforward, dead_zone_inverse, backlash_inverse, \
                 anti_windup) is given; write enabled = false for no compensation",
            ));
        }
        Ok(())
    }

    /// [`Compensation::validate`] plus the checks that need the control sample time `ts_s`
    /// (s): the velocity filter corner below the Nyquist frequency 1/(2·ts), and the
    /// back-calculation gain ts/T_t at most 1 (a larger gain overshoots the saturated command
    /// in one step and makes the integrator oscillate).
    pub fn validate_at(&self, ts_s: f64) -> Result<()> {
        self.validate()?;
        if let Some(FrictionFeedforward {
            velocity: VelocitySource::OutputDifference { filter_hz },
            ..
        }) = self.friction_feedforward
        {
            let nyq = 0.5 / ts_s;
            if filter_hz >= nyq {
                return Err(Error::input(
                    field("friction_feedforward.velocity.filter_hz"),
                    format!("{filter_hz} Hz is at or above the Nyquist frequency {nyq} Hz"),
                ));
            }
        }
        if let Some(la) = self.friction_feedforward.and_then(|f| f.lag_aware) {
            // The deadbeat inverse's lead p/(1 − p) ≈ lag/ts must stay a modest f32 gain.
            if la.lag_s > 1e4 * ts_s {
                return Err(Error::input(
                    field("friction_feedforward.lag_aware.lag_s"),
                    format!(
                        "{} s is more than 1e4 sample times ({ts_s} s): the lag's inverse would \
                         amplify the feedforward's steps by {:.1e}",
                        la.lag_s,
                        la.lag_s / ts_s
                    ),
                ));
            }
        }
        if let Some(aw) = &self.anti_windup {
            if aw.tracking_time_s < ts_s {
                return Err(Error::input(
                    field("anti_windup.tracking_time_s"),
                    format!(
                        "{} s is shorter than the sample time {ts_s} s (back-calculation gain \
                         ts/T_t must be <= 1)",
                        aw.tracking_time_s
                    ),
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn full() -> Compensation {
        Compensation {
            enabled: true,
            provenance: CompensationProvenance {
                effect: "coulomb_friction".into(),
                place: "drive".into(),
                verdict: "explained".into(),
                source: "ferrosid gap on a.csv".into(),
                nrmse_before: Some(0.2),
                nrmse_after: Some(0.05),
            },
            friction_feedforward: Some(FrictionFeedforward {
                coulomb: 0.02,
                viscous: 0.001,
                smoothing_velocity: 0.5,
                velocity: VelocitySource::OutputDifference { filter_hz: 50.0 },
                lag_aware: Some(LagAwareFriction {
                    lag_s: 3e-3,
                    horizon_s: 1e-3,
                    stick_band: 1e-4,
                }),
            }),
            dead_zone_inverse: Some(DeadZoneInverse {
                width: 0.1,
                smoothing: 0.01,
            }),
            backlash_inverse: Some(BacklashInverse {
                gap: 0.05,
                smoothing: 0.01,
            }),
            anti_windup: Some(AntiWindup {
                u_min: -1.0,
                u_max: 1.0,
                tracking_time_s: 0.01,
            }),
        }
    }

    /// The lag-aware part of `c`'s friction feedforward (present in [`full`]).
    fn lag_aware(c: &mut Compensation) -> &mut LagAwareFriction {
        c.friction_feedforward
            .as_mut()
            .unwrap()
            .lag_aware
            .as_mut()
            .unwrap()
    }

    fn err_field(c: &Compensation, ts: Option<f64>) -> String {
        let r = match ts {
            Some(ts) => c.validate_at(ts),
            None => c.validate(),
        };
        match r {
            Err(Error::Input { field, .. }) => field,
            other => panic!("expected an input error, got {other:?}"),
        }
    }

    #[test]
    fn a_full_block_validates_and_round_trips_through_json() {
        let c = full();
        c.validate().unwrap();
        c.validate_at(1e-3).unwrap();
        let json = serde_json::to_string(&c).unwrap();
        assert!(json.contains(r#""velocity":{"kind":"output_difference","filter_hz":50.0}"#));
        let back: Compensation = serde_json::from_str(&json).unwrap();
        assert_eq!(back, c);
        // Absent parts may be omitted from the JSON.
        let min: Compensation = serde_json::from_str(
            r#"{"enabled": false, "provenance": {"effect": "", "place": "", "verdict": "none",
                "source": ""}}"#,
        )
        .unwrap();
        min.validate().unwrap();
        assert!(min.friction_feedforward.is_none() && min.provenance.nrmse_before.is_none());
        // A feedforward without `lag_aware` is the plain law, and writes no such key.
        let mut plain = c.clone();
        plain.friction_feedforward.as_mut().unwrap().lag_aware = None;
        let json = serde_json::to_string(&plain).unwrap();
        assert!(!json.contains("lag_aware"), "{json}");
        assert_eq!(serde_json::from_str::<Compensation>(&json).unwrap(), plain);
    }

    #[test]
    fn bad_values_are_refused_naming_the_field() {
        type Mutate = fn(&mut Compensation);
        let cases: Vec<(Mutate, &str)> = vec![
            (
                |c| c.friction_feedforward.as_mut().unwrap().coulomb = -0.1,
                "compensation.friction_feedforward.coulomb",
            ),
            (
                |c| c.friction_feedforward.as_mut().unwrap().coulomb = f64::NAN,
                "compensation.friction_feedforward.coulomb",
            ),
            (
                |c| c.friction_feedforward.as_mut().unwrap().viscous = f64::INFINITY,
                "compensation.friction_feedforward.viscous",
            ),
            (
                |c| c.friction_feedforward.as_mut().unwrap().smoothing_velocity = 0.0,
                "compensation.friction_feedforward.smoothing_velocity",
            ),
            (
                |c| {
                    c.friction_feedforward.as_mut().unwrap().velocity =
                        VelocitySource::OutputDifference { filter_hz: -1.0 }
                },
                "compensation.friction_feedforward.velocity.filter_hz",
            ),
            (
                |c| lag_aware(c).lag_s = 0.0,
                "compensation.friction_feedforward.lag_aware.lag_s",
            ),
            (
                |c| lag_aware(c).horizon_s = 0.031,
                "compensation.friction_feedforward.lag_aware.horizon_s",
            ),
            (
                |c| lag_aware(c).horizon_s = -1e-3,
                "compensation.friction_feedforward.lag_aware.horizon_s",
            ),
            (
                |c| lag_aware(c).stick_band = f64::NAN,
                "compensation.friction_feedforward.lag_aware.stick_band",
            ),
            (
                |c| c.dead_zone_inverse.as_mut().unwrap().width = 1e300,
                "compensation.dead_zone_inverse.width",
            ),
            (
                |c| c.dead_zone_inverse.as_mut().unwrap().smoothing = -0.0,
                "compensation.dead_zone_inverse.smoothing",
            ),
            (
                |c| c.backlash_inverse.as_mut().unwrap().gap = 0.0,
                "compensation.backlash_inverse.gap",
            ),
            (
                |c| c.backlash_inverse.as_mut().unwrap().smoothing = f64::NEG_INFINITY,
                "compensation.backlash_inverse.smoothing",
            ),
            (
                |c| c.provenance.place = "sensor".into(),
                "compensation.backlash_inverse",
            ),
            (
                |c| c.anti_windup.as_mut().unwrap().u_max = -2.0,
                "compensation.anti_windup.u_max",
            ),
            (
                |c| c.anti_windup.as_mut().unwrap().u_min = f64::NAN,
                "compensation.anti_windup.u_min",
            ),
            (
                |c| c.anti_windup.as_mut().unwrap().tracking_time_s = 0.0,
                "compensation.anti_windup.tracking_time_s",
            ),
            (
                |c| c.provenance.nrmse_after = Some(-0.5),
                "compensation.provenance.nrmse_after",
            ),
            (
                |c| c.provenance.nrmse_before = Some(f64::NAN),
                "compensation.provenance.nrmse_before",
            ),
            (
                |c| {
                    c.friction_feedforward = None;
                    c.dead_zone_inverse = None;
                    c.backlash_inverse = None;
                    c.anti_windup = None;
                },
                "compensation.enabled",
            ),
        ];
        for (mutate, want) in cases {
            let mut c = full();
            mutate(&mut c);
            assert_eq!(err_field(&c, None), want);
            assert_eq!(err_field(&c, Some(1e-3)), want);
        }
    }

    #[test]
    fn rate_dependent_limits_need_the_sample_time() {
        let mut c = full();
        c.friction_feedforward.as_mut().unwrap().velocity =
            VelocitySource::OutputDifference { filter_hz: 500.0 };
        c.validate().unwrap();
        assert_eq!(
            err_field(&c, Some(1e-3)),
            "compensation.friction_feedforward.velocity.filter_hz"
        );
        let mut c = full();
        lag_aware(&mut c).lag_s = 20.0;
        c.validate().unwrap();
        assert_eq!(
            err_field(&c, Some(1e-3)),
            "compensation.friction_feedforward.lag_aware.lag_s"
        );
        let mut c = full();
        c.anti_windup.as_mut().unwrap().tracking_time_s = 1e-4;
        c.validate().unwrap();
        assert_eq!(
            err_field(&c, Some(1e-3)),
            "compensation.anti_windup.tracking_time_s"
        );
    }

    #[test]
    fn malformed_json_is_a_serde_error_not_a_panic() {
        for bad in [
            r#"{"enabled": true}"#,
            r#"{"enabled": "yes", "provenance": {"effect":"","place":"","verdict":"","source":""}}"#,
            r#"{"enabled": true, "provenance": {"effect":"","place":"","verdict":"","source":""},
                "friction_feedforward": {"coulomb": 1, "viscous": 0, "smoothing_velocity": 1,
                "velocity": {"kind": "tachometer"}}}"#,
            r#"{"enabled": true, "provenance": {"effect":"","place":"","verdict":"","source":""},
                "friction_feedforward": {"coulomb": 1, "viscous": 0, "smoothing_velocity": 1,
                "velocity": {"kind": "output"},
                "lag_aware": {"lag_s": 0.003, "horizon_s": 0.001, "stick_band": 1e-4, "lead": 2}}}"#,
        ] {
            assert!(serde_json::from_str::<Compensation>(bad).is_err(), "{bad}");
        }
    }
}
