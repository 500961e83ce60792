//! `ferrosid identify` end to end on a known simulated plant: the order, the frequency response
//! of the written model file (evaluated independently in the test) and the continuous poles
//! against the true plant with stated tolerances; JSON fields; option handling (--no-d,
//! --order, --order-range, --stable-margin); the continuous-time warning; byte-identical reruns.
mod cli_support;
use cli_support::{discrete_response, ferrosid, logspace, rows, s, scratch, write_csv, Rng};
use ferrosid::lti::{poly_mul, StateSpace, StateSpaceData, TransferFunction};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

const TS: f64 = 1e-3;
/// Real pole of the reference plant, Hz.
const F_REAL: f64 = 5.0;
/// Resonance of the reference plant, Hz, and its damping ratio.
const F_RES: f64 = 40.0;
const ZETA: f64 = 0.05;

/// The reference plant G(s) = a·ωn² / ((s + a)(s² + 2ζωn s + ωn²)), a = 2π·5 rad/s,
/// ωn = 2π·40 rad/s, ζ = 0.05 (unit DC gain), discretised by ZOH at 1 kHz.
fn plant() -> StateSpace {
    let a = 2.0 * PI * F_REAL;
    let wn = 2.0 * PI * F_RES;
    TransferFunction::new(
        vec![a * wn * wn],
        poly_mul(&[1.0, a], &[1.0, 2.0 * ZETA * wn, wn * wn]),
        0.0,
    )
    .and_then(|tf| tf.to_state_space())
    .and_then(|g| g.c2d_zoh(TS))
    .expect("reference plant")
}

/// Simulates `sys` on white Gaussian input (seeded) and adds white output noise of
/// `noise_rel` times the noise-free output's standard deviation.
fn experiment(sys: &StateSpace, n: usize, seed: u64, noise_rel: f64) -> (Vec<f64>, Vec<f64>) {
    let mut rng = Rng::new(seed);
    let u = rng.noise(n, 1.0);
    let y0 = sys.simulate_siso(&u, None).expect("simulate");
    let m = y0.iter().sum::<f64>() / n as f64;
    let sd = (y0.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n as f64).sqrt();
    let y = y0
        .iter()
        .map(|v| v + noise_rel * sd * rng.normal())
        .collect();
    (u, y)
}

fn logs(dir: &Path) -> (PathBuf, PathBuf) {
    let g = plant();
    let (u, y) = experiment(&g, 10_000, 1, 0.02);
    let est = dir.join("est.csv");
    write_csv(&est, TS, &u, &y);
    let (u, y) = experiment(&g, 5_000, 2, 0.02);
    let val = dir.join("val.csv");
    write_csv(&val, TS, &u, &y);
    (est, val)
}

fn json(stdout: &str) -> serde_json::Value {
    serde_json::from_str(stdout).expect("--json output parses")
}

fn model_file(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("model file")).expect("model JSON")
}

#[test]
fn recovers_order_frequency_response_and_poles_of_a_known_plant() {
    let d = scratch("known");
    let (est, val) = logs(&d);
    let out = d.join("model.json");
    let r = ferrosid(&[
        "identify",
        s(&est),
        "--validate",
        s(&val),
        "--crossover-hz",
        "10",
        "--json",
        "--out",
        s(&out),
    ]);
    assert_eq!(r.code, 0, "{}\n{}", r.stderr, r.stdout);
    let v = json(&r.stdout);
    assert_eq!(v["command"], "identify");
    assert_eq!(
        v["n4sid"]["order"], 3,
        "order: {}",
        v["n4sid"]["order_reason"]
    );
    assert!(v["n4sid"]["order_reason"]
        .as_str()
        .is_some_and(|t| !t.is_empty()));
    assert_eq!(
        v["n4sid"]["singular_values"].as_array().map(Vec::len),
        Some(20),
        "i·p singular values"
    );
    assert_eq!(v["ts"], TS);
    assert_eq!(v["estimation_samples"], 10_000);
    // Mean removal is recorded for the estimation and the validation log.
    assert_eq!(v["preprocessing"][0]["steps"][0]["step"], "remove_mean");
    assert_eq!(
        v["validation"]["preprocessing"]["steps"][0]["step"],
        "remove_mean"
    );
    assert_eq!(v["validation"]["data"], s(&val));
    // 2 % output noise: the free-run fit on fresh data is bounded by 100·(1 − 0.02) = 98 %.
    let fit = v["validation"]["fit"]["fit_percent"][0]
        .as_f64()
        .expect("fit");
    assert!(fit > 97.0, "fit {fit} %");
    assert_eq!(v["phase_checklist_passed"], true);
    let cmp = &v["validation"]["phase"][0]["comparison"];
    assert!(cmp["bins"].as_array().is_some_and(|b| !b.is_empty()));
    assert_eq!(cmp["f_max_hz"], 20.0);
    assert!(v["validation"]["residuals"]["whiteness_ok"].is_boolean());

    // The model file: exactly {a, b, c, d, ts} plus the operating point it was identified at
    // (issue 10), readable as a StateSpaceData.
    let m = model_file(&out);
    let mut keys: Vec<&str> = m
        .as_object()
        .expect("object")
        .keys()
        .map(String::as_str)
        .collect();
    keys.sort_unstable();
    assert_eq!(keys, ["a", "b", "c", "d", "operating_point", "ts"]);
    let data: StateSpaceData =
        serde_json::from_value(m.clone()).expect("model file is a StateSpaceData");
    assert!(StateSpace::try_from(&data).is_ok());
    assert_eq!(
        m, v["n4sid"]["model"],
        "file and report hold the same model"
    );
    // ... and it is what `ferrosid gap --sim` loads.
    let sim = ferrosid::gap::simfile::load_sim(&out).expect("gap --sim reads the model file");
    assert_eq!((sim.n_states(), sim.ts), (3, TS));

    // Frequency response against the true discrete plant, evaluated by the test's own solver.
    let g = StateSpaceData::from(&plant());
    let (a, b, c, dd) = (rows(&m["a"]), rows(&m["b"]), rows(&m["c"]), rows(&m["d"]));
    let mut worst = 0.0_f64;
    // Grid up to 150 Hz, where the plant is still within 50 dB of its DC gain; above that the
    // white 2 % output noise dominates the high-frequency output and no estimator can pin the
    // relative response.
    for f in logspace(0.5, 150.0, 60) {
        let truth = discrete_response(&g.a, &g.b, &g.c, &g.d, TS, f);
        let id = discrete_response(&a, &b, &c, &dd, TS, f);
        worst = worst.max((id - truth).norm() / truth.norm());
    }
    // Stated tolerance: 3 % relative over 0.5..150 Hz (resonance peak included); 2.24 % on
    // this realisation (2 % held on the one before the generators were unified).
    assert!(worst < 0.03, "worst relative FRF error {worst}");

    // Continuous poles: a real pole at 5 Hz and a 40 Hz pair with ζ = 0.05.
    let poles = v["continuous"]["poles"]
        .as_array()
        .expect("continuous poles");
    assert_eq!(poles.len(), 3);
    let f0 = poles[0]["freq_hz"].as_f64().expect("f");
    assert!((f0 - F_REAL).abs() < 0.03 * F_REAL, "real pole {f0} Hz");
    for p in &poles[1..] {
        let f = p["freq_hz"].as_f64().expect("f");
        let z = p["damping"].as_f64().expect("ζ");
        assert!((f - F_RES).abs() < 0.01 * F_RES, "resonance {f} Hz");
        assert!((z - ZETA).abs() < 0.01, "damping {z}");
    }
}

#[test]
fn text_report_shows_singular_values_reason_and_checklist() {
    let d = scratch("text");
    let (est, val) = logs(&d);
    let r = ferrosid(&[
        "identify",
        s(&est),
        "--validate",
        s(&val),
        "--crossover-hz",
        "10",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    for needle in [
        "singular value",
        "<- chosen order",
        "continuous-time equivalent",
        "simulation fit y:",
        "phase checklist (+-5 deg) PASS",
        "residual tests",
        "removed means:",
    ] {
        assert!(
            r.stdout.contains(needle),
            "missing `{needle}`:\n{}",
            r.stdout
        );
    }
}

#[test]
fn phase_checklist_failure_exits_with_1() {
    // A 1° bound cannot be met by every bin up to 2 × 45 Hz with 2 % noise: exit 1.
    let d = scratch("checkfail");
    let (est, val) = logs(&d);
    let r = ferrosid(&[
        "identify",
        s(&est),
        "--validate",
        s(&val),
        "--crossover-hz",
        "45",
        "--phase-tol",
        "0.01",
    ]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert!(r.stdout.contains("FAIL"));
}

#[test]
fn order_options_no_d_and_stability_margin() {
    let d = scratch("options");
    let (est, _) = logs(&d);
    let r = ferrosid(&["identify", s(&est), "--order", "5", "--json"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let v = json(&r.stdout);
    assert_eq!(v["n4sid"]["order"], 5);
    assert_eq!(v["validation"]["data"], "estimation data");

    let r = ferrosid(&["identify", s(&est), "--order-range", "4..6", "--json"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let n = json(&r.stdout)["n4sid"]["order"].as_u64().expect("order");
    assert!((4..=6).contains(&n), "order {n}");

    let r = ferrosid(&["identify", s(&est), "--no-d", "--json"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let v = json(&r.stdout);
    assert_eq!(v["n4sid"]["model"]["d"][0][0], 0.0);
    assert_eq!(v["options"]["estimate_d"], false);

    // --d-auto: the plant is strictly proper, so D is dropped unless the noise makes the
    // estimate look significant (5 % chance); either way the flag and the model agree.
    let r = ferrosid(&["identify", s(&est), "--d-auto", "--json"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let v = json(&r.stdout);
    assert_eq!(v["options"]["d_significance"], 2.0);
    let dropped = v["n4sid"]["d_fixed_by_test"]
        .as_bool()
        .expect("d_fixed_by_test");
    assert_eq!(dropped, v["n4sid"]["model"]["d"][0][0] == 0.0);
    let r = ferrosid(&["identify", s(&est), "--d-auto", "--no-d"]);
    assert_eq!(r.code, 2, "conflicting D options must be a usage error");

    // The plant's resonance sits at |z| ≈ 0.9875; a margin of 0.05 forces |z| <= 0.95.
    let r = ferrosid(&["identify", s(&est), "--stable-margin", "0.05", "--json"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let v = json(&r.stdout);
    assert_eq!(v["n4sid"]["stability_enforced"], true);
    for p in v["poles"].as_array().expect("poles") {
        let (re, im) = (p["re"].as_f64().unwrap(), p["im"].as_f64().unwrap());
        assert!((re * re + im * im).sqrt() <= 0.95 + 1e-9, "pole {re} {im}");
    }
    assert!(v["warnings"].as_array().is_some_and(|w| w
        .iter()
        .any(|x| x.as_str().is_some_and(|t| t.contains("n4sid")))));
}

#[test]
fn negative_real_pole_gives_a_continuous_time_warning() {
    // y[k] = −0.6 y[k−1] + u[k−1]: a discrete pole at z = −0.6 has no real matrix logarithm.
    let d = scratch("negpole");
    let mut rng = Rng::new(13);
    let n = 4000;
    let u = rng.noise(n, 1.0);
    let mut y = vec![0.0; n];
    for k in 1..n {
        y[k] = -0.6 * y[k - 1] + u[k - 1];
    }
    for v in y.iter_mut() {
        *v += 0.01 * rng.normal();
    }
    let p = d.join("neg.csv");
    write_csv(&p, TS, &u, &y);
    let r = ferrosid(&["identify", s(&p), "--order", "1", "--json"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let v = json(&r.stdout);
    let z = v["poles"][0]["re"].as_f64().expect("pole");
    assert!((z + 0.6).abs() < 0.01, "pole {z}");
    assert!(v["continuous"].is_null());
    assert!(v["warnings"].as_array().is_some_and(|w| w.iter().any(|x| x
        .as_str()
        .is_some_and(|t| t.contains("no continuous-time equivalent")))));
}

#[test]
fn reruns_are_byte_identical() {
    let d = scratch("rerun");
    let (est, val) = logs(&d);
    for json_flag in [false, true] {
        let mut outs = Vec::new();
        for k in 0..2 {
            let out = d.join(format!("m{k}.json"));
            let mut args = vec![
                "identify",
                s(&est),
                "--validate",
                s(&val),
                "--crossover-hz",
                "10",
            ];
            let out_s = s(&out).to_string();
            args.extend(["--out", &out_s]);
            if json_flag {
                args.push("--json");
            }
            let r = ferrosid(&args);
            assert_eq!(r.code, 0, "{}", r.stderr);
            outs.push((r.stdout_bytes, std::fs::read(&out).expect("model file")));
        }
        // The model-file path differs between the runs and is named in the report; compare
        // with it replaced.
        let norm = |b: &[u8], k: usize| {
            String::from_utf8_lossy(b).replace(s(&d.join(format!("m{k}.json"))), "MODEL")
        };
        assert_eq!(norm(&outs[0].0, 0), norm(&outs[1].0, 1), "json {json_flag}");
        assert_eq!(outs[0].1, outs[1].1, "model file");
    }
}

/// A stage K_f/(m s² + c s + k) (m = 0.5 kg, c = 2 N·s/m, k = 800 N/m, K_f = 4 N/A: 6.4 Hz,
/// ζ = 0.05) built as a transfer function (not through the grey-box structure's state space),
/// ZOH at 1 kHz, random-level input held 20 samples, 0.5 % output noise.
fn stage_log(dir: &Path) -> PathBuf {
    let (m, c, k, kf) = (0.5, 2.0, 800.0, 4.0);
    let g = TransferFunction::new(vec![kf], vec![m, c, k], 0.0)
        .and_then(|tf| tf.to_state_space())
        .and_then(|g| g.c2d_zoh(TS))
        .expect("stage");
    let mut rng = Rng::new(11);
    let n = 4000;
    let mut u = Vec::with_capacity(n);
    let mut level = 0.0;
    for i in 0..n {
        if i % 20 == 0 {
            level = rng.normal();
        }
        u.push(level);
    }
    let y0 = g.simulate_siso(&u, None).expect("simulate");
    let sd = (y0.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
    let y: Vec<f64> = y0.iter().map(|v| v + 0.005 * sd * rng.normal()).collect();
    let path = dir.join("stage.csv");
    write_csv(&path, TS, &u, &y);
    path
}

/// `--structure stage --known Kf=4`: m, c, k within 2 % and 4 standard deviations of the truth, in the text table, the JSON report and the --params-out file.
#[test]
fn structure_prints_and_writes_physical_parameters() {
    let d = scratch("structure");
    let log = stage_log(&d);
    let params = d.join("params.json");
    let r = ferrosid(&[
        "identify",
        s(&log),
        "--order",
        "2",
        "--structure",
        "stage",
        "--known",
        "Kf=4",
        "--params-out",
        s(&params),
        "--json",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let v = json(&r.stdout);
    let from_file: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&params).expect("params file"))
            .expect("params json");
    assert_eq!(v["physical"], from_file);
    for (name, truth, status) in [
        ("m", 0.5, "estimated"),
        ("c", 2.0, "estimated"),
        ("k", 800.0, "estimated"),
        ("Kf", 4.0, "known"),
    ] {
        let p = from_file["parameters"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["name"] == name)
            .expect(name);
        assert_eq!(p["status"], status, "{name}");
        let val = p["value"].as_f64().unwrap();
        assert!(
            (val / truth - 1.0).abs() < 0.02,
            "{name} = {val}, truth {truth}"
        );
        if status == "estimated" {
            // One realisation: the truth within 4 standard deviations (a 95 % interval
            // misses by design 1 time in 20; its calibration is greybox_coverage's job).
            let lo = p["interval"][0].as_f64().unwrap();
            let hi = p["interval"][1].as_f64().unwrap();
            let sd = p["std_dev"].as_f64().unwrap();
            assert!(
                lo < val && val < hi && sd > 0.0,
                "{name}: [{lo}, {hi}], {val}"
            );
            assert!(
                (val - truth).abs() < 4.0 * sd,
                "{name} = {val} ± {sd}, truth {truth}"
            );
        }
    }
    assert_eq!(from_file["parameters"][0]["unit"], "kg");
    let t = ferrosid(&[
        "identify",
        s(&log),
        "--order",
        "2",
        "--structure",
        "stage",
        "--known",
        "Kf=4",
    ]);
    assert_eq!(t.code, 0, "{}", t.stderr);
    for needle in [
        "physical parameters (stage; 95 % intervals",
        "N·s/m",
        "estimated",
        "known",
    ] {
        assert!(
            t.stdout.contains(needle),
            "missing `{needle}`:\n{}",
            t.stdout
        );
    }
}

/// Unknown structure, unknown parameter name, a malformed --known, and a request the data
/// cannot answer (no known parameter for a stage): usage errors (exit 2) naming the problem,
/// before any log is read (the log path does not exist).
#[test]
fn structure_bad_input_is_refused_clearly() {
    let d = scratch("structure-bad");
    let log = stage_log(&d);
    for (args, needle) in [
        (vec!["--structure", "three-mass"], "unknown structure"),
        (
            vec!["--structure", "stage", "--known", "mass=1"],
            "has no parameter of that name (it has m, c, k, Kf)",
        ),
        (vec!["--structure", "stage", "--known", "m"], "NAME=VALUE"),
        (
            vec!["--structure", "stage", "--known", "m=-1"],
            "must be finite and > 0",
        ),
        (
            vec!["--structure", "stage"],
            "give one of Kf, m, k with --known NAME=VALUE",
        ),
        (
            vec!["--structure", "two-mass", "--known", "c=0.1"],
            "give one of Kt, Jm, Jl",
        ),
    ] {
        for path in [s(&log), "does-not-exist.csv"] {
            let mut a = vec!["identify", path];
            a.extend(&args);
            let r = ferrosid(&a);
            assert_eq!(r.code, 2, "{args:?}: {}", r.stderr);
            assert!(r.stderr.contains(needle), "{args:?}: {}", r.stderr);
        }
    }
}
