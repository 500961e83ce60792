//! The design card's crates on the target (issue 16): the `cratecmp` image
//! (`tests/qemu/src/bin/cratecmp.rs`) measures nalgebra, micromath and heapless against what
//! they replace, under `qemu-system-arm -icount shift=0`, and this test prints its figures (the
//! docs/firmware.md's table "Design-card crates on the target") and checks the claims the firmware's
//! choices rest on. Instruction counts under `-icount` are deterministic, so the two count
//! comparisons below are count assertions, not timings.
//!
//! Run: `cargo test -p ferrosid-tests --test design_card_crates -- --nocapture`.
//! Needs qemu-system-arm, llvm-nm and the thumbv7em-none-eabihf target (scripts/setup.sh).

// Matrix loops index several arrays at once: indices read clearer than iterator chains.
#![allow(clippy::needless_range_loop)]

use std::process::Command;
use std::sync::OnceLock;
use std::time::Duration;

use ferrosid_tests::{build_run_decode, image_path, panic_sites, LogLine, RunOptions};

/// The image run once under `-icount shift=0`: exit code and decoded lines.
fn cmp_run() -> &'static (i32, Vec<LogLine>) {
    static RUN: OnceLock<(i32, Vec<LogLine>)> = OnceLock::new();
    RUN.get_or_init(|| {
        let opts = RunOptions {
            icount: true,
            timeout: Duration::from_secs(300),
            ..RunOptions::default()
        };
        match build_run_decode("cratecmp", &opts) {
            Ok((run, lines)) => {
                for l in &lines {
                    println!("cratecmp: {l}");
                }
                assert_eq!(run.exit_code, 0, "cratecmp exit code ({})", run.stderr);
                (run.exit_code, lines)
            }
            Err(e) => panic!("QEMU harness: {e}"),
        }
    })
}

/// `(instructions per call, max error)` of the line `CMP job=<job> variant=<variant> ...`.
fn figure(job: &str, variant: &str) -> (f64, f64) {
    let (_, lines) = cmp_run();
    let field = |t: &str, k: &str| -> Option<f64> {
        t.split_whitespace()
            .find_map(|w| w.strip_prefix(k).and_then(|r| r.strip_prefix('=')))
            .and_then(|v| v.parse().ok())
    };
    lines
        .iter()
        .find(|l| {
            l.text.starts_with("CMP ")
                && l.text.contains(&format!(" job={job} "))
                && l.text.contains(&format!(" variant={variant} "))
        })
        .and_then(|l| Some((field(&l.text, "instr")?, field(&l.text, "err")?)))
        .unwrap_or_else(|| panic!("no CMP line for {job}/{variant}"))
}

const MODELS: [(&str, usize); 3] = [
    ("model_axis2", 2),
    ("model_twomass4", 4),
    ("model_threemass6", 6),
];

/// Model evaluation at the 16 check bins: the firmware's hand-written elimination against
/// nalgebra's LU and QR. All within tolerance of numpy's complex128 response (1e-4 relative
/// for the 2- and 4-state models; 5e-3 for the 6-state one, whose lightly damped
/// non-collocated realisation loses about three digits of f32 anywhere; 1e-2 for the QR there).
/// nalgebra's LU takes fewer instructions at 2 and 4 states (the reason it was tried).
#[test]
fn model_evaluation_hand_written_against_nalgebra() {
    println!(
        "| model | states | instr/eval hand | nalgebra LU | nalgebra QR | max rel. error hand | LU | QR |"
    );
    for (job, ns) in MODELS {
        let (ih, eh) = figure(job, "hand");
        let (il, el) = figure(job, "nalgebra");
        let (iq, eq) = figure(job, "nalgebra_qr");
        println!("| {job} | {ns} | {ih:.0} | {il:.0} | {iq:.0} | {eh:.2e} | {el:.2e} | {eq:.2e} |");
        let tol = if ns <= 4 { 1e-4 } else { 5e-3 };
        assert!(
            eh < tol && el < tol && eq < 2.0 * tol,
            "{job}: errors {eh:e} / {el:e} / {eq:e}"
        );
        assert!(
            ih > 0.0 && il > 0.0 && iq > 0.0,
            "{job}: counts {ih} / {il} / {iq}"
        );
        if ns <= 4 {
            assert!(il < ih, "{job}: nalgebra LU {il} instr, hand-written {ih}");
        }
    }
}

/// Why the firmware keeps its hand-written elimination: nalgebra's LU leaves branches to panic
/// entry points in the evaluation (its row-permutation swaps index with run-time pivots), the
/// hand-written code and nalgebra's QR none. Counted on the `cratecmp` image as the
/// `*_has_no_panic_path` tests count them (branches, attributed by the debug information).
#[test]
fn model_evaluation_panic_paths() {
    cmp_run();
    let sites = panic_sites(&image_path("cratecmp")).unwrap_or_else(|e| panic!("{e}"));
    let count = |f: &str| {
        sites
            .iter()
            .filter(|s| s.frames.iter().any(|(func, _)| func.contains(f)))
            .count()
    };
    let (hand, lu, qr) = (
        count("check::model::model_response"),
        count("eval_alt::model_response_nalgebra"),
        count("eval_alt::model_response_qr"),
    );
    println!("panic branches in the model evaluation (2, 4, 6 states): hand-written {hand}, nalgebra LU {lu}, nalgebra QR {qr}");
    assert_eq!(hand, 0, "the firmware's evaluation has panic paths");
    assert!(
        lu > 0,
        "nalgebra's LU has no panic path any more: reconsider it"
    );
}

/// The unit-circle point of a check bin: the firmware's table path is as accurate as the f64
/// series it replaced (G0's error the same within a factor 2) and costs about 1 % of it;
/// micromath's sin/cos (2e-3 rad) would make G0 wrong by more than 1 % — rejected.
#[test]
fn unit_circle_table_against_series_and_micromath() {
    let (it, et) = figure("unit_circle", "table");
    let (is, es) = figure("unit_circle", "f64series");
    let (im, em) = figure("unit_circle", "micromath");
    let (il, el) = figure("unit_circle", "libm");
    println!(
        "z = e^(j2πk/N): table {it:.0} instr {et:.1e}; f64 series {is:.0} {es:.1e}; \
         micromath {im:.0} {em:.1e}; libm {il:.0} {el:.1e}"
    );
    assert!(et < 2.5e-7 && es < 1e-7, "table {et:e}, series {es:e}");
    assert!(it < is / 10.0, "table {it} instr, series {is}");
    assert!(em > 1e-4, "micromath's z error {em:e}");
    for (job, _) in MODELS {
        let (_, gt) = figure(job, "z_table");
        let (_, gs) = figure(job, "z_f64series");
        let (_, gm) = figure(job, "z_micromath");
        println!(
            "{job}: G0 error with z from table {gt:.2e}, f64 series {gs:.2e}, micromath {gm:.2e}"
        );
        assert!(gt <= 2.0 * gs + 1e-7, "{job}: table {gt:e}, series {gs:e}");
        assert!(gm > 1e-2, "{job}: micromath {gm:e}");
    }
}

/// micromath's scalar functions against libm and the firmware's table sine: printed, and the
/// accuracy facts the firmware's choices rest on (sqrt 5 % off, sin 1e-3 off).
#[test]
fn micromath_scalar_functions() {
    for (job, kind) in [
        ("sqrt", "rel"),
        ("exp", "rel"),
        ("atan2", "abs"),
        ("sin_phase", "abs"),
    ] {
        let other = if job == "sin_phase" { "table" } else { "libm" };
        let (io, eo) = figure(job, other);
        let (im, em) = figure(job, "micromath");
        println!("{job}: {other} {io:.1} instr, {kind} error {eo:.1e}; micromath {im:.1} instr, {em:.1e}");
        assert!(eo < 1e-6, "{job}/{other} error {eo:e}");
        assert!(em > 100.0 * eo, "{job}: micromath {em:e} against {eo:e}");
    }
    assert!(figure("sqrt", "micromath").1 > 0.01);
}

/// The failing-frequency list: heapless::Vec gives the same list as the array and count.
#[test]
fn failed_list_heapless_equals_array() {
    let (ia, _) = figure("failed_list", "array");
    let (ih, same) = figure("failed_list", "heapless");
    println!("failed_hz list of 16 results: array {ia:.0} instr, heapless::Vec {ih:.0}");
    assert_eq!(same, 0.0, "the two lists differ");
}

/// Code size of the model evaluation for the three models together (2, 4 and 6 states): the
/// sizes of the out-of-line wrappers `eval_hand` / `eval_nalgebra` / `eval_qr` and of the
/// monomorphisations they call when those are not inlined, from `llvm-nm --print-size`.
#[test]
fn model_evaluation_code_size() {
    cmp_run();
    let elf = image_path("cratecmp");
    let out = Command::new("llvm-nm")
        .args(["--print-size", "-C"])
        .arg(&elf)
        .output()
        .expect("llvm-nm (scripts/setup.sh installs it)");
    assert!(out.status.success(), "llvm-nm failed");
    let text = String::from_utf8_lossy(&out.stdout);
    let total = |pats: &[&str]| -> u64 {
        text.lines()
            .filter(|l| pats.iter().any(|p| l.contains(p)))
            .filter_map(|l| u64::from_str_radix(l.split_whitespace().nth(1)?, 16).ok())
            .sum()
    };
    let hand = total(&["cratecmp::eval_hand::", "check::model::model_response::"]);
    let lu = total(&[
        "cratecmp::eval_nalgebra::",
        "eval_alt::model_response_nalgebra::",
    ]);
    let qr = total(&["cratecmp::eval_qr::", "eval_alt::model_response_qr::"]);
    println!("model evaluation code, 2 + 4 + 6 states: hand-written {hand} B, nalgebra LU {lu} B, nalgebra QR {qr} B (+ shared nalgebra helpers not inlined)");
    assert!(hand > 0 && lu > 0 && qr > 0, "{hand} {lu} {qr}");
}

/// nalgebra's LU and QR evaluations (the image's alternatives), compiled for the host.
#[allow(dead_code)]
#[path = "../qemu/src/eval_alt.rs"]
mod eval_alt;

/// The workspace's seeded generator (uniform in [0, 1), Box–Muller normals).
use ferrosid_sim::rng::Rng;

/// `x = M⁻¹ r` in complex f64 (Gaussian elimination, partial pivoting): the reference.
fn solve_f64(
    mut m: Vec<Vec<num_complex::Complex64>>,
    mut r: Vec<num_complex::Complex64>,
) -> Vec<num_complex::Complex64> {
    let n = r.len();
    for k in 0..n {
        let p = (k..n)
            .max_by(|&i, &j| m[i][k].norm().total_cmp(&m[j][k].norm()))
            .unwrap();
        m.swap(k, p);
        r.swap(k, p);
        for i in k + 1..n {
            let f = m[i][k] / m[k][k];
            for j in k..n {
                let v = m[k][j];
                m[i][j] -= f * v;
            }
            let v = r[k];
            r[i] -= f * v;
        }
    }
    for k in (0..n).rev() {
        let s = (k + 1..n).fold(r[k], |s, j| s - m[k][j] * r[j]);
        r[k] = s / m[k][k];
    }
    r
}

/// Errors of both f32 evaluations on `trials` random models of `N` states (lightly damped
/// modal pairs, radius 1 − 10^-(1..3), behind a random dense similarity), each at a random
/// check bin of a 512-point period, against the f64 reference of the same f32 matrices:
/// (ratios nalgebra/hand, hand errors, nalgebra errors).
fn error_study<const N: usize>(rng: &mut Rng, trials: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>)
where
    nalgebra::Const<N>: nalgebra::DimMin<nalgebra::Const<N>, Output = nalgebra::Const<N>>,
{
    use ferrosid_firmware::check::{model_response, C32};
    use num_complex::Complex64;
    let (mut ratio, mut eh, mut en) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..trials {
        let mut modal = [[0.0f64; N]; N];
        let mut k = 0;
        while k + 1 < N {
            let r = 1.0 - 10f64.powf(-1.0 - 2.0 * rng.uniform());
            let th = 0.02 + 1.5 * rng.uniform();
            modal[k][k] = r * th.cos();
            modal[k][k + 1] = -r * th.sin();
            modal[k + 1][k] = r * th.sin();
            modal[k + 1][k + 1] = r * th.cos();
            k += 2;
        }
        if k < N {
            modal[k][k] = 0.9 * rng.uniform();
        }
        // A = T·modal·S, S = T⁻¹ (columns from the reference solver).
        let t: Vec<Vec<f64>> = (0..N)
            .map(|i| {
                (0..N)
                    .map(|j| f64::from(u8::from(i == j)) + 0.5 * rng.normal())
                    .collect()
            })
            .collect();
        let tc: Vec<Vec<Complex64>> = t
            .iter()
            .map(|row| row.iter().map(|&v| Complex64::new(v, 0.0)).collect())
            .collect();
        let mut s = [[0.0f64; N]; N];
        for j in 0..N {
            let e: Vec<Complex64> = (0..N)
                .map(|i| Complex64::new(f64::from(u8::from(i == j)), 0.0))
                .collect();
            for (i, v) in solve_f64(tc.clone(), e).iter().enumerate() {
                s[i][j] = v.re;
            }
        }
        let mut a = [[0.0f32; N]; N];
        for i in 0..N {
            for j in 0..N {
                let mut v = 0.0;
                for p in 0..N {
                    for q in 0..N {
                        v += t[i][p] * modal[p][q] * s[q][j];
                    }
                }
                a[i][j] = v as f32;
            }
        }
        let b: [[f32; 1]; N] = std::array::from_fn(|_| [rng.normal() as f32]);
        let c: [[f32; N]; 1] = [std::array::from_fn(|_| rng.normal() as f32)];
        let d = [[0.0f32]];
        let z = C32::unit_circle((rng.uniform() * 255.0) as u32 + 1, 512);
        let zc = Complex64::new(f64::from(z.re), f64::from(z.im));
        let m: Vec<Vec<Complex64>> = (0..N)
            .map(|i| {
                (0..N)
                    .map(
                        |j| if i == j { zc } else { Complex64::new(0.0, 0.0) } - f64::from(a[i][j]),
                    )
                    .collect()
            })
            .collect();
        let x = solve_f64(
            m,
            (0..N)
                .map(|i| Complex64::new(f64::from(b[i][0]), 0.0))
                .collect(),
        );
        let g: Complex64 = x
            .iter()
            .zip(c[0].iter())
            .map(|(xi, &ci)| xi * f64::from(ci))
            .sum();
        let err = |v: Option<C32>| {
            v.map_or(f64::INFINITY, |v| {
                (Complex64::new(f64::from(v.re), f64::from(v.im)) - g).norm() / g.norm()
            })
        };
        let h = err(model_response(&a, &b, &c, &d, z, 0, 0));
        let n = err(eval_alt::model_response_nalgebra(&a, &b, &c, &d, z, 0, 0));
        // A random model can put a pole within f32 rounding of z: either method may then call
        // it singular (None). Such trials are left out; the count of usable ones is checked.
        if h > 0.0 && n > 0.0 && h.is_finite() && n.is_finite() {
            ratio.push(n / h);
            eh.push(h);
            en.push(n);
        }
    }
    (ratio, eh, en)
}

/// The three models above are too few to compare the two solvers' rounding: on 1,000 random
/// models per order (2, 3, 4, 6, 8 states) nalgebra's LU errors against an f64 reference are
/// the firmware's hand-written elimination's (median ratio within 0.8–1.25, 95th percentiles within 1.5×).
/// Host f32 arithmetic is the target's (IEEE single, no fused multiply-add in either).
#[test]
fn model_evaluation_errors_agree_on_random_models() {
    fn quantile(v: &mut [f64], q: f64) -> f64 {
        v.sort_by(f64::total_cmp);
        v[((v.len() - 1) as f64 * q) as usize]
    }
    let mut rng = Rng::new(0x9E37_79B9_7F4A_7C15);
    println!("| states | median error hand | nalgebra | 95th pct hand | nalgebra | median ratio |");
    let check = |ns: usize, (mut r, mut h, mut n): (Vec<f64>, Vec<f64>, Vec<f64>)| {
        let (mr, mh, mn, ph, pn) = (
            quantile(&mut r, 0.5),
            quantile(&mut h, 0.5),
            quantile(&mut n, 0.5),
            quantile(&mut h, 0.95),
            quantile(&mut n, 0.95),
        );
        println!("| {ns} | {mh:.2e} | {mn:.2e} | {ph:.2e} | {pn:.2e} | {mr:.3} |");
        assert!(r.len() > 900, "{ns} states: {} usable trials", r.len());
        assert!((0.8..1.25).contains(&mr), "{ns} states: median ratio {mr}");
        assert!(
            pn < 1.5 * ph && ph < 1.5 * pn,
            "{ns} states: p95 {ph:e} / {pn:e}"
        );
    };
    check(2, error_study::<2>(&mut rng, 1000));
    check(3, error_study::<3>(&mut rng, 1000));
    check(4, error_study::<4>(&mut rng, 1000));
    check(6, error_study::<6>(&mut rng, 1000));
    check(8, error_study::<8>(&mut rng, 1000));
}
