//! Bad input and statistics: NaN/inf/out-of-range samples quarantine whole segments (checked
//! against the f64 reference over the surviving segments), length mismatch, invalid
//! configurations, coherence bias of uncorrelated noise (≈ 1/n_avg), memory budget, and a
//! property test that no f32 input sequence can panic or produce a non-finite output.

mod common;

use common::*;
use ferrosid_firmware::welch::{accepts, MAX_ABS_SAMPLE};
use ferrosid_firmware::{Error, Welch, WelchConfig, Window};
use proptest::prelude::*;

#[test]
fn memory_budget_welch_1024() {
    // Issue bar for the whole image: 24·N + 2 KiB of static RAM; the estimator itself must
    // stay within 24·N + 512 bytes.
    let s = core::mem::size_of::<Welch<1024>>();
    println!(
        "size_of::<Welch<1024>>() = {s} bytes (24·N = {})",
        24 * 1024
    );
    assert!(s <= 24 * 1024 + 512, "{s}");
    assert!(core::mem::size_of::<Welch<64>>() <= 24 * 64 + 512);
    assert!(core::mem::size_of::<Welch<4096>>() <= 24 * 4096 + 512);
}

#[test]
fn nonfinite_samples_drop_exactly_the_segments_containing_them() {
    const N: usize = 256;
    let hop = 128;
    let mut rng = Noise::new(5);
    let u = rng.gauss_vec(60 * N);
    let y = lfilter(&[0.3, 0.2], &[1.0, -0.5], &u);
    let (mut u32s, mut y32s) = (to_f32(&u), to_f32(&y));
    // Bad samples: NaN in u, +inf in y, -inf in both, an out-of-range finite value, and a NaN
    // in both channels at the same instant (one sample pair).
    let bad: [(usize, f32, bool, bool); 5] = [
        (1000, f32::NAN, true, false),
        (5000, f32::INFINITY, false, true),
        (5001, f32::NEG_INFINITY, true, true),
        (9000, 2.0 * MAX_ABS_SAMPLE, true, false),
        (12_345, f32::NAN, true, true),
    ];
    for &(i, v, in_u, in_y) in &bad {
        if in_u {
            u32s[i] = v;
        }
        if in_y {
            y32s[i] = v;
        }
    }
    let mut w = Welch::<N>::new(WelchConfig::scipy_default(100.0, N)).unwrap();
    w.push_slice(&u32s, &y32s).unwrap();
    let hit = |s: usize| bad.iter().any(|&(i, ..)| s <= i && i < s + N);
    let total = (u32s.len() - N) / hop + 1;
    let n_hit = (0..total).filter(|&j| hit(j * hop)).count();
    assert_eq!(w.nonfinite_samples(), 5);
    assert_eq!(w.dropped_segments() as usize, n_hit);
    assert_eq!(w.averages() as usize, total - n_hit);
    // The survivors agree with the reference restricted to the same segments.
    let (uw, yw) = (widen(&u32s), widen(&y32s));
    let r = ref_csd(&uw, &yw, N, N - hop, true, true, 100.0, hit);
    assert_eq!(r.segments, w.averages() as usize);
    for k in 0..w.bins() {
        assert!(w.suu(k).is_finite() && w.syy(k).is_finite());
        if r.coherence(k) > 0.5 {
            assert!(
                (w.suu(k) as f64 - r.suu[k]).abs() <= 1e-4 * r.suu[k],
                "k={k}"
            );
            assert!(
                (w.syy(k) as f64 - r.syy[k]).abs() <= 1e-4 * r.syy[k],
                "k={k}"
            );
            assert!(
                (w.coherence(k) as f64 - r.coherence(k)).abs() <= 1e-4,
                "k={k}"
            );
        }
    }
}

#[test]
fn unconfigured_estimator_is_inert_until_configured() {
    let mut w = Welch::<64>::unconfigured();
    assert!(!w.is_configured());
    let mut rng = Noise::new(1);
    for _ in 0..1000 {
        w.push(rng.gauss() as f32, rng.gauss() as f32);
    }
    w.push_slice(&[1.0; 300], &[2.0; 300]).unwrap();
    w.push(f32::NAN, 0.0);
    assert_eq!(w.averages(), 0);
    for k in 0..w.bins() {
        assert_eq!((w.suu(k), w.coherence(k), w.h1(k)), (0.0, 0.0, None));
    }
    w.configure(WelchConfig::scipy_default(10.0, 64)).unwrap();
    assert!(w.is_configured());
    assert_eq!(
        (w.averages(), w.nonfinite_samples()),
        (0, 0),
        "configure() resets"
    );
    let u: Vec<f32> = (0..64 * 4).map(|_| rng.gauss() as f32).collect();
    w.push_slice(&u, &u).unwrap();
    assert_eq!(w.averages(), 7);
    assert!((w.coherence(5) - 1.0).abs() < 1e-5 && w.h1(5).is_some());
}

#[test]
fn push_slice_length_mismatch_is_an_error_and_consumes_nothing() {
    let mut w = Welch::<64>::new(WelchConfig::scipy_default(1.0, 64)).unwrap();
    assert_eq!(
        w.push_slice(&[1.0, 2.0, 3.0], &[1.0, 2.0]),
        Err(Error::LengthMismatch { u: 3, y: 2 })
    );
    for i in 0..63 {
        w.push(i as f32, 1.0);
    }
    assert_eq!(
        w.averages(),
        0,
        "the failed call must not have consumed samples"
    );
    w.push(1.0, 2.0);
    // The segment that just ended is folded in over the next hop's pushes, or by flush().
    assert!(w.segment_in_work());
    assert_eq!(w.averages(), 0);
    w.flush();
    assert!(!w.segment_in_work());
    assert_eq!(w.averages(), 1);
}

/// Bounded push: the work of a segment that has ended is spread over the next hop's pushes.
/// Every estimate read meanwhile is, bin by bin, bit for bit either the estimate without that
/// segment or the estimate with it (each bin is a mean over the segments it contains); the
/// number of bins that include it never decreases; and once the next segment ends it is fully
/// included without any flush().
#[test]
fn segment_work_is_spread_over_the_next_hop_and_estimates_stay_consistent() {
    // N = 256: the final radix-2 stage is fused into the recombination; N = 128: it is not.
    spread_and_consistent::<256>();
    spread_and_consistent::<128>();
}

fn spread_and_consistent<const N: usize>() {
    let configs = [
        WelchConfig::scipy_default(100.0, N),
        WelchConfig {
            fs_hz: 100.0,
            overlap: N / 8 + 5,
            window: Window::Rectangular,
            detrend_mean: true,
        },
        WelchConfig {
            fs_hz: 100.0,
            overlap: 0,
            window: Window::Hann,
            detrend_mean: false,
        },
    ];
    for cfg in configs {
        let hop = N - cfg.overlap;
        let mut rng = Noise::new(9);
        let u = to_f32(&rng.gauss_vec(N + 3 * hop));
        let y = to_f32(&lfilter(&[0.3, 0.2], &[1.0, -0.5], &widen(&u)));
        // The second segment ends with sample `end - 1`.
        let end = N + hop;
        let mut before = Welch::<N>::new(cfg).unwrap();
        before.push_slice(&u[..end - 1], &y[..end - 1]).unwrap();
        let mut after = Welch::<N>::new(cfg).unwrap();
        after.push_slice(&u[..end], &y[..end]).unwrap();
        assert_eq!((before.averages(), after.averages()), (1, 2));
        let bits = |w: &Welch<N>, k: usize| {
            let (re, im) = w.suy(k);
            [w.suu(k), w.syy(k), re, im, w.coherence(k)].map(f32::to_bits)
        };
        let mut live = Welch::<N>::new(cfg).unwrap();
        for (&a, &b) in u[..end].iter().zip(&y[..end]) {
            live.push(a, b);
        }
        assert!(live.segment_in_work(), "overlap {}", cfg.overlap);
        let mut included = 0;
        let mut pushes_in_work = 0;
        for j in end..end + hop {
            let mut now = 0;
            for k in 0..live.bins() {
                let v = bits(&live, k);
                if v == bits(&after, k) {
                    now += 1;
                } else {
                    assert_eq!(
                        v,
                        bits(&before, k),
                        "overlap {} k={k} push {j}",
                        cfg.overlap
                    );
                }
            }
            assert!(
                now >= included,
                "bins including the segment went {included} -> {now}"
            );
            included = now;
            pushes_in_work += usize::from(live.segment_in_work());
            live.push(u[j], y[j]);
        }
        // The third segment has just ended and is in work now; the second is complete.
        assert!(live.segment_in_work(), "overlap {}", cfg.overlap);
        assert_eq!(live.averages(), 2);
        for k in 0..live.bins() {
            assert_eq!(bits(&live, k), bits(&after, k), "k={k}");
        }
        // The work really is spread: it takes more than a few pushes.
        assert!(
            pushes_in_work > 8,
            "segment done after {pushes_in_work} pushes"
        );
    }
}

#[test]
fn invalid_configurations_are_rejected() {
    let ok = WelchConfig::scipy_default(1000.0, 128);
    for fs in [f32::NAN, f32::INFINITY, 0.0, -1.0, 1e-7, 2e12] {
        let cfg = WelchConfig { fs_hz: fs, ..ok };
        assert_eq!(
            Welch::<128>::new(cfg).err(),
            Some(Error::InvalidSampleRate),
            "fs={fs}"
        );
    }
    for overlap in [128, 129, usize::MAX] {
        let cfg = WelchConfig { overlap, ..ok };
        assert_eq!(Welch::<128>::new(cfg).err(), Some(Error::InvalidOverlap));
    }
    assert!(Welch::<128>::new(WelchConfig { overlap: 127, ..ok }).is_ok());
    assert!(Welch::<128>::new(WelchConfig { overlap: 0, ..ok }).is_ok());
    // configure() leaves a working estimator untouched on error.
    let mut w = Welch::<128>::new(ok).unwrap();
    assert_eq!(
        w.configure(WelchConfig { overlap: 500, ..ok }),
        Err(Error::InvalidOverlap)
    );
    assert_eq!(w.config(), &ok);
    assert_eq!(w.hop(), 64);
    w.configure(WelchConfig {
        overlap: 32,
        window: Window::Rectangular,
        ..ok
    })
    .unwrap();
    assert_eq!(w.hop(), 96);
}

#[test]
fn undefined_outputs_before_any_average() {
    let mut w = Welch::<64>::new(WelchConfig::scipy_default(1.0, 64)).unwrap();
    for i in 0..63 {
        w.push((i as f32).sin(), 1.0);
    }
    assert_eq!(w.averages(), 0);
    for k in 0..w.bins() + 3 {
        assert_eq!(w.h1(k), None);
        assert_eq!(w.coherence(k), 0.0);
        assert_eq!(w.suu(k), 0.0);
    }
    assert_eq!(w.gate(0.0).count(), 0);
    // Out-of-range bins after averages: zeros / None, no panic.
    w.push(0.5, 0.5);
    w.flush();
    assert_eq!(w.averages(), 1);
    assert_eq!(w.h1(33), None);
    assert_eq!(w.suy(1000), (0.0, 0.0));
    // One average: coherence is exactly 1 wherever both spectra are non-zero (bias!).
    let mut rng = Noise::new(3);
    let mut w = Welch::<64>::new(WelchConfig::scipy_default(1.0, 64)).unwrap();
    for _ in 0..64 {
        w.push(rng.gauss() as f32, rng.gauss() as f32);
    }
    w.flush();
    for k in 1..32 {
        assert!(
            (w.coherence(k) - 1.0).abs() < 1e-5,
            "k={k}: {}",
            w.coherence(k)
        );
    }
    // reset() forgets everything.
    w.reset();
    assert_eq!(
        (w.averages(), w.dropped_segments(), w.nonfinite_samples()),
        (0, 0, 0)
    );
    assert_eq!(w.coherence(3), 0.0);
}

/// Mean coherence over bins 1..N/2 of independent Gaussian u, y.
fn mean_noise_coherence<const N: usize>(
    cfg: WelchConfig,
    segments: usize,
    seed: u64,
) -> (f64, u32, usize) {
    let mut rng = Noise::new(seed);
    let mut w = Welch::<N>::new(cfg).unwrap();
    let len = N + (segments - 1) * (N - cfg.overlap);
    for _ in 0..len {
        w.push(rng.gauss() as f32, rng.gauss() as f32);
    }
    w.flush();
    let m = (1..N / 2).map(|k| w.coherence(k) as f64).sum::<f64>() / (N / 2 - 1) as f64;
    (m, w.averages(), w.gate(0.3).count())
}

#[test]
fn coherence_of_uncorrelated_noise_is_about_one_over_n_avg() {
    // Rectangular, no overlap: independent segments and bins, γ̂² ~ Beta(1, K-1), mean 1/K,
    // sd per bin ≈ 1/K; mean over 2047 bins has sd ≈ 2.2 % of 1/K ⇒ tolerance ±10 % (4.5 sd).
    const N: usize = 4096;
    let k = 32;
    let cfg = WelchConfig {
        fs_hz: 1.0,
        overlap: 0,
        window: Window::Rectangular,
        detrend_mean: true,
    };
    let (m, avg, gated) = mean_noise_coherence::<N>(cfg, k, 21);
    assert_eq!(avg as usize, k);
    println!(
        "rectangular, K={k}: mean γ² = {m:.5}, 1/K = {:.5}",
        1.0 / k as f64
    );
    assert!((m * k as f64 - 1.0).abs() < 0.10, "mean γ² {m} vs 1/K");
    // Gate at 0.3: P(γ̂² > 0.3) = 0.7^31 = 1.6e-5 per bin ⇒ ~0.03 of 2049 bins expected.
    assert!(gated <= 2, "{gated} noise bins passed a 0.3 gate");

    // Hann, 50 % overlap: overlapping segments are correlated, fewer effective averages
    // (n_d ≈ K/1.056 for Welch's variance); expect a mean a few % above 1/K.
    let (m, avg, _) = mean_noise_coherence::<1024>(WelchConfig::scipy_default(1.0, 1024), 64, 22);
    println!(
        "Hann 50 %, K={avg}: mean γ² = {m:.5}, 1/K = {:.5}",
        1.0 / avg as f64
    );
    let ratio = m * avg as f64;
    assert!(ratio > 0.95 && ratio < 1.20, "K·mean γ² = {ratio}");
}

fn sample() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => any::<f32>(),
        2 => -1.0f32..1.0,
        1 => -2.0e12f32..2.0e12,
        1 => Just(MAX_ABS_SAMPLE),
        1 => Just(-MAX_ABS_SAMPLE),
        1 => Just(f32::MIN_POSITIVE / 4.0),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 200,
        failure_persistence: None,
        ..ProptestConfig::default()
    })]
    #[test]
    fn push_never_panics_and_outputs_stay_finite(
        data in proptest::collection::vec((sample(), sample()), 0..700),
        overlap in 0usize..64,
        hann in any::<bool>(),
        detrend in any::<bool>(),
        fs_exp in -6i32..12,
    ) {
        let cfg = WelchConfig {
            fs_hz: 10f32.powi(fs_exp),
            overlap,
            window: if hann { Window::Hann } else { Window::Rectangular },
            detrend_mean: detrend,
        };
        let mut w = Welch::<64>::new(cfg).unwrap();
        for &(u, y) in &data {
            w.push(u, y);
        }
        w.flush();
        let bad = data
            .iter()
            .filter(|(u, y)| !accepts(*u, *y))
            .count();
        prop_assert_eq!(w.nonfinite_samples() as usize, bad);
        let ends = if data.len() >= 64 { 1 + (data.len() - 64) / (64 - overlap) } else { 0 };
        prop_assert_eq!((w.averages() + w.dropped_segments()) as usize, ends);
        for k in 0..w.bins() + 2 {
            let (s_uu, s_yy, (re, im), g) = (w.suu(k), w.syy(k), w.suy(k), w.coherence(k));
            prop_assert!(s_uu.is_finite() && s_uu >= 0.0, "suu {}", s_uu);
            prop_assert!(s_yy.is_finite() && s_yy >= 0.0, "syy {}", s_yy);
            prop_assert!(re.is_finite() && im.is_finite());
            prop_assert!((0.0..=1.0).contains(&g), "coherence {}", g);
            if let Some((hr, hi)) = w.h1(k) {
                prop_assert!(hr.is_finite() && hi.is_finite());
            }
            prop_assert!(w.bin_hz(k).is_finite());
        }
        let _ = w.gate(0.5);
    }

    /// push() per pair (then flush()) and push_slice() over arbitrary chunks give bit-identical
    /// estimates and counters: push spreads each segment's work over the next hop in slices,
    /// push_slice completes it at once, and the arithmetic does not depend on the slicing.
    #[test]
    fn push_slice_equals_push(
        data in proptest::collection::vec((sample(), sample()), 0..900),
        chunks in proptest::collection::vec(1usize..150, 1..40),
        overlap in 0usize..64,
        hann in any::<bool>(),
    ) {
        let cfg = WelchConfig {
            fs_hz: 1.0,
            overlap,
            window: if hann { Window::Hann } else { Window::Rectangular },
            detrend_mean: true,
        };
        let mut a = Welch::<64>::new(cfg).unwrap();
        let mut b = Welch::<64>::new(cfg).unwrap();
        let (u, y): (Vec<f32>, Vec<f32>) = data.iter().cloned().unzip();
        for (&p, &q) in u.iter().zip(&y) {
            a.push(p, q);
        }
        a.flush();
        let mut off = 0;
        for c in chunks.iter().cycle() {
            if off >= u.len() {
                break;
            }
            let end = (off + c).min(u.len());
            b.push_slice(&u[off..end], &y[off..end]).unwrap();
            off = end;
        }
        prop_assert_eq!(a.averages(), b.averages());
        prop_assert_eq!(a.dropped_segments(), b.dropped_segments());
        prop_assert_eq!(a.nonfinite_samples(), b.nonfinite_samples());
        for k in 0..a.bins() {
            prop_assert_eq!(a.suu(k).to_bits(), b.suu(k).to_bits());
            prop_assert_eq!(a.syy(k).to_bits(), b.syy(k).to_bits());
            prop_assert_eq!(a.suy(k).0.to_bits(), b.suy(k).0.to_bits());
            prop_assert_eq!(a.suy(k).1.to_bits(), b.suy(k).1.to_bits());
        }
    }
}
