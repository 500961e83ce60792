//! End to end: the host identifies the bench axis from logs, fits W_m, tunes a robust PID and
//! generates the headers; the generated C compiles and simulates like the host; the power-up
//! firmware is built around the generated Rust module and run under QEMU against the nominal
//! and drifted plants; the host re-identifies the drifted plant from the target's spectra frame.
//!
//! References are independent of the code under test: the bench axis' exact ZOH response
//! (host matrix exponential) for the plants the firmware simulates (RK4 in f32), the host's
//! Hessenberg frequency response and polynomial W_m evaluation for the firmware's f32 complex
//! solve and Horner evaluation, the host `lti` simulation and `DiscretePid::update` for the C
//! program. Tolerances are stated at each assertion.
//!
//! Needs gcc, qemu-system-arm, llvm-size and the thumbv7em-none-eabihf target: when missing,
//! these tests FAIL with a message pointing at scripts/setup.sh.
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use ferrosid::cli::reidentify::reidentify;
use ferrosid::rational_fit::RationalFitOptions;
use ferrosid::robust::pid::DiscretePidState;
use ferrosid_tests::e2e::{
    build_powerup, run_codegen, run_pipeline, run_powerup, Axis, Pipeline, PowerupRun, CHECK_HZ,
    TS, WELCH_N,
};
use ferrosid_tests::{image_size, panic_sites, repo_root};
use num_complex::Complex64;

fn work_dir() -> PathBuf {
    repo_root().join("target").join("e2e")
}

/// The host pipeline, run once per test binary.
fn pipeline() -> &'static Pipeline {
    static P: OnceLock<Result<Pipeline, String>> = OnceLock::new();
    match P.get_or_init(|| run_pipeline(&work_dir())) {
        Ok(p) => p,
        Err(e) => panic!("host pipeline failed: {e}"),
    }
}

/// The power-up image built around the generated module, once per test binary.
fn powerup_elf() -> &'static Path {
    static E: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    match E.get_or_init(|| build_powerup(&pipeline().rust_module).map_err(|e| e.to_string())) {
        Ok(p) => p,
        Err(e) => panic!("building the power-up image: {e}"),
    }
}

fn run(args: &[String]) -> PowerupRun {
    let r = run_powerup(powerup_elf(), args).unwrap_or_else(|e| panic!("QEMU: {e}"));
    for l in r.lines.iter().filter(|l| !l.text.starts_with("FRAME ")) {
        println!("target: {l}");
    }
    r
}

fn scenario(words: &[&str]) -> Vec<String> {
    let mut a = Axis::nominal().firmware_args();
    a.extend(words.iter().map(|w| w.to_string()));
    a
}

/// |G_plant − G0| / |G0| / |W_m| at `f` for a plant given by its response.
fn predicted_ratio(p: &Pipeline, f: f64, g_plant: Complex64) -> f64 {
    let g0 = p.model.freq_response_siso(f).unwrap();
    (g_plant - g0).norm() / g0.norm() / p.weight.magnitude_hz(f)
}

#[test]
fn host_identifies_the_axis_fits_wm_tunes_and_generates() {
    let p = pipeline();
    println!(
        "N4SID order {}; W_m order {} (worst overbound ratio {:.3}); PID {:?}; crossover {:.2} Hz, \
         Ms {:.3}, ||W_m T|| {:?}; receipts all pass: {}",
        p.order,
        p.weight.order,
        p.weight.worst_overbound_ratio,
        p.tuned.pid,
        p.tuned.design.crossover_hz,
        p.tuned.ms,
        p.tuned.wm_t,
        p.receipts_all_pass
    );
    assert_eq!(p.order, 2, "the axis is second order");
    // Identified model vs the exact ZOH response of unit A: 1 % up to 150 Hz (noise 1e-3 rad
    // on 16 k samples).
    let ax = Axis::nominal();
    for k in 1..=75 {
        let f = 2.0 * k as f64;
        let g0 = p.model.freq_response_siso(f).unwrap();
        let g = ax.response_hz(f, 0);
        assert!(
            (g0 - g).norm() <= 0.01 * g.norm(),
            "model off by more than 1 % at {f} Hz"
        );
    }
    // The weight overbounds the measured envelope, and the nominal plant sits inside it at
    // every check frequency.
    assert!(p.weight.constraint_holds);
    for &f in &CHECK_HZ {
        let r = predicted_ratio(p, f, ax.response_hz(f, 0));
        assert!(r < 1.0, "nominal plant outside W_m at {f} Hz (ratio {r})");
    }
    assert!(p.tuned.wm_t.is_some_and(|v| v < 1.0));
    assert!(p.c_header.exists() && p.rust_module.exists());
}

fn gcc(dir: &Path, src: &str, exe: Option<&str>) {
    let c = dir.join(if exe.is_some() { "prog.c" } else { "inc.c" });
    std::fs::write(&c, src).unwrap();
    let mut cmd = Command::new("gcc");
    cmd.args(["-std=c99", "-Wall", "-Wextra", "-Werror", "-I"])
        .arg(dir);
    match exe {
        Some(e) => cmd.arg("-o").arg(dir.join(e)).arg(&c),
        None => cmd.arg("-c").arg("-o").arg(dir.join("inc.o")).arg(&c),
    };
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("cannot run gcc ({e}): install gcc (Debian package gcc)"));
    assert!(
        out.status.success(),
        "gcc failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

const STEPS: usize = 2000;

/// The error sequence fed to both PID implementations.
fn pid_error(k: usize) -> f64 {
    (if k % 400 < 200 { 0.1 } else { -0.05 }) + 0.02 * (k % 7) as f64
}

/// Builds and runs a C program that includes `header` (prefix `p`) and runs the documented
/// PID law on [`pid_error`] in float; returns the commands.
fn c_pid_outputs(dir: &Path, header: &str, p: &str) -> Vec<f64> {
    let prog = format!(
        r#"#include <stdio.h>
#include "{header}"
int main(void) {{
    float e1 = 0, i = 0, d = 0, v1 = 0, v2 = 0, u1 = 0, u2 = 0;
    int k;
    for (k = 0; k < {STEPS}; k++) {{
        float e = (k % 400 < 200 ? 0.1f : -0.05f) + 0.02f * (float)(k % 7);
        float p, v, u;
        i = i + {p}_PID_KI_D * (e + e1);
        d = {p}_PID_A_D * d + {p}_PID_B_D * (e - e1);
        p = {p}_PID_KP * e;
        v = p + i + d;
        u = {p}_PID_HAS_ROLLOFF
            ? {p}_PID_ROLLOFF_B[0] * v + {p}_PID_ROLLOFF_B[1] * v1 + {p}_PID_ROLLOFF_B[2] * v2
              - {p}_PID_ROLLOFF_A[1] * u1 - {p}_PID_ROLLOFF_A[2] * u2
            : v;
        e1 = e; v2 = v1; v1 = v; u2 = u1; u1 = u;
        printf("U %.9g\n", (double)u);
    }}
    return 0;
}}
"#
    );
    let exe = format!("pid_{}", p.to_lowercase());
    gcc(dir, &prog, Some(&exe));
    let out = Command::new(dir.join(&exe)).output().unwrap();
    assert!(out.status.success());
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| l.strip_prefix("U "))
        .map(|v| v.trim().parse().unwrap())
        .collect()
}

/// Compares the C commands with `DiscretePid::update` (f64, linear law) on the same errors.
/// The integrator accumulates float rounding over 2000 steps: 1e-4 of the peak command.
fn assert_pid_matches(u_c: &[f64], dp: &ferrosid::robust::pid::DiscretePid, what: &str) {
    let mut st = DiscretePidState::default();
    let u_h: Vec<f64> = (0..STEPS)
        .map(|k| dp.update(&mut st, pid_error(k), None))
        .collect();
    let upeak = u_h.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let uworst = u_h
        .iter()
        .zip(u_c)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f64, f64::max);
    println!(
        "{what}: C float PID vs host DiscretePid::update: worst {uworst:.3e} (peak {upeak:.3e})"
    );
    assert_eq!(u_c.len(), STEPS);
    assert!(
        uworst <= 1e-4 * upeak,
        "{what}: C PID deviates {uworst:e} > 1e-4 x {upeak:e}"
    );
}

#[test]
fn generated_c_compiles_and_simulates_like_the_host() {
    let p = pipeline();
    let dir = p.c_header.parent().unwrap().to_path_buf();
    gcc(
        &dir,
        "#include \"axis_1.h\"\nint main(void) { return 0; }\n",
        None,
    );
    // A C program: step response with the emitted float matrices, printed with 9 significant
    // digits.
    let prog = format!(
        r#"#include <stdio.h>
#include "axis_1.h"
int main(void) {{
    float x[AXIS_1_N_STATES] = {{0}}, xn[AXIS_1_N_STATES];
    int k, r, c;
    for (k = 0; k < {STEPS}; k++) {{
        float y = AXIS_1_D[0][0];
        for (c = 0; c < AXIS_1_N_STATES; c++) y += AXIS_1_C[0][c] * x[c];
        for (r = 0; r < AXIS_1_N_STATES; r++) {{
            xn[r] = AXIS_1_B[r][0];
            for (c = 0; c < AXIS_1_N_STATES; c++) xn[r] += AXIS_1_A[r][c] * x[c];
        }}
        for (r = 0; r < AXIS_1_N_STATES; r++) x[r] = xn[r];
        printf("Y %.9g\n", (double)y);
    }}
    return 0;
}}
"#
    );
    gcc(&dir, &prog, Some("prog"));
    let out = Command::new(dir.join("prog")).output().unwrap();
    assert!(out.status.success());
    let y_c: Vec<f64> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| l.strip_prefix("Y "))
        .map(|v| v.trim().parse().unwrap())
        .collect();
    // Host simulation of the f64 model (lti::simulate): step from rest.
    let y_h = p.model.simulate_siso(&vec![1.0; STEPS], None).unwrap();
    let peak = y_h.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let worst = y_h
        .iter()
        .zip(&y_c)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f64, f64::max);
    println!("C float step vs host f64 simulation: worst {worst:.3e} (peak {peak:.3e})");
    // Float coefficients (relative 6e-8) and float arithmetic over 2000 steps of a resonance
    // with |z| = 0.984: within 1e-4 of the peak.
    assert_eq!(y_c.len(), STEPS);
    assert!(
        worst <= 1e-4 * peak,
        "C step deviates {worst:e} > 1e-4 x {peak:e}"
    );

    // The tuned controller's law in C vs the host's.
    let u_c = c_pid_outputs(&dir, "axis_1.h", "AXIS_1");
    assert_pid_matches(
        &u_c,
        p.tuned.discrete.as_ref().expect("discrete PID"),
        "tuned PID",
    );
}

#[test]
fn generated_pid_with_derivative_and_rolloff_runs_like_the_host() {
    // The tuned controller of the bench is a PI with roll-off (W_m limits the bandwidth); this
    // exercises the derivative filter and the prewarped Tustin path too: a continuous PID file
    // through `ferrosid codegen --pid ... --prewarp-hz 10`.
    use clap::Parser as _;
    use ferrosid::robust::pid::{Pid, Rolloff};
    let p = pipeline();
    let dir = work_dir().join("generated-pid");
    std::fs::create_dir_all(&dir).unwrap();
    let pid = Pid {
        kp: 0.8,
        ki: 4.0,
        kd: 0.01,
        tau_f: 0.002,
        rolloff: Some(Rolloff {
            corner_hz: 60.0,
            zeta: 0.7,
        }),
    };
    let file = dir.join("pid.json");
    std::fs::write(&file, serde_json::to_string(&pid).unwrap()).unwrap();
    let cli = ferrosid::cli::Cli::try_parse_from([
        "ferrosid".as_ref(),
        "codegen".as_ref(),
        "--model".as_ref(),
        p.json[0].as_os_str(),
        "--pid".as_ref(),
        file.as_os_str(),
        "--prewarp-hz".as_ref(),
        "10".as_ref(),
        "--wm-level".as_ref(),
        "0.1".as_ref(),
        "--prefix".as_ref(),
        "pidcheck".as_ref(),
        "--out-dir".as_ref(),
        dir.as_os_str(),
    ])
    .unwrap();
    ferrosid::cli::run(&cli).unwrap();
    let u_c = c_pid_outputs(&dir, "pidcheck.h", "PIDCHECK");
    let dp = pid.discretize(TS, Some(10.0)).unwrap();
    assert!(dp.b_d != 0.0 && dp.rolloff.is_some());
    assert_pid_matches(&u_c, &dp, "PID with derivative and roll-off");
}

#[test]
fn bundled_pipeline_outputs_feed_codegen() {
    // `ferrosid run examples/pipeline.toml` writes model.json, pid.json, wm.json and
    // receipts.json; `ferrosid codegen` takes them as they are, and the header compiles.
    use clap::Parser as _;
    let out = work_dir().join("example-pipeline");
    // The test's own scratch directory: start empty, so outputs of an older ferrosid (written
    // before the output manifest existed, which `run` now refuses to replace) cannot linger.
    let _ = std::fs::remove_dir_all(&out);
    let toml = repo_root().join("examples").join("pipeline.toml");
    let cli = ferrosid::cli::Cli::try_parse_from([
        "ferrosid".as_ref(),
        "run".as_ref(),
        toml.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
    ])
    .unwrap();
    ferrosid::cli::run(&cli).unwrap_or_else(|e| panic!("ferrosid run: {e}"));
    let gen = out.join("generated");
    let f = |n: &str| out.join(n).into_os_string();
    let cli = ferrosid::cli::Cli::try_parse_from([
        "ferrosid".into(),
        "codegen".into(),
        "--model".into(),
        f("model.json"),
        "--pid".into(),
        f("pid.json"),
        "--wm".into(),
        f("wm.json"),
        "--receipts".into(),
        f("receipts.json"),
        "--prefix".into(),
        "two-mass".into(),
        "--out-dir".into(),
        gen.clone().into_os_string(),
    ])
    .unwrap();
    ferrosid::cli::run(&cli).unwrap_or_else(|e| panic!("ferrosid codegen: {e}"));
    let h = std::fs::read_to_string(gen.join("two_mass.h")).unwrap();
    assert!(h.contains("#define TWO_MASS_HAS_PID 1"));
    assert!(
        h.contains("receipt PASS sensitivity_peak"),
        "receipts summary in the provenance"
    );
    gcc(
        &gen,
        "#include \"two_mass.h\"\nint main(void) { return 0; }\n",
        None,
    );
}

#[test]
fn codegen_rerun_gives_byte_identical_files() {
    let p = pipeline();
    let again = work_dir().join("generated-rerun");
    run_codegen(p, &again).unwrap();
    for name in ["axis_1.h", "axis_1.rs"] {
        let a = std::fs::read(p.c_header.parent().unwrap().join(name)).unwrap();
        let b = std::fs::read(again.join(name)).unwrap();
        assert!(a == b, "{name} differs between two runs");
    }
}

#[test]
fn powerup_image_builds_with_the_generated_module() {
    let p = pipeline();
    let elf = powerup_elf();
    let size = image_size(elf).unwrap_or_else(|e| panic!("{e}"));
    println!(
        "powerup image: flash {} B (text {} + data {}), static RAM {} B (data {} + bss {})",
        size.flash(),
        size.text,
        size.data,
        size.ram(),
        size.data,
        size.bss
    );
    // The image carries the generated module: its inputs digest is what the target reports.
    let module = std::fs::read_to_string(&p.rust_module).unwrap();
    let sha = module
        .lines()
        .find_map(|l| l.strip_prefix("pub const INPUTS_SHA256: &str = \""))
        .map(|s| s.trim_end_matches("\";").to_string())
        .unwrap();
    let r = run(&scenario(&["plant=nominal"]));
    assert!(
        r.text.contains(&format!("POWERUP sha256={sha} ")),
        "the target does not report the generated module's digest {sha}"
    );
}

#[test]
fn powerup_code_has_no_panic_path() {
    // Branches to core's panic entry points whose innermost source frame outside the standard
    // library lies in the power-up application or the generated module: there must be none
    // (bounds checks, unwraps and overflow checks all absent or compiled away). Sites inside
    // dependencies (e.g. the semihosting command-line parser, inlined into main) are listed
    // but not ours to fix here.
    let sites = panic_sites(powerup_elf()).unwrap_or_else(|e| panic!("{e}"));
    let innermost = |s: &ferrosid_tests::PanicSite| {
        s.frames
            .iter()
            .find(|(_, loc)| !loc.starts_with("/rustc/"))
            .map(|(_, loc)| loc.clone())
            .unwrap_or_default()
    };
    for s in &sites {
        println!(
            "panic site {:#x} innermost non-core frame {}",
            s.addr,
            innermost(s)
        );
    }
    let ours: Vec<String> = sites
        .iter()
        .filter(|s| {
            let loc = innermost(s);
            loc.contains("firmware/app/src")
                || loc.contains("flashed_model.rs")
                || loc.contains("firmware/src/check")
        })
        .map(|s| s.to_string())
        .collect();
    assert!(
        ours.is_empty(),
        "panic paths in the power-up code:\n{}",
        ours.join("\n")
    );
}

#[test]
fn nominal_plant_passes_and_the_target_evaluates_g0_and_wm_like_the_host() {
    let p = pipeline();
    let r = run(&scenario(&["plant=nominal"]));
    assert_eq!(r.verdict(), Some("PASS"), "verdict");
    assert_eq!(r.exit_code, 0);
    let samples = (1 + 4) * WELCH_N;
    assert!(r.text.contains(&format!("samples={samples}")));
    assert_eq!(r.receipt().len(), CHECK_HZ.len());
    for row in r.receipt() {
        assert_eq!(row.verdict, "PASS", "{row:?}");
        // G0 on target (f32 complex elimination) vs host (f64 Hessenberg): 1e-4 relative
        // (f32 rounding of A amplified by the resonance's conditioning, |z − p| ~ 0.02).
        let g0 = p.model.freq_response_siso(row.hz).unwrap();
        assert!(
            (row.g0 - g0).norm() <= 1e-4 * g0.norm(),
            "target G0 {} vs host {g0} at {} Hz",
            row.g0,
            row.hz
        );
        // |W_m| on target (f32 Horner) vs host (f64): 1e-5 relative.
        let wm = p.weight.magnitude_hz(row.hz);
        assert!(
            (row.wm - wm).abs() <= 1e-5 * wm,
            "target |W_m| {} vs {wm}",
            row.wm
        );
        // The measured H1 vs the exact response of the plant simulated on target.
        let g = Axis::nominal().response_hz(row.hz, 0);
        let err = (row.g_meas - g).norm() / g.norm();
        assert!(
            err < 0.02,
            "H1 off the true plant by {err} at {} Hz",
            row.hz
        );
    }
}

/// A drifted plant fails, and the frequencies it fails at are the ones the host predicts from
/// the drifted plant's exact response: every check frequency with predicted ratio
/// |G − G0|/|G0|/|W_m| above 1.5 must FAIL, every one below 0.67 must PASS (bins in between
/// may go either way with the estimation noise).
fn drifted_fails_where_predicted(words: &[&str], plant: Axis, delay: u32) -> PowerupRun {
    let p = pipeline();
    let r = run(&scenario(words));
    assert_eq!(r.verdict(), Some("FAIL"));
    assert_eq!(r.exit_code, 1);
    assert!(
        !r.failed_hz.is_empty(),
        "the VERDICT line must name the failed frequencies"
    );
    for row in r.receipt() {
        let ratio = predicted_ratio(p, row.hz, plant.response_hz(row.hz, delay));
        println!(
            "{:>8.3} Hz: predicted ratio {ratio:.3}, target {}",
            row.hz, row.verdict
        );
        if ratio > 1.5 {
            assert_eq!(row.verdict, "FAIL", "{} Hz (ratio {ratio})", row.hz);
            assert!(r.failed_hz.iter().any(|f| (f - row.hz).abs() < 1e-3));
        }
        if ratio < 0.67 {
            assert_eq!(row.verdict, "PASS", "{} Hz (ratio {ratio})", row.hz);
        }
    }
    r
}

#[test]
fn inertia_drift_fails_naming_the_frequencies_and_is_reidentified() {
    let drifted = Axis::nominal().with_inertia_scale(1.3);
    let r = drifted_fails_where_predicted(&["plant=inertia", "jscale=1.3"], drifted, 0);
    // The host re-identifies the drifted plant from the target's spectra frame.
    let frame = r.frame.as_ref().expect("spectra frame");
    let re = reidentify(frame, &RationalFitOptions::new(2, 1, 1), 1..=1, None, 1e-6).unwrap();
    let ss = ferrosid::lti::StateSpace::try_from(&re.model).unwrap();
    // Agreement with the drifted plant's exact response over 1..200 Hz: 2 %.
    let worst = (1..=100)
        .map(|k| {
            let f = 2.0 * k as f64;
            let g = drifted.response_hz(f, 0);
            (ss.freq_response_siso(f).unwrap() - g).norm() / g.norm()
        })
        .fold(0.0f64, f64::max);
    // Natural frequency: 25 Hz / sqrt(1.3) = 21.93 Hz, from the fitted poles: 0.5 %.
    let fn_true = 25.0 / 1.3f64.sqrt();
    let z = Complex64::new(re.fit.poles[0][0], re.fit.poles[0][1]);
    let fn_fit = (z.ln() / TS).norm() / (2.0 * std::f64::consts::PI);
    println!(
        "re-identified on {} bins: worst response error {worst:.4}, natural frequency {fn_fit:.3} Hz (true {fn_true:.3})",
        re.points.h.len()
    );
    assert!(
        worst < 0.02,
        "re-identified model off the drifted plant by {worst}"
    );
    assert!((fn_fit / fn_true - 1.0).abs() < 5e-3);
}

#[test]
fn extra_delay_fails_naming_the_frequencies_and_the_delay_is_reidentified() {
    let r = drifted_fails_where_predicted(&["plant=delay", "delay=3"], Axis::nominal(), 3);
    let frame = r.frame.as_ref().expect("spectra frame");
    let re = reidentify(frame, &RationalFitOptions::new(2, 1, 1), 1..=8, None, 1e-6).unwrap();
    // One sample from the ZOH plus the three extra.
    assert_eq!(re.fit.options.nk, 4, "re-identified delay");
    let ss = ferrosid::lti::StateSpace::try_from(&re.model).unwrap();
    let worst = (1..=100)
        .map(|k| {
            let f = 2.0 * k as f64;
            let g = Axis::nominal().response_hz(f, 3);
            (ss.freq_response_siso(f).unwrap() - g).norm() / g.norm()
        })
        .fold(0.0f64, f64::max);
    println!("re-identified delayed plant: worst response error {worst:.4}");
    assert!(
        worst < 0.02,
        "re-identified model off the delayed plant by {worst}"
    );
}

#[test]
fn coulomb_friction_fails_naming_the_frequencies() {
    // Friction has no linear prediction. It dissipates: the measured gain must drop below the
    // model's at the lowest check frequency (where friction is a large share of the torque),
    // and the receipt must fail there.
    let p = pipeline();
    let r = run(&scenario(&["plant=friction", "coulomb=0.4"]));
    assert_eq!(r.verdict(), Some("FAIL"));
    assert_eq!(r.exit_code, 1);
    let low = &r.receipt()[0];
    let g0 = p.model.freq_response_siso(low.hz).unwrap();
    assert!(
        low.g_meas.norm() < g0.norm(),
        "friction raised the gain: {low:?}"
    );
    assert_eq!(low.verdict, "FAIL");
    assert!(r.failed_hz.iter().any(|f| (f - low.hz).abs() < 1e-3));
}

#[test]
fn low_coherence_is_inconclusive_and_a_bad_command_line_is_refused() {
    // Output noise 1000 times the bench's: fewer than the 5 (of 9) check frequencies the
    // generated settings require count as evidence, so the target cannot vouch either way:
    // verdict INCONCLUSIVE, exit status 2.
    let mut words = Axis::nominal().firmware_args();
    words.retain(|w| !w.starts_with("noise="));
    words.push("noise=1.0".into());
    let r = run(&words);
    assert_eq!(r.verdict(), Some("INCONCLUSIVE"));
    assert_eq!(r.exit_code, 2);
    // Bins below the gate are skipped; gated bins whose random error σ (Bendat & Piersol,
    // from coherence and averages) is too large to resolve |W_m| (3σ > |W_m|) do not count.
    let counted = r
        .receipt()
        .iter()
        .filter(|row| !matches!(row.verdict.as_str(), "SKIP" | "UNRESOLVED"))
        .count();
    assert!(counted < 5, "{counted} bins counted");
    for row in r.receipt() {
        let sigma = ((1.0 - row.coherence) / (2.0 * 4.0 * row.coherence)).sqrt();
        assert!(
            (row.sigma - sigma).abs() <= 1e-5 * sigma.max(1e-3),
            "{row:?}"
        );
        match row.verdict.as_str() {
            "SKIP" => assert!(row.coherence < 0.9),
            "UNRESOLVED" => assert!(row.coherence >= 0.9 && 3.0 * row.sigma > row.wm),
            _ => assert!(row.coherence >= 0.9 && 3.0 * row.sigma <= row.wm),
        }
    }
    assert!(
        r.receipt().iter().any(|row| row.verdict == "UNRESOLVED"),
        "the resolution rule is exercised"
    );
    // Unknown scenario: set-up error, exit status 3, named on the log.
    let r = run(&["plant=warp".to_string()]);
    assert_eq!(r.exit_code, 3);
    assert!(
        r.text.contains("ERROR bad command line: plant"),
        "{}",
        r.text
    );
    // A parameter out of range is named too.
    let r = run(&["J=-1".to_string()]);
    assert_eq!(r.exit_code, 3);
    assert!(
        r.text
            .contains("ERROR plant parameter out of range: inertia"),
        "{}",
        r.text
    );
}

#[test]
fn reidentify_command_writes_a_model_the_generator_accepts() {
    use clap::Parser as _;
    let dir = work_dir().join("reidentify");
    std::fs::create_dir_all(&dir).unwrap();
    let r = run(&scenario(&["plant=inertia", "jscale=1.3"]));
    let log = dir.join("target.log");
    std::fs::write(&log, &r.text).unwrap();
    let model = dir.join("drifted.json");
    let cli = ferrosid::cli::Cli::try_parse_from([
        "ferrosid".as_ref(),
        "reidentify".as_ref(),
        log.as_os_str(),
        "--out".as_ref(),
        model.as_os_str(),
    ])
    .unwrap();
    ferrosid::cli::run(&cli).unwrap();
    let cli = ferrosid::cli::Cli::try_parse_from([
        "ferrosid".as_ref(),
        "codegen".as_ref(),
        "--model".as_ref(),
        model.as_os_str(),
        "--wm-level".as_ref(),
        "0.2".as_ref(),
        "--out-dir".as_ref(),
        dir.join("gen").as_os_str(),
        "--prefix".as_ref(),
        "drifted".as_ref(),
    ])
    .unwrap();
    ferrosid::cli::run(&cli).unwrap();
    assert!(dir.join("gen").join("drifted.h").exists());
}

/// The friction scenario again with the compensation active (issue 12): the pipeline's
/// generated module plus a friction feedforward block for the plant's Coulomb friction
/// (0.4 N·m = 0.4/K input units, ramp over 1 rad/s, velocity from the difference of the
/// measured angle low-passed at 400 Hz), built into its own image; the multisine goes through
/// the compensation. The same image without `comp=on` still fails; with it the relative error
/// falls at every line, and at most half as many lines fail.
///
/// The velocity estimate's lag matters: with a 100 Hz filter (≈ 2 ms with the half-sample of
/// the difference) the feedforward lags the friction by ~19° at the 25 Hz resonance, its
/// quadrature part shifts the resonance, and bins from 13 to 25 Hz still failed (relative
/// errors 0.12–0.21 against |W_m| 0.09–0.14). At 400 Hz the error falls 1.5× (70 Hz) to 9.5×
/// (99.6 Hz), 2.4× at the lowest line (3.9 Hz: 0.0573 → 0.0235), where friction is the largest
/// share of the torque. These are the target's measurements (seeded noise, deterministic).
///
/// Whether every line then passes is decided by |W_m|, not by the compensation: W_m is fitted
/// to the envelope of three simulated unit logs, and its level at the band edge moves with the
/// logs' noise draws. Over 27 seed sets of `simulate_log` (bases 1, 2, 3, 11, 21, …, 241),
/// |W_m| at 3.9 Hz spans 0.0046–0.046 (the fit lands in one of two shapes), and with the
/// errors of this run the compensated scenario passes 9/9 lines with 14 of them, 6/9 at worst,
/// while the uncompensated one fails at least twice as many lines with every one. The
/// committed seeds (11, 12, 13) give |W_m| 0.0220 at 3.9 Hz: that line fails (0.0235), 8/9
/// pass; the xorshift64* draws used before the workspace's one RNG gave 0.0262 and 9/9. So the
/// test asserts what holds over the seeds (the error falls by at least a quarter at every line,
/// no line fails that passed without the compensation, at most half as many lines fail), not the
/// 9/9.
#[test]
fn coulomb_friction_compensation_cuts_the_error_and_the_failing_lines() {
    use clap::Parser as _;
    use ferrosid_codegen as cg;
    use ferrosid_tests::e2e::{build_app_image, codegen_args, write_if_changed};
    let p = pipeline();
    let dir = work_dir().join("generated-comp");
    let cli = ferrosid::cli::Cli::try_parse_from(codegen_args(p, &dir)).unwrap();
    let ferrosid::cli::Command::Codegen(args) = cli.command else {
        panic!("codegen arguments")
    };
    let mut input = ferrosid::cli::codegen::build_input(&args).unwrap();
    let gain = Axis::nominal().gain;
    input.compensation = Some(cg::Compensation {
        enabled: true,
        provenance: cg::CompensationProvenance {
            effect: "coulomb_friction".into(),
            place: "motor".into(),
            verdict: "explained".into(),
            source: "tests/tests/e2e_powerup.rs (the scenario's friction)".into(),
            nrmse_before: None,
            nrmse_after: None,
        },
        friction_feedforward: Some(cg::FrictionFeedforward {
            coulomb: 0.4 / gain,
            viscous: 0.0,
            smoothing_velocity: 1.0,
            velocity: cg::VelocitySource::OutputDifference { filter_hz: 400.0 },
            lag_aware: None,
        }),
        dead_zone_inverse: None,
        backlash_inverse: None,
        anti_windup: None,
    });
    let g = cg::generate(&input).unwrap();
    let module = dir.join(&g.rs_file_name);
    write_if_changed(&module, &g.rust_module).unwrap();
    let elf = build_app_image(
        &module,
        "powerup",
        &repo_root().join("target").join("qemu-powerup-comp"),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let friction = scenario(&["plant=friction", "coulomb=0.4"]);
    let run_with = |extra: &[&str]| {
        let mut a = friction.clone();
        a.extend(extra.iter().map(|s| s.to_string()));
        let r = run_powerup(&elf, &a).unwrap_or_else(|e| panic!("QEMU: {e}"));
        for l in r.lines.iter().filter(|l| !l.text.starts_with("FRAME ")) {
            println!("target: {l}");
        }
        r
    };
    let off = run_with(&[]);
    assert_eq!(off.verdict(), Some("FAIL"), "without the compensation");
    let on = run_with(&["comp=on"]);
    assert!(on.text.contains("COMPENSATION on"));
    let (mut failed_off, mut failed_on) = (0usize, 0usize);
    for (a, b) in off.receipt().iter().zip(on.receipt()) {
        println!(
            "{:>8.3} Hz: relative error {:.4} -> {:.4} (|W_m| {:.4}), {} -> {}",
            a.hz, a.rel_error, b.rel_error, b.wm, a.verdict, b.verdict
        );
        assert!((a.hz - b.hz).abs() < 1e-9);
        assert!(
            b.rel_error <= 0.75 * a.rel_error,
            "{} Hz: the compensation does not cut the error by a quarter ({} -> {})",
            a.hz,
            a.rel_error,
            b.rel_error
        );
        if a.verdict == "FAIL" {
            failed_off += 1;
        }
        if b.verdict == "FAIL" {
            failed_on += 1;
            assert_eq!(
                a.verdict, "FAIL",
                "{} Hz fails only with the compensation",
                a.hz
            );
        }
    }
    println!("failing lines: {failed_off} without the compensation, {failed_on} with it");
    assert!(failed_off > 0);
    assert!(
        2 * failed_on <= failed_off,
        "{failed_on} lines fail with the compensation, {failed_off} without"
    );
    let expected_exit = if failed_on == 0 { 0 } else { 1 };
    assert_eq!(
        on.verdict(),
        Some(if failed_on == 0 { "PASS" } else { "FAIL" }),
        "with the compensation"
    );
    assert_eq!(on.exit_code, expected_exit);
}
