//! The added mode (`resonance`): its frequency grid from the residual spectrum, and the
//! labelling that keeps the linear part closest to the nominal sim.
use super::eval::{eval_fixed_poles, log_grid, Fitted, TrainData};
use super::joint::refined;
use super::model::{AugmentedModel, VelocitySource};
use super::{
    resonance_range_hz, COARSE_SAMPLES, JOINT_MAX_ITER, MAX_RESONANCE_DAMPING,
    MIN_RESONANCE_DAMPING,
};
use crate::gap::effect::Effect;
use crate::gap::modal::ModalModel;
use num_complex::Complex64;

/// Largest relative training-cost increase at which a relabelled resonance model counts as
/// fitting the data equally well (see [`relabel_resonance`]).
pub const RELABEL_COST_TOL: f64 = 0.10;

/// Continuous-equivalent (rad/s) of the discrete pole r·e^{jφ} at sample time `ts`.
pub(super) fn pair_to_s(r: f64, phi: f64, ts: f64) -> Complex64 {
    Complex64::new(r.ln(), phi) / ts
}

/// Natural frequency (Hz) and damping ratio of a continuous pole.
pub(super) fn freq_damping(s: Complex64) -> (f64, f64) {
    let wn = s.norm();
    (
        wn / (2.0 * std::f64::consts::PI),
        if wn > 0.0 { -s.re / wn } else { 1.0 },
    )
}

/// Σ over the linear part's poles of the relative distance |s − s_sim|/|s_sim| to the nearest
/// pole of the nominal sim (continuous equivalents).
pub(super) fn distance_to_sim(lin: &ModalModel, sim_s: &[Complex64]) -> f64 {
    lin.poles()
        .iter()
        .map(|&z| {
            let s = z.ln() / lin.ts;
            sim_s
                .iter()
                .map(|&q| (s - q).norm() / q.norm().max(1e-300))
                .fold(f64::INFINITY, f64::min)
        })
        .sum()
}

/// An added mode in series and a mode of the linear part can swap roles with the same
/// input-output behaviour (the residues absorb the difference), so the data alone cannot say
/// which mode is the unmodelled one. Among the labellings that fit the training data within
/// [`RELABEL_COST_TOL`] of the fitted one, this keeps the one whose linear part is closest to
/// the nominal sim's poles (`sim_poles`, discrete at the logs' sample time): the added mode is
/// the one the sim does not have.
pub(super) fn relabel_resonance(td: &TrainData, fitted: Fitted, sim_poles: &[Complex64]) -> Fitted {
    let Some(Effect::Resonance { freq_hz, damping }) = fitted.model.effect else {
        return fitted;
    };
    let sim_s: Vec<Complex64> = sim_poles
        .iter()
        .filter(|z| z.norm() > 0.0)
        .map(|&z| z.ln() / td.ts)
        .collect();
    if sim_s.is_empty() {
        return fitted;
    }
    let lin = &fitted.model.linear;
    let (flo, fhi) = resonance_range_hz(td.ts);
    let w = 2.0 * std::f64::consts::PI * freq_hz;
    let s_eff = Complex64::new(-damping * w, w * (1.0 - damping * damping).max(0.0).sqrt());
    let z_eff = (s_eff * td.ts).exp();
    let mut best_d = distance_to_sim(lin, &sim_s);
    let mut best = fitted.clone();
    for (i, &(r, phi)) in lin.pairs.iter().enumerate() {
        let (f, z) = freq_damping(pair_to_s(r, phi, td.ts));
        if !(flo..=fhi).contains(&f)
            || !(MIN_RESONANCE_DAMPING..=MAX_RESONANCE_DAMPING).contains(&z)
        {
            continue;
        }
        let mut swapped = lin.clone();
        swapped.pairs[i] = (z_eff.norm(), z_eff.im.atan2(z_eff.re));
        let effect = Effect::Resonance {
            freq_hz: f,
            damping: z,
        };
        let Some(start) = eval_fixed_poles(td, &swapped, effect, VelocitySource::Output) else {
            continue;
        };
        let cand = refined(td, start, JOINT_MAX_ITER);
        if cand.train_cost > fitted.train_cost * (1.0 + RELABEL_COST_TOL) {
            continue;
        }
        let d = distance_to_sim(&cand.model.linear, &sim_s);
        if d < best_d {
            best_d = d;
            best = cand;
        }
    }
    best
}

/// Resonance frequencies (Hz) to search: a log grid over [`resonance_range_hz`] at about 12 %
/// spacing plus a 2.5 % grid around the strongest peaks of the base model's residual spectrum
/// (a lightly damped mode is only found near its frequency).
pub(super) fn resonance_grid_hz(td: &TrainData, base: &AugmentedModel) -> Vec<f64> {
    let (flo, fhi) = resonance_range_hz(td.ts);
    let n = ((fhi / flo).ln() / 0.12).ceil() as usize + 1;
    let mut f = log_grid(flo, fhi, n);
    for peak in residual_peaks_hz(td, base, 3) {
        for i in -4i32..=4 {
            let v = peak * (0.025 * i as f64).exp();
            if (flo..=fhi).contains(&v) {
                f.push(v);
            }
        }
    }
    f.sort_by(f64::total_cmp);
    f
}

/// The `k` frequencies (Hz) where the residual of `base` on the training logs has the largest
/// power relative to the output's, from a DFT at 4 % log spacing over the resonance range.
pub(super) fn residual_peaks_hz(td: &TrainData, base: &AugmentedModel, k: usize) -> Vec<f64> {
    let (flo, fhi) = resonance_range_hz(td.ts);
    let n = ((fhi / flo).ln() / 0.04).ceil() as usize + 1;
    let freqs = log_grid(flo.max(2.0 / (td.ts * COARSE_SAMPLES as f64)), fhi, n);
    let mut score = vec![0.0; freqs.len()];
    for (u, y) in td.u.iter().zip(&td.base.y) {
        let Ok(yh) = base.simulate(u) else {
            return Vec::new();
        };
        let w0 = td.base.warmup;
        let r: Vec<f64> = y.iter().zip(&yh).skip(w0).map(|(a, b)| a - b).collect();
        let yy: Vec<f64> = y[w0..].to_vec();
        let hann = hann_window(r.len());
        for (i, &f) in freqs.iter().enumerate() {
            let pr = dft_power(&r, &hann, f * td.ts);
            let py = dft_power(&yy, &hann, f * td.ts);
            if py > 0.0 {
                score[i] += pr / py;
            }
        }
    }
    let mut idx: Vec<usize> = (0..freqs.len()).collect();
    idx.sort_by(|&a, &b| score[b].total_cmp(&score[a]));
    let mut out: Vec<f64> = Vec::new();
    for i in idx {
        if out.len() >= k {
            break;
        }
        if out.iter().all(|&o| (freqs[i] / o).ln().abs() > 0.1) {
            out.push(freqs[i]);
        }
    }
    out
}

/// The Hann window of [`dft_power`] for a signal of `n` samples: its value at every
/// `(n / 8192).max(1)`-th sample (the samples the DFT uses).
pub(super) fn hann_window(n: usize) -> Vec<f64> {
    let step = (n / 8192).max(1);
    (0..n / step)
        .map(|i| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * (i * step) as f64 / n as f64).cos())
        .collect()
}

/// |Σ x_t e^{−j2πνt}|² with a Hann window over a band of ±2 % of ν (cycles per sample),
/// averaged over 5 frequencies so a line between grid points is not missed. `hann`: the
/// window from [`hann_window`] for `x.len()` samples.
pub(super) fn dft_power(x: &[f64], hann: &[f64], nu: f64) -> f64 {
    let n = x.len();
    if n < 2 {
        return 0.0;
    }
    let step = (n / 8192).max(1);
    let mut acc = 0.0;
    for j in -2i32..=2 {
        let f = nu * (1.0 + 0.01 * j as f64);
        let (mut re, mut im) = (0.0, 0.0);
        let w = 2.0 * std::f64::consts::PI * f;
        let (s, c) = w.sin_cos();
        let (mut cr, mut ci) = (1.0f64, 0.0f64);
        // Every `step`-th sample enters the sum; the rotation advances at every sample.
        for (chunk, &hw) in x[..step * (n / step)].chunks_exact(step).zip(hann) {
            let v = chunk[0];
            re += hw * v * cr;
            im -= hw * v * ci;
            for _ in 0..step {
                let nr = cr * c - ci * s;
                ci = cr * s + ci * c;
                cr = nr;
            }
        }
        acc += re * re + im * im;
    }
    acc
}
