//! The linear model of the diagnosis: the sim's poles in modal form (integrators kept), the
//! warm-up, period averaging of the training logs, and the output-error re-fit of the linear
//! part guarded by the nominal.
use super::fit::TrainData;
use super::modal::{FitSet, ModalModel};
use super::noise;
use super::simfile::is_integrator_pole;
use crate::error::{Error, Result};
use crate::lti::StateSpace;
use crate::n4sid::{n4sid_slices, N4sidOptions, OrderSelection};
use num_complex::Complex64;

/// Scored samples per log on which every start of the linear re-fit is refined before the best
/// one is refined on all the data.
pub const REFIT_SCREEN_SAMPLES: usize = 8192;

/// Continuous-equivalent of a discrete pole, s = ln(z)/ts (rad/s).
pub fn s_of(z: Complex64, ts: f64) -> Complex64 {
    z.ln() / ts
}

/// The poles of `sys` with every continuous-equivalent pole scaled by `alpha`.
fn scaled_poles(poles: &[Complex64], ts: f64, alpha: f64) -> Vec<Complex64> {
    poles
        .iter()
        .map(|&z| (s_of(z, ts) * alpha * ts).exp())
        .collect()
}

/// `start`'s poles with its real pole nearest z = 1 moved to exactly 1 when `sim` (the sim's
/// poles in modal form, [`modal_stand_in`]) has an integrator: the structure the re-fit keeps
/// (an integrator is fixed in every fit, and the place of friction follows from it), which a
/// stabilised N4SID start would otherwise replace by a slow stable pole.
fn with_integrator_of(start: &[Complex64], sim: &[Complex64]) -> Vec<Complex64> {
    let mut p = start.to_vec();
    if !sim.iter().any(|z| *z == Complex64::new(1.0, 0.0)) {
        return p;
    }
    let nearest = p
        .iter()
        .enumerate()
        .filter(|(_, z)| z.im.abs() <= 1e-9 * z.norm())
        .max_by(|a, b| a.1.re.total_cmp(&b.1.re))
        .map(|(i, _)| i);
    if let Some(i) = nearest {
        p[i] = Complex64::new(1.0, 0.0);
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn n4sid_start_gets_the_sims_integrator_only_when_the_sim_has_one() {
        let c = |re: f64, im: f64| Complex64::new(re, im);
        let start = [c(0.9, 0.1), c(0.9, -0.1), c(0.9977, 0.0), c(0.5, 0.0)];
        let sim = modal_stand_in(&[c(1.0 - 1e-12, 0.0), c(0.98, 0.0)]);
        let p = with_integrator_of(&start, &sim);
        assert_eq!(p[2], c(1.0, 0.0));
        assert_eq!([p[0], p[1], p[3]], [start[0], start[1], start[3]]);
        // No integrator in the sim: the start is left as it is.
        assert_eq!(with_integrator_of(&start, &[c(0.98, 0.0)]), start.to_vec());
        // Only complex poles: nothing to move.
        assert_eq!(with_integrator_of(&start[..2], &sim), start[..2].to_vec());
    }
}

/// Output-error re-fit of the linear part (see [`crate::gap`] docs): starts from the sim's
/// poles, after a scan of a common frequency scale factor 0.6..1.6, and from N4SID at the
/// sim's order on each training log; keeps the lowest training cost.
fn linear_refit(
    td: &TrainData,
    poles: &[Complex64],
    use_d: bool,
    nominal: Option<&ModalModel>,
    notes: &mut Vec<String>,
) -> Result<(ModalModel, f64)> {
    let ts = td.ts;
    let n = poles.len();
    let mut starts: Vec<(ModalModel, &'static str)> = Vec::new();
    // The nominal's own poles, unscaled (the scan below need not hit a factor of exactly 1).
    if let Some(m) = nominal {
        starts.push((m.clone(), "nominal"));
    }
    // Frequency-scale scan from the sim.
    let mut best_scan: Option<(ModalModel, f64)> = None;
    for i in 0..=20 {
        let alpha = 0.6 * (1.6f64 / 0.6).powf(i as f64 / 20.0);
        let Ok(mut m) = ModalModel::from_poles(ts, &scaled_poles(poles, ts, alpha), use_d) else {
            continue;
        };
        if let Some(c) = m.fit_linear_params(&td.base) {
            if best_scan.as_ref().is_none_or(|(_, b)| c < *b) {
                best_scan = Some((m, c));
            }
        }
    }
    if let Some((m, _)) = best_scan {
        starts.push((m, "sim poles"));
    }
    for (l, (u, y)) in td.u.iter().zip(&td.base.y).enumerate() {
        let opts = N4sidOptions {
            order: OrderSelection::Fixed(n.max(1)),
            estimate_d: use_d,
            estimate_kalman_gain: false,
            stability_margin: Some(1e-4),
            ..N4sidOptions::default()
        };
        match n4sid_slices(ts, &[u.as_slice()], &[y.as_slice()], &opts)
            .and_then(|r| r.model.poles())
            .map(|p| with_integrator_of(&p, poles))
            .and_then(|p| ModalModel::from_poles(ts, &p, use_d))
        {
            Ok(m) => starts.push((m, "n4sid")),
            Err(e) => notes.push(format!("N4SID start on training log {l} skipped: {e}")),
        }
    }
    // Every start is refined on the first REFIT_SCREEN_SAMPLES scored samples of each log;
    // the best is refined on all the data (the whole data when the logs are that short).
    let coarse = td.coarse(REFIT_SCREEN_SAMPLES);
    let mut best: Option<(ModalModel, f64)> = None;
    for (mut m, _) in starts {
        if let Some(c) = m.fit_output_error(&coarse.base, 60) {
            if best.as_ref().is_none_or(|(_, b)| c < *b) {
                best = Some((m, c));
            }
        }
    }
    let (mut m, c) = best.ok_or_else(|| {
        Error::Numerical("linear re-fit failed from every start (singular regressors)".into())
    })?;
    if coarse
        .base
        .y
        .iter()
        .zip(&td.base.y)
        .all(|(a, b)| a.len() == b.len())
    {
        return Ok((m, c));
    }
    let before = m.clone();
    match m.fit_output_error(&td.base, 60) {
        Some(c) => Ok((m, c)),
        None => {
            let c = before.cost(&td.base);
            Ok((before, c))
        }
    }
}

/// Period averaging of a training log for the fits: when the input repeats with period P
/// ([`noise::detect_period`]) and at least two whole periods follow the warm-up (rounded up to
/// whole periods, at least one period skipped when three or more exist), the input and output
/// are averaged over those periods and the average is repeated ⌈warm-up/P⌉ + 1 times, so the
/// fit sees the same periodic steady state after the same warm-up from rest, with the noise
/// divided by the number of periods and the cost cut by the same factor (standard practice in
/// periodic identification; a nonlinear plant's periodic steady state is kept exactly).
/// Returns (u, y, P, periods averaged), `None` for a non-periodic log.
pub fn period_average(
    u: &[f64],
    y: &[f64],
    warmup: usize,
) -> Option<(Vec<f64>, Vec<f64>, usize, usize)> {
    let p = noise::detect_period(u)?;
    let (skip, m) = noise::whole_periods(u.len(), p, warmup)?;
    let avg = |x: &[f64]| -> Vec<f64> {
        let mut a = vec![0.0; p];
        for q in skip..skip + m {
            for (v, s) in a.iter_mut().zip(&x[q * p..(q + 1) * p]) {
                *v += s / m as f64;
            }
        }
        a
    };
    let (ua, ya) = (avg(u), avg(y));
    let copies = warmup.div_ceil(p) + 1;
    let rep = |a: &[f64]| -> Vec<f64> { (0..copies).flat_map(|_| a.iter().copied()).collect() };
    // Only worth it when it shortens the log.
    if copies * p >= u.len() {
        return None;
    }
    Some((rep(&ua), rep(&ya), p, m))
}

/// Offset (output units) that best fits the training logs with `m`'s residues fixed: the
/// weighted mean of its residual.
fn mean_offset(td: &TrainData, m: &ModalModel) -> f64 {
    let mut zero = m.clone();
    zero.offset = 0.0;
    let (mut num, mut den) = (0.0, 0.0);
    for ((u, y), &w) in td.base.w.iter().zip(&td.base.y).zip(&td.base.weight) {
        let yh = zero.simulate(u);
        for (a, b) in y.iter().zip(&yh).skip(td.base.warmup) {
            num += w * (a - b);
            den += w;
        }
    }
    if den > 0.0 {
        num / den
    } else {
        0.0
    }
}

/// Stand-in for an integrator in the modal form, which needs |z| < 1: z = 1 − this (a time
/// constant of 10⁷ samples, far beyond any log).
pub const INTEGRATOR_STAND_IN: f64 = 1e-7;

/// The poles for the modal form: the first integrator (|z − 1| within
/// [`crate::gap::simfile::INTEGRATOR_TOL`]) exactly at z = 1 (the modal model keeps one exact
/// integrator), any further one at z = 1 − [`INTEGRATOR_STAND_IN`].
pub fn modal_stand_in(poles: &[Complex64]) -> Vec<Complex64> {
    let mut seen = false;
    poles
        .iter()
        .map(|&p| {
            if is_integrator_pole(p) {
                let z = if seen { 1.0 - INTEGRATOR_STAND_IN } else { 1.0 };
                seen = true;
                Complex64::new(z, 0.0)
            } else {
                p
            }
        })
        .collect()
}

/// Default warm-up: five time constants of the slowest *stable* pole (integrators do not decay
/// and are left out), at most a tenth of the shortest log.
pub fn default_warmup(poles: &[Complex64], shortest: usize) -> usize {
    let slowest = poles
        .iter()
        .filter(|p| !is_integrator_pole(**p) && p.norm() < 1.0)
        .map(|p| p.norm())
        .fold(0.0f64, f64::max);
    let tau = if slowest > 0.0 {
        -1.0 / slowest.ln()
    } else {
        0.0
    };
    ((5.0 * tau).ceil() as usize).min(shortest / 10)
}

/// The nominal sim in modal form: `poles` with the residues (and the feedthrough when `use_d`)
/// fitted to the sim's own noise-free response on the training inputs `fu` and the validation
/// input `vu` (no measured data), so the modal form reproduces the nominal where it is
/// compared. A start of the re-fit and of every candidate, and the fallback linear model;
/// `None` when that fit fails.
pub fn nominal_modal_form(
    sim: &StateSpace,
    ts: f64,
    poles: &[Complex64],
    use_d: bool,
    fu: &[Vec<f64>],
    vu: &[f64],
    warmup: usize,
) -> Option<ModalModel> {
    let mut nominal = ModalModel::from_poles(ts, poles, use_d).ok()?;
    let inputs: Vec<Vec<f64>> = fu.iter().cloned().chain([vu.to_vec()]).collect();
    let y_sim: Vec<Vec<f64>> = inputs
        .iter()
        .map(|u| sim.simulate_siso(u, None))
        .collect::<Result<_>>()
        .ok()?;
    let set = FitSet::new(inputs, y_sim, warmup).ok()?;
    nominal.fit_linear_params(&set)?;
    Some(nominal)
}

/// The linear model of the diagnosis ([`choose_linear`]).
#[derive(Debug, Clone)]
pub struct LinearChoice {
    /// The output-error re-fit.
    pub refit: ModalModel,
    /// Its validation NRMSE.
    pub gap_refit: f64,
    /// The linear model: the re-fit, or the nominal in modal form when the re-fit does worse
    /// than the nominal on validation.
    pub lin: ModalModel,
    /// Training cost of `lin` (Σ NRMSE², the fit set's metric).
    pub cost: f64,
    /// `refit` or `nominal` (`LinearReport::source`).
    pub source: &'static str,
}

/// The output-error re-fit ([`linear_refit`]) guarded by the nominal: when the re-fit's
/// validation NRMSE (`score` of its simulated validation output for input `vu`) is above the
/// nominal's `gap_before`, the linear model is the nominal in modal form with its offset set
/// on the training logs (its residues fixed) or as it is, whichever the training logs prefer;
/// as it is when the one with the offset is above the nominal on validation too.
#[allow(clippy::too_many_arguments)]
pub fn choose_linear(
    td: &TrainData,
    poles: &[Complex64],
    use_d: bool,
    nominal: Option<&ModalModel>,
    gap_before: f64,
    vu: &[f64],
    score: &dyn Fn(&[f64]) -> f64,
    notes: &mut Vec<String>,
) -> Result<LinearChoice> {
    let (refit, refit_cost) = linear_refit(td, poles, use_d, nominal, notes)?;
    let gap_refit = score(&refit.simulate(vu));
    Ok(match nominal {
        Some(nom) if gap_refit.is_nan() || gap_refit > gap_before => {
            let mut with_offset = nom.clone();
            with_offset.offset = mean_offset(td, nom);
            let (c0, c1) = (nom.cost(&td.base), with_offset.cost(&td.base));
            let mut pick = if c1 < c0 { with_offset } else { nom.clone() };
            let g = score(&pick.simulate(vu));
            if g.is_nan() || g > gap_before {
                pick = nom.clone();
            }
            notes.push(format!(
                "the output-error re-fit ({gap_refit:.4}) does worse than the nominal sim \
                 ({gap_before:.4}) on the validation log: the linear model is the nominal in \
                 modal form"
            ));
            let cost = pick.cost(&td.base);
            LinearChoice {
                refit,
                gap_refit,
                lin: pick,
                cost,
                source: "nominal",
            }
        }
        _ => LinearChoice {
            lin: refit.clone(),
            refit,
            gap_refit,
            cost: refit_cost,
            source: "refit",
        },
    })
}
