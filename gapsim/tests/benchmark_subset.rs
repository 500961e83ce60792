//! A rule-chosen subset of the two-family gap benchmark with its aggregate targets.
//!
//! Rule: every [`SAME_STRIDE`]-th case of the `same` family and every [`INDEP_STRIDE`]-th case
//! of the `indep` family, each in its fixed order and starting with its first case, at [`N`]
//! samples per log (a quarter of the benchmark's 16,384, so
//! the subset runs in a test build in about 55 s — measured with `cargo test -p ferrosid-gapsim --test
//! benchmark_subset` on the shared 2-core machine under a load of ~8; the figures below
//! are measured with exactly this subset and length, not with the full benchmark).
//!
//! The assertions hold the figures as measured on the diagnosis of the day (they can fail: a
//! change that loses verdicts drops below them), and the targets this subset meets:
//! zero `none` verdicts above twice the noise floor, zero linear re-fits worse than the nominal,
//! place right in ≥ 90 % of right verdicts, median parameter error ≤ 10 %. NOT yet met and not
//! asserted: ≥ 95 % right verdicts overall, ≥ 90 % on the cross-family split, worst parameter
//! error ≤ 25 %. Raise the thresholds as the diagnosis improves.
use ferrosid::gap::GapOptions;
use ferrosid_gapsim::bench::{all_cases, run_all, AnyCase};
use ferrosid_gapsim::score::{aggregate, markdown, Family};

/// Every SAME_STRIDE-th case of the first family (54 cases → 8).
const SAME_STRIDE: usize = 7;
/// Every INDEP_STRIDE-th case of the independent family (149 cases → 38).
const INDEP_STRIDE: usize = 4;
/// Samples per log.
const N: usize = 4096;

fn subset() -> Vec<AnyCase> {
    let pick = |family: &str, stride: usize| {
        all_cases(family)
            .into_iter()
            .enumerate()
            .filter(move |(i, _)| i % stride == 0)
            .map(|(_, c)| c)
    };
    pick("same", SAME_STRIDE)
        .chain(pick("indep", INDEP_STRIDE))
        .collect()
}

#[test]
fn benchmark_subset_holds_the_measured_aggregates() {
    let cases = subset();
    let outcomes = run_all(&cases, (N, 0), 1, &GapOptions::default(), &|o, _| {
        eprintln!(
            "{:<44} {} expected {:<24} verdict {}",
            o.id,
            if o.verdict_right { "ok " } else { "BAD" },
            o.expected,
            o.verdict
        );
    });
    eprintln!("{}", markdown(&outcomes));
    assert_eq!(outcomes.len(), cases.len());
    let same = aggregate(outcomes.iter().filter(|o| o.family == Family::Same));
    let indep = aggregate(outcomes.iter().filter(|o| o.family == Family::Indep));
    let cross = aggregate(outcomes.iter().filter(|o| o.cross_family));
    let all = aggregate(&outcomes);
    eprintln!(
        "same {}/{}, indep {}/{}, cross {}/{}, none>2floor {}, linear worse {}",
        same.right,
        same.cases,
        indep.right,
        indep.cases,
        cross.right,
        cross.cases,
        all.none_above_floor,
        all.linear_worse
    );
    // Measured values (see the module docs); margin: one case each.
    assert!(
        same.right + 1 >= SAME_RIGHT,
        "same family: {} right",
        same.right
    );
    assert!(
        indep.right + 1 >= INDEP_RIGHT,
        "independent family: {} right",
        indep.right
    );
    assert!(
        cross.right + 1 >= CROSS_RIGHT,
        "cross-family: {} right",
        cross.right
    );
    // Honesty invariants of the issue: exactly zero.
    assert_eq!(
        all.none_above_floor, 0,
        "{} none verdicts above 2x floor",
        all.none_above_floor
    );
    assert_eq!(
        all.linear_worse, 0,
        "{} linear re-fits worse than nominal",
        all.linear_worse
    );
    // Issue targets met on this subset: place right in >= 90 % of right verdicts, median
    // parameter error <= 10 %.
    assert!(
        10 * all.place_right >= 9 * all.placed,
        "place right in {}/{} right verdicts",
        all.place_right,
        all.placed
    );
    assert!(
        all.param_median <= 0.10,
        "median parameter error {:.3}",
        all.param_median
    );
}

// Measured on the diagnosis of 2026-11-26 (issue 9: drift of integrating models left
// out of every error, the `state_limit` candidate, tentative forward steps and the play partner
// of friction), 46 cases, each run through the release `gap_benchmark` example with the same
// options and length: same 8/8, indep 31/38 (82 %), cross-family 10/15 (67 %), 0 `none`
// verdicts above twice the noise floor, 0 linear re-fits worse than the nominal, place right
// 34/34, median (worst) parameter error 0.1 % (114 %). (Earlier diagnoses of 2026-11-25: indep
// 30/38, cross-family 10/15; indep 28/38, cross-family 9/15.) NOT MET (issue 9 targets):
// >= 95 % overall (here 39/46 = 85 %), >= 90 % cross-family (67 %), worst parameter error
// <= 25 % (114 %). With integrating models fitted drift-free (this test in debug on
// main): same 8/8, indep 31/38, cross-family 11/15, median (worst) parameter error 0.1 %
// (86 %). With the continuous slew, pair backward step, nested pair variants, drivetrain
// partner and the lattice of the logged values (debug on main): unchanged, 8/8, 31/38,
// 11/15 — the cases those fixes turned are not in this rule-chosen subset (full run: 191/203,
// 57/64).
// With the likelihood ratio in the fit's metric, the selected friction on a Stribeck curve and
// Stribeck friction on the driven body relabelled same-family, as the candidate shares its
// law (debug on main): same 8/8, indep 32/38, cross-family 9/12 (the three cases relabelled
// were right; no verdict of the subset differs between the two diagnosis changes).
const SAME_RIGHT: usize = 8;
const INDEP_RIGHT: usize = 32;
const CROSS_RIGHT: usize = 9;
