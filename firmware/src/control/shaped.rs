//! Controllers beyond the plain PID (issue 14), in the host design's exact discrete form:
//!
//! * [`BiquadCascade`]: `S` second-order sections in series (notches, leads), direct form I;
//! * [`PidNotchLaw`]: the PID of [`PidConfig`] (Tustin, filtered derivative, optional
//!   roll-off), then the cascade, then the actuator clamp, with the host's conditional-integration
//!   anti-windup (`ferrosid::robust::pid::DiscretePid::update_detailed`, run by
//!   `ferrosid::synth::sim::DiscreteLaw::PidThenFilter`);
//! * [`StateSpaceLaw`]: a discrete SISO controller of order `N` (the reduced, discretised H∞
//!   controller) with observer-form back-calculation anti-windup
//!   (`ferrosid::synth::sim::SsFilter` with an anti-windup gain).
//!
//! Configuration is separate from state, sizes are const generics (checked at compile time),
//! f32 throughout, no allocation, no panic path, no division in a step.
//!
//! # The laws (normative; the host's f64 twins are named above)
//! PID + cascade, per sample with e = r − y:
//! ```text
//! i' = i + ki_d·(e + e₁);  d' = a_d·d + b_d·(e − e₁);  v = kp·e + i' + d';  w = rolloff(v) or v
//! if anti_windup and ((w > u_max and i' > i) or (w < u_min and i' < i)):
//!     i' = i (the step's integration is dropped) and v, w are recomputed
//! n = cascade(w);  u = clamp(n, u_min, u_max)
//! ```
//! The roll-off and the cascade keep their unclamped outputs as state (they stay linear).
//!
//! State space, per sample with e = r − y (ξ the controller state, L the anti-windup gain):
//! ```text
//! v = C ξ + D e;  u = clamp(v, u_min, u_max);  ξ' = A ξ + B e + L (u − v)
//! ```
//! While u is inside the rails this is the linear controller; at a rail the state is corrected
//! towards the applied input (the observer form of back-calculation: ξ' = (A − L C) ξ +
//! (B − L D) e + L u, stable when A − L C is; L = 0 is plain clamping). A non-finite r or y
//! leaves the state untouched and repeats the previous command.
//!
//! ```
//! use ferrosid_firmware::control::*;
//! // A pure integrator u = ξ, ξ' = ξ + 0.1·e with back-calculation L = 1 against ±1 rails.
//! let cfg = StateSpaceConfig::<1> {
//!     a: [[1.0]], b: [0.1], c: [1.0], d: 0.0, l: [1.0], u_min: -1.0, u_max: 1.0,
//! };
//! let law = StateSpaceLaw::new(&cfg)?;
//! let mut st = StateSpaceState::new();
//! for _ in 0..100 {
//!     law.step(&mut st, 10.0, 0.0);
//! }
//! // Without anti-windup ξ would be 100; with it ξ stays at the rail plus one step.
//! assert!(st.state()[0] <= 1.0 + 1.0 + 1e-6);
//! # Ok::<(), ferrosid_firmware::Error>(())
//! ```
//!
//! The order bound is checked when the law is built:
//! ```compile_fail
//! use ferrosid_firmware::control::*;
//! let cfg = StateSpaceConfig::<0> { a: [], b: [], c: [], d: 1.0, l: [], u_min: -1.0, u_max: 1.0 };
//! let _ = StateSpaceLaw::new(&cfg);
//! ```
use super::{check, clamp, Biquad, PidConfig};
use crate::Error;

/// Largest controller order [`StateSpaceLaw`] accepts (N² multiply–adds per step).
pub const MAX_STATE_ORDER: usize = 16;
/// Most sections a [`BiquadCascade`] accepts.
pub const MAX_SECTIONS: usize = 8;

/// `S` second-order sections in series, each `a[0] == 1`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BiquadCascade<const S: usize> {
    /// The sections, applied first to last.
    pub sections: [Biquad; S],
}

/// The state of a [`BiquadCascade`]: per section `[x₁, x₂, y₁, y₂]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CascadeState<const S: usize> {
    z: [[f32; 4]; S],
}

impl<const S: usize> CascadeState<S> {
    /// At rest.
    pub const fn new() -> Self {
        CascadeState { z: [[0.0; 4]; S] }
    }
}

impl<const S: usize> Default for CascadeState<S> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const S: usize> BiquadCascade<S> {
    const SECTIONS_OK: () = assert!(S <= MAX_SECTIONS, "at most MAX_SECTIONS sections");

    /// Every coefficient finite and each `a[0] == 1`.
    ///
    /// # Errors
    /// [`Error::InvalidControlParameter`] naming `cascade.b`/`cascade.a`.
    pub fn validate(&self) -> Result<(), Error> {
        let () = Self::SECTIONS_OK;
        for s in &self.sections {
            for v in s.b {
                check("cascade.b", v)?;
            }
            for v in s.a {
                check("cascade.a", v)?;
            }
            if s.a[0] != 1.0 {
                return Err(Error::InvalidControlParameter { what: "cascade.a" });
            }
        }
        Ok(())
    }

    /// One sample through all sections; the state advances.
    #[inline]
    pub fn step(&self, st: &mut CascadeState<S>, x: f32) -> f32 {
        let mut v = x;
        for (s, z) in self.sections.iter().zip(st.z.iter_mut()) {
            let y = s.b[0] * v + s.b[1] * z[0] + s.b[2] * z[1] - s.a[1] * z[2] - s.a[2] * z[3];
            *z = [v, z[0], y, z[2]];
            v = y;
        }
        v
    }
}

fn check_rails(u_min: f32, u_max: f32) -> Result<(), Error> {
    check("u_min", u_min)?;
    check("u_max", u_max)?;
    if u_min < u_max {
        Ok(())
    } else {
        Err(Error::InvalidControlParameter { what: "u_max" })
    }
}

/// PID + cascade + clamp (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PidNotchConfig<const S: usize> {
    /// The PID (with its optional roll-off).
    pub pid: PidConfig,
    /// The notch/lead sections after the PID.
    pub cascade: BiquadCascade<S>,
    /// Lower rail, input units.
    pub u_min: f32,
    /// Upper rail (> `u_min`).
    pub u_max: f32,
    /// Conditional integration at the rails.
    pub anti_windup: bool,
}

/// The validated PID + cascade law (immutable).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PidNotchLaw<const S: usize> {
    cfg: PidNotchConfig<S>,
}

/// The state of a [`PidNotchLaw`] (zero at start).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PidNotchState<const S: usize> {
    e1: f32,
    i: f32,
    d: f32,
    v1: f32,
    v2: f32,
    w1: f32,
    w2: f32,
    last_u: f32,
    cascade: CascadeState<S>,
}

impl<const S: usize> PidNotchState<S> {
    /// At rest.
    pub const fn new() -> Self {
        PidNotchState {
            e1: 0.0,
            i: 0.0,
            d: 0.0,
            v1: 0.0,
            v2: 0.0,
            w1: 0.0,
            w2: 0.0,
            last_u: 0.0,
            cascade: CascadeState::new(),
        }
    }
    /// The integrator state.
    pub fn integrator(&self) -> f32 {
        self.i
    }
}

impl<const S: usize> Default for PidNotchState<S> {
    fn default() -> Self {
        Self::new()
    }
}

/// One step's result.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LawOutput {
    /// The applied (clamped) command.
    pub u: f32,
    /// The command before the clamp.
    pub u_unclamped: f32,
    /// True when r or y was not finite (previous command repeated, state untouched).
    pub held: bool,
}

impl LawOutput {
    /// The output of a held step: the previous command `last_u` repeated.
    #[inline(always)]
    const fn hold(last_u: f32) -> Self {
        LawOutput {
            u: last_u,
            u_unclamped: last_u,
            held: true,
        }
    }
}

impl<const S: usize> PidNotchLaw<S> {
    /// Validates the PID, the cascade and the rails.
    ///
    /// # Errors
    /// [`Error::InvalidControlParameter`] naming the first bad field.
    pub fn new(cfg: &PidNotchConfig<S>) -> Result<Self, Error> {
        cfg.pid.validate()?;
        cfg.cascade.validate()?;
        check_rails(cfg.u_min, cfg.u_max)?;
        Ok(PidNotchLaw { cfg: *cfg })
    }

    #[inline(always)]
    fn pid_out(&self, st: &PidNotchState<S>, e: f32, i: f32, d: f32) -> (f32, f32) {
        let p = &self.cfg.pid;
        let v = p.kp * e + i + d;
        let w = match &p.rolloff {
            Some(bq) => {
                bq.b[0] * v + bq.b[1] * st.v1 + bq.b[2] * st.v2 - bq.a[1] * st.w1 - bq.a[2] * st.w2
            }
            None => v,
        };
        (v, w)
    }

    /// One step for reference `r` and measurement `y`.
    #[inline]
    pub fn step(&self, st: &mut PidNotchState<S>, r: f32, y: f32) -> LawOutput {
        if !(r.is_finite() && y.is_finite()) {
            return LawOutput::hold(st.last_u);
        }
        let c = &self.cfg;
        let e = r - y;
        let mut i_new = st.i + c.pid.ki_d * (e + st.e1);
        let d_new = c.pid.a_d * st.d + c.pid.b_d * (e - st.e1);
        let (mut v, mut w) = self.pid_out(st, e, i_new, d_new);
        if c.anti_windup && ((w > c.u_max && i_new > st.i) || (w < c.u_min && i_new < st.i)) {
            i_new = st.i;
            (v, w) = self.pid_out(st, e, i_new, d_new);
        }
        let n = c.cascade.step(&mut st.cascade, w);
        let u = clamp(n, c.u_min, c.u_max);
        st.e1 = e;
        st.i = i_new;
        st.d = d_new;
        st.v2 = st.v1;
        st.v1 = v;
        st.w2 = st.w1;
        st.w1 = w;
        st.last_u = u;
        LawOutput {
            u,
            u_unclamped: n,
            held: false,
        }
    }
}

/// A discrete SISO controller of order `N` with its anti-windup gain and rails.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StateSpaceConfig<const N: usize> {
    /// A (N×N), row-major.
    pub a: [[f32; N]; N],
    /// B column (from e).
    pub b: [f32; N],
    /// C row.
    pub c: [f32; N],
    /// Feedthrough D.
    pub d: f32,
    /// Anti-windup gain L (zero: plain clamping).
    pub l: [f32; N],
    /// Lower rail.
    pub u_min: f32,
    /// Upper rail (> `u_min`).
    pub u_max: f32,
}

/// The validated state-space law (immutable).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StateSpaceLaw<const N: usize> {
    cfg: StateSpaceConfig<N>,
}

/// The state ξ of a [`StateSpaceLaw`] (zero at start).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StateSpaceState<const N: usize> {
    x: [f32; N],
    last_u: f32,
}

impl<const N: usize> StateSpaceState<N> {
    /// At rest.
    pub const fn new() -> Self {
        StateSpaceState {
            x: [0.0; N],
            last_u: 0.0,
        }
    }
    /// The controller state ξ.
    pub fn state(&self) -> &[f32; N] {
        &self.x
    }
}

impl<const N: usize> Default for StateSpaceState<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> StateSpaceLaw<N> {
    const ORDER_OK: () = assert!(
        N >= 1 && N <= MAX_STATE_ORDER,
        "controller order must be in 1..=MAX_STATE_ORDER"
    );

    /// Validates every entry (finite, within ±1e15) and the rails.
    ///
    /// # Errors
    /// [`Error::InvalidControlParameter`] naming the first bad field (`ss.a`, `ss.b`, `ss.c`,
    /// `ss.d`, `ss.l`, `u_min`, `u_max`).
    pub fn new(cfg: &StateSpaceConfig<N>) -> Result<Self, Error> {
        let () = Self::ORDER_OK;
        for row in &cfg.a {
            for &v in row {
                check("ss.a", v)?;
            }
        }
        for (&b, (&c, &l)) in cfg.b.iter().zip(cfg.c.iter().zip(cfg.l.iter())) {
            check("ss.b", b)?;
            check("ss.c", c)?;
            check("ss.l", l)?;
        }
        check("ss.d", cfg.d)?;
        check_rails(cfg.u_min, cfg.u_max)?;
        Ok(StateSpaceLaw { cfg: *cfg })
    }

    /// One step for reference `r` and measurement `y` (see the module docs).
    #[inline]
    pub fn step(&self, st: &mut StateSpaceState<N>, r: f32, y: f32) -> LawOutput {
        if !(r.is_finite() && y.is_finite()) {
            return LawOutput::hold(st.last_u);
        }
        let c = &self.cfg;
        let e = r - y;
        let mut v = c.d * e;
        for (ci, xi) in c.c.iter().zip(st.x.iter()) {
            v += ci * xi;
        }
        let u = clamp(v, c.u_min, c.u_max);
        let corr = u - v;
        let mut next = [0.0f32; N];
        for (((nx, row), b), l) in next
            .iter_mut()
            .zip(c.a.iter())
            .zip(c.b.iter())
            .zip(c.l.iter())
        {
            let mut acc = b * e + l * corr;
            for (a, xj) in row.iter().zip(st.x.iter()) {
                acc += a * xj;
            }
            *nx = acc;
        }
        // A non-finite state (an unstable controller driven far) is not kept: the step is
        // held instead, so the next sample starts from the last finite state.
        if !(v.is_finite() && next.iter().all(|x| x.is_finite())) {
            return LawOutput::hold(st.last_u);
        }
        st.x = next;
        st.last_u = u;
        LawOutput {
            u,
            u_unclamped: v,
            held: false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A notch at 50 Hz, 1 kHz, Tustin prewarped (ζ_n = 0, ζ_d = 0.5): a sine at the centre
    /// is removed after the transient, one at 5 Hz passes.
    fn notch() -> Biquad {
        let (w, t) = (2.0 * core::f64::consts::PI * 50.0, 1e-3);
        let c = w / (w * t / 2.0).tan();
        let (zn, zd) = (0.0, 0.5);
        let n = [
            c * c + 2.0 * zn * w * c + w * w,
            -2.0 * c * c + 2.0 * w * w,
            c * c - 2.0 * zn * w * c + w * w,
        ];
        let d = [
            c * c + 2.0 * zd * w * c + w * w,
            -2.0 * c * c + 2.0 * w * w,
            c * c - 2.0 * zd * w * c + w * w,
        ];
        Biquad {
            b: [
                (n[0] / d[0]) as f32,
                (n[1] / d[0]) as f32,
                (n[2] / d[0]) as f32,
            ],
            a: [1.0, (d[1] / d[0]) as f32, (d[2] / d[0]) as f32],
        }
    }

    fn tail_amplitude(f_hz: f32) -> f32 {
        let cas = BiquadCascade {
            sections: [notch()],
        };
        cas.validate().unwrap();
        let mut st = CascadeState::new();
        let mut peak = 0.0f32;
        for k in 0..4000 {
            let x = libm::sinf(2.0 * core::f32::consts::PI * f_hz * k as f32 * 1e-3);
            let y = cas.step(&mut st, x);
            if k > 3000 {
                peak = peak.max(y.abs());
            }
        }
        peak
    }

    #[test]
    fn notch_cascade_removes_its_centre_and_passes_low_frequencies() {
        assert!(tail_amplitude(50.0) < 1e-3, "{}", tail_amplitude(50.0));
        let low = tail_amplitude(5.0);
        assert!((low - 1.0).abs() < 0.02, "{low}");
    }

    #[test]
    fn bad_configurations_are_refused() {
        let mut bq = notch();
        bq.a[0] = 2.0;
        let cas = BiquadCascade { sections: [bq] };
        assert_eq!(
            cas.validate(),
            Err(Error::InvalidControlParameter { what: "cascade.a" })
        );
        let cfg = StateSpaceConfig::<2> {
            a: [[0.5, 0.0], [0.0, f32::NAN]],
            b: [1.0; 2],
            c: [1.0; 2],
            d: 0.0,
            l: [0.0; 2],
            u_min: -1.0,
            u_max: 1.0,
        };
        assert_eq!(
            StateSpaceLaw::new(&cfg),
            Err(Error::InvalidControlParameter { what: "ss.a" })
        );
        let cfg = StateSpaceConfig {
            a: [[0.5, 0.0], [0.0, 0.5]],
            u_min: 1.0,
            ..cfg
        };
        assert_eq!(
            StateSpaceLaw::new(&cfg),
            Err(Error::InvalidControlParameter { what: "u_max" })
        );
    }

    #[test]
    fn pid_notch_conditional_integration_holds_the_integrator_at_the_rail() {
        let pid = PidConfig {
            kp: 0.0,
            ki_d: 0.05,
            a_d: 0.0,
            b_d: 0.0,
            rolloff: None,
        };
        let run = |aw: bool| {
            let law = PidNotchLaw::new(&PidNotchConfig {
                pid,
                cascade: BiquadCascade { sections: [] },
                u_min: -1.0,
                u_max: 1.0,
                anti_windup: aw,
            })
            .unwrap();
            let mut st = PidNotchState::<0>::new();
            for _ in 0..100 {
                let o = law.step(&mut st, 1.0, 0.0);
                assert!(o.u <= 1.0);
            }
            st.integrator()
        };
        // 0.05·(1 + 1) per step after the first (0.05): 9.95 without; with it the step that
        // would cross the rail is dropped, so i stays at 0.95.
        assert!((run(false) - 9.95).abs() < 1e-4);
        let held = run(true);
        assert!((held - 0.95).abs() < 1e-5, "{held}");
    }

    #[test]
    fn state_space_law_is_linear_inside_the_rails_and_holds_bad_samples() {
        // First-order lag ξ' = 0.9 ξ + 0.1 e, u = ξ + 0.5 e, rails wide.
        let cfg = StateSpaceConfig::<1> {
            a: [[0.9]],
            b: [0.1],
            c: [1.0],
            d: 0.5,
            l: [0.7],
            u_min: -100.0,
            u_max: 100.0,
        };
        let law = StateSpaceLaw::new(&cfg).unwrap();
        let mut st = StateSpaceState::new();
        let mut x = 0.0f64;
        for k in 0..50 {
            let e = if k % 7 < 3 { 1.0 } else { -0.5 };
            let o = law.step(&mut st, e, 0.0);
            let u = x + 0.5 * f64::from(e);
            x = 0.9 * x + 0.1 * f64::from(e);
            assert!((f64::from(o.u) - u).abs() < 1e-6);
        }
        let before = st;
        let o = law.step(&mut st, f32::NAN, 0.0);
        assert!(o.held && st == before);
    }
}
