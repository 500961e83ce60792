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
//! change that loses verdicts drops below them). The targets are NOT yet met and are
//! not asserted here: ≥ 95 % right verdicts overall, ≥ 90 % on the cross-family split, place
//! right in ≥ 90 % of right verdicts, zero `none` verdicts above twice the noise floor, zero
//! linear re-fits worse than the nominal. Raise the thresholds as the diagnosis improves.
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
    let outcomes = run_all(&cases, N, 1, &GapOptions::default(), &|o, _| {
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
    assert!(
        all.none_above_floor <= NONE_ABOVE_FLOOR + 1,
        "{} none verdicts above 2x floor",
        all.none_above_floor
    );
    assert!(
        all.linear_worse <= LINEAR_WORSE + 1,
        "{} linear re-fits worse than nominal",
        all.linear_worse
    );
}

// Measured on the diagnosis of main at 5e6f936 (issue 9 not yet done), 46 cases:
// same 7/8, indep 19/38 (50 %), cross-family 6/15 (40 %), 5 `none` verdicts above twice the
// noise floor, 3 linear re-fits worse than the nominal. NOT MET (issue 9 targets): ≥ 95 %
// overall (here 26/46 = 57 %), ≥ 90 % cross-family (40 %), zero `none` above 2× floor (5),
// zero linear re-fits worse than nominal (3).
const SAME_RIGHT: usize = 7;
const INDEP_RIGHT: usize = 19;
const CROSS_RIGHT: usize = 6;
const NONE_ABOVE_FLOOR: usize = 5;
const LINEAR_WORSE: usize = 3;
