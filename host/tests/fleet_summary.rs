//! `ferrosid fleet` on the generated example fleet (examples/fleet, six two-mass actuators
//! with known parameters in units.json): the identified resonances and their spread match the
//! generating parameters, the bad unit is caught, results do not depend on the thread count,
//! and the file-prefix layout gives the same numbers as the subdirectory layout.
mod pipeline_support;

use ferrosid::fleet::{discover_units, run_fleet, FleetOptions, Layout};
use ferrosid::pipeline::LoadedConfig;
use pipeline_support as sup;
use serde_json::Value;
use std::path::{Path, PathBuf};

fn fleet_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/fleet")
}

/// Resonance (Hz) of a two-mass actuator from its parameters: the complex root of
/// det(sI − A) for A = [[0, 1, −1], [−k/jm, −(c+bm)/jm, c/jm], [k/jl, c/jl, −(c+bl)/jl]]
/// (characteristic polynomial s³ − tr(A)s² + (Σ principal 2×2 minors)s − det A).
fn true_resonance(u: &Value) -> f64 {
    let g = |k: &str| u[k].as_f64().unwrap_or_else(|| panic!("{k}"));
    let (jm, jl, k, c, bm, bl) = (g("jm"), g("jl"), g("k"), g("c"), g("bm"), g("bl"));
    let a = [
        [0.0, 1.0, -1.0],
        [-k / jm, -(c + bm) / jm, c / jm],
        [k / jl, c / jl, -(c + bl) / jl],
    ];
    let tr = a[0][0] + a[1][1] + a[2][2];
    let m2 = (a[0][0] * a[1][1] - a[0][1] * a[1][0])
        + (a[0][0] * a[2][2] - a[0][2] * a[2][0])
        + (a[1][1] * a[2][2] - a[1][2] * a[2][1]);
    let det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
        - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    let modes = sup::oscillatory_modes(&[1.0, -tr, m2, -det]);
    assert_eq!(modes.len(), 1, "{modes:?}");
    modes[0].0
}

fn mean_std(v: &[f64]) -> (f64, f64) {
    let m = v.iter().sum::<f64>() / v.len() as f64;
    let s = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt();
    (m, s)
}

#[test]
fn fleet_resonance_spread_matches_the_generated_fleet() {
    let dir = fleet_dir();
    if !dir.join("units.json").is_file() {
        panic!("examples/fleet is missing: regenerate with `cargo run --release -p ferrosid-sim --example make_example_fleet`");
    }
    let truth: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("units.json")).expect("units"))
            .expect("units.json");
    let units = truth["units"].as_array().expect("units");
    let template = LoadedConfig::load(&dir.join("pipeline.toml")).expect("template");
    let (layout, serials) = discover_units(&dir).expect("units");
    assert_eq!(layout, Layout::Subdirectories);
    assert_eq!(serials.len(), units.len());

    let out = sup::scratch("fleet-out");
    let s1 = run_fleet(
        &dir,
        &template,
        &FleetOptions {
            jobs: Some(2),
            out_dir: Some(out.clone()),
            ..FleetOptions::default()
        },
        &|_| {},
    )
    .expect("fleet");
    assert_eq!(s1.units.len(), 6);
    assert_eq!(s1.units_error, 0);

    let mut est = Vec::new();
    let mut tru = Vec::new();
    for (u, t) in s1.units.iter().zip(units) {
        assert_eq!(u.serial, t["serial"].as_str().expect("serial"));
        let f_true = true_resonance(t);
        let osc = u.oscillatory();
        assert_eq!(osc.len(), 1, "{}: {:?}", u.serial, u.modes);
        let f = osc[0].natural_hz;
        // Each unit's resonance within 1.5 % of its generating parameters.
        assert!(
            (f - f_true).abs() < 0.015 * f_true,
            "{}: {f} Hz vs {f_true} Hz",
            u.serial
        );
        est.push(f);
        tru.push(f_true);
        assert!(out.join(&u.serial).join("receipts.json").is_file());
    }
    // The spread across serial numbers: mean within 1 %, standard deviation within 25 %.
    let (me, se) = mean_std(&est);
    let (mt, st) = mean_std(&tru);
    assert!((me - mt).abs() < 0.01 * mt, "mean {me} vs {mt}");
    assert!((se - st).abs() < 0.25 * st, "std {se} vs {st}");
    let d = s1
        .parameters
        .iter()
        .find(|d| d.parameter == "mode1_natural_frequency")
        .expect("distribution");
    assert_eq!(d.count, 6);
    assert!((d.mean - me).abs() < 1e-12 && (d.std - se).abs() < 1e-12);
    let lo = est.iter().copied().fold(f64::INFINITY, f64::min);
    assert_eq!(d.min, lo);

    // The unit with Coulomb friction (units.json) fails the amplitude audit; the linear units
    // pass it.
    for (u, t) in s1.units.iter().zip(units) {
        let friction = t["coulomb"].as_f64().expect("coulomb") > 0.0;
        let audit_failed = u.failed.iter().any(|n| n.starts_with("audit_"));
        assert_eq!(
            audit_failed, friction,
            "{}: failed {:?}",
            u.serial, u.failed
        );
    }
    assert!(!s1.all_pass());
    let fleet_json = std::fs::read_to_string(out.join("fleet.json")).expect("fleet.json");
    assert!(fleet_json.contains("\"schema\": \"ferrosid.fleet/1\""));

    // One thread gives the same summary (order and numbers) as two.
    let s2 = run_fleet(
        &dir,
        &template,
        &FleetOptions {
            jobs: Some(1),
            out_dir: None,
            ..FleetOptions::default()
        },
        &|_| {},
    )
    .expect("fleet, one job");
    let j1 = serde_json::to_value(&s1.parameters).expect("json");
    let j2 = serde_json::to_value(&s2.parameters).expect("json");
    assert_eq!(j1, j2);
}

#[test]
fn prefix_layout_matches_subdirectory_layout() {
    let src = fleet_dir();
    let flat = sup::scratch("fleet-prefix");
    for serial in ["SN0001", "SN0002"] {
        for f in ["low.csv", "high.csv"] {
            std::fs::copy(src.join(serial).join(f), flat.join(format!("{serial}_{f}")))
                .expect("copy");
        }
    }
    let template = LoadedConfig::load(&src.join("pipeline.toml")).expect("template");
    let (layout, serials) = discover_units(&flat).expect("units");
    assert_eq!(layout, Layout::Prefix);
    assert_eq!(serials, ["SN0001", "SN0002"]);
    let a = run_fleet(&flat, &template, &FleetOptions::default(), &|_| {}).expect("flat");
    let sub = sup::scratch("fleet-sub");
    for serial in ["SN0001", "SN0002"] {
        std::fs::create_dir_all(sub.join(serial)).expect("mkdir");
        for f in ["low.csv", "high.csv"] {
            std::fs::copy(src.join(serial).join(f), sub.join(serial).join(f)).expect("copy");
        }
    }
    let b = run_fleet(&sub, &template, &FleetOptions::default(), &|_| {}).expect("sub");
    for (x, y) in a.units.iter().zip(&b.units) {
        assert_eq!(x.serial, y.serial);
        assert_eq!(x.modes, y.modes);
        assert_eq!(x.passed, y.passed);
    }
}

#[test]
fn fleet_errors_are_per_unit_and_empty_dirs_are_errors() {
    let src = fleet_dir();
    let d = sup::scratch("fleet-broken");
    std::fs::create_dir_all(d.join("SN0001")).expect("mkdir");
    for f in ["low.csv", "high.csv"] {
        std::fs::copy(src.join("SN0001").join(f), d.join("SN0001").join(f)).expect("copy");
    }
    // SN0002 has a corrupt log: its unit reports the error, SN0001 still runs.
    std::fs::create_dir_all(d.join("SN0002")).expect("mkdir");
    std::fs::copy(src.join("SN0002/low.csv"), d.join("SN0002/low.csv")).expect("copy");
    std::fs::write(d.join("SN0002/high.csv"), "u,y\n1,2\n3,x\n").expect("write");
    let template = LoadedConfig::load(&src.join("pipeline.toml")).expect("template");
    let s = run_fleet(&d, &template, &FleetOptions::default(), &|_| {}).expect("fleet");
    assert_eq!(s.units_error, 1);
    let bad = &s.units[1];
    assert_eq!(bad.status, "error");
    let e = bad.error.as_deref().expect("error text");
    assert!(e.contains("high.csv") && e.contains(":3"), "{e}");
    assert_ne!(s.units[0].status, "error");

    let empty = sup::scratch("fleet-empty");
    let err = discover_units(&empty).expect_err("no units");
    assert!(err.to_string().contains("no units found"), "{err}");

    // The command line: exit 1 for a failing unit, 3 without a template.
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_ferrosid"))
        .args(["fleet"])
        .arg(&empty)
        .output()
        .expect("run");
    assert_eq!(st.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&st.stderr).contains("pipeline.toml"));
}

#[test]
fn fleet_output_dirs_are_checked_before_any_unit_is_computed() {
    let src = fleet_dir();
    let d = sup::scratch("fleet-foreign");
    for sn in ["SN0001", "SN0002"] {
        std::fs::create_dir_all(d.join(sn)).expect("mkdir");
        for f in ["low.csv", "high.csv"] {
            std::fs::copy(src.join(sn).join(f), d.join(sn).join(f)).expect("copy");
        }
    }
    // The user keeps a report of their own where the LAST unit's report would go.
    let out = sup::scratch("fleet-foreign-out");
    std::fs::create_dir_all(out.join("SN0002")).expect("mkdir");
    let mine = out.join("SN0002/report.html");
    std::fs::write(&mine, "<p>my notes</p>").expect("write");
    let template = LoadedConfig::load(&src.join("pipeline.toml")).expect("template");
    let computed = std::sync::atomic::AtomicUsize::new(0);
    let opts = FleetOptions {
        out_dir: Some(out.clone()),
        ..FleetOptions::default()
    };
    let err = run_fleet(&d, &template, &opts, &|_| {
        computed.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
    })
    .expect_err("a foreign file in a unit's output directory");
    let msg = err.to_string();
    assert!(
        msg.contains("report.html") && msg.contains("SN0002"),
        "{msg}"
    );
    // Refused before any unit ran: nothing computed, nothing written, the user's file intact.
    assert_eq!(computed.load(std::sync::atomic::Ordering::SeqCst), 0);
    assert!(!out.join("SN0001/report.html").exists());
    assert!(!out.join("fleet.json").exists());
    assert_eq!(std::fs::read_to_string(&mine).unwrap(), "<p>my notes</p>");
    // A fleet.json ferrosid did not write is not replaced either.
    std::fs::remove_file(&mine).unwrap();
    std::fs::write(out.join("fleet.json"), "{\"mine\": true}").unwrap();
    let err = run_fleet(&d, &template, &opts, &|_| {}).expect_err("foreign fleet.json");
    assert!(err.to_string().contains("fleet.json"), "{err}");
    assert_eq!(
        std::fs::read_to_string(out.join("fleet.json")).unwrap(),
        "{\"mine\": true}"
    );
}

/// `--structure two-mass --known Kt=1` on the example fleet (torque in mN·m and speed in
/// mrad/s: the same 1e-3 scale on both sides, so with K_t = 1 every parameter is in SI units):
/// J_m, J_l, k within 3 % of units.json for every unit and b within 3 % of b_m + b_l (the
/// structure has one viscous friction; the motor-side sensor sees the sum on the rigid-body
/// pole). The shaft damping c is not compared: the load-side friction the structure leaves out
/// moves into it. The faulty unit SN0004 (Coulomb friction on the motor) is outside the fleet's
/// spread of b, and no other unit is flagged.
#[test]
fn physical_parameters_match_the_fleet_and_flag_the_faulty_unit() {
    use ferrosid::pipeline::physical_stage::PhysicalConfig;
    let dir = fleet_dir();
    let truth: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("units.json")).expect("units"))
            .expect("units.json");
    let template = LoadedConfig::load(&dir.join("pipeline.toml")).expect("template");
    let s = run_fleet(
        &dir,
        &template,
        &FleetOptions {
            physical: Some(PhysicalConfig {
                structure: "two-mass".into(),
                known: [("Kt".to_string(), 1.0)].into(),
                confidence: None,
                run: None,
            }),
            ..FleetOptions::default()
        },
        &|_| {},
    )
    .expect("fleet");
    for (u, t) in s.units.iter().zip(truth["units"].as_array().unwrap()) {
        assert_eq!(u.serial, t["serial"].as_str().unwrap());
        assert!(
            u.physical_error.is_none(),
            "{}: {:?}",
            u.serial,
            u.physical_error
        );
        let est = |n: &str| u.physical.iter().find(|p| p.name == n).unwrap().value;
        let tv = |n: &str| t[n].as_f64().unwrap();
        if u.serial == "SN0004" {
            continue;
        }
        for (name, want) in [
            ("Jm", tv("jm")),
            ("Jl", tv("jl")),
            ("k", tv("k")),
            ("b", tv("bm") + tv("bl")),
        ] {
            let got = est(name);
            assert!(
                (got / want - 1.0).abs() < 0.03,
                "{} {name}: {got} vs {want}",
                u.serial
            );
        }
    }
    let flagged: Vec<(&str, &str)> = s
        .outliers
        .iter()
        .map(|o| (o.serial.as_str(), o.parameter.as_str()))
        .collect();
    assert!(flagged.contains(&("SN0004", "b")), "{flagged:?}");
    assert!(flagged.iter().all(|(u, _)| *u == "SN0004"), "{flagged:?}");
    assert_eq!(s.physical.len(), 5, "Jm, Jl, k, c, b distributions");
}
