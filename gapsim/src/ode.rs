//! Adaptive Dormand–Prince 5(4) integration of a hybrid (mode-switching) system with event
//! location.
//!
//! The system is smooth inside a mode. Each mode has guard functions that are positive while
//! the mode is valid; an event fires when a guard goes from > 0 to <= 0 during a step. The
//! earliest crossing in the step is located by the Illinois variant of regula falsi on the step
//! length (each trial re-integrates one Dormand–Prince step from the step's start, so the state
//! at the event is fifth-order accurate), to [`EVENT_TIME_TOL`] s; the system then switches
//! mode (and may reset states, e.g. a velocity to exactly zero when a body sticks) and the
//! integration continues from the event. A guard that starts a step at exactly zero (a mode just
//! entered on its boundary) fires only if it goes strictly negative (the mode was invalid after
//! all, e.g. a body released from stick whose drive fell back below the sliding level at once).
//!
//! Step-size control: error per component relative to `abs_tol_i + rel_tol·|x_i|`, max norm,
//! step factor 0.9·err^(−1/5) clamped to [0.2, 5].

/// Largest state dimension.
pub const MAXN: usize = 12;

/// A state vector (only the first [`HybridSystem::dim`] entries are used).
pub type State = [f64; MAXN];

/// Width of the time bracket at which an event is considered located, s.
pub const EVENT_TIME_TOL: f64 = 1e-12;

/// Most events accepted inside one integration interval before the run is declared Zeno.
pub const MAX_EVENTS_PER_INTERVAL: usize = 200;

/// A mode-switching continuous-time system.
pub trait HybridSystem {
    /// Number of states.
    fn dim(&self) -> usize;
    /// Absolute error tolerance per state (the states' natural scales differ by decades).
    fn abs_tol(&self) -> State;
    /// State derivative in the current mode.
    fn deriv(&self, x: &State, dx: &mut State);
    /// Number of guard functions.
    fn n_guards(&self) -> usize;
    /// Guard values in the current mode (positive while the mode is valid).
    fn guards(&self, x: &State, g: &mut [f64]);
    /// Switches mode after guard `k` fired at the state `x` (which it may reset).
    fn on_event(&mut self, k: usize, x: &mut State);
    /// Makes the mode consistent with the state and the current input (after an input jump).
    fn settle(&mut self, x: &mut State);
}

/// Integrator settings and counters.
#[derive(Debug, Clone)]
pub struct Integrator {
    /// Relative tolerance.
    pub rel_tol: f64,
    /// Step size carried from one call to the next, s.
    pub h: f64,
    /// Largest step, s.
    pub h_max: f64,
    /// Accepted steps so far.
    pub steps: usize,
    /// Rejected steps so far.
    pub rejected: usize,
    /// Events located so far.
    pub events: usize,
    /// Time of the last located event, s (NaN before the first).
    pub last_event_time: f64,
}

/// Why an integration stopped early.
#[derive(Debug, Clone, PartialEq)]
pub enum OdeError {
    /// The step size fell below the floating-point resolution of the time.
    StepUnderflow {
        /// Time at which it happened, s.
        t: f64,
    },
    /// More than [`MAX_EVENTS_PER_INTERVAL`] events in one interval.
    Zeno {
        /// Time at which it happened, s.
        t: f64,
    },
    /// A state became non-finite.
    NonFinite {
        /// Time at which it happened, s.
        t: f64,
    },
}

impl std::fmt::Display for OdeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            OdeError::StepUnderflow { t } => write!(f, "step size underflow at t = {t} s"),
            OdeError::Zeno { t } => write!(
                f,
                "more than {MAX_EVENTS_PER_INTERVAL} events in one interval at t = {t} s"
            ),
            OdeError::NonFinite { t } => write!(f, "state became non-finite at t = {t} s"),
        }
    }
}

// Dormand–Prince 5(4) tableau.
const A21: f64 = 1.0 / 5.0;
const A31: f64 = 3.0 / 40.0;
const A32: f64 = 9.0 / 40.0;
const A41: f64 = 44.0 / 45.0;
const A42: f64 = -56.0 / 15.0;
const A43: f64 = 32.0 / 9.0;
const A51: f64 = 19372.0 / 6561.0;
const A52: f64 = -25360.0 / 2187.0;
const A53: f64 = 64448.0 / 6561.0;
const A54: f64 = -212.0 / 729.0;
const A61: f64 = 9017.0 / 3168.0;
const A62: f64 = -355.0 / 33.0;
const A63: f64 = 46732.0 / 5247.0;
const A64: f64 = 49.0 / 176.0;
const A65: f64 = -5103.0 / 18656.0;
const B1: f64 = 35.0 / 384.0;
const B3: f64 = 500.0 / 1113.0;
const B4: f64 = 125.0 / 192.0;
const B5: f64 = -2187.0 / 6784.0;
const B6: f64 = 11.0 / 84.0;
// Error weights: fifth-order minus embedded fourth-order solution.
const E1: f64 = 71.0 / 57600.0;
const E3: f64 = -71.0 / 16695.0;
const E4: f64 = 71.0 / 1920.0;
const E5: f64 = -17253.0 / 339200.0;
const E6: f64 = 22.0 / 525.0;
const E7: f64 = -1.0 / 40.0;

/// One Dormand–Prince step of size `h` from `x`: returns the fifth-order solution and the error
/// estimate. The node times c_i are not needed: the systems are autonomous within an interval
/// (the input is held).
fn dp_step<S: HybridSystem>(sys: &S, x: &State, h: f64) -> (State, State) {
    let n = sys.dim();
    let mut k1 = [0.0; MAXN];
    let mut k2 = [0.0; MAXN];
    let mut k3 = [0.0; MAXN];
    let mut k4 = [0.0; MAXN];
    let mut k5 = [0.0; MAXN];
    let mut k6 = [0.0; MAXN];
    let mut k7 = [0.0; MAXN];
    let mut xt = [0.0; MAXN];
    sys.deriv(x, &mut k1);
    for i in 0..n {
        xt[i] = x[i] + h * A21 * k1[i];
    }
    sys.deriv(&xt, &mut k2);
    for i in 0..n {
        xt[i] = x[i] + h * (A31 * k1[i] + A32 * k2[i]);
    }
    sys.deriv(&xt, &mut k3);
    for i in 0..n {
        xt[i] = x[i] + h * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i]);
    }
    sys.deriv(&xt, &mut k4);
    for i in 0..n {
        xt[i] = x[i] + h * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i]);
    }
    sys.deriv(&xt, &mut k5);
    for i in 0..n {
        xt[i] = x[i] + h * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] + A65 * k5[i]);
    }
    sys.deriv(&xt, &mut k6);
    let mut x5 = [0.0; MAXN];
    for i in 0..n {
        x5[i] = x[i] + h * (B1 * k1[i] + B3 * k3[i] + B4 * k4[i] + B5 * k5[i] + B6 * k6[i]);
    }
    sys.deriv(&x5, &mut k7);
    let mut err = [0.0; MAXN];
    for i in 0..n {
        err[i] = h * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i]);
    }
    (x5, err)
}

impl Integrator {
    /// An integrator with relative tolerance `rel_tol` and largest step `h_max` s.
    pub fn new(rel_tol: f64, h_max: f64) -> Self {
        Self {
            rel_tol,
            h: h_max,
            h_max,
            steps: 0,
            rejected: 0,
            events: 0,
            last_event_time: f64::NAN,
        }
    }

    fn error_norm<S: HybridSystem>(&self, sys: &S, x: &State, xn: &State, err: &State) -> f64 {
        let atol = sys.abs_tol();
        let mut e: f64 = 0.0;
        for i in 0..sys.dim() {
            let sc = atol[i] + self.rel_tol * x[i].abs().max(xn[i].abs());
            e = e.max(err[i].abs() / sc);
        }
        e
    }

    /// Integrates `sys` from `t0` to `t1` (the input held), handling events on the way.
    /// `x` holds the state at `t0` on entry and at `t1` on return.
    pub fn advance<S: HybridSystem>(
        &mut self,
        sys: &mut S,
        x: &mut State,
        t0: f64,
        t1: f64,
    ) -> Result<(), OdeError> {
        let ng = sys.n_guards();
        let mut g0 = vec![0.0; ng];
        let mut g1 = vec![0.0; ng];
        let mut t = t0;
        let mut n_events = 0usize;
        sys.guards(x, &mut g0);
        while t < t1 {
            let remaining = t1 - t;
            let mut h = self.h.min(self.h_max).min(remaining);
            // Avoid a sliver step just before the interval end.
            if remaining - h < 1e-3 * h {
                h = remaining;
            }
            if h <= 4.0 * f64::EPSILON * t1.abs().max(1e-3) {
                // Interval end reached to floating-point resolution.
                break;
            }
            let (xn, err) = dp_step(sys, x, h);
            let e = self.error_norm(sys, x, &xn, &err);
            if !e.is_finite() {
                if h < 1e-14 {
                    return Err(OdeError::NonFinite { t });
                }
                self.h = 0.2 * h;
                self.rejected += 1;
                continue;
            }
            if e > 1.0 {
                self.h = h * (0.9 * e.powf(-0.2)).clamp(0.2, 1.0);
                self.rejected += 1;
                if self.h < 1e-15 * t1.abs().max(1.0) {
                    return Err(OdeError::StepUnderflow { t });
                }
                continue;
            }
            self.steps += 1;
            let grow = if e == 0.0 {
                5.0
            } else {
                (0.9 * e.powf(-0.2)).clamp(0.2, 5.0)
            };
            sys.guards(&xn, &mut g1);
            // A guard fires when it goes from > 0 to <= 0, or from exactly 0 (a mode entered on
            // its boundary) to < 0 (the mode turned out invalid right away).
            let fired: Vec<usize> = (0..ng)
                .filter(|&k| (g0[k] > 0.0 && g1[k] <= 0.0) || (g0[k] == 0.0 && g1[k] < 0.0))
                .collect();
            if fired.is_empty() {
                *x = xn;
                t += h;
                std::mem::swap(&mut g0, &mut g1);
                self.h = if h < remaining {
                    h * grow
                } else {
                    self.h.max(h)
                };
                continue;
            }
            // Locate the earliest crossing: phi(θ) = min over fired guards, phi(0) > 0 >= phi(h).
            let phi = |sys: &S, th: f64, g: &mut [f64]| -> (f64, usize, State) {
                let (xt, _) = dp_step(sys, x, th);
                sys.guards(&xt, g);
                let (mut m, mut arg) = (f64::INFINITY, fired[0]);
                for &k in &fired {
                    if g[k] < m {
                        m = g[k];
                        arg = k;
                    }
                }
                (m, arg, xt)
            };
            let (mut a, mut fa) = (
                0.0,
                fired.iter().map(|&k| g0[k]).fold(f64::INFINITY, f64::min),
            );
            let (mut b, mut fb, mut kb, mut xb) = {
                let (m, arg, _) = phi(sys, h, &mut g1);
                (h, m, arg, xn)
            };
            let mut side = 0i8;
            let mut iter = 0;
            while b - a > EVENT_TIME_TOL && iter < 200 {
                iter += 1;
                let mut c = if fa.is_finite() && fb.is_finite() && fa != fb {
                    b - fb * (b - a) / (fb - fa)
                } else {
                    0.5 * (a + b)
                };
                if !(c > a && c < b) {
                    c = 0.5 * (a + b);
                }
                let (fc, kc, xc) = phi(sys, c, &mut g1);
                if fc <= 0.0 {
                    b = c;
                    fb = fc;
                    kb = kc;
                    xb = xc;
                    if side == -1 {
                        fa *= 0.5;
                    }
                    side = -1;
                } else {
                    a = c;
                    fa = fc;
                    if side == 1 {
                        fb *= 0.5;
                    }
                    side = 1;
                }
            }
            *x = xb;
            t += b;
            self.events += 1;
            self.last_event_time = t;
            n_events += 1;
            if n_events > MAX_EVENTS_PER_INTERVAL {
                return Err(OdeError::Zeno { t });
            }
            sys.on_event(kb, x);
            sys.settle(x);
            sys.guards(x, &mut g0);
            if x[..sys.dim()].iter().any(|v| !v.is_finite()) {
                return Err(OdeError::NonFinite { t });
            }
        }
        Ok(())
    }
}
