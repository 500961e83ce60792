//! The generated files compile and hold the numbers they claim to.
//!
//! * C: `gcc -std=c99 -Wall -Wextra -Werror -pedantic` compiles the header; a C program built
//!   here prints every constant with `%.9g` (enough digits to read back the exact `float`) and
//!   simulates a step response with the emitted matrices, compared with an `f64` simulation
//!   written in this test from the `f64` input matrices.
//! * Rust: `rustc --edition 2021 -D warnings` compiles the module inside a `#![no_std]` library,
//!   and a std program built from it prints its constants for the same read-back comparison.
//! * Determinism, the runtime template engine, user overrides, sanitising and bad input.
//!
//! Needs `gcc` and `rustc` on PATH (a Rust toolchain on Linux links with `cc`/gcc).
use std::path::{Path, PathBuf};
use std::process::Command;

use ferrosid_codegen::*;

/// A fresh scratch directory under the system temp dir for test `name`.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("ferrosid-codegen-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create scratch dir");
    dir
}

/// A 3-state lightly damped plant (resonance + lag) at 1 kHz with a PID, roll-off, W_m of
/// order 2, sources and receipts: every section of the templates is exercised.
fn full_input() -> CodegenInput {
    CodegenInput {
        prefix: "gimbal pitch".into(),
        model: DiscreteModel {
            ts_s: 1e-3,
            matrices: Matrices {
                a: vec![
                    vec![1.9702, -0.98, 0.0],
                    vec![1.0, 0.0, 0.0],
                    vec![0.013, 0.004, 0.95],
                ],
                b: vec![vec![1.0], vec![0.0], vec![0.05]],
                c: vec![vec![1.234e-4, 1.1e-4, 0.25]],
                d: vec![vec![0.0]],
            },
        },
        continuous: Some(ContinuousModel {
            matrices: Matrices {
                a: vec![
                    vec![-10.0, -3948.0, 0.0],
                    vec![1.0, 0.0, 0.0],
                    vec![0.0, 0.0, -51.3],
                ],
                b: vec![vec![1.0], vec![0.0], vec![50.0]],
                c: vec![vec![0.0, 3948.0, 0.25]],
                d: vec![vec![0.0]],
            },
            note: "inverse ZOH of the discrete model */ with a comment terminator".into(),
        }),
        pid: Some(PidGains {
            ts_s: 1e-3,
            kp: 0.8,
            ki_d: 0.0125,
            a_d: 0.6,
            b_d: 4.2,
            rolloff: Some(Biquad {
                b: [0.02, 0.04, 0.02],
                a: [1.0, -1.56, 0.64],
            }),
            prewarp_hz: Some(20.0),
            continuous: Some(ContinuousPid {
                kp: 0.8,
                ki: 25.0,
                kd: 0.0105,
                tau_f: 0.002,
            }),
        }),
        weight: WeightCoefficients {
            num: vec![0.5, 40.0, 1200.0],
            den: vec![1.0, 300.0, 40000.0],
            note: "order-2 fit to the unit spread".into(),
        },
        self_id: SelfIdSettings {
            welch_n: 512,
            check_hz: vec![4.0, 8.0, 16.0, 25.0, 50.0, 100.0],
            coherence_gate: 0.9,
            averages: 4,
            settle_periods: 1,
            excitation_rms: 0.5,
            excitation_max_hz: 250.0,
            min_checked: 3,
            closed_loop: None,
        },
        provenance: Provenance {
            tool: "ferrosid-codegen tests".into(),
            sources: vec![
                SourceDigest {
                    label: "logs/unit \"A\".csv".into(),
                    sha256: sha256_hex(b"unit A"),
                },
                SourceDigest {
                    label: "logs/unit-B-°C.csv".into(),
                    sha256: sha256_hex(b"unit B"),
                },
            ],
            receipts: vec![
                ReceiptLine {
                    name: "sensitivity_peak".into(),
                    value: "1.42 1".into(),
                    condition: "<= 1.6".into(),
                    pass: true,
                },
                ReceiptLine {
                    name: "phase_margin".into(),
                    value: "41.0 deg??/".into(),
                    condition: ">= 45".into(),
                    pass: false,
                },
            ],
            notes: vec!["ferrosid identify unit_a.csv --order 3".into()],
        },
        operating_point: None,
        compensation: Some(full_compensation()),
        state_controller: None,
    }
}

/// Every part of the compensation block, with provenance text that needs escaping.
fn full_compensation() -> Compensation {
    Compensation {
        enabled: true,
        provenance: CompensationProvenance {
            effect: "coulomb_friction".into(),
            place: "drive".into(),
            verdict: "explained */ \"quoted\" ??/".into(),
            source: "ferrosid gap on unit_a.csv,unit_b.csv".into(),
            nrmse_before: Some(0.21),
            nrmse_after: None,
        },
        friction_feedforward: Some(FrictionFeedforward {
            coulomb: 0.0213,
            viscous: 1.5e-3,
            smoothing_velocity: 0.25,
            velocity: VelocitySource::OutputDifference { filter_hz: 80.0 },
            lag_aware: Some(LagAwareFriction {
                lag_s: 3e-3,
                horizon_s: 1e-3,
                stick_band: 1e-4,
            }),
        }),
        dead_zone_inverse: Some(DeadZoneInverse {
            width: 0.12,
            smoothing: 3e-3,
        }),
        backlash_inverse: Some(BacklashInverse {
            gap: 0.05,
            smoothing: 0.01,
        }),
        anti_windup: Some(AntiWindup {
            u_min: -2.5,
            u_max: 3.0,
            tracking_time_s: 0.02,
        }),
    }
}

/// The compensation numbers in emission order: the inputs, then the derived filter
/// coefficient alpha = 1 - exp(-2 pi f ts) and back-calculation gain ts/T_t (f64 here).
fn comp_numbers(c: &Compensation, ts: f64) -> Vec<f64> {
    let ff = c.friction_feedforward.unwrap();
    let VelocitySource::OutputDifference { filter_hz } = ff.velocity else {
        panic!("test compensation filters the output difference")
    };
    let dz = c.dead_zone_inverse.unwrap();
    let bl = c.backlash_inverse.unwrap();
    let aw = c.anti_windup.unwrap();
    let la = ff.lag_aware.expect("test compensation is lag-aware");
    let alpha = 1.0 - (-2.0 * std::f64::consts::PI * filter_hz * ts).exp();
    vec![
        ff.coulomb,
        ff.viscous,
        ff.smoothing_velocity,
        filter_hz,
        1.0 - (-2.0 * std::f64::consts::PI * filter_hz * ts).exp(),
        dz.width,
        dz.smoothing,
        bl.gap,
        bl.smoothing,
        aw.u_min,
        aw.u_max,
        aw.tracking_time_s,
        ts / aw.tracking_time_s,
        la.lag_s,
        la.horizon_s,
        la.stick_band,
        (-ts / la.lag_s).exp(),
        // horizon + the output difference's delay ts/2 + ts(1 − α)/α
        la.horizon_s + ts / 2.0 + ts * (1.0 - alpha) / alpha,
    ]
}

/// The smallest input: 1 state, no PID, no continuous model, no sources or receipts.
fn minimal_input() -> CodegenInput {
    let mut i = full_input();
    i.prefix = "m".into();
    i.model.matrices = Matrices {
        a: vec![vec![0.9]],
        b: vec![vec![1.0]],
        c: vec![vec![0.1]],
        d: vec![vec![0.0]],
    };
    i.continuous = None;
    i.pid = None;
    i.weight = WeightCoefficients {
        num: vec![0.1],
        den: vec![1.0],
        note: "flat".into(),
    };
    i.provenance.sources.clear();
    i.provenance.receipts.clear();
    i.provenance.notes.clear();
    i.compensation = None;
    i
}

fn run(cmd: &mut Command, what: &str) -> String {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("{what}: cannot start {cmd:?}: {e} (is it installed?)"));
    assert!(
        out.status.success(),
        "{what} failed: {cmd:?}\nstdout:\n{}\nstderr:\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Writes `module` into a fresh scratch dir and compiles it inside a `no_std` library with
/// warnings and missing docs denied; returns (dir, module path).
fn no_std_module(name: &str, file: &str, module: &str) -> (PathBuf, PathBuf) {
    let dir = scratch(name);
    let path = dir.join(file);
    std::fs::write(&path, module).unwrap();
    let lib = dir.join("lib.rs");
    std::fs::write(
        &lib,
        format!(
            "#![no_std]\n#![deny(warnings, missing_docs)]\n//! test\n/// flashed\npub mod flashed {{ include!({:?}); }}\n",
            path.display().to_string()
        ),
    )
    .unwrap();
    run(
        Command::new("rustc")
            .args([
                "--edition",
                "2021",
                "--crate-type",
                "lib",
                "--emit",
                "metadata",
            ])
            .args(["-D", "warnings", "--out-dir"])
            .arg(&dir)
            .arg(&lib),
        "rustc (no_std library)",
    );
    (dir, path)
}

const GCC_FLAGS: &[&str] = &["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"];

fn compile_c(dir: &Path, main_c: &str, exe: Option<&str>) {
    let src = dir.join("main.c");
    std::fs::write(&src, main_c).unwrap();
    let mut cmd = Command::new("gcc");
    cmd.args(GCC_FLAGS).arg("-I").arg(dir);
    match exe {
        Some(e) => cmd.arg("-o").arg(dir.join(e)).arg(&src).arg("-lm"),
        None => cmd.arg("-c").arg("-o").arg(dir.join("main.o")).arg(&src),
    };
    run(&mut cmd, "gcc");
}

#[test]
fn c_header_compiles_with_strict_flags_for_every_section_combination() {
    let mut disabled = minimal_input();
    disabled.prefix = "disabled comp".into();
    disabled.compensation = Some(Compensation {
        enabled: false,
        friction_feedforward: None,
        backlash_inverse: None,
        anti_windup: None,
        ..full_compensation()
    });
    for (name, input) in [
        ("full", full_input()),
        ("minimal", minimal_input()),
        ("disabled", disabled),
    ] {
        let dir = scratch(&format!("cc-{name}"));
        let g = generate(&input).unwrap();
        std::fs::write(dir.join(&g.c_file_name), &g.c_header).unwrap();
        // Included twice (guard) and otherwise unused: no warning may fire.
        let main = format!(
            "#include \"{0}\"\n#include \"{0}\"\nint main(void) {{ return 0; }}\n",
            g.c_file_name
        );
        compile_c(&dir, &main, None);
    }
}

/// Parses `NAME v v v` lines into a map.
fn parse_dump(text: &str) -> std::collections::BTreeMap<String, Vec<f64>> {
    text.lines()
        .filter_map(|l| {
            let mut it = l.split_whitespace();
            let name = it.next()?.to_string();
            let vals = it.map(|v| v.parse::<f64>().expect(v)).collect();
            Some((name, vals))
        })
        .collect()
}

fn flat(m: &[Vec<f64>]) -> Vec<f64> {
    m.iter().flatten().copied().collect()
}

/// Every emitted number reads back as exactly `value as f32`.
fn assert_exact(dump: &std::collections::BTreeMap<String, Vec<f64>>, input: &CodegenInput) {
    let m = &input.model.matrices;
    let pid = input.pid.as_ref().unwrap();
    let bq = pid.rolloff.unwrap();
    let g = generate(input).unwrap();
    let expect: Vec<(&str, Vec<f64>)> = vec![
        ("A", flat(&m.a)),
        ("B", flat(&m.b)),
        ("C", flat(&m.c)),
        ("D", flat(&m.d)),
        ("TS", vec![input.model.ts_s]),
        ("PID", vec![pid.kp, pid.ki_d, pid.a_d, pid.b_d]),
        ("RB", bq.b.to_vec()),
        ("RA", bq.a.to_vec()),
        ("WN", input.weight.num.clone()),
        ("WD", input.weight.den.clone()),
        ("HZ", g.checks.iter().map(|c| c.hz).collect()),
        ("BIN", g.checks.iter().map(|c| c.bin as f64).collect()),
        ("GATE", vec![input.self_id.coherence_gate]),
        (
            "COMP",
            comp_numbers(input.compensation.as_ref().unwrap(), input.model.ts_s),
        ),
    ];
    for (name, want) in expect {
        let got = dump.get(name).unwrap_or_else(|| panic!("no {name} line"));
        assert_eq!(got.len(), want.len(), "{name}");
        for (k, (g, w)) in got.iter().zip(&want).enumerate() {
            assert_eq!(
                (*g as f32).to_bits(),
                (*w as f32).to_bits(),
                "{name}[{k}]: emitted {g}, input {w}"
            );
        }
    }
}

/// f64 reference: step response of (A, B, C, D) from x = 0, u = 1, `n` samples.
fn step_reference(m: &Matrices, n: usize) -> Vec<f64> {
    let ns = m.a.len();
    let mut x = vec![0.0f64; ns];
    let mut y = Vec::with_capacity(n);
    for _ in 0..n {
        let yk: f64 = (0..ns).map(|j| m.c[0][j] * x[j]).sum::<f64>() + m.d[0][0];
        y.push(yk);
        let xn: Vec<f64> = (0..ns)
            .map(|i| (0..ns).map(|j| m.a[i][j] * x[j]).sum::<f64>() + m.b[i][0])
            .collect();
        x = xn;
    }
    y
}

const STEPS: usize = 3000;

#[test]
fn c_program_reads_back_exact_values_and_simulates_the_step() {
    let input = full_input();
    let g = generate(&input).unwrap();
    let dir = scratch("c-sim");
    std::fs::write(dir.join(&g.c_file_name), &g.c_header).unwrap();
    let p = &g.prefix;
    let main = format!(
        r#"#include <stdio.h>
#include "{file}"
static void row(const char *name, const float *v, int n) {{
    int i;
    printf("%s", name);
    for (i = 0; i < n; i++) printf(" %.9g", (double)v[i]);
    printf("\n");
}}
int main(void) {{
    float x[{p}_N_STATES] = {{0}}, xn[{p}_N_STATES];
    float pid[4] = {{ {p}_PID_KP, {p}_PID_KI_D, {p}_PID_A_D, {p}_PID_B_D }};
    float ts = {p}_TS_S, gate = {p}_COHERENCE_GATE;
    float comp[18] = {{ {p}_COMP_FF_COULOMB, {p}_COMP_FF_VISCOUS, {p}_COMP_FF_SMOOTHING_VELOCITY,
        {p}_COMP_FF_FILTER_HZ, {p}_COMP_FF_FILTER_ALPHA, {p}_COMP_DZ_WIDTH, {p}_COMP_DZ_SMOOTHING,
        {p}_COMP_BL_GAP, {p}_COMP_BL_SMOOTHING, {p}_COMP_AW_U_MIN, {p}_COMP_AW_U_MAX,
        {p}_COMP_AW_TRACKING_TIME_S, {p}_COMP_AW_GAIN, {p}_COMP_FF_LAG_S, {p}_COMP_FF_LAG_HORIZON_S,
        {p}_COMP_FF_LAG_STICK_BAND, {p}_COMP_FF_LAG_POLE, {p}_COMP_FF_LAG_PREDICTION_S }};
    int k, i, j;
    row("A", &{p}_A[0][0], {p}_N_STATES * {p}_N_STATES);
    row("B", &{p}_B[0][0], {p}_N_STATES * {p}_N_INPUTS);
    row("C", &{p}_C[0][0], {p}_N_OUTPUTS * {p}_N_STATES);
    row("D", &{p}_D[0][0], {p}_N_OUTPUTS * {p}_N_INPUTS);
    row("TS", &ts, 1);
    row("PID", pid, 4);
    row("RB", {p}_PID_ROLLOFF_B, 3);
    row("RA", {p}_PID_ROLLOFF_A, 3);
    row("WN", {p}_WM_NUM, {p}_WM_ORDER + 1);
    row("WD", {p}_WM_DEN, {p}_WM_ORDER + 1);
    row("HZ", {p}_CHECK_HZ, {p}_CHECK_COUNT);
    row("GATE", &gate, 1);
    row("COMP", comp, 18);
    printf("COMPSTR %s|%s|%s|%s\n", {p}_COMP_EFFECT, {p}_COMP_PLACE, {p}_COMP_VERDICT, {p}_COMP_SOURCE);
    if (!({p}_HAS_COMPENSATION == 1 && {p}_COMP_ENABLED == 1 && {p}_COMP_HAS_FRICTION_FF == 1
          && {p}_COMP_FF_VELOCITY == {p}_COMP_FF_VELOCITY_OUTPUT_DIFFERENCE
          && {p}_COMP_HAS_DEAD_ZONE_INVERSE == 1 && {p}_COMP_HAS_BACKLASH_INVERSE == 1
          && {p}_COMP_HAS_ANTI_WINDUP == 1 && {p}_COMP_FF_LAG_AWARE == 1)) return 4;
    printf("BIN");
    for (i = 0; i < {p}_CHECK_COUNT; i++) printf(" %u", (unsigned){p}_CHECK_BIN[i]);
    printf("\nSHA %s\nSTEP", {p}_INPUTS_SHA256);
    for (k = 0; k < {steps}; k++) {{
        float y = {p}_D[0][0];
        for (j = 0; j < {p}_N_STATES; j++) y += {p}_C[0][j] * x[j];
        printf(" %.9g", (double)y);
        for (i = 0; i < {p}_N_STATES; i++) {{
            xn[i] = {p}_B[i][0];
            for (j = 0; j < {p}_N_STATES; j++) xn[i] += {p}_A[i][j] * x[j];
        }}
        for (i = 0; i < {p}_N_STATES; i++) x[i] = xn[i];
    }}
    printf("\n");
    return {p}_HAS_PID == 1 && {p}_PID_HAS_ROLLOFF == 1 && {p}_SOURCE_COUNT == 2 ? 0 : 3;
}}
"#,
        file = g.c_file_name,
        steps = STEPS
    );
    compile_c(&dir, &main, Some("sim"));
    let out = run(&mut Command::new(dir.join("sim")), "C simulation");
    let sha_line = out.lines().find(|l| l.starts_with("SHA ")).unwrap();
    assert_eq!(&sha_line[4..], g.inputs_sha256);
    // Provenance strings survive the C string escaping byte for byte.
    let pv = &input.compensation.as_ref().unwrap().provenance;
    let strs = out
        .lines()
        .find_map(|l| l.strip_prefix("COMPSTR "))
        .unwrap();
    assert_eq!(
        strs,
        format!("{}|{}|{}|{}", pv.effect, pv.place, pv.verdict, pv.source)
    );
    let dump = parse_dump(
        &out.lines()
            .filter(|l| !l.starts_with("SHA") && !l.starts_with("COMPSTR"))
            .collect::<Vec<_>>()
            .join("\n"),
    );
    assert_exact(&dump, &input);

    // Step response in float vs the f64 reference: the plant's resonance (|z| = 0.99) rings
    // for ~1000 samples. Float coefficient rounding (relative 6e-8 on entries near 2, pole
    // shift ~1e-7) and float arithmetic stay below 1e-4 of the response peak.
    let y_ref = step_reference(&input.model.matrices, STEPS);
    let y_c = &dump["STEP"];
    let peak = y_ref.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let worst = y_ref
        .iter()
        .zip(y_c)
        .map(|(r, c)| (r - c).abs())
        .fold(0.0f64, f64::max);
    println!("C float step vs f64 reference: worst {worst:.3e}, peak {peak:.3e}");
    assert!(
        worst <= 1e-4 * peak,
        "worst {worst:e} > 1e-4 x peak {peak:e}"
    );
}

#[test]
fn rust_module_compiles_in_a_no_std_library_and_reads_back_exact_values() {
    let input = full_input();
    let g = generate(&input).unwrap();
    let (dir, module) = no_std_module("rs", &g.rs_file_name, &g.rust_module);
    // std program printing the constants.
    let main = dir.join("main.rs");
    std::fs::write(
        &main,
        format!(
            r#"#[allow(dead_code)]
mod flashed {{ include!({path:?}); }}
use flashed::*;
fn row(name: &str, v: &[f32]) {{
    print!("{{name}}");
    for x in v {{ print!(" {{x:?}}"); }}
    println!();
}}
fn main() {{
    row("A", A.as_flattened());
    row("B", B.as_flattened());
    row("C", C.as_flattened());
    row("D", D.as_flattened());
    row("TS", &[TS_S]);
    let p = PID.unwrap();
    row("PID", &[p.kp, p.ki_d, p.a_d, p.b_d]);
    let r = p.rolloff.unwrap();
    row("RB", &r.b);
    row("RA", &r.a);
    row("WN", &WM_NUM);
    row("WD", &WM_DEN);
    row("HZ", &CHECK_HZ);
    row("GATE", &[COHERENCE_GATE]);
    let c = COMPENSATION.unwrap();
    assert!(c.enabled);
    let ff = c.friction_feedforward.unwrap();
    let VelocitySource::OutputDifference {{ filter_hz, alpha }} = ff.velocity else {{ panic!() }};
    let dz = c.dead_zone_inverse.unwrap();
    let bl = c.backlash_inverse.unwrap();
    let aw = c.anti_windup.unwrap();
    let la = ff.lag_aware.unwrap();
    row("COMP", &[ff.coulomb, ff.viscous, ff.smoothing_velocity, filter_hz, alpha, dz.width,
        dz.smoothing, bl.gap, bl.smoothing, aw.u_min, aw.u_max, aw.tracking_time_s, aw.gain,
        la.lag_s, la.horizon_s, la.stick_band, la.pole, la.prediction_s]);
    assert_eq!(COMPENSATION_VERDICT, "explained */ \"quoted\" ??/");
    assert_eq!(COMPENSATION_PLACE, "drive");
    println!("BIN {{}}", CHECK_BIN.iter().map(|b| b.to_string()).collect::<Vec<_>>().join(" "));
    assert_eq!(SOURCES.len(), 2);
    assert_eq!(RECEIPTS.len(), 2);
    assert!(!RECEIPTS_ALL_PASS);
    assert_eq!(SELF_ID_SAMPLES, 5 * 512);
    assert_eq!(PREFIX, "GIMBAL_PITCH");
}}
"#,
            path = module.display().to_string()
        ),
    )
    .unwrap();
    let exe = dir.join("dump");
    run(
        Command::new("rustc")
            .args(["--edition", "2021", "-o"])
            .arg(&exe)
            .arg(&main),
        "rustc (dump program)",
    );
    let out = run(&mut Command::new(&exe), "Rust dump program");
    assert_exact(&parse_dump(&out), &input);
}

#[test]
fn same_input_gives_byte_identical_files_and_any_change_shows() {
    let a = generate(&full_input()).unwrap();
    let b = generate(&full_input().clone()).unwrap();
    assert_eq!(a.c_header, b.c_header);
    assert_eq!(a.rust_module, b.rust_module);
    assert_eq!(a.inputs_sha256, b.inputs_sha256);
    // No date (dddd-dd-dd) or time of day (dd:dd) leaks in; files end with one newline.
    for text in [&a.c_header, &a.rust_module] {
        let b = text.as_bytes();
        let digit = |i: usize| b.get(i).is_some_and(u8::is_ascii_digit);
        for i in 0..b.len() {
            let date = (0..4).all(|k| digit(i + k)) && b.get(i + 4) == Some(&b'-') && digit(i + 5);
            let time = digit(i) && digit(i + 1) && b.get(i + 2) == Some(&b':') && digit(i + 3);
            assert!(!date && !time, "date/time-like text at byte {i}");
        }
        assert!(text.ends_with('\n') && !text.ends_with("\n\n"));
    }
    // A change of one coefficient in the last bit of f32 changes the file and the digest.
    let mut changed = full_input();
    changed.model.matrices.a[2][2] = f64::from(f32::from_bits(0.95f32.to_bits() + 1));
    let c = generate(&changed).unwrap();
    assert_ne!(a.inputs_sha256, c.inputs_sha256);
    assert_ne!(a.c_header, c.c_header);
    // Changing a source log's digest changes the inputs digest.
    let mut src = full_input();
    src.provenance.sources[0].sha256 = sha256_hex(b"unit A, re-run");
    assert_ne!(generate(&src).unwrap().inputs_sha256, a.inputs_sha256);
    // The tool version alone does not.
    let mut tool = full_input();
    tool.provenance.tool = "ferrosid 9.9.9".into();
    assert_eq!(generate(&tool).unwrap().inputs_sha256, a.inputs_sha256);
}

#[test]
fn sha256_matches_the_fips_180_test_vectors() {
    assert_eq!(
        sha256_hex(b"abc"),
        "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
    );
    assert_eq!(
        sha256_hex(b""),
        "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855"
    );
}

#[test]
fn runtime_engine_renders_the_builtin_templates_byte_identically() {
    let mut with_sk = full_input();
    with_sk.state_controller = Some(state_controller());
    for input in [full_input(), minimal_input(), with_sk] {
        let a = generate(&input).unwrap();
        let r = generate_builtin_runtime(&input).unwrap();
        for (x, y) in [(&a.c_header, &r.c_header), (&a.rust_module, &r.rust_module)] {
            let diff: Vec<(usize, &str, &str)> = x
                .lines()
                .zip(y.lines())
                .enumerate()
                .filter(|(_, (p, q))| p != q)
                .map(|(i, (p, q))| (i + 1, p, q))
                .take(5)
                .collect();
            assert!(
                diff.is_empty(),
                "askama vs minijinja differ (line, askama, minijinja): {diff:#?}"
            );
            assert_eq!(x, y);
        }
    }
}

#[test]
fn user_templates_override_and_errors_name_the_file_and_line() {
    let dir = scratch("tpl");
    let input = full_input();
    // Only the C template is overridden; the Rust one falls back to the built-in.
    let custom = builtin_template(C_TEMPLATE).unwrap().replace(
        "#include <stdint.h>",
        "#include <stdint.h>\n/* house style: {{ c.p }} */",
    );
    std::fs::write(dir.join(C_TEMPLATE), custom).unwrap();
    let g = generate_with_templates(&input, &dir).unwrap();
    assert!(g.c_header.contains("/* house style: GIMBAL_PITCH */"));
    assert_eq!(g.rust_module, generate(&input).unwrap().rust_module);
    // The overridden header still compiles.
    std::fs::write(dir.join(&g.c_file_name), &g.c_header).unwrap();
    compile_c(
        &dir,
        &format!(
            "#include \"{}\"\nint main(void) {{ return 0; }}\n",
            g.c_file_name
        ),
        None,
    );

    std::fs::write(dir.join(C_TEMPLATE), "line one\n{{ c.no_such_variable }}\n").unwrap();
    let e = generate_with_templates(&input, &dir)
        .unwrap_err()
        .to_string();
    assert!(e.contains("model.h") && e.contains("line 2"), "{e}");

    std::fs::write(dir.join(C_TEMPLATE), "{% for x in c.checks %}\nunclosed\n").unwrap();
    let e = generate_with_templates(&input, &dir)
        .unwrap_err()
        .to_string();
    assert!(e.contains("model.h"), "{e}");
}

#[test]
fn prefix_is_sanitised_into_every_identifier_and_the_file_names() {
    let mut input = minimal_input();
    input.prefix = "3-axis gimbal/pitch".into();
    let g = generate(&input).unwrap();
    assert_eq!(g.prefix, "P_3_AXIS_GIMBAL_PITCH");
    assert_eq!(g.c_file_name, "p_3_axis_gimbal_pitch.h");
    assert_eq!(g.rs_file_name, "p_3_axis_gimbal_pitch.rs");
    assert!(g.c_header.contains("#ifndef P_3_AXIS_GIMBAL_PITCH_MODEL_H"));
    assert!(g
        .c_header
        .contains("#define P_3_AXIS_GIMBAL_PITCH_N_STATES 1"));
    assert!(g
        .rust_module
        .contains("pub const PREFIX: &str = \"P_3_AXIS_GIMBAL_PITCH\";"));
    // Every C identifier after `#define` / `float` / `uint16_t` / `char` starts with the prefix.
    for line in g.c_header.lines() {
        for kw in ["#define ", "static const float ", "static const uint16_t "] {
            if let Some(rest) = line.strip_prefix(kw) {
                assert!(rest.starts_with("P_3_AXIS_GIMBAL_PITCH_"), "{line}");
            }
        }
    }
    let dir = scratch("prefix");
    std::fs::write(dir.join(&g.c_file_name), &g.c_header).unwrap();
    compile_c(
        &dir,
        &format!(
            "#include \"{}\"\nint main(void) {{ return 0; }}\n",
            g.c_file_name
        ),
        None,
    );
    // Hostile free text cannot break out of comments or strings: the full input's note holds
    // "*/" and a receipt "??/", and the header compiled above; check the text too.
    let full = generate(&full_input()).unwrap();
    assert!(full.c_header.contains("* / with a comment terminator"));
    assert!(!full.c_header.contains("??"));
    assert!(full.c_header.contains(r#""logs/unit \"A\".csv""#));
}

fn input_error(input: &CodegenInput) -> String {
    match generate(input) {
        Err(e @ Error::Input { .. }) => e.to_string(),
        other => panic!("expected an input error, got {other:?}"),
    }
}

/// An edit of a valid input that makes it invalid.
type Edit = Box<dyn Fn(&mut CodegenInput)>;

#[test]
fn bad_input_is_an_error_naming_the_field() {
    let base = full_input();
    let cases: Vec<(Edit, &str)> = vec![
        (
            Box::new(|i| i.model.matrices.a[1].pop().map(|_| ()).unwrap_or(())),
            "model.a[1]",
        ),
        (
            Box::new(|i| i.model.matrices.b[2][0] = f64::NAN),
            "model.b[2][0]",
        ),
        (
            Box::new(|i| i.model.matrices.c[0][1] = 1e39),
            "model.c[0][1]",
        ),
        (Box::new(|i| i.model.matrices.a.clear()), "model.a"),
        (Box::new(|i| i.model.ts_s = 0.0), "model.ts_s"),
        (
            Box::new(|i| {
                if let Some(c) = i.continuous.as_mut() {
                    c.matrices.a.pop();
                }
            }),
            "continuous.a[0]",
        ),
        (
            Box::new(|i| {
                if let Some(p) = i.pid.as_mut() {
                    p.ts_s = 2e-3;
                }
            }),
            "pid.ts_s",
        ),
        (
            Box::new(|i| {
                if let Some(p) = i.pid.as_mut() {
                    p.rolloff = Some(Biquad {
                        b: [1.0; 3],
                        a: [2.0, 0.0, 0.0],
                    });
                }
            }),
            "pid.rolloff.a[0]",
        ),
        (
            Box::new(|i| i.weight.den.pop().map(|_| ()).unwrap_or(())),
            "weight",
        ),
        (
            Box::new(|i| i.weight.num[1] = f64::INFINITY),
            "weight.num[1]",
        ),
        (Box::new(|i| i.self_id.welch_n = 500), "self_id.welch_n"),
        (
            Box::new(|i| i.self_id.coherence_gate = 1.0),
            "self_id.coherence_gate",
        ),
        (Box::new(|i| i.self_id.averages = 1), "self_id.averages"),
        (
            Box::new(|i| i.self_id.excitation_max_hz = 600.0),
            "self_id.excitation_max_hz",
        ),
        (
            Box::new(|i| i.self_id.check_hz.push(300.0)),
            "self_id.check_hz[6]",
        ),
        (
            Box::new(|i| i.self_id.check_hz.push(0.5)),
            "self_id.check_hz[6]",
        ),
        (
            Box::new(|i| i.self_id.check_hz.push(f64::NAN)),
            "self_id.check_hz[6]",
        ),
        (
            Box::new(|i| i.self_id.check_hz.push(16.5)),
            "self_id.check_hz",
        ),
        (Box::new(|i| i.self_id.check_hz.clear()), "self_id.check_hz"),
        (
            Box::new(|i| i.self_id.min_checked = 7),
            "self_id.min_checked",
        ),
        (
            Box::new(|i| i.provenance.sources[1].sha256 = "ABC".into()),
            "provenance.sources[1].sha256",
        ),
        (Box::new(|i| i.prefix = "--".into()), "prefix"),
        (
            Box::new(|i| {
                i.compensation = Some(Compensation {
                    enabled: true,
                    provenance: CompensationProvenance {
                        effect: "dead_zone".into(),
                        place: "drive".into(),
                        verdict: "explained".into(),
                        source: "test".into(),
                        nrmse_before: None,
                        nrmse_after: None,
                    },
                    friction_feedforward: None,
                    dead_zone_inverse: Some(DeadZoneInverse {
                        width: f64::NAN,
                        smoothing: 0.01,
                    }),
                    backlash_inverse: None,
                    anti_windup: None,
                })
            }),
            "compensation.dead_zone_inverse.width",
        ),
    ];
    for (k, (edit, field)) in cases.iter().enumerate() {
        let mut i = base.clone();
        edit(&mut i);
        let e = input_error(&i);
        assert!(
            e.contains(&format!("`{field}`")),
            "case {k}: error {e:?} does not name `{field}`"
        );
    }
    // The duplicate-bin message names both requested frequencies.
    let mut i = base.clone();
    i.self_id.check_hz.push(16.5);
    let e = input_error(&i);
    assert!(e.contains("16 Hz") && e.contains("16.5 Hz"), "{e}");
}

/// A 2-state discrete controller (lag + lead) at the model's 1 kHz.
fn state_controller() -> StateController {
    StateController {
        method: "hinf".into(),
        ts_s: 1e-3,
        matrices: Matrices {
            a: vec![vec![0.995, 0.01], vec![-0.02, 0.9]],
            b: vec![vec![0.5], vec![1.25]],
            c: vec![vec![0.03, -0.011]],
            d: vec![vec![0.002]],
        },
        note: "test controller".into(),
        mpc: None,
        saturation: None,
        pid_notch: None,
    }
}

/// f64 reference: u[k] of the controller for e = 1 from xi = 0.
fn controller_reference(m: &Matrices, n: usize) -> Vec<f64> {
    let ns = m.a.len();
    let mut x = vec![0.0f64; ns];
    (0..n)
        .map(|_| {
            let u = (0..ns).map(|j| m.c[0][j] * x[j]).sum::<f64>() + m.d[0][0];
            x = (0..ns)
                .map(|i| (0..ns).map(|j| m.a[i][j] * x[j]).sum::<f64>() + m.b[i][0])
                .collect();
            u
        })
        .collect()
}

#[test]
fn state_controller_block_compiles_in_c_and_no_std_rust_and_steps_like_f64() {
    let mut input = full_input();
    input.state_controller = Some(state_controller());
    let g = generate(&input).unwrap();
    // Absent block: nothing of it in the files (the PID-only output is unchanged).
    let plain = generate(&full_input()).unwrap();
    assert!(!plain.c_header.contains("STATE_CONTROLLER") && !plain.rust_module.contains("k_step"));
    assert_ne!(g.inputs_sha256, plain.inputs_sha256);
    let reference = controller_reference(&state_controller().matrices, 200);
    let peak = reference.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    // C: strict flags, then 200 steps with e = 1 against the f64 reference (f32 arithmetic:
    // relative 1e-4 of the peak).
    let dir = scratch("sk-c");
    std::fs::write(dir.join(&g.c_file_name), &g.c_header).unwrap();
    let p = "GIMBAL_PITCH";
    let main = format!(
        "#include <stdio.h>\n#include \"{f}\"\nint main(void) {{\n    float xi[{p}_K_N_STATES] = {{0}};\n    int k;\n    for (k = 0; k < 200; ++k) {{\n        printf(\"%.9g\\n\", (double){p}_k_step(xi, 1.0f));\n    }}\n    return 0;\n}}\n",
        f = g.c_file_name
    );
    compile_c(&dir, &main, Some("sk"));
    let out = run(&mut Command::new(dir.join("sk")), "sk");
    let got: Vec<f64> = out.lines().map(|l| l.parse().unwrap()).collect();
    assert_eq!(got.len(), 200);
    for (k, (a, b)) in got.iter().zip(&reference).enumerate() {
        assert!((a - b).abs() <= 1e-4 * peak, "C u[{k}] {a} vs {b}");
    }
    // Rust: no_std library with warnings and missing docs denied, then a std program.
    let (dir, module) = no_std_module("sk-rs", &g.rs_file_name, &g.rust_module);
    let main = dir.join("main.rs");
    std::fs::write(
        &main,
        format!(
            "#[allow(dead_code)]\nmod flashed {{ include!({:?}); }}\nfn main() {{\n    let mut xi = [0.0f32; flashed::K_N_STATES];\n    for _ in 0..200 {{\n        println!(\"{{}}\", flashed::k_step(&mut xi, 1.0));\n    }}\n}}\n",
            module.display().to_string()
        ),
    )
    .unwrap();
    run(
        Command::new("rustc")
            .args(["--edition", "2021", "-o"])
            .arg(dir.join("skrs"))
            .arg(&main),
        "rustc (std program)",
    );
    let out = run(&mut Command::new(dir.join("skrs")), "skrs");
    let got: Vec<f64> = out.lines().map(|l| l.parse().unwrap()).collect();
    assert_eq!(got.len(), 200);
    for (k, (a, b)) in got.iter().zip(&reference).enumerate() {
        assert!((a - b).abs() <= 1e-4 * peak, "Rust u[{k}] {a} vs {b}");
    }
}

#[test]
fn bad_state_controller_is_an_error_naming_the_field() {
    let mut input = full_input();
    let mut k = state_controller();
    k.ts_s = 2e-3;
    input.state_controller = Some(k);
    let e = generate(&input).unwrap_err().to_string();
    assert!(e.contains("state_controller.ts_s"), "{e}");
    let mut k = state_controller();
    k.matrices.b = vec![vec![0.5, 1.0], vec![1.25, 0.0]];
    k.matrices.d = vec![vec![0.0, 0.0]];
    input.state_controller = Some(k);
    let e = generate(&input).unwrap_err().to_string();
    assert!(e.contains("state_controller") && e.contains("SISO"), "{e}");
    let mut k = state_controller();
    k.matrices.a[1][0] = f64::NAN;
    input.state_controller = Some(k);
    let e = generate(&input).unwrap_err().to_string();
    assert!(e.contains("state_controller.a[1][0]"), "{e}");
}

// ---- MPC block -----------------------------------------------------------------------------

/// Dense Gauss–Jordan inverse (test-only reference; the matrices here are small and SPD).
fn inverse(m: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let n = m.len();
    let mut a: Vec<Vec<f64>> = m
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let mut r = r.clone();
            r.extend((0..n).map(|j| if i == j { 1.0 } else { 0.0 }));
            r
        })
        .collect();
    for c in 0..n {
        let p = (c..n)
            .max_by(|&x, &y| a[x][c].abs().total_cmp(&a[y][c].abs()))
            .unwrap();
        a.swap(c, p);
        let d = a[c][c];
        for v in a[c].iter_mut() {
            *v /= d;
        }
        for r in 0..n {
            if r != c {
                let f = a[r][c];
                let row_c = a[c].clone();
                for (v, w) in a[r].iter_mut().zip(row_c) {
                    *v -= f * w;
                }
            }
        }
    }
    a.into_iter().map(|r| r[n..].to_vec()).collect()
}

/// The MPC of the full input's plant (horizon `n`), designed here in f64 from the formulas of
/// `ferrosid::synth::mpc` (condensed Γ, Φ; H = 2(qΓᵀΓ + ρ_ΔDᵀD); K = (H + σI + ρMᵀM)⁻¹).
fn mpc_of_full_input(n: usize) -> MpcController {
    let m = full_input().model.matrices;
    let nx = m.a.len();
    let (q, r_rate, rho, sigma) = (1.0, 1e-2, 1.0, 1e-6);
    let mut phi = vec![vec![0.0; nx]; n];
    let mut markov = vec![0.0; n];
    let mut c_ak = m.c[0].clone();
    for k in 0..n {
        markov[k] = (0..nx).map(|j| c_ak[j] * m.b[j][0]).sum();
        c_ak = (0..nx)
            .map(|j| (0..nx).map(|i| c_ak[i] * m.a[i][j]).sum())
            .collect();
        phi[k] = c_ak.clone();
    }
    let gamma = |k: usize, j: usize| if j <= k { markov[k - j] } else { 0.0 };
    let dd = |i: usize, j: usize| {
        if i == j {
            1.0
        } else if j + 1 == i {
            -1.0
        } else {
            0.0
        }
    };
    let mut kk = vec![vec![0.0; n]; n];
    for i in 0..n {
        for j in 0..n {
            let gtg: f64 = (0..n).map(|k| gamma(k, i) * gamma(k, j)).sum();
            let dtd: f64 = (0..n).map(|k| dd(k, i) * dd(k, j)).sum();
            let mtm = if i == j { 1.0 } else { 0.0 } + dtd;
            kk[i][j] =
                2.0 * (q * gtg + r_rate * dtd) + if i == j { sigma } else { 0.0 } + rho * mtm;
        }
    }
    MpcController {
        horizon: n,
        k: inverse(&kk),
        gx: (0..n)
            .map(|i| {
                (0..nx)
                    .map(|j| 2.0 * q * (0..n).map(|k| gamma(k, i) * phi[k][j]).sum::<f64>())
                    .collect()
            })
            .collect(),
        gr: (0..n)
            .map(|i| 2.0 * q * (0..n).map(|k| gamma(k, i)).sum::<f64>())
            .collect(),
        two_r_rate: 2.0 * r_rate,
        sigma,
        rho,
        u_min: -0.4,
        u_max: 0.5,
        du_max: 0.05,
        iterations: 40,
    }
}

fn mpc_block(n: usize) -> StateController {
    StateController {
        method: "mpc".into(),
        ts_s: 1e-3,
        matrices: full_input().model.matrices,
        note: "test MPC".into(),
        mpc: Some(mpc_of_full_input(n)),
        saturation: None,
        pid_notch: None,
    }
}

/// f64 reference of the closed loop (plant = the model, state fed back) with the ADMM written
/// on the dense M = [I; D] (not the O(N) structure the generated code uses): (y, u) per sample.
fn mpc_reference(c: &MpcController, m: &Matrices, r: f64, samples: usize) -> Vec<(f64, f64)> {
    let n = c.horizon;
    let nx = m.a.len();
    let mm = |i: usize, j: usize| -> f64 {
        if i < n {
            f64::from(u8::from(i == j))
        } else if i - n == j {
            1.0
        } else if j + 1 == i - n {
            -1.0
        } else {
            0.0
        }
    };
    let (mut u, mut z, mut l) = (vec![0.0; n], vec![0.0; 2 * n], vec![0.0; 2 * n]);
    let mut x = vec![0.0; nx];
    let mut u_prev = 0.0;
    let mut out = Vec::new();
    for _ in 0..samples {
        let y: f64 = (0..nx).map(|j| m.c[0][j] * x[j]).sum();
        let mut f: Vec<f64> = (0..n)
            .map(|i| (0..nx).map(|j| c.gx[i][j] * x[j]).sum::<f64>() - c.gr[i] * r)
            .collect();
        f[0] -= c.two_r_rate * u_prev;
        let (mut lo, mut hi) = (vec![c.u_min; 2 * n], vec![c.u_max; 2 * n]);
        for i in n..2 * n {
            lo[i] = -c.du_max;
            hi[i] = c.du_max;
        }
        lo[n] += u_prev;
        hi[n] += u_prev;
        for _ in 0..c.iterations {
            let rhs: Vec<f64> = (0..n)
                .map(|j| {
                    c.sigma * u[j] - f[j]
                        + (0..2 * n)
                            .map(|i| mm(i, j) * (c.rho * z[i] - l[i]))
                            .sum::<f64>()
                })
                .collect();
            u = (0..n)
                .map(|i| (0..n).map(|j| c.k[i][j] * rhs[j]).sum())
                .collect();
            for i in 0..2 * n {
                let mu: f64 = (0..n).map(|j| mm(i, j) * u[j]).sum();
                z[i] = (mu + l[i] / c.rho).clamp(lo[i], hi[i]);
                l[i] += c.rho * (mu - z[i]);
            }
        }
        let un = z[0]
            .clamp(u_prev - c.du_max, u_prev + c.du_max)
            .clamp(c.u_min, c.u_max);
        let shift = |v: &mut [f64]| {
            v.rotate_left(1);
            if n >= 2 {
                v[n - 1] = v[n - 2];
            }
        };
        shift(&mut u);
        shift(&mut z[..n]);
        shift(&mut z[n..]);
        shift(&mut l[..n]);
        shift(&mut l[n..]);
        out.push((y, un));
        x = (0..nx)
            .map(|i| (0..nx).map(|j| m.a[i][j] * x[j]).sum::<f64>() + m.b[i][0] * un)
            .collect();
        u_prev = un;
    }
    out
}

fn parse_pairs(text: &str) -> Vec<(f64, f64)> {
    text.lines()
        .map(|l| {
            // The printed f32 values, read back as f32 (exact), then widened.
            let v: Vec<f64> = l
                .split_whitespace()
                .map(|t| f64::from(t.parse::<f32>().unwrap()))
                .collect();
            (v[0], v[1])
        })
        .collect()
}

fn check_mpc_trace(what: &str, got: &[(f64, f64)], reference: &[(f64, f64)], c: &MpcController) {
    assert_eq!(got.len(), reference.len(), "{what}");
    let y_peak = reference.iter().fold(0.0f64, |m, v| m.max(v.0.abs()));
    let mut u_prev = 0.0;
    let mut at_rail = 0;
    for (k, ((y, u), (yr, ur))) in got.iter().zip(reference).enumerate() {
        // The rails and the rate limit hold exactly in f32 (up to its rounding of u_prev ± Δu).
        assert!(
            *u >= c.u_min as f32 as f64 && *u <= c.u_max as f32 as f64,
            "{what} u[{k}] {u}"
        );
        assert!(
            (u - u_prev).abs() <= c.du_max * (1.0 + 1e-5),
            "{what} Δu[{k}]"
        );
        // f32 against f64: 1e-3 of the output peak, 2e-3 of the box width for u.
        assert!((y - yr).abs() <= 1e-3 * y_peak, "{what} y[{k}] {y} vs {yr}");
        assert!(
            (u - ur).abs() <= 2e-3 * (c.u_max - c.u_min),
            "{what} u[{k}] {u} vs {ur}"
        );
        if *u >= c.u_max as f32 as f64 {
            at_rail += 1;
        }
        u_prev = *u;
    }
    assert!(at_rail > 0, "{what}: the step must reach the rail");
}

#[test]
fn mpc_block_compiles_in_c_and_no_std_rust_and_runs_like_an_f64_reference() {
    let mut input = full_input();
    input.state_controller = Some(mpc_block(8));
    let g = generate(&input).unwrap();
    assert!(!g.c_header.contains("HAS_STATE_CONTROLLER") && !g.rust_module.contains("k_step"));
    let c = mpc_of_full_input(8);
    let m = full_input().model.matrices;
    let r = 4.0;
    let reference = mpc_reference(&c, &m, r, 300);
    // C: strict flags, closed loop with the header's model.
    let dir = scratch("mpc-c");
    std::fs::write(dir.join(&g.c_file_name), &g.c_header).unwrap();
    let p = "GIMBAL_PITCH";
    let main = format!(
        "#include <stdio.h>\n#include \"{f}\"\nint main(void) {{\n    static struct {p}_mpc_warm w;\n    float x[{p}_N_STATES] = {{0}};\n    float u_prev = 0.0f;\n    int k, i, j;\n    for (k = 0; k < 300; ++k) {{\n        float y = 0.0f, u, nx[{p}_N_STATES];\n        for (j = 0; j < {p}_N_STATES; ++j) y += {p}_C[0][j] * x[j];\n        u = {p}_mpc_step(&w, x, {r:?}f, u_prev);\n        printf(\"%.9g %.9g\\n\", (double)y, (double)u);\n        for (i = 0; i < {p}_N_STATES; ++i) {{\n            nx[i] = {p}_B[i][0] * u;\n            for (j = 0; j < {p}_N_STATES; ++j) nx[i] += {p}_A[i][j] * x[j];\n        }}\n        for (i = 0; i < {p}_N_STATES; ++i) x[i] = nx[i];\n        u_prev = u;\n    }}\n    return 0;\n}}\n",
        f = g.c_file_name
    );
    compile_c(&dir, &main, Some("mpc"));
    let out = run(&mut Command::new(dir.join("mpc")), "mpc");
    check_mpc_trace("C", &parse_pairs(&out), &reference, &c);
    // Rust: no_std library (warnings, missing docs denied), then the firmware's solver
    // (`ferrosid_firmware::mpc`, included by path) built from the module's MPC_* consts.
    let (dir, module) = no_std_module("mpc-rs", &g.rs_file_name, &g.rust_module);
    let fw = Path::new(env!("CARGO_MANIFEST_DIR")).join("../firmware/src/mpc/mod.rs");
    let main = dir.join("main.rs");
    std::fs::write(
        &main,
        format!(
            "#[allow(dead_code)]\nmod flashed {{ include!({module:?}); }}\n#[allow(dead_code)]\n#[path = {fw:?}]\nmod mpc;\nuse flashed::*;\nstatic QP: mpc::MpcQp<MPC_N, MPC_NX> = mpc::MpcQp {{ k: MPC_K, gx: MPC_GX, gr: MPC_GR, two_r_rate: MPC_TWO_R_RATE, sigma: MPC_SIGMA, rho: MPC_RHO, u_min: MPC_U_MIN, u_max: MPC_U_MAX, du_max: MPC_DU_MAX, iterations: MPC_ITERATIONS }};\nfn main() {{\n    let mut w = mpc::MpcWarm::<MPC_N>::default();\n    let mut x = [0.0f32; N_STATES];\n    let mut u_prev = 0.0f32;\n    for _ in 0..300 {{\n        let y: f32 = C[0].iter().zip(x.iter()).map(|(c, v)| c * v).sum();\n        let u = QP.step(&mut w, &x, {r:?}, u_prev);\n        println!(\"{{y}} {{u}}\");\n        let mut nx = [0.0f32; N_STATES];\n        for i in 0..N_STATES {{\n            nx[i] = B[i][0] * u + A[i].iter().zip(x.iter()).map(|(a, v)| a * v).sum::<f32>();\n        }}\n        x = nx;\n        u_prev = u;\n    }}\n}}\n",
            module = module.display().to_string(),
            fw = fw.display().to_string()
        ),
    )
    .unwrap();
    run(
        Command::new("rustc")
            .args(["--edition", "2021", "-O", "-o"])
            .arg(dir.join("mpcrs"))
            .arg(&main),
        "rustc (std program with the firmware's MPC)",
    );
    let out = run(&mut Command::new(dir.join("mpcrs")), "mpcrs");
    check_mpc_trace("Rust", &parse_pairs(&out), &reference, &c);
}

#[test]
fn bad_mpc_block_is_an_error_naming_the_field() {
    let mut input = full_input();
    let cases: Vec<(Box<dyn Fn(&mut StateController)>, &str)> = vec![
        (
            Box::new(|k| k.mpc.as_mut().unwrap().k[2].pop().map(|_| ()).unwrap()),
            "state_controller.mpc.k[2]",
        ),
        (
            Box::new(|k| k.mpc.as_mut().unwrap().gx[1][0] = f64::NAN),
            "state_controller.mpc.gx[1][0]",
        ),
        (
            Box::new(|k| k.mpc.as_mut().unwrap().gr.push(1.0)),
            "state_controller.mpc.gr",
        ),
        (
            Box::new(|k| k.mpc.as_mut().unwrap().u_max = -1.0),
            "state_controller.mpc.u_max",
        ),
        (
            Box::new(|k| k.mpc.as_mut().unwrap().du_max = 0.0),
            "state_controller.mpc.du_max",
        ),
        (
            Box::new(|k| k.mpc.as_mut().unwrap().iterations = 0),
            "state_controller.mpc.iterations",
        ),
        (
            Box::new(|k| k.mpc.as_mut().unwrap().horizon = 65),
            "state_controller.mpc.horizon",
        ),
        (Box::new(|k| k.matrices.d[0][0] = 0.1), "state_controller.d"),
        (Box::new(|k| k.ts_s = 2e-3), "state_controller.ts_s"),
    ];
    for (edit, field) in cases {
        let mut k = mpc_block(4);
        edit(&mut k);
        input.state_controller = Some(k);
        let e = generate(&input).unwrap_err().to_string();
        assert!(e.contains(field), "{field}: {e}");
    }
}
