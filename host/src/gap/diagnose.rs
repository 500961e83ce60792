//! The diagnosis itself: linear re-fit, candidate effects, ranking, verdict, shrink.
//!
//! The verdict rule and the nested-effect statistics are in [`crate::gap::verdict`], the linear
//! model (modal stand-ins, warm-up, period averaging, re-fit) in [`crate::gap::linear`]; both
//! are re-exported here.
use super::align;
use super::drift::validation_nrmse;
use super::effect::{Effect, EffectKind};
use super::evidence::{self, Evidence};
use super::fit::{AugmentedModel, TrainData};
use super::linear::{choose_linear, nominal_modal_form, s_of, LinearChoice};
use super::locate::{locate, Where};
use super::logs::{read_logs, Logs};
use super::modal::{nrmse, FitSet, ModalModel};
use super::noise::{self, NoiseFloor};
use super::outliers;
use super::place::Candidate;
use super::report::{BandError, EffectReport, GapReport, LinearReport, Settings, VerdictEffect};
use super::select::{default_candidates, select_effects, Scored, SelectOptions, Selection};
use super::simfile::is_integrator_pole;
use super::structure::TwoMassStructure;
use crate::data::Log;
use crate::error::{Error, Result};
use crate::lti::{StateSpace, StateSpaceData};
use num_complex::Complex64;
use std::collections::BTreeMap;
use std::path::PathBuf;

pub use super::linear::{
    default_warmup, modal_stand_in, period_average, INTEGRATOR_STAND_IN, REFIT_SCREEN_SAMPLES,
};
pub use super::verdict::{
    effective_samples, nested_likelihood_ratio, pooled_likelihood_ratio, Decision, LogFit,
    VerdictRule, MAX_CORRELATION_LAG, NESTED_LR_THRESHOLD, NESTED_LR_THRESHOLD_2,
};

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

/// What the fits work on: the sim's poles as modal stand-ins, the warm-up, the drift
/// window (with an integrator), the fitting inputs and the training data.
struct Setup {
    poles: Vec<Complex64>,
    warmup: usize,
    drift_window: Option<usize>,
    fu: Vec<Vec<f64>>,
    td: TrainData,
}

/// The sim's poles (an unstable one other than an integrator is an error), the warm-up, and
/// the fitting data: periodic training logs averaged over their periods
/// ([`period_average`]), the raw logs serve everything else.
fn setup(
    sim: &StateSpace,
    train: &[Log],
    logs: &Logs,
    opts: &GapOptions,
    notes: &mut Vec<String>,
) -> Result<Setup> {
    let (tu, ty) = (&logs.tu, &logs.ty);
    let shortest = tu
        .iter()
        .map(Vec::len)
        .chain([logs.vu.len()])
        .min()
        .unwrap_or(0);
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
    let integrator = sim_poles.iter().any(|p| is_integrator_pole(*p));
    if integrator {
        notes.push(format!(
            "the sim has an integrator (pole at z = 1): kept exactly in its modal form (a second \
             one at z = 1 − {INTEGRATOR_STAND_IN:e}); the warm-up follows the slowest stable pole"
        ));
    }
    let mut fu = Vec::with_capacity(tu.len());
    let mut fy = Vec::with_capacity(tu.len());
    for (log, (u, y)) in train.iter().zip(tu.iter().zip(ty)) {
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
    let drift_window = integrator.then_some(warmup);
    let mut td = TrainData::new(logs.ts, fu.clone(), fy, warmup)?;
    td.base.drift_window = drift_window;
    Ok(Setup {
        poles,
        warmup,
        drift_window,
        fu,
        td,
    })
}

/// Wall-clock marks on stderr when `GAP_PROFILE` is set.
struct Profile {
    on: bool,
    start: std::time::Instant,
}

impl Profile {
    fn new() -> Self {
        Self {
            on: std::env::var_os("GAP_PROFILE").is_some(),
            start: std::time::Instant::now(),
        }
    }

    fn mark(&self, what: &str) {
        if self.on {
            eprintln!(
                "profile: {what} {:.3} s",
                self.start.elapsed().as_secs_f64()
            );
        }
    }
}

/// Residuals of the linear model (training and validation) and of the nominal (training),
/// with the linear model's simulated outputs.
struct Residuals {
    y_lin_train: Vec<Vec<f64>>,
    train_lin: Vec<Vec<f64>>,
    y_lin_val: Vec<f64>,
    val_lin: Vec<f64>,
    train_nom: Vec<Vec<f64>>,
}

fn difference(y: &[f64], yh: &[f64]) -> Vec<f64> {
    y.iter().zip(yh).map(|(a, b)| a - b).collect()
}

impl Residuals {
    fn of(sim: &StateSpace, linear: &AugmentedModel, logs: &Logs) -> Result<Self> {
        let y_lin_train: Vec<Vec<f64>> = logs
            .tu
            .iter()
            .map(|u| linear.simulate(u))
            .collect::<Result<_>>()?;
        let train_lin = logs
            .ty
            .iter()
            .zip(&y_lin_train)
            .map(|(y, yh)| difference(y, yh))
            .collect();
        let y_lin_val = linear.simulate(&logs.vu)?;
        let val_lin = difference(&logs.vy, &y_lin_val);
        let train_nom = logs
            .tu
            .iter()
            .zip(&logs.ty)
            .map(|(u, y)| Ok(difference(y, &sim.simulate_siso(u, None)?)))
            .collect::<Result<_>>()?;
        Ok(Self {
            y_lin_train,
            train_lin,
            y_lin_val,
            val_lin,
            train_nom,
        })
    }
}

/// WHICH: forward selection (host/src/gap/select/) from the linear model first, then the other
/// of {re-fit, nominal sim in modal form}; with the noise floor known.
#[allow(clippy::too_many_arguments)]
fn run_selection(
    sim: &StateSpace,
    logs: &Logs,
    s: &Setup,
    choice: &LinearChoice,
    nominal_modal: Option<&ModalModel>,
    noise_floor: &NoiseFloor,
    (gap_linear, alignment_samples): (f64, f64),
    opts: &GapOptions,
) -> Result<Selection> {
    let lin = &choice.lin;
    let mut starts = vec![lin.clone()];
    if choice.source == "nominal" {
        starts.push(choice.refit.clone());
    } else if let Some(mut nominal) = nominal_modal.cloned() {
        nominal.offset = lin.offset;
        starts.push(nominal);
    }
    let structure = TwoMassStructure::detect(sim);
    let candidates: Vec<Candidate> = if opts.candidates == EffectKind::ALL.to_vec() {
        Vec::new()
    } else {
        default_candidates(structure.is_some())
            .into_iter()
            .filter(|c| opts.candidates.contains(&c.kind))
            .collect()
    };
    select_effects(
        &s.td,
        &starts,
        &s.poles,
        structure.as_ref(),
        &logs.vu,
        &logs.vy,
        s.warmup,
        &SelectOptions {
            margin: opts.margin,
            nested_margin: opts.nested_margin,
            candidates,
            // The validation NRMSE noise alone leaves: within twice it, the validation log
            // cannot separate nested effects nor credit a second one.
            // A floor the linear re-fit contradicts describes other noise: none.
            noise_floor: (noise_floor.available()
                && !super::verdict::floor_contradicted(gap_linear, noise_floor))
            .then_some(noise_floor.nrmse),
            drift_window: s.drift_window,
            min_excess_closed: opts.min_excess_closed,
            // The lattice of a quantizing sensor is read off the logged values: the period
            // average of periodic logs sits on a lattice m times finer.
            raw_outputs: logs.ty.clone(),
            alignment_samples,
            ..SelectOptions::default()
        },
    )
}

/// WHERE, and the evidence: error bands and time regions, amplitude dependence, nonlinear
/// distortion, and the selection's lattice and dwell evidence.
#[allow(clippy::too_many_arguments)]
fn where_and_evidence(
    sim: &StateSpace,
    train: &[Log],
    validate: &Log,
    logs: &Logs,
    s: &Setup,
    lin: &ModalModel,
    resid: &Residuals,
    selection: &Selection,
    opts: &GapOptions,
) -> Result<(Where, Evidence)> {
    let paths: Vec<PathBuf> = train.iter().map(|l| l.path.clone()).collect();
    let mut where_: Where = locate(
        sim,
        &logs.tu,
        &logs.ty,
        &resid.y_lin_train,
        &resid.train_lin,
        &resid.train_nom,
        s.warmup,
        logs.ts,
        opts,
        &paths,
    )?;
    let amplitude = evidence::amplitude_evidence(
        &logs.tu,
        &logs.ty,
        lin,
        s.warmup,
        logs.ts,
        where_.nperseg,
        opts.coherence_min,
        opts.amplitude_tol,
    )?;
    where_.amplitude_dependent = amplitude.amplitude_dependent;
    where_.amplitude_change = amplitude.amplitude_change;
    let mut dist_logs: Vec<(String, &[f64], &[f64])> = train
        .iter()
        .zip(logs.tu.iter().zip(&logs.ty))
        .map(|(l, (u, y))| (l.path.display().to_string(), u.as_slice(), y.as_slice()))
        .collect();
    dist_logs.push((validate.path.display().to_string(), &logs.vu, &logs.vy));
    let nonlinear_distortion = evidence::distortion(&dist_logs, s.warmup, logs.ts);
    let evidence = Evidence {
        amplitude,
        nonlinear_distortion,
        residual_regions: where_.residual_regions.clone(),
        lattice: selection.lattice.map(Into::into),
        dwell: selection.dwell.as_ref().map(Into::into),
    };
    Ok((where_, evidence))
}

/// The verdict of a selection: its decision, the verdict name and the validation NRMSE after.
struct Verdict {
    decision: Decision,
    name: String,
    gap_after: f64,
}

/// VERDICT: the rule ([`VerdictRule`]) on the selection's validation NRMSE, a lattice deciding
/// quantization by itself; the reasons go to `notes`.
fn decide_verdict(
    selection: &Selection,
    gap_linear: f64,
    noise_floor: &NoiseFloor,
    evidence: &Evidence,
    opts: &GapOptions,
    notes: &mut Vec<String>,
) -> Verdict {
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
        noise_floor,
        evidence,
    );
    if quantization_by_lattice {
        decision = Decision::Effect;
    }
    let name = match decision {
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
    if let Some(reason) = rule.explain(gap_linear, best_tried, noise_floor, decision) {
        notes.push(reason);
    }
    let gap_after = if decision == Decision::Effect {
        best_gap
    } else {
        gap_linear
    };
    Verdict {
        decision,
        name,
        gap_after,
    }
}

fn params_of(e: &Effect) -> BTreeMap<String, f64> {
    e.params()
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect()
}

/// The report row of a scored candidate (a single or a pair; `None` without an effect).
/// `n_logs`: training logs (the training NRMSE is the root mean of their NRMSE²).
fn effect_report(sc: &Scored, gap_linear: f64, n_logs: usize) -> Option<EffectReport> {
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
        improvement: (gap_linear - sc.gap) / gap_linear,
        train_nrmse: (sc.train_cost / n_logs as f64).sqrt(),
        velocity_from: first
            .effect
            .kind()
            .is_friction()
            .then(|| sc.model.velocity_label().to_string()),
        vanished: false,
    })
}

/// The linear part of the report: its state-space form, offset, source, poles (Hz, damping).
fn linear_report(
    choice: &LinearChoice,
    ts: f64,
    train_nrmse: f64,
    alignment_samples: f64,
) -> Result<LinearReport> {
    let lin = &choice.lin;
    Ok(LinearReport {
        model: StateSpaceData::from(&lin.to_state_space()?),
        offset: lin.offset,
        source: choice.source.into(),
        gap_refit: choice.gap_refit,
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
        train_nrmse,
        alignment_samples,
    })
}

/// The selected effects as the verdict lists them (name, place, parameters, share).
fn verdict_effects(selection: &Selection) -> Vec<VerdictEffect> {
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
}

/// The noise floor of the diagnosis ([`noise::noise_floor`]) from the validation log and the
/// linear model's residuals on it and on the training logs.
fn noise_floor_of(
    logs: &Logs,
    resid: &Residuals,
    warmup: usize,
    ts: f64,
) -> Result<noise::NoiseFloor> {
    noise::noise_floor(
        (logs.vu.as_slice(), logs.vy.as_slice()),
        &resid.val_lin,
        &logs
            .tu
            .iter()
            .zip(&logs.ty)
            .map(|(u, y)| (u.as_slice(), y.as_slice()))
            .collect::<Vec<_>>(),
        &resid
            .train_lin
            .iter()
            .map(Vec::as_slice)
            .collect::<Vec<_>>(),
        warmup,
        1.0 / ts,
    )
}

/// The linear stage of a diagnosis: the nominal on the validation log, the nominal in modal
/// form, the linear re-fit guarded by it, and the residuals.
struct LinearStage {
    y_nom: Vec<f64>,
    gap_before: f64,
    nominal_modal: Option<ModalModel>,
    choice: LinearChoice,
    linear: AugmentedModel,
    gap_linear: f64,
    resid: Residuals,
}

fn linear_stage(
    sim: &StateSpace,
    logs: &Logs,
    s: &Setup,
    notes: &mut Vec<String>,
) -> Result<LinearStage> {
    let (ts, warmup) = (logs.ts, s.warmup);
    let vu = &logs.vu;
    // HOW FAR (before): the nominal sim on the validation log (with an integrator, the
    // free run's drift left out).
    let vscore = |yh: &[f64]| validation_nrmse(&logs.vy, yh, warmup, s.drift_window);
    let y_nom = sim.simulate_siso(vu, None)?;
    let gap_before = vscore(&y_nom);
    // The nominal in modal form, and the linear re-fit guarded by it (LinearReport::source).
    let use_d = sim.d[(0, 0)] != 0.0;
    let nominal_modal = nominal_modal_form(sim, ts, &s.poles, use_d, &s.fu, vu, warmup);
    let choice = choose_linear(
        &s.td,
        &s.poles,
        use_d,
        nominal_modal.as_ref(),
        gap_before,
        vu,
        &vscore,
        notes,
    )?;
    let linear = AugmentedModel::linear(choice.lin.clone());
    let gap_linear = vscore(&linear.simulate(vu)?);
    let resid = Residuals::of(sim, &linear, logs)?;
    Ok(LinearStage {
        y_nom,
        gap_before,
        nominal_modal,
        choice,
        linear,
        gap_linear,
        resid,
    })
}

/// Finds the output spikes of every log on the linear model's residuals
/// ([`crate::gap::outliers`]) and masks them in `logs`; their report (and a note), `None`
/// without spikes.
fn mask_spikes(
    train: &[Log],
    validate: &Log,
    logs: &mut Logs,
    resid: &Residuals,
    notes: &mut Vec<String>,
) -> Option<outliers::Outliers> {
    let mut found: Vec<(String, Vec<usize>, &[f64])> = Vec::new();
    for (i, log) in train.iter().enumerate() {
        // The warm-up too: a spike is sharp against the smooth initial transient.
        let at = outliers::spikes(&resid.train_lin[i], 0);
        outliers::mask(&mut logs.ty[i], &resid.y_lin_train[i], &at);
        found.push((log.path.display().to_string(), at, &resid.train_lin[i]));
    }
    let at = outliers::spikes(&resid.val_lin, 0);
    outliers::mask(&mut logs.vy, &resid.y_lin_val, &at);
    found.push((validate.path.display().to_string(), at, &resid.val_lin));
    let total = logs.ty.iter().map(Vec::len).sum::<usize>() + logs.vy.len();
    let o = outliers::report(&found, logs.ts, total)?;
    notes.push(format!(
        "{} output spike(s) ({:.2} % of the samples) masked before the noise floor and every \
         fit (largest {:.4e} output units)",
        o.count,
        100.0 * o.share,
        o.logs
            .iter()
            .map(|l| l.largest)
            .max_by(|a, b| a.abs().total_cmp(&b.abs()))
            .unwrap_or(0.0)
    ));
    Some(o)
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
    let logs = read_logs(sim, train, validate)?;
    let use_d = sim.d[(0, 0)] != 0.0;
    // ALIGNMENT, on the training logs.
    let first = setup(sim, train, &logs, opts, &mut Vec::new())?;
    let alignment = align::estimate(&first.td.coarse(REFIT_SCREEN_SAMPLES), &first.poles, use_d)
        .filter(|a| a.applied);
    let Some(a) = alignment else {
        return diagnose_logs(sim, train, validate, opts, logs, 0.0, Vec::new());
    };
    // An unmodelled effect can pull the alignment estimate (a shift mimics part of a missing
    // mode's phase): the diagnosis runs on the aligned and on the logs as logged, and keeps
    // the aligned one unless the other's verdict model does better on the validation log by
    // the verdict margin.
    let aligned_logs = Logs {
        ts: logs.ts,
        tu: logs
            .tu
            .iter()
            .map(|u| align::shift_input(u, a.samples))
            .collect(),
        ty: logs.ty.clone(),
        vu: align::shift_input(&logs.vu, a.samples),
        vy: logs.vy.clone(),
    };
    let note = format!(
        "sample alignment: the logged output {} the zero-order-hold model by {:.2} samples \
         (likelihood ratio {:.1} over no alignment); every log's input was shifted by it before \
         the fits (a logging offset and a dead time of that length are the same thing in \
         input/output data)",
        if a.samples > 0.0 { "lags" } else { "leads" },
        a.samples.abs(),
        a.likelihood_ratio
    );
    let aligned = diagnose_logs(
        sim,
        train,
        validate,
        opts,
        aligned_logs,
        a.samples,
        vec![note],
    );
    let as_logged = diagnose_logs(sim, train, validate, opts, logs, 0.0, Vec::new());
    match (aligned, as_logged) {
        (Ok(al), Ok(mut raw))
            if raw.report.gap_after < (1.0 - opts.margin) * al.report.gap_after =>
        {
            raw.report.notes.push(format!(
                "an alignment of {:+.2} samples was significant for the linear model alone \
                 (likelihood ratio {:.1}), but on the aligned logs the verdict {} leaves {:.4} \
                 against {:.4} here: the logs are judged as logged",
                a.samples,
                a.likelihood_ratio,
                al.report.verdict,
                al.report.gap_after,
                raw.report.gap_after
            ));
            Ok(raw)
        }
        (Ok(al), _) => Ok(al),
        (Err(_), raw) => raw,
    }
}

/// The diagnosis of logs already aligned by `alignment_samples` (reported as such), with
/// `notes` to start from.
fn diagnose_logs(
    sim: &StateSpace,
    train: &[Log],
    validate: &Log,
    opts: &GapOptions,
    mut logs: Logs,
    alignment_samples: f64,
    mut notes: Vec<String>,
) -> Result<Diagnosis> {
    let s = setup(sim, train, &logs, opts, &mut notes)?;
    let profile = Profile::new();
    let mut s = s;
    let mut st = linear_stage(sim, &logs, &s, &mut notes)?;
    // OUTLIERS: spikes on the linear model's residual, masked in every log, then the linear
    // model again on the masked logs.
    let outliers = mask_spikes(train, validate, &mut logs, &st.resid, &mut notes);
    if outliers.is_some() {
        s = setup(sim, train, &logs, opts, &mut Vec::new())?;
        st = linear_stage(sim, &logs, &s, &mut Vec::new())?;
    }
    profile.mark("linear refit");
    let LinearStage {
        y_nom,
        gap_before,
        nominal_modal,
        choice,
        linear,
        gap_linear,
        resid,
    } = st;
    let (ts, warmup, drift_window) = (logs.ts, s.warmup, s.drift_window);
    let (vu, vy) = (&logs.vu, &logs.vy);
    // NOISE FLOOR.
    let noise_floor = noise_floor_of(&logs, &resid, warmup, ts)?;

    let selection = run_selection(
        sim,
        &logs,
        &s,
        &choice,
        nominal_modal.as_ref(),
        &noise_floor,
        (gap_linear, alignment_samples),
        opts,
    )?;
    notes.extend(selection.notes.iter().cloned());
    profile.mark("candidates done");
    let (where_, evidence) = where_and_evidence(
        sim,
        train,
        validate,
        &logs,
        &s,
        &choice.lin,
        &resid,
        &selection,
        opts,
    )?;
    profile.mark("evidence done");
    let verdict = decide_verdict(
        &selection,
        gap_linear,
        &noise_floor,
        &evidence,
        opts,
        &mut notes,
    );
    let has_effect = verdict.decision == Decision::Effect;

    // Singles in the selection's order (validation NRMSE, nested pair resolved), then the pairs
    // tried on top of the best single, best first.
    let ranked: Vec<&Scored> = selection.singles.iter().chain(&selection.pairs).collect();
    let n_logs = s.td.u.len();
    let mut effects: Vec<EffectReport> = ranked
        .iter()
        .filter_map(|sc| effect_report(sc, gap_linear, n_logs))
        .collect();
    let verdict_effects: Vec<VerdictEffect> = if has_effect {
        verdict_effects(&selection)
    } else {
        Vec::new()
    };
    let candidates: Vec<AugmentedModel> = ranked.iter().map(|sc| sc.model.clone()).collect();
    let verdict_model = if has_effect {
        selection.model.clone()
    } else {
        linear.clone()
    };

    // The frequency-domain error in the worst band.
    let y_best_val = verdict_model.simulate(vu)?;
    let band_error = BandError::compute(
        where_.worst_band_hz,
        vy,
        &[&y_nom, &resid.y_lin_val, &y_best_val],
        warmup,
        ts,
        where_.nperseg,
    )?;

    // In the candidates' metric (drift left out with an integrator).
    let lin_cost = if drift_window.is_some() {
        linear.cost(&s.td.base, &s.td.u)
    } else {
        choice.cost
    };
    let train_linear = (lin_cost / n_logs as f64).sqrt();
    for e in &mut effects {
        e.vanished = e.reproduces_linear(train_linear, gap_linear);
    }
    let report = GapReport {
        outliers,
        verdict: verdict.name,
        verdict_effects,
        noise_floor,
        evidence,
        where_,
        gap_before,
        gap_linear,
        gap_after: verdict.gap_after,
        band_error,
        effects,
        linear: linear_report(&choice, ts, train_linear, alignment_samples)?,
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
    profile.mark("total");
    Ok(Diagnosis {
        report,
        nominal: sim.clone(),
        linear,
        verdict_model,
        candidates,
        validation: (logs.vu, logs.vy),
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
