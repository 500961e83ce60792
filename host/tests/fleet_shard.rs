//! `ferrosid fleet --shard K/N` and `ferrosid fleet merge` on the example fleet
//! (examples/fleet, six two-mass actuators, one of them faulty): the shards partition the
//! units, and merging every shard's fleet.json gives the summary of the unsharded run —
//! units, distributions, physical parameters and outlier flags — whatever the number of
//! shards; incomplete, repeated or foreign shards are refused with the file named.
mod pipeline_support;

use ferrosid::fleet::shard::read_summary;
use ferrosid::fleet::{merge_summaries, run_fleet, FleetOptions, FleetSummary, Shard};
use ferrosid::pipeline::physical_stage::PhysicalConfig;
use ferrosid::pipeline::LoadedConfig;
use pipeline_support as sup;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn fleet_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/fleet")
}

fn two_mass() -> PhysicalConfig {
    PhysicalConfig {
        structure: "two-mass".into(),
        known: [("Kt".to_string(), 1.0)].into(),
        confidence: None,
        run: None,
    }
}

/// The summary as JSON without the per-unit output directories (they differ between runs
/// written to different places).
fn comparable(s: &FleetSummary) -> Value {
    let mut v = serde_json::to_value(s).expect("json");
    for u in v["units"].as_array_mut().expect("units") {
        u.as_object_mut().expect("unit").remove("out_dir");
    }
    v
}

/// Runs shard k of n into `out/k` and returns the fleet.json path written.
fn run_shard(template: &LoadedConfig, out: &Path, k: usize, n: usize) -> PathBuf {
    let dir = out.join(format!("{k}"));
    let s = run_fleet(
        &fleet_dir(),
        template,
        &FleetOptions {
            out_dir: Some(dir.clone()),
            physical: Some(two_mass()),
            shard: Some(Shard { index: k, count: n }),
            jobs: None,
        },
        &|_| {},
    )
    .expect("shard");
    assert_eq!(
        s.shard.map(|i| (i.index, i.count, i.units_total)),
        Some((k, n, 6))
    );
    dir.join("fleet.json")
}

#[test]
fn merged_shards_equal_the_unsharded_fleet() {
    let template = LoadedConfig::load(&fleet_dir().join("pipeline.toml")).expect("template");
    let whole = run_fleet(
        &fleet_dir(),
        &template,
        &FleetOptions {
            physical: Some(two_mass()),
            ..FleetOptions::default()
        },
        &|_| {},
    )
    .expect("fleet");
    assert!(whole.shard.is_none());
    assert!(!whole.outliers.is_empty(), "the faulty unit is flagged");
    let out = sup::scratch("fleet-shards");
    // Three shards: 2 units each, dealt round-robin.
    let files: Vec<PathBuf> = (1..=3).map(|k| run_shard(&template, &out, k, 3)).collect();
    let shards: Vec<FleetSummary> = files
        .iter()
        .map(|f| read_summary(f).expect("read"))
        .collect();
    let serials: Vec<Vec<&str>> = shards
        .iter()
        .map(|s| s.units.iter().map(|u| u.serial.as_str()).collect())
        .collect();
    assert_eq!(
        serials,
        [
            ["SN0001", "SN0004"],
            ["SN0002", "SN0005"],
            ["SN0003", "SN0006"]
        ]
    );
    // A shard alone has too few units to judge a spread: the merge must recompute it.
    assert!(shards.iter().all(|s| s.outliers.is_empty()));
    // Given in any order.
    let order = [2, 0, 1];
    let merged = merge_summaries(
        &order.map(|i| files[i].clone()),
        order.map(|i| shards[i].clone()).to_vec(),
    )
    .expect("merge");
    assert!(merged.shard.is_none());
    assert_eq!(comparable(&merged), comparable(&whole));

    // Refused: a missing shard, a repeated one, a shard of another split, a whole fleet.
    let err = merge_summaries(&files[..2], shards[..2].to_vec()).unwrap_err();
    assert!(
        err.to_string().contains("missing from the merge: 3/3"),
        "{err}"
    );
    let twice = vec![shards[0].clone(), shards[1].clone(), shards[0].clone()];
    let paths = [files[0].clone(), files[1].clone(), files[0].clone()];
    let err = merge_summaries(&paths, twice).unwrap_err();
    assert!(err.to_string().contains("shard 1/3 given twice"), "{err}");
    let mut other = shards[2].clone();
    other.shard.as_mut().expect("shard").count = 4;
    let err = merge_summaries(&files, vec![shards[0].clone(), shards[1].clone(), other])
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("does not belong") && err.contains("3/fleet.json"),
        "{err}"
    );
    let err = merge_summaries(&files[..1], vec![whole.clone()]).unwrap_err();
    assert!(err.to_string().contains("not a shard summary"), "{err}");
}

#[test]
fn cli_shard_and_merge() {
    let exe = env!("CARGO_BIN_EXE_ferrosid");
    let out = sup::scratch("fleet-cli-shards");
    // Two shards of three units through the command line (no physical fit: quicker).
    for k in 1..=2 {
        let st = Command::new(exe)
            .args(["fleet", fleet_dir().to_str().unwrap(), "--json", "--shard"])
            .arg(format!("{k}/2"))
            .arg("--out")
            .arg(out.join(format!("s{k}")))
            .output()
            .expect("run");
        // SN0004 fails a receipt (exit 1) and is in shard 2; shard 1 passes.
        assert_eq!(st.status.code(), Some(if k == 1 { 0 } else { 1 }), "{st:?}");
        let v: Value = serde_json::from_slice(&st.stdout).expect("json");
        assert_eq!(v["shard"]["index"], k);
        assert_eq!(v["units"].as_array().unwrap().len(), 3);
    }
    let st = Command::new(exe)
        .args(["fleet", "merge", "--json"])
        .arg(out.join("s2"))
        .arg(out.join("s1/fleet.json"))
        .arg("--out")
        .arg(out.join("merged"))
        .output()
        .expect("merge");
    assert_eq!(
        st.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let merged: Value = serde_json::from_slice(&st.stdout).expect("json");
    let serials: Vec<&str> = merged["units"]
        .as_array()
        .unwrap()
        .iter()
        .map(|u| u["serial"].as_str().unwrap())
        .collect();
    assert_eq!(
        serials,
        ["SN0001", "SN0002", "SN0003", "SN0004", "SN0005", "SN0006"]
    );
    assert!(merged.get("shard").is_none());
    let written: Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("merged/fleet.json")).expect("fleet.json"),
    )
    .expect("json");
    assert_eq!(written, merged);
    // A shard missing and a bad --shard are errors with the documented exit codes.
    let st = Command::new(exe)
        .args(["fleet", "merge"])
        .arg(out.join("s1"))
        .output()
        .expect("merge");
    assert_eq!(st.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&st.stderr).contains("2/2"));
    let st = Command::new(exe)
        .args(["fleet", fleet_dir().to_str().unwrap(), "--shard", "3/2"])
        .output()
        .expect("run");
    assert_eq!(st.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&st.stderr).contains("--shard"));
}
