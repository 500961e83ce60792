//! Stiction on a Stribeck curve, end to end on the independent simulator's logs: the diagnosis
//! reads the static level (the law's f_s) and the Coulomb level within 10 % on Stribeck and
//! LuGre friction (a Karnopp switch read them 55–87 % off), and keeps no Stribeck curve where
//! the law has none (Karnopp friction with a stick band).
use ferrosid::gap::GapOptions;
use ferrosid_gapsim::bench::{all_cases, run_case};
use serde_json::Value;

/// The verdict's stiction parameters of the independent case `id` (16,384 samples per log).
fn stiction_of(id: &str) -> (bool, Vec<(String, f64)>, Value) {
    let case = all_cases("indep")
        .into_iter()
        .find(|c| c.id() == id)
        .unwrap_or_else(|| panic!("no case {id}"));
    let (o, report) = run_case(&case, 16_384, &GapOptions::default());
    let report = report.expect("diagnosis ran");
    let params = report["verdict_effects"]
        .as_array()
        .and_then(|v| v.iter().find(|e| e["effect"] == "stiction"))
        .map(|e| e["params"].clone())
        .unwrap_or(Value::Null);
    (o.verdict_right, o.param_errors, params)
}

#[test]
fn stribeck_and_lugre_breakaways_are_read_on_their_curve() {
    for id in [
        "indep/dc_motor/stribeck/1",
        "indep/flexure/stribeck/1",
        "indep/dc_motor/lugre/0",
    ] {
        let (right, errors, params) = stiction_of(id);
        assert!(right, "{id}: verdict");
        assert!(
            params["stribeck_velocity"]
                .as_f64()
                .is_some_and(|v| v > 0.0),
            "{id}: no Stribeck curve in {params}"
        );
        for (name, e) in &errors {
            assert!(*e <= 0.10, "{id}: {name} off by {:.1} %", 100.0 * e);
        }
    }
}

#[test]
fn karnopp_friction_keeps_no_stribeck_curve() {
    let id = "indep/dc_motor/karnopp/0";
    let (right, errors, params) = stiction_of(id);
    assert!(right, "{id}: verdict");
    assert!(
        params.get("stribeck_velocity").is_none(),
        "{id}: a Stribeck curve on a Karnopp law: {params}"
    );
    for (name, e) in &errors {
        assert!(*e <= 0.05, "{id}: {name} off by {:.1} %", 100.0 * e);
    }
}
