//! The tuned loop in Lur'e form: one nonlinearity in feedback with the linear part it sees.
//!
//! ```text
//!   r=0 ─(+)─ e ─► C(z) ─ u ─► [drive NL] ─ w ─(+)──► G ──┬── y ─► [sensor NL] ─ y_m ─┐
//!        ▲−                                   ▲−          │                            │
//!        │                                    └─ [friction NL] ◄─ v (velocity) ◄───────┤
//!        └─────────────────────────────────────────────────────────────────────────────┘
//! ```
//!
//! With one nonlinearity x ↦ N(x) at a [`Site`], the rest of the loop is a linear map from the
//! nonlinearity's output back to (minus) its input, the **linear part** L(e^{jωT}), evaluated
//! at z = e^{jωT} with the controller's sample time T (the loop is discrete: the plant is its
//! ZOH equivalent at T and the controller is the discretised PID with its roll-off):
//!
//! | site | nonlinearity input x → output | linear part L |
//! |---|---|---|
//! | `drive` (dead zone, saturation, backlash on the command) | command u → plant input w | C·G |
//! | `sensor` (quantization, sensor clipping) | output y → measurement y_m | G·C |
//! | `velocity` (Coulomb friction, stiction on the driven mass) | velocity v → friction force F (input units, subtracted at the plant input) | G_v/(1 + C·G) |
//! | `velocity`, friction on the slowest mode ([`Body`]) | velocity v = y → force F on the body | B/(1 + C·G) |
//!
//! G_v is the plant from its input to the velocity friction opposes: G itself when the output
//! is the velocity ([`VelocitySource::Output`]), s·G when the output is a position
//! ([`VelocitySource::OutputDerivative`]). Friction acts continuously (it is not sampled), so
//! G_v is the continuous plant G_c(jω) when one exists (sampled-data approximation: the
//! controller path C·G is the discrete loop, aliasing neglected); without a continuous
//! equivalent, the discrete G (resp. G·(1 − z⁻¹)/T) with the force held over a sample. A harmonic-balance solution is 1 + N(A)·L(e^{jωT}) = 0,
//! i.e. L = −1/N(A) ([`crate::limit_cycle::predict`]).
use super::describing::DescribingFunction;
use crate::error::{Error, Result};
use crate::gap::effect::Effect;
use crate::gap::fit::VelocitySource;
use crate::gap::place::{Place, PlacedEffect};
use crate::lti::{FreqEvaluator, StateSpace, TransferFunction};
use crate::robust::pid::DiscretePid;
use crate::synth::sim::DiscreteLaw;
use num_complex::Complex64;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Where the nonlinearity sits in the loop (see the module table).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Site {
    /// On the command, between the controller and the plant input.
    Drive,
    /// Friction against the velocity of the driven mass, at the plant input.
    Velocity,
    /// On the measured output.
    Sensor,
}

impl Site {
    /// Report name (`drive`, `velocity`, `sensor`).
    pub fn name(self) -> &'static str {
        match self {
            Site::Drive => "drive",
            Site::Velocity => "velocity",
            Site::Sensor => "sensor",
        }
    }
}

/// One nonlinearity of the loop: its describing function and its site.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Nonlinearity {
    /// The nonlinearity with its parameters.
    pub df: DescribingFunction,
    /// Where it acts.
    pub site: Site,
}

impl Nonlinearity {
    /// The nonlinearity of a diagnosed effect at its place:
    /// `coulomb_friction`/`stiction` at `motor` → velocity; `deadzone`, `saturation`,
    /// `backlash` at `drive` → drive; `quantization`, `saturation` at `sensor` → sensor.
    /// Errors (naming the effect) for non-finite or out-of-range parameters, for effects that
    /// are linear (`time_delay`, `resonance`: they belong in the plant model), and for effects
    /// without a describing function here (`slew_rate`, `state_limit`, `current_limit`, backlash in the
    /// drivetrain or friction on the load of a two-mass structure, which act inside the plant).
    pub fn from_placed(pe: &PlacedEffect) -> Result<Self> {
        pe.effect.validate()?;
        let unsupported = |why: &str| {
            Err(Error::InvalidArgument(format!(
                "limit-cycle analysis of {} at {}: {why}",
                pe.effect.kind(),
                pe.place
            )))
        };
        let (df, site) = match (pe.effect, pe.place) {
            (Effect::CoulombFriction { level }, Place::Motor) => {
                (DescribingFunction::Relay { level }, Site::Velocity)
            }
            // A Stribeck curve (stribeck_velocity > 0) is dropped here: the describing function
            // and the loop simulation use the Karnopp law at the fitted level and breakaway,
            // which under-states the friction for velocity amplitudes near v_s.
            (
                Effect::Stiction {
                    level, breakaway, ..
                },
                Place::Motor,
            ) => (
                DescribingFunction::Stiction { level, breakaway },
                Site::Velocity,
            ),
            (Effect::Deadzone { width }, Place::Drive) => {
                (DescribingFunction::DeadZone { width }, Site::Drive)
            }
            (Effect::Saturation { limit }, Place::Drive) => {
                (DescribingFunction::Saturation { limit }, Site::Drive)
            }
            (Effect::Saturation { limit }, Place::Sensor) => {
                (DescribingFunction::Saturation { limit }, Site::Sensor)
            }
            (Effect::Backlash { gap }, Place::Drive) => {
                (DescribingFunction::Backlash { gap }, Site::Drive)
            }
            (Effect::Quantization { step }, Place::Sensor) => {
                (DescribingFunction::Quantization { step }, Site::Sensor)
            }
            (Effect::TimeDelay { .. } | Effect::Resonance { .. }, _) => {
                return unsupported(
                    "the effect is linear; add it to the plant model instead of analysing it \
                     as a nonlinearity",
                )
            }
            (Effect::Backlash { .. }, Place::Drivetrain)
            | (Effect::CoulombFriction { .. } | Effect::Stiction { .. }, Place::Load) => {
                return unsupported(
                    "it acts inside the two-mass structure; the loop's linear part seen from \
                     it is not available from the input/output model",
                )
            }
            _ => return unsupported("no describing function for this effect at this place"),
        };
        Ok(Self { df, site })
    }
}

/// The tuned loop: discrete plant and controller at the controller's sample time, plus what
/// the simulation needs (a continuous equivalent for sub-stepping friction, the velocity
/// source).
#[derive(Debug, Clone)]
pub struct LureLoop {
    /// Controller sample time T, s.
    pub ts: f64,
    /// Plant G, discrete at `ts` (ZOH).
    pub plant: StateSpace,
    /// Continuous equivalent of the plant (for sub-stepped simulation); `None` when the
    /// discrete plant has no real continuous equivalent (then friction is simulated at the
    /// sample rate).
    pub plant_continuous: Option<StateSpace>,
    /// The controller (Tustin PID with roll-off).
    pub controller: DiscretePid,
    /// Which signal friction opposes.
    pub velocity: VelocitySource,
    /// Friction on the slowest mode ([`LureLoop::with_friction_on_slowest_mode`]); `None`:
    /// friction subtracts at the plant input.
    pub body: Option<Body>,
    /// Friction at a state of the continuous plant instead of its input
    /// ([`LureLoop::with_friction_input`]): the column B_f (plant states per unit force, force
    /// in input units) through which the friction force enters, e.g. the body's velocity
    /// equation of a motor whose torque lags the command. `None`: at the plant input.
    pub friction_input: Option<Vec<f64>>,
    /// A general discrete controller in place of the PID ([`LureLoop::with_controller`]):
    /// the linear part and the simulation use it; `controller` is then not in the loop.
    pub general: Option<GeneralController>,
    friction_eval: Option<FreqEvaluator>,
    plant_eval: FreqEvaluator,
    plant_continuous_eval: Option<FreqEvaluator>,
    controller_tf: TransferFunction,
}

/// A general discrete controller of a [`LureLoop`] ([`LureLoop::with_controller`]).
#[derive(Debug, Clone)]
pub struct GeneralController {
    /// The controller u = K·e, discrete at the loop's sample time.
    pub model: StateSpace,
    /// The same controller as the law the simulation steps.
    pub law: DiscreteLaw,
    eval: FreqEvaluator,
}

/// The body friction acts on when it acts on the slowest real mode (the gap fit's
/// `velocity_from = "output_slowest_mode"`, [`crate::gap::friction_port::FrictionPort`]):
/// B(s) = dc_gain·(−pole)/(s − pole), the first-order body at the plant's slowest real pole with
/// the plant's static gain, so a constant force cancels an equal constant input. The output is
/// the body's velocity: y = G(u) − B(f).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Body {
    /// Continuous pole s_b = ln(p_b)/T of the slowest real discrete pole p_b, rad/s (< 0).
    pub pole_rad_s: f64,
    /// Static gain of the plant G(1) (output units per input unit).
    pub dc_gain: f64,
}

impl LureLoop {
    /// Builds the loop from a plant (continuous: discretised by ZOH at the controller's sample
    /// time; discrete: must have that sample time) and the discretised controller. Errors for a
    /// non-SISO plant, a sample-time mismatch, non-finite coefficients, or a controller whose
    /// transfer function is invalid.
    pub fn new(
        plant: &StateSpace,
        controller: &DiscretePid,
        velocity: VelocitySource,
    ) -> Result<Self> {
        let ts = controller.ts;
        if !(ts.is_finite() && ts > 0.0) {
            return Err(Error::InvalidArgument(format!(
                "limit-cycle loop: controller sample time {ts} s must be finite and > 0"
            )));
        }
        if !plant.is_siso() {
            return Err(Error::InvalidArgument(format!(
                "limit-cycle loop: the plant must be SISO (got {}x{})",
                plant.n_outputs(),
                plant.n_inputs()
            )));
        }
        let finite = |m: &faer::Mat<f64>| {
            (0..m.nrows()).all(|i| (0..m.ncols()).all(|j| m[(i, j)].is_finite()))
        };
        if !(finite(&plant.a) && finite(&plant.b) && finite(&plant.c) && finite(&plant.d)) {
            return Err(Error::InvalidArgument(
                "limit-cycle loop: the plant has non-finite coefficients".into(),
            ));
        }
        let coeffs = [
            controller.kp,
            controller.ki_d,
            controller.a_d,
            controller.b_d,
        ];
        if coeffs
            .iter()
            .chain(&controller.num)
            .chain(&controller.den)
            .any(|v| !v.is_finite())
        {
            return Err(Error::InvalidArgument(
                "limit-cycle loop: the controller has non-finite coefficients".into(),
            ));
        }
        let (pd, pc) = if plant.is_discrete() {
            if (plant.ts - ts).abs() > 1e-9 * ts {
                return Err(Error::InvalidArgument(format!(
                    "limit-cycle loop: plant sample time {} s differs from the controller's {ts} s",
                    plant.ts
                )));
            }
            (plant.clone(), plant.d2c_zoh().ok())
        } else {
            (plant.c2d_zoh(ts)?, Some(plant.clone()))
        };
        let controller_tf = controller.transfer_function()?;
        Ok(Self {
            ts,
            plant_eval: pd.freq_evaluator(),
            plant_continuous_eval: pc.as_ref().map(|p| p.freq_evaluator()),
            plant: pd,
            plant_continuous: pc,
            controller: controller.clone(),
            velocity,
            body: None,
            friction_input: None,
            general: None,
            friction_eval: None,
            controller_tf,
        })
    }

    /// The loop with friction acting on the plant's slowest real mode ([`Body`]) instead of
    /// its input. Errors unless the output is the velocity, the discrete plant has at least two
    /// states, every real pole lies in (0, 1) and the static gain is finite and non-zero (the
    /// conditions of the gap fit's friction port).
    pub fn with_friction_on_slowest_mode(mut self) -> Result<Self> {
        let bad = |why: &str| {
            Err(Error::InvalidArgument(format!(
                "limit-cycle loop: friction on the slowest mode needs {why}"
            )))
        };
        if self.velocity != VelocitySource::Output {
            return bad("the output to be the velocity");
        }
        let poles = self.plant.poles()?;
        if poles.len() < 2 {
            return bad("a plant with at least two states");
        }
        let real: Vec<f64> = poles
            .iter()
            .filter(|z| z.im.abs() <= 1e-12 * z.norm().max(1.0))
            .map(|z| z.re)
            .collect();
        if real.is_empty() || real.iter().any(|&p| !(p > 0.0 && p < 1.0 - 1e-9)) {
            return bad("every real pole of the discrete plant in (0, 1) and at least one");
        }
        let pb = real.iter().copied().fold(f64::MIN, f64::max);
        let dc = self.plant_response(0.0)?.re;
        if !(dc.is_finite() && dc != 0.0) {
            return bad("a finite, non-zero static gain");
        }
        self.body = Some(Body {
            pole_rad_s: pb.ln() / self.ts,
            dc_gain: dc,
        });
        Ok(self)
    }

    /// The loop with friction entering the continuous plant through the column `b_f` (states
    /// per unit force, input units) instead of at the plant input: the force acts on the body
    /// while the command reaches it through the actuator's dynamics (a current-loop lag, a
    /// transmission). Errors unless the plant is continuous (or has a continuous equivalent),
    /// `b_f` has one finite entry per state, not all zero, and C·b_f = 0 (a force does not
    /// move the measured position within an instant; for a velocity output use the plant input).
    pub fn with_friction_input(mut self, b_f: &[f64]) -> Result<Self> {
        let bad = |why: String| {
            Err(Error::InvalidArgument(format!(
                "limit-cycle loop: friction input column: {why}"
            )))
        };
        let Some(pc) = self.plant_continuous.as_ref() else {
            return bad("needs a continuous plant (none for this discrete plant)".into());
        };
        let n = pc.n_states();
        if b_f.len() != n {
            return bad(format!("{} entries for a plant of {n} states", b_f.len()));
        }
        if b_f.iter().any(|v| !v.is_finite()) || b_f.iter().all(|v| *v == 0.0) {
            return bad("entries must be finite and not all zero".into());
        }
        let cb: f64 = (0..n).map(|j| pc.c[(0, j)] * b_f[j]).sum();
        if cb.abs() > 1e-12 * b_f.iter().fold(0.0f64, |m, v| m.max(v.abs())) {
            return bad(format!("C·b_f = {cb} must be 0 (the output is a position)"));
        }
        if self.velocity != VelocitySource::OutputDerivative || self.body.is_some() {
            return bad("needs a position output (velocity = its derivative) and no body".into());
        }
        let sys = StateSpace::new(
            pc.a.clone(),
            faer::Mat::from_fn(n, 1, |i, _| b_f[i]),
            pc.c.clone(),
            faer::Mat::zeros(1, 1),
            0.0,
        )?;
        self.friction_eval = Some(sys.freq_evaluator());
        self.friction_input = Some(b_f.to_vec());
        Ok(self)
    }

    /// Nyquist angular frequency π/T, rad/s.
    pub fn nyquist_rad_s(&self) -> f64 {
        PI / self.ts
    }

    /// Plant G(e^{jωT}).
    pub fn plant_response(&self, w_rad_s: f64) -> Result<Complex64> {
        Ok(self.plant_eval.at_rad_s(w_rad_s)?[(0, 0)])
    }

    /// Controller C(e^{jωT}).
    pub fn controller_response(&self, w_rad_s: f64) -> Result<Complex64> {
        match &self.general {
            Some(g) => Ok(g.eval.at_rad_s(w_rad_s)?[(0, 0)]),
            None => self.controller_tf.freq_response(w_rad_s),
        }
    }

    /// The loop with the discrete SISO controller `k` (u = K·e at the loop's sample time) in
    /// place of the PID, stepped in the simulation by `law` (the same controller as a
    /// [`DiscreteLaw`], run without rails: the PID loop has none either). Errors for a
    /// continuous or MIMO controller, another sample time or non-finite coefficients.
    pub fn with_controller(mut self, k: &StateSpace, law: DiscreteLaw) -> Result<Self> {
        k.validate()?;
        if !k.is_siso() || !k.is_discrete() || (k.ts - self.ts).abs() > 1e-9 * self.ts {
            return Err(Error::InvalidArgument(format!(
                "limit-cycle loop: the controller must be discrete SISO at ts = {} s (got {}x{},                  ts = {} s)",
                self.ts,
                k.n_outputs(),
                k.n_inputs(),
                k.ts
            )));
        }
        self.general = Some(GeneralController {
            eval: k.freq_evaluator(),
            model: k.clone(),
            law,
        });
        Ok(self)
    }

    /// The linear part L(e^{jωT}) seen from a nonlinearity at `site` (module table).
    pub fn linear_part(&self, site: Site, w_rad_s: f64) -> Result<Complex64> {
        let g = self.plant_response(w_rad_s)?;
        let c = self.controller_response(w_rad_s)?;
        Ok(match site {
            Site::Drive | Site::Sensor => c * g,
            Site::Velocity => {
                // Friction acts continuously on the plant (it is not sampled): its path to the
                // velocity is the continuous plant when there is one; the feedback through the
                // sampled controller is the discrete loop (sampled-data approximation, aliasing
                // neglected).
                let one = Complex64::new(1.0, 0.0);
                if let Some(b) = self.body {
                    // Friction on the body only: B(jω)/(1 + C·G).
                    let bv = Complex64::new(-b.dc_gain * b.pole_rad_s, 0.0)
                        / (Complex64::new(0.0, w_rad_s) - b.pole_rad_s);
                    return Ok(bv / (one + c * g));
                }
                if let (Some(fe), Some(pe)) = (&self.friction_eval, &self.plant_continuous_eval) {
                    // Friction at the body: v/(−F) = G_vf − G_vu·H·C·G_yf/(1 + C·G), with
                    // G_yf the continuous force → position response, G_vf = s·G_yf, G_vu = s·G_c
                    // and H(jω) = (1 − e^{−jωT})/(jωT) the hold's response.
                    let s = Complex64::new(0.0, w_rad_s);
                    let gyf = fe.at_rad_s(w_rad_s)?[(0, 0)];
                    let gvu = pe.at_rad_s(w_rad_s)?[(0, 0)] * s;
                    let h = if w_rad_s == 0.0 {
                        one
                    } else {
                        (one - Complex64::from_polar(1.0, -w_rad_s * self.ts)) / (s * self.ts)
                    };
                    return Ok(s * gyf - gvu * h * c * gyf / (one + c * g));
                }
                let gv = match (&self.plant_continuous_eval, self.velocity) {
                    (Some(ev), VelocitySource::Output) => ev.at_rad_s(w_rad_s)?[(0, 0)],
                    (Some(ev), VelocitySource::OutputDerivative) => {
                        ev.at_rad_s(w_rad_s)?[(0, 0)] * Complex64::new(0.0, w_rad_s)
                    }
                    (None, VelocitySource::Output) => g,
                    (None, VelocitySource::OutputDerivative) => {
                        let z_inv = Complex64::from_polar(1.0, -w_rad_s * self.ts);
                        g * (Complex64::new(1.0, 0.0) - z_inv) / self.ts
                    }
                };
                gv / (Complex64::new(1.0, 0.0) + c * g)
            }
        })
    }
}
