//! Welch H1 and coherence on known plants with closed-form frequency responses, conventions
//! (phase sign), coherence gating, and bad-input cases.
use std::f64::consts::PI;

use ferrosid::spectral::{coherence_gate, excluded_bands, Detrend, Welch, Window};
use ferrosid::{Error, Log};
use num_complex::Complex64;

mod spectral_support;
use spectral_support::{lfilter, Rng};

/// H(e^{j w}) at `f` Hz for sample rate `fs`.
fn freqz(b: &[f64], a: &[f64], f: f64, fs: f64) -> Complex64 {
    spectral_support::freqz(b, a, 2.0 * PI * f / fs)
}

#[test]
fn first_order_plant_from_white_noise() {
    // y[n] = 0.8 y[n-1] + 0.5 u[n], fs = 1 kHz, 2^16 samples, no output noise.
    let (b, a) = ([0.5], [1.0, -0.8]);
    let fs = 1000.0;
    let u = Rng::new(1).noise(1 << 16, 1.0);
    let y = lfilter(&b, &a, &u);
    let e = Welch::new(1024).etfe(&u, &y, fs).unwrap();
    let mut worst = 0.0f64;
    for k in 1..e.h.len() {
        let h = freqz(&b, &a, e.freq_hz[k], fs);
        worst = worst.max((e.h[k] - h).norm() / h.norm());
        assert!(
            e.coherence[k] > 0.999,
            "bin {k}: coherence {}",
            e.coherence[k]
        );
    }
    eprintln!("first order: max relative H1 error {worst:.2e}");
    // Residual error is the windowed-segment (leakage/transient) bias; tolerance 1 %.
    assert!(worst < 1e-2, "{worst}");
}

#[test]
fn lightly_damped_second_order_resonance() {
    // Poles at radius 0.995, angle 0.2 rad (damping ratio ~0.025), DC gain 1.
    let (r, th) = (0.995f64, 0.2f64);
    let a = [1.0, -2.0 * r * th.cos(), r * r];
    let g = a.iter().sum::<f64>();
    let b = [g];
    let fs = 1.0;
    let u = Rng::new(2).noise(1 << 17, 1.0);
    let y = lfilter(&b, &a, &u);
    let e = Welch::new(4096).etfe(&u, &y, fs).unwrap();
    let (mut worst, mut k_peak) = (0.0f64, 0);
    for k in 1..e.h.len() {
        let h = freqz(&b, &a, e.freq_hz[k], fs);
        worst = worst.max((e.h[k] - h).norm() / h.norm());
        if e.h[k].norm() > e.h[k_peak].norm() {
            k_peak = k;
        }
    }
    // Exact resonance (peak of |H|) on a fine grid.
    let f_res = (0..200_000)
        .map(|i| i as f64 * 0.5 / 200_000.0)
        .max_by(|p, q| {
            freqz(&b, &a, *p, fs)
                .norm()
                .total_cmp(&freqz(&b, &a, *q, fs).norm())
        })
        .unwrap();
    let df = fs / 4096.0;
    let h_peak = freqz(&b, &a, f_res, fs).norm();
    eprintln!(
        "second order: max rel error {worst:.2e}, peak at {:.5} (true {f_res:.5}), |H| {:.3} vs {h_peak:.3}",
        e.freq_hz[k_peak],
        e.h[k_peak].norm()
    );
    assert!(
        (e.freq_hz[k_peak] - f_res).abs() <= df,
        "peak off by more than one bin"
    );
    assert!(
        (e.h[k_peak].norm() / h_peak - 1.0).abs() < 0.05,
        "peak magnitude"
    );
    // Hann-window smoothing of a resonance 8 bins wide: 5 % tolerance everywhere.
    assert!(worst < 0.05, "{worst}");
}

#[test]
fn pure_delay_has_negative_phase_h1_is_y_over_u() {
    // y[n] = 2 u[n-3]: H = 2 e^{-j 3 w}. Checks the csd convention conj(U)·Y.
    let u = Rng::new(3).noise(20_000, 1.0);
    let mut y = vec![0.0; u.len()];
    for n in 3..u.len() {
        y[n] = 2.0 * u[n - 3];
    }
    let e = Welch {
        window: Window::Hann,
        ..Welch::new(512)
    }
    .etfe(&u, &y, 1.0)
    .unwrap();
    for k in [10usize, 50, 100] {
        let w = 2.0 * PI * e.freq_hz[k];
        let expect = Complex64::from_polar(2.0, -3.0 * w);
        assert!(
            (e.h[k] - expect).norm() < 0.02,
            "bin {k}: {} vs {expect}",
            e.h[k]
        );
    }
    // Swapping input and output inverts the response (H1 of y->u is about 1/H).
    let inv = Welch::new(512).etfe(&y, &u, 1.0).unwrap();
    let k = 50;
    assert!((inv.h[k] * e.h[k] - 1.0).norm() < 0.02);
}

#[test]
fn coherence_with_output_noise_matches_theory() {
    // White u (variance 1) through H, white output noise variance s2: gamma^2 = |H|^2 / (|H|^2 + s2).
    let (b, a) = ([0.3, 0.3], [1.0, -0.5]);
    let s2: f64 = 0.25;
    let mut rng = Rng::new(4);
    let u = rng.noise(1 << 17, 1.0);
    let mut y = lfilter(&b, &a, &u);
    for v in &mut y {
        *v += s2.sqrt() * rng.normal();
    }
    let e = Welch::new(512).etfe(&u, &y, 1.0).unwrap();
    // Random error of the coherence estimate (Bendat & Piersol): std ~ sqrt(2) g (1 - g) /
    // sqrt(n_d) with g = gamma (not squared) ... expressed for gamma^2:
    // std(gamma^2_hat) ~ sqrt(2) gamma^2 (1 - gamma^2) / sqrt(gamma^2 n_d) = sqrt(2 gamma^2) (1 - gamma^2) / sqrt(n_d).
    // The estimate is also biased upwards by about (1 - gamma^2)^2 / n_d. The normalised check
    // uses the bins where these large-sample formulas hold (0.2 < gamma^2 < 0.95).
    let nd = e.n_averages as f64;
    let (mut sum_abs, mut sum_z2, mut worst_z, mut m) = (0.0, 0.0, 0.0f64, 0.0);
    for k in 1..e.h.len() - 1 {
        let h2 = freqz(&b, &a, e.freq_hz[k], 1.0).norm_sqr();
        let g = h2 / (h2 + s2);
        sum_abs += (e.coherence[k] - g).abs();
        if g > 0.2 && g < 0.95 {
            let err = e.coherence[k] - g - (1.0 - g).powi(2) / nd;
            let sd = (2.0 * g).sqrt() * (1.0 - g) / nd.sqrt();
            sum_z2 += (err / sd).powi(2);
            worst_z = worst_z.max((err / sd).abs());
            m += 1.0;
        }
    }
    assert!(m > 100.0);
    let (mean, rms_z) = (sum_abs / (e.h.len() - 2) as f64, (sum_z2 / m).sqrt());
    eprintln!(
        "coherence vs theory: mean abs error {mean:.4}, normalised rms {rms_z:.3}, worst {worst_z:.2} sd, {} averages",
        e.n_averages
    );
    // The normalised error should have rms ~1 (50 % overlapped Hann segments are slightly
    // correlated, so a little above 1); no bin beyond 5 standard deviations.
    assert!((0.7..1.5).contains(&rms_z), "{rms_z}");
    assert!(worst_z < 5.0, "{worst_z}");
    assert!(mean < 0.03, "{mean}");
    // H1 is unbiased by output noise, with E|H1 - H|^2 = |H|^2 (1 - gamma^2) / (gamma^2 n_d)
    // (Bendat & Piersol): the normalised squared error averages to about 1.
    let (mut zsum, mut m) = (0.0, 0.0);
    for k in 1..e.h.len() - 1 {
        let h = freqz(&b, &a, e.freq_hz[k], 1.0);
        let g = h.norm_sqr() / (h.norm_sqr() + s2);
        if g > 0.2 {
            zsum += (e.h[k] - h).norm_sqr() / (h.norm_sqr() * (1.0 - g) / (g * nd));
            m += 1.0;
        }
    }
    let zmean = zsum / m;
    eprintln!("H1 normalised mean squared error {zmean:.3} over {m} bins");
    assert!((0.7..1.5).contains(&zmean), "{zmean}");
}

#[test]
fn gate_excludes_the_notch_band_only() {
    // FIR notch with zeros on the unit circle at f0 = 0.2 fs: |H(f0)| = 0, so the coherence
    // collapses there under output noise, and only there.
    let f0 = 0.2;
    let c = (2.0 * PI * f0).cos();
    let b = [1.0, -2.0 * c, 1.0];
    let mut rng = Rng::new(5);
    let u = rng.noise(1 << 16, 1.0);
    let mut y = lfilter(&b, &[1.0], &u);
    for v in &mut y {
        *v += 0.05 * rng.normal();
    }
    let e = Welch::new(256).etfe(&u, &y, 1.0).unwrap();
    let gate = e.gate(ferrosid::spectral::DEFAULT_COHERENCE_THRESHOLD);
    assert_eq!(gate, coherence_gate(&e.coherence, 0.85));
    let bands = e.excluded_bands(0.85);
    eprintln!("excluded bands: {bands:?}");
    // The band around f0 is excluded; the DC bin region (|H(0)| = 2 - 2c = 1.38) is fine.
    let notch = bands
        .iter()
        .find(|b| b.f_lo_hz <= f0 && b.f_hi_hz >= f0)
        .expect("notch band excluded");
    assert!(notch.min_coherence < 0.1);
    assert!(notch.f_hi_hz - notch.f_lo_hz < 0.05);
    assert_eq!(bands.len(), 1, "{bands:?}");
    assert_eq!(
        gate.iter().filter(|g| !**g).count(),
        notch.last - notch.first + 1
    );
    // A NaN coherence is never accepted and shows up as its own band.
    let b2 = excluded_bands(&[0.0, 1.0, 2.0], &[0.9, f64::NAN, 0.95], 0.85);
    assert_eq!(b2.len(), 1);
    assert!(b2[0].min_coherence.is_nan() && b2[0].first == 1);
}

#[test]
fn bad_inputs_are_errors() {
    let u: Vec<f64> = Rng::new(6).noise(1000, 1.0);
    let y = u.clone();
    let inv = |r: Result<ferrosid::spectral::Etfe, Error>| match r {
        Err(Error::InvalidArgument(m)) => m,
        other => panic!("expected InvalidArgument, got {other:?}"),
    };
    assert!(inv(Welch::new(4).etfe(&u, &y, 1.0)).contains(">= 8"));
    let w = Welch {
        noverlap: Some(64),
        ..Welch::new(64)
    };
    assert!(inv(w.etfe(&u, &y, 1.0)).contains("overlap"));
    assert!(inv(Welch::new(2048).etfe(&u, &y, 1.0)).contains("fewer than"));
    assert!(inv(Welch::new(64).etfe(&u, &y[..999], 1.0)).contains("differ"));
    let mut bad = u.clone();
    bad[17] = f64::NAN;
    assert!(inv(Welch::new(64).etfe(&bad, &y, 1.0)).contains("sample 17"));
    for fs in [0.0, -1.0, f64::INFINITY] {
        inv(Welch::new(64).etfe(&u, &y, fs));
    }
    let w = Welch {
        window: Window::Custom(vec![1.0; 10]),
        ..Welch::new(64)
    };
    assert!(inv(w.etfe(&u, &y, 1.0)).contains("custom window"));

    // Log-level entry point: too short names the file; bad channel index.
    let log = Log::siso(
        "bench/short.csv",
        0.001,
        u[..100].to_vec(),
        y[..100].to_vec(),
    );
    match Welch::new(256).etfe_log(&log, 0, 0) {
        Err(Error::Data { file, msg }) => {
            assert_eq!(file, std::path::PathBuf::from("bench/short.csv"));
            assert!(msg.contains("256") && msg.contains("100"), "{msg}");
        }
        other => panic!("{other:?}"),
    }
    assert!(matches!(
        Welch::new(64).etfe_log(&log, 0, 1),
        Err(Error::InvalidArgument(_))
    ));
    let ok = Welch {
        detrend: Detrend::Linear,
        ..Welch::new(64)
    }
    .etfe_log(&log, 0, 0)
    .unwrap();
    assert!((ok.fs - 1000.0).abs() < 1e-9);
    // Identical input and output: H = 1, coherence 1.
    for k in 1..ok.h.len() {
        assert!((ok.h[k] - 1.0).norm() < 1e-12 && (ok.coherence[k] - 1.0).abs() < 1e-12);
    }
}

#[test]
fn gate_rejects_bins_without_input_power_despite_coherence() {
    // Periodic input exciting only every 4th bin of the Welch grid, and an output with an
    // extra deterministic tone (as a nonlinearity would produce) on a non-excited bin: there
    // S_uu is round-off and the coherence can be close to 1, but the bin must not pass.
    let n = 256;
    let (p, reps) = (n, 64);
    let mut rng = Rng::new(9);
    let lines: Vec<usize> = (4..120).step_by(4).collect();
    let ph: Vec<f64> = lines.iter().map(|_| 2.0 * PI * rng.uniform()).collect();
    let one: Vec<f64> = (0..p)
        .map(|t| {
            lines
                .iter()
                .zip(&ph)
                .map(|(&k, &f)| (2.0 * PI * (k * t) as f64 / p as f64 + f).cos())
                .sum()
        })
        .collect();
    let u: Vec<f64> = one.iter().cycle().take(p * reps).cloned().collect();
    let y: Vec<f64> = u
        .iter()
        .enumerate()
        .map(|(t, &v)| 0.5 * v + 0.3 * (2.0 * PI * (50 * t) as f64 / p as f64).cos())
        .collect();
    let e = Welch {
        window: Window::Rectangular,
        noverlap: Some(0),
        ..Welch::new(n)
    }
    .etfe(&u, &y, 1.0)
    .unwrap();
    let gate = e.gate(0.85);
    for &k in &lines {
        assert!(gate[k], "excited bin {k} rejected");
        assert!((e.h[k] - 0.5).norm() < 1e-9);
    }
    assert!(
        !gate[50],
        "unexcited bin 50 passed (coherence {})",
        e.coherence[50]
    );
    let band = e
        .excluded_bands(0.85)
        .into_iter()
        .find(|b| b.first <= 50 && b.last >= 50)
        .unwrap();
    assert!(band.unexcited >= 1);
    assert!(e.suu[50] < 1e-10 * e.suu[4]);
}
