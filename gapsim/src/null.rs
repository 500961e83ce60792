//! The null set: effect-free logs on which the diagnosis must not name an effect.
//!
//! Every case runs one of the four plants of [`crate::cases::setups`] with **no** nonlinear
//! effect. What varies is everything a real, linear rig still puts between the nominal model
//! and the log (all drawn from the case's seed):
//! * linear mismatch: every physical parameter of the nominal off by up to ±[`NULL_MISMATCH`];
//! * unmodelled linear dynamics the nominal's order cannot hold, applied to the output: none,
//!   a first-order sensor lag (corner 2–5× the excitation's upper band edge), a lead–lag pair
//!   (zero at 0.5–2× the band edge, pole 1.3–2× above it), or a well-damped second-order mode
//!   (ζ 0.5–0.7 at 1–3× the band edge);
//! * sample alignment: the logged output lags (a > 0) or leads (a < 0) the zero-order-hold
//!   model by a ∈ [−2, 2] samples (fractional; exact in the simulator as an output time shift),
//!   in three cases of five; aligned otherwise;
//! * measurement noise of 0.3 %, 1 % or 3 % of the output standard deviation, white or
//!   coloured (first-order, pole 0.95, rescaled to the same standard deviation);
//! * sensor spikes in one case of four: 0.1–1 % of the samples, ±(0.5–2)× the output standard
//!   deviation;
//! * slow additive drift in one case of four: a ramp plus a half sine over the log, peak
//!   2–5 % of the output standard deviation;
//! * periodic excitation (odd multisines, as the independent family) in one case of three,
//!   band-limited noise with a log-spaced multisine validation otherwise.
//!
//! The true noise floor is the noise's standard deviation over the validation output's (spikes
//! and drift are not noise: a diagnosis must not let them set its floor).
use crate::cases::{excitations, setups, Setup, TS};
use crate::excite::std_dev;
use crate::laws::Effects;
use crate::rng::Xoshiro;
use crate::simulate::simulate;
use ferrosid::data::Log;
use ferrosid::lti::StateSpace;
use std::f64::consts::PI;

/// Relative parameter mismatch of the nominal model in the null set (uniform ±).
pub const NULL_MISMATCH: f64 = 0.30;

/// Cases per plant.
pub const CASES_PER_PLANT: usize = 80;

/// Largest alignment drawn, samples (either sign).
pub const MAX_ALIGNMENT: f64 = 2.0;

/// Unmodelled linear dynamics on the output.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ExtraDynamics {
    /// None.
    None,
    /// First-order low-pass at the corner, Hz.
    SensorLag(f64),
    /// (1 + s/ωz)/(1 + s/ωp), Hz.
    LeadLag(f64, f64),
    /// ω²/(s² + 2ζωs + ω²) at (Hz, ζ).
    DampedMode(f64, f64),
}

/// One effect-free case.
#[derive(Debug, Clone)]
pub struct Case {
    /// Identifier, `null/<plant>/<k>`.
    pub id: String,
    /// Plant and scales.
    pub setup: Setup,
    /// Seed of everything drawn.
    pub seed: u64,
    /// Periodic excitation.
    pub periodic: bool,
    /// Linear dynamics the nominal lacks.
    pub extra: ExtraDynamics,
    /// Output alignment, samples (> 0: the output lags).
    pub alignment: f64,
    /// Noise standard deviation relative to the low run's output standard deviation.
    pub noise_rel: f64,
    /// Coloured noise.
    pub coloured: bool,
    /// Share of samples with a spike (0: none).
    pub spike_share: f64,
    /// Peak drift relative to the output standard deviation (0: none).
    pub drift_rel: f64,
}

impl Case {
    /// One line of the drawn factors, for benchmark logs.
    pub fn describe(&self) -> String {
        format!(
            "{} extra={:?} align={:+.2} noise={}{} spikes={:.3}% drift={:.3}",
            if self.periodic { "periodic" } else { "noise" },
            self.extra,
            self.alignment,
            self.noise_rel,
            if self.coloured { " coloured" } else { "" },
            100.0 * self.spike_share,
            self.drift_rel
        )
    }
}

/// Every case of the null set, in a fixed order ([`CASES_PER_PLANT`] per plant).
pub fn cases() -> Vec<Case> {
    let mut out = Vec::new();
    for (pi, setup) in setups().into_iter().enumerate() {
        for k in 0..CASES_PER_PLANT {
            let seed = 700_000 + 1000 * pi as u64 + k as u64;
            let mut r = Xoshiro::new(seed ^ 0x0A11_6E55_u64);
            let f_hi = setup.f_hi;
            let extra = match k % 4 {
                0 => ExtraDynamics::None,
                1 => ExtraDynamics::SensorLag(f_hi * r.range(2.0, 5.0)),
                2 => {
                    let z = f_hi * r.range(0.5, 2.0);
                    ExtraDynamics::LeadLag(z, z * r.range(1.3, 2.0))
                }
                _ => ExtraDynamics::DampedMode(f_hi * r.range(1.0, 3.0), r.range(0.5, 0.7)),
            };
            let alignment = if k % 5 < 3 {
                r.range(-MAX_ALIGNMENT, MAX_ALIGNMENT)
            } else {
                0.0
            };
            let noise_rel = [0.003, 0.01, 0.03][(k / 4) % 3];
            out.push(Case {
                id: format!("null/{}/{k}", setup.plant.name()),
                setup,
                seed,
                periodic: k % 3 == 0,
                extra,
                alignment,
                noise_rel,
                coloured: (k / 2) % 2 == 1,
                spike_share: if k % 4 == 3 {
                    r.range(0.001, 0.01)
                } else {
                    0.0
                },
                drift_rel: if (k / 3) % 4 == 1 {
                    r.range(0.02, 0.05)
                } else {
                    0.0
                },
            });
        }
    }
    out
}

/// The generated logs of a null case.
#[derive(Debug, Clone)]
pub struct NullData {
    /// Nominal (mismatched) continuous-time model.
    pub sim: StateSpace,
    /// Training logs: low, high amplitude.
    pub train: Vec<Log>,
    /// Validation log.
    pub validate: Log,
    /// NRMSE the noise alone leaves on the validation log.
    pub noise_floor: f64,
}

/// Discrete first- or second-order section by the bilinear transform: b(z)/a(z) with
/// a[0] = 1, run in direct form I over `x`.
fn run_section(b: [f64; 3], a: [f64; 3], x: &mut [f64]) {
    let (mut x1, mut x2, mut y1, mut y2) = (0.0, 0.0, 0.0, 0.0);
    for v in x.iter_mut() {
        let y = (b[0] * *v + b[1] * x1 + b[2] * x2 - a[1] * y1 - a[2] * y2) / a[0];
        x2 = x1;
        x1 = *v;
        y2 = y1;
        y1 = y;
        *v = y;
    }
}

/// Bilinear transform of (n2 s² + n1 s + n0)/(d2 s² + d1 s + d0) at sample time `ts`.
fn bilinear(n: [f64; 3], d: [f64; 3], ts: f64) -> ([f64; 3], [f64; 3]) {
    let k = 2.0 / ts;
    let poly = |c: [f64; 3]| {
        [
            c[2] * k * k + c[1] * k + c[0],
            2.0 * c[0] - 2.0 * c[2] * k * k,
            c[2] * k * k - c[1] * k + c[0],
        ]
    };
    let (b, a) = (poly(n), poly(d));
    let a0 = a[0];
    (b.map(|v| v / a0), a.map(|v| v / a0))
}

/// Applies the extra linear dynamics to `y` (continuous-time forms in the module docs).
pub fn apply_extra(extra: ExtraDynamics, y: &mut [f64]) {
    let w = |f: f64| 2.0 * PI * f;
    let (n, d) = match extra {
        ExtraDynamics::None => return,
        ExtraDynamics::SensorLag(f) => ([1.0, 0.0, 0.0], [1.0, 1.0 / w(f), 0.0]),
        ExtraDynamics::LeadLag(z, p) => ([1.0, 1.0 / w(z), 0.0], [1.0, 1.0 / w(p), 0.0]),
        ExtraDynamics::DampedMode(f, zeta) => {
            let wn = w(f);
            ([wn * wn, 0.0, 0.0], [wn * wn, 2.0 * zeta * wn, 1.0])
        }
    };
    let (b, a) = bilinear(n, d, TS);
    run_section(b, a, y);
}

/// The noise of one log: white or first-order coloured, standard deviation `sd`.
fn noise(n: usize, sd: f64, coloured: bool, rng: &mut Xoshiro) -> Vec<f64> {
    let mut v: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
    if coloured {
        let rho: f64 = 0.95;
        let mut s = 0.0;
        let g = (1.0 - rho * rho).sqrt();
        for x in v.iter_mut() {
            s = rho * s + g * *x;
            *x = s;
        }
    }
    v.iter_mut().for_each(|x| *x *= sd);
    v
}

/// Generates the three logs of `case` with `n` samples each (module docs).
pub fn generate(case: &Case, n: usize) -> ferrosid::error::Result<NullData> {
    let s = case.setup;
    let mut rng = Xoshiro::new(case.seed);
    let nominal = s.plant.perturbed(NULL_MISMATCH, &mut rng).linear()?;
    // A lead needs the output up to ⌈−a⌉ samples past the last command.
    let lead = (-case.alignment).max(0.0).ceil() as usize;
    let out_delay = (case.alignment + lead as f64) * TS;
    let len = n + lead;
    let (u_low, u_high, u_val) = excitations(&s, case.periodic, len, &mut rng);
    let fx = Effects {
        output_delay: out_delay,
        ..Effects::default()
    };
    let err = |e: crate::ode::OdeError| {
        ferrosid::error::Error::Numerical(format!("{}: simulation failed: {e}", case.id))
    };
    let run = |u: &[f64], amp: f64| -> ferrosid::error::Result<Vec<f64>> {
        let (mut y, _) = simulate(s.plant, &fx, u, TS, amp, s.y_ref * amp / s.a).map_err(err)?;
        apply_extra(case.extra, &mut y);
        Ok(y.split_off(lead))
    };
    let clean = [
        run(&u_low, s.a)?,
        run(&u_high, 3.0 * s.a)?,
        run(&u_val, 2.0 * s.a)?,
    ];
    let y_sd = std_dev(&clean[0]);
    let noise_sd = case.noise_rel * y_sd;
    let mut nrng = Xoshiro::new(case.seed ^ 0x00DE_7EC7_ED0F_F5E7);
    let mut logs = Vec::new();
    for (i, (u, c)) in [u_low, u_high, u_val].into_iter().zip(clean).enumerate() {
        let e = noise(n, noise_sd, case.coloured, &mut nrng);
        let mut y: Vec<f64> = c.iter().zip(&e).map(|(a, b)| a + b).collect();
        if case.drift_rel > 0.0 {
            let peak = case.drift_rel * y_sd;
            let sign = if nrng.uniform() < 0.5 { -1.0 } else { 1.0 };
            for (k, v) in y.iter_mut().enumerate() {
                let t = k as f64 / n as f64;
                *v += sign * peak * 0.5 * (t + (PI * t).sin());
            }
        }
        if case.spike_share > 0.0 {
            let count = ((case.spike_share * n as f64).round() as usize).max(1);
            for _ in 0..count {
                let k = ((nrng.uniform() * n as f64) as usize).min(n - 1);
                let sign = if nrng.uniform() < 0.5 { -1.0 } else { 1.0 };
                y[k] += sign * nrng.range(0.5, 2.0) * y_sd;
            }
        }
        let name = ["low", "high", "validate"][i];
        let mut u = u;
        u.truncate(n);
        logs.push(Log::siso(format!("{}/{name}", case.id), TS, u, y));
    }
    let validate = logs.pop().expect("three logs");
    let sd_val = std_dev(validate.y());
    Ok(NullData {
        sim: nominal,
        train: logs,
        validate,
        noise_floor: if sd_val > 0.0 {
            noise_sd / sd_val
        } else {
            f64::NAN
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_null_set_has_at_least_300_cases_on_four_plants_with_unique_ids() {
        let c = cases();
        assert!(c.len() >= 300, "{}", c.len());
        let mut ids: Vec<&str> = c.iter().map(|c| c.id.as_str()).collect();
        ids.sort();
        ids.dedup();
        assert_eq!(ids.len(), c.len());
        let plants: std::collections::BTreeSet<&str> =
            c.iter().map(|c| c.setup.plant.name()).collect();
        assert_eq!(plants.len(), 4);
        assert!(c.iter().any(|c| c.alignment < -1.0) && c.iter().any(|c| c.alignment > 1.0));
        assert!(c.iter().any(|c| c.spike_share > 0.0) && c.iter().any(|c| c.drift_rel > 0.0));
        assert!(c.iter().any(|c| c.periodic) && c.iter().any(|c| !c.periodic));
    }

    /// An integer lead of one sample: the logged output is the aligned one advanced by one.
    #[test]
    fn a_lead_of_one_sample_advances_the_output_by_one_sample() {
        let base = cases()
            .into_iter()
            .find(|c| c.id == "null/dc_motor/3")
            .unwrap();
        let mk = |alignment: f64| Case {
            alignment,
            noise_rel: 0.0,
            spike_share: 0.0,
            drift_rel: 0.0,
            ..base.clone()
        };
        let a = generate(&mk(0.0), 600).unwrap();
        let b = generate(&mk(-1.0), 600).unwrap();
        let (ya, yb) = (a.validate.y(), b.validate.y());
        let worst = (0..598)
            .map(|k| (yb[k] - ya[k + 1]).abs())
            .fold(0.0, f64::max);
        assert!(worst <= 1e-6 * std_dev(ya), "{worst}");
    }

    /// The lead–lag section has unit gain at DC and the ratio p/z at high frequency.
    #[test]
    fn the_lead_lag_section_has_its_closed_form_gains() {
        let mut step = vec![1.0; 4000];
        apply_extra(ExtraDynamics::LeadLag(10.0, 20.0), &mut step);
        assert!((step[3999] - 1.0).abs() < 1e-9, "{}", step[3999]);
        // Bilinear transform: the response at k = 0 is b0 = (1 + kτz)/(1 + kτp), k = 2/ts,
        // τ = 1/(2πf): the high-frequency gain p/z = 2 seen through the prewarp-free map.
        let (k, tz, tp) = (2.0 / TS, 1.0 / (2.0 * PI * 10.0), 1.0 / (2.0 * PI * 20.0));
        let b0 = (1.0 + k * tz) / (1.0 + k * tp);
        assert!((step[0] - b0).abs() < 1e-12, "{} vs {b0}", step[0]);
        assert!((b0 - 2.0).abs() < 0.06);
    }
}
