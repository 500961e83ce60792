//! Multisine: spectrum of one period (excited lines at their amplitude, every other bin below
//! -100 dB), Schroeder phases against the closed form, the odd random-phase design, crest-factor
//! optimisation beating Schroeder on the same lines, playback from a flash table, a
//! period-synchronous H1 through a known plant, and bad input.

mod common;

use common::*;
use ferrosid_firmware::excitation::{
    odd_random_phase_lines, Line, Multisine, MultisineScratch, MultisineSpec, OddLineCounts, Phases,
};
use ferrosid_firmware::{Error, Excitation, Welch, WelchConfig, Window};
use rustfft::num_complex::Complex64;

/// f64 DFT (rustfft) of one period.
fn spectrum(t: &[f32]) -> Vec<Complex64> {
    let mut b: Vec<Complex64> = t.iter().map(|&v| Complex64::new(v as f64, 0.0)).collect();
    rustfft::FftPlanner::new()
        .plan_fft_forward(t.len())
        .process(&mut b);
    b
}

/// Checks the spectrum of a designed table: returns (max amplitude error relative to the
/// line's amplitude, worst other-bin level in dB relative to the smallest excited amplitude).
fn check_spectrum<const N: usize>(ms: &Multisine<N>, lines: &[Line]) -> (f64, f64) {
    let x = spectrum(ms.table());
    let mut amp = vec![0.0f64; N / 2 + 1];
    for l in lines {
        amp[l.bin] = l.amplitude as f64;
    }
    let a_min = lines
        .iter()
        .map(|l| l.amplitude as f64)
        .fold(f64::INFINITY, f64::min);
    let (mut amp_err, mut leak) = (0.0f64, 0.0f64);
    for k in 0..=N / 2 {
        let a = x[k].norm() / (N as f64 / 2.0);
        if amp[k] > 0.0 {
            amp_err = amp_err.max((a - amp[k]).abs() / amp[k]);
        } else {
            leak = leak.max(a / a_min);
        }
    }
    let leak_db = 20.0 * leak.max(1e-30).log10();
    assert!(amp_err < 1e-5, "excited-line amplitude error {amp_err:e}");
    assert!(leak_db < -100.0, "unexcited bin at {leak_db:.1} dB");
    // RMS from Parseval: sqrt(Σ A²/2).
    let rms = (lines
        .iter()
        .map(|l| (l.amplitude as f64).powi(2) / 2.0)
        .sum::<f64>())
    .sqrt();
    assert!((ms.rms() as f64 / rms - 1.0).abs() < 1e-5);
    let peak = ms.table().iter().fold(0.0f32, |m, v| m.max(v.abs()));
    assert_eq!(ms.peak(), peak);
    assert!((ms.crest_factor() as f64 - peak as f64 / rms).abs() < 1e-5 * peak as f64 / rms);
    (amp_err, leak_db)
}

#[test]
fn arbitrary_lines_have_exact_spectrum_for_every_phase_strategy() {
    const N: usize = 512;
    // Unsorted, uneven amplitudes, neighbours and isolated lines, highest allowed bin N/2 - 1.
    let lines = [
        Line {
            bin: 40,
            amplitude: 0.5,
        },
        Line {
            bin: 3,
            amplitude: 2.0,
        },
        Line {
            bin: 4,
            amplitude: 1.0,
        },
        Line {
            bin: 255,
            amplitude: 0.25,
        },
        Line {
            bin: 1,
            amplitude: 1.5,
        },
        Line {
            bin: 100,
            amplitude: 0.8,
        },
        Line {
            bin: 101,
            amplitude: 0.8,
        },
        Line {
            bin: 102,
            amplitude: 0.8,
        },
    ];
    let mut scratch = MultisineScratch::<N>::new();
    for phases in [
        Phases::Schroeder,
        Phases::Random { seed: 1 },
        Phases::Random { seed: 2 },
    ] {
        for iters in [0, 50] {
            let spec = MultisineSpec {
                lines: &lines,
                phases,
                crest_iterations: iters,
            };
            let ms = Multisine::<N>::design(&spec, &mut scratch).unwrap();
            let (e, l) = check_spectrum(&ms, &lines);
            println!(
                "{phases:?} iters {iters}: amp err {e:.1e}, leakage {l:.0} dB, crest {:.3}",
                ms.crest_factor()
            );
        }
    }
}

#[test]
fn schroeder_phases_match_closed_form_for_flat_consecutive_lines() {
    // φ_k = -π k(k-1)/F for lines 1..=F of equal amplitude (Schroeder 1970); the table's DFT
    // phase is φ_k (x = Σ A cos(2πkn/N + φ_k)). Tolerance 1e-4 rad.
    const N: usize = 256;
    let f = 60usize;
    let lines: Vec<Line> = (1..=f)
        .map(|k| Line {
            bin: k,
            amplitude: 1.0,
        })
        .collect();
    let ms = Multisine::<N>::design(
        &MultisineSpec {
            lines: &lines,
            phases: Phases::Schroeder,
            crest_iterations: 0,
        },
        &mut MultisineScratch::new(),
    )
    .unwrap();
    let x = spectrum(ms.table());
    for (k, xk) in x.iter().enumerate().take(f + 1).skip(1) {
        let expect = -std::f64::consts::PI * (k * (k - 1)) as f64 / f as f64;
        let d = (xk.arg() - expect).rem_euclid(2.0 * std::f64::consts::PI);
        let d = d.min(2.0 * std::f64::consts::PI - d);
        assert!(d < 1e-4, "k={k}: phase off by {d}");
    }
    // Random phases are different (seeded, reproducible).
    let spec = |seed| MultisineSpec {
        lines: &lines,
        phases: Phases::Random { seed },
        crest_iterations: 0,
    };
    let a = Multisine::<N>::design(&spec(5), &mut MultisineScratch::new()).unwrap();
    let b = Multisine::<N>::design(&spec(5), &mut MultisineScratch::new()).unwrap();
    let c = Multisine::<N>::design(&spec(6), &mut MultisineScratch::new()).unwrap();
    assert_eq!(a.table(), b.table());
    assert_ne!(a.table(), c.table());
}

#[test]
fn odd_random_phase_design_and_crest_factor_optimisation() {
    const N: usize = 1024;
    let mut excited = [Line {
        bin: 0,
        amplitude: 0.0,
    }; 256];
    let mut detection = [0usize; 64];
    // Odd bins 1..=301: 151 lines, groups of G = 4: 37 full groups + a tail of 3 ⇒ 38 detection
    // lines, 113 excited.
    let counts = odd_random_phase_lines(1, 301, 4, 0.1, 42, &mut excited, &mut detection).unwrap();
    assert_eq!(
        counts,
        OddLineCounts {
            excited: 113,
            detection: 38
        }
    );
    let ex = &excited[..counts.excited];
    let det = &detection[..counts.detection];
    for g in 0..38 {
        let lo = 1 + 8 * g;
        let hi = (lo + 8).min(303);
        let d = det.iter().filter(|&&b| b >= lo && b < hi).count();
        let e = ex.iter().filter(|l| l.bin >= lo && l.bin < hi).count();
        assert_eq!(d, 1, "group {g}: one detection line");
        assert_eq!(e + d, if g < 37 { 4 } else { 3 });
    }
    assert!(ex.iter().all(|l| l.bin % 2 == 1 && l.amplitude == 0.1));
    assert!(det.iter().all(|b| b % 2 == 1));

    let mut scratch = MultisineScratch::<N>::new();
    let design = |phases, iters, s: &mut MultisineScratch<N>| {
        Multisine::<N>::design(
            &MultisineSpec {
                lines: ex,
                phases,
                crest_iterations: iters,
            },
            s,
        )
        .unwrap()
    };
    let random = design(Phases::Random { seed: 7 }, 0, &mut scratch);
    let schroeder = design(Phases::Schroeder, 0, &mut scratch);
    let optimised = design(Phases::Random { seed: 7 }, 300, &mut scratch);
    let optimised_s = design(Phases::Schroeder, 300, &mut scratch);
    for ms in [&random, &schroeder, &optimised, &optimised_s] {
        check_spectrum(ms, ex); // detection and even lines stay below -100 dB
        let x = spectrum(ms.table());
        for &b in det {
            assert!(
                x[b].norm() / (N as f64 / 2.0 * 0.1) < 1e-5,
                "detection line {b} excited"
            );
        }
    }
    println!(
        "odd random-phase multisine, 113 lines: crest random {:.3}, Schroeder {:.3}, \
         optimised from random {:.3}, optimised from Schroeder {:.3}",
        random.crest_factor(),
        schroeder.crest_factor(),
        optimised.crest_factor(),
        optimised_s.crest_factor()
    );
    assert!(optimised.crest_factor() < schroeder.crest_factor());
    assert!(optimised_s.crest_factor() < schroeder.crest_factor());
    assert!(optimised.crest_factor() < random.crest_factor());
}

#[test]
fn optimised_crest_factor_beats_schroeder_on_a_flat_band() {
    const N: usize = 1024;
    let lines: Vec<Line> = (1..=200)
        .map(|k| Line {
            bin: k,
            amplitude: 1.0,
        })
        .collect();
    let mut scratch = MultisineScratch::<N>::new();
    let d = |phases, iters, s: &mut MultisineScratch<N>| {
        Multisine::<N>::design(
            &MultisineSpec {
                lines: &lines,
                phases,
                crest_iterations: iters,
            },
            s,
        )
        .unwrap()
    };
    let schroeder = d(Phases::Schroeder, 0, &mut scratch);
    let optimised = d(Phases::Schroeder, 300, &mut scratch);
    check_spectrum(&optimised, &lines);
    println!(
        "flat band 1..=200 of N=1024: crest Schroeder {:.4}, optimised {:.4}",
        schroeder.crest_factor(),
        optimised.crest_factor()
    );
    // Schroeder's flat-band crest factor is about 1.66-1.7 (known); the optimum is near 1.4.
    assert!((1.6..1.75).contains(&schroeder.crest_factor()));
    assert!(optimised.crest_factor() < schroeder.crest_factor());

    // Odd lines only (spacing 2): the envelope repeats every N/2 samples and the generalised
    // Schroeder sweep spans N/2, which keeps the flat-band crest factor (~1.7).
    let odd: Vec<Line> = (0..100)
        .map(|j| Line {
            bin: 2 * j + 1,
            amplitude: 1.0,
        })
        .collect();
    let s_odd = Multisine::<N>::design(
        &MultisineSpec {
            lines: &odd,
            phases: Phases::Schroeder,
            crest_iterations: 0,
        },
        &mut scratch,
    )
    .unwrap();
    println!(
        "odd lines 1..=199 (no gaps): crest Schroeder {:.4}",
        s_odd.crest_factor()
    );
    assert!((1.6..1.75).contains(&s_odd.crest_factor()));
}

#[test]
fn plays_a_flash_table_periodically() {
    const N: usize = 64;
    let lines = [Line {
        bin: 5,
        amplitude: 1.0,
    }];
    let designed = Multisine::<N>::design(
        &MultisineSpec {
            lines: &lines,
            phases: Phases::Schroeder,
            crest_iterations: 0,
        },
        &mut MultisineScratch::new(),
    )
    .unwrap();
    // A 'static table as a host tool would emit it (`static TABLE: [f32; N] = [...]`).
    let table: &'static [f32; N] = Box::leak(Box::new(*designed.table()));
    let mut flash: Multisine<N, &'static [f32; N]> = Multisine::from_table(table).unwrap();
    assert!(
        (flash.crest_factor() - std::f32::consts::SQRT_2).abs() < 1e-5,
        "single sine: √2"
    );
    for rep in 0..3 {
        for (n, &v) in table.iter().enumerate() {
            assert_eq!(flash.next_sample(), v, "rep {rep} n {n}");
        }
    }
    assert_eq!(flash.position(), 0);
    flash.next_sample();
    flash.reset();
    assert_eq!(flash.next_sample(), table[0]);
    // The signal is A cos(2π 5 n / N + φ) with φ = 0 (Schroeder, one line).
    for (n, &v) in table.iter().enumerate() {
        let e = (2.0 * std::f64::consts::PI * 5.0 * n as f64 / N as f64).cos();
        assert!((v as f64 - e).abs() < 1e-6);
    }
    assert_eq!(
        Multisine::<N>::from_table([0.0; N]).err(),
        Some(Error::InvalidAmplitude)
    );
    let mut bad = [0.5f32; N];
    bad[7] = f32::NAN;
    assert_eq!(
        Multisine::<N>::from_table(bad).err(),
        Some(Error::InvalidAmplitude)
    );
}

#[test]
fn period_synchronous_h1_through_a_known_plant_is_exact_on_the_lines() {
    // Multisine with period N, rectangular window, no overlap: every segment is one steady-state
    // period, so there is no leakage and H1 equals the plant's response at the excited lines up
    // to f32 rounding. Plant: y[n] = 0.9 y[n-1] + 0.1 u[n-1]. Tolerance 1e-4 relative.
    const N: usize = 256;
    let mut ex = [Line {
        bin: 0,
        amplitude: 0.0,
    }; 64];
    let mut det = [0usize; 32];
    let c = odd_random_phase_lines(1, 101, 3, 1.0, 3, &mut ex, &mut det).unwrap();
    let lines = &ex[..c.excited];
    let mut ms = Multisine::<N>::design(
        &MultisineSpec {
            lines,
            phases: Phases::Random { seed: 9 },
            crest_iterations: 20,
        },
        &mut MultisineScratch::new(),
    )
    .unwrap();
    let u: Vec<f64> = (0..40 * N).map(|_| ms.next_sample() as f64).collect();
    let (b, a) = ([0.0, 0.1], [1.0, -0.9]);
    let y = lfilter(&b, &a, &u);
    let cfg = WelchConfig {
        fs_hz: 1.0,
        overlap: 0,
        window: Window::Rectangular,
        detrend_mean: false,
    };
    let mut w = Welch::<N>::new(cfg).unwrap();
    // Skip the first 4 periods (transient: 0.9^1024 ≈ 0).
    let (u32s, y32s) = (to_f32(&u[4 * N..]), to_f32(&y[4 * N..]));
    w.push_slice(&u32s, &y32s).unwrap();
    assert_eq!(w.averages(), 36);
    let mut worst = 0.0f64;
    for l in lines {
        let h = freqz(&b, &a, 2.0 * std::f64::consts::PI * l.bin as f64 / N as f64);
        let (hr, hi) = w.h1(l.bin).unwrap();
        let e = (Complex64::new(hr as f64, hi as f64) - h).norm() / h.norm();
        worst = worst.max(e);
        assert!(w.coherence(l.bin) > 0.9999);
    }
    println!(
        "period-synchronous H1 worst relative error on {} lines: {worst:.2e}",
        lines.len()
    );
    assert!(worst < 1e-4);
    // Detection and even lines carry no input power (below -100 dB of the excited level).
    let s_ex = w.suu(lines[0].bin);
    for &d in &det[..c.detection] {
        assert!(w.suu(d) < 1e-10 * s_ex);
        assert!(w.suu(d + 1) < 1e-10 * s_ex);
    }
}

#[test]
fn invalid_line_lists_are_rejected_naming_the_entry() {
    const N: usize = 128;
    let mut s = MultisineScratch::<N>::new();
    let mut d = |lines: &[Line]| {
        Multisine::<N>::design(
            &MultisineSpec {
                lines,
                phases: Phases::Schroeder,
                crest_iterations: 3,
            },
            &mut s,
        )
        .err()
    };
    let good = Line {
        bin: 3,
        amplitude: 1.0,
    };
    assert_eq!(d(&[]), Some(Error::NoLines));
    for (bad, why) in [
        (
            Line {
                bin: 0,
                amplitude: 1.0,
            },
            "DC",
        ),
        (
            Line {
                bin: 64,
                amplitude: 1.0,
            },
            "Nyquist",
        ),
        (
            Line {
                bin: 1000,
                amplitude: 1.0,
            },
            "beyond Nyquist",
        ),
        (
            Line {
                bin: 5,
                amplitude: 0.0,
            },
            "zero amplitude",
        ),
        (
            Line {
                bin: 5,
                amplitude: -1.0,
            },
            "negative amplitude",
        ),
        (
            Line {
                bin: 5,
                amplitude: f32::NAN,
            },
            "NaN amplitude",
        ),
        (
            Line {
                bin: 5,
                amplitude: f32::INFINITY,
            },
            "inf amplitude",
        ),
        (
            Line {
                bin: 5,
                amplitude: 2e12,
            },
            "too large",
        ),
    ] {
        assert_eq!(
            d(&[good, bad]),
            Some(Error::InvalidLine { index: 1 }),
            "{why}"
        );
    }
    assert_eq!(
        d(&[
            good,
            Line {
                bin: 7,
                amplitude: 1.0
            },
            Line {
                bin: 3,
                amplitude: 0.5
            }
        ]),
        Some(Error::DuplicateLine { index: 2 })
    );
    assert!(d(&[
        good,
        Line {
            bin: 63,
            amplitude: 1e12
        }
    ])
    .is_none());

    let (mut ex, mut det) = ([good; 8], [0usize; 8]);
    assert_eq!(
        odd_random_phase_lines(1, 31, 1, 1.0, 0, &mut ex, &mut det).err(),
        Some(Error::InvalidGroupSize)
    );
    assert_eq!(
        odd_random_phase_lines(0, 31, 4, 1.0, 0, &mut ex, &mut det).err(),
        Some(Error::InvalidLine { index: 0 })
    );
    assert_eq!(
        odd_random_phase_lines(9, 3, 4, 1.0, 0, &mut ex, &mut det).err(),
        Some(Error::InvalidLine { index: 0 })
    );
    assert_eq!(
        odd_random_phase_lines(4, 4, 4, 1.0, 0, &mut ex, &mut det).err(),
        Some(Error::InvalidLine { index: 0 })
    );
    assert_eq!(
        odd_random_phase_lines(1, 31, 4, f32::NAN, 0, &mut ex, &mut det).err(),
        Some(Error::InvalidLine { index: 0 })
    );
    // 16 odd lines, G = 4: 12 excited, 4 detection; excited buffer of 8 is too small.
    assert_eq!(
        odd_random_phase_lines(1, 31, 4, 1.0, 0, &mut ex, &mut det).err(),
        Some(Error::BufferTooSmall { needed: 12 })
    );
    let mut ex16 = [good; 16];
    assert_eq!(
        odd_random_phase_lines(1, 31, 4, 1.0, 0, &mut ex16, &mut det[..3]).err(),
        Some(Error::BufferTooSmall { needed: 4 })
    );
    assert_eq!(
        odd_random_phase_lines(1, 31, 4, 1.0, 0, &mut ex16, &mut det).unwrap(),
        OddLineCounts {
            excited: 12,
            detection: 4
        }
    );
    // A single trailing odd line stays excited: 1..=9 has 5 odd lines, G = 4 ⇒ 1 detection.
    assert_eq!(
        odd_random_phase_lines(1, 9, 4, 1.0, 0, &mut ex16, &mut det).unwrap(),
        OddLineCounts {
            excited: 4,
            detection: 1
        }
    );
}
