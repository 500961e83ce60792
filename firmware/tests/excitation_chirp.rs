//! Chirp: samples against an f64 evaluation of the documented law, the frequency law recovered
//! from zero crossings of the generated signal, the spectrum of a linear sweep against the
//! stationary-phase level, and invalid configurations.

use ferrosid_firmware::excitation::{Chirp, ChirpConfig, ChirpLaw};
use ferrosid_firmware::{Error, Excitation};
use std::f64::consts::PI;

fn cfg(law: ChirpLaw, f0: f32, f1: f32) -> ChirpConfig {
    ChirpConfig {
        fs_hz: 2000.0,
        f0_hz: f0,
        f1_hz: f1,
        duration_s: 10.0,
        fade_s: 0.25,
        amplitude: 0.7,
        law,
    }
}

/// f[n] of the documented law, in f64.
fn law(c: &ChirpConfig, len: u32, n: f64) -> f64 {
    let (f0, f1) = (c.f0_hz as f64, c.f1_hz as f64);
    match c.law {
        ChirpLaw::Linear => f0 + (f1 - f0) * n / len as f64,
        ChirpLaw::Logarithmic => f0 * (f1 / f0).powf(n / len as f64),
    }
}

fn generate(c: &ChirpConfig) -> (Chirp, Vec<f32>) {
    let mut ch = Chirp::new(*c).unwrap();
    let len = ch.len_samples() as usize;
    let x: Vec<f32> = (0..len).map(|_| ch.next_sample()).collect();
    (ch, x)
}

/// Largest |x - x_ref| over the sweep, x_ref from the documented law in f64.
fn max_deviation(c: &ChirpConfig) -> f64 {
    let (ch, x) = generate(c);
    let len = ch.len_samples();
    let fade = ch.fade_samples();
    assert_eq!(len, 20_000);
    assert_eq!(fade, 500);
    let fs = c.fs_hz as f64;
    let mut phase = 0.0f64; // cycles
    let mut worst = 0.0f64;
    for (n, &v) in x.iter().enumerate() {
        let m = if (n as u32) < fade {
            n as f64
        } else if n as u32 >= len - fade {
            (len - 1 - n as u32) as f64
        } else {
            f64::INFINITY
        };
        let w = if m.is_finite() {
            0.5 - 0.5 * (PI * m / fade as f64).cos()
        } else {
            1.0
        };
        let r = c.amplitude as f64 * w * (2.0 * PI * phase.fract()).sin();
        worst = worst.max((v as f64 - r).abs());
        phase += law(c, len, n as f64) / fs;
        assert!(
            (ch.instantaneous_frequency_hz(n as u32) as f64 - law(c, len, n as f64)).abs()
                <= 1e-6 * law(c, len, n as f64),
            "n={n}"
        );
    }
    worst
}

#[test]
fn samples_follow_the_documented_law() {
    // Linear: exact 64-bit phase accumulation; error = sine approximation (< 2.5e-7) × A.
    let lin = max_deviation(&cfg(ChirpLaw::Linear, 10.0, 400.0));
    let lin_down = max_deviation(&cfg(ChirpLaw::Linear, 400.0, 0.0));
    // Logarithmic: f[n] from f32 expf, relative error ≲ 5e-7 per sample; integrated over 20k
    // samples at up to 800 Hz (8000 cycles) the phase error stays below 8000·5e-7·2π ≈ 0.025 rad
    // in the worst (fully correlated) case ⇒ tolerance 0.025·A.
    let log = max_deviation(&cfg(ChirpLaw::Logarithmic, 5.0, 800.0));
    println!(
        "max |x - x_ref|: linear {lin:.2e}, linear down {lin_down:.2e}, log {log:.2e} (A = 0.7)"
    );
    assert!(lin < 0.7 * 3e-7, "{lin}");
    assert!(lin_down < 0.7 * 3e-7, "{lin_down}");
    assert!(log < 0.7 * 0.025, "{log}");
}

/// Frequency recovered from the signal: upward zero crossings M cycles apart give the mean
/// frequency M/Δt over [t_a, t_b]; the law's mean over the same interval, with its half-sample
/// lag (see Chirp docs), is the expectation. Returns the max relative error.
/// Crossing times: the two samples around a crossing are mapped to phase by asin(x/A) (the
/// envelope is 1 outside the fades) and the phase is interpolated linearly, which is exact for a
/// locally constant frequency (plain linear interpolation of x would err by up to 0.026 sample
/// at 0.2·fs).
fn zero_crossing_error(c: &ChirpConfig, cycles: usize) -> f64 {
    let (ch, x) = generate(c);
    let fs = c.fs_hz as f64;
    let len = ch.len_samples() as f64;
    let fade = ch.fade_samples() as usize;
    let mut ups = Vec::new();
    for n in fade..x.len() - fade - 1 {
        let (a, b) = (x[n] as f64, x[n + 1] as f64);
        if a < 0.0 && b >= 0.0 {
            let amp = c.amplitude as f64;
            let (pa, pb) = ((a / amp).asin(), (b / amp).asin());
            ups.push((n as f64 + pa / (pa - pb)) / fs);
        }
    }
    let (f0, f1) = (c.f0_hz as f64, c.f1_hz as f64);
    let t_len = len / fs;
    // ∫ f(t - 1/(2fs)) dt over [ta, tb] / (tb - ta)
    let mean_law = |ta: f64, tb: f64| {
        let (a, b) = (ta - 0.5 / fs, tb - 0.5 / fs);
        match c.law {
            ChirpLaw::Linear => f0 + (f1 - f0) * 0.5 * (a + b) / t_len,
            ChirpLaw::Logarithmic => {
                let k = f1 / f0;
                f0 * t_len / k.ln() * (k.powf(b / t_len) - k.powf(a / t_len)) / (b - a)
            }
        }
    };
    let mut worst = 0.0f64;
    for i in 0..ups.len() - cycles {
        let (ta, tb) = (ups[i], ups[i + cycles]);
        let f_est = cycles as f64 / (tb - ta);
        worst = worst.max((f_est / mean_law(ta, tb) - 1.0).abs());
    }
    assert!(ups.len() > 100);
    worst
}

#[test]
fn frequency_law_recovered_from_zero_crossings() {
    // Residual crossing-time error: the sine approximation (2.5e-7/A rad) and the frequency
    // change within one sample; over 10 cycles (>= 50 samples) far below 1e-5 relative.
    // Tolerance 1e-5 (the log law's phase error, see above, is ~1e-7 relative per sample).
    let lin = zero_crossing_error(&cfg(ChirpLaw::Linear, 20.0, 400.0), 10);
    let log = zero_crossing_error(&cfg(ChirpLaw::Logarithmic, 20.0, 400.0), 10);
    println!("zero-crossing frequency error: linear {lin:.2e}, log {log:.2e}");
    assert!(lin < 1e-5 && log < 1e-5);
    // The tolerance is able to tell the laws apart: the log signal does not follow the
    // linear law (checked by swapping the law in the expectation).
    let mut c = cfg(ChirpLaw::Logarithmic, 20.0, 400.0);
    let (_, x) = generate(&c);
    c.law = ChirpLaw::Linear;
    let (_, y) = generate(&c);
    assert!(x.iter().zip(&y).any(|(a, b)| (a - b).abs() > 0.1));
}

#[test]
fn linear_sweep_spectrum_is_in_band_at_the_stationary_phase_level() {
    // x = A sin φ, sweep rate c = (f1 - f0)/T Hz/s: |X(f)|² ≈ A²/(4c) inside the band
    // (stationary phase), DFT |X[k]|² ≈ fs²·A²/(4c). Out-of-band energy (beyond 30 Hz from the
    // band edges) < 1e-3 of the total; in-band mean level within ±0.5 dB of the prediction.
    let c = ChirpConfig {
        fs_hz: 2000.0,
        f0_hz: 100.0,
        f1_hz: 500.0,
        duration_s: 4.0,
        fade_s: 0.1,
        amplitude: 1.0,
        law: ChirpLaw::Linear,
    };
    let (_, x) = generate(&c);
    let n = x.len();
    let mut buf: Vec<rustfft::num_complex::Complex64> = x
        .iter()
        .map(|&v| rustfft::num_complex::Complex64::new(v as f64, 0.0))
        .collect();
    rustfft::FftPlanner::new()
        .plan_fft_forward(n)
        .process(&mut buf);
    let df = c.fs_hz as f64 / n as f64;
    let p: Vec<f64> = buf[..n / 2].iter().map(|z| z.norm_sqr()).collect();
    let total: f64 = p.iter().sum();
    let out: f64 = p
        .iter()
        .enumerate()
        .filter(|(k, _)| {
            let f = *k as f64 * df;
            !(70.0..=530.0).contains(&f)
        })
        .map(|(_, v)| v)
        .sum();
    let rate = (500.0 - 100.0) / 4.0;
    let expect = (c.fs_hz as f64).powi(2) / (4.0 * rate);
    let band: Vec<f64> = p
        .iter()
        .enumerate()
        .filter(|(k, _)| (150.0..=450.0).contains(&(*k as f64 * df)))
        .map(|(_, v)| *v)
        .collect();
    let mean_db = 10.0 * (band.iter().sum::<f64>() / band.len() as f64 / expect).log10();
    println!(
        "out-of-band fraction {:.2e}, in-band level {mean_db:+.3} dB vs stationary phase",
        out / total
    );
    assert!(out / total < 1e-3);
    assert!(mean_db.abs() < 0.5);
}

#[test]
fn silent_after_the_sweep_and_restart_repeats() {
    let mut ch = Chirp::new(ChirpConfig {
        duration_s: 0.01,
        fade_s: 0.0,
        ..cfg(ChirpLaw::Linear, 10.0, 100.0)
    })
    .unwrap();
    assert_eq!(ch.len_samples(), 20);
    let a: Vec<f32> = (0..20).map(|_| ch.next_sample()).collect();
    assert!(ch.is_finished());
    assert_eq!(ch.next_sample(), 0.0);
    assert_eq!(ch.instantaneous_frequency_hz(20), 0.0);
    ch.restart();
    let b: Vec<f32> = (0..20).map(|_| ch.next_sample()).collect();
    assert_eq!(a, b);
    assert_eq!(a[0], 0.0, "phase starts at 0");
}

#[test]
fn invalid_configurations_are_rejected() {
    let ok = cfg(ChirpLaw::Logarithmic, 10.0, 100.0);
    let e = |c: ChirpConfig| Chirp::new(c).err();
    for fs in [0.0, -1.0, f32::NAN, f32::INFINITY] {
        assert_eq!(
            e(ChirpConfig { fs_hz: fs, ..ok }),
            Some(Error::InvalidSampleRate)
        );
    }
    for f in [0.0, -5.0, 1000.0, 1500.0, f32::NAN] {
        assert_eq!(
            e(ChirpConfig { f0_hz: f, ..ok }),
            Some(Error::InvalidFrequency),
            "f0={f}"
        );
        assert_eq!(
            e(ChirpConfig { f1_hz: f, ..ok }),
            Some(Error::InvalidFrequency),
            "f1={f}"
        );
    }
    // A linear sweep may start at DC.
    assert!(Chirp::new(ChirpConfig {
        f0_hz: 0.0,
        law: ChirpLaw::Linear,
        ..ok
    })
    .is_ok());
    for a in [0.0, -1.0, f32::NAN] {
        assert_eq!(
            e(ChirpConfig { amplitude: a, ..ok }),
            Some(Error::InvalidAmplitude)
        );
    }
    for (d, f) in [
        (0.0, 0.0),
        (0.0005, 0.0),
        (-1.0, 0.0),
        (f32::NAN, 0.0),
        (1.0, 0.6),
        (1.0, -0.1),
        (1e9, 0.0),
    ] {
        assert_eq!(
            e(ChirpConfig {
                duration_s: d,
                fade_s: f,
                ..ok
            }),
            Some(Error::InvalidDuration),
            "duration {d}, fade {f}"
        );
    }
    assert!(Chirp::new(ChirpConfig {
        duration_s: 1.0,
        fade_s: 0.5,
        ..ok
    })
    .is_ok());
}
