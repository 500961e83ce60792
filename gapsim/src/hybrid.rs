//! A plant with its effects as one mode-switching system for [`crate::ode`].
//!
//! State layout: the plant states, then (each only when present) the slew-limited drive output,
//! the actuator mode (position, velocity), the bristle state of LuGre/Dahl friction, and the
//! sensor mode (position, velocity). Modes and their guards (positive while valid):
//!
//! | element | modes | guard |
//! |---|---|---|
//! | stick-band friction | stick / slide + / slide − | breakaway − \|F_req\| / v / −v |
//! | slew-rate limit | tracking / ramp ± | — / ±(command − output) |
//! | shaft backlash | free / engaged + / engaged − | two: b − Δθ and Δθ + b / Δθ − b / −b − Δθ (b = gap/2) |
//! | state limit | free / clamped ± | two: L − x and L + x / ±ẋ_free |
//!
//! F_req is the force that would accelerate the body if it had no friction (its other forces);
//! in stick the body's velocity is held at exactly zero. Guard index order: friction, slew,
//! shaft (2), state limit (2); unused guards are +1.
use crate::laws::{Body, Effects, FrictionLaw};
use crate::ode::{HybridSystem, State, MAXN};
use crate::plants::Plant;

/// Mode of a stick-band friction element.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Slide {
    /// At rest, velocity exactly zero.
    Stick,
    /// Sliding with positive velocity.
    Pos,
    /// Sliding with negative velocity.
    Neg,
}

/// Mode of a two-sided element (shaft backlash, state limit, slew ramp): free or active in one
/// direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// Inactive.
    Free,
    /// Active upwards.
    Pos,
    /// Active downwards.
    Neg,
}

/// The plant, its effects, the held drive command and every mode.
#[derive(Debug, Clone)]
pub struct Machine {
    /// The true plant.
    pub plant: Plant,
    /// The effects.
    pub fx: Effects,
    /// Drive command currently held (after dead band, saturation and play), input units.
    pub command: f64,
    /// Friction mode (stick-band laws).
    pub slide: Slide,
    /// Slew-rate limiter mode.
    pub slew: Side,
    /// Shaft backlash mode.
    pub shaft: Side,
    /// State-limit mode.
    pub clamp: Side,
    n: usize,
    i_slew: usize,
    i_act: usize,
    i_z: usize,
    i_sens: usize,
    atol: State,
}

const NONE: usize = usize::MAX;

impl Machine {
    /// Builds the system; `u_scale` and `y_scale` are the input and output magnitudes of the
    /// run (for the integrator's absolute tolerances, `rel` times the states' scales).
    pub fn new(plant: Plant, fx: Effects, u_scale: f64, y_scale: f64, rel: f64) -> Self {
        let mut n = plant.n_states();
        let mut atol = [1.0; MAXN];
        let sc = plant.state_scales(y_scale);
        atol[..n].copy_from_slice(&sc[..n]);
        let mut take = |k: usize, scales: &[f64]| {
            let i = n;
            for (j, s) in scales.iter().enumerate().take(k) {
                atol[i + j] = *s;
            }
            n += k;
            i
        };
        let i_slew = if fx.slew_rate.is_some() {
            take(1, &[u_scale])
        } else {
            NONE
        };
        let i_act = match fx.actuator_mode {
            Some(m) => take(2, &[u_scale, u_scale * m.omega()]),
            None => NONE,
        };
        let i_z = match fx.friction {
            Some((law, _)) if law.has_state() => take(1, &[law.z_scale()]),
            _ => NONE,
        };
        let i_sens = match fx.sensor_mode {
            Some(m) => take(2, &[y_scale, y_scale * m.omega()]),
            None => NONE,
        };
        for a in atol.iter_mut().take(n) {
            *a *= rel;
        }
        Self {
            plant,
            fx,
            command: 0.0,
            slide: Slide::Stick,
            slew: Side::Free,
            shaft: Side::Free,
            clamp: Side::Free,
            n,
            i_slew,
            i_act,
            i_z,
            i_sens,
            atol,
        }
    }

    /// Index of the body's velocity state of the friction element, if any.
    fn friction_velocity(&self) -> Option<(FrictionLaw, usize)> {
        self.fx.friction.map(|(law, body)| {
            let iv = match body {
                Body::Motor => self.plant.motor_velocity(),
                Body::Load => self
                    .plant
                    .load_velocity()
                    .unwrap_or(self.plant.motor_velocity()),
            };
            (law, iv)
        })
    }

    /// The plant's sensed quantity (before any sensor mode), output units.
    pub fn plant_output(&self, x: &State) -> f64 {
        let row = self.plant.output_row();
        (0..self.plant.n_states()).map(|i| row[i] * x[i]).sum()
    }

    /// The sensor reading before noise (after the sensor mode, if any), output units.
    pub fn output(&self, x: &State) -> f64 {
        if self.i_sens != NONE {
            x[self.i_sens]
        } else {
            self.plant_output(x)
        }
    }

    /// Shaft torque of the two-mass plant in the current backlash mode.
    fn shaft_torque(&self, x: &State) -> f64 {
        match (self.fx.shaft_backlash, self.plant.shaft()) {
            (Some(gap), Some((k, c))) => {
                let b = 0.5 * gap;
                let dw = x[1] - x[2];
                match self.shaft {
                    Side::Free => 0.0,
                    // Contact pushes, never pulls: the torque is clipped at zero.
                    Side::Pos => (k * (x[0] - b) + c * dw).max(0.0),
                    Side::Neg => (k * (x[0] + b) + c * dw).min(0.0),
                }
            }
            _ => self.plant.linear_shaft(&x[..self.plant.n_states()]),
        }
    }

    /// Derivative without the stick-band friction force and without the state clamp.
    fn free_deriv(&self, x: &State, dx: &mut State) {
        let np = self.plant.n_states();
        let base = if self.i_slew != NONE {
            x[self.i_slew]
        } else {
            self.command
        };
        let w = if self.i_act != NONE {
            x[self.i_act]
        } else {
            base
        };
        // Friction from the bristle laws (smooth) goes in directly; stick-band laws later.
        let (mut f_motor, mut f_load) = (0.0, 0.0);
        if let (Some((law, body)), true) = (self.fx.friction, self.i_z != NONE) {
            let iv = match body {
                Body::Motor => self.plant.motor_velocity(),
                Body::Load => self.plant.load_velocity().unwrap_or(1),
            };
            let (zd, f) = law.bristle(x[iv], x[self.i_z]);
            dx[self.i_z] = zd;
            match body {
                Body::Motor => f_motor = -f,
                Body::Load => f_load = -f,
            }
        }
        let shaft = self.shaft_torque(x);
        self.plant
            .deriv(&x[..np], w, shaft, f_motor, f_load, &mut dx[..np]);
        if self.i_slew != NONE {
            dx[self.i_slew] = match (self.slew, self.fx.slew_rate) {
                (Side::Pos, Some(r)) => r,
                (Side::Neg, Some(r)) => -r,
                _ => 0.0,
            };
        }
        if let Some(m) = self.fx.actuator_mode {
            let (om, z) = (m.omega(), m.damping);
            let i = self.i_act;
            dx[i] = x[i + 1];
            dx[i + 1] = om * om * (base - x[i]) - 2.0 * z * om * x[i + 1];
        }
        if let Some(m) = self.fx.sensor_mode {
            let (om, z) = (m.omega(), m.damping);
            let i = self.i_sens;
            let y = self.plant_output(x);
            dx[i] = x[i + 1];
            dx[i + 1] = om * om * (y - x[i]) - 2.0 * z * om * x[i + 1];
        }
    }

    /// Force that would accelerate the stick-band friction body without friction.
    fn required_force(&self, x: &State) -> f64 {
        match self.friction_velocity() {
            Some((_, iv)) => {
                let mut dx = [0.0; MAXN];
                self.free_deriv(x, &mut dx);
                dx[iv] / self.plant.inv_mass(iv)
            }
            None => 0.0,
        }
    }

    /// Whether the stick-band friction body is held only by the band: stuck, with a required
    /// force above the Coulomb level (Coulomb friction would let it slide here). Samples
    /// where this holds are the only ones in which a stick band differs from Coulomb friction.
    pub fn held_by_stick_band(&self, x: &State) -> bool {
        match self.friction_velocity() {
            Some((law, _)) if law.has_stick_mode() && self.slide == Slide::Stick => {
                self.required_force(x).abs() > law.coulomb()
            }
            _ => false,
        }
    }

    /// Unclamped derivative of the limited state.
    fn limited_rate(&self, x: &State) -> f64 {
        match self.fx.state_limit {
            Some((s, _)) => {
                let mut dx = [0.0; MAXN];
                self.free_deriv(x, &mut dx);
                dx[s]
            }
            None => 0.0,
        }
    }

    fn decide_slide(&mut self, x: &mut State) {
        if let Some((law, iv)) = self.friction_velocity() {
            if law.has_stick_mode() {
                x[iv] = 0.0;
                let f = self.required_force(x);
                // Strict: a guard located at |F_req| = breakaway must leave the stick mode.
                self.slide = if f.abs() < law.breakaway() {
                    Slide::Stick
                } else if f > 0.0 {
                    Slide::Pos
                } else {
                    Slide::Neg
                };
            }
        }
    }
}

impl HybridSystem for Machine {
    fn dim(&self) -> usize {
        self.n
    }

    fn abs_tol(&self) -> State {
        self.atol
    }

    fn deriv(&self, x: &State, dx: &mut State) {
        self.free_deriv(x, dx);
        if let Some((law, iv)) = self.friction_velocity() {
            if law.has_stick_mode() {
                let im = self.plant.inv_mass(iv);
                match self.slide {
                    Slide::Stick => dx[iv] = 0.0,
                    Slide::Pos => dx[iv] -= law.sliding(x[iv].abs()) * im,
                    Slide::Neg => dx[iv] += law.sliding(x[iv].abs()) * im,
                }
            }
        }
        if let Some((s, _)) = self.fx.state_limit {
            if self.clamp != Side::Free {
                dx[s] = 0.0;
            }
        }
    }

    fn n_guards(&self) -> usize {
        6
    }

    fn guards(&self, x: &State, g: &mut [f64]) {
        g.iter_mut().for_each(|v| *v = 1.0);
        if let Some((law, iv)) = self.friction_velocity() {
            if law.has_stick_mode() {
                g[0] = match self.slide {
                    Slide::Stick => law.breakaway() - self.required_force(x).abs(),
                    Slide::Pos => x[iv],
                    Slide::Neg => -x[iv],
                };
            }
        }
        if self.i_slew != NONE {
            let d = self.command - x[self.i_slew];
            g[1] = match self.slew {
                Side::Free => 1.0,
                Side::Pos => d,
                Side::Neg => -d,
            };
        }
        if let (Some(gap), Some(_)) = (self.fx.shaft_backlash, self.plant.shaft()) {
            let b = 0.5 * gap;
            match self.shaft {
                Side::Free => {
                    g[2] = b - x[0];
                    g[3] = x[0] + b;
                }
                Side::Pos => g[2] = x[0] - b,
                Side::Neg => g[2] = -b - x[0],
            }
        }
        if let Some((s, lim)) = self.fx.state_limit {
            match self.clamp {
                Side::Free => {
                    g[4] = lim - x[s];
                    g[5] = lim + x[s];
                }
                Side::Pos => g[4] = self.limited_rate(x),
                Side::Neg => g[4] = -self.limited_rate(x),
            }
        }
    }

    fn on_event(&mut self, k: usize, x: &mut State) {
        match k {
            0 => match self.slide {
                Slide::Stick => {
                    let f = self.required_force(x);
                    self.slide = if f > 0.0 { Slide::Pos } else { Slide::Neg };
                }
                _ => self.decide_slide(x),
            },
            1 => {
                x[self.i_slew] = self.command;
                self.slew = Side::Free;
            }
            2 | 3 => {
                self.shaft = match (self.shaft, k) {
                    (Side::Free, 2) => Side::Pos,
                    (Side::Free, _) => Side::Neg,
                    _ => Side::Free,
                };
            }
            _ => {
                if let Some((s, lim)) = self.fx.state_limit {
                    self.clamp = match (self.clamp, k) {
                        (Side::Free, 4) => {
                            x[s] = lim;
                            Side::Pos
                        }
                        (Side::Free, _) => {
                            x[s] = -lim;
                            Side::Neg
                        }
                        _ => Side::Free,
                    };
                }
            }
        }
    }

    fn settle(&mut self, x: &mut State) {
        if let Some((law, iv)) = self.friction_velocity() {
            let inconsistent = (self.slide == Slide::Pos && x[iv] < 0.0)
                || (self.slide == Slide::Neg && x[iv] > 0.0);
            if law.has_stick_mode() && (self.slide == Slide::Stick || x[iv] == 0.0 || inconsistent)
            {
                self.decide_slide(x);
            }
        }
        if self.i_slew != NONE {
            let d = self.command - x[self.i_slew];
            self.slew = if d > 0.0 {
                Side::Pos
            } else if d < 0.0 {
                Side::Neg
            } else {
                Side::Free
            };
        }
        // The shaft mode depends on the state only and changes by its events; the run starts at
        // rest, inside the gap (Free).
        if let Some((s, lim)) = self.fx.state_limit {
            let r = self.limited_rate(x);
            self.clamp = if x[s] >= lim && r > 0.0 {
                x[s] = lim;
                Side::Pos
            } else if x[s] <= -lim && r < 0.0 {
                x[s] = -lim;
                Side::Neg
            } else {
                Side::Free
            };
        }
    }
}
