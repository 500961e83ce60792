//! Smoke tests on the real measured logs in ../shared/data (skipped with a notice when absent):
//! motor bench (.mat, periodic multisine: period-synchronous FRF must show the two-mass
//! anti-resonance / resonance pair) and DaISy (.dat: Welch spectra equal scipy's on the same
//! file, reference tests/fixtures/spectral_daisy_scipy.json from tests/ref/scipy_daisy.py).
use crate::shared_data::shared_data;

use ferrosid::io::{read_columns, read_log, LogSpec, TextOptions};
use ferrosid::spectral::{Detrend, PeriodicAveraging, Welch, Window, DEFAULT_COHERENCE_THRESHOLD};
use num_complex::Complex64;
use serde::Deserialize;

use crate::scipy_spectra::WithSpectra;

/// (frequency, magnitude) of the largest |H| and of the smallest |H| below it, in a band.
fn pair_in(freq: &[f64], h: &[Complex64], lo: f64, hi: f64) -> ((f64, f64), (f64, f64)) {
    let idx: Vec<usize> = (0..freq.len())
        .filter(|&i| freq[i] >= lo && freq[i] <= hi)
        .collect();
    let kmax = *idx
        .iter()
        .max_by(|&&a, &&b| h[a].norm().total_cmp(&h[b].norm()))
        .unwrap();
    let kmin = *idx
        .iter()
        .filter(|&&i| freq[i] < freq[kmax])
        .min_by(|&&a, &&b| h[a].norm().total_cmp(&h[b].norm()))
        .unwrap();
    ((freq[kmax], h[kmax].norm()), (freq[kmin], h[kmin].norm()))
}

#[test]
fn motor_bench_resonance_and_antiresonance() {
    let Some(dir) = shared_data("motor-bench", "the real-data spectral test") else {
        return;
    };
    for f in ["MultisineTypeA.mat", "MultisineTypeB.mat"] {
        let p = dir.join(f);
        let log = read_log(
            &p,
            &LogSpec {
                inputs: vec!["iq_refx".into()],
                outputs: vec!["omega_max".into(), "theta_mx".into()],
                ..LogSpec::default()
            },
        )
        .unwrap();
        assert_eq!(log.fs(), 2500.0, "fs from the `fs` variable");
        let pa = PeriodicAveraging::new(2500);
        let r = pa.frf_log(&log, 0, 0).unwrap();
        assert_eq!(r.n_periods, 20);
        let (lo, hi) = (r.freq_hz[0], *r.freq_hz.last().unwrap());
        eprintln!(
            "{f}: {} excited lines {lo}..{hi} Hz, min coherence {:.3}, excluded bands at 0.85: {}",
            r.lines.len(),
            r.coherence.iter().cloned().fold(1.0, f64::min),
            r.excluded_bands(DEFAULT_COHERENCE_THRESHOLD).len()
        );
        assert!(lo >= 11.0 - 1e-9 && hi <= 250.0 + 1e-9, "band {lo}..{hi}");
        let ((fr, hr), (fa, ha)) = pair_in(&r.freq_hz, &r.h, 11.0, 150.0);
        let depth_db = 20.0 * (hr / ha).log10();
        eprintln!(
            "{f} omega_max/iq_refx: resonance {fr} Hz ({:.1} dB), anti-resonance {fa} Hz ({:.1} dB), \
             peak/notch {depth_db:.1} dB",
            20.0 * hr.log10(),
            20.0 * ha.log10()
        );
        // Two-mass coupling seen from the motor side: anti-resonance below the resonance.
        assert!((60.0..100.0).contains(&fr), "resonance at {fr} Hz");
        assert!((40.0..fr).contains(&fa), "anti-resonance at {fa} Hz");
        assert!(depth_db > 20.0, "{depth_db} dB");
        // Relative noise at the resonance is small; the variance is reported.
        let i = r.freq_hz.iter().position(|&x| x == fr).unwrap();
        assert!(
            r.var_h[i].sqrt() < 0.05 * hr,
            "{} vs {hr}",
            r.var_h[i].sqrt()
        );

        // The angle output shows the same pair (it is the integrated velocity).
        let rt = pa.frf_log(&log, 0, 1).unwrap();
        let h_int: Vec<Complex64> =
            rt.h.iter()
                .zip(&rt.freq_hz)
                .map(|(h, f)| h * Complex64::new(0.0, 2.0 * std::f64::consts::PI * f))
                .collect();
        let ((fr2, _), (fa2, _)) = pair_in(&rt.freq_hz, &h_int, 11.0, 150.0);
        eprintln!("{f} theta_mx·jω: resonance {fr2} Hz, anti-resonance {fa2} Hz");
        assert!((fr2 - fr).abs() <= 2.0 && (fa2 - fa).abs() <= 2.0);

        // Welch with period-synchronous segments (one period each, rectangular window, no
        // overlap) is the same estimator up to noise: H1 at the excited lines within 2 % of the
        // period-averaged H (the noise-to-signal ratio there is below 1 %), same pair.
        let w = Welch {
            nperseg: 2500,
            noverlap: Some(0),
            window: Window::Rectangular,
            detrend: Detrend::None,
        }
        .etfe_log(&log, 0, 0)
        .unwrap();
        let mut worst = 0.0f64;
        for (i, &k) in r.lines.iter().enumerate() {
            worst = worst.max((w.h[k] - r.h[i]).norm() / r.h[i].norm());
        }
        eprintln!("{f}: Welch (rectangular, synchronous) vs periodic H: max rel diff {worst:.1e}");
        assert!(worst < 0.02, "{worst}");
        // Default Welch (Hann, 50 %): the odd-odd multisine (type B) leaves bins without input
        // power, where H1 is meaningless (|H1| of 116 dB at 19 Hz); the coherence gate removes
        // them, and the gated bins show the same pair (Hann's 3-bin kernel mixes neighbouring
        // lines: within 2 Hz).
        let hann = Welch::new(2500).etfe_log(&log, 0, 0).unwrap();
        let gate = hann.gate(DEFAULT_COHERENCE_THRESHOLD);
        let (gf, gh): (Vec<f64>, Vec<Complex64>) = (0..gate.len())
            .filter(|&k| gate[k])
            .map(|k| (hann.freq_hz[k], hann.h[k]))
            .unzip();
        let ((fh, _), (fah, _)) = pair_in(&gf, &gh, 11.0, 150.0);
        eprintln!(
            "{f}: Welch (Hann, 50 %): {} of {} bins in 11..250 Hz pass the gate; resonance {fh} Hz, \
             anti-resonance {fah} Hz",
            gf.iter().filter(|&&x| (11.0..=250.0).contains(&x)).count(),
            hann.freq_hz.iter().filter(|&&x| (11.0..=250.0).contains(&x)).count()
        );
        assert!((fh - fr).abs() <= 2.0, "{fh} vs {fr}");
    }
}

#[derive(Deserialize)]
struct Pair {
    file: String,
    input_col: usize,
    output_col: usize,
    n: usize,
}

#[derive(Deserialize)]
struct DaisyRef {
    nperseg: usize,
    pairs: Vec<WithSpectra<Pair>>,
}

#[test]
fn daisy_welch_matches_scipy_on_the_real_files() {
    let Some(dir) = shared_data("daisy", "the real-data spectral test") else {
        return;
    };
    let fx: DaisyRef = serde_json::from_str(
        &std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/fixtures/spectral_daisy_scipy.json"
        ))
        .unwrap(),
    )
    .unwrap();
    for pr in &fx.pairs {
        let log = read_columns(
            &dir.join(&pr.file),
            &TextOptions {
                input_cols: vec![pr.input_col],
                output_cols: vec![pr.output_col],
                fs: Some(1.0),
                ..TextOptions::default()
            },
        )
        .unwrap();
        assert_eq!(log.len(), pr.n);
        assert!(log.warnings.is_empty(), "{:?}", log.warnings);
        let e = Welch::new(fx.nperseg).etfe_log(&log, 0, 0).unwrap();
        let rel = |a: f64, b: f64, top: f64| (a - b).abs() / b.abs().max(1e-7 * top);
        let (tu, ty) = (
            pr.scipy.pxx.iter().cloned().fold(0.0, f64::max),
            pr.scipy.pyy.iter().cloned().fold(0.0, f64::max),
        );
        // Same rule as tests/spectral_scipy.rs: relative error at bins whose reference is above
        // 1e-7 of the largest; the coherence where the cross-spectrum is (at the band edges of
        // the robot-arm input the spectra sit 1e-13 below their peak, at the round-off floor).
        let pxy = pr.scipy.pxy();
        let top_xy = pxy.iter().map(|z| z.norm()).fold(0.0, f64::max);
        let mut worst = 0.0f64;
        for k in 0..pr.scipy.f.len() {
            let pxy = pxy[k];
            worst = worst
                .max(rel(e.freq_hz[k], pr.scipy.f[k], 1.0))
                .max(rel(e.suu[k], pr.scipy.pxx[k], tu))
                .max(rel(e.syy[k], pr.scipy.pyy[k], ty))
                .max((e.suy[k] - pxy).norm() / pxy.norm().max(1e-7 * top_xy));
            if pxy.norm() > 1e-7 * top_xy {
                worst = worst.max((e.coherence[k] - pr.scipy.cxy[k]).abs() / pr.scipy.cxy[k]);
            }
        }
        let gated = e
            .gate(DEFAULT_COHERENCE_THRESHOLD)
            .iter()
            .filter(|g| **g)
            .count();
        let (fr, _) = pair_in(&e.freq_hz, &e.h, 0.0, 0.5).0;
        eprintln!(
            "{} u{} -> y{}: max rel deviation from scipy {worst:.1e}; {gated}/{} bins pass the 0.85 \
             gate; largest |H1| at {fr:.4} cycles/sample",
            pr.file,
            pr.input_col,
            pr.output_col,
            e.freq_hz.len()
        );
        assert!(worst < 1e-9, "{}: {worst}", pr.file);
    }
}
