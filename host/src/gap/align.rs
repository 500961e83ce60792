//! Sample alignment between a log's input and output, estimated as part of the linear model.
//!
//! Many loggers store y[k] sampled at the *end* of the control period in which u[k] was applied
//! (the output leads the zero-order-hold model by one sample), and multi-rate logs carry a skew
//! of a fraction of a sample. Neither is an effect of the plant, and a linear re-fit without
//! lead or feedthrough cannot hold either, so an effect-free plant would read as `unexplained`.
//!
//! The alignment a (samples, fractional, within ±[`MAX_ALIGNMENT`]) says the logged output lags
//! the zero-order-hold model by a samples (a < 0: it leads). It is estimated on the training
//! logs only ([`estimate`]):
//! 1. for every shift of a grid (step [`GRID_STEP`]) the input is shifted ([`shift_input`]) and
//!    the linear model's residues, feedthrough and offset are fitted by least squares on the
//!    sim's poles scaled by a common factor (0.6–1.6, as the re-fit's scan), the best factor
//!    kept: a cost curve over the shift;
//! 2. the best grid point is refined by a golden-section search within ± one grid step, then by
//!    output-error fits (poles free) at the refined shift and ±[`OE_PROBE`], whose parabola gives
//!    the estimate (the window moves to the vertex, up to four times, while the vertex lands on
//!    its edge);
//! 3. the alignment is **applied** only when it is significant: the likelihood ratio of the
//!    aligned output-error fit over the unaligned one, Λ = N_eff·ln(C₀/C_a) (N_eff the effective
//!    sample count of the unaligned residual, [`crate::gap::verdict::effective_samples`]), is at
//!    least the χ² quantile with one degree of freedom at p = 0.001 (10.83), and |a| ≥
//!    [`MIN_ALIGNMENT`].
//!
//! Applied, every log's input is shifted by a before the diagnosis fits and judges anything, so
//! effects are judged on aligned data; the report states a (`linear.alignment_samples`). From
//! input/output data a logging offset and a dead time of the same length are the same thing: a
//! lag within the range is reported as the alignment, a longer one as a `time_delay` on top.
use super::fit::TrainData;
use super::modal::{FitSet, ModalModel};
use super::verdict::{effective_samples, NESTED_LR_THRESHOLD};
use num_complex::Complex64;

/// Largest alignment estimated, samples (either sign).
pub const MAX_ALIGNMENT: f64 = 3.0;

/// Step of the coarse grid of shifts, samples.
pub const GRID_STEP: f64 = 0.5;

/// Half-spacing of the output-error probes around the refined shift, samples.
pub const OE_PROBE: f64 = 0.25;

/// Smallest alignment applied, samples.
pub const MIN_ALIGNMENT: f64 = 0.05;

/// Output-error iterations of each probe.
const OE_ITER: usize = 30;

/// Times the output-error window may move after its vertex.
const OE_MOVES: usize = 4;

/// The estimated alignment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Alignment {
    /// Estimated lag of the logged output behind the zero-order-hold model, samples.
    pub samples: f64,
    /// Likelihood ratio of the aligned linear fit over the unaligned one.
    pub likelihood_ratio: f64,
    /// Whether the diagnosis applies it (significant, see the module docs).
    pub applied: bool,
}

/// `u` delayed by `a` samples (fractional; a < 0 advances it): u_a[k] = u(k − a), linear
/// interpolation between samples, the first and last sample held beyond the log's ends.
pub fn shift_input(u: &[f64], a: f64) -> Vec<f64> {
    let n = u.len() as isize;
    if n == 0 || a == 0.0 {
        return u.to_vec();
    }
    let m = a.floor();
    let f = a - m;
    let m = m as isize;
    let at = |j: isize| u[j.clamp(0, n - 1) as usize];
    (0..n)
        .map(|k| (1.0 - f) * at(k - m) + f * at(k - m - 1))
        .collect()
}

fn shifted_set(td: &TrainData, a: f64) -> Option<FitSet> {
    let w: Vec<Vec<f64>> = td.u.iter().map(|u| shift_input(u, a)).collect();
    let mut set = FitSet::new(w, td.base.y.clone(), td.base.warmup).ok()?;
    set.drift_window = td.base.drift_window;
    Some(set)
}

/// The linear starts of the scan: the sim's poles with every continuous-equivalent pole scaled
/// by a common factor 0.6..1.6 (11 factors, log-spaced).
fn scan_models(ts: f64, poles: &[Complex64], use_d: bool) -> Vec<ModalModel> {
    (0..=10)
        .filter_map(|i| {
            let alpha = 0.6 * (1.6f64 / 0.6).powf(i as f64 / 10.0);
            let p: Vec<Complex64> = poles
                .iter()
                .map(|&z| {
                    if (z - Complex64::new(1.0, 0.0)).norm() < 1e-12 {
                        z
                    } else {
                        (z.ln() * alpha).exp()
                    }
                })
                .collect();
            ModalModel::from_poles(ts, &p, use_d).ok()
        })
        .collect()
}

/// Least-squares cost at shift `a` and the model reaching it (best scan factor).
fn ls_cost(td: &TrainData, models: &[ModalModel], a: f64) -> Option<(f64, ModalModel)> {
    let set = shifted_set(td, a)?;
    models
        .iter()
        .filter_map(|m| {
            let mut m = m.clone();
            let c = m.fit_linear_params(&set)?;
            c.is_finite().then_some((c, m))
        })
        .min_by(|x, y| x.0.total_cmp(&y.0))
}

/// Output-error cost at shift `a` from `start`.
fn oe_cost(td: &TrainData, start: &ModalModel, a: f64) -> Option<(f64, ModalModel)> {
    let set = shifted_set(td, a)?;
    let mut m = start.clone();
    let c = m.fit_output_error(&set, OE_ITER)?;
    c.is_finite().then_some((c, m))
}

/// Golden-section minimum of `f` on [lo, hi] to within `tol`.
fn golden(lo: f64, hi: f64, tol: f64, f: &dyn Fn(f64) -> f64) -> f64 {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut a, mut b) = (lo, hi);
    let mut c = b - g * (b - a);
    let mut d = a + g * (b - a);
    let (mut fc, mut fd) = (f(c), f(d));
    while b - a > tol {
        if fc <= fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = f(d);
        }
    }
    0.5 * (a + b)
}

/// Vertex of the parabola through (x − h, l), (x, c), (x + h, r), clamped to [x − h, x + h]
/// (x itself when the three points are not convex).
fn parabola_vertex(x: f64, h: f64, (l, c, r): (f64, f64, f64)) -> f64 {
    let curv = l - 2.0 * c + r;
    if !(curv > 0.0) {
        return x;
    }
    (x + 0.5 * h * (l - r) / curv).clamp(x - h, x + h)
}

/// Estimates the alignment on the training data `td` (module docs): `poles` the sim's poles in
/// modal form, `use_d` whether the linear model has a feedthrough. `None` when no linear model
/// can be fitted at all.
pub fn estimate(td: &TrainData, poles: &[Complex64], use_d: bool) -> Option<Alignment> {
    let models = scan_models(td.ts, poles, use_d);
    let steps = (MAX_ALIGNMENT / GRID_STEP).round() as i32;
    let grid: Vec<(f64, f64)> = (-steps..=steps)
        .filter_map(|i| {
            let a = f64::from(i) * GRID_STEP;
            ls_cost(td, &models, a).map(|(c, _)| (a, c))
        })
        .collect();
    let &(a0, _) = grid.iter().min_by(|x, y| x.1.total_cmp(&y.1))?;
    let cost = |a: f64| ls_cost(td, &models, a).map_or(f64::INFINITY, |(c, _)| c);
    let lo = (a0 - GRID_STEP).max(-MAX_ALIGNMENT);
    let hi = (a0 + GRID_STEP).min(MAX_ALIGNMENT);
    let a1 = golden(lo, hi, 0.01, &cost);
    // Output-error probes (poles free) around the refined shift, and at zero.
    let (_, start) = ls_cost(td, &models, a1)?;
    let probe = |a: f64| oe_cost(td, &start, a.clamp(-MAX_ALIGNMENT, MAX_ALIGNMENT));
    // The least-squares curve can sit off the output-error minimum (the poles are held there):
    // the parabola's window follows its vertex while that lands on the window's edge.
    let mut a1 = a1;
    let mut cm = probe(a1)?;
    let mut a = a1;
    for _ in 0..OE_MOVES {
        let (cl, cr) = (probe(a1 - OE_PROBE)?, probe(a1 + OE_PROBE)?);
        a = parabola_vertex(a1, OE_PROBE, (cl.0, cm.0, cr.0)).clamp(-MAX_ALIGNMENT, MAX_ALIGNMENT);
        if (a - a1).abs() < 0.99 * OE_PROBE || a.abs() >= MAX_ALIGNMENT {
            break;
        }
        a1 = a;
        cm = probe(a1)?;
    }
    let aligned = probe(a)?;
    let (_, start0) = ls_cost(td, &models, 0.0)?;
    let unaligned = oe_cost(td, &start0, 0.0)?;
    let (a, best) = if aligned.0 <= cm.0 {
        (a, aligned.0)
    } else {
        (a1, cm.0)
    };
    // Effective samples of the unaligned residual over the scored samples of every log.
    let set0 = shifted_set(td, 0.0)?;
    let n_eff: f64 = set0
        .w
        .iter()
        .zip(&set0.y)
        .map(|(w, y)| {
            let r: Vec<f64> = y
                .iter()
                .zip(unaligned.1.simulate(w))
                .skip(set0.warmup)
                .map(|(a, b)| a - b)
                .collect();
            effective_samples(&r)
        })
        .sum();
    let lr = if best > 0.0 && unaligned.0 > best {
        n_eff * (unaligned.0 / best).ln()
    } else {
        0.0
    };
    Some(Alignment {
        samples: a,
        likelihood_ratio: lr,
        applied: lr >= NESTED_LR_THRESHOLD && a.abs() >= MIN_ALIGNMENT,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::simulator::rng::Rng;

    #[test]
    fn an_integer_shift_moves_the_input_by_whole_samples() {
        let u = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(shift_input(&u, 1.0), vec![1.0, 1.0, 2.0, 3.0]);
        assert_eq!(shift_input(&u, -1.0), vec![2.0, 3.0, 4.0, 4.0]);
        assert_eq!(shift_input(&u, 0.5), vec![1.0, 1.5, 2.5, 3.5]);
        assert_eq!(shift_input(&u, -0.25), vec![1.25, 2.25, 3.25, 4.0]);
    }

    #[test]
    fn the_parabola_vertex_of_a_quadratic_is_exact() {
        let q = |x: f64| 3.0 * (x - 0.37).powi(2) + 1.0;
        let v = parabola_vertex(0.5, 0.25, (q(0.25), q(0.5), q(0.75)));
        assert!((v - 0.37).abs() < 1e-12, "{v}");
    }

    /// A second-order plant (resonance at 40 Hz, ζ = 0.1, and a pole at 15 Hz) logged at 1 kHz
    /// with its output shifted by a known fractional number of samples: the estimate is within
    /// 0.1 sample for lags and leads up to 2 samples; with no shift nothing is applied.
    #[test]
    fn recovers_leads_and_lags_within_a_tenth_of_a_sample() {
        let ts = 1e-3;
        let s = |f: f64, z: f64| {
            let w = 2.0 * std::f64::consts::PI * f;
            Complex64::new(-z * w, w * (1.0 - z * z).sqrt())
        };
        let sp = [
            s(40.0, 0.1),
            s(40.0, 0.1).conj(),
            Complex64::new(-2.0 * 3.14159 * 15.0, 0.0),
        ];
        let poles: Vec<Complex64> = sp.iter().map(|p| (p * ts).exp()).collect();
        let truth = {
            let mut m = ModalModel::from_poles(ts, &poles, false).unwrap();
            // Residues from a fit to a reference impulse-like response: any non-degenerate set.
            let mut rng = Rng::new(7);
            let u: Vec<f64> = (0..4096).map(|_| rng.normal()).collect();
            let y: Vec<f64> = {
                let mut y = vec![0.0; u.len()];
                let (mut y1, mut y2, mut x1) = (0.0, 0.0, 0.0);
                for (k, v) in u.iter().enumerate() {
                    // A stable reference filter with the same poles' flavour.
                    let yk = 1.8 * y1 - 0.86 * y2 + 0.05 * x1;
                    y[k] = yk;
                    y2 = y1;
                    y1 = yk;
                    x1 = *v;
                }
                y
            };
            let set = FitSet::new(vec![u], vec![y], 100).unwrap();
            m.fit_linear_params(&set).unwrap();
            m
        };
        let mut rng = Rng::new(11);
        let n = 6000;
        let inputs: Vec<Vec<f64>> = (0..2)
            .map(|_| {
                // Band-limited input: a moving average of white noise.
                let w: Vec<f64> = (0..n + 4).map(|_| rng.normal()).collect();
                (0..n)
                    .map(|k| w[k..k + 4].iter().sum::<f64>() / 4.0)
                    .collect()
            })
            .collect();
        for &a in &[-2.0, -1.0, -0.4, 0.0, 0.7, 1.5, 2.0] {
            let y: Vec<Vec<f64>> = inputs
                .iter()
                .map(|u| {
                    truth
                        .simulate(&shift_input(u, a))
                        .into_iter()
                        .map(|v| v + 1e-3 * rng.normal())
                        .collect()
                })
                .collect();
            let td = TrainData::new(ts, inputs.clone(), y, 100).unwrap();
            let est = estimate(&td, &poles, false).unwrap();
            if a == 0.0 {
                assert!(!est.applied || est.samples.abs() < 0.1, "{est:?}");
            } else {
                assert!(est.applied, "a = {a}: {est:?}");
                assert!((est.samples - a).abs() <= 0.1, "a = {a}: {est:?}");
            }
        }
    }
}
