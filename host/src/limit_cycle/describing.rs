//! Sinusoidal-input describing functions N(A) of the nonlinearities the gap diagnosis knows.
//!
//! For an input x(t) = A·sin(ωt) the output's first harmonic is b₁·sin(ωt) + a₁·cos(ωt); the
//! describing function is N(A) = (b₁ + j·a₁)/A (gain and phase of the fundamental; a lag
//! gives Im N < 0). Every nonlinearity here is rate-independent, so N depends on A only.
//!
//! Closed forms (A is the input amplitude in the nonlinearity's input units; references:
//! J.-J. E. Slotine & W. Li, *Applied Nonlinear Control*, 1991, §5.3; A. Gelb & W. E. Vander
//! Velde, *Multiple-Input Describing Functions and Nonlinear System Design*, 1968, ch. 2 and
//! app. B; H. K. Khalil, *Nonlinear Systems*, 3rd ed., §7.2):
//!
//! | nonlinearity | parameters | N(A) |
//! |---|---|---|
//! | relay / Coulomb friction | level M | 4M/(πA) |
//! | relay with hysteresis | level M, half-width h | 4M/(πA)·(√(1−(h/A)²) − j·h/A), A > h; 0 else |
//! | ideal saturation (unit slope) | limit δ | 1 for A ≤ δ; (2/π)(asin(δ/A) + (δ/A)√(1−(δ/A)²)) |
//! | dead zone (unit slope) | full width 2δ | 0 for A ≤ δ; 1 − (2/π)(asin(δ/A) + (δ/A)√(1−(δ/A)²)) |
//! | backlash / play (unit slope) | total play 2b | for A > b: [π/2 + asin(1−2b/A) + 2(1−2b/A)√((b/A)(1−b/A))]/π − j·(4b/(πA))(1−b/A); 0 else |
//! | quantizer (rounding) | step q | (4q/(πA))·Σᵢ √(1 − ((2i−1)q/(2A))²) over the n thresholds (2i−1)q/2 < A |
//! | stiction (Karnopp) | sliding M, breakaway M_s | 4M/(πA) — see below |
//!
//! **Stiction.** A sinusoidal velocity never dwells at zero, so the Karnopp law only ever
//! slides: its describing function is the Coulomb relay at the *sliding* level and the
//! breakaway level does not appear. The stick phases that make stiction dangerous (hunting,
//! stick-slip at low speed) are invisible to the describing function — one of the reasons the
//! prediction is always confirmed by simulating the nonlinear loop
//! ([`crate::limit_cycle::simulate`]).
//!
//! [`DescribingFunction::first_harmonic_numeric`] computes N(A) independently by quadrature of
//! the nonlinearity's time-domain output over one period (the play and the hysteretic relay
//! are run over two periods and the second is used), the cross-check of the closed forms.
use crate::error::{Error, Result};
use crate::gap::effect::{deadzone, quantize, saturation, Play};
use num_complex::Complex64;
use serde::Serialize;
use std::f64::consts::PI;

/// A nonlinearity with its parameters, all in the units of its input signal (input units for
/// drive effects and friction forces, output units for sensor effects) except friction, whose
/// *input* is a velocity and whose *output* (`level`) is a force in plant input units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum DescribingFunction {
    /// Ideal relay ±`level` (Coulomb friction against velocity).
    Relay {
        /// Output level M (> 0).
        level: f64,
    },
    /// Relay ±`level` switching at ±`half_width` (output changes sign when the input passes
    /// +h going up or −h going down).
    RelayHysteresis {
        /// Output level M (> 0).
        level: f64,
        /// Half-width h of the hysteresis band (> 0), input units.
        half_width: f64,
    },
    /// Unit-slope saturation at ±`limit`.
    Saturation {
        /// Limit δ (> 0).
        limit: f64,
    },
    /// Unit-slope dead zone of full `width` (output sign(x)·max(|x| − width/2, 0)).
    DeadZone {
        /// Full width 2δ (> 0).
        width: f64,
    },
    /// Play (backlash) of total `gap` with unit slope ([`crate::gap::effect::Play`]).
    Backlash {
        /// Total play 2b (> 0).
        gap: f64,
    },
    /// Rounding quantizer with `step` ([`crate::gap::effect::quantize`]).
    Quantization {
        /// Step q (> 0).
        step: f64,
    },
    /// Karnopp stick-slip friction: slides at `level`, breaks away at `breakaway`.
    Stiction {
        /// Sliding level (> 0).
        level: f64,
        /// Breakaway level (>= level).
        breakaway: f64,
    },
}

impl DescribingFunction {
    /// Short name (`relay`, `relay_hysteresis`, `saturation`, `dead_zone`, `backlash`,
    /// `quantization`, `stiction`).
    pub fn name(&self) -> &'static str {
        match self {
            Self::Relay { .. } => "relay",
            Self::RelayHysteresis { .. } => "relay_hysteresis",
            Self::Saturation { .. } => "saturation",
            Self::DeadZone { .. } => "dead_zone",
            Self::Backlash { .. } => "backlash",
            Self::Quantization { .. } => "quantization",
            Self::Stiction { .. } => "stiction",
        }
    }

    /// Checks that every parameter is finite and in range (see the variants).
    pub fn validate(&self) -> Result<()> {
        let (vals, extra_ok): (Vec<(&str, f64)>, bool) = match *self {
            Self::Relay { level } => (vec![("level", level)], true),
            Self::RelayHysteresis { level, half_width } => {
                (vec![("level", level), ("half_width", half_width)], true)
            }
            Self::Saturation { limit } => (vec![("limit", limit)], true),
            Self::DeadZone { width } => (vec![("width", width)], true),
            Self::Backlash { gap } => (vec![("gap", gap)], true),
            Self::Quantization { step } => (vec![("step", step)], true),
            Self::Stiction { level, breakaway } => (
                vec![("level", level), ("breakaway", breakaway)],
                breakaway >= level,
            ),
        };
        for (n, v) in vals {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::InvalidArgument(format!(
                    "describing function {}: parameter {n} = {v} must be finite and > 0",
                    self.name()
                )));
            }
        }
        if !extra_ok {
            return Err(Error::InvalidArgument(format!(
                "describing function {}: breakaway must be >= level",
                self.name()
            )));
        }
        Ok(())
    }

    /// The amplitude below which N(A) = 0 (the input never leaves a dead band or a
    /// hysteresis band); 0 for nonlinearities that respond to any amplitude.
    pub fn threshold(&self) -> f64 {
        match *self {
            Self::RelayHysteresis { half_width, .. } => half_width,
            Self::DeadZone { width } => 0.5 * width,
            Self::Backlash { gap } => 0.5 * gap,
            Self::Quantization { step } => 0.5 * step,
            _ => 0.0,
        }
    }

    /// The nonlinearity's own amplitude scale (level, width, limit, play or step), used to
    /// place amplitude grids.
    pub fn scale(&self) -> f64 {
        match *self {
            Self::Relay { level } | Self::Stiction { level, .. } => level,
            Self::RelayHysteresis { half_width, .. } => half_width,
            Self::Saturation { limit } => limit,
            Self::DeadZone { width } => width,
            Self::Backlash { gap } => gap,
            Self::Quantization { step } => step,
        }
    }

    /// N(A) by the closed form of the module table. `a` must be finite and > 0 (else NaN).
    pub fn eval(&self, a: f64) -> Complex64 {
        if !(a.is_finite() && a > 0.0) {
            return Complex64::new(f64::NAN, f64::NAN);
        }
        let re = |v: f64| Complex64::new(v, 0.0);
        // (2/π)(asin r + r√(1−r²)), the saturation's N for r = δ/A <= 1.
        let sat = |r: f64| (2.0 / PI) * (r.asin() + r * (1.0 - r * r).max(0.0).sqrt());
        match *self {
            Self::Relay { level } | Self::Stiction { level, .. } => re(4.0 * level / (PI * a)),
            Self::RelayHysteresis { level, half_width } => {
                if a <= half_width {
                    re(0.0)
                } else {
                    let r = half_width / a;
                    Complex64::new((1.0 - r * r).sqrt(), -r) * (4.0 * level / (PI * a))
                }
            }
            Self::Saturation { limit } => {
                if a <= limit {
                    re(1.0)
                } else {
                    re(sat(limit / a))
                }
            }
            Self::DeadZone { width } => {
                let d = 0.5 * width;
                if a <= d {
                    re(0.0)
                } else {
                    re(1.0 - sat(d / a))
                }
            }
            Self::Backlash { gap } => {
                let b = 0.5 * gap;
                if a <= b {
                    re(0.0)
                } else {
                    let r = b / a;
                    let p = (PI / 2.0
                        + (1.0 - 2.0 * r).asin()
                        + 2.0 * (1.0 - 2.0 * r) * (r * (1.0 - r)).max(0.0).sqrt())
                        / PI;
                    let q = -(4.0 * r / PI) * (1.0 - r);
                    Complex64::new(p, q)
                }
            }
            Self::Quantization { step } => {
                let mut sum = 0.0;
                let mut i = 1.0f64;
                loop {
                    let t = (2.0 * i - 1.0) * step / (2.0 * a);
                    if t >= 1.0 || i > 1e6 {
                        break;
                    }
                    sum += (1.0 - t * t).sqrt();
                    i += 1.0;
                }
                re(4.0 * step / (PI * a) * sum)
            }
        }
    }

    /// The time-domain output for the input sequence `x`, starting from the nonlinearity's
    /// rest state (play engaged at 0, hysteretic relay at +level when x[0] >= 0 else −level,
    /// stiction sliding: `sign` law at the sliding level).
    pub fn respond(&self, x: &[f64]) -> Vec<f64> {
        match *self {
            Self::Relay { level } | Self::Stiction { level, .. } => x
                .iter()
                .map(|&v| if v == 0.0 { 0.0 } else { level * v.signum() })
                .collect(),
            Self::RelayHysteresis { level, half_width } => {
                let mut out = if x.first().is_some_and(|&v| v < 0.0) {
                    -level
                } else {
                    level
                };
                x.iter()
                    .map(|&v| {
                        if v >= half_width {
                            out = level;
                        } else if v <= -half_width {
                            out = -level;
                        }
                        out
                    })
                    .collect()
            }
            Self::Saturation { limit } => x.iter().map(|&v| saturation(v, limit)).collect(),
            Self::DeadZone { width } => x.iter().map(|&v| deadzone(v, width)).collect(),
            Self::Backlash { gap } => {
                let mut p = Play::new(gap);
                x.iter().map(|&v| p.apply(v)).collect()
            }
            Self::Quantization { step } => x.iter().map(|&v| quantize(v, step)).collect(),
        }
    }

    /// N(A) computed numerically: the nonlinearity's output for A·sin θ over two periods
    /// (`n` midpoint samples per period), first Fourier coefficients of the second period by the
    /// midpoint rule. Independent of [`Self::eval`]; the error is O(1/n) for discontinuous
    /// outputs (relays, quantizer).
    pub fn first_harmonic_numeric(&self, a: f64, n: usize) -> Complex64 {
        let n = n.max(16);
        let dth = 2.0 * PI / n as f64;
        let x: Vec<f64> = (0..2 * n)
            .map(|k| a * ((k as f64 + 0.5) * dth).sin())
            .collect();
        second_period_harmonic(&self.respond(&x), a)
    }
}

/// First Fourier coefficients (b₁ + j·a₁)/A of `y`, a response to A·sin θ sampled at the
/// midpoints θ_k = (k + ½)·2π/n of two periods (2n samples): the midpoint rule over the second
/// period, so the first period absorbs the transient of a nonlinearity with memory.
pub(crate) fn second_period_harmonic(y: &[f64], a: f64) -> Complex64 {
    let n = y.len() / 2;
    let dth = 2.0 * PI / n as f64;
    let (mut b1, mut a1) = (0.0, 0.0);
    for (k, yk) in y.iter().enumerate().skip(n) {
        let th = (k as f64 + 0.5) * dth;
        b1 += yk * th.sin();
        a1 += yk * th.cos();
    }
    Complex64::new(b1, a1) * (dth / (PI * a))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all() -> Vec<DescribingFunction> {
        vec![
            DescribingFunction::Relay { level: 0.7 },
            DescribingFunction::RelayHysteresis {
                level: 1.3,
                half_width: 0.4,
            },
            DescribingFunction::Saturation { limit: 0.8 },
            DescribingFunction::DeadZone { width: 0.6 },
            DescribingFunction::Backlash { gap: 0.5 },
            DescribingFunction::Quantization { step: 0.25 },
            DescribingFunction::Stiction {
                level: 0.2,
                breakaway: 0.5,
            },
        ]
    }

    /// Every closed form against the quadrature of the time-domain law, over amplitudes from
    /// just above the threshold to 50 scales (tolerance: midpoint-rule error of a discontinuous
    /// output with 200k points, relative to the largest |N|).
    #[test]
    fn closed_forms_match_the_numerical_first_harmonic() {
        for df in all() {
            df.validate().unwrap();
            let s = df.scale();
            for &m in &[0.3, 0.55, 0.9, 1.0, 1.7, 3.1, 7.0, 50.0] {
                let a = m * s + 1.01 * df.threshold();
                let closed = df.eval(a);
                let num = df.first_harmonic_numeric(a, 200_000);
                let tol = 2e-4 * closed.norm().max(1e-3 * df.scale() / a).max(1e-3);
                assert!(
                    (closed - num).norm() < tol,
                    "{} A={a}: closed {closed} vs numeric {num}",
                    df.name()
                );
            }
        }
    }

    /// Textbook values at specific points (hand-evaluated).
    #[test]
    fn textbook_values() {
        // Relay: N = 4M/(πA); M = 1, A = 4/π gives 1.
        let r = DescribingFunction::Relay { level: 1.0 }.eval(4.0 / PI);
        assert!((r - Complex64::new(1.0, 0.0)).norm() < 1e-15);
        // Hysteresis relay M = 1, h = 0.5, A = 1: (4/π)(√0.75 − 0.5j).
        let h = DescribingFunction::RelayHysteresis {
            level: 1.0,
            half_width: 0.5,
        }
        .eval(1.0);
        assert!((h - Complex64::new(4.0 / PI * 0.75f64.sqrt(), -2.0 / PI)).norm() < 1e-14);
        // −1/N of the hysteresis relay has the constant imaginary part −πh/(4M).
        for a in [0.6, 1.0, 5.0] {
            let n = DescribingFunction::RelayHysteresis {
                level: 2.0,
                half_width: 0.5,
            }
            .eval(a);
            assert!(((-1.0 / n).im + PI * 0.5 / 8.0).abs() < 1e-14);
        }
        // Saturation δ = 1 at A = 2: (2/π)(π/6 + 0.5·√0.75) = 0.608998.
        let s = DescribingFunction::Saturation { limit: 1.0 }.eval(2.0);
        assert!((s.re - (2.0 / PI) * (PI / 6.0 + 0.5 * 0.75f64.sqrt())).abs() < 1e-14);
        assert!((s.re - 0.608_997_8).abs() < 1e-6);
        // Dead zone + saturation of the same δ sum to the identity.
        for a in [1.2, 3.0, 10.0] {
            let d = DescribingFunction::DeadZone { width: 2.0 }.eval(a);
            let s = DescribingFunction::Saturation { limit: 1.0 }.eval(a);
            assert!((d + s - Complex64::new(1.0, 0.0)).norm() < 1e-14);
        }
        // Backlash b = 0.5 (gap 1) at A = 1: r = 0.5 → Re = (π/2 + 0 + 0)/π = 0.5,
        // Im = −(4·0.5/π)(0.5) = −1/π.
        let b = DescribingFunction::Backlash { gap: 1.0 }.eval(1.0);
        assert!((b - Complex64::new(0.5, -1.0 / PI)).norm() < 1e-14);
        // Quantizer q = 1 at A = 1: one threshold 0.5 → (4/π)√0.75.
        let q = DescribingFunction::Quantization { step: 1.0 }.eval(1.0);
        assert!((q.re - 4.0 / PI * 0.75f64.sqrt()).abs() < 1e-14);
        // Large amplitude: saturation → 4δ/(πA) (a relay), dead zone and play → 1.
        let s = DescribingFunction::Saturation { limit: 1.0 }.eval(1e4);
        assert!((s.re / (4.0 / (PI * 1e4)) - 1.0).abs() < 1e-6);
        assert!((DescribingFunction::DeadZone { width: 1.0 }.eval(1e6).re - 1.0).abs() < 1e-6);
        assert!((DescribingFunction::Backlash { gap: 1.0 }.eval(1e6) - 1.0).norm() < 1e-5);
    }

    #[test]
    fn below_threshold_and_bad_inputs() {
        assert_eq!(
            DescribingFunction::DeadZone { width: 1.0 }.eval(0.4).re,
            0.0
        );
        assert_eq!(
            DescribingFunction::Quantization { step: 1.0 }.eval(0.4).re,
            0.0
        );
        assert!(DescribingFunction::Relay { level: 1.0 }
            .eval(f64::NAN)
            .re
            .is_nan());
        assert!(DescribingFunction::Relay { level: 1.0 }
            .eval(-1.0)
            .re
            .is_nan());
        let e = DescribingFunction::Saturation { limit: f64::NAN }
            .validate()
            .unwrap_err()
            .to_string();
        assert!(e.contains("limit") && e.contains("finite"), "{e}");
        assert!(DescribingFunction::Stiction {
            level: 1.0,
            breakaway: 0.5
        }
        .validate()
        .is_err());
    }
}
