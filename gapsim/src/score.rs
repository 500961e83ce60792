//! Scoring of diagnosis reports against the ground truth, and the markdown summary.
//!
//! The report is read as a JSON value (`serde_json::to_value(&GapReport)`), so fields that later
//! versions of the diagnosis add (`verdict_effects` with `place` and `params`, `noise_floor`) are
//! used when present and their absence is tolerated.
//!
//! Rules:
//! * expected verdict: `none` for an effect-free case; `unexplained` when a true effect's name
//!   is outside the diagnosis's vocabulary (the eight original names plus any name among the
//!   report's candidates), e.g. `slew_rate` or `state_limit` before they exist; otherwise the set
//!   of true effect names. A verdict is right when its `+`-separated names equal that set (order
//!   free); `none` and `unexplained` must match exactly.
//! * place (right verdicts only): every true effect has an entry of its name in
//!   `verdict_effects` with the true place; for `time_delay` and `resonance` `drive` and `sensor`
//!   are both accepted. A report without places (the diagnosis before issue 9) is read with
//!   [`legacy_place`]: friction at `motor`, quantization at `sensor`, everything else at `drive`.
//! * parameter errors: |fitted − true|/|true| per parameter of each true effect, from its
//!   `verdict_effects` entry if there is one, else from the first candidate of that name — in
//!   both cases only from an entry at an accepted place (a drive saturation's limit in input
//!   units says nothing about a sensor range in output units).
//! * a true `time_delay` within [`ALIGNMENT_RANGE`] samples is the sample alignment's to
//!   report: it is scored on the report's total lag (`linear.alignment_samples` plus the
//!   verdict's delays, within [`ALIGNMENT_TOL`] samples) and the verdict on the other effects;
//! * honesty counts: a `none` verdict on an effect case whose linear re-fit stays above twice
//!   the noise floor; a linear re-fit worse than the nominal on validation (gap_linear >
//!   gap_before·(1 + 1e-9)).
use crate::cases::TruthEffect;
use serde_json::Value;
use std::collections::BTreeSet;
use std::fmt::Write as _;

/// The original eight effect names of the diagnosis.
pub const BASE_VOCABULARY: [&str; 8] = [
    "coulomb_friction",
    "stiction",
    "backlash",
    "deadzone",
    "saturation",
    "time_delay",
    "resonance",
    "quantization",
];

/// Which benchmark family a case belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Family {
    /// `ferrosid_sim::benchmark` (same equations as the candidates).
    Same,
    /// This crate's simulator.
    Indep,
    /// Effect-free logs of this crate's simulator ([`crate::null`]).
    Null,
}

impl Family {
    /// `same` / `indep`.
    pub fn name(self) -> &'static str {
        match self {
            Family::Same => "same",
            Family::Indep => "indep",
            Family::Null => "null",
        }
    }
}

/// Which part of a benchmark family a case belongs to: thresholds, grids and rules are chosen
/// on the tuning part only; the held-out part only reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Split {
    /// Cases rules may be tuned on.
    Tuning,
    /// Cases no rule, threshold or grid is chosen on.
    HeldOut,
}

impl Split {
    /// `tuning` / `held-out`.
    pub fn name(self) -> &'static str {
        match self {
            Split::Tuning => "tuning",
            Split::HeldOut => "held-out",
        }
    }
}

/// 64-bit FNV-1a hash of `text` (fixed: the split must not move between versions).
pub fn fnv1a(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// The split of a case, by the FNV-1a hash of its id: odd hashes are held out.
pub fn split_of(id: &str) -> Split {
    if fnv1a(id) % 2 == 1 {
        Split::HeldOut
    } else {
        Split::Tuning
    }
}

/// The scored result of one case.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// Family.
    pub family: Family,
    /// Tuning or held-out part ([`split_of`] the id).
    pub split: Split,
    /// Case id.
    pub id: String,
    /// Plant name.
    pub plant: String,
    /// Truth label: `name@place` joined by `+`, or `none`.
    pub label: String,
    /// Number of true effects (0, 1, 2).
    pub n_effects: usize,
    /// Whether any true effect is cross-family.
    pub cross_family: bool,
    /// Expected verdict (names sorted and joined by `+`, or `none` / `unexplained`).
    pub expected: String,
    /// The verdict (or `error: ...` when the diagnosis failed).
    pub verdict: String,
    /// Verdict right.
    pub verdict_right: bool,
    /// Place right (right effect verdicts only; [`legacy_place`] where the report gives none).
    pub place_right: Option<bool>,
    /// Whether the report gave places (else the legacy places were assumed).
    pub places_reported: bool,
    /// Relative parameter errors, `effect.param`.
    pub param_errors: Vec<(String, f64)>,
    /// Validation NRMSE: nominal, linear re-fit, verdict model.
    pub gaps: [f64; 3],
    /// Noise floor of the validation log (NRMSE the measurement noise alone leaves).
    pub noise_floor: f64,
    /// Noise floor the report estimated, if it has one.
    pub noise_floor_reported: Option<f64>,
    /// Wall time of the diagnosis, s.
    pub seconds: f64,
}

impl Outcome {
    /// `none` verdict although the linear re-fit stays above twice the noise floor (of an
    /// effect case, or of an effect-free case of the null set, whose `none` must be honest too).
    pub fn none_above_floor(&self) -> bool {
        (self.n_effects > 0 || self.family == Family::Null)
            && self.verdict.split(' ').next() == Some("none")
            && self.gaps[1] > 2.0 * self.noise_floor
    }
    /// Whether the verdict names an effect (neither `none`, `unexplained` nor an error).
    pub fn names_effect(&self) -> bool {
        !matches!(self.verdict.as_str(), "none" | "unexplained")
            && !self.verdict.starts_with("error")
    }
    /// Linear re-fit worse than the nominal on validation.
    pub fn linear_worse(&self) -> bool {
        self.gaps[1] > self.gaps[0] * (1.0 + 1e-9)
    }
}

fn vocabulary(report: &Value) -> BTreeSet<String> {
    let mut v: BTreeSet<String> = BASE_VOCABULARY.iter().map(|s| s.to_string()).collect();
    if let Some(list) = report.get("effects").and_then(Value::as_array) {
        for e in list {
            if let Some(name) = e.get("effect").and_then(Value::as_str) {
                for part in name.split('+') {
                    v.insert(part.to_string());
                }
            }
        }
    }
    v
}

/// The expected verdict for `truth` given the report's vocabulary.
pub fn expected_verdict(truth: &[TruthEffect], report: &Value) -> String {
    if truth.is_empty() {
        return "none".into();
    }
    let vocab = vocabulary(report);
    if truth.iter().any(|t| !vocab.contains(t.name)) {
        return "unexplained".into();
    }
    let set: BTreeSet<&str> = truth.iter().map(|t| t.name).collect();
    set.into_iter().collect::<Vec<_>>().join("+")
}

fn accepted_places(t: &TruthEffect) -> Vec<&'static str> {
    match t.name {
        "time_delay" | "resonance" => vec!["drive", "sensor"],
        _ => vec![t.place],
    }
}

/// The place the diagnosis gave before places were reported: friction on the driven body,
/// quantization at the sensor, everything else in the drive.
pub fn legacy_place(name: &str) -> &'static str {
    match name {
        "coulomb_friction" | "stiction" => "motor",
        "quantization" => "sensor",
        _ => "drive",
    }
}

/// The place of a reported effect entry (its `place`, else [`legacy_place`]).
fn entry_place(e: &Value) -> &str {
    e.get("place")
        .and_then(Value::as_str)
        .unwrap_or_else(|| legacy_place(e.get("effect").and_then(Value::as_str).unwrap_or("")))
}

fn f64_at(v: &Value, key: &str) -> f64 {
    v.get(key).and_then(Value::as_f64).unwrap_or(f64::NAN)
}

/// A true delay within this many samples is the sample alignment's to report
/// ([`ferrosid::gap::align::MAX_ALIGNMENT`]): from input/output data a dead time and a logging
/// offset of the same length are one thing.
pub const ALIGNMENT_RANGE: f64 = ferrosid::gap::align::MAX_ALIGNMENT;

/// How close the reported total lag (alignment plus any `time_delay` of the verdict) must come
/// to a true delay within [`ALIGNMENT_RANGE`]: within this many samples or half the true lag,
/// whichever is larger (the delay is found; how well is its parameter error, as for every other
/// effect).
pub const ALIGNMENT_TOL: f64 = 0.3;

/// Whether a reported lag finds a true one (see [`ALIGNMENT_TOL`]), both in samples.
pub fn lag_found(reported: f64, truth: f64) -> bool {
    (reported - truth).abs() <= ALIGNMENT_TOL.max(0.5 * truth.abs())
}

/// The true delays within [`ALIGNMENT_RANGE`] (in samples at sample time `ts`), and the truth
/// without them.
fn split_alignment(truth: &[TruthEffect], ts: f64) -> (f64, Vec<TruthEffect>) {
    let mut lag = 0.0;
    let mut rest = Vec::new();
    for t in truth {
        let d = t
            .params
            .iter()
            .find(|p| p.0 == "seconds")
            .map_or(f64::NAN, |p| p.1 / ts);
        if t.name == "time_delay" && d.abs() <= ALIGNMENT_RANGE {
            lag += d;
        } else {
            rest.push(t.clone());
        }
    }
    (lag, rest)
}

/// The total lag a report states, samples: its alignment plus the verdict's time delays.
fn reported_lag(report: &Value, ts: f64) -> f64 {
    let a = report
        .get("linear")
        .and_then(|l| l.get("alignment_samples"))
        .and_then(Value::as_f64)
        .unwrap_or(0.0);
    let d: f64 = report
        .get("verdict_effects")
        .and_then(Value::as_array)
        .map(|v| {
            v.iter()
                .filter(|e| e.get("effect").and_then(Value::as_str) == Some("time_delay"))
                .filter_map(|e| e.get("params")?.get("seconds")?.as_f64())
                .sum::<f64>()
        })
        .unwrap_or(0.0);
    a + d / ts
}

/// Scores one report. A true delay within [`ALIGNMENT_RANGE`] samples is scored on the
/// reported total lag (alignment plus the verdict's delays, within [`ALIGNMENT_TOL`]); the
/// verdict is scored on the other true effects.
#[allow(clippy::too_many_arguments)]
pub fn score(
    family: Family,
    id: &str,
    plant: &str,
    truth_all: &[TruthEffect],
    report: &Value,
    noise_floor: f64,
    seconds: f64,
) -> Outcome {
    let verdict_raw = report
        .get("verdict")
        .and_then(Value::as_str)
        .unwrap_or("?")
        .to_string();
    let ts = report
        .get("settings")
        .and_then(|s| s.get("ts"))
        .and_then(Value::as_f64)
        .unwrap_or(crate::cases::TS);
    let (true_lag, truth_rest) = split_alignment(truth_all, ts);
    let lag_scored = truth_rest.len() < truth_all.len();
    let truth: &[TruthEffect] = if lag_scored { &truth_rest } else { truth_all };
    let lag = reported_lag(report, ts);
    let lag_right = !lag_scored || lag_found(lag, true_lag);
    // The verdict without the delays the alignment range holds.
    let verdict = if lag_scored {
        let v: Vec<&str> = verdict_raw
            .split('+')
            .filter(|n| *n != "time_delay")
            .collect();
        if v.is_empty() {
            "none".to_string()
        } else {
            v.join("+")
        }
    } else {
        verdict_raw.clone()
    };
    let expected = expected_verdict(truth, report);
    let verdict_right = if family == Family::Null {
        // Effect-free with linear mismatch the re-fit may not hold: `unexplained` names no
        // effect; `none` must stand on a linear re-fit within twice the floor.
        verdict == "unexplained"
            || (verdict == "none" && f64_at(report, "gap_linear") <= 2.0 * noise_floor)
    } else if expected == "none" || expected == "unexplained" {
        verdict == expected
    } else {
        let a: BTreeSet<&str> = verdict.split('+').collect();
        let b: BTreeSet<&str> = expected.split('+').collect();
        a == b
    } && lag_right;
    let reported: Vec<Value> = report
        .get("verdict_effects")
        .and_then(Value::as_array)
        .cloned()
        .unwrap_or_default();
    let places_reported = reported.iter().any(|e| e.get("place").is_some());
    // Without `verdict_effects`, the verdict's names at their legacy places.
    let ve: Vec<Value> = if reported.is_empty() && verdict != "none" && verdict != "unexplained" {
        verdict
            .split('+')
            .map(|n| serde_json::json!({ "effect": n }))
            .collect()
    } else {
        reported
    };
    let place_right = if verdict_right && !truth.is_empty() && expected != "unexplained" {
        Some(truth.iter().all(|t| {
            let ok = accepted_places(t);
            ve.iter()
                .filter(|e| e.get("effect").and_then(Value::as_str) == Some(t.name))
                .any(|e| ok.contains(&entry_place(e)))
        }))
    } else {
        None
    };
    let candidates: Vec<Value> = report
        .get("effects")
        .and_then(Value::as_array)
        .cloned()
        .unwrap_or_default();
    let mut param_errors = Vec::new();
    for t in truth {
        let ok = accepted_places(t);
        let by_name = |list: &[Value]| -> Option<Value> {
            list.iter()
                .find(|e| {
                    e.get("effect").and_then(Value::as_str) == Some(t.name)
                        && ok.contains(&entry_place(e))
                })
                .and_then(|e| e.get("params").cloned())
        };
        if let Some(params) = by_name(&ve).or_else(|| by_name(&candidates)) {
            for (k, v) in &t.params {
                if let Some(f) = params.get(*k).and_then(Value::as_f64) {
                    param_errors.push((format!("{}.{k}", t.name), ((f - v) / v).abs()));
                }
            }
        }
    }
    if lag_scored && true_lag != 0.0 {
        param_errors.push((
            "time_delay.seconds".into(),
            ((lag - true_lag) / true_lag).abs(),
        ));
    }
    let truth = truth_all;
    let label = if truth.is_empty() {
        "none".to_string()
    } else {
        truth
            .iter()
            .map(|t| format!("{}@{}", t.name, t.place))
            .collect::<Vec<_>>()
            .join("+")
    };
    Outcome {
        family,
        split: split_of(id),
        id: id.to_string(),
        plant: plant.to_string(),
        label,
        n_effects: truth.len(),
        cross_family: truth.iter().any(|t| t.cross_family),
        expected: if lag_scored {
            format!("{expected} (lag {true_lag:.2})")
        } else {
            expected
        },
        verdict: if lag_scored {
            format!("{verdict_raw} (lag {lag:.2})")
        } else {
            verdict_raw
        },
        verdict_right,
        place_right,
        places_reported,
        param_errors,
        gaps: [
            f64_at(report, "gap_before"),
            f64_at(report, "gap_linear"),
            f64_at(report, "gap_after"),
        ],
        noise_floor,
        noise_floor_reported: report
            .get("noise_floor")
            .and_then(|n| n.get("nrmse"))
            .and_then(Value::as_f64),
        seconds,
    }
}

/// Outcome of a case whose generation or diagnosis failed (counted as a wrong verdict).
pub fn failed(family: Family, id: &str, plant: &str, truth: &[TruthEffect], msg: &str) -> Outcome {
    let mut o = score(family, id, plant, truth, &Value::Null, f64::NAN, 0.0);
    o.verdict = format!("error: {msg}");
    o.verdict_right = false;
    o
}

fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

/// Aggregate figures of a set of outcomes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aggregate {
    /// Cases.
    pub cases: usize,
    /// Right verdicts.
    pub right: usize,
    /// Right effect verdicts (with a place, reported or legacy).
    pub placed: usize,
    /// Of those, place right.
    pub place_right: usize,
    /// Median relative parameter error (pooled over all parameters).
    pub param_median: f64,
    /// Worst relative parameter error.
    pub param_worst: f64,
    /// `none` verdicts with the linear re-fit above twice the noise floor.
    pub none_above_floor: usize,
    /// Linear re-fit worse than the nominal.
    pub linear_worse: usize,
}

impl Aggregate {
    /// Share of right verdicts.
    pub fn accuracy(&self) -> f64 {
        self.right as f64 / self.cases.max(1) as f64
    }
}

/// Aggregates `outcomes`.
pub fn aggregate<'a>(outcomes: impl IntoIterator<Item = &'a Outcome>) -> Aggregate {
    let os: Vec<&Outcome> = outcomes.into_iter().collect();
    let pe: Vec<f64> = os
        .iter()
        .flat_map(|o| o.param_errors.iter().map(|p| p.1))
        .collect();
    Aggregate {
        cases: os.len(),
        right: os.iter().filter(|o| o.verdict_right).count(),
        placed: os.iter().filter(|o| o.place_right.is_some()).count(),
        place_right: os.iter().filter(|o| o.place_right == Some(true)).count(),
        param_worst: pe
            .iter()
            .copied()
            .filter(|x| x.is_finite())
            .fold(f64::NAN, f64::max),
        param_median: median(pe),
        none_above_floor: os.iter().filter(|o| o.none_above_floor()).count(),
        linear_worse: os.iter().filter(|o| o.linear_worse()).count(),
    }
}

fn pct(a: usize, b: usize) -> String {
    if b == 0 {
        "—".into()
    } else {
        format!("{a}/{b} ({:.0} %)", 100.0 * a as f64 / b as f64)
    }
}

fn row(s: &mut String, label: &str, os: &[&Outcome]) {
    if os.is_empty() {
        return;
    }
    let a = aggregate(os.iter().copied());
    let g = |i: usize| median(os.iter().map(|o| o.gaps[i]).collect());
    let perr = if a.param_median.is_finite() {
        format!(
            "{:.1} % ({:.0} %)",
            100.0 * a.param_median,
            100.0 * a.param_worst
        )
    } else {
        "—".into()
    };
    let _ = writeln!(
        s,
        "| {label} | {} | {} | {} | {perr} | {} | {} | {:.3} → {:.3} → {:.3} |",
        a.cases,
        pct(a.right, a.cases),
        pct(a.place_right, a.placed),
        a.none_above_floor,
        a.linear_worse,
        g(0),
        g(1),
        g(2)
    );
}

const HEADER: &str = "| cases | n | verdict right | place right (of right) | median (worst) param error | `none` > 2× floor | linear worse | median gap before → linear → after |\n|---|---:|---:|---:|---|---:|---:|---|";

fn table<'a, K: Ord + Clone + std::fmt::Display>(
    s: &mut String,
    title: &str,
    outcomes: &'a [Outcome],
    key: impl Fn(&'a Outcome) -> K,
) {
    let _ = writeln!(s, "\n**{title}**\n\n{HEADER}");
    let mut keys: Vec<K> = outcomes.iter().map(&key).collect();
    keys.sort();
    keys.dedup();
    for k in keys {
        let os: Vec<&Outcome> = outcomes.iter().filter(|o| key(o) == k).collect();
        row(s, &k.to_string(), &os);
    }
}

/// The null set's error rates per split: effects named (false positives) overall and per
/// effect name, `unexplained`, dishonest `none`.
fn null_summary(s: &mut String, outcomes: &[Outcome]) {
    let null: Vec<&Outcome> = outcomes
        .iter()
        .filter(|o| o.family == Family::Null)
        .collect();
    if null.is_empty() {
        return;
    }
    let _ = writeln!(
        s,
        "\n**Null set (effect-free)**\n\n| part | n | effects named | `unexplained` | `none` > 2× floor | named effects (count) |\n|---|---:|---:|---:|---:|---|"
    );
    for split in [None, Some(Split::Tuning), Some(Split::HeldOut)] {
        let os: Vec<&&Outcome> = null
            .iter()
            .filter(|o| split.is_none_or(|sp| o.split == sp))
            .collect();
        let mut per: std::collections::BTreeMap<&str, usize> = Default::default();
        for o in os.iter().filter(|o| o.names_effect()) {
            for name in o.verdict.split('+') {
                *per.entry(name).or_default() += 1;
            }
        }
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} |",
            split.map_or("all", Split::name),
            os.len(),
            pct(os.iter().filter(|o| o.names_effect()).count(), os.len()),
            pct(
                os.iter().filter(|o| o.verdict == "unexplained").count(),
                os.len()
            ),
            os.iter().filter(|o| o.none_above_floor()).count(),
            per.iter()
                .map(|(k, v)| format!("{k} {v}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
}

/// Markdown summary: totals, per family, the cross-family split, per plant, per effect,
/// single/pair/none, and the list of wrong verdicts.
pub fn markdown(outcomes: &[Outcome]) -> String {
    let mut s = String::new();
    let all: Vec<&Outcome> = outcomes.iter().collect();
    let _ = writeln!(s, "**Totals**\n\n{HEADER}");
    row(&mut s, "all", &all);
    for split in [Split::Tuning, Split::HeldOut] {
        let os: Vec<&Outcome> = outcomes.iter().filter(|o| o.split == split).collect();
        row(&mut s, split.name(), &os);
    }
    for fam in [Family::Same, Family::Indep, Family::Null] {
        for split in [None, Some(Split::Tuning), Some(Split::HeldOut)] {
            let os: Vec<&Outcome> = outcomes
                .iter()
                .filter(|o| o.family == fam && split.is_none_or(|sp| o.split == sp))
                .collect();
            let label = match split {
                None => format!("family {}", fam.name()),
                Some(sp) => format!("family {} {}", fam.name(), sp.name()),
            };
            row(&mut s, &label, &os);
        }
    }
    let cross: Vec<&Outcome> = outcomes.iter().filter(|o| o.cross_family).collect();
    let non: Vec<&Outcome> = outcomes.iter().filter(|o| !o.cross_family).collect();
    row(&mut s, "cross-family", &cross);
    row(&mut s, "not cross-family", &non);
    null_summary(&mut s, outcomes);
    table(&mut s, "Per family and plant", outcomes, |o| {
        format!("{} {}", o.family.name(), o.plant)
    });
    table(
        &mut s,
        "Per family, single / pair / effect-free",
        outcomes,
        |o| {
            let k = match o.n_effects {
                0 => "none",
                1 => "single",
                _ => "pair",
            };
            format!(
                "{} {k}{}",
                o.family.name(),
                if o.cross_family { " (cross)" } else { "" }
            )
        },
    );
    table(&mut s, "Per true effect (name@place)", outcomes, |o| {
        format!("{} {}", o.family.name(), o.label)
    });
    // The table pools every parameter error, including those a wrong verdict's candidates
    // carry (the scoring takes them from the candidates when the verdict lacks the effect);
    // the worst on right verdicts is the error of what the diagnosis reports.
    let worst_right = outcomes
        .iter()
        .filter(|o| o.verdict_right)
        .flat_map(|o| {
            o.param_errors
                .iter()
                .map(move |(n, e)| (*e, o.id.as_str(), n))
        })
        .filter(|p| p.0.is_finite())
        .max_by(|a, b| a.0.total_cmp(&b.0));
    if let Some((e, id, name)) = worst_right {
        let _ = writeln!(
            s,
            "\nWorst parameter error on right verdicts: {:.1} % ({id}, {name}).",
            100.0 * e
        );
    }
    let timing: Vec<f64> = outcomes.iter().map(|o| o.seconds).collect();
    let _ = writeln!(
        s,
        "\nMedian diagnosis time per case: {:.2} s (max {:.2} s).",
        median(timing.clone()),
        timing.iter().copied().fold(0.0, f64::max)
    );
    if outcomes
        .iter()
        .any(|o| o.n_effects > 0 && !o.places_reported)
    {
        let _ = writeln!(
            s,
            "Places: where a report names none, the legacy places were assumed (friction at \
             `motor`, quantization at `sensor`, everything else at `drive`)."
        );
    }
    let nf: Vec<(f64, f64)> = outcomes
        .iter()
        .filter_map(|o| o.noise_floor_reported.map(|r| (r, o.noise_floor)))
        .collect();
    if nf.is_empty() {
        let _ = writeln!(s, "The reports carry no noise-floor estimate.");
    } else {
        let ratio: Vec<f64> = nf.iter().map(|(r, t)| r / t).collect();
        let _ = writeln!(
            s,
            "Reported / true noise floor over {} cases: median {:.2}, range {:.2}–{:.2}.",
            nf.len(),
            median(ratio.clone()),
            ratio.iter().copied().fold(f64::INFINITY, f64::min),
            ratio.iter().copied().fold(0.0, f64::max)
        );
    }
    let bad: Vec<&Outcome> = outcomes
        .iter()
        .filter(|o| !o.verdict_right || o.place_right == Some(false) || o.linear_worse())
        .collect();
    if !bad.is_empty() {
        let _ = writeln!(
            s,
            "\n**Wrong verdicts, wrong places, linear re-fits worse than nominal**\n\n| case | cross | expected | verdict | place | gaps before / linear / after | floor |\n|---|---|---|---|---|---|---:|"
        );
        for o in bad {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} | {:.3} / {:.3} / {:.3}{} | {:.4} |",
                o.id,
                if o.cross_family { "yes" } else { "" },
                o.expected,
                o.verdict,
                match o.place_right {
                    Some(true) => "ok",
                    Some(false) => "WRONG",
                    None => "—",
                },
                o.gaps[0],
                o.gaps[1],
                o.gaps[2],
                if o.linear_worse() {
                    " (linear worse)"
                } else {
                    ""
                },
                o.noise_floor
            );
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The summary's worst error on right verdicts leaves out a wrong verdict's candidates,
    /// which the pooled table column keeps.
    #[test]
    fn worst_error_on_right_verdicts_skips_wrong_ones() {
        let mut right = failed(Family::Indep, "indep/a/x/0", "a", &[], "");
        right.verdict_right = true;
        right.param_errors = vec![("stiction.breakaway".into(), 0.1)];
        let mut wrong = failed(Family::Indep, "indep/a/y/0", "a", &[], "");
        wrong.param_errors = vec![("time_delay.seconds".into(), 0.8)];
        let outcomes = [right, wrong];
        assert_eq!(aggregate(&outcomes).param_worst, 0.8);
        let md = markdown(&outcomes);
        assert!(
            md.contains(
                "Worst parameter error on right verdicts: 10.0 % (indep/a/x/0, stiction.breakaway)."
            ),
            "{md}"
        );
    }
}
