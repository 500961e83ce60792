//! `ferrosid run` end to end on a simulated plant with known dynamics: receipts cross-checked
//! independently, exit codes, byte-identical reruns, and bad pipeline files.
mod pipeline_support;

use ferrosid::output::write_outputs;
use ferrosid::pipeline::{run_pipeline, LoadedConfig};
use pipeline_support as sup;
use serde_json::Value;
use std::f64::consts::PI;
use std::path::Path;
use std::process::Command;

fn ferrosid() -> Command {
    Command::new(env!("CARGO_BIN_EXE_ferrosid"))
}

/// `ferrosid run TOML --out OUT`, waited for.
fn run_to(toml: &Path, out: impl AsRef<std::ffi::OsStr>) -> std::process::Output {
    ferrosid()
        .arg("run")
        .arg(toml)
        .arg("--out")
        .arg(out)
        .output()
        .expect("run ferrosid")
}

fn read_json(p: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(p).expect("read json")).expect("parse json")
}

type C = (f64, f64);
fn cmul(a: C, b: C) -> C {
    (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0)
}
fn cdiv(a: C, b: C) -> C {
    let d = b.0 * b.0 + b.1 * b.1;
    ((a.0 * b.0 + a.1 * b.1) / d, (a.1 * b.0 - a.0 * b.1) / d)
}

/// C (zI − A)⁻¹ B + D by Gaussian elimination with partial pivoting (written here, independent
/// of the library's Hessenberg evaluator).
fn ss_eval(m: &Value, z: C) -> C {
    let rows = |k: &str| -> Vec<Vec<f64>> {
        m[k].as_array()
            .expect("matrix")
            .iter()
            .map(|r| {
                r.as_array()
                    .expect("row")
                    .iter()
                    .map(|v| v.as_f64().expect("num"))
                    .collect()
            })
            .collect()
    };
    let (a, b, c, d) = (rows("a"), rows("b"), rows("c"), rows("d"));
    let n = a.len();
    let mut mat: Vec<Vec<C>> = (0..n)
        .map(|i| {
            let mut r: Vec<C> = (0..n)
                .map(|j| {
                    let diag = if i == j { z } else { (0.0, 0.0) };
                    (diag.0 - a[i][j], diag.1)
                })
                .collect();
            r.push((b[i][0], 0.0));
            r
        })
        .collect();
    for col in 0..n {
        let piv = (col..n)
            .max_by(|&p, &q| {
                let np = mat[p][col].0.hypot(mat[p][col].1);
                let nq = mat[q][col].0.hypot(mat[q][col].1);
                np.total_cmp(&nq)
            })
            .expect("pivot");
        mat.swap(col, piv);
        for r in col + 1..n {
            let f = cdiv(mat[r][col], mat[col][col]);
            let pivot_row = mat[col].clone();
            for (k, p) in pivot_row.iter().enumerate().skip(col) {
                let t = cmul(f, *p);
                mat[r][k] = (mat[r][k].0 - t.0, mat[r][k].1 - t.1);
            }
        }
    }
    let mut x = vec![(0.0, 0.0); n];
    for i in (0..n).rev() {
        let mut s = mat[i][n];
        for k in i + 1..n {
            let t = cmul(mat[i][k], x[k]);
            s = (s.0 - t.0, s.1 - t.1);
        }
        x[i] = cdiv(s, mat[i][i]);
    }
    let mut y = (d[0][0], 0.0);
    for j in 0..n {
        y = (y.0 + c[0][j] * x[j].0, y.1 + c[0][j] * x[j].1);
    }
    y
}

/// A polynomial in z (descending powers) at z.
fn poly(p: &[f64], z: C) -> C {
    let mut acc = (0.0, 0.0);
    for &c in p {
        acc = cmul(acc, z);
        acc.0 += c;
    }
    acc
}

fn receipt<'a>(doc: &'a Value, name: &str) -> &'a Value {
    doc["receipts"]
        .as_array()
        .expect("receipts")
        .iter()
        .find(|r| r["name"] == name)
        .unwrap_or_else(|| panic!("receipt {name} missing"))
}

#[test]
fn known_plant_end_to_end_receipts_cross_checked() {
    let toml = sup::setup("pipeline-known", "", "");
    let dir = toml.parent().expect("dir").to_path_buf();
    let out = dir.join("out");
    let st = run_to(&toml, &out);
    let stdout = String::from_utf8_lossy(&st.stdout);
    assert_eq!(
        st.status.code(),
        Some(0),
        "{stdout}\n{}",
        String::from_utf8_lossy(&st.stderr)
    );
    assert!(stdout.contains("PASS: all"), "{stdout}");
    for f in [
        "receipts.json",
        "model.json",
        "pid.json",
        "wm.json",
        "report.html",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let doc = read_json(&out.join("receipts.json"));
    assert_eq!(doc["schema"], "ferrosid.pipeline.receipts/1");
    assert_eq!(doc["verdict"], "pass");
    let rs = doc["receipts"].as_array().expect("receipts");
    assert_eq!(doc["passed"].as_u64(), Some(rs.len() as u64));
    assert!(rs.iter().all(|r| r["pass"] == true));
    for name in [
        "audit_gain_shift",
        "controller_design",
        "closed_loop_stable",
        "gain_margin",
        "phase_margin",
        "sensitivity_peak",
        "complementary_sensitivity_peak",
        "robust_stability",
        "disturbance_rejection_bandwidth",
        "peak_control_effort",
        "step_actuator_demand",
        "etfe_phase_agreement",
        "cross_validation_fit",
    ] {
        receipt(&doc, name);
    }

    // The identified resonance against the plant's (from its denominator polynomial, roots by
    // Durand–Kerner here): within 1 % in frequency, 20 % in damping.
    let den = sup::plant_tf().den;
    let truth = sup::oscillatory_modes(&den);
    assert_eq!(truth.len(), 1);
    assert!(
        (truth[0].0 - sup::F_RES).abs() < 1e-9 * sup::F_RES,
        "{truth:?}"
    );
    let modes: Vec<&Value> = doc["model"]["modes"]
        .as_array()
        .expect("modes")
        .iter()
        .filter(|m| m["oscillatory"] == true)
        .collect();
    assert_eq!(modes.len(), 1, "{modes:?}");
    let f = modes[0]["natural_hz"].as_f64().expect("f");
    let z = modes[0]["damping"].as_f64().expect("zeta");
    assert!(
        (f - sup::F_RES).abs() < 0.01 * sup::F_RES,
        "resonance {f} Hz"
    );
    assert!(
        (z - sup::ZETA_RES).abs() < 0.2 * sup::ZETA_RES,
        "damping {z}"
    );
    let dc = doc["model"]["dc_gain"].as_f64().expect("dc");
    assert!(
        (dc - sup::DC_GAIN).abs() < 0.02 * sup::DC_GAIN,
        "dc gain {dc}"
    );
    assert_eq!(doc["model"]["order"], 3);

    // M_s recomputed from model.json and the firmware controller in pid.json on a dense grid of
    // the unit circle, with this file's own complex arithmetic: the grid maximum is a lower
    // bound of ‖S‖∞ and, refined around its peak, agrees with the receipt to 1e-4.
    let model = read_json(&out.join("model.json"));
    let pid = read_json(&out.join("pid.json"));
    let disc = &pid["discrete"];
    let num: Vec<f64> = disc["num"]
        .as_array()
        .expect("num")
        .iter()
        .map(|v| v.as_f64().expect("n"))
        .collect();
    let den: Vec<f64> = disc["den"]
        .as_array()
        .expect("den")
        .iter()
        .map(|v| v.as_f64().expect("d"))
        .collect();
    let ts = model["ts"].as_f64().expect("ts");
    let s_mag = |f: f64| -> f64 {
        let w = 2.0 * PI * f * ts;
        let z = (w.cos(), w.sin());
        let g = ss_eval(&model, z);
        let k = cdiv(poly(&num, z), poly(&den, z));
        let l = cmul(g, k);
        1.0 / (1.0 + l.0).hypot(l.1)
    };
    let nyq = 0.5 / ts;
    let (mut best, mut at) = (0.0f64, 0.0);
    for i in 0..20_000 {
        let f = 0.01 * (nyq * 0.9999 / 0.01f64).powf(i as f64 / 19_999.0);
        let v = s_mag(f);
        if v > best {
            best = v;
            at = f;
        }
    }
    for i in 0..=4000 {
        let f = at * (0.98 + 0.04 * i as f64 / 4000.0);
        best = best.max(s_mag(f));
    }
    let ms = receipt(&doc, "sensitivity_peak")["value"]
        .as_f64()
        .expect("ms");
    assert!(
        best <= ms * (1.0 + 1e-9),
        "grid {best} above the H∞ value {ms}"
    );
    assert!(
        (ms - best) / ms < 1e-4,
        "receipt M_s {ms} vs dense grid {best} at {at} Hz"
    );
    assert!(ms <= 1.6 + 1e-12);

    // Validation fit: noise of 0.4 rad/s on a signal of tens of rad/s leaves a fit above 90 %.
    let fit = receipt(&doc, "cross_validation_fit")["value"]
        .as_f64()
        .expect("fit");
    assert!(fit > 90.0, "fit {fit}");

    // model.json is the {"a","b","c","d","ts"} form other commands read, with the operating
    // point of the estimation run (issue 10).
    let keys: Vec<&String> = model.as_object().expect("object").keys().collect();
    assert_eq!(keys, ["a", "b", "c", "d", "operating_point", "ts"]);
}

#[test]
fn reruns_are_byte_identical_from_any_directory() {
    let toml = sup::setup("pipeline-rerun", "", "");
    let dir = toml.parent().expect("dir").to_path_buf();
    let cfg = LoadedConfig::load(&toml).expect("load");
    let a = run_pipeline(&cfg, &|_| {}).expect("run a");
    let written_a = write_outputs(&a, &dir.join("a")).expect("write a");
    let b = run_pipeline(&cfg, &|_| {}).expect("run b");
    write_outputs(&b, &dir.join("b")).expect("write b");
    // The binary started from the data directory with a different relative path.
    let st = ferrosid()
        .current_dir(&dir)
        .args(["run", "pipeline.toml", "--out", "c"])
        .output()
        .expect("run");
    assert_eq!(
        st.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    assert!(written_a.len() >= 10, "{written_a:?}");
    for p in &written_a {
        let rel = p.strip_prefix(dir.join("a")).expect("relative");
        let x = std::fs::read(p).expect("read a");
        for other in ["b", "c"] {
            let y = std::fs::read(dir.join(other).join(rel)).expect("read other");
            assert!(x == y, "{} differs between runs ({other})", rel.display());
        }
    }
    let text = std::fs::read_to_string(dir.join("a/receipts.json")).expect("receipts");
    assert!(
        !text.contains(&*dir.to_string_lossy()),
        "absolute path leaked into receipts.json"
    );
}

#[test]
fn failing_receipts_exit_one() {
    // A receipt limit nobody can meet: the files are still written, the exit status is 1 and
    // the table names the failing receipt.
    let toml = sup::setup(
        "pipeline-fail-cv",
        "",
        "[receipts]\ncross_validation_fit_min = 99.99\n",
    );
    let out = toml.parent().expect("dir").join("out");
    let st = run_to(&toml, &out);
    let stdout = String::from_utf8_lossy(&st.stdout);
    assert_eq!(st.status.code(), Some(1), "{stdout}");
    assert!(
        stdout.contains("FAIL: 1 of") && stdout.contains("cross_validation_fit"),
        "{stdout}"
    );
    let doc = read_json(&out.join("receipts.json"));
    assert_eq!(doc["verdict"], "fail");
    assert_eq!(receipt(&doc, "cross_validation_fit")["pass"], false);
    assert!(out.join("report.html").is_file());

    // An impossible M_s limit: no controller can be tuned; controller_design fails and says why.
    let toml = sup::setup("pipeline-fail-ms", "ms_max = 1.01", "");
    let out = toml.parent().expect("dir").join("out");
    let st = run_to(&toml, &out);
    let stdout = String::from_utf8_lossy(&st.stdout);
    assert_eq!(st.status.code(), Some(1), "{stdout}");
    let doc = read_json(&out.join("receipts.json"));
    let cd = receipt(&doc, "controller_design");
    assert_eq!(cd["pass"], false);
    assert!(cd["value"].is_null());
    assert!(
        cd["detail"]
            .as_str()
            .expect("detail")
            .contains("infeasible"),
        "{cd}"
    );
    assert!(doc["controller"].is_null() && doc["controller_error"].is_string());
    assert!(!out.join("pid.json").exists());
    // Model receipts are still issued.
    receipt(&doc, "etfe_phase_agreement");
    receipt(&doc, "cross_validation_fit");
}

#[test]
fn a_single_run_and_no_validation_fail_their_receipts() {
    let d = sup::scratch("pipeline-single");
    sup::write_dataset(&d);
    let text = sup::pipeline_toml("", "")
        .replace("[[runs]]\nname = \"low\"\nfile = \"low.csv\"\n\n", "")
        .replace("[validation]\nfile = \"val.csv\"\n", "");
    let toml = d.join("pipeline.toml");
    std::fs::write(&toml, text).expect("write");
    let cfg = LoadedConfig::load(&toml).expect("load");
    let run = run_pipeline(&cfg, &|_| {}).expect("run");
    let a = run
        .receipts
        .get("nonlinearity_audit")
        .expect("audit receipt");
    assert!(!a.pass && a.detail.contains("fewer than two"));
    let cv = run
        .receipts
        .get("cross_validation_fit")
        .expect("cv receipt");
    assert!(!cv.pass && cv.value.is_nan() && cv.detail.contains("no `[validation]`"));
    assert!(!run.receipts.all_pass);
}

fn run_err(name: &str, toml_text: &str) -> (Option<i32>, String) {
    let d = sup::scratch(name);
    sup::write_dataset(&d);
    let p = d.join("pipeline.toml");
    std::fs::write(&p, toml_text).expect("write");
    let st = run_to(&p, d.join("out"));
    (
        st.status.code(),
        String::from_utf8_lossy(&st.stderr).into_owned(),
    )
}

#[test]
fn bad_pipeline_files_name_file_line_and_key() {
    let base = sup::pipeline_toml("", "");
    let line_of = |text: &str, needle: &str| -> usize {
        text.lines()
            .position(|l| l.contains(needle))
            .expect("needle")
            + 1
    };
    // (scratch name, pipeline text, the line the error must name (by a text on it), what the
    // error must contain); every one exits 3.
    let cases: Vec<(&str, String, Option<&str>, &[&str])> = vec![
        // Unknown key (typo).
        (
            "pipeline-bad-unknown",
            base.replace("actuator_limit = 2.0", "actuator_limt = 2.0"),
            Some("actuator_limt"),
            &["control.actuator_limt"],
        ),
        // Wrong type.
        (
            "pipeline-bad-type",
            base.replace("nperseg = 500", "nperseg = \"500\""),
            Some("nperseg"),
            &["etfe.nperseg"],
        ),
        // Invalid value.
        (
            "pipeline-bad-value",
            base.replace("crossover_hz = 6.0", "crossover_hz = -6.0"),
            Some("crossover_hz"),
            &["control.crossover_hz", "> 0"],
        ),
        // Crossover above Nyquist (known only once the data are read).
        (
            "pipeline-bad-nyquist",
            base.replace("crossover_hz = 6.0", "crossover_hz = 600.0"),
            None,
            &["control.crossover_hz", "Nyquist"],
        ),
        // Missing required key.
        (
            "pipeline-bad-missing",
            base.replace("actuator_limit = 2.0\n", ""),
            None,
            &["pipeline.toml", "actuator_limit"],
        ),
        // Syntax error.
        (
            "pipeline-bad-syntax",
            base.replace("file = \"low.csv\"", "file = \"low.csv"),
            Some("file = \"low.csv"),
            &[],
        ),
        // A log that does not exist: the error names the log file.
        (
            "pipeline-bad-log",
            base.replace("file = \"val.csv\"", "file = \"missing.csv\""),
            None,
            &["missing.csv"],
        ),
        // A column that is not in the log.
        (
            "pipeline-bad-column",
            base.replace("fs = 1000.0", "fs = 1000.0\ninput = \"current\""),
            None,
            &["low.csv", "current"],
        ),
        // Unknown run in the identification table.
        (
            "pipeline-bad-run",
            format!("{base}\n[identification]\nrun = \"medium\"\n"),
            None,
            &["identification.run", "medium"],
        ),
        // Mismatched sample rates between logs.
        (
            "pipeline-bad-fs",
            base.replace("file = \"val.csv\"", "file = \"val.csv\"\nfs = 2000.0"),
            None,
            &["val.csv", "sample rate"],
        ),
    ];
    for (name, t, line_needle, needles) in cases {
        let (code, err) = run_err(name, &t);
        assert_eq!(code, Some(3), "{name}: {err}");
        if let Some(n) = line_needle {
            let l = line_of(&t, n);
            assert!(
                err.contains(&format!("pipeline.toml:{l}:")),
                "{name}: {err}"
            );
        }
        for n in needles {
            assert!(err.contains(n), "{name}: no `{n}` in {err}");
        }
    }
}
