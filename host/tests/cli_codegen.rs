//! `ferrosid codegen` and `ferrosid reidentify` on files: what they write, that reruns are
//! byte-identical, template overrides, and a clear error (naming the file) for each bad input.
use clap::Parser as _;
use ferrosid::cli::{run, Cli};
use ferrosid::Error;
use std::path::{Path, PathBuf};

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!(
        "ferrosid-cli-codegen-{}-{name}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn cmd(args: &[&str]) -> Result<ferrosid::cli::ExitCode, Error> {
    let mut v = vec!["ferrosid"];
    v.extend_from_slice(args);
    let cli = Cli::try_parse_from(v).unwrap_or_else(|e| panic!("clap: {e}"));
    run(&cli)
}

/// A discrete 2-state model at 1 kHz, a continuous PID, W_m, receipts and a "log".
fn inputs(dir: &Path) -> [String; 5] {
    let w = |name: &str, text: &str| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p.display().to_string()
    };
    [
        w(
            "model.json",
            r#"{"ts": 0.001, "a": [[0.99, 0.001], [-20.0, 0.96]], "b": [[0.01], [20.0]],
               "c": [[1.0, 0.0]], "d": [[0.0]]}"#,
        ),
        w(
            "pid.json",
            r#"{"kp": 0.8, "ki": 4.0, "kd": 0.01, "tau_f": 0.002, "rolloff": null}"#,
        ),
        w(
            "wm.json",
            r#"{"order": 1, "num": [0.5, 20.0], "den": [1.0, 400.0]}"#,
        ),
        w(
            "receipts.json",
            r#"{"schema": "ferrosid.receipts/1", "all_pass": true, "receipts": [
                {"name": "sensitivity_peak", "value": 1.42, "value_text": "1.42 1",
                 "limit": 1.6, "unit": "1", "comparison": "at_most", "pass": true}]}"#,
        ),
        w("unit_a.csv", "t,u,y\n0,1,0\n0.001,1,0.01\n"),
    ]
}

fn codegen_args<'a>(f: &'a [String; 5], out: &'a str) -> Vec<&'a str> {
    vec![
        "codegen",
        "--model",
        &f[0],
        "--pid",
        &f[1],
        "--wm",
        &f[2],
        "--receipts",
        &f[3],
        "--source",
        &f[4],
        "--prefix",
        "unit-7",
        "--out-dir",
        out,
        "--check-hz",
        "5,20,80",
    ]
}

#[test]
fn writes_both_files_reproducibly_with_the_tustin_gains() {
    let dir = scratch("ok");
    let f = inputs(&dir);
    let out1 = dir.join("gen1").display().to_string();
    let out2 = dir.join("gen2").display().to_string();
    cmd(&codegen_args(&f, &out1)).unwrap();
    cmd(&codegen_args(&f, &out2)).unwrap();
    for name in ["unit_7.h", "unit_7.rs"] {
        let a = std::fs::read(Path::new(&out1).join(name)).unwrap();
        let b = std::fs::read(Path::new(&out2).join(name)).unwrap();
        assert!(a == b, "{name} differs between runs");
    }
    let h = std::fs::read_to_string(Path::new(&out1).join("unit_7.h")).unwrap();
    // Plain Tustin (no prewarp), c = 2/ts = 2000: ki_d = Ki/c = 0.002,
    // a_d = (τc − 1)/(τc + 1) = 3/5 = 0.6, b_d = Kd·c/(τc + 1) = 20/5 = 4.0.
    assert!(h.contains("UNIT_7_PID_KI_D = 0.002f;"), "{h}");
    assert!(h.contains("UNIT_7_PID_A_D = 0.6f;"));
    assert!(h.contains("UNIT_7_PID_B_D = 4.0f;"));
    assert!(h.contains("UNIT_7_WM_NUM[UNIT_7_WM_ORDER + 1] = { 0.5f, 20.0f };"));
    // Check frequencies snapped to the 512-point grid at 1 kHz (1.953125 Hz bins).
    assert!(h.contains("UNIT_7_CHECK_BIN[UNIT_7_CHECK_COUNT] = { 3, 10, 41 };"));
    assert!(h.contains("receipt PASS sensitivity_peak: 1.42 1 (limit <= 1.6000 1)"));
    let log_sha = ferrosid_codegen::sha256_hex(b"t,u,y\n0,1,0\n0.001,1,0.01\n");
    assert!(
        h.contains(&log_sha),
        "the log's digest is in the provenance"
    );
}

#[test]
fn continuous_models_are_discretised_at_the_given_rate() {
    let dir = scratch("cont");
    let m = dir.join("c.json");
    // x' = -100 x + 100 u, y = x: ZOH at 1 ms gives a = e^-0.1, b = 1 − e^-0.1.
    std::fs::write(
        &m,
        r#"{"ts": 0.0, "a": [[-100.0]], "b": [[100.0]], "c": [[1.0]], "d": [[0.0]]}"#,
    )
    .unwrap();
    let out = dir.join("gen").display().to_string();
    let ms = m.display().to_string();
    let base = [
        "codegen",
        "--model",
        &ms,
        "--wm-level",
        "0.1",
        "--out-dir",
        &out,
        "--check-hz",
        "10",
    ];
    match cmd(&base) {
        Err(Error::Data { file, msg }) => {
            assert_eq!(file, m);
            assert!(msg.contains("--ts"), "{msg}");
        }
        other => panic!("{other:?}"),
    }
    let mut with_ts = base.to_vec();
    with_ts.extend(["--ts", "0.001"]);
    cmd(&with_ts).unwrap();
    let rs = std::fs::read_to_string(dir.join("gen").join("ferrosid.rs")).unwrap();
    let a = format!("[{:?}],", (-0.1f64).exp() as f32);
    let b = format!("[{:?}],", (1.0 - (-0.1f64).exp()) as f32);
    assert!(rs.contains(&a) && rs.contains(&b), "{rs}");
    assert!(rs.contains("[-100.0]"), "continuous model documented");
}

#[test]
fn user_templates_override_the_built_in_ones() {
    let dir = scratch("tpl");
    let f = inputs(&dir);
    let tpl = dir.join("tpl").display().to_string();
    cmd(&["codegen", "--write-templates", &tpl]).unwrap();
    let h = Path::new(&tpl).join("model.h");
    let text = std::fs::read_to_string(&h).unwrap();
    std::fs::write(
        &h,
        text.replace(
            "#include <stdint.h>",
            "#include <stdint.h>\n/* ACME {{ c.p }} */",
        ),
    )
    .unwrap();
    let out = dir.join("gen").display().to_string();
    let mut a = codegen_args(&f, &out);
    a.extend(["--templates", &tpl]);
    cmd(&a).unwrap();
    let g = std::fs::read_to_string(Path::new(&out).join("unit_7.h")).unwrap();
    assert!(g.contains("/* ACME UNIT_7 */"));
}

#[test]
fn bad_inputs_are_clear_errors_naming_the_file() {
    let dir = scratch("bad");
    let f = inputs(&dir);
    let out = dir.join("gen").display().to_string();
    let w = |name: &str, text: &str| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p.display().to_string()
    };
    let with = |i: usize, path: &str| {
        let mut g = f.clone();
        g[i] = path.to_string();
        g
    };
    let names_file = |e: Error, path: &str| {
        let s = e.to_string();
        assert!(s.contains(path), "{s:?} does not name {path}");
        s
    };
    // Missing model file.
    let missing = dir.join("nope.json").display().to_string();
    let e = cmd(&codegen_args(&with(0, &missing), &out)).unwrap_err();
    assert!(matches!(e, Error::Io { .. }));
    names_file(e, &missing);
    // Not JSON: parse error with the line.
    let bad = w("bad.json", "{\n\"ts\": 0.001,\n oops\n}");
    match cmd(&codegen_args(&with(0, &bad), &out)).unwrap_err() {
        Error::Parse { line, .. } => assert_eq!(line, 3),
        other => panic!("{other:?}"),
    }
    // JSON without a model.
    let e = cmd(&codegen_args(&with(0, &w("m1.json", r#"{"x": 1}"#)), &out)).unwrap_err();
    assert!(names_file(e, "m1.json").contains("no model"));
    // Ragged matrix.
    let e = cmd(&codegen_args(
        &with(
            0,
            &w(
                "m2.json",
                r#"{"ts":0.001,"a":[[1,0],[0]],"b":[[1],[0]],"c":[[1,0]],"d":[[0]]}"#,
            ),
        ),
        &out,
    ))
    .unwrap_err();
    assert!(names_file(e, "m2.json").contains("row 1"));
    // A discrete model at another rate than --ts.
    let mut a = codegen_args(&f, &out);
    a.extend(["--ts", "0.002"]);
    let e = cmd(&a).unwrap_err();
    assert!(names_file(e, "model.json").contains("control rate"));
    // PID file of unknown shape, W_m without den, receipts without a list.
    let e = cmd(&codegen_args(
        &with(1, &w("p.json", r#"{"gain": 1}"#)),
        &out,
    ))
    .unwrap_err();
    assert!(names_file(e, "p.json").contains("not a PID"));
    let e = cmd(&codegen_args(
        &with(2, &w("w.json", r#"{"num": [1.0]}"#)),
        &out,
    ))
    .unwrap_err();
    assert!(names_file(e, "w.json").contains("\"den\""));
    let e = cmd(&codegen_args(
        &with(2, &w("w2.json", r#"{"num": [1.0, "x"], "den": [1, 2]}"#)),
        &out,
    ))
    .unwrap_err();
    assert!(names_file(e, "w2.json").contains("\"num\"[1]"));
    let e = cmd(&codegen_args(
        &with(3, &w("r.json", r#"{"schema": 1}"#)),
        &out,
    ))
    .unwrap_err();
    assert!(names_file(e, "r.json").contains("receipts"));
    // No weight at all, a non-positive flat weight.
    let (m, o) = (f[0].as_str(), out.as_str());
    match cmd(&["codegen", "--model", m, "--out-dir", o]) {
        Err(Error::InvalidArgument(s)) => assert!(s.contains("--wm"), "{s}"),
        other => panic!("{other:?}"),
    }
    match cmd(&["codegen", "--model", m, "--out-dir", o, "--wm-level=-1"]) {
        Err(Error::InvalidArgument(s)) => assert!(s.contains("--wm-level"), "{s}"),
        other => panic!("{other:?}"),
    }
    // A check frequency beyond the excited band names the field.
    match cmd(&[
        "codegen",
        "--model",
        m,
        "--out-dir",
        o,
        "--wm-level",
        "0.1",
        "--check-hz",
        "5,400",
    ]) {
        Err(Error::InvalidArgument(s)) => assert!(s.contains("self_id.check_hz[1]"), "{s}"),
        other => panic!("{other:?}"),
    }
    // A model with a NaN entry names the matrix entry.
    let nan = w(
        "m3.json",
        r#"{"ts":0.001,"a":[[0.5]],"b":[[1]],"c":[[1]],"d":[[0]]}"#
            .replace("0.5", "1e999")
            .as_str(),
    );
    let e = cmd(&codegen_args(&with(0, &nan), &out)).unwrap_err();
    names_file(e, "m3.json");
}

#[test]
fn reidentify_errors_name_the_file() {
    let dir = scratch("reid");
    let missing = dir.join("none.log").display().to_string();
    assert!(matches!(
        cmd(&["reidentify", &missing]).unwrap_err(),
        Error::Io { .. }
    ));
    let p = dir.join("bad.log");
    std::fs::write(&p, "FRAME_BEGIN fs=1000 n=64\nFRAME 0 1 1 0 0 x\n").unwrap();
    match cmd(&["reidentify", &p.display().to_string()]).unwrap_err() {
        Error::Parse { file, line, .. } => {
            assert_eq!(file, p);
            assert_eq!(line, 2);
        }
        other => panic!("{other:?}"),
    }
    // A complete frame whose bins never pass the gate: not enough data to fit.
    let mut t = String::from("FRAME_BEGIN fs=1000 n=64 gate=0.9\n");
    for k in 0..=32 {
        t.push_str(&format!("FRAME {k} 1e-3 1e-3 1e-4 0 0.1\n"));
    }
    t.push_str("FRAME_END bins=33\n");
    std::fs::write(&p, t).unwrap();
    match cmd(&["reidentify", &p.display().to_string()]).unwrap_err() {
        Error::Data { file, msg } => {
            assert_eq!(file, p);
            assert!(msg.contains("only 0 bins"), "{msg}");
        }
        other => panic!("{other:?}"),
    }
    let mut a = vec!["reidentify", "x", "--min-delay", "3", "--max-delay", "1"];
    a[1] = "whatever.log";
    assert!(matches!(cmd(&a).unwrap_err(), Error::InvalidArgument(_)));
}

/// A `compensation.json` as `ferrosid run` writes it, with `choice`, `enabled` and the friction
/// level substituted.
/// Writes `text` to `dir/name` and returns the path.
fn write_in(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

fn compensation_json(choice: &str, enabled: bool, coulomb: &str) -> String {
    format!(
        r#"{{"kind": "ferrosid.compensation/1", "choice": "{choice}", "reason": "test",
  "compensation": {{"enabled": {enabled},
    "provenance": {{"effect": "coulomb_friction", "place": "motor",
      "verdict": "coulomb_friction", "source": "test"}},
    "friction_feedforward": {{"coulomb": {coulomb}, "viscous": 0.0,
      "smoothing_velocity": 0.01, "velocity": {{"kind": "output"}}}}}}}}"#
    )
}

#[test]
fn compensation_file_goes_into_the_header_and_bad_ones_are_named() {
    let dir = scratch("comp");
    let f = inputs(&dir);
    let out = dir.join("gen").display().to_string();
    let w = |name: &str, text: &str| write_in(&dir, name, text);
    let with_comp = |path: &str| {
        let mut a: Vec<String> = codegen_args(&f, &out)
            .into_iter()
            .map(String::from)
            .collect();
        a.extend(["--compensation".to_string(), path.to_string()]);
        a
    };
    let cmd = |a: Vec<String>| cmd(&a.iter().map(String::as_str).collect::<Vec<_>>());
    // A good file: the block is in the header, enabled.
    let good = w("c.json", &compensation_json("compensate", true, "0.008"));
    cmd(with_comp(&good)).expect("codegen with compensation");
    let h = std::fs::read_to_string(dir.join("gen/unit_7.h")).unwrap();
    assert!(h.to_lowercase().contains("coulomb"), "{h}");
    // Round trip of the typed file (the pipeline writes it, codegen reads it back).
    let text = compensation_json("compensate", true, "0.008");
    let parsed: ferrosid::ops::codegen::CompensationFile = serde_json::from_str(&text).unwrap();
    let back: ferrosid::ops::codegen::CompensationFile =
        serde_json::from_str(&serde_json::to_string(&parsed).unwrap()).unwrap();
    assert_eq!(parsed, back);
    parsed.validate().unwrap();
    // Bad files: each error names the file and what is wrong.
    for (name, text, what) in [
        ("c1.json", "{\n\"kind\": 1,\n oops }".to_string(), "line"),
        (
            "c2.json",
            compensation_json("compensate", true, "0.008").replace("/1", "/9"),
            "kind",
        ),
        (
            "c3.json",
            compensation_json("tune_harder", false, "0.008"),
            "choice",
        ),
        (
            "c4.json",
            compensation_json("widen_wm", true, "0.008"),
            "enabled",
        ),
        (
            "c5.json",
            compensation_json("compensate", true, "-1.0"),
            "coulomb",
        ),
        (
            "c6.json",
            compensation_json("compensate", true, "0.008").replace("\"reason\"", "\"why\""),
            "why",
        ),
    ] {
        let p = w(name, &text);
        let e = cmd(with_comp(&p)).unwrap_err();
        let s = e.to_string();
        assert!(s.contains(name), "{name}: {s}");
        assert!(s.contains(what), "{name}: {s}");
    }
}

#[test]
fn pid_files_are_read_as_typed_formats() {
    let dir = scratch("pidtypes");
    let f = inputs(&dir);
    let out = dir.join("gen").display().to_string();
    let w = |name: &str, text: &str| write_in(&dir, name, text);
    let run_with = |pid: &str| {
        let mut g = f.clone();
        g[1] = pid.to_string();
        cmd(&codegen_args(&g, &out))
            .map(|_| std::fs::read_to_string(dir.join("gen/unit_7.h")).unwrap())
    };
    // A discrete PID is used as is.
    let d = w(
        "d.json",
        r#"{"ts": 0.001, "prewarp_hz": null, "kp": 0.5, "ki_d": 0.002, "a_d": 0.6,
            "b_d": 4.0, "rolloff": null, "num": [1.0], "den": [1.0]}"#,
    );
    let h = run_with(&d).expect("discrete");
    assert!(h.contains("PID_KI_D = 0.002f;"), "{h}");
    // A tuning result: its discrete controller.
    let t = w(
        "t.json",
        r#"{"pid": {"kp": 0.8, "ki": 4.0, "kd": 0.01, "tau_f": 0.002, "rolloff": null},
            "discrete": {"ts": 0.001, "prewarp_hz": 5.0, "kp": 0.7, "ki_d": 0.003,
              "a_d": 0.5, "b_d": 3.0, "rolloff": null, "num": [1.0], "den": [1.0]},
            "design": {"crossover_hz": 5.0, "integral_ratio": null}}"#,
    );
    let h = run_with(&t).expect("tuned");
    assert!(h.contains("PID_KI_D = 0.003f;"), "{h}");
    // A discrete PID missing a field: the error says what each format lacks.
    let bad = w(
        "b.json",
        r#"{"ts": 0.001, "kp": 0.5, "a_d": 0.6, "b_d": 4.0, "num": [1.0], "den": [1.0]}"#,
    );
    let s = run_with(&bad).unwrap_err().to_string();
    assert!(s.contains("b.json") && s.contains("not a PID"), "{s}");
    assert!(s.contains("ki_d") && s.contains("`pid`"), "{s}");
}
