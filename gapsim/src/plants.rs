//! The four continuous-time plants of the independent benchmark family, by their physical
//! parameters (SI units), with nominal numbers of their own (not those of `ferrosid_sim::plant`).
//!
//! | plant | input | output | states |
//! |---|---|---|---|
//! | [`TwoMass`] | motor torque, N·m | motor speed, rad/s | shaft twist θm − θl (rad), ωm, ωl (rad/s) |
//! | [`Flexure`] | force, N | stage position, µm | x (m), v (m/s) |
//! | [`DcMotor`] | armature voltage, V | rotor speed, rad/s | current i (A), ω (rad/s) |
//! | [`IntegratingAxis`] | force, N | carriage position, m | x (m), v (m/s) |
//!
//! The linear equations here are the plants without any effect; the effect laws act on the same
//! states in [`crate::hybrid`]. [`Plant::linear`] gives the continuous state-space model handed
//! to the diagnosis (for the nominal model: of a copy with perturbed parameters).
use crate::rng::Xoshiro;
use faer::Mat;
use ferrosid::lti::StateSpace;

/// Two-mass actuator: motor inertia and load inertia coupled by an elastic shaft.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwoMass {
    /// Motor inertia, kg·m².
    pub jm: f64,
    /// Load inertia, kg·m².
    pub jl: f64,
    /// Shaft stiffness, N·m/rad.
    pub k: f64,
    /// Shaft damping, N·m·s/rad.
    pub c: f64,
    /// Motor-side viscous friction, N·m·s/rad.
    pub bm: f64,
    /// Load-side viscous friction, N·m·s/rad.
    pub bl: f64,
}

/// Flexure-guided stage: a mass on a flexure spring.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Flexure {
    /// Moving mass, kg.
    pub m: f64,
    /// Flexure stiffness, N/m.
    pub k: f64,
    /// Damping, N·s/m.
    pub c: f64,
}

/// Voltage-driven DC motor with armature inductance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DcMotor {
    /// Armature resistance, Ω.
    pub r: f64,
    /// Armature inductance, H.
    pub l: f64,
    /// Torque constant, N·m/A.
    pub kt: f64,
    /// Back-EMF constant, V·s/rad.
    pub ke: f64,
    /// Rotor inertia, kg·m².
    pub j: f64,
    /// Viscous friction, N·m·s/rad.
    pub b: f64,
}

/// Position-output axis: a carriage with viscous damping only (a pole at s = 0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IntegratingAxis {
    /// Carriage mass, kg.
    pub m: f64,
    /// Viscous damping, N·s/m.
    pub c: f64,
}

/// One of the plants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Plant {
    /// Two-mass actuator.
    TwoMass(TwoMass),
    /// Flexure stage.
    Flexure(Flexure),
    /// DC motor.
    DcMotor(DcMotor),
    /// Integrating (position-output) axis.
    IntegratingAxis(IntegratingAxis),
}

/// Output of the flexure stage per metre (the output is in µm).
pub const FLEXURE_OUTPUT_PER_M: f64 = 1e6;

impl Plant {
    /// Two-mass actuator: anti-resonance 36.8 Hz, resonance 73.5 Hz, shaft damping 4 %.
    pub fn two_mass() -> Self {
        Plant::TwoMass(TwoMass {
            jm: 5e-4,
            jl: 1.5e-3,
            k: 80.0,
            c: 0.0139,
            bm: 3e-3,
            bl: 5e-3,
        })
    }
    /// Flexure stage: 19.5 Hz, 3 % damping.
    pub fn flexure() -> Self {
        Plant::Flexure(Flexure {
            m: 0.8,
            k: 12_000.0,
            c: 5.9,
        })
    }
    /// DC motor: electrical pole near 212 Hz, mechanical near 2.8 Hz, DC gain 27.5 rad/s/V.
    pub fn dc_motor() -> Self {
        Plant::DcMotor(DcMotor {
            r: 1.2,
            l: 0.9e-3,
            kt: 0.035,
            ke: 0.035,
            j: 6e-5,
            b: 4e-5,
        })
    }
    /// Integrating axis: 2.5 kg carriage, damping pole at 6 rad/s (0.95 Hz).
    pub fn integrating_axis() -> Self {
        Plant::IntegratingAxis(IntegratingAxis { m: 2.5, c: 15.0 })
    }

    /// Short name used in case ids.
    pub fn name(&self) -> &'static str {
        match self {
            Plant::TwoMass(_) => "two_mass",
            Plant::Flexure(_) => "flexure",
            Plant::DcMotor(_) => "dc_motor",
            Plant::IntegratingAxis(_) => "int_axis",
        }
    }

    /// Number of plant states.
    pub fn n_states(&self) -> usize {
        match self {
            Plant::TwoMass(_) => 3,
            _ => 2,
        }
    }

    /// Index of the driven body's velocity (where motor-side friction acts).
    pub fn motor_velocity(&self) -> usize {
        1
    }

    /// Index of the load velocity (two-mass only).
    pub fn load_velocity(&self) -> Option<usize> {
        match self {
            Plant::TwoMass(_) => Some(2),
            _ => None,
        }
    }

    /// Physical force (N or N·m) on the driven body per input unit at rest: 1 for force and
    /// torque inputs, kt/r for the voltage-driven motor. A friction force F is labelled
    /// F / force_per_input in input units.
    pub fn force_per_input(&self) -> f64 {
        match self {
            Plant::DcMotor(p) => p.kt / p.r,
            _ => 1.0,
        }
    }

    /// Inverse mass (or inertia) of the body whose velocity is state `iv`.
    pub fn inv_mass(&self, iv: usize) -> f64 {
        match (self, iv) {
            (Plant::TwoMass(p), 1) => 1.0 / p.jm,
            (Plant::TwoMass(p), _) => 1.0 / p.jl,
            (Plant::Flexure(p), _) => 1.0 / p.m,
            (Plant::DcMotor(p), _) => 1.0 / p.j,
            (Plant::IntegratingAxis(p), _) => 1.0 / p.m,
        }
    }

    /// Output row: y = Σ c_i x_i.
    pub fn output_row(&self) -> [f64; 3] {
        match self {
            Plant::TwoMass(_) => [0.0, 1.0, 0.0],
            Plant::Flexure(_) => [FLEXURE_OUTPUT_PER_M, 0.0, 0.0],
            Plant::DcMotor(_) => [0.0, 1.0, 0.0],
            Plant::IntegratingAxis(_) => [1.0, 0.0, 0.0],
        }
    }

    /// Natural scale of each plant state for the integrator's absolute tolerance, given the
    /// output scale `y_scale` (output units).
    pub fn state_scales(&self, y_scale: f64) -> [f64; 3] {
        match self {
            Plant::TwoMass(p) => [
                y_scale / (2.0 * std::f64::consts::PI * 40.0),
                y_scale,
                y_scale * (p.jm / p.jl).max(0.1),
            ],
            Plant::Flexure(p) => {
                let x = y_scale / FLEXURE_OUTPUT_PER_M;
                [x, x * (p.k / p.m).sqrt(), 0.0]
            }
            Plant::DcMotor(p) => [y_scale * p.b.max(p.kt * p.ke / p.r) / p.kt, y_scale, 0.0],
            Plant::IntegratingAxis(p) => [y_scale, y_scale * p.c / p.m, 0.0],
        }
    }

    /// State derivative of the plant alone: drive `w` (input units), shaft torque `shaft`
    /// (two-mass only, N·m), external forces `f_motor`, `f_load` opposing... added to the driven
    /// and the load body (N or N·m; friction enters with a minus sign from the caller).
    pub fn deriv(&self, x: &[f64], w: f64, shaft: f64, f_motor: f64, f_load: f64, dx: &mut [f64]) {
        match self {
            Plant::TwoMass(p) => {
                dx[0] = x[1] - x[2];
                dx[1] = (w - shaft - p.bm * x[1] + f_motor) / p.jm;
                dx[2] = (shaft - p.bl * x[2] + f_load) / p.jl;
            }
            Plant::Flexure(p) => {
                dx[0] = x[1];
                dx[1] = (w - p.k * x[0] - p.c * x[1] + f_motor) / p.m;
            }
            Plant::DcMotor(p) => {
                dx[0] = (w - p.r * x[0] - p.ke * x[1]) / p.l;
                dx[1] = (p.kt * x[0] - p.b * x[1] + f_motor) / p.j;
            }
            Plant::IntegratingAxis(p) => {
                dx[0] = x[1];
                dx[1] = (w - p.c * x[1] + f_motor) / p.m;
            }
        }
    }

    /// Linear shaft torque of the two-mass plant (0 for the others), N·m.
    pub fn linear_shaft(&self, x: &[f64]) -> f64 {
        match self {
            Plant::TwoMass(p) => p.k * x[0] + p.c * (x[1] - x[2]),
            _ => 0.0,
        }
    }

    /// Shaft stiffness and damping of the two-mass plant.
    pub fn shaft(&self) -> Option<(f64, f64)> {
        match self {
            Plant::TwoMass(p) => Some((p.k, p.c)),
            _ => None,
        }
    }

    /// A copy with every physical parameter multiplied by an independent factor uniform in
    /// [1 − rel, 1 + rel] (the "nominal model" a team would have written down).
    pub fn perturbed(&self, rel: f64, rng: &mut Xoshiro) -> Self {
        let mut f = || rng.range(1.0 - rel, 1.0 + rel);
        match *self {
            Plant::TwoMass(p) => Plant::TwoMass(TwoMass {
                jm: p.jm * f(),
                jl: p.jl * f(),
                k: p.k * f(),
                c: p.c * f(),
                bm: p.bm * f(),
                bl: p.bl * f(),
            }),
            Plant::Flexure(p) => Plant::Flexure(Flexure {
                m: p.m * f(),
                k: p.k * f(),
                c: p.c * f(),
            }),
            Plant::DcMotor(p) => Plant::DcMotor(DcMotor {
                r: p.r * f(),
                l: p.l * f(),
                kt: p.kt * f(),
                ke: p.ke * f(),
                j: p.j * f(),
                b: p.b * f(),
            }),
            Plant::IntegratingAxis(p) => Plant::IntegratingAxis(IntegratingAxis {
                m: p.m * f(),
                c: p.c * f(),
            }),
        }
    }

    /// The continuous linear model u → y, read off [`Plant::deriv`] column by column (the
    /// equations are linear without effects, so finite differences of unit vectors are exact).
    pub fn linear(&self) -> ferrosid::error::Result<StateSpace> {
        let n = self.n_states();
        let mut a = Mat::zeros(n, n);
        let mut b = Mat::zeros(n, 1);
        let mut dx = [0.0; 3];
        for j in 0..n {
            let mut x = [0.0; 3];
            x[j] = 1.0;
            self.deriv(
                &x[..n],
                0.0,
                self.linear_shaft(&x[..n]),
                0.0,
                0.0,
                &mut dx[..n],
            );
            for i in 0..n {
                a[(i, j)] = dx[i];
            }
        }
        self.deriv(&[0.0; 3][..n], 1.0, 0.0, 0.0, 0.0, &mut dx[..n]);
        for i in 0..n {
            b[(i, 0)] = dx[i];
        }
        let row = self.output_row();
        let c = Mat::from_fn(1, n, |_, j| row[j]);
        StateSpace::new(a, b, c, Mat::zeros(1, 1), 0.0)
    }
}
