//! Panic-path probe: calls the firmware's public API with inputs the compiler cannot see
//! (`core::hint::black_box`), so that every check the firmware's code would need at run time is
//! compiled in. The host test `firmware_api_has_no_panic_path` disassembles this image and
//! requires that no firmware function calls a panic entry point ("no panic reachable from any
//! input"). The values themselves are valid, and the image exits 0 after one pass.
#![no_std]
#![no_main]

use core::hint::black_box;

use cortex_m_rt::entry;
use ferrosid_firmware::excitation::{
    odd_random_phase_lines, Chirp, ChirpConfig, ChirpLaw, Line, Multisine, MultisineScratch,
    MultisineSpec, Phases, Prbs,
};
use ferrosid_firmware::{Excitation, Welch, WelchConfig, Window};
use ferrosid_qemu::{exit, EXIT_SUCCESS};

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    ferrosid_qemu::report_panic(info)
}

/// Period of the multisine table played from flash.
static TABLE: [f32; 64] = {
    let mut t = [0.0f32; 64];
    t[1] = 1.0;
    t[33] = -1.0;
    t
};

#[entry]
fn main() -> ! {
    let mut acc = 0.0f32;

    if let Ok(mut p) = Prbs::new(black_box(9), black_box(3), black_box(0.5), black_box(2)) {
        for _ in 0..black_box(100) {
            acc += p.next_sample();
        }
        acc += p.next_chip() as f32 + p.period_samples() as f32;
        p.reset();
    }

    for law in [ChirpLaw::Linear, ChirpLaw::Logarithmic] {
        let cfg = ChirpConfig {
            fs_hz: black_box(1000.0),
            f0_hz: black_box(2.0),
            f1_hz: black_box(300.0),
            duration_s: black_box(0.5),
            fade_s: black_box(0.05),
            amplitude: black_box(1.0),
            law: black_box(law),
        };
        if let Ok(mut c) = Chirp::new(cfg) {
            for _ in 0..black_box(600) {
                acc += c.next_sample();
            }
            acc += c.instantaneous_frequency_hz(black_box(17));
            c.restart();
        }
    }

    let mut excited = [Line {
        bin: 0,
        amplitude: 0.0,
    }; 32];
    let mut detection = [0usize; 16];
    let lines = match odd_random_phase_lines(
        black_box(1),
        black_box(50),
        black_box(4),
        black_box(0.1),
        black_box(5),
        &mut excited,
        &mut detection,
    ) {
        Ok(counts) => counts.excited.min(excited.len()),
        Err(_) => 0,
    };
    let mut scratch = MultisineScratch::<128>::new();
    let spec = MultisineSpec {
        lines: &excited[..lines],
        phases: black_box(Phases::Random { seed: 9 }),
        crest_iterations: black_box(5),
    };
    if let Ok(mut m) = Multisine::<128>::design(&spec, &mut scratch) {
        for _ in 0..black_box(200) {
            acc += m.next_sample();
        }
        acc += m.crest_factor() + m.peak() + m.rms();
    }
    if let Ok(mut m) = Multisine::<64, &'static [f32; 64]>::from_table(black_box(&TABLE)) {
        acc += m.next_sample() + m.crest_factor();
    }

    if let Some(slot) = cortex_m::singleton!(: Option<Welch<128>> = None) {
        *slot = Welch::new(WelchConfig {
            fs_hz: black_box(100.0),
            overlap: black_box(64),
            window: black_box(Window::Hann),
            detrend_mean: black_box(true),
        })
        .ok();
        if let Some(w) = slot.as_mut() {
            let u = black_box([0.5f32; 40]);
            let y = black_box([0.25f32; 40]);
            for i in 0..black_box(300) {
                w.push(black_box(i as f32), black_box(0.5 * i as f32));
            }
            acc += w.segment_in_work() as u32 as f32;
            w.flush();
            let n = black_box(40usize).min(y.len());
            let _ = w.push_slice(&u, &y[..n]);
            let k = black_box(7);
            acc += w.suu(k) + w.syy(k) + w.suy(k).0 + w.coherence(k) + w.bin_hz(k);
            acc += w.h1(k).map_or(0.0, |h| h.0);
            let gate = w.gate(black_box(0.5));
            acc += gate.count() as f32 + gate.passes(k) as u32 as f32;
            acc += gate.iter().count() as f32;
            acc += (w.averages() + w.dropped_segments() + w.nonfinite_samples()) as f32;
            let _ = w.configure(WelchConfig::scipy_default(black_box(50.0), 128));
            w.reset();
        }
    }

    black_box(acc);
    defmt::println!("NOPANIC done");
    exit(EXIT_SUCCESS)
}
