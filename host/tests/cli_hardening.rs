//! Regression tests of issue 10 (hardening) through the command line: each case panicked,
//! hung, printed a silently wrong answer, destroyed a file or gave the wrong exit code before.
//! Exit code and message are asserted for every case.
mod cli_support;
use cli_support::{expect, ferrosid, no_panic, s, scratch, write_csv, Rng, Run};
use std::path::{Path, PathBuf};

fn example(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples")
        .join(name)
}

/// A first-order plant y[k] = 0.9 y[k-1] + 0.1 u[k-1] + noise, driven by white noise.
fn plant_log(n: usize, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let mut rng = Rng::new(seed);
    let u = rng.noise(n, 1.0);
    let mut y = vec![0.0; n];
    for k in 1..n {
        y[k] = 0.9 * y[k - 1] + 0.1 * u[k - 1];
    }
    let e = rng.noise(n, 0.01);
    let y: Vec<f64> = y.iter().zip(&e).map(|(a, b)| a + b).collect();
    (u, y)
}

fn write_pipeline(dir: &Path, extra: &str) -> PathBuf {
    let data = example("data");
    let text = format!(
        "[signals]\ninput = \"u\"\noutput = \"y\"\ntime = \"t\"\n\
         [[runs]]\nname = \"low\"\nfile = \"{}\"\namplitude = 0.05\n\
         [[runs]]\nname = \"high\"\nfile = \"{}\"\namplitude = 0.15\n\
         [validation]\nfile = \"{}\"\n\
         [etfe]\nnperseg = 500\n\
         [control]\ncrossover_hz = 8.0\nrolloff_ratio = 4.0\nms_max = 1.6\n\
         actuator_limit = 0.3\nreference_amplitude = 5.0\n{extra}",
        s(&data.join("two_mass_low.csv")),
        s(&data.join("two_mass_high.csv")),
        s(&data.join("two_mass_validate.csv")),
    );
    let p = dir.join("pipeline.toml");
    std::fs::write(&p, text).expect("write pipeline");
    p
}

/// `ferrosid run` of [`write_pipeline`] with `extra` in a fresh scratch directory `name`.
fn run_with(name: &str, extra: &str) -> Run {
    let d = scratch(name);
    let p = write_pipeline(&d, extra);
    ferrosid(&["run", s(&p), "--out", s(&d.join("out"))])
}

// ---- 1. Panics: every numeric parameter is range-checked before any work -------------------

#[test]
fn huge_numeric_parameters_are_usage_errors_with_the_bound() {
    let log = example("data/two_mass_high.csv");
    let r = ferrosid(&["identify", s(&log), "--block-rows", "3074457345618258600"]);
    expect(
        &r,
        2,
        &["--block-rows", "2..=1000"],
        "identify --block-rows huge",
    );
    let r = ferrosid(&["identify", s(&log), "--decimate", "18446744073709551615"]);
    expect(
        &r,
        2,
        &["--decimate", "2..=1000"],
        "identify --decimate huge",
    );
    let r = ferrosid(&["frf", s(&log), "--nperseg", "1000000000000000000"]);
    expect(&r, 2, &["--nperseg", "8..=4194304"], "frf --nperseg huge");
    let r = ferrosid(&["frf", s(&log), "--period", "1000000000000000000"]);
    expect(&r, 2, &["--period", "2..=4194304"], "frf --period huge");
    let r = ferrosid(&["frf", s(&log), "--time-jitter", "1e300"]);
    expect(
        &r,
        2,
        &["--time-jitter", "[0, 0.5]"],
        "frf --time-jitter huge",
    );
}

#[test]
fn pipeline_block_rows_huge_is_a_key_error() {
    let r = run_with(
        "pipe_block_rows",
        "[identification]\nblock_rows = 3074457345618258600\n",
    );
    expect(
        &r,
        3,
        &["identification.block_rows", "2..=1000"],
        "pipeline block_rows",
    );
}

fn frame_text(gate: &str) -> String {
    let mut t = format!("FRAME_BEGIN fs=1000 n=64 averages=4 gate={gate}\n");
    for b in 0..=32 {
        let f = b as f64 / 64.0;
        // H(z) = z⁻¹ / (1 − 0.5 z⁻¹): na = 1, nb = 0, delay 1.
        let q = num_complex::Complex64::from_polar(1.0, -2.0 * std::f64::consts::PI * f);
        let h = q / (1.0 - 0.5 * q);
        let suu = if b == 0 { 0.0 } else { 1.0 };
        t.push_str(&format!(
            "FRAME {b} {suu} {} {} {} {}\n",
            h.norm_sqr() * suu,
            h.re * suu,
            h.im * suu,
            if b == 0 { 0.0 } else { 0.99 }
        ));
    }
    t.push_str("FRAME_END bins=33\n");
    t
}

#[test]
fn reidentify_orders_and_delays_are_bounded() {
    let d = scratch("reid_bounds");
    let f = d.join("target.log");
    std::fs::write(&f, frame_text("0.9")).unwrap();
    let max = "18446744073709551615";
    let r = ferrosid(&["reidentify", s(&f), "--nb", max]);
    expect(&r, 2, &["--nb", "0..=40"], "reidentify --nb huge");
    let r = ferrosid(&["reidentify", s(&f), "--na", max]);
    expect(&r, 2, &["--na", "1..=40"], "reidentify --na huge");
    let r = ferrosid(&["reidentify", s(&f), "--min-delay", max, "--max-delay", max]);
    expect(
        &r,
        2,
        &["--min-delay", "0..=512"],
        "reidentify --min-delay huge",
    );
    let r = ferrosid(&["reidentify", s(&f), "--max-delay", "1000000000000000000"]);
    expect(
        &r,
        2,
        &["--max-delay", "0..=512"],
        "reidentify --max-delay 1e18",
    );
    // The frame itself still fits.
    let r = ferrosid(&["reidentify", s(&f), "--na", "1", "--nb", "0"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
}

// ---- 2. Hangs ------------------------------------------------------------------------------

#[test]
fn audit_band_factor_is_bounded() {
    let r = run_with("band_factor", "[audit]\nband_factor = 1e300\n");
    expect(
        &r,
        3,
        &["audit.band_factor", "1000000"],
        "band_factor 1e300",
    );
}

#[test]
fn fleet_jobs_are_bounded_and_a_missing_directory_is_named() {
    let d = scratch("fleet_jobs");
    let r = ferrosid(&["fleet", s(&example("fleet")), "--jobs", "100000"]);
    expect(&r, 2, &["--jobs", "1..=256"], "fleet --jobs 100000");
    let missing = d.join("no_such_fleet");
    let r = ferrosid(&["fleet", s(&missing)]);
    expect(
        &r,
        3,
        &[s(&missing), "fleet directory not found"],
        "fleet on a missing directory",
    );
    assert!(!r.stderr.contains("no pipeline template"), "{}", r.stderr);
}

fn model_json(dir: &Path) -> PathBuf {
    let p = dir.join("model.json");
    std::fs::write(
        &p,
        r#"{"a":[[0.9]],"b":[[1.0]],"c":[[0.1]],"d":[[0.0]],"ts":0.001}"#,
    )
    .unwrap();
    p
}

/// `ferrosid codegen --model MODEL --wm-level 0.2 --out-dir OUT` and the arguments `extra`.
fn codegen_wm(model: &Path, out: &Path, extra: &[&str]) -> Run {
    let mut args = vec![
        "codegen",
        "--model",
        s(model),
        "--wm-level",
        "0.2",
        "--out-dir",
        s(out),
    ];
    args.extend_from_slice(extra);
    ferrosid(&args)
}

#[test]
fn runaway_user_template_ends_with_an_error() {
    let d = scratch("template_fuel");
    let m = model_json(&d);
    let t = d.join("templates");
    std::fs::create_dir_all(&t).unwrap();
    std::fs::write(
        t.join("model.h"),
        "{% for i in range(100000) %}{% for j in range(100000) %}x{% endfor %}{% endfor %}\n",
    )
    .unwrap();
    let r = codegen_wm(&m, &d.join("gen"), &["--templates", s(&t)]);
    expect(&r, 3, &["model.h", "fuel"], "nested 100k loops");
}

// ---- 3. Silently wrong ---------------------------------------------------------------------

fn frf_json(path: &Path, extra: &[&str]) -> (i32, serde_json::Value, String) {
    let mut args = vec!["frf", s(path), "--json"];
    args.extend_from_slice(extra);
    let r = ferrosid(&args);
    let v = serde_json::from_str(&r.stdout).unwrap_or(serde_json::Value::Null);
    (r.code, v, r.stderr)
}

fn column(v: &serde_json::Value, key: &str) -> Vec<f64> {
    v["estimates"][0][key]
        .as_array()
        .unwrap_or_else(|| panic!("no {key} in {v}"))
        .iter()
        .map(|x| x.as_f64().unwrap_or(f64::NAN))
        .collect()
}

#[test]
fn frf_and_identify_are_scale_invariant() {
    let d = scratch("scale");
    let (u, y) = plant_log(4096, 7);
    let base = d.join("volts.csv");
    write_csv(&base, 1e-3, &u, &y);
    let (code, v0, err) = frf_json(&base, &[]);
    assert_eq!(code, 0, "{err}");
    let coh0 = column(&v0, "coherence");
    let db0 = column(&v0, "mag_db");
    for (name, gu, gy, ts) in [
        ("big.csv", 1e300, 1e300, 1e-3),
        ("small.csv", 1e-300, 1e-300, 1e-3),
        ("mixed.csv", 1e-150, 1e150, 1e-3),
        ("fast.csv", 1.0, 1.0, 1e-300),
    ] {
        let p = d.join(name);
        let us: Vec<f64> = u.iter().map(|v| v * gu).collect();
        let ys: Vec<f64> = y.iter().map(|v| v * gy).collect();
        write_csv(&p, ts, &us, &ys);
        let (code, v, err) = frf_json(&p, &[]);
        assert_eq!(code, 0, "{name}: {err}");
        let coh = column(&v, "coherence");
        let db = column(&v, "mag_db");
        let shift = 20.0 * (gy / gu).log10();
        for k in 1..coh0.len() {
            assert!(
                (coh[k] - coh0[k]).abs() < 1e-9,
                "{name} bin {k}: coherence {} vs {}",
                coh[k],
                coh0[k]
            );
            assert!(
                (db[k] - shift - db0[k]).abs() < 1e-6,
                "{name} bin {k}: |H| {} dB vs {} dB + {shift}",
                db[k],
                db0[k]
            );
        }
        // identify: same pole, no "constant" complaint.
        let r = ferrosid(&["identify", s(&p), "--order", "1", "--json"]);
        assert_eq!(r.code, 0, "{name}: {}", r.stderr);
        assert!(!r.stderr.contains("constant"), "{name}: {}", r.stderr);
        let j: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
        let pole = j["poles"][0]["re"].as_f64().unwrap();
        assert!((pole - 0.9).abs() < 0.01, "{name}: pole {pole}");
        let fit = j["validation"]["fit"]["fit_percent"][0].as_f64().unwrap();
        assert!(fit > 80.0, "{name}: fit {fit}");
        assert!(
            j["normalisation"].as_str().unwrap().contains("normalised"),
            "{name}: no normalisation note"
        );
    }
}

#[test]
fn ten_row_log_passes_no_bin_and_says_why() {
    let d = scratch("ten_rows");
    let (u, y) = plant_log(10, 3);
    let p = d.join("ten.csv");
    write_csv(&p, 1e-3, &u, &y);
    let r = ferrosid(&["frf", s(&p)]);
    no_panic(&r, "10-row frf");
    assert_eq!(r.code, 1, "{}\n{}", r.stdout, r.stderr);
    assert!(r.stdout.contains("0 of 5 bins pass"), "{}", r.stdout);
    assert!(
        r.stdout.contains("only 1 Welch segment(s) averaged") && r.stdout.contains("at least 4"),
        "{}",
        r.stdout
    );
}

#[test]
fn codegen_missing_template_directory_is_an_error() {
    let d = scratch("templates_missing");
    let m = model_json(&d);
    let missing = d.join("nonexistent");
    let r = codegen_wm(&m, &d.join("gen"), &["--templates", s(&missing)]);
    expect(
        &r,
        3,
        &[s(&missing), "template directory not found"],
        "--templates /nonexistent",
    );
    assert!(!d.join("gen/ferrosid.h").exists());
}

// ---- 4. Data loss --------------------------------------------------------------------------

#[test]
fn output_over_an_input_is_refused_and_the_input_kept() {
    let d = scratch("out_is_input");
    let (u, y) = plant_log(2000, 5);
    let x = d.join("x.csv");
    let v = d.join("v.csv");
    write_csv(&x, 1e-3, &u, &y);
    write_csv(&v, 1e-3, &u, &y);
    let before = std::fs::read(&x).unwrap();
    let r = ferrosid(&["identify", s(&x), "--out", s(&x)]);
    expect(
        &r,
        2,
        &["--out", "refusing to overwrite an input"],
        "identify X --out X",
    );
    // Another spelling of the same file.
    let other = format!("{}/./x.csv", s(&d));
    let r = ferrosid(&["identify", s(&x), "--out", &other]);
    expect(
        &r,
        2,
        &["refusing to overwrite an input"],
        "identify X --out ./X",
    );
    let r = ferrosid(&["identify", s(&x), "--validate", s(&v), "--out", s(&v)]);
    expect(
        &r,
        2,
        &["refusing to overwrite an input"],
        "--validate V --out V",
    );
    assert_eq!(std::fs::read(&x).unwrap(), before);
    let f = d.join("target.log");
    std::fs::write(&f, frame_text("0.9")).unwrap();
    let r = ferrosid(&["reidentify", s(&f), "--out", s(&f)]);
    expect(
        &r,
        2,
        &["refusing to overwrite an input"],
        "reidentify F --out F",
    );
    assert!(std::fs::read_to_string(&f)
        .unwrap()
        .starts_with("FRAME_BEGIN"));
}

#[test]
fn output_path_that_cannot_be_written_fails_before_computing() {
    let d = scratch("unwritable");
    let (u, y) = plant_log(2000, 5);
    let x = d.join("x.csv");
    write_csv(&x, 1e-3, &u, &y);
    // A regular file where a directory is needed.
    let blocker = d.join("blocker");
    std::fs::write(&blocker, "not a directory").unwrap();
    let out = blocker.join("model.json");
    let r = ferrosid(&["identify", s(&x), "--out", s(&out)]);
    expect(&r, 3, &[s(&blocker)], "identify --out under a file");
    assert!(
        r.stdout.is_empty(),
        "no report before the check: {}",
        r.stdout
    );
    let p = write_pipeline(&d, "");
    let r = ferrosid(&["run", s(&p), "--out", s(&blocker.join("out"))]);
    expect(&r, 3, &[s(&blocker)], "run --out under a file");
}

#[test]
fn run_never_replaces_or_deletes_files_it_did_not_write_and_locks() {
    let d = scratch("run_safety");
    let p = write_pipeline(&d, "");
    let out = d.join("out");
    std::fs::create_dir_all(out.join("figures")).unwrap();
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    std::fs::write(out.join("pid.json"), "my own pid").unwrap();
    // A file of one of ferrosid's names that ferrosid did not write: refused, kept.
    let r = ferrosid(&["run", s(&p), "--out", s(&out)]);
    expect(
        &r,
        3,
        &["pid.json", "not written by ferrosid"],
        "user pid.json",
    );
    assert_eq!(
        std::fs::read_to_string(out.join("pid.json")).unwrap(),
        "my own pid"
    );
    std::fs::remove_file(out.join("pid.json")).unwrap();
    // A live lock (this test process holds it): refused with the holder named.
    std::fs::write(
        out.join(".ferrosid.lock"),
        format!("{}\n", std::process::id()),
    )
    .unwrap();
    let r = ferrosid(&["run", s(&p), "--out", s(&out)]);
    expect(
        &r,
        3,
        &["another ferrosid", ".ferrosid.lock"],
        "locked directory",
    );
    std::fs::remove_file(out.join(".ferrosid.lock")).unwrap();
    // Now it runs; the manifest lists what it wrote, the user's file survives, the lock is gone.
    let r = ferrosid(&["run", s(&p), "--out", s(&out)]);
    assert!(r.code == 0 || r.code == 1, "{}", r.stderr);
    let manifest = std::fs::read_to_string(out.join(".ferrosid-manifest")).unwrap();
    assert!(
        manifest.lines().any(|l| l.ends_with("  model.json")),
        "{manifest}"
    );
    assert!(!manifest.contains("notes.txt"));
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "mine"
    );
    assert!(!out.join(".ferrosid.lock").exists());
    // A second run replaces its own files without complaint.
    let r = ferrosid(&["run", s(&p), "--out", s(&out)]);
    assert!(r.code == 0 || r.code == 1, "{}", r.stderr);
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "mine"
    );
    // The model file carries the operating point of the estimation run.
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("model.json")).unwrap()).unwrap();
    assert_eq!(m["operating_point"]["detrend"], "mean");
    assert_eq!(m["operating_point"]["u0"].as_array().unwrap().len(), 1);
}

#[test]
fn write_templates_keeps_edited_templates_without_force() {
    let d = scratch("write_templates");
    let t = d.join("tpl");
    let r = ferrosid(&["codegen", "--write-templates", s(&t)]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    // Unedited: writing again is fine.
    let r = ferrosid(&["codegen", "--write-templates", s(&t)]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    std::fs::write(t.join("model.h"), "my edited template\n").unwrap();
    let r = ferrosid(&["codegen", "--write-templates", s(&t)]);
    expect(&r, 3, &["model.h", "--force"], "edited template");
    assert_eq!(
        std::fs::read_to_string(t.join("model.h")).unwrap(),
        "my edited template\n"
    );
    let r = ferrosid(&["codegen", "--write-templates", s(&t), "--force"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_ne!(
        std::fs::read_to_string(t.join("model.h")).unwrap(),
        "my edited template\n"
    );
}

// ---- 5. Exit codes and messages ------------------------------------------------------------

#[test]
fn codegen_bad_model_contents_are_data_errors_naming_the_file() {
    let d = scratch("codegen_bad_model");
    let m = d.join("huge.json");
    std::fs::write(
        &m,
        r#"{"a":[[0.5]],"b":[[1e300]],"c":[[1.0]],"d":[[0.0]],"ts":0.001}"#,
    )
    .unwrap();
    let r = codegen_wm(&m, &d.join("gen"), &[]);
    expect(&r, 3, &[s(&m), "model.b"], "codegen model with 1e300");
    let w = d.join("wm.json");
    std::fs::write(&w, r#"{"num":[1e300],"den":[1.0]}"#).unwrap();
    let r = ferrosid(&[
        "codegen",
        "--model",
        s(&model_json(&d)),
        "--wm",
        s(&w),
        "--out-dir",
        s(&d.join("gen")),
    ]);
    expect(&r, 3, &[s(&w), "weight.num"], "codegen W_m with 1e300");
}

#[test]
fn reidentify_blames_the_frame_header_not_the_flag() {
    let d = scratch("reid_gate");
    let f = d.join("target.log");
    std::fs::write(&f, frame_text("1.5")).unwrap();
    let r = ferrosid(&["reidentify", s(&f)]);
    expect(
        &r,
        3,
        &[&format!("{}:1:", s(&f)), "gate = 1.5"],
        "header gate 1.5",
    );
    assert!(!r.stderr.contains("--gate must"), "{}", r.stderr);
}

#[test]
fn huge_fields_and_nuls_are_not_echoed_whole() {
    let d = scratch("huge_field");
    let p = d.join("huge.csv");
    let mut text = String::from("t,u,y\n0,1,2\n0.001,");
    text.push_str(&"9x".repeat(1_000_000));
    text.push_str(",3\n");
    std::fs::write(&p, &text).unwrap();
    let r = ferrosid(&["frf", s(&p)]);
    expect(
        &r,
        3,
        &[&format!("{}:3:", s(&p)), "bytes in all"],
        "2 MB field",
    );
    assert!(r.stderr.len() < 1000, "{} bytes of error", r.stderr.len());
    let q = d.join("nul.csv");
    let mut text = String::from("t,u,y\n0,1,2\n0.001,");
    text.push_str(&"\0".repeat(50_000));
    text.push_str(",3\n");
    std::fs::write(&q, &text).unwrap();
    let r = ferrosid(&["frf", s(&q)]);
    expect(&r, 3, &[&format!("{}:3:", s(&q))], "50 kB of NULs");
    assert!(r.stderr.len() < 1000, "{} bytes of error", r.stderr.len());
    assert!(!r.stderr.contains('\0'));
}

#[test]
fn truncated_mat_file_says_it_holds_nothing() {
    let d = scratch("truncated_mat");
    let p = d.join("cut.mat");
    let mut bytes = b"MATLAB 5.0 MAT-file, truncated by a test".to_vec();
    bytes.resize(116, b' ');
    bytes.extend_from_slice(&[0u8; 8]); // subsystem offset
    bytes.extend_from_slice(&[0x00, 0x01, b'I', b'M']); // version 0x0100, little endian
    let r = ferrosid(&["frf", s(&p), "--input", "u", "--output", "y", "--fs", "100"]);
    // The file does not exist yet: an I/O error naming it.
    expect(&r, 3, &[s(&p)], "missing .mat");
    std::fs::write(&p, &bytes).unwrap();
    let r = ferrosid(&["frf", s(&p), "--input", "u", "--output", "y", "--fs", "100"]);
    expect(
        &r,
        3,
        &[s(&p), "holds no numeric variable at all"],
        "truncated .mat",
    );
    assert!(!r.stderr.contains("variables are: \n"), "{}", r.stderr);
}

// ---- 6. Real files: time-column jitter -----------------------------------------------------

#[test]
fn rounded_time_columns_are_accepted_and_fs_overrides_with_a_warning() {
    let d = scratch("jitter");
    let (u, y) = plant_log(4000, 9);
    // Time written with 5 significant digits at 3 kHz: rounding up to 1.5e-4 of the interval
    // near t = 1.33 s... and 1.5e-2 at the end (t ~ 1.333 s printed as 1.3333).
    let write_t = |name: &str, fmt: &dyn Fn(f64) -> String| -> PathBuf {
        let p = d.join(name);
        let mut text = String::from("t,u,y\n");
        for k in 0..u.len() {
            text.push_str(&format!(
                "{},{:e},{:e}\n",
                fmt(k as f64 / 3000.0),
                u[k],
                y[k]
            ));
        }
        std::fs::write(&p, text).unwrap();
        p
    };
    // 9 significant digits: relative rounding of the interval about 1e-6..1e-5: accepted.
    let nine = write_t("nine.csv", &|t| format!("{t:.8e}"));
    let r = ferrosid(&["frf", s(&nine)]);
    assert_eq!(r.code, 0, "9-digit time column refused: {}", r.stderr);
    assert!(
        r.stdout.contains("3000.000 Hz") || r.stdout.contains("at 3000"),
        "{}",
        r.stdout
    );
    // 5 digits: the interval rule alone refuses it (rounding up to 1.5e-1 of the interval at
    // the end), but every stamp lies on the uniform grid within its printed rounding: accepted.
    let five = write_t("five.csv", &|t| format!("{t:.4e}"));
    let r = ferrosid(&["frf", s(&five)]);
    assert_eq!(r.code, 0, "5-digit time column refused: {}", r.stderr);
    // Real jitter (1 % of the interval every 7th sample, printed to 12 digits): refused, naming
    // the line and both options that fix it.
    let jit = write_t("jittered.csv", &|t| {
        let k = (t * 3000.0).round() as i64;
        let j = if k % 7 == 3 { 0.01 / 3000.0 } else { 0.0 };
        format!("{:.11e}", t + j)
    });
    let r = ferrosid(&["frf", s(&jit)]);
    expect(
        &r,
        3,
        &["non-uniform sampling", "--time-jitter", "--fs"],
        "jittered time column",
    );
    // --fs takes precedence over the time column, with a warning.
    let r = ferrosid(&["frf", s(&jit), "--fs", "3000"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stderr.contains("warning") && r.stderr.contains("using the given fs = 3000 Hz"),
        "{}",
        r.stderr
    );
    // A grossly different --fs is still refused.
    let r = ferrosid(&["frf", s(&jit), "--fs", "1000"]);
    expect(&r, 3, &["implies fs", "1000"], "wrong --fs");
}

// ---- 8. Operating point ------------------------------------------------------------------

#[test]
fn identify_writes_the_operating_point_and_codegen_emits_it() {
    let d = scratch("operating_point");
    let (u, y) = plant_log(4000, 11);
    let (u0, y0) = (2.5, -40.0);
    let uo: Vec<f64> = u.iter().map(|v| v + u0).collect();
    let yo: Vec<f64> = y.iter().map(|v| v + y0).collect();
    let x = d.join("offset.csv");
    write_csv(&x, 1e-3, &uo, &yo);
    let v = d.join("offset_val.csv");
    let (uv, yv) = plant_log(4000, 12);
    let uvo: Vec<f64> = uv.iter().map(|v| v + u0).collect();
    // The validation data's output sits on the same operating point (y0 + G·(u − u0) with the
    // plant's DC gain 1): the fit through the operating point is as good as the zero-mean one.
    let yvo: Vec<f64> = yv.iter().map(|v| v + y0).collect();
    write_csv(&v, 1e-3, &uvo, &yvo);
    let m = d.join("model.json");
    let r = ferrosid(&[
        "identify",
        s(&x),
        "--validate",
        s(&v),
        "--order",
        "1",
        "--out",
        s(&m),
        "--json",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let j: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
    let opfit = j["validation"]["operating_point_fit"]["fit_percent"][0]
        .as_f64()
        .unwrap();
    assert!(opfit > 90.0, "fit through the operating point {opfit}");
    let model: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&m).unwrap()).unwrap();
    let op = &model["operating_point"];
    let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len() as f64;
    assert!(
        (op["u0"][0].as_f64().unwrap() - mean(&uo)).abs() < 1e-9,
        "{op}"
    );
    assert!(
        (op["y0"][0].as_f64().unwrap() - mean(&yo)).abs() < 1e-9,
        "{op}"
    );
    assert_eq!(op["detrend"], "mean");
    assert_eq!(op["decimation"], 1);
    // codegen puts U0/Y0 into both headers.
    let gen = d.join("gen");
    let r = codegen_wm(&m, &gen, &[]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let h = std::fs::read_to_string(gen.join("ferrosid.h")).unwrap();
    let lit = |v: f64| format!("{}", v as f32);
    let (mu, my) = (mean(&uo), mean(&yo));
    assert!(
        h.contains(&format!("FERROSID_U0[FERROSID_N_INPUTS] = {{ {}", lit(mu))),
        "{h}"
    );
    assert!(
        h.contains(&format!("FERROSID_Y0[FERROSID_N_OUTPUTS] = {{ {}", lit(my))),
        "{h}"
    );
    let rs = std::fs::read_to_string(gen.join("ferrosid.rs")).unwrap();
    assert!(
        rs.contains(&format!("pub static U0: [f32; N_INPUTS] = [{}", lit(mu))),
        "{rs}"
    );
    // An old model file without the field still loads; the headers then say so.
    let r = codegen_wm(&model_json(&d), &d.join("gen_old"), &[]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let h = std::fs::read_to_string(d.join("gen_old/ferrosid.h")).unwrap();
    assert!(h.contains("no operating point recorded"), "{h}");
}

#[test]
fn codegen_tiny_sample_time_is_an_error_not_a_panic() {
    let d = scratch("codegen_tiny_ts");
    let m = d.join("cont.json");
    std::fs::write(
        &m,
        r#"{"a":[[-1.0]],"b":[[1.0]],"c":[[1.0]],"d":[[0.0]],"ts":0}"#,
    )
    .unwrap();
    for ts in ["1e-300", "1e-40"] {
        let r = ferrosid(&[
            "codegen",
            "--model",
            s(&m),
            "--ts",
            ts,
            "--wm-level",
            "0.2",
            "--out-dir",
            s(&d.join("gen")),
        ]);
        expect(&r, 2, &["--ts", "32-bit"], "codegen --ts tiny");
    }
}
