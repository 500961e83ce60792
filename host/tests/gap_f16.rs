//! `ferrosid gap` on the F-16 ground-vibration benchmark (../shared/data/f16-gvt, see its
//! docs/gap-benchmark.md), as a new user would run it: the nominal is ferrosid's own order-8 N4SID model of
//! Level 1 (`identify --order 8 --out`), Levels 1 and 7 train, Level 4 validates; output the
//! wing acceleration next to the interface (`Acceleration2`) and the payload acceleration
//! (`Acceleration3`).
//!
//! What is known about the structure (the benchmark's own description): friction and clearance
//! in the wing-to-payload interface make the low modes (about 7.3 Hz) shift and change damping
//! with the force level. None of the candidate effects (all single-input, at the shaker or the
//! sensor) is that mechanism, so the honest verdict is `unexplained` with that evidence — never
//! `none` with a third of the output unexplained. Pinned, independently of the tool's choices:
//! * the noise floor comes from the period-to-period scatter (the multisines repeat 9 times);
//! * the linear model's gap is more than twice the floor, so `none` would be dishonest;
//! * the verdict is not `none`; when it is `unexplained` the evidence shows amplitude
//!   dependence with a significant shift of a mode between 6.5 and 10 Hz (the interface modes);
//! * the ranked residual bands lie where the shaker force has power (2–15 Hz), not in the
//!   60 fragments from 0.1 to 165 Hz the multiplicative-error runs used to list;
//! * the linear model is not worse than the nominal on the validation log.
//!
//! The data are read in place; when ../shared/data is absent the test prints a notice and
//! returns.
mod cli_support;
use crate::shared_data::shared_data;
use cli_support::{ferrosid, s, scratch};
use serde_json::Value;

fn diagnose_output(output: &str) -> Option<Value> {
    let dir = shared_data("f16-gvt", "the F-16 gap test")?;
    let f = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let (l1, l7, l4) = (
        f("F16Data_FullMSine_Level1.csv"),
        f("F16Data_FullMSine_Level7.csv"),
        f("F16Data_FullMSine_Level4_Validation.csv"),
    );
    let work = scratch(&format!("f16-{output}"));
    let sim = work.join("f16.json");
    // The channels and rate of the F-16 files, for both commands.
    let signals = ["--fs", "400", "--input", "Force", "--output", output];
    let r = ferrosid(
        &[
            &["identify", &l1][..],
            &signals,
            &["--order", "8", "--out", s(&sim)],
        ]
        .concat(),
    );
    assert!(r.code == 0 || r.code == 1, "identify failed: {}", r.stderr);
    let r = ferrosid(
        &[
            &[
                "gap",
                "--sim",
                s(&sim),
                "--real",
                &l1,
                "--real",
                &l7,
                "--validate",
                &l4,
            ][..],
            &signals,
            &["--json"],
        ]
        .concat(),
    );
    assert_eq!(r.code, 0, "gap failed: {}", r.stderr);
    Some(serde_json::from_str(&r.stdout).expect("JSON report"))
}

fn check(v: &Value, output: &str) {
    let g = |k: &str| v[k].as_f64().unwrap();
    let (before, linear, after) = (g("gap_before"), g("gap_linear"), g("gap_after"));
    let floor = v["noise_floor"]["nrmse"].as_f64().unwrap();
    let verdict = v["verdict"].as_str().unwrap();
    println!(
        "F-16 {output}: verdict {verdict}, gaps {before:.4} -> {linear:.4} -> {after:.4}, noise \
         floor {floor:.4}"
    );
    assert_eq!(v["noise_floor"]["method"], "periodic_scatter");
    assert_eq!(v["noise_floor"]["period_samples"], 8192);
    assert!(linear <= before * (1.0 + 1e-9), "{linear} > {before}");
    assert!(after <= linear * (1.0 + 1e-12));
    assert!(linear > 2.0 * floor, "linear {linear} floor {floor}");
    assert_ne!(verdict, "none");
    let ev = &v["evidence"];
    if verdict == "unexplained" {
        assert_eq!(ev["amplitude_dependent"], true);
        let shifts = ev["mode_shifts"].as_array().unwrap();
        assert!(
            shifts.iter().any(|m| m["significant"] == true
                && (6.5..10.0).contains(&m["freq_low_hz"].as_f64().unwrap())),
            "{shifts:?}"
        );
    }
    let bands = v["where"]["bands"].as_array().unwrap();
    assert!(!bands.is_empty() && bands.len() <= 5, "{bands:?}");
    for b in bands {
        let (lo, hi) = (b["lo_hz"].as_f64().unwrap(), b["hi_hz"].as_f64().unwrap());
        assert!(
            lo >= 1.5 && hi <= 15.5,
            "band {lo}..{hi} outside the excited 2-15 Hz"
        );
    }
    for b in v["where"]["bands_hz"].as_array().unwrap() {
        let hi = b[1].as_f64().unwrap();
        assert!(hi <= 16.0, "multiplicative-error band up to {hi} Hz");
    }
}

#[test]
fn f16_wing_acceleration_is_unexplained_not_none() {
    if let Some(v) = diagnose_output("Acceleration2") {
        check(&v, "Acceleration2");
    }
}

#[test]
fn f16_payload_acceleration_is_unexplained_not_none() {
    if let Some(v) = diagnose_output("Acceleration3") {
        check(&v, "Acceleration3");
    }
}
