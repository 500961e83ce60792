//! The diagnosis itself: linear re-fit, candidate effects, ranking, verdict, shrink.
use super::effect::{Effect, EffectKind};
use super::fit::{fit_candidate, AugmentedModel, Fitted, TrainData};
use super::locate::{locate, Where};
use super::modal::{nrmse, FitSet, ModalModel};
use super::report::{BandError, EffectReport, GapReport, LinearReport, Settings};
use crate::data::Log;
use crate::error::{Error, Result};
use crate::lti::{StateSpace, StateSpaceData};
use crate::n4sid::{n4sid_slices, N4sidOptions, OrderSelection};
use num_complex::Complex64;
use std::path::PathBuf;

/// Fewest samples per log the diagnosis accepts.
pub const MIN_SAMPLES: usize = 512;

/// Default relative improvement over the linear re-fit that an effect must reach on the
/// validation log to become the verdict: (gap_linear − gap_effect)/gap_linear >= 0.10.
pub const DEFAULT_MARGIN: f64 = 0.10;

/// Default relative improvement a 2-parameter effect must add on the validation log over the
/// 1-parameter effect it contains (stiction over Coulomb friction) to rank above it.
pub const DEFAULT_NESTED_MARGIN: f64 = 0.03;

/// Likelihood-ratio threshold for the nested pair (stiction over Coulomb friction) when the
/// validation log cannot separate them: the χ² quantile with one degree of freedom (the extra
/// breakaway parameter) at p = 0.001. See [`nested_likelihood_ratio`].
pub const NESTED_LR_THRESHOLD: f64 = 10.83;

/// Longest lag of the residual autocorrelation used by [`effective_samples`], samples.
pub const MAX_CORRELATION_LAG: usize = 2000;

/// Effective number of independent samples of a residual sequence: N/τ with the integrated
/// autocorrelation time τ = 1 + 2·Σ ρ_k, summed over Geyer's initial positive sequence (pairs
/// ρ_{2m+1} + ρ_{2m+2} while positive, at most [`MAX_CORRELATION_LAG`] lags). White residuals
/// give about N; residuals dominated by slow model error give far fewer. At least 1.
pub fn effective_samples(r: &[f64]) -> f64 {
    let n = r.len();
    if n < 4 {
        return n.max(1) as f64;
    }
    let mean = r.iter().sum::<f64>() / n as f64;
    let d: Vec<f64> = r.iter().map(|v| v - mean).collect();
    let c0: f64 = d.iter().map(|v| v * v).sum();
    if c0.is_nan() || c0 <= 0.0 {
        return 1.0;
    }
    let rho = |k: usize| d.iter().zip(&d[k..]).map(|(a, b)| a * b).sum::<f64>() / c0;
    let mut tau = 1.0;
    let mut k = 1;
    while k + 1 < n.min(MAX_CORRELATION_LAG) {
        let pair = rho(k) + rho(k + 1);
        if pair.is_nan() || pair <= 0.0 {
            break;
        }
        tau += 2.0 * pair;
        k += 2;
    }
    (n as f64 / tau).max(1.0)
}

/// Likelihood-ratio statistic of the nested model `rich` over `simple` on the training logs,
/// Λ = Σ_logs N_eff · ln(SSE_simple / SSE_rich), with N_eff the [`effective_samples`] of the
/// simple model's residual on that log (Gaussian residuals, variance unknown; the effective
/// count keeps correlated model error from passing as evidence). Under the simple model Λ is
/// about χ² with one degree of freedom per extra parameter.
pub fn nested_likelihood_ratio(
    simple: &AugmentedModel,
    rich: &AugmentedModel,
    u: &[Vec<f64>],
    y: &[Vec<f64>],
    warmup: usize,
) -> Result<f64> {
    let mut lr = 0.0;
    for (ul, yl) in u.iter().zip(y) {
        let rs: Vec<f64> = yl
            .iter()
            .zip(&simple.simulate(ul)?)
            .skip(warmup)
            .map(|(a, b)| a - b)
            .collect();
        let rr: Vec<f64> = yl
            .iter()
            .zip(&rich.simulate(ul)?)
            .skip(warmup)
            .map(|(a, b)| a - b)
            .collect();
        let (ss, sr) = (
            rs.iter().map(|v| v * v).sum::<f64>(),
            rr.iter().map(|v| v * v).sum::<f64>(),
        );
        if ss > 0.0 && sr > 0.0 {
            lr += effective_samples(&rs) * (ss / sr).ln();
        }
    }
    Ok(if lr.is_finite() { lr } else { 0.0 })
}

/// Settings of [`diagnose`]. `Default` gives the documented defaults.
#[derive(Debug, Clone, PartialEq)]
pub struct GapOptions {
    /// Verdict margin (relative NRMSE improvement over the linear re-fit), default
    /// [`DEFAULT_MARGIN`].
    pub margin: f64,
    /// Parsimony margin for nested effects, default [`DEFAULT_NESTED_MARGIN`].
    pub nested_margin: f64,
    /// Multiplicative-error threshold for the "where" bands (default 0.2 = 20 %).
    pub threshold: f64,
    /// Magnitude-squared coherence below which a bin counts as a coherence drop and is not
    /// used for the multiplicative error (default 0.85, the project's gating default).
    pub coherence_min: f64,
    /// Median relative difference between the low- and high-amplitude frequency responses
    /// above which the gap is called amplitude dependent (default 0.1 = 10 %).
    pub amplitude_tol: f64,
    /// Samples at the start of every log left out of all errors; `None`: five time constants
    /// of the slowest sim pole, at most a tenth of the shortest log.
    pub warmup: Option<usize>,
    /// Welch segment length for the frequency analysis; `None`: the largest power of two
    /// <= N/8, between 64 and 4096.
    pub nperseg: Option<usize>,
    /// Candidate effects to fit (default: all eight).
    pub candidates: Vec<EffectKind>,
}

impl Default for GapOptions {
    fn default() -> Self {
        Self {
            margin: DEFAULT_MARGIN,
            nested_margin: DEFAULT_NESTED_MARGIN,
            threshold: 0.2,
            coherence_min: 0.85,
            amplitude_tol: 0.1,
            warmup: None,
            nperseg: None,
            candidates: EffectKind::ALL.to_vec(),
        }
    }
}

/// Everything [`diagnose`] produced: the report and the fitted models behind it.
#[derive(Debug, Clone)]
pub struct Diagnosis {
    /// The serialisable report.
    pub report: GapReport,
    /// The nominal sim, discrete at the logs' sample time.
    pub nominal: StateSpace,
    /// The linear re-fit.
    pub linear: AugmentedModel,
    /// Every fitted candidate, ranked best first (same order as `report.effects`).
    pub candidates: Vec<AugmentedModel>,
    /// Validation input and output.
    pub validation: (Vec<f64>, Vec<f64>),
    /// Warm-up samples used.
    pub warmup: usize,
}

impl Diagnosis {
    /// The model of the verdict (the linear re-fit when the verdict is `none`).
    pub fn verdict_model(&self) -> &AugmentedModel {
        if self.report.verdict == "none" {
            &self.linear
        } else {
            &self.candidates[0]
        }
    }
}

fn siso(log: &Log, role: &str) -> Result<(Vec<f64>, Vec<f64>)> {
    if log.inputs.len() != 1 || log.outputs.len() != 1 {
        return Err(Error::Data {
            file: log.path.clone(),
            msg: format!(
                "{role} log has {} input and {} output channel(s); the gap diagnosis is SISO",
                log.inputs.len(),
                log.outputs.len()
            ),
        });
    }
    let (u, y) = (log.u(), log.y());
    if u.len() != y.len() {
        return Err(Error::Data {
            file: log.path.clone(),
            msg: format!("input has {} samples, output {}", u.len(), y.len()),
        });
    }
    if u.len() < MIN_SAMPLES {
        return Err(Error::Data {
            file: log.path.clone(),
            msg: format!(
                "{role} log is too short for the gap diagnosis: {} samples, at least \
                 {MIN_SAMPLES} needed",
                u.len()
            ),
        });
    }
    if let Some(k) = u.iter().chain(y).position(|v| !v.is_finite()) {
        return Err(Error::Data {
            file: log.path.clone(),
            msg: format!("non-finite sample at index {}", k % u.len()),
        });
    }
    Ok((u.to_vec(), y.to_vec()))
}

/// Continuous-equivalent of a discrete pole, s = ln(z)/ts (rad/s).
fn s_of(z: Complex64, ts: f64) -> Complex64 {
    z.ln() / ts
}

/// The poles of `sys` with every continuous-equivalent pole scaled by `alpha`.
fn scaled_poles(poles: &[Complex64], ts: f64, alpha: f64) -> Vec<Complex64> {
    poles
        .iter()
        .map(|&z| (s_of(z, ts) * alpha * ts).exp())
        .collect()
}

/// Output-error re-fit of the linear part (see [`crate::gap`] docs): starts from the sim's
/// poles, after a scan of a common frequency scale factor 0.6..1.6, and from N4SID at the
/// sim's order on each training log; keeps the lowest training cost.
fn linear_refit(
    td: &TrainData,
    sim: &StateSpace,
    notes: &mut Vec<String>,
) -> Result<(ModalModel, f64)> {
    let ts = td.ts;
    let use_d = sim.d[(0, 0)] != 0.0;
    let poles = sim.poles()?;
    let n = poles.len();
    let mut starts: Vec<(ModalModel, &'static str)> = Vec::new();
    // Frequency-scale scan from the sim.
    let mut best_scan: Option<(ModalModel, f64)> = None;
    for i in 0..=20 {
        let alpha = 0.6 * (1.6f64 / 0.6).powf(i as f64 / 20.0);
        let Ok(mut m) = ModalModel::from_poles(ts, &scaled_poles(&poles, ts, alpha), use_d) else {
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
            .and_then(|p| ModalModel::from_poles(ts, &p, use_d))
        {
            Ok(m) => starts.push((m, "n4sid")),
            Err(e) => notes.push(format!("N4SID start on training log {l} skipped: {e}")),
        }
    }
    let mut best: Option<(ModalModel, f64)> = None;
    for (mut m, _) in starts {
        if let Some(c) = m.fit_output_error(&td.base, 60) {
            if best.as_ref().is_none_or(|(_, b)| c < *b) {
                best = Some((m, c));
            }
        }
    }
    best.ok_or_else(|| {
        Error::Numerical("linear re-fit failed from every start (singular regressors)".into())
    })
}

/// Runs the gap diagnosis of the discrete nominal model `sim` (SISO, sample time equal to the
/// logs', see [`crate::gap::simfile::discretise_for_logs`]) against the training logs `train`
/// (typically low and high amplitude) and the validation log `validate`.
///
/// Errors ([`Error::Data`] naming the log) for non-SISO logs, logs shorter than
/// [`MIN_SAMPLES`], sample times that differ between logs or from the sim, non-finite samples;
/// [`Error::InvalidArgument`] for no training log; [`Error::Numerical`] when even the linear
/// re-fit fails.
pub fn diagnose(
    sim: &StateSpace,
    train: &[Log],
    validate: &Log,
    opts: &GapOptions,
) -> Result<Diagnosis> {
    if train.is_empty() {
        return Err(Error::InvalidArgument(
            "the gap diagnosis needs at least one training log (--real)".into(),
        ));
    }
    let ts = validate.ts;
    for log in train.iter().chain(std::iter::once(validate)) {
        if (log.ts - ts).abs() > 1e-9 * ts {
            return Err(Error::Data {
                file: log.path.clone(),
                msg: format!(
                    "sample time {} s differs from the validation log's {} s",
                    log.ts, ts
                ),
            });
        }
    }
    if !sim.is_discrete() || (sim.ts - ts).abs() > 1e-9 * ts || !sim.is_siso() {
        return Err(Error::InvalidArgument(format!(
            "diagnose needs the sim as a SISO discrete model at the logs' ts = {ts} s (got {}x{}, \
             ts = {} s); use discretise_for_logs",
            sim.n_outputs(),
            sim.n_inputs(),
            sim.ts
        )));
    }
    let mut tu = Vec::new();
    let mut ty = Vec::new();
    for log in train {
        let (u, y) = siso(log, "training")?;
        tu.push(u);
        ty.push(y);
    }
    let (vu, vy) = siso(validate, "validation")?;
    let shortest = tu.iter().map(Vec::len).chain([vu.len()]).min().unwrap_or(0);
    let poles = sim.poles()?;
    let warmup = opts.warmup.unwrap_or_else(|| {
        let slowest = poles.iter().map(|p| p.norm()).fold(0.0f64, f64::max);
        let tau = if slowest > 0.0 {
            -1.0 / slowest.ln()
        } else {
            0.0
        };
        ((5.0 * tau).ceil() as usize).min(shortest / 10)
    });
    if warmup >= shortest / 2 {
        return Err(Error::InvalidArgument(format!(
            "warm-up of {warmup} samples leaves too little of the shortest log ({shortest})"
        )));
    }
    let mut notes = Vec::new();
    let td = TrainData::new(ts, tu.clone(), ty.clone(), warmup)?;

    // HOW FAR (before): the nominal sim on the validation log.
    let y_nom = sim.simulate_siso(&vu, None)?;
    let gap_before = nrmse(&vy, &y_nom, warmup);

    // Linear re-fit.
    let t0 = std::time::Instant::now();
    let (lin, lin_cost) = linear_refit(&td, sim, &mut notes)?;
    if std::env::var_os("GAP_PROFILE").is_some() {
        eprintln!("profile: linear refit {:.3} s", t0.elapsed().as_secs_f64());
    }
    let linear = AugmentedModel::linear(lin.clone());
    let gap_linear = nrmse(&vy, &linear.simulate(&vu)?, warmup);

    // WHICH: every candidate, from the linear re-fit and from the nominal sim in modal form
    // (residues fitted to the sim's own noise-free response on the training inputs).
    let mut starts = vec![lin.clone()];
    if let Ok(mut nominal) = ModalModel::from_poles(ts, &poles, lin.use_d) {
        let y_sim: Vec<Vec<f64>> = tu
            .iter()
            .map(|u| sim.simulate_siso(u, None))
            .collect::<Result<_>>()?;
        if let Ok(set) = FitSet::new(tu.clone(), y_sim, warmup) {
            if nominal.fit_linear_params(&set).is_some() {
                nominal.offset = lin.offset;
                starts.push(nominal);
            }
        }
    }
    let mut fitted: Vec<Fitted> = Vec::new();
    let mut coulomb: Option<Fitted> = None;
    let mut kinds = opts.candidates.clone();
    kinds.sort();
    kinds.dedup();
    for &kind in &kinds {
        let hint = if kind == EffectKind::Stiction {
            coulomb
                .clone()
                .or_else(|| fit_candidate(EffectKind::CoulombFriction, &td, &starts, None, &poles))
        } else {
            None
        };
        let t0 = std::time::Instant::now();
        let fc = fit_candidate(kind, &td, &starts, hint.as_ref(), &poles);
        if std::env::var_os("GAP_PROFILE").is_some() {
            eprintln!("profile: {kind} {:.3} s", t0.elapsed().as_secs_f64());
        }
        match fc {
            Some(f) => {
                if kind == EffectKind::CoulombFriction {
                    coulomb = Some(f.clone());
                }
                fitted.push(f);
            }
            None => notes.push(format!(
                "{kind}: no fit ({})",
                if kind == EffectKind::Quantization {
                    "the measured outputs do not sit on a lattice"
                } else {
                    "every trial model failed"
                }
            )),
        }
    }
    let mut scored: Vec<(Fitted, f64)> = Vec::new();
    for f in fitted {
        let g = nrmse(&vy, &f.model.simulate(&vu)?, warmup);
        scored.push((f, if g.is_finite() { g } else { f64::INFINITY }));
    }
    scored.sort_by(|a, b| a.1.total_cmp(&b.1));
    // Nested pair: stiction contains Coulomb friction (breakaway = level). Stiction is
    // preferred only if it lowers the validation NRMSE by the nested margin, or — when the
    // validation log cannot tell them apart (within that margin; a stuck mass needs
    // low-amplitude excitation) — if its training-log likelihood ratio over Coulomb friction
    // exceeds NESTED_LR_THRESHOLD.
    let pos = |k: EffectKind, s: &[(Fitted, f64)]| {
        s.iter()
            .position(|(f, _)| f.model.effect.map(|e| e.kind()) == Some(k))
    };
    if let (Some(is), Some(ic)) = (
        pos(EffectKind::Stiction, &scored),
        pos(EffectKind::CoulombFriction, &scored),
    ) {
        let (gs, gc) = (scored[is].1, scored[ic].1);
        let lr =
            nested_likelihood_ratio(&scored[ic].0.model, &scored[is].0.model, &tu, &ty, warmup)?;
        notes.push(format!(
            "stiction vs coulomb_friction: training likelihood ratio {lr:.1} (threshold \
             {NESTED_LR_THRESHOLD}), validation NRMSE {gs:.4} vs {gc:.4}"
        ));
        let stiction_wins = gs < gc * (1.0 - opts.nested_margin)
            || (gs <= gc * (1.0 + opts.nested_margin) && lr > NESTED_LR_THRESHOLD);
        if stiction_wins != (is < ic) {
            scored.swap(is, ic);
        }
    }
    let best_gap = scored.first().map_or(f64::INFINITY, |s| s.1);
    let improvement = |g: f64| (gap_linear - g) / gap_linear;
    let verdict = match scored.first() {
        Some((f, g)) if improvement(*g) >= opts.margin => f
            .model
            .effect
            .map_or("none".to_string(), |e| e.kind().name().to_string()),
        _ => "none".to_string(),
    };
    let gap_after = if verdict == "none" {
        gap_linear
    } else {
        best_gap
    };

    let effects: Vec<EffectReport> = scored
        .iter()
        .filter_map(|(f, g)| {
            let e: Effect = f.model.effect?;
            Some(EffectReport {
                effect: e.kind().name().to_string(),
                params: e
                    .params()
                    .into_iter()
                    .map(|(k, v)| (k.to_string(), v))
                    .collect(),
                gap_after: *g,
                improvement: improvement(*g),
                train_nrmse: (f.train_cost / td.u.len() as f64).sqrt(),
                velocity_from: matches!(
                    e,
                    Effect::CoulombFriction { .. } | Effect::Stiction { .. }
                )
                .then(|| f.model.velocity.name().to_string()),
            })
        })
        .collect();
    let candidates: Vec<AugmentedModel> = scored.into_iter().map(|(f, _)| f.model).collect();
    let best_model = if verdict == "none" {
        &linear
    } else {
        &candidates[0]
    };

    // WHERE, and the frequency-domain error in the worst band.
    let train_resid_lin: Vec<Vec<f64>> = tu
        .iter()
        .zip(&ty)
        .map(|(u, y)| {
            let yh = linear.simulate(u)?;
            Ok(y.iter().zip(&yh).map(|(a, b)| a - b).collect())
        })
        .collect::<Result<_>>()?;
    let y_lin_train: Vec<Vec<f64>> = tu
        .iter()
        .map(|u| linear.simulate(u))
        .collect::<Result<_>>()?;
    let where_: Where = locate(
        sim,
        &tu,
        &ty,
        &y_lin_train,
        &train_resid_lin,
        warmup,
        ts,
        opts,
        &train
            .iter()
            .map(|l| l.path.clone())
            .collect::<Vec<PathBuf>>(),
    )?;
    let y_lin_val = linear.simulate(&vu)?;
    let y_best_val = best_model.simulate(&vu)?;
    let band_error = BandError::compute(
        where_.worst_band_hz,
        &vy,
        &[&y_nom, &y_lin_val, &y_best_val],
        warmup,
        ts,
        where_.nperseg,
    )?;

    let lin_ss = lin.to_state_space()?;
    let report = GapReport {
        verdict,
        where_,
        gap_before,
        gap_linear,
        gap_after,
        band_error,
        effects,
        linear: LinearReport {
            model: StateSpaceData::from(&lin_ss),
            offset: lin.offset,
            poles_hz: lin
                .poles()
                .iter()
                .filter(|p| p.im >= 0.0)
                .map(|&z| {
                    let s = s_of(z, ts);
                    let wn = s.norm();
                    (
                        wn / (2.0 * std::f64::consts::PI),
                        if wn > 0.0 { -s.re / wn } else { 1.0 },
                    )
                })
                .collect(),
            train_nrmse: (lin_cost / td.u.len() as f64).sqrt(),
        },
        settings: Settings {
            ts,
            warmup_samples: warmup,
            margin: opts.margin,
            nested_margin: opts.nested_margin,
            threshold: opts.threshold,
            coherence_min: opts.coherence_min,
            amplitude_tol: opts.amplitude_tol,
        },
        notes,
    };
    Ok(Diagnosis {
        report,
        nominal: sim.clone(),
        linear,
        candidates,
        validation: (vu, vy),
        warmup,
    })
}

/// NRMSE of a model on one log's samples (helper for callers and tests).
pub fn model_nrmse(model: &AugmentedModel, u: &[f64], y: &[f64], warmup: usize) -> Result<f64> {
    Ok(nrmse(y, &model.simulate(u)?, warmup))
}

/// The training cost helper re-exported for benchmarks: Σ NRMSE² of `model` over logs.
pub fn train_cost(
    model: &AugmentedModel,
    u: &[Vec<f64>],
    y: &[Vec<f64>],
    warmup: usize,
) -> Result<f64> {
    let set = FitSet::new(u.to_vec(), y.to_vec(), warmup)?;
    Ok(model.cost(&set, u))
}
