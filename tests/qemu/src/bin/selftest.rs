//! On-target self-test of `ferrosid-firmware` on the emulated Cortex-M4F.
//!
//! Each check compares the firmware's `f32` results with references computed independently on
//! the target (module `ferrosid_qemu::reference`: `f64` direct DFT, reference Welch estimate,
//! analytic responses of plants simulated in `f64`, counting arguments), and logs one defmt line
//! `CHECK <name> PASS|FAIL worst=<max error/tolerance>` (worst <= 1 passes). The image exits
//! through semihosting with 0 when every check passed, 1 otherwise; 101 after a panic.
//!
//! Command-line words (QEMU `-semihosting-config ...,arg=WORD`):
//! * `--inject-failure`: multiply one analytic reference (`welch_h1_periodic_exact`) by 1.01, so
//!   exactly that check must fail: shows that the harness can fail.
//! * `--panic`: panic after the first check (tests the panic path).
#![no_std]
#![no_main]
// `!(err <= tol)` is deliberate: a NaN error must fail, which `err > tol` would let through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use core::f64::consts::PI;

use cortex_m_rt::entry;
use ferrosid_firmware::excitation::{
    odd_random_phase_lines, Chirp, ChirpConfig, ChirpLaw, Line, Multisine, MultisineScratch,
    MultisineSpec, Phases, Prbs,
};
use ferrosid_firmware::{Error, Excitation, Welch, WelchConfig, Window};
use ferrosid_qemu::reference::{
    cabs, cdiv, welch_reference, wrap_pi, Dft, FirstOrderLag, RefSpectra, RefWindow,
    SecondOrderMode, UniformNoise,
};
use ferrosid_qemu::{exit, EXIT_FAILURE, EXIT_SUCCESS};

/// Sample rate of all Welch checks (Hz).
const FS: f32 = 1000.0;
/// Longest record any check needs (samples).
const REC: usize = 24 * 1024;

/// Outcome of one check: all conditions held, and the worst error/tolerance ratio seen.
struct Outcome {
    ok: bool,
    worst: f64,
}

impl Outcome {
    fn new() -> Self {
        Outcome {
            ok: true,
            worst: 0.0,
        }
    }

    /// Requires `err <= tol` (a NaN error fails).
    fn within(&mut self, err: f64, tol: f64) {
        let ratio = err / tol;
        if !(err <= tol) {
            self.ok = false;
        }
        if !(ratio <= self.worst) {
            self.worst = ratio;
        }
    }

    /// Requires a structural condition.
    fn require(&mut self, cond: bool) {
        if !cond {
            self.ok = false;
        }
    }
}

/// Tally of the checks run so far.
struct Report {
    run: u32,
    failed: u32,
}

impl Report {
    fn record(&mut self, name: &str, o: Outcome) {
        self.run += 1;
        if !o.ok {
            self.failed += 1;
        }
        defmt::println!(
            "CHECK {=str} {=str} worst={=f64}",
            name,
            if o.ok { "PASS" } else { "FAIL" },
            o.worst
        );
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    ferrosid_qemu::report_panic(info)
}

#[entry]
fn main() -> ! {
    let inject = ferrosid_qemu::has_arg("--inject-failure");
    let want_panic = ferrosid_qemu::has_arg("--panic");
    let mut report = Report { run: 0, failed: 0 };

    report.record("fpu_enabled", fpu_enabled());
    if want_panic {
        panic!("requested by --panic");
    }

    // Large state lives in statics (.bss), not on the stack.
    let (Some(w256), Some(w1024), Some(u), Some(y)) = (
        cortex_m::singleton!(: Option<Welch<256>> = None),
        cortex_m::singleton!(: Option<Welch<1024>> = None),
        cortex_m::singleton!(: [f32; REC] = [0.0; REC]),
        cortex_m::singleton!(: [f32; REC] = [0.0; REC]),
    ) else {
        defmt::println!("SELFTEST FAIL: statics already taken");
        exit(EXIT_FAILURE)
    };
    *w256 = Welch::new(Welch::<256>::default_config(FS)).ok();
    *w1024 = Welch::new(Welch::<1024>::default_config(FS)).ok();
    let (Some(w256), Some(w1024)) = (w256.as_mut(), w1024.as_mut()) else {
        defmt::println!("SELFTEST FAIL: Welch::new rejected scipy's default configuration");
        exit(EXIT_FAILURE)
    };

    report.record("prbs_period_and_balance", prbs_period_and_balance());
    report.record("prbs_flat_spectrum", prbs_flat_spectrum());
    report.record("prbs_rejects_bad_config", prbs_rejects_bad_config());
    report.record("chirp_linear_law", chirp_law(ChirpLaw::Linear));
    report.record("chirp_log_law", chirp_law(ChirpLaw::Logarithmic));
    report.record(
        "multisine_schroeder_spectrum",
        multisine_schroeder_spectrum(),
    );
    report.record(
        "multisine_crest_beats_schroeder",
        multisine_crest_beats_schroeder(),
    );
    report.record(
        "welch_matches_direct_dft",
        welch_matches_direct_dft(w256, u, y),
    );
    report.record(
        "welch_h1_first_order_lag",
        welch_h1_first_order_lag(w256, u, y),
    );
    report.record(
        "welch_h1_resonant_mode",
        welch_h1_resonant_mode(w1024, u, y),
    );
    report.record(
        "welch_h1_periodic_exact",
        welch_h1_periodic_exact(w256, inject),
    );
    report.record("coherence_statistics", coherence_statistics(w256, u, y));
    report.record("coherence_gate", coherence_gate(w256, u, y));
    report.record("nonfinite_quarantine", nonfinite_quarantine(w256, u, y));
    report.record("welch_bad_input", welch_bad_input(w256, u, y));

    let passed = report.run - report.failed;
    if report.failed == 0 {
        defmt::println!("SELFTEST PASS {=u32}/{=u32}", passed, report.run);
        exit(EXIT_SUCCESS)
    } else {
        defmt::println!("SELFTEST FAIL {=u32}/{=u32}", report.failed, report.run);
        exit(EXIT_FAILURE)
    }
}

/// CP10/CP11 full access in CPACR: cortex-m-rt enabled the FPU before `main`; and an `f32`
/// computation that needs it gives the IEEE result.
fn fpu_enabled() -> Outcome {
    let mut o = Outcome::new();
    let cpacr = unsafe { (*cortex_m::peripheral::SCB::PTR).cpacr.read() };
    o.require(cpacr & (0xF << 20) == (0xF << 20));
    // A VFP instruction with the FPU off would fault (and the image would never exit).
    let x = core::hint::black_box(3.0f32);
    o.require(core::hint::black_box(x * x / 9.0) == 1.0);
    o
}

/// Fills `x` with one period (or more) of an excitation.
fn fill(gen: &mut impl Excitation, x: &mut [f64]) {
    for v in x.iter_mut() {
        *v = gen.next_sample() as f64;
    }
}

/// PRBS of 10 bits: the sequence repeats after exactly 1023 chips and after no divisor of 1023
/// (3, 11, 31, 33, 93, 341); one period holds 512 `+a` and 511 `-a` chips; with `hold = 3`
/// each chip is repeated 3 times; 7 bits: periodic autocorrelation `P·a²` at lag 0 and `-a²`
/// at every other lag.
fn prbs_period_and_balance() -> Outcome {
    let mut o = Outcome::new();
    let a = 0.5f32;
    let Ok(mut g) = Prbs::new(10, 0x2A5, a, 1) else {
        o.require(false);
        return o;
    };
    const P: usize = 1023;
    let mut x = [0i8; 2 * P];
    for v in x.iter_mut() {
        let s = g.next_sample();
        *v = if s == a {
            1
        } else if s == -a {
            -1
        } else {
            0
        };
    }
    o.require(x.iter().all(|&v| v != 0));
    o.require((0..P).all(|i| x[i] == x[i + P]));
    for d in [3usize, 11, 31, 33, 93, 341] {
        o.require((0..P - d).any(|i| x[i] != x[i + d]));
    }
    let ones = x[..P].iter().filter(|&&v| v == 1).count();
    o.require(ones == 512 && P - ones == 511);
    o.require(g.period_chips() == P as u32);

    // hold = 3: same chips, each repeated.
    let (Ok(mut g1), Ok(mut g3)) = (Prbs::new(10, 0x2A5, a, 1), Prbs::new(10, 0x2A5, a, 3)) else {
        o.require(false);
        return o;
    };
    for _ in 0..300 {
        let c = g1.next_sample();
        for _ in 0..3 {
            o.require(g3.next_sample() == c);
        }
    }
    o.require(g3.period_samples() == 3 * P as u64);

    // Two-valued periodic autocorrelation (7 bits, P = 127).
    let Ok(mut g7) = Prbs::new(7, 1, 1.0, 1) else {
        o.require(false);
        return o;
    };
    let mut s = [0.0f64; 127];
    fill(&mut g7, &mut s);
    for lag in 0..127 {
        let r: f64 = (0..127).map(|i| s[i] * s[(i + lag) % 127]).sum();
        let want = if lag == 0 { 127.0 } else { -1.0 };
        o.within((r - want).abs(), 1e-9);
    }
    o
}

/// DFT of one PRBS period (7 bits, hold 1, amplitude a): `|X[k]|² = (P+1)·a²` for `k ≠ 0` and
/// `X[0] = a` (direct f64 DFT; tolerance 1e-9 relative: the samples are exactly `±a`).
fn prbs_flat_spectrum() -> Outcome {
    let mut o = Outcome::new();
    let a = 0.25;
    let Ok(mut g) = Prbs::new(7, 0x55, a as f32, 1) else {
        o.require(false);
        return o;
    };
    let mut x = [0.0f64; 127];
    fill(&mut g, &mut x);
    let dft = Dft::<127>::new(127);
    let x0 = dft.bin(&x, 0);
    o.within((x0.0 - a).abs() / a, 1e-9);
    for k in 1..127 {
        let p = {
            let c = dft.bin(&x, k);
            c.0 * c.0 + c.1 * c.1
        };
        let want = 128.0 * a * a;
        o.within((p - want).abs() / want, 1e-9);
    }
    o
}

/// Invalid PRBS configurations are errors, never a silently wrong sequence.
fn prbs_rejects_bad_config() -> Outcome {
    let mut o = Outcome::new();
    o.require(matches!(
        Prbs::new(4, 1, 1.0, 1),
        Err(Error::InvalidRegisterLength { bits: 4 })
    ));
    o.require(matches!(
        Prbs::new(32, 1, 1.0, 1),
        Err(Error::InvalidRegisterLength { bits: 32 })
    ));
    o.require(matches!(Prbs::new(8, 0, 1.0, 1), Err(Error::InvalidSeed)));
    o.require(matches!(Prbs::new(8, 256, 1.0, 1), Err(Error::InvalidSeed)));
    o.require(matches!(
        Prbs::new(8, 1, f32::NAN, 1),
        Err(Error::InvalidAmplitude)
    ));
    o.require(matches!(
        Prbs::new(8, 1, -1.0, 1),
        Err(Error::InvalidAmplitude)
    ));
    o.require(matches!(Prbs::new(8, 1, 1.0, 0), Err(Error::InvalidHold)));
    o.require(Prbs::new(31, 0x7FFF_FFFF, 1.0, 1).is_ok());
    o
}

/// Chirp samples against the closed-form phase of the documented law, in f64:
/// `φ[n] = 2π Σ_{m<n} f[m]/fs` with
/// * linear `f[m] = f0 + (f1-f0)·m/L`: `Σ = n·f0 + (f1-f0)·n(n-1)/(2L)`,
/// * log `f[m] = f0·r^m`, `r = (f1/f0)^(1/L)`: `Σ = f0·(r^n - 1)/(r - 1)`,
///
/// times the raised-cosine fades `w[n]`. Tolerances (relative to the amplitude A): linear
/// 2e-5 (generator sine error < 2.5e-7·A, exact 64-bit phase); log 3e-3 (the per-sample
/// frequency is rounded to `f32`/32 bits, relative error <= about 5e-7, integrated over the
/// ~470 cycles of this sweep: <= 2.4e-4 cycles = 1.5e-3 rad). Also: silent after `L` samples.
fn chirp_law(law: ChirpLaw) -> Outcome {
    let mut o = Outcome::new();
    let (fs, f0, f1, dur, fade, amp) = (1000.0f64, 5.0f64, 200.0f64, 4.0f64, 0.25f64, 0.8f64);
    let cfg = ChirpConfig {
        fs_hz: fs as f32,
        f0_hz: f0 as f32,
        f1_hz: f1 as f32,
        duration_s: dur as f32,
        fade_s: fade as f32,
        amplitude: amp as f32,
        law,
    };
    let Ok(mut c) = Chirp::new(cfg) else {
        o.require(false);
        return o;
    };
    let l = libm::round(dur * fs) as u32;
    let fl = libm::round(fade * fs) as u32;
    o.require(c.len_samples() == l && c.fade_samples() == fl);
    let tol = match law {
        ChirpLaw::Linear => 2e-5,
        ChirpLaw::Logarithmic => 3e-3,
    };
    let r = libm::pow(f1 / f0, 1.0 / l as f64);
    for n in 0..l {
        let nf = n as f64;
        let cycles = match law {
            ChirpLaw::Linear => (nf * f0 + (f1 - f0) * nf * (nf - 1.0) / (2.0 * l as f64)) / fs,
            ChirpLaw::Logarithmic => f0 * (libm::pow(r, nf) - 1.0) / (r - 1.0) / fs,
        };
        let frac = cycles - libm::floor(cycles);
        let w = if n < fl {
            0.5 - 0.5 * libm::cos(PI * nf / fl as f64)
        } else if n >= l - fl {
            0.5 - 0.5 * libm::cos(PI * (l - 1 - n) as f64 / fl as f64)
        } else {
            1.0
        };
        let want = amp * w * libm::sin(2.0 * PI * frac);
        let got = c.next_sample() as f64;
        o.within((got - want).abs() / amp, tol);
    }
    o.require(c.is_finished());
    for _ in 0..10 {
        o.require(c.next_sample() == 0.0);
    }
    o
}

/// Number of samples per multisine period in the checks.
const MS_N: usize = 256;

/// One period of `ms` in f64.
fn period(ms: &mut Multisine<MS_N>) -> [f64; MS_N] {
    let mut x = [0.0; MS_N];
    ms.reset();
    fill(ms, &mut x);
    x
}

/// Peak / RMS of `x`, computed here.
fn crest(x: &[f64]) -> f64 {
    let peak = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let rms = libm::sqrt(x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64);
    peak / rms
}

/// Checks the DFT of one period `x`: every line in `lines` at `A·N/2` (relative 1e-4), every
/// other bin in `1..N/2` below -100 dB of the smallest line (`|X| < 1e-5·A_min·N/2`).
fn check_line_spectrum(o: &mut Outcome, dft: &Dft<MS_N>, x: &[f64; MS_N], lines: &[Line]) {
    let a_min = lines
        .iter()
        .fold(f64::MAX, |m, l| m.min(l.amplitude as f64));
    for k in 1..MS_N / 2 {
        let mag = cabs(dft.bin(x, k));
        match lines.iter().find(|l| l.bin == k) {
            Some(l) => {
                let want = l.amplitude as f64 * MS_N as f64 / 2.0;
                o.within((mag - want).abs() / want, 1e-4);
            }
            None => o.within(mag / (a_min * MS_N as f64 / 2.0), 1e-5),
        }
    }
}

/// Schroeder multisine, bins 2..=40, equal amplitudes: lines at the right level, unexcited bins
/// below -100 dB, phases `φ_m = -π m(m-1)/F` (m = 1..F, tolerance 1e-3 rad), and
/// `crest_factor()` equal to peak/RMS of the samples (relative 1e-5).
fn multisine_schroeder_spectrum() -> Outcome {
    let mut o = Outcome::new();
    let mut lines = [Line {
        bin: 0,
        amplitude: 0.1,
    }; 39];
    for (i, l) in lines.iter_mut().enumerate() {
        l.bin = 2 + i;
    }
    let spec = MultisineSpec {
        lines: &lines,
        phases: Phases::Schroeder,
        crest_iterations: 0,
    };
    let mut scratch = MultisineScratch::<MS_N>::new();
    let Ok(mut ms) = Multisine::<MS_N>::design(&spec, &mut scratch) else {
        o.require(false);
        return o;
    };
    let x = period(&mut ms);
    let dft = Dft::<MS_N>::new(MS_N);
    check_line_spectrum(&mut o, &dft, &x, &lines);
    let f = lines.len() as f64;
    for (i, l) in lines.iter().enumerate() {
        let m = (i + 1) as f64;
        let c = dft.bin(&x, l.bin);
        let phase = libm::atan2(c.1, c.0);
        o.within(wrap_pi(phase + PI * m * (m - 1.0) / f).abs(), 1e-3);
    }
    o.within(
        (ms.crest_factor() as f64 - crest(&x)).abs() / crest(&x),
        1e-5,
    );
    o
}

/// Odd random-phase line set (bins 1..=101, groups of 4 odd lines with one detection line):
/// the crest-factor-optimised design (random phases + 200 swapping iterations) beats the
/// Schroeder design on the same lines, and both keep the exact amplitude spectrum (lines at
/// `A·N/2` to 1e-4, detection and even bins below -100 dB).
fn multisine_crest_beats_schroeder() -> Outcome {
    let mut o = Outcome::new();
    let mut excited = [Line {
        bin: 0,
        amplitude: 0.0,
    }; 64];
    let mut detection = [0usize; 32];
    let Ok(counts) = odd_random_phase_lines(1, 101, 4, 0.05, 7, &mut excited, &mut detection)
    else {
        o.require(false);
        return o;
    };
    // 51 odd bins: 12 full groups + a trailing group of 3 => 13 detection lines.
    o.require(counts.excited == 38 && counts.detection == 13);
    let lines = &excited[..counts.excited];
    o.require(lines.iter().all(|l| l.bin % 2 == 1));
    o.require(
        !detection[..counts.detection]
            .iter()
            .any(|d| lines.iter().any(|l| l.bin == *d)),
    );
    let mut scratch = MultisineScratch::<MS_N>::new();
    let schroeder = Multisine::<MS_N>::design(
        &MultisineSpec {
            lines,
            phases: Phases::Schroeder,
            crest_iterations: 0,
        },
        &mut scratch,
    );
    let optimised = Multisine::<MS_N>::design(
        &MultisineSpec {
            lines,
            phases: Phases::Random { seed: 11 },
            crest_iterations: 200,
        },
        &mut scratch,
    );
    let (Ok(mut s), Ok(mut opt)) = (schroeder, optimised) else {
        o.require(false);
        return o;
    };
    let dft = Dft::<MS_N>::new(MS_N);
    let xs = period(&mut s);
    let xo = period(&mut opt);
    check_line_spectrum(&mut o, &dft, &xs, lines);
    check_line_spectrum(&mut o, &dft, &xo, lines);
    let (cs, co) = (crest(&xs), crest(&xo));
    defmt::info!(
        "multisine crest factor: Schroeder {=f64}, optimised {=f64}",
        cs,
        co
    );
    o.require(co < cs);
    o.within((opt.crest_factor() as f64 - co).abs() / co, 1e-5);
    o
}

/// Fills `u` with `0.5 + uniform` white noise and `y` with a first-order lag of it plus 0.1
/// uniform noise (seeded).
fn noisy_lag_record(u: &mut [f32], y: &mut [f32], seed: u32) {
    let mut rng = UniformNoise::new(seed);
    let mut plant = FirstOrderLag::new(0.8);
    for (ui, yi) in u.iter_mut().zip(y.iter_mut()) {
        let x = 0.5 + rng.uniform();
        *ui = x as f32;
        *yi = (plant.step(x) + 0.1 * rng.uniform()) as f32;
    }
}

/// Compares the firmware's spectra with the f64 reference: `S_uu`, `S_yy` relative 1e-4 in bins
/// above 1e-4 of their maximum (absolute 1e-8·max below: f32 FFT rounding); `S_uy`, `H1` and
/// coherence (absolute 1e-4) in bins with reference coherence > 0.5, as the issue demands.
fn compare_spectra<const N: usize, const B: usize>(
    o: &mut Outcome,
    w: &Welch<N>,
    r: &RefSpectra<B>,
) {
    o.require(w.bins() == B && w.averages() == r.segments && w.dropped_segments() == r.skipped);
    let max_uu = r.uu.iter().fold(0.0f64, |m, &v| m.max(v));
    let max_yy = r.yy.iter().fold(0.0f64, |m, &v| m.max(v));
    for k in 0..B {
        for (got, want, max) in [(w.suu(k), r.uu[k], max_uu), (w.syy(k), r.yy[k], max_yy)] {
            let got = got as f64;
            if want > 1e-4 * max {
                o.within((got - want).abs() / want, 1e-4);
            } else {
                o.within((got - want).abs() / max, 1e-8);
            }
        }
        if r.coherence(k) > 0.5 {
            let (re, im) = w.suy(k);
            let d = cabs((re as f64 - r.uy[k].0, im as f64 - r.uy[k].1));
            o.within(d / cabs(r.uy[k]), 1e-4);
            let h_ref = cdiv(r.uy[k], (r.uu[k], 0.0));
            match w.h1(k) {
                Some((hr, hi)) => {
                    let d = cabs((hr as f64 - h_ref.0, hi as f64 - h_ref.1));
                    o.within(d / cabs(h_ref), 1e-4);
                }
                None => o.require(false),
            }
            o.within((w.coherence(k) as f64 - r.coherence(k)).abs(), 1e-4);
        }
    }
}

/// Welch<256> (Hann, 50 % overlap, mean removal, fs = 1 kHz) over 8 segments of a record with a
/// DC offset against the f64 reference estimate from direct DFTs (see [`compare_spectra`]);
/// also the bin frequencies `k·fs/N`.
fn welch_matches_direct_dft(w: &mut Welch<256>, u: &mut [f32], y: &mut [f32]) -> Outcome {
    let mut o = Outcome::new();
    let len = 256 + 7 * 128;
    noisy_lag_record(&mut u[..len], &mut y[..len], 0x1234_5678);
    o.require(w.configure(WelchConfig::scipy_default(FS, 256)).is_ok());
    o.require(w.push_slice(&u[..len], &y[..len]).is_ok());
    let dft = Dft::<256>::new(256);
    let r: RefSpectra<129> = welch_reference(
        &dft,
        &u[..len],
        &y[..len],
        128,
        RefWindow::Hann,
        true,
        FS as f64,
    );
    o.require(r.segments == 8);
    compare_spectra(&mut o, w, &r);
    for k in [0usize, 1, 64, 128] {
        o.within((w.bin_hz(k) as f64 - k as f64 * 1000.0 / 256.0).abs(), 1e-4);
    }
    o
}

/// Fills `u` with white uniform noise and `y` with `plant(u)`.
fn plant_record(u: &mut [f32], y: &mut [f32], seed: u32, mut plant: impl FnMut(f64) -> f64) {
    let mut rng = UniformNoise::new(seed);
    for (ui, yi) in u.iter_mut().zip(y.iter_mut()) {
        let x = rng.uniform();
        *ui = x as f32;
        *yi = plant(x) as f32;
    }
}

/// H1 of Welch<N> against an analytic response `h(ω)` (ω in rad/sample) over bins `2..N/2`
/// whose coherence exceeds 0.9 (bin 1 is excluded: with a Hann window, removing the segment mean
/// also removes part of bin 1, a known bias of `detrend='constant'`). Per bin, the complex error
/// relative to |H| must stay within `bias + 5·σ_k`, where `σ_k = √(1-γ²)/(|γ|·√(2·n_d))` is the
/// normalised random error of |H1| (Bendat & Piersol, Random Data, 4th ed., Table 9.6) with
/// `n_d = averages/1.06` (50 % overlapped Hann) and `bias` the resolution-bias bound of the
/// plant; and the median error over those bins must be below 0.5 %. Returns the bins used.
fn check_h1<const N: usize>(
    o: &mut Outcome,
    w: &Welch<N>,
    h: impl Fn(f64) -> (f64, f64),
    bias: f64,
) -> usize {
    let nd = w.averages() as f64 / 1.06;
    let mut errs = [0.0f64; 2048];
    let mut used = 0;
    for k in 2..N / 2 {
        let g2 = w.coherence(k) as f64;
        if g2 <= 0.9 {
            continue;
        }
        let want = h(2.0 * PI * k as f64 / N as f64);
        let sigma = libm::sqrt(1.0 - g2) / (libm::sqrt(g2) * libm::sqrt(2.0 * nd));
        match w.h1(k) {
            Some((re, im)) => {
                let e = cabs((re as f64 - want.0, im as f64 - want.1)) / cabs(want);
                o.within(e, bias + 5.0 * sigma);
                if let Some(slot) = errs.get_mut(used) {
                    *slot = e;
                    used += 1;
                }
            }
            None => o.require(false),
        }
    }
    let errs = &mut errs[..used];
    errs.sort_unstable_by(|a, b| a.total_cmp(b));
    let median = errs.get(used / 2).copied().unwrap_or(f64::NAN);
    defmt::info!(
        "H1 vs analytic: {=usize} bins, median error {=f64}",
        used,
        median
    );
    o.within(median, 0.005);
    used
}

/// First-order lag `a = 0.9` (corner fs/60 ≈ 16.8 Hz) driven by white noise, noise-free output,
/// Welch<256> scipy defaults, 64 averages: H1 against the analytic response per [`check_h1`]
/// with resolution bias 0.5 % (smooth response); at least 120 of the 126 bins are used.
/// (The residual error is leakage: the response to input before each segment.)
fn welch_h1_first_order_lag(w: &mut Welch<256>, u: &mut [f32], y: &mut [f32]) -> Outcome {
    let mut o = Outcome::new();
    let len = 256 + 63 * 128;
    let mut plant = FirstOrderLag::new(0.9);
    plant_record(&mut u[..len], &mut y[..len], 99, |x| plant.step(x));
    o.require(w.configure(WelchConfig::scipy_default(FS, 256)).is_ok());
    o.require(w.push_slice(&u[..len], &y[..len]).is_ok());
    o.require(w.averages() == 64);
    let reference = FirstOrderLag::new(0.9);
    let used = check_h1(&mut o, w, |om| reference.response(om), 0.005);
    o.require(used >= 120);
    o
}

/// Lightly damped mode (poles 0.985·e^{±j2π·0.05}: f_n ≈ 50 Hz at fs = 1 kHz, ζ ≈ 0.048),
/// white-noise input, Welch<1024> scipy defaults, 46 averages: H1 against the analytic
/// response per [`check_h1`] with the resolution bias bound `(B_e/B_r)²/3` (Bendat & Piersol
/// Sec. 8.5.1; B_e = 1.5·fs/N = 1.46 Hz for Hann, B_r = 2ζf_n ≈ 4.8 Hz: 3.1 %) plus 0.5 %;
/// the largest |H1| in the bin of the analytic peak, and the phase crossing -90° there.
fn welch_h1_resonant_mode(w: &mut Welch<1024>, u: &mut [f32], y: &mut [f32]) -> Outcome {
    let mut o = Outcome::new();
    let len = 1024 + 45 * 512;
    let theta = 2.0 * PI * 0.05;
    let mut plant = SecondOrderMode::new(0.985, theta);
    plant_record(&mut u[..len], &mut y[..len], 4242, |x| plant.step(x));
    o.require(w.configure(WelchConfig::scipy_default(FS, 1024)).is_ok());
    o.require(w.push_slice(&u[..len], &y[..len]).is_ok());
    o.require(w.averages() == 46);
    let reference = SecondOrderMode::new(0.985, theta);
    let zeta = -libm::log(0.985) / theta;
    let b_e = 1.5 * FS as f64 / 1024.0;
    let b_r = 2.0 * zeta * 50.0;
    let bias = (b_e / b_r) * (b_e / b_r) / 3.0 + 0.005;
    let used = check_h1(&mut o, w, |om| reference.response(om), bias);
    o.require(used >= 480);
    let mag = |k: usize| w.h1(k).map(|(re, im)| re * re + im * im).unwrap_or(0.0);
    let k_peak = (1..512).fold(1, |b, k| if mag(k) > mag(b) { k } else { b });
    let k_ref = (1..512).fold(1, |b, k| {
        let h = |k: usize| cabs(reference.response(2.0 * PI * k as f64 / 1024.0));
        if h(k) > h(b) {
            k
        } else {
            b
        }
    });
    o.require(k_peak == k_ref);
    // Phase of H: above -90° below the peak, below it above the peak.
    let phase = |k: usize| {
        w.h1(k)
            .map(|(re, im)| libm::atan2(im as f64, re as f64))
            .unwrap_or(0.0)
    };
    o.require(phase(k_ref - 3) > -PI / 2.0 && phase(k_ref + 3) < -PI / 2.0);
    o
}

/// Period-synchronous averaging: Schroeder multisine (period 256, bins 1..=60) through the
/// first-order lag `a = 0.9` in steady state (20 periods discarded), Welch<256> with a
/// rectangular window and no overlap over 8 periods. No leakage and no noise, so H1 at the
/// excited bins equals the analytic response to 1e-4 (relative complex error) and the
/// coherence is 1 to 1e-4. `--inject-failure` multiplies the reference by 1.01.
fn welch_h1_periodic_exact(w: &mut Welch<256>, inject: bool) -> Outcome {
    let mut o = Outcome::new();
    let mut lines = [Line {
        bin: 0,
        amplitude: 0.2,
    }; 60];
    for (i, l) in lines.iter_mut().enumerate() {
        l.bin = 1 + i;
    }
    let spec = MultisineSpec {
        lines: &lines,
        phases: Phases::Schroeder,
        crest_iterations: 0,
    };
    let mut scratch = MultisineScratch::<256>::new();
    let Ok(mut ms) = Multisine::<256>::design(&spec, &mut scratch) else {
        o.require(false);
        return o;
    };
    let cfg = WelchConfig {
        fs_hz: FS,
        overlap: 0,
        window: Window::Rectangular,
        detrend_mean: true,
    };
    o.require(w.configure(cfg).is_ok());
    let mut plant = FirstOrderLag::new(0.9);
    for _ in 0..20 * 256 {
        plant.step(ms.next_sample() as f64);
    }
    for _ in 0..8 * 256 {
        let x = ms.next_sample();
        let yv = plant.step(x as f64);
        w.push(x, yv as f32);
    }
    // The last segment ended with the last push; its work is spread over the next hop's
    // pushes, so it counts only after those or after flush().
    o.require(w.averages() == 7 && w.segment_in_work());
    w.flush();
    o.require(w.averages() == 8 && !w.segment_in_work());
    let scale = if inject { 1.01 } else { 1.0 };
    for l in &lines {
        let h = plant.response(2.0 * PI * l.bin as f64 / 256.0);
        let want = (h.0 * scale, h.1 * scale);
        match w.h1(l.bin) {
            Some((re, im)) => {
                let d = cabs((re as f64 - want.0, im as f64 - want.1));
                o.within(d / cabs(want), 1e-4);
            }
            None => o.require(false),
        }
        o.within(1.0 - w.coherence(l.bin) as f64, 1e-4);
    }
    o
}

/// Coherence behaviour with known truth, Welch<256> scipy defaults:
/// * one average: exactly 1 (to 1e-5) in every bin 1..N/2, whatever the signals (the bias);
/// * independent white `u`, `y`, 64 averages (n_d ≈ 64/1.06): mean over bins 1..N/2 of γ̂² is
///   near E = 1/n_d ≈ 0.0166; accepted in [0.5/n_d, 2/n_d] (±4 standard errors);
/// * `y = u + e`, `e` independent with the variance of `u`: true γ² = 0.5 in every bin; mean of
///   γ̂² over bins within 0.05 of 0.5 + (1-γ²)²/n_d.
fn coherence_statistics(w: &mut Welch<256>, u: &mut [f32], y: &mut [f32]) -> Outcome {
    let mut o = Outcome::new();
    let len = 256 + 63 * 128;
    let mut rng = UniformNoise::new(31337);
    for (ui, yi) in u[..len].iter_mut().zip(y[..len].iter_mut()) {
        *ui = rng.uniform() as f32;
        *yi = rng.uniform() as f32;
    }
    o.require(w.configure(WelchConfig::scipy_default(FS, 256)).is_ok());
    o.require(w.push_slice(&u[..256], &y[..256]).is_ok());
    o.require(w.averages() == 1);
    for k in 1..128 {
        o.within((1.0 - w.coherence(k) as f64).abs(), 1e-5);
    }
    o.require(w.push_slice(&u[256..len], &y[256..len]).is_ok());
    o.require(w.averages() == 64);
    let nd = 64.0 / 1.06;
    let mean = (1..128).map(|k| w.coherence(k) as f64).sum::<f64>() / 127.0;
    defmt::info!(
        "independent signals: mean coherence {=f64}, 1/n_d = {=f64}",
        mean,
        1.0 / nd
    );
    o.require(mean >= 0.5 / nd && mean <= 2.0 / nd);

    w.reset();
    for i in 0..len {
        y[i] += u[i];
    }
    o.require(w.push_slice(&u[..len], &y[..len]).is_ok());
    let mean = (1..128).map(|k| w.coherence(k) as f64).sum::<f64>() / 127.0;
    defmt::info!("SNR 0 dB: mean coherence {=f64} (true 0.5)", mean);
    o.within((mean - (0.5 + 0.25 / nd)).abs(), 0.05);
    o
}

/// `gate(t)` passes exactly the bins with coherence >= t (direct loop), covers N/2+1 bins, and
/// passes nothing for a NaN threshold; on the SNR 0 dB-in-band record of a lag it splits bins.
fn coherence_gate(w: &mut Welch<256>, u: &mut [f32], y: &mut [f32]) -> Outcome {
    let mut o = Outcome::new();
    let len = 256 + 31 * 128;
    noisy_lag_record(&mut u[..len], &mut y[..len], 555);
    o.require(w.configure(WelchConfig::scipy_default(FS, 256)).is_ok());
    o.require(w.push_slice(&u[..len], &y[..len]).is_ok());
    for t in [0.3f32, 0.5, 0.9] {
        let g = w.gate(t);
        o.require(g.bins() == 129);
        let mut n = 0;
        for k in 0..129 {
            let pass = w.coherence(k) >= t;
            n += pass as usize;
            o.require(g.passes(k) == pass);
        }
        o.require(g.count() == n);
        if t == 0.9 {
            // Low-pass plant + white output noise: coherence high at low and low at high
            // frequencies, so the gate must split the band.
            o.require(n > 5 && n < 124);
        }
    }
    o.require(w.gate(f32::NAN).count() == 0);
    o
}

/// NaN in `u` at sample 600, +inf in `y` at 1000, 1e13 in `u` at 100: all three counted, the
/// segments containing them (2 + 2 + 1 of the 8 segments of Hann/50 % with N = 256) dropped,
/// the rest accumulated exactly as the f64 reference that skips those segments, and every
/// output finite.
fn nonfinite_quarantine(w: &mut Welch<256>, u: &mut [f32], y: &mut [f32]) -> Outcome {
    let mut o = Outcome::new();
    let len = 256 + 7 * 128;
    noisy_lag_record(&mut u[..len], &mut y[..len], 0xBAD);
    u[600] = f32::NAN;
    y[1000] = f32::INFINITY;
    u[100] = 1.0e13;
    o.require(w.configure(WelchConfig::scipy_default(FS, 256)).is_ok());
    o.require(w.push_slice(&u[..len], &y[..len]).is_ok());
    o.require(w.nonfinite_samples() == 3);
    // Segment s covers [128 s, 128 s + 256): 100 -> s=0; 600 -> s=3,4; 1000 -> s=6,7.
    o.require(w.dropped_segments() == 5 && w.averages() == 3);
    let dft = Dft::<256>::new(256);
    let r: RefSpectra<129> = welch_reference(
        &dft,
        &u[..len],
        &y[..len],
        128,
        RefWindow::Hann,
        true,
        FS as f64,
    );
    o.require(r.segments == 3 && r.skipped == 5);
    compare_spectra(&mut o, w, &r);
    for k in 0..129 {
        let (re, im) = w.suy(k);
        o.require(w.suu(k).is_finite() && w.syy(k).is_finite() && re.is_finite());
        o.require(im.is_finite() && w.coherence(k).is_finite());
    }
    o
}

/// Bad input to the estimator: mismatched slice lengths are an error that consumes nothing;
/// invalid configurations are errors that leave the estimator unchanged; `push_slice` and
/// sample-wise `push` (then `flush`) give bit-identical estimates.
fn welch_bad_input(w: &mut Welch<256>, u: &mut [f32], y: &mut [f32]) -> Outcome {
    let mut o = Outcome::new();
    let len = 256 + 3 * 128;
    noisy_lag_record(&mut u[..len], &mut y[..len], 77);
    o.require(w.configure(WelchConfig::scipy_default(FS, 256)).is_ok());
    o.require(matches!(
        w.push_slice(&u[..10], &y[..9]),
        Err(Error::LengthMismatch { u: 10, y: 9 })
    ));
    o.require(w.push_slice(&u[..len], &y[..len]).is_ok());
    o.require(w.averages() == 4 && w.nonfinite_samples() == 0);
    let snapshot: [f32; 129] = core::array::from_fn(|k| w.suu(k));
    let bad = [
        WelchConfig {
            overlap: 256,
            ..WelchConfig::scipy_default(FS, 256)
        },
        WelchConfig::scipy_default(f32::NAN, 256),
        WelchConfig::scipy_default(0.0, 256),
        WelchConfig::scipy_default(-1.0, 256),
    ];
    o.require(matches!(w.configure(bad[0]), Err(Error::InvalidOverlap)));
    for cfg in &bad[1..] {
        o.require(matches!(w.configure(*cfg), Err(Error::InvalidSampleRate)));
    }
    o.require(w.averages() == 4);
    o.require((0..129).all(|k| w.suu(k).to_bits() == snapshot[k].to_bits()));
    w.reset();
    for i in 0..len {
        w.push(u[i], y[i]);
    }
    // The last segment ended with the last push; flush() completes its spread work.
    w.flush();
    o.require((0..129).all(|k| w.suu(k).to_bits() == snapshot[k].to_bits()));
    o
}
