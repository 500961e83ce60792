//! Physical model structures: their parameters (names, units, meaning), the continuous state
//! space they define, and what a single input/output pair can determine of them.
//!
//! Conventions (SI units throughout; the plant input is the drive's command as logged):
//! - [`Structure::Stage`]: flexure or voice-coil stage, `m ẍ + c ẋ + k x = K_f u` with `u` the
//!   coil current (A) and `x` the position (m) or `ẋ` the velocity (m/s).
//! - [`Structure::DcMotor`]: voltage-driven DC motor, `L di/dt = u − R i − K ω`,
//!   `J dω/dt = K i − b ω` with `u` the terminal voltage (V), `ω` the shaft speed (rad/s) and one
//!   motor constant `K = K_t = K_e` (N·m/A = V·s/rad; SI units make them equal).
//! - [`Structure::TwoMass`]: two-mass axis, motor inertia `J_m` and load inertia `J_l` joined by
//!   a shaft of stiffness `k` and damping `c`, viscous friction `b` at the motor (bearing losses;
//!   the load side is assumed free of viscous friction, which the motor-side sensor cannot tell
//!   apart from `b` at usable precision), driven by the motor current (A) through the torque
//!   constant `K_t`: `J_m ω̇_m = K_t u − b ω_m − k θ − c (ω_m − ω_l)`,
//!   `J_l ω̇_l = k θ + c (ω_m − ω_l)`, `θ̇ = ω_m − ω_l` (θ the shaft twist, rad). The sensor is on
//!   the motor: speed ω_m (rad/s) or angle φ_m (rad). Gearing: a gearbox of ratio `n` is folded
//!   into the load side (J_l, k, c are as seen from the motor shaft: J_l,motor = J_l,load/n²).
//! - [`Structure::TwoMassLag`]: the two-mass axis driven through a first-order lag of time
//!   constant `τ` between the logged command and the torque (the current loop's bandwidth, or a
//!   speed filter in the drive): `τ i̇ = u − i`, torque `K_t i`; motor speed output; 4 states.
//!   For a drive whose logged current reference is not the current (a real current loop has a
//!   bandwidth of a few hundred Hz to a few kHz, which a 2.5 kHz log sees as phase lag).
use crate::error::{Error, Result};
use crate::lti::StateSpace;
use faer::Mat;
use serde::Serialize;

/// What the sensor measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Measured {
    /// Position (m) or angle (rad).
    Position,
    /// Velocity (m/s) or angular speed (rad/s).
    Velocity,
}

/// A physical model structure (see the module docs for the equations and units).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case", tag = "kind", content = "output")]
pub enum Structure {
    /// Flexure / voice-coil stage: parameters m, c, k, K_f.
    Stage(Measured),
    /// Voltage-driven DC motor, speed output: parameters R, L, K, J, b.
    DcMotor,
    /// Two-mass axis with a motor-side sensor: parameters J_m, J_l, k, c, b, K_t.
    TwoMass(Measured),
    /// Two-mass axis driven through a first-order torque lag, motor speed output: parameters
    /// J_m, J_l, k, c, b, K_t, τ.
    TwoMassLag,
}

/// One parameter of a structure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParameterSpec {
    /// Name used on the command line and in reports (`--known Kt=0.1`).
    pub name: &'static str,
    /// SI unit.
    pub unit: &'static str,
    /// Meaning, in words.
    pub description: &'static str,
}

const fn spec(name: &'static str, unit: &'static str, description: &'static str) -> ParameterSpec {
    ParameterSpec {
        name,
        unit,
        description,
    }
}

const STAGE: [ParameterSpec; 4] = [
    spec("m", "kg", "moving mass"),
    spec("c", "N·s/m", "viscous damping"),
    spec("k", "N/m", "flexure stiffness"),
    spec("Kf", "N/A", "force constant"),
];
const DC_MOTOR: [ParameterSpec; 5] = [
    spec("R", "Ω", "armature resistance"),
    spec("L", "H", "armature inductance"),
    spec(
        "K",
        "N·m/A",
        "motor constant (torque constant = back-EMF constant)",
    ),
    spec("J", "kg·m²", "rotor + load inertia"),
    spec("b", "N·m·s/rad", "viscous friction"),
];
const TWO_MASS: [ParameterSpec; 6] = [
    spec("Jm", "kg·m²", "motor-side inertia"),
    spec(
        "Jl",
        "kg·m²",
        "load-side inertia (reflected to the motor shaft)",
    ),
    spec("k", "N·m/rad", "shaft stiffness"),
    spec("c", "N·m·s/rad", "shaft damping"),
    spec("b", "N·m·s/rad", "viscous friction at the motor"),
    spec("Kt", "N·m/A", "torque constant"),
];
const TWO_MASS_LAG: [ParameterSpec; 7] = [
    TWO_MASS[0],
    TWO_MASS[1],
    TWO_MASS[2],
    TWO_MASS[3],
    TWO_MASS[4],
    TWO_MASS[5],
    spec(
        "tau",
        "s",
        "time constant of the lag from the logged command to the torque",
    ),
];

impl Structure {
    /// Parses a command-line name: `stage`, `stage-velocity`, `dc-motor`, `two-mass`,
    /// `two-mass-position`.
    pub fn parse(name: &str) -> Result<Structure> {
        Ok(match name {
            "stage" | "stage-position" => Structure::Stage(Measured::Position),
            "stage-velocity" => Structure::Stage(Measured::Velocity),
            "dc-motor" => Structure::DcMotor,
            "two-mass" | "two-mass-velocity" => Structure::TwoMass(Measured::Velocity),
            "two-mass-position" => Structure::TwoMass(Measured::Position),
            "two-mass-lag" => Structure::TwoMassLag,
            other => {
                return Err(Error::InvalidArgument(format!(
                    "unknown structure {:?}: expected stage, stage-velocity, dc-motor, two-mass, \
                     two-mass-position or two-mass-lag",
                    crate::error::excerpt(other)
                )))
            }
        })
    }

    /// The command-line name (inverse of [`Self::parse`]).
    pub fn name(self) -> &'static str {
        match self {
            Structure::Stage(Measured::Position) => "stage",
            Structure::Stage(Measured::Velocity) => "stage-velocity",
            Structure::DcMotor => "dc-motor",
            Structure::TwoMass(Measured::Velocity) => "two-mass",
            Structure::TwoMass(Measured::Position) => "two-mass-position",
            Structure::TwoMassLag => "two-mass-lag",
        }
    }

    /// Parameters, in the order of every parameter vector of this structure.
    pub fn parameters(self) -> &'static [ParameterSpec] {
        match self {
            Structure::Stage(_) => &STAGE,
            Structure::DcMotor => &DC_MOTOR,
            Structure::TwoMass(_) => &TWO_MASS,
            Structure::TwoMassLag => &TWO_MASS_LAG,
        }
    }

    /// Index of the parameter called `name` (case-sensitive), if any.
    pub fn index_of(self, name: &str) -> Option<usize> {
        self.parameters().iter().position(|p| p.name == name)
    }

    /// Number of states of [`Self::state_space`].
    pub fn order(self) -> usize {
        match self {
            Structure::Stage(_) | Structure::DcMotor => 2,
            Structure::TwoMass(Measured::Velocity) => 3,
            Structure::TwoMass(Measured::Position) | Structure::TwoMassLag => 4,
        }
    }

    /// The identifiability rule: which parameters must be given (`--known`) because one
    /// input/output pair of this structure cannot separate them. `Ok(())` when `known` (flags
    /// per parameter) satisfies it, else an error saying what is missing and why.
    ///
    /// - stage: the transfer function `K_f/(m s² + c s + k)` has three coefficients for four
    ///   parameters — every parameter scales with the mass. One of `m`, `k`, `Kf` is needed.
    /// - dc-motor: `K/(LJ s² + (Lb + RJ) s + Rb + K²)` has three coefficients for five
    ///   parameters; given `R` and `L` the other three follow uniquely (other pairs leave the
    ///   electrical and mechanical time constants interchangeable). `R` and `L` are needed.
    /// - two-mass: six transfer-function coefficients (anti-resonance, resonance, rigid-body
    ///   gain and damping) for six parameters, but a common scale of all inertias, stiffness,
    ///   damping and `K_t` leaves the response unchanged. One of `Kt`, `Jm`, `Jl` is needed.
    pub fn check_known(self, known: &[bool]) -> Result<()> {
        let names = self.parameters();
        let is_known = |n: &str| self.index_of(n).is_some_and(|i| known[i]);
        let (ok, need, why) = match self {
            Structure::Stage(_) => (
                is_known("m") || is_known("k") || is_known("Kf"),
                "one of Kf, m, k",
                "current -> position alone determines K_f/m, c/m and k/m only: every parameter \
                 scales with the mass",
            ),
            Structure::DcMotor => (
                is_known("R") && is_known("L"),
                "both R and L",
                "voltage -> speed alone determines three combinations of R, L, K, J, b: \
                 J and K are not separable without R and L (measure them at standstill)",
            ),
            Structure::TwoMass(_) | Structure::TwoMassLag => (
                is_known("Kt") || is_known("Jm") || is_known("Jl"),
                "one of Kt, Jm, Jl",
                "current -> motor speed/angle alone fixes the parameters only up to a common \
                 scale (inertias, stiffness, damping and K_t together)",
            ),
        };
        if ok {
            return Ok(());
        }
        // The first name listed is the one a datasheet or a bench measurement usually gives.
        let first = need
            .trim_start_matches("one of ")
            .trim_start_matches("both ");
        let first = first.split([',', ' ']).next().unwrap_or("");
        let example = names
            .iter()
            .find(|p| p.name == first)
            .map_or(String::new(), |p| {
                format!(" (e.g. --known {}=VALUE in {})", p.name, p.unit)
            });
        Err(Error::InvalidArgument(format!(
            "structure {}: {why}; give {need} with --known NAME=VALUE{example}",
            self.name()
        )))
    }

    /// The continuous state space of the structure at parameters `p` (SI units, order of
    /// [`Self::parameters`]). Every parameter must be finite and > 0 except the dampings
    /// (`c`, `b`), which may be 0.
    pub fn state_space(self, p: &[f64]) -> Result<StateSpace> {
        let names = self.parameters();
        if p.len() != names.len() {
            return Err(Error::InvalidArgument(format!(
                "structure {}: {} parameters given, {} expected",
                self.name(),
                p.len(),
                names.len()
            )));
        }
        for (v, s) in p.iter().zip(names) {
            let damping = matches!(s.name, "c" | "b");
            if !v.is_finite() || *v < 0.0 || (!damping && *v == 0.0) {
                return Err(Error::InvalidArgument(format!(
                    "structure {}: parameter {} = {v} {} must be finite and {}",
                    self.name(),
                    s.name,
                    s.unit,
                    if damping { ">= 0" } else { "> 0" }
                )));
            }
        }
        let (a, b, c): (Vec<Vec<f64>>, Vec<f64>, Vec<f64>) = match self {
            Structure::Stage(out) => {
                let (m, cd, k, kf) = (p[0], p[1], p[2], p[3]);
                let c = match out {
                    Measured::Position => vec![1.0, 0.0],
                    Measured::Velocity => vec![0.0, 1.0],
                };
                (
                    vec![vec![0.0, 1.0], vec![-k / m, -cd / m]],
                    vec![0.0, kf / m],
                    c,
                )
            }
            Structure::DcMotor => {
                let (r, l, km, j, bv) = (p[0], p[1], p[2], p[3], p[4]);
                (
                    vec![vec![-r / l, -km / l], vec![km / j, -bv / j]],
                    vec![1.0 / l, 0.0],
                    vec![0.0, 1.0],
                )
            }
            Structure::TwoMass(out) => {
                let (jm, jl, k, cd, bv, kt) = (p[0], p[1], p[2], p[3], p[4], p[5]);
                // States: ω_m, ω_l, θ (twist) [, φ_m].
                let mut a = vec![
                    vec![-(bv + cd) / jm, cd / jm, -k / jm],
                    vec![cd / jl, -cd / jl, k / jl],
                    vec![1.0, -1.0, 0.0],
                ];
                let mut b = vec![kt / jm, 0.0, 0.0];
                let c = match out {
                    Measured::Velocity => vec![1.0, 0.0, 0.0],
                    Measured::Position => {
                        for row in &mut a {
                            row.push(0.0);
                        }
                        a.push(vec![1.0, 0.0, 0.0, 0.0]);
                        b.push(0.0);
                        vec![0.0, 0.0, 0.0, 1.0]
                    }
                };
                (a, b, c)
            }
            Structure::TwoMassLag => {
                let (jm, jl, k, cd, bv, kt, tau) = (p[0], p[1], p[2], p[3], p[4], p[5], p[6]);
                // States: ω_m, ω_l, θ (twist), i (the lagged command).
                (
                    vec![
                        vec![-(bv + cd) / jm, cd / jm, -k / jm, kt / jm],
                        vec![cd / jl, -cd / jl, k / jl, 0.0],
                        vec![1.0, -1.0, 0.0, 0.0],
                        vec![0.0, 0.0, 0.0, -1.0 / tau],
                    ],
                    vec![0.0, 0.0, 0.0, 1.0 / tau],
                    vec![1.0, 0.0, 0.0, 0.0],
                )
            }
        };
        let n = a.len();
        StateSpace::new(
            Mat::from_fn(n, n, |i, j| a[i][j]),
            Mat::from_fn(n, 1, |i, _| b[i]),
            Mat::from_fn(1, n, |_, j| c[j]),
            Mat::zeros(1, 1),
            0.0,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_complex::Complex64;

    #[test]
    fn names_round_trip() {
        for s in [
            Structure::Stage(Measured::Position),
            Structure::Stage(Measured::Velocity),
            Structure::DcMotor,
            Structure::TwoMass(Measured::Velocity),
            Structure::TwoMass(Measured::Position),
            Structure::TwoMassLag,
        ] {
            assert_eq!(Structure::parse(s.name()).unwrap(), s);
            assert_eq!(
                s.state_space(&vec![1.0; s.parameters().len()])
                    .unwrap()
                    .n_states(),
                s.order()
            );
        }
        assert!(Structure::parse("three-mass").is_err());
    }

    /// The two-mass transfer function against its closed form
    /// ω_m/u = K_t (J_l s² + c s + k) / (s (J_m J_l s² + (J_m + J_l) c s + (J_m + J_l) k)
    ///         + b (J_l s² + c s + k)).
    #[test]
    fn two_mass_matches_closed_form() {
        let p = [2e-4, 6e-4, 30.0, 4e-3, 1e-3, 0.05];
        let (jm, jl, k, c, b, kt) = (p[0], p[1], p[2], p[3], p[4], p[5]);
        let ss = Structure::TwoMass(Measured::Velocity)
            .state_space(&p)
            .unwrap();
        for f in [1.0, 20.0, 55.0, 300.0] {
            let s = Complex64::new(0.0, 2.0 * std::f64::consts::PI * f);
            let num = kt * (jl * s * s + c * s + k);
            let den = s * (jm * jl * s * s + (jm + jl) * c * s + (jm + jl) * k)
                + b * (jl * s * s + c * s + k);
            let want = num / den;
            let got = ss.freq_response_siso(f).unwrap();
            assert!(
                (got - want).norm() <= 1e-10 * want.norm(),
                "{f} Hz: {got} vs {want}"
            );
        }
    }

    /// The lagged two-mass axis is the two-mass transfer function times 1/(τ s + 1).
    #[test]
    fn two_mass_lag_is_two_mass_times_lag() {
        let p = [2e-4, 6e-4, 30.0, 4e-3, 1e-3, 0.05];
        let tau = 3e-4;
        let plain = Structure::TwoMass(Measured::Velocity)
            .state_space(&p)
            .unwrap();
        let mut q = p.to_vec();
        q.push(tau);
        let lag = Structure::TwoMassLag.state_space(&q).unwrap();
        for f in [1.0, 20.0, 55.0, 300.0, 2000.0] {
            let s = Complex64::new(0.0, 2.0 * std::f64::consts::PI * f);
            let want = plain.freq_response_siso(f).unwrap() / (tau * s + 1.0);
            let got = lag.freq_response_siso(f).unwrap();
            assert!((got - want).norm() <= 1e-10 * want.norm(), "{f} Hz");
        }
    }

    #[test]
    fn refuses_bad_parameters_and_missing_knowns() {
        let s = Structure::DcMotor;
        assert!(s.state_space(&[1.0, 0.0, 1.0, 1.0, 0.0]).is_err());
        assert!(s.state_space(&[1.0, 1.0, f64::NAN, 1.0, 0.0]).is_err());
        let e = s
            .check_known(&[true, false, false, false, false])
            .unwrap_err();
        assert!(e.to_string().contains("R and L"), "{e}");
        assert!(s.check_known(&[true, true, false, false, false]).is_ok());
        let e = Structure::TwoMass(Measured::Velocity)
            .check_known(&[false; 6])
            .unwrap_err();
        assert!(e.to_string().contains("--known Kt=VALUE in N·m/A"), "{e}");
    }
}
