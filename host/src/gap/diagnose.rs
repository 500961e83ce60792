//! The diagnosis itself: linear re-fit, candidate effects, ranking, verdict, shrink.
use super::drift::validation_nrmse;
use super::effect::{Effect, EffectKind};
use super::evidence::{self, Evidence};
use super::fit::{AugmentedModel, TrainData};
use super::locate::{locate, Where};
use super::modal::{nrmse, FitSet, ModalModel};
use super::noise::{self, NoiseFloor};
use super::place::Candidate;
use super::report::{BandError, EffectReport, GapReport, LinearReport, Settings, VerdictEffect};
use super::select::{default_candidates, select_effects, Scored, SelectOptions};
use super::simfile::is_integrator_pole;
use super::structure::TwoMassStructure;
use crate::data::Log;
use crate::error::{Error, Result};
use crate::lti::{StateSpace, StateSpaceData};
use crate::n4sid::{n4sid_slices, N4sidOptions, OrderSelection};
use num_complex::Complex64;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Fewest samples per log the diagnosis accepts.
pub const MIN_SAMPLES: usize = 512;

/// Default relative improvement over the linear re-fit that an effect must reach on the
/// validation log to become the verdict: (gap_linear − gap_effect)/gap_linear >= 0.10.
pub const DEFAULT_MARGIN: f64 = 0.10;

/// Default relative improvement a 2-parameter effect must add on the validation log over the
/// 1-parameter effect it contains (stiction over Coulomb friction) to rank above it.
pub const DEFAULT_NESTED_MARGIN: f64 = 0.03;

/// Default noise factor: the verdict is `none` only when the linear re-fit's validation NRMSE
/// is at most this multiple of the noise floor (see [`VerdictRule`]).
pub const DEFAULT_NOISE_FACTOR: f64 = 2.0;

/// Default share of the linear re-fit's excess over the noise floor, gap_linear − floor, that
/// an effect must remove to be the verdict (see [`VerdictRule`]).
pub const DEFAULT_MIN_EXCESS_CLOSED: f64 = 0.5;

/// What the verdict rule decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// The best candidate (or combination) is the verdict.
    Effect,
    /// The linear re-fit reaches the noise floor: no unmodelled effect.
    None,
    /// A gap above the noise floor that no candidate closes.
    Unexplained,
}

/// The verdict rule (docs/gap.md, "Verdict"). With `floor` the noise-floor NRMSE on the
/// validation log and `best` the best candidate's validation NRMSE:
/// 1. **effect** when the candidate improves on the linear re-fit by at least `margin`
///    (relative) *and* removes at least `min_excess_closed` of the excess
///    gap_linear − floor (floor taken as 0 when it could not be estimated);
/// 2. else **none** when gap_linear ≤ `noise_factor`·floor;
/// 3. else, when the floor could not be estimated, **none** unless the evidence shows a
///    nonlinearity (amplitude dependence, nonlinear distortion, residual concentration);
/// 4. else **unexplained**.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VerdictRule {
    /// Relative improvement over the linear re-fit an effect needs.
    pub margin: f64,
    /// gap_linear ≤ noise_factor·floor means "at the noise floor".
    pub noise_factor: f64,
    /// Share of the excess above the floor an effect must remove.
    pub min_excess_closed: f64,
}

impl VerdictRule {
    /// Decides (see the type docs). `has_candidate`: whether `best` belongs to a fitted effect.
    pub fn decide(
        &self,
        gap_linear: f64,
        best: f64,
        has_candidate: bool,
        floor: &NoiseFloor,
        evidence: &Evidence,
    ) -> Decision {
        let f = if floor.available() { floor.nrmse } else { 0.0 };
        if has_candidate
            && best.is_finite()
            && (gap_linear - best) >= self.margin * gap_linear
            && (gap_linear - best) >= self.min_excess_closed * (gap_linear - f)
        {
            return Decision::Effect;
        }
        if floor.available() {
            if gap_linear <= self.noise_factor * floor.nrmse {
                Decision::None
            } else {
                Decision::Unexplained
            }
        } else if evidence.nonlinear() {
            Decision::Unexplained
        } else {
            Decision::None
        }
    }

    /// A one-line reason for notes (why not an effect, why none/unexplained).
    pub fn explain(
        &self,
        gap_linear: f64,
        best: f64,
        floor: &NoiseFloor,
        d: Decision,
    ) -> Option<String> {
        let fl = floor.nrmse;
        match d {
            Decision::Effect => None,
            Decision::None if floor.available() => Some(format!(
                "verdict none: the linear re-fit ({gap_linear:.4}) is within {}x the noise floor \
                 ({fl:.4}, {})",
                self.noise_factor, floor.method
            )),
            Decision::None => Some(format!(
                "verdict none: no noise floor could be estimated (no repeating input, no \
                 off-band bins) and no evidence of a nonlinearity; the linear re-fit leaves \
                 {gap_linear:.4}"
            )),
            Decision::Unexplained => Some(format!(
                "verdict unexplained: the linear re-fit leaves {gap_linear:.4}{}, and the best \
                 candidate ({best:.4}) does not improve on it by {:.0}% while removing {:.0}% of \
                 the excess over the floor",
                if floor.available() {
                    format!(" against a noise floor of {fl:.4}")
                } else {
                    String::new()
                },
                100.0 * self.margin,
                100.0 * self.min_excess_closed
            )),
        }
    }
}

/// Likelihood-ratio threshold for the nested pair (stiction over Coulomb friction) when the
/// validation log cannot separate them: the χ² quantile with one degree of freedom (the extra
/// breakaway parameter) at p = 0.001. See [`nested_likelihood_ratio`].
pub const NESTED_LR_THRESHOLD: f64 = 10.83;

/// Scored samples per log on which every start of the linear re-fit is refined before the best
/// one is refined on all the data.
pub const REFIT_SCREEN_SAMPLES: usize = 8192;

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
    // The richer model nests the simpler one, so at its optimum the statistic is >= 0; a
    // negative value means its fit stopped short of the simpler one's: no evidence (0).
    Ok(if lr.is_finite() { lr.max(0.0) } else { 0.0 })
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
    /// Noise factor of the verdict rule, default [`DEFAULT_NOISE_FACTOR`].
    pub noise_factor: f64,
    /// Share of the excess over the noise floor an effect must remove, default
    /// [`DEFAULT_MIN_EXCESS_CLOSED`].
    pub min_excess_closed: f64,
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
            noise_factor: DEFAULT_NOISE_FACTOR,
            min_excess_closed: DEFAULT_MIN_EXCESS_CLOSED,
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
    /// The linear model (the output-error re-fit, or the nominal in modal form when the re-fit
    /// does worse than the nominal on the validation log; `report.linear.source`).
    pub linear: AugmentedModel,
    /// The model of the verdict (the linear model when the verdict is `none` or
    /// `unexplained`).
    pub verdict_model: AugmentedModel,
    /// Every fitted candidate, ranked best first (same order as `report.effects`).
    pub candidates: Vec<AugmentedModel>,
    /// Validation input and output.
    pub validation: (Vec<f64>, Vec<f64>),
    /// Warm-up samples used.
    pub warmup: usize,
}

impl Diagnosis {
    /// The model of the verdict (the linear model when the verdict is `none` or
    /// `unexplained`).
    pub fn verdict_model(&self) -> &AugmentedModel {
        &self.verdict_model
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
    for (sig, what) in [(u, "input"), (y, "output")] {
        if sig.iter().all(|&v| v == sig[0]) {
            return Err(Error::Data {
                file: log.path.clone(),
                msg: format!(
                    "{role} log's {what} is constant (every sample equals {}): there is no \
                     response to compare (NRMSE undefined)",
                    sig[0]
                ),
            });
        }
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
    if let Some(msg) = super::simfile::zero_response(sim) {
        return Err(Error::InvalidArgument(msg));
    }
    let shortest = tu.iter().map(Vec::len).chain([vu.len()]).min().unwrap_or(0);
    let sim_poles = sim.poles()?;
    if let Some(p) = sim_poles
        .iter()
        .find(|p| p.norm() >= 1.0 - 1e-9 && !is_integrator_pole(**p))
    {
        return Err(Error::InvalidArgument(format!(
            "the sim has a pole on or outside the unit circle other than an integrator: z = {p:.6}"
        )));
    }
    let poles = modal_stand_in(&sim_poles);
    let warmup = opts
        .warmup
        .unwrap_or_else(|| default_warmup(&sim_poles, shortest));
    if warmup >= shortest / 2 {
        return Err(Error::InvalidArgument(format!(
            "warm-up of {warmup} samples leaves too little of the shortest log ({shortest})"
        )));
    }
    let mut notes = Vec::new();
    if sim_poles.iter().any(|p| is_integrator_pole(*p)) {
        notes.push(format!(
            "the sim has an integrator (pole at z = 1): kept exactly in its modal form (a second \
             one at z = 1 − {INTEGRATOR_STAND_IN:e}); the warm-up follows the slowest stable pole"
        ));
    }
    // Fitting data: periodic training logs averaged over their periods (module docs of
    // `period_average`); the raw logs serve everything else.
    let mut fu = Vec::with_capacity(tu.len());
    let mut fy = Vec::with_capacity(tu.len());
    for (log, (u, y)) in train.iter().zip(tu.iter().zip(&ty)) {
        match period_average(u, y, warmup) {
            Some((ua, ya, p, m)) => {
                notes.push(format!(
                    "{}: input repeats every {p} samples; the fits use the average of {m} \
                     periods (repeated to cover the warm-up)",
                    log.path.display()
                ));
                fu.push(ua);
                fy.push(ya);
            }
            None => {
                fu.push(u.clone());
                fy.push(y.clone());
            }
        }
    }
    // With an integrator, every fit and validation score leaves the free run's drift out
    // (modal::nrmse_drift_free over the warm-up).
    let drift_window = sim_poles
        .iter()
        .any(|p| is_integrator_pole(*p))
        .then_some(warmup);
    let mut td = TrainData::new(ts, fu.clone(), fy, warmup)?;
    td.base.drift_window = drift_window;
    let profile = std::env::var_os("GAP_PROFILE").is_some();
    let t_start = std::time::Instant::now();

    // HOW FAR (before): the nominal sim on the validation log (with an integrator, the
    // free run's drift left out).
    let vnrmse = |y: &[f64], yh: &[f64]| validation_nrmse(y, yh, warmup, drift_window);
    let y_nom = sim.simulate_siso(&vu, None)?;
    let gap_before = vnrmse(&vy, &y_nom);

    // The nominal sim in modal form (residues fitted to its own noise-free response on the
    // training inputs): a start of the re-fit and of every candidate, and the fallback linear
    // model.
    let use_d = sim.d[(0, 0)] != 0.0;
    let nominal_modal: Option<ModalModel> = (|| {
        let mut nominal = ModalModel::from_poles(ts, &poles, use_d).ok()?;
        // The sim's own response (no measured data) on the training inputs and on the
        // validation input, so the modal form reproduces the nominal where it is compared.
        let inputs: Vec<Vec<f64>> = fu.iter().cloned().chain([vu.clone()]).collect();
        let y_sim: Vec<Vec<f64>> = inputs
            .iter()
            .map(|u| sim.simulate_siso(u, None))
            .collect::<Result<_>>()
            .ok()?;
        let set = FitSet::new(inputs, y_sim, warmup).ok()?;
        nominal.fit_linear_params(&set)?;
        Some(nominal)
    })();

    // Linear re-fit, guarded by the nominal (see LinearReport::source).
    let (refit, refit_cost) = linear_refit(&td, &poles, use_d, nominal_modal.as_ref(), &mut notes)?;
    if profile {
        eprintln!(
            "profile: linear refit {:.3} s",
            t_start.elapsed().as_secs_f64()
        );
    }
    let gap_refit = vnrmse(&vy, &refit.simulate(&vu));
    let (lin, lin_cost, linear_source) = match &nominal_modal {
        Some(nom) if gap_refit.is_nan() || gap_refit > gap_before => {
            // The nominal with its offset set on the training logs (its residues fixed), or
            // as it is, whichever the training logs prefer; as it is when that one is not
            // above the nominal on validation either.
            let mut with_offset = nom.clone();
            with_offset.offset = mean_offset(&td, nom);
            let (c0, c1) = (nom.cost(&td.base), with_offset.cost(&td.base));
            let mut pick = if c1 < c0 { with_offset } else { nom.clone() };
            let g = vnrmse(&vy, &pick.simulate(&vu));
            if g.is_nan() || g > gap_before {
                pick = nom.clone();
            }
            notes.push(format!(
                "the output-error re-fit ({gap_refit:.4}) does worse than the nominal sim \
                 ({gap_before:.4}) on the validation log: the linear model is the nominal in \
                 modal form"
            ));
            let c = pick.cost(&td.base);
            (pick, c, "nominal")
        }
        _ => (refit.clone(), refit_cost, "refit"),
    };
    let linear = AugmentedModel::linear(lin.clone());
    let gap_linear = vnrmse(&vy, &linear.simulate(&vu)?);

    // WHICH: forward selection (host/src/gap/select/) from the linear model first, then the
    // other of {re-fit, nominal sim in modal form}.
    let mut starts = vec![lin.clone()];
    if linear_source == "nominal" {
        starts.push(refit.clone());
    } else if let Some(mut nominal) = nominal_modal.clone() {
        nominal.offset = lin.offset;
        starts.push(nominal);
    }
    let structure = TwoMassStructure::detect(sim);
    let candidates_opt: Vec<Candidate> = if opts.candidates == EffectKind::ALL.to_vec() {
        Vec::new()
    } else {
        let all = default_candidates(structure.is_some());
        all.into_iter()
            .filter(|c| opts.candidates.contains(&c.kind))
            .collect()
    };
    // Residuals of the linear model (training and validation) and of the nominal (training).
    let resid =
        |y: &[f64], yh: &[f64]| -> Vec<f64> { y.iter().zip(yh).map(|(a, b)| a - b).collect() };
    let y_lin_train: Vec<Vec<f64>> = tu
        .iter()
        .map(|u| linear.simulate(u))
        .collect::<Result<_>>()?;
    let train_resid_lin: Vec<Vec<f64>> = ty
        .iter()
        .zip(&y_lin_train)
        .map(|(y, yh)| resid(y, yh))
        .collect();
    let y_lin_val = linear.simulate(&vu)?;
    let val_resid_lin = resid(&vy, &y_lin_val);
    let train_resid_nom: Vec<Vec<f64>> = tu
        .iter()
        .zip(&ty)
        .map(|(u, y)| Ok(resid(y, &sim.simulate_siso(u, None)?)))
        .collect::<Result<_>>()?;

    // NOISE FLOOR.
    let noise_floor = noise::noise_floor(
        (&vu, &vy),
        &val_resid_lin,
        &tu.iter()
            .zip(&ty)
            .map(|(u, y)| (u.as_slice(), y.as_slice()))
            .collect::<Vec<_>>(),
        &train_resid_lin
            .iter()
            .map(Vec::as_slice)
            .collect::<Vec<_>>(),
        warmup,
        1.0 / ts,
    )?;

    // WHICH (continued): the selection, with the noise floor known.
    let selection = select_effects(
        &td,
        &starts,
        &poles,
        structure.as_ref(),
        &vu,
        &vy,
        warmup,
        &SelectOptions {
            margin: opts.margin,
            nested_margin: opts.nested_margin,
            candidates: candidates_opt,
            // The validation NRMSE noise alone leaves: within twice it, the validation log
            // cannot separate nested effects nor credit a second one.
            noise_floor: noise_floor.available().then_some(noise_floor.nrmse),
            drift_window,
            ..SelectOptions::default()
        },
    )?;
    notes.extend(selection.notes.iter().cloned());
    if profile {
        eprintln!(
            "profile: candidates done {:.3} s",
            t_start.elapsed().as_secs_f64()
        );
    }

    // WHERE, and the evidence.
    let paths: Vec<PathBuf> = train.iter().map(|l| l.path.clone()).collect();
    let mut where_: Where = locate(
        sim,
        &tu,
        &ty,
        &y_lin_train,
        &train_resid_lin,
        &train_resid_nom,
        warmup,
        ts,
        opts,
        &paths,
    )?;
    let amplitude = evidence::amplitude_evidence(
        &tu,
        &ty,
        &lin,
        warmup,
        ts,
        where_.nperseg,
        opts.coherence_min,
        opts.amplitude_tol,
    )?;
    where_.amplitude_dependent = amplitude.amplitude_dependent;
    where_.amplitude_change = amplitude.amplitude_change;
    let mut dist_logs: Vec<(String, &[f64], &[f64])> = train
        .iter()
        .zip(tu.iter().zip(&ty))
        .map(|(l, (u, y))| (l.path.display().to_string(), u.as_slice(), y.as_slice()))
        .collect();
    dist_logs.push((validate.path.display().to_string(), &vu, &vy));
    let nonlinear_distortion = evidence::distortion(&dist_logs, warmup, ts);
    let evidence = Evidence {
        amplitude,
        nonlinear_distortion,
        residual_regions: where_.residual_regions.clone(),
        lattice: selection.lattice.map(Into::into),
        dwell: selection.dwell.as_ref().map(Into::into),
    };
    if profile {
        eprintln!(
            "profile: evidence done {:.3} s",
            t_start.elapsed().as_secs_f64()
        );
    }

    // VERDICT.
    let improvement = |g: f64| (gap_linear - g) / gap_linear;
    let best_gap = selection
        .selected
        .last()
        .map_or(f64::INFINITY, |e| e.gap_after);
    let rule = VerdictRule {
        margin: opts.margin,
        noise_factor: opts.noise_factor,
        min_excess_closed: opts.min_excess_closed,
    };
    let quantization_by_lattice = selection.lattice.is_some()
        && selection
            .selected
            .iter()
            .any(|e| e.effect.kind() == EffectKind::Quantization);
    let mut decision = rule.decide(
        gap_linear,
        best_gap,
        !selection.selected.is_empty(),
        &noise_floor,
        &evidence,
    );
    if quantization_by_lattice {
        decision = Decision::Effect;
    }
    let verdict = match decision {
        Decision::Effect => selection
            .selected
            .iter()
            .map(|e| e.effect.kind().name())
            .collect::<Vec<_>>()
            .join("+"),
        Decision::None => "none".into(),
        Decision::Unexplained => "unexplained".into(),
    };
    if decision != Decision::Effect {
        if let Some(e) = selection.selected.first() {
            notes.push(format!(
                "{} at {} improves on the linear model ({:.4} → {:.4}) but removes only {:.0}% \
                 of its excess over the noise floor: not the verdict",
                e.effect.kind().name(),
                e.place.name(),
                gap_linear,
                best_gap,
                100.0 * (gap_linear - best_gap)
                    / (gap_linear - noise_floor.nrmse.max(0.0).min(gap_linear)).max(1e-300)
            ));
        }
    }
    // For the note: the selection's gap, or the best single's when nothing was selected.
    let best_tried = if best_gap.is_finite() {
        best_gap
    } else {
        selection.singles.first().map_or(f64::NAN, |s| s.gap)
    };
    if let Some(reason) = rule.explain(gap_linear, best_tried, &noise_floor, decision) {
        notes.push(reason);
    }
    let has_effect = decision == Decision::Effect;
    let gap_after = if has_effect { best_gap } else { gap_linear };

    let params_of = |e: &Effect| -> BTreeMap<String, f64> {
        e.params()
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect()
    };
    let report_of = |sc: &Scored| -> Option<EffectReport> {
        let first = sc.effects.first()?;
        let names: Vec<&str> = sc.effects.iter().map(|p| p.effect.kind().name()).collect();
        let places: Vec<&str> = sc.effects.iter().map(|p| p.place.name()).collect();
        let mut params = BTreeMap::new();
        for p in &sc.effects {
            for (k, v) in params_of(&p.effect) {
                let key = if sc.effects.len() > 1 {
                    format!("{}.{k}", p.effect.kind().name())
                } else {
                    k
                };
                params.insert(key, v);
            }
        }
        Some(EffectReport {
            effect: names.join("+"),
            place: places.join("+"),
            params,
            gap_after: sc.gap,
            improvement: improvement(sc.gap),
            train_nrmse: (sc.train_cost / td.u.len() as f64).sqrt(),
            velocity_from: first
                .effect
                .kind()
                .is_friction()
                .then(|| sc.model.velocity_label().to_string()),
            vanished: false,
        })
    };
    // Singles in the selection's order (validation NRMSE, nested pair resolved), then the pairs
    // tried on top of the best single, best first.
    let ranked: Vec<&Scored> = selection.singles.iter().chain(&selection.pairs).collect();
    let effects: Vec<EffectReport> = ranked.iter().filter_map(|s| report_of(s)).collect();
    let verdict_effects: Vec<VerdictEffect> = if has_effect {
        selection
            .selected
            .iter()
            .map(|e| VerdictEffect {
                effect: e.effect.kind().name().to_string(),
                place: e.place.name().to_string(),
                params: params_of(&e.effect),
                share: e.share,
            })
            .collect()
    } else {
        Vec::new()
    };
    let candidates: Vec<AugmentedModel> = ranked.iter().map(|s| s.model.clone()).collect();
    let verdict_model = if has_effect {
        selection.model.clone()
    } else {
        linear.clone()
    };

    // The frequency-domain error in the worst band.
    let y_best_val = verdict_model.simulate(&vu)?;
    let band_error = BandError::compute(
        where_.worst_band_hz,
        &vy,
        &[&y_nom, &y_lin_val, &y_best_val],
        warmup,
        ts,
        where_.nperseg,
    )?;

    let lin_ss = lin.to_state_space()?;
    // In the candidates' metric (drift left out with an integrator).
    let lin_cost = if drift_window.is_some() {
        linear.cost(&td.base, &td.u)
    } else {
        lin_cost
    };
    let train_linear = (lin_cost / td.u.len() as f64).sqrt();
    let mut effects = effects;
    for e in &mut effects {
        e.vanished = e.reproduces_linear(train_linear, gap_linear);
    }
    let report = GapReport {
        verdict,
        verdict_effects,
        noise_floor,
        evidence,
        where_,
        gap_before,
        gap_linear,
        gap_after,
        band_error,
        effects,
        linear: LinearReport {
            model: StateSpaceData::from(&lin_ss),
            offset: lin.offset,
            source: linear_source.into(),
            gap_refit,
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
            train_nrmse: train_linear,
        },
        settings: Settings {
            ts,
            warmup_samples: warmup,
            margin: opts.margin,
            nested_margin: opts.nested_margin,
            noise_factor: opts.noise_factor,
            min_excess_closed: opts.min_excess_closed,
            threshold: opts.threshold,
            coherence_min: opts.coherence_min,
            amplitude_tol: opts.amplitude_tol,
        },
        notes,
    };
    if profile {
        eprintln!("profile: total {:.3} s", t_start.elapsed().as_secs_f64());
    }
    Ok(Diagnosis {
        report,
        nominal: sim.clone(),
        linear,
        verdict_model,
        candidates,
        validation: (vu, vy),
        warmup,
    })
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
    let total = u.len() / p;
    let mut skip = warmup.div_ceil(p);
    if total >= 3 {
        skip = skip.max(1);
    }
    let m = total.checked_sub(skip)?;
    if m < 2 {
        return None;
    }
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
