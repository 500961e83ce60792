//! Runs the cases of both families through the diagnosis and scores them.
//!
//! Family `same`: the cases of `ferrosid_sim::benchmark` (ids prefixed `same/`), truth from its
//! generator, places by effect kind (friction → `motor`, quantization → `sensor`, everything
//! else → `drive`), all not cross-family. Its noise floor is approximated as
//! 0.01·RMS(low-run output)/SD(validation output) (that generator adds noise of 1 % of the
//! noise-free low-run RMS; the measured RMS differs from the noise-free one by ~1e-4 relative).
//! Family `indep`: [`crate::cases`], noise floor exact.
use crate::cases::{self, TruthEffect, TS};
use crate::excite::rms;
use crate::null;
use crate::score::{failed, score, Family, Outcome};
use ferrosid::gap::{diagnose, GapOptions};
use serde_json::Value;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// A case of either family.
#[derive(Debug, Clone)]
pub enum AnyCase {
    /// From `ferrosid_sim::benchmark`.
    Same(ferrosid_sim::benchmark::Case),
    /// From this crate.
    Indep(cases::Case),
    /// Effect-free, from this crate ([`crate::null`]).
    Null(null::Case),
}

impl AnyCase {
    /// Case id (`same/...` or `indep/...`).
    pub fn id(&self) -> String {
        match self {
            AnyCase::Same(c) => format!("same/{}", c.id),
            AnyCase::Indep(c) => c.id.clone(),
            AnyCase::Null(c) => c.id.clone(),
        }
    }
    /// Family.
    pub fn family(&self) -> Family {
        match self {
            AnyCase::Same(_) => Family::Same,
            AnyCase::Indep(_) => Family::Indep,
            AnyCase::Null(_) => Family::Null,
        }
    }
    /// What was drawn for a null case (empty for the effect families).
    pub fn describe(&self) -> String {
        match self {
            AnyCase::Null(c) => c.describe(),
            _ => String::new(),
        }
    }
    /// Adds `k` to the seed.
    pub fn offset_seed(&mut self, k: u64) {
        match self {
            AnyCase::Same(c) => c.seed = c.seed.wrapping_add(k),
            AnyCase::Indep(c) => c.seed = c.seed.wrapping_add(k),
            AnyCase::Null(c) => c.seed = c.seed.wrapping_add(k),
        }
    }
}

/// All cases of the selected families (`same`, `indep`, `all` = both, or `null`, the
/// effect-free set), in a fixed order.
pub fn all_cases(family: &str) -> Vec<AnyCase> {
    if family == "null" {
        return null::cases().into_iter().map(AnyCase::Null).collect();
    }
    let mut v = Vec::new();
    if family == "same" || family == "all" {
        v.extend(
            ferrosid_sim::benchmark::cases()
                .into_iter()
                .map(AnyCase::Same),
        );
    }
    if family == "indep" || family == "all" {
        v.extend(cases::cases().into_iter().map(AnyCase::Indep));
    }
    v
}

fn same_place(name: &str) -> &'static str {
    match name {
        "coulomb_friction" | "stiction" => "motor",
        "quantization" => "sensor",
        _ => "drive",
    }
}

fn plant_of(id: &str) -> String {
    id.split('/').nth(1).unwrap_or("?").to_string()
}

/// Generates, diagnoses and scores one case with `n` samples per log. Returns the outcome and
/// the report as JSON (None when generation or diagnosis failed).
pub fn run_case(case: &AnyCase, n: usize, opts: &GapOptions) -> (Outcome, Option<Value>) {
    run_case_with_lead(case, n, opts, 0)
}

/// Every log of a case as a logger that stores y[k] at the end of the period in which u[k] was
/// applied would write it: the output advanced by `lead` samples (the last `lead` samples of
/// each log dropped).
fn with_output_lead(log: ferrosid::data::Log, lead: usize) -> ferrosid::data::Log {
    if lead == 0 {
        return log;
    }
    let (u, y) = (log.u(), log.y());
    let n = u.len().saturating_sub(lead);
    ferrosid::data::Log::siso(
        log.path.display().to_string(),
        log.ts,
        u[..n].to_vec(),
        y[lead..lead + n].to_vec(),
    )
}

/// [`run_case`] with every output advanced by `lead` samples ([`with_output_lead`]).
pub fn run_case_with_lead(
    case: &AnyCase,
    n: usize,
    opts: &GapOptions,
    lead: usize,
) -> (Outcome, Option<Value>) {
    let id = case.id();
    let fam = case.family();
    let plant = plant_of(&id);
    type Gen = (
        ferrosid::lti::StateSpace,
        Vec<ferrosid::data::Log>,
        ferrosid::data::Log,
        Vec<TruthEffect>,
        f64,
    );
    let generated: Result<Gen, String> = match case {
        AnyCase::Same(c) => ferrosid_sim::benchmark::generate(c, n)
            .map(|d| {
                let truth: Vec<TruthEffect> = d
                    .truth
                    .iter()
                    .map(|e| {
                        let name = e.kind().name();
                        TruthEffect {
                            name,
                            place: same_place(name),
                            params: e.params(),
                            cross_family: false,
                            law: "candidate law".into(),
                        }
                    })
                    .collect();
                let yv = d.validate.y();
                let m = yv.iter().sum::<f64>() / yv.len().max(1) as f64;
                let sd = (yv.iter().map(|v| (v - m).powi(2)).sum::<f64>() / yv.len().max(1) as f64)
                    .sqrt();
                let floor = 0.01 * rms(d.train[0].y()) / sd;
                (d.sim, d.train, d.validate, truth, floor)
            })
            .map_err(|e| e.to_string()),
        AnyCase::Indep(c) => cases::generate(c, n)
            .map(|d| (d.sim, d.train, d.validate, d.truth, d.noise_floor))
            .map_err(|e| e.to_string()),
        AnyCase::Null(c) => null::generate(c, n)
            .map(|d| (d.sim, d.train, d.validate, Vec::new(), d.noise_floor))
            .map_err(|e| e.to_string()),
    };
    let (sim, train, validate, truth, floor) = match generated {
        Ok((sim, train, validate, mut truth, floor)) => {
            // The logged output leads: a true delay lags the logs by `lead` samples less.
            for t in truth.iter_mut().filter(|t| t.name == "time_delay") {
                for p in t.params.iter_mut().filter(|p| p.0 == "seconds") {
                    p.1 -= lead as f64 * TS;
                }
            }
            (
                sim,
                train
                    .into_iter()
                    .map(|l| with_output_lead(l, lead))
                    .collect::<Vec<_>>(),
                with_output_lead(validate, lead),
                truth,
                floor,
            )
        }
        Err(e) => {
            return (
                failed(fam, &id, &plant, &[], &format!("generation: {e}")),
                None,
            )
        }
    };
    let t0 = std::time::Instant::now();
    let result = sim
        .c2d_zoh(TS)
        .and_then(|sd| diagnose(&sd, &train, &validate, opts));
    let secs = t0.elapsed().as_secs_f64();
    match result {
        Ok(d) => match serde_json::to_value(&d.report) {
            Ok(v) => (score(fam, &id, &plant, &truth, &v, floor, secs), Some(v)),
            Err(e) => (
                failed(fam, &id, &plant, &truth, &format!("report: {e}")),
                None,
            ),
        },
        Err(e) => (failed(fam, &id, &plant, &truth, &e.to_string()), None),
    }
}

/// Runs `cases` with `n` samples per log, every output advanced by `lead` samples, on `jobs`
/// threads (at least 1); `on_done` is called as each case finishes (from
/// the worker thread). The outcomes come back in the order of `cases`.
pub fn run_all(
    cases: &[AnyCase],
    (n, lead): (usize, usize),
    jobs: usize,
    opts: &GapOptions,
    on_done: &(dyn Fn(&Outcome, Option<&Value>) + Sync),
) -> Vec<Outcome> {
    let next = AtomicUsize::new(0);
    let slots: Mutex<Vec<Option<Outcome>>> = Mutex::new(vec![None; cases.len()]);
    std::thread::scope(|s| {
        for _ in 0..jobs.max(1) {
            s.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= cases.len() {
                    break;
                }
                let (o, v) = run_case_with_lead(&cases[i], n, opts, lead);
                on_done(&o, v.as_ref());
                if let Ok(mut g) = slots.lock() {
                    g[i] = Some(o);
                }
            });
        }
    });
    slots
        .into_inner()
        .unwrap_or_default()
        .into_iter()
        .flatten()
        .collect()
}
