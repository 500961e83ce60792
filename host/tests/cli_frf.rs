//! `ferrosid frf` end to end: JSON fields and values against closed-form FIR responses, the
//! period-synchronous path (exact at the excited lines for periodic steady state), coherence
//! marks in the table, the exit code when nothing passes the gate, and byte-identical reruns.
mod cli_support;
use cli_support::{ferrosid, s, scratch, write_csv, Rng};
use num_complex::Complex64;
use std::f64::consts::PI;

/// FIR taps of the reference plant y[k] = 0.8 u[k] − 0.5 u[k−1] + 0.25 u[k−2].
const TAPS: [f64; 3] = [0.8, -0.5, 0.25];
const FS: f64 = 1000.0;

fn fir(u: &[f64], taps: &[f64]) -> Vec<f64> {
    (0..u.len())
        .map(|k| {
            taps.iter()
                .enumerate()
                .filter(|(d, _)| *d <= k)
                .map(|(d, b)| b * u[k - d])
                .sum()
        })
        .collect()
}

/// Closed-form response Σ b_d e^{−j 2π f d / fs}.
fn fir_response(taps: &[f64], f_hz: f64) -> Complex64 {
    taps.iter()
        .enumerate()
        .map(|(d, &b)| Complex64::from_polar(b, -2.0 * PI * f_hz * d as f64 / FS))
        .sum()
}

fn json(stdout: &str) -> serde_json::Value {
    serde_json::from_str(stdout).expect("--json output parses")
}

fn col(v: &serde_json::Value, key: &str) -> Vec<f64> {
    v[key]
        .as_array()
        .unwrap_or_else(|| panic!("field {key}"))
        .iter()
        .map(|x| x.as_f64().unwrap_or(f64::NAN))
        .collect()
}

#[test]
fn welch_json_matches_the_closed_form_fir_response() {
    let d = scratch("welch_fir");
    let mut rng = Rng::new(7);
    let u = rng.noise(20_000, 1.0);
    let y = fir(&u, &TAPS);
    let p = d.join("fir.csv");
    write_csv(&p, 1.0 / FS, &u, &y);
    let r = ferrosid(&["frf", s(&p), "--nperseg", "256", "--json"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let v = json(&r.stdout);
    assert_eq!(v["command"], "frf");
    assert_eq!(v["method"]["kind"], "welch");
    assert_eq!(v["method"]["nperseg"], 256);
    assert_eq!(v["method"]["noverlap"], 128);
    assert_eq!(v["logs"][0]["samples"], 20_000);
    assert_eq!(v["gate"], 0.85);
    let e = &v["estimates"][0];
    assert_eq!(e["input"], "u");
    assert_eq!(e["output"], "y");
    // (20000 − 128) / 128 = 155 half-overlapped segments.
    assert_eq!(e["n_averages"], 155);
    let f = col(e, "freq_hz");
    let (re, im) = (col(e, "re"), col(e, "im"));
    let (mag, ph, coh) = (col(e, "mag_db"), col(e, "phase_deg"), col(e, "coherence"));
    assert_eq!(f.len(), 129);
    let mut worst = 0.0_f64;
    for k in 1..f.len() {
        assert!((f[k] - k as f64 * FS / 256.0).abs() < 1e-9);
        let g = fir_response(&TAPS, f[k]);
        let h = Complex64::new(re[k], im[k]);
        worst = worst.max((h - g).norm() / g.norm());
        // The derived columns agree with re/im.
        assert!((mag[k] - 20.0 * h.norm().log10()).abs() < 1e-9);
        assert!((ph[k] - h.im.atan2(h.re).to_degrees()).abs() < 1e-9);
        // Noise-free linear data: coherence close to 1 and every bin gated in.
        assert!(coh[k] > 0.99, "coherence {} at {} Hz", coh[k], f[k]);
        assert_eq!(e["gated"][k], true);
    }
    // Leakage of the 2-sample memory across Hann-windowed segments of 256 is the only error:
    // well under 1 %.
    assert!(worst < 0.01, "worst relative error {worst}");
}

#[test]
fn period_synchronous_json_is_exact_for_periodic_steady_state() {
    let d = scratch("periodic_fir");
    let period = 128;
    // Multisine on lines 1..=40 with random phases, 6 periods.
    let one: Vec<f64> = (0..period)
        .map(|n| {
            (1..=40)
                .map(|l| {
                    let phi = 2.0 * PI * ((l * 7919) % 97) as f64 / 97.0;
                    (2.0 * PI * l as f64 * n as f64 / period as f64 + phi).cos()
                })
                .sum::<f64>()
        })
        .collect();
    let u: Vec<f64> = one.iter().copied().cycle().take(6 * period).collect();
    let y = fir(&u, &TAPS);
    let p = d.join("ms.csv");
    write_csv(&p, 1.0 / FS, &u, &y);
    let r = ferrosid(&[
        "frf",
        s(&p),
        "--period",
        "128",
        "--skip-periods",
        "1",
        "--json",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let v = json(&r.stdout);
    assert_eq!(v["method"]["kind"], "periodic");
    assert_eq!(v["method"]["period"], 128);
    let e = &v["estimates"][0];
    assert_eq!(e["n_averages"], 5);
    let f = col(e, "freq_hz");
    assert_eq!(f.len(), 40, "the 40 excited lines are detected");
    let (re, im) = (col(e, "re"), col(e, "im"));
    let sd = col(e, "std_h");
    for k in 0..f.len() {
        assert!((f[k] - (k + 1) as f64 * FS / 128.0).abs() < 1e-9);
        let g = fir_response(&TAPS, f[k]);
        let h = Complex64::new(re[k], im[k]);
        assert!(
            (h - g).norm() <= 1e-9 * g.norm(),
            "line {} Hz: {h} vs {g}",
            f[k]
        );
        assert!(sd[k] < 1e-9, "noise-free periods have no spread");
    }
}

#[test]
fn table_marks_exactly_the_bins_below_the_gate() {
    let d = scratch("marks");
    let mut rng = Rng::new(3);
    let u = rng.noise(8192, 1.0);
    // Zeros at DC and Nyquist: coherence collapses there once noise is added.
    let mut y = fir(&u, &[1.0, 0.0, -1.0]);
    for v in y.iter_mut() {
        *v += 0.3 * rng.normal();
    }
    let p = d.join("notch.csv");
    write_csv(&p, 1.0 / FS, &u, &y);
    let text = ferrosid(&["frf", s(&p), "--nperseg", "128"]);
    let js = ferrosid(&["frf", s(&p), "--nperseg", "128", "--json"]);
    assert_eq!(text.code, 0, "{}", text.stderr);
    let v = json(&js.stdout);
    let gated: Vec<bool> = v["estimates"][0]["gated"]
        .as_array()
        .expect("gated")
        .iter()
        .map(|g| g.as_bool().expect("bool"))
        .collect();
    let n_low = gated.iter().filter(|g| !**g).count();
    assert!(
        n_low > 0 && n_low < gated.len(),
        "{n_low} of {}",
        gated.len()
    );
    let rows: Vec<&str> = text
        .stdout
        .lines()
        .skip_while(|l| !l.contains("freq_Hz"))
        .skip(1)
        .take(gated.len())
        .collect();
    assert_eq!(rows.len(), gated.len());
    for (row, g) in rows.iter().zip(&gated) {
        assert_eq!(row.trim_end().ends_with("low"), !g, "row `{row}`");
    }
    assert!(text.stdout.contains(&format!(
        "{} of 65 bins pass the coherence gate",
        65 - n_low
    )));
    assert!(text.stdout.contains("below the gate: 0.000-"));
}

#[test]
fn no_bin_above_the_gate_exits_with_1() {
    let d = scratch("nogate");
    let mut rng = Rng::new(5);
    let u = rng.noise(4096, 1.0);
    let y = rng.noise(4096, 1.0); // unrelated to u
    let p = d.join("noise.csv");
    write_csv(&p, 1.0 / FS, &u, &y);
    let r = ferrosid(&["frf", s(&p), "--nperseg", "64"]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert!(r.stderr.contains("no bin"), "{}", r.stderr);
    assert!(r.stdout.contains("0 of 33 bins pass"), "{}", r.stdout);
}

#[test]
fn several_logs_are_pooled_and_mimo_pairs_estimated() {
    let d = scratch("pool");
    let mut rng = Rng::new(9);
    let mut paths = Vec::new();
    for name in ["a.csv", "b.csv"] {
        let u1 = rng.noise(4096, 1.0);
        let u2 = rng.noise(4096, 1.0);
        let y1: Vec<f64> = fir(&u1, &TAPS)
            .iter()
            .zip(fir(&u2, &[0.3]))
            .map(|(a, b)| a + b)
            .collect();
        let mut text = String::from("t,u1,u2,y1\n");
        for k in 0..4096 {
            text.push_str(&format!(
                "{:e},{:e},{:e},{:e}\n",
                k as f64 / FS,
                u1[k],
                u2[k],
                y1[k]
            ));
        }
        let p = d.join(name);
        std::fs::write(&p, text).expect("write");
        paths.push(p);
    }
    let r = ferrosid(&[
        "frf",
        s(&paths[0]),
        s(&paths[1]),
        "--input",
        "u1",
        "--input",
        "u2",
        "--output",
        "y1",
        "--nperseg",
        "256",
        "--json",
    ]);
    assert_eq!(
        r.code, 1,
        "u2 -> y1 has coherence ~0.08: no bin passes; {}",
        r.stderr
    );
    let v = json(&r.stdout);
    let est = v["estimates"].as_array().expect("estimates");
    assert_eq!(est.len(), 2);
    assert_eq!(est[0]["input"], "u1");
    assert_eq!(est[1]["input"], "u2");
    assert_eq!(est[0]["logs"].as_array().map(Vec::len), Some(2));
    // Pooled: 2 × (4096 − 128)/128 = 62 segments.
    assert_eq!(est[0]["n_averages"], 62);
    // SISO H1 per pair with independent white inputs is unbiased; the other input acts as
    // noise. Expected RMS error ≈ sqrt(S_other / S_uu / n_avg): pair 1 sqrt(0.09/62) ≈ 0.04,
    // pair 2 sqrt(0.95/62) ≈ 0.12. Bounds at about twice that; swapped pairs would be off by ~1.
    for (e, taps, bound) in [(&est[0], &TAPS[..], 0.08), (&est[1], &[0.3][..], 0.25)] {
        let f = col(e, "freq_hz");
        let (re, im) = (col(e, "re"), col(e, "im"));
        let mut err = 0.0;
        for k in 1..f.len() {
            let g = fir_response(taps, f[k]);
            err += (Complex64::new(re[k], im[k]) - g).norm();
        }
        err /= (f.len() - 1) as f64;
        assert!(err < bound, "mean absolute error {err} (bound {bound})");
    }
}

#[test]
fn reruns_are_byte_identical() {
    let d = scratch("rerun");
    let mut rng = Rng::new(21);
    let u = rng.noise(3000, 1.0);
    let y: Vec<f64> = fir(&u, &TAPS)
        .iter()
        .map(|v| v + 0.1 * rng.normal())
        .collect();
    let p = d.join("r.csv");
    write_csv(&p, 1.0 / FS, &u, &y);
    for extra in [
        vec![],
        vec!["--json"],
        vec!["--window", "boxcar", "--nperseg", "300"],
    ] {
        let mut args = vec!["frf", s(&p)];
        args.extend(extra.iter().copied());
        let a = ferrosid(&args);
        let b = ferrosid(&args);
        assert_eq!(a.stdout_bytes, b.stdout_bytes, "{args:?}");
        assert!(!a.stdout_bytes.is_empty());
        // stderr is a pipe here: no progress bar or spinner output may appear.
        assert!(a.stderr.is_empty(), "stderr not empty: {:?}", a.stderr);
    }
}

#[test]
fn help_has_examples_and_exit_codes() {
    for cmd in [
        "frf",
        "identify",
        "codegen",
        "reidentify",
        "run",
        "fleet",
        "gap",
    ] {
        let r = ferrosid(&[cmd, "--help"]);
        assert_eq!(r.code, 0);
        assert!(r.stdout.contains("Examples:"), "{cmd}: {}", r.stdout);
        assert!(
            r.stdout.contains("Exit codes") || r.stdout.contains("Exit status"),
            "{cmd}"
        );
        assert!(r.stdout.contains(&format!("ferrosid {cmd} ")), "{cmd}");
    }
    let r = ferrosid(&["--help"]);
    assert_eq!(r.code, 0);
    assert!(r.stdout.contains("frf") && r.stdout.contains("identify"));
}
