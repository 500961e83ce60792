//! Period-synchronous averaging on multisines through known plants: exactness without noise,
//! and noise variances that match the actual errors statistically.
use std::f64::consts::PI;

use ferrosid::spectral::PeriodicAveraging;
use ferrosid::{Error, Log};

mod spectral_support;
use spectral_support::{freqz, lfilter, Rng};

/// Random-phase multisine with period `p` exciting `lines`, repeated `reps` times.
fn multisine(p: usize, lines: &[usize], reps: usize, seed: u64) -> Vec<f64> {
    let mut rng = Rng::new(seed);
    let phases: Vec<f64> = lines.iter().map(|_| 2.0 * PI * rng.uniform()).collect();
    let one: Vec<f64> = (0..p)
        .map(|n| {
            lines
                .iter()
                .zip(&phases)
                .map(|(&k, &ph)| (2.0 * PI * (k * n) as f64 / p as f64 + ph).cos())
                .sum()
        })
        .collect();
    one.iter().cycle().take(p * reps).cloned().collect()
}

// Lightly damped second-order plant: poles 0.98 e^{±0.25j}, zero at -0.6.
const B: [f64; 2] = [0.02, 0.012];

fn plant_a() -> [f64; 3] {
    let (r, th) = (0.98f64, 0.25f64);
    [1.0, -2.0 * r * th.cos(), r * r]
}

#[test]
fn noise_free_multisine_is_exact_at_excited_lines() {
    let a = plant_a();
    let p = 1000; // not a power of two
    let lines: Vec<usize> = (3..=300).step_by(4).collect(); // odd-odd style grid
    let (skip, np) = (3, 8);
    let u = multisine(p, &lines, skip + np, 7);
    let y = lfilter(&B, &a, &u);
    let fs = 2500.0;
    let pa = PeriodicAveraging {
        skip_periods: skip,
        ..PeriodicAveraging::new(p)
    };
    let r = pa.frf(&u, &y, fs).unwrap();
    assert_eq!(r.lines, lines, "detected lines");
    assert_eq!(r.n_periods, np);
    assert_eq!(r.unused_samples, 0);
    let mut worst = 0.0f64;
    for (i, &k) in r.lines.iter().enumerate() {
        let w = 2.0 * PI * k as f64 / p as f64;
        assert!((r.freq_hz[i] - k as f64 * fs / p as f64).abs() < 1e-9);
        let h = freqz(&B, &a, w);
        worst = worst.max((r.h[i] - h).norm() / h.norm());
        assert!((r.coherence[i] - 1.0).abs() < 1e-9);
    }
    eprintln!("noise-free periodic FRF: max relative error {worst:.2e}");
    // Transient after 3 skipped periods: 0.98^3000 ~ 1e-26; only round-off remains.
    assert!(worst < 1e-11, "{worst}");
    // Variances are at the round-off floor.
    let vmax = r.var_h.iter().cloned().fold(0.0, f64::max);
    assert!(vmax < 1e-20, "{vmax}");
    // Amplitude scaling: a unit cosine gives |U| = 1/2 on its line.
    for &k in &lines {
        assert!((r.spectra.u[k].norm() - 0.5).abs() < 1e-12);
    }
    // Not skipping the transient gives a visible error at the resonance: the skip matters.
    let r0 = PeriodicAveraging::new(p).frf(&u, &y, fs).unwrap();
    let worst0 = r0
        .lines
        .iter()
        .zip(&r0.h)
        .map(|(&k, hk)| {
            let h = freqz(&B, &a, 2.0 * PI * k as f64 / p as f64);
            (hk - h).norm() / h.norm()
        })
        .fold(0.0, f64::max);
    assert!(worst0 > 1e-6, "{worst0}");
}

#[test]
fn reported_variance_matches_actual_error() {
    // Output noise and (smaller) input noise, independent over time. For each line the
    // normalised error |H_hat - H|^2 / var_h (var_h estimated from the spread of 20 periods)
    // follows approximately F(2, 2(P-1)) with mean (P-1)/(P-2) = 1.056; averaged over L lines its
    // standard deviation is about 1.1/sqrt(L).
    let p = 512;
    let lines: Vec<usize> = (2..=240).step_by(2).collect();
    let (skip, np) = (2, 20);
    let a = plant_a();
    let u0 = multisine(p, &lines, skip + np, 11);
    let y0 = lfilter(&B, &a, &u0);
    let mut rng = Rng::new(12);
    let (su, sy) = (0.05, 0.3);
    let u: Vec<f64> = u0.iter().map(|v| v + su * rng.normal()).collect();
    let y: Vec<f64> = y0.iter().map(|v| v + sy * rng.normal()).collect();
    let r = PeriodicAveraging {
        skip_periods: skip,
        ..PeriodicAveraging::new(p)
    }
    .frf(&u, &y, 1.0)
    .unwrap();
    assert_eq!(r.lines, lines, "detection with a noisy input");
    let mut z = Vec::new();
    for (i, &k) in r.lines.iter().enumerate() {
        let h = freqz(&B, &a, 2.0 * PI * k as f64 / p as f64);
        z.push((r.h[i] - h).norm_sqr() / r.var_h[i]);
    }
    let mean = z.iter().sum::<f64>() / z.len() as f64;
    let expect = (np as f64 - 1.0) / (np as f64 - 2.0);
    let sd = 1.12 / (z.len() as f64).sqrt();
    eprintln!(
        "normalised squared error: mean {mean:.3} (expected {expect:.3} ± {sd:.3}) over {} lines",
        z.len()
    );
    assert!((mean - expect).abs() < 4.0 * sd, "{mean}");
    // Noise variance of the mean output spectrum: white noise sy^2 gives E|N_k|^2 = sy^2 / p per
    // period (DFT scaled by 1/p), divided by np for the mean. Check over the non-excited bins.
    let expect_vy = sy * sy / p as f64 / np as f64;
    let non: Vec<usize> = (1..p / 2).filter(|k| !lines.contains(k)).collect();
    let mean_vy = non.iter().map(|&k| r.spectra.var_y[k]).sum::<f64>() / non.len() as f64;
    eprintln!("var_y: mean {mean_vy:.3e}, expected {expect_vy:.3e}");
    assert!(
        (mean_vy / expect_vy - 1.0).abs() < 0.05,
        "{mean_vy} vs {expect_vy}"
    );
    let expect_vu = su * su / p as f64 / np as f64;
    let mean_vu = non.iter().map(|&k| r.spectra.var_u[k]).sum::<f64>() / non.len() as f64;
    assert!(
        (mean_vu / expect_vu - 1.0).abs() < 0.05,
        "{mean_vu} vs {expect_vu}"
    );
    // Coherence of the periods: in (0, 1); above 0.95 where the per-period output SNR
    // (|H|^2 |U|^2 over the output noise sy^2 / p) exceeds 100; gating and the excluded bands
    // agree with each other.
    for (i, &k) in r.lines.iter().enumerate() {
        let c = r.coherence[i];
        assert!(c > 0.0 && c < 1.0, "line {k}: {c}");
        let h = freqz(&B, &a, 2.0 * PI * k as f64 / p as f64);
        let snr = h.norm_sqr() * 0.25 / (sy * sy / p as f64);
        if snr > 100.0 {
            assert!(c > 0.95, "line {k}: snr {snr}, coherence {c}");
        }
    }
    let gate = r.gate(0.85);
    let rejected: usize = r
        .excluded_bands(0.85)
        .iter()
        .map(|b| b.last - b.first + 1)
        .sum();
    assert_eq!(rejected, gate.iter().filter(|g| !**g).count());
}

#[test]
fn explicit_lines_and_bad_inputs() {
    let p = 100;
    let lines = vec![5, 9, 13];
    let a = plant_a();
    let u = multisine(p, &lines, 4, 3);
    let y = lfilter(&B, &a, &u);
    let r = PeriodicAveraging {
        lines: Some(vec![13, 5]),
        skip_periods: 1,
        ..PeriodicAveraging::new(p)
    }
    .frf(&u, &y, 1.0)
    .unwrap();
    assert_eq!(r.lines, vec![5, 13]);

    let inv = |r: Result<ferrosid::spectral::PeriodicFrf, Error>| match r {
        Err(Error::InvalidArgument(m)) => m,
        other => panic!("expected InvalidArgument, got {other:?}"),
    };
    // Only one period after skipping.
    let m = inv(PeriodicAveraging {
        skip_periods: 3,
        ..PeriodicAveraging::new(p)
    }
    .frf(&u, &y, 1.0));
    assert!(m.contains("at least 2 periods"), "{m}");
    assert!(inv(PeriodicAveraging::new(1).frf(&u, &y, 1.0)).contains(">= 2"));
    let m = inv(PeriodicAveraging {
        lines: Some(vec![0]),
        ..PeriodicAveraging::new(p)
    }
    .frf(&u, &y, 1.0));
    assert!(m.contains("outside"), "{m}");
    assert!(inv(PeriodicAveraging::new(p).frf(&u, &y[..399], 1.0)).contains("differ"));

    // Log entry point: too short names the file.
    let log = Log::siso("bench/ms.mat", 1.0, u[..150].to_vec(), y[..150].to_vec());
    match PeriodicAveraging::new(p).frf_log(&log, 0, 0) {
        Err(Error::Data { file, msg }) => {
            assert!(file.ends_with("ms.mat"));
            assert!(msg.contains("200") && msg.contains("150"), "{msg}");
        }
        other => panic!("{other:?}"),
    }
}
