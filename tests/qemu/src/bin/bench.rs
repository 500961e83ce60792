//! Instruction counts of the firmware's per-sample work on the emulated Cortex-M4F.
//!
//! Run under `qemu-system-arm ... -icount shift=0` (see `scripts/bench-firmware.sh`): SysTick
//! deltas are then exact instruction counts up to a constant number of instructions per tick,
//! which is measured first on a loop of known length (`calibration_instr_per_tick`).
//!
//! Each figure is `(ticks(loop with the work) - ticks(same loop without it)) · instr/tick /
//! samples`, so loop, array reads and counter reads cancel. Output: one defmt line per figure,
//! `BENCH <name> <value> <unit>`. Exit code 0, or 1 when the counter does not advance as an
//! instruction counter (not run with `-icount`).
#![no_std]
#![no_main]

use core::hint::black_box;

use cortex_m_rt::entry;
use ferrosid_firmware::control::{
    AntiWindup, BacklashInverse, Biquad, CompensationConfig, ControlConfig, ControlLaw,
    ControlState, DeadZoneInverse, FrictionFeedforward, PidConfig, VelocitySource,
};
use ferrosid_firmware::excitation::{
    Chirp, ChirpConfig, ChirpLaw, Line, Multisine, MultisineScratch, MultisineSpec, Phases, Prbs,
};
use ferrosid_firmware::{Excitation, Welch, WelchConfig, Window};
use ferrosid_qemu::reference::UniformNoise;
use ferrosid_qemu::{exit, InstructionCounter, EXIT_FAILURE, EXIT_SUCCESS};

/// Input record replayed cyclically (power of two).
const REC: usize = 4096;
/// Samples per measured run.
const SAMPLES: usize = 64 * 1024;
/// Samples between two counter laps (keeps every delta far below the 24-bit wrap).
const BLOCK: usize = 256;
/// Sample rate for the configurations (Hz); irrelevant to the counts.
const FS: f32 = 1000.0;

/// Ticks of `SAMPLES` iterations of `body(i)` with `i` the sample index.
fn run(ic: &mut InstructionCounter, mut body: impl FnMut(usize)) -> u64 {
    ic.reset();
    let mut i = 0;
    while i < SAMPLES {
        for j in i..i + BLOCK {
            body(j);
        }
        ic.lap();
        i += BLOCK;
    }
    ic.lap()
}

/// Largest number of ticks of a single `body(i)` over `SAMPLES` iterations, and the largest of
/// an empty body measured the same way (the counter reads), to be subtracted.
fn max_ticks(ic: &mut InstructionCounter, mut body: impl FnMut(usize)) -> (u32, u32) {
    let (mut worst, mut empty) = (0, 0);
    for i in 0..SAMPLES {
        worst = worst.max(ic.ticks_of(|| body(i)));
        empty = empty.max(ic.ticks_of(|| black_box(())));
    }
    (worst, empty)
}

fn report(name: &str, ticks: u64, base: u64, ipt: f64, per: usize, unit: &str) -> f64 {
    let v = (ticks as f64 - base as f64) * ipt / per as f64;
    defmt::println!("BENCH {=str} {=f64} {=str}", name, v, unit);
    v
}

/// Prints a largest single-call figure: `(worst - empty)` ticks, in instructions. A tick is
/// `ipt` (40) instructions, so the figure is exact to one tick.
fn report_max(name: &str, worst: u32, empty: u32, ipt: f64) {
    let v = f64::from(worst.saturating_sub(empty)) * ipt;
    defmt::println!("BENCH {=str} {=f64} instr/push", name, v);
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    ferrosid_qemu::report_panic(info)
}

#[entry]
fn main() -> ! {
    let Some(p) = cortex_m::Peripherals::take() else {
        exit(EXIT_FAILURE)
    };
    let mut ic = InstructionCounter::new(p.SYST);

    // Instructions per tick from two loop lengths (fixed call overhead cancels).
    let (i1, t1) = ic.calibrate(1_000_000);
    let (i2, t2) = ic.calibrate(3_000_000);
    if t2 <= t1 {
        defmt::println!("BENCH error: SysTick does not advance; run under qemu -icount shift=0");
        exit(EXIT_FAILURE)
    }
    let ipt = (i2 - i1) as f64 / (t2 - t1) as f64;
    defmt::println!("BENCH calibration_instr_per_tick {=f64} instr/tick", ipt);
    // Repeatability: the same loop twice gives the same count, up to the one-tick phase of
    // the tick boundary (a tick is `ipt` instructions).
    // Three repetitions, so that wall-clock jitter (no -icount) cannot pass by chance.
    let repeatable = (0..3).all(|_| ic.calibrate(3_000_000).1.abs_diff(t2) <= 1);
    if !repeatable {
        defmt::println!("BENCH error: counts not deterministic; run under qemu -icount shift=0");
        exit(EXIT_FAILURE)
    }

    let (Some(u), Some(y)) = (
        cortex_m::singleton!(: [f32; REC] = [0.0; REC]),
        cortex_m::singleton!(: [f32; REC] = [0.0; REC]),
    ) else {
        exit(EXIT_FAILURE)
    };
    let mut rng = UniformNoise::new(2024);
    let mut lag = 0.0f32;
    for (ui, yi) in u.iter_mut().zip(y.iter_mut()) {
        *ui = rng.uniform() as f32;
        lag = 0.9 * lag + 0.1 * *ui;
        *yi = lag;
    }
    let (u, y) = (&*u, &*y);

    let base = run(&mut ic, |i| {
        black_box(u[i & (REC - 1)]);
        black_box(y[i & (REC - 1)]);
    });

    // Welch::push, scipy defaults (Hann, 50 % overlap, mean removal).
    let Some(w256) = cortex_m::singleton!(: Option<Welch<256>> = Welch::new(Welch::<256>::default_config(FS)).ok())
    else {
        exit(EXIT_FAILURE)
    };
    let Some(w256) = w256.as_mut() else {
        exit(EXIT_FAILURE)
    };
    let t = run(&mut ic, |i| w256.push(u[i & (REC - 1)], y[i & (REC - 1)]));
    black_box(w256.suu(3));
    report("welch_push_n256", t, base, ipt, SAMPLES, "instr/sample");
    // Largest single push (every push measured alone, segment ends included).
    w256.reset();
    let (worst, empty) = max_ticks(&mut ic, |i| w256.push(u[i & (REC - 1)], y[i & (REC - 1)]));
    report_max("welch_push_max_n256", worst, empty, ipt);

    let Some(w1024) = cortex_m::singleton!(: Option<Welch<1024>> = Welch::new(Welch::<1024>::default_config(FS)).ok())
    else {
        exit(EXIT_FAILURE)
    };
    let Some(w1024) = w1024.as_mut() else {
        exit(EXIT_FAILURE)
    };
    let t = run(&mut ic, |i| w1024.push(u[i & (REC - 1)], y[i & (REC - 1)]));
    black_box(w1024.suu(3));
    report("welch_push_n1024", t, base, ipt, SAMPLES, "instr/sample");
    defmt::println!(
        "BENCH welch_n1024_averages {=u32} segments",
        w1024.averages()
    );
    w1024.reset();
    let (worst, empty) = max_ticks(&mut ic, |i| w1024.push(u[i & (REC - 1)], y[i & (REC - 1)]));
    report_max("welch_push_max_n1024", worst, empty, ipt);
    // Rectangular window, no overlap (hop = N: the least work per push, the longest spread).
    if w1024
        .configure(WelchConfig {
            fs_hz: FS,
            overlap: 0,
            window: Window::Rectangular,
            detrend_mean: true,
        })
        .is_ok()
    {
        let t = run(&mut ic, |i| w1024.push(u[i & (REC - 1)], y[i & (REC - 1)]));
        report(
            "welch_push_rect_hop1024_n1024",
            t,
            base,
            ipt,
            SAMPLES,
            "instr/sample",
        );
        w1024.reset();
        let (worst, empty) = max_ticks(&mut ic, |i| w1024.push(u[i & (REC - 1)], y[i & (REC - 1)]));
        report_max("welch_push_max_rect_hop1024_n1024", worst, empty, ipt);
    }
    if w1024.configure(Welch::<1024>::default_config(FS)).is_err() {
        exit(EXIT_FAILURE)
    }

    // push_slice over blocks (same work, slice API).
    w1024.reset();
    ic.reset();
    let mut i = 0;
    while i < SAMPLES {
        let s = i & (REC - 1);
        let _ = w1024.push_slice(&u[s..s + BLOCK], &y[s..s + BLOCK]);
        ic.lap();
        i += BLOCK;
    }
    let t = ic.lap();
    report("welch_push_slice_n1024", t, 0, ipt, SAMPLES, "instr/sample");

    // The push that completes a segment (it only switches banks; the work follows), and the
    // whole work of one segment done at once by flush() (what that push used to cost).
    w1024.reset();
    for i in 0..1024 + 511 {
        w1024.push(u[i & (REC - 1)], y[i & (REC - 1)]);
    }
    w1024.flush();
    ic.reset();
    ic.lap();
    let empty = ic.lap();
    ic.reset();
    w1024.push(u[7], y[7]);
    let t = ic.lap();
    report("welch_segment_push_n1024", t, empty, ipt, 1, "instr/push");
    ic.reset();
    w1024.flush();
    let t = ic.lap();
    report(
        "welch_segment_work_n1024",
        t,
        empty,
        ipt,
        1,
        "instr/segment",
    );

    // Post-processing per bin (N = 1024): coherence, H1.
    ic.reset();
    for k in 0..w1024.bins() {
        black_box(w1024.coherence(black_box(k)));
    }
    let t = ic.lap();
    report(
        "welch_coherence_per_bin_n1024",
        t,
        0,
        ipt,
        w1024.bins(),
        "instr/bin",
    );
    ic.reset();
    for k in 0..w1024.bins() {
        black_box(w1024.h1(black_box(k)));
    }
    let t = ic.lap();
    report(
        "welch_h1_per_bin_n1024",
        t,
        0,
        ipt,
        w1024.bins(),
        "instr/bin",
    );
    ic.reset();
    black_box(w1024.gate(black_box(0.9)));
    let t = ic.lap();
    report("welch_gate_n1024", t, 0, ipt, 1, "instr/call");

    // Excitation generators, per sample.
    let base_gen = run(&mut ic, |i| {
        black_box(i);
    });
    if let Ok(mut g) = Prbs::new(15, 1, 1.0, 1) {
        let t = run(&mut ic, |_| {
            black_box(g.next_sample());
        });
        report("prbs15_hold1", t, base_gen, ipt, SAMPLES, "instr/sample");
    }
    for (name, law) in [
        ("chirp_linear", ChirpLaw::Linear),
        ("chirp_log", ChirpLaw::Logarithmic),
    ] {
        let cfg = ChirpConfig {
            fs_hz: FS,
            f0_hz: 1.0,
            f1_hz: 400.0,
            duration_s: 100.0,
            fade_s: 1.0,
            amplitude: 1.0,
            law,
        };
        if let Ok(mut c) = Chirp::new(cfg) {
            let t = run(&mut ic, |_| {
                black_box(c.next_sample());
            });
            report(name, t, base_gen, ipt, SAMPLES, "instr/sample");
        }
    }
    let mut lines = [Line {
        bin: 0,
        amplitude: 0.1,
    }; 100];
    for (i, l) in lines.iter_mut().enumerate() {
        l.bin = 1 + 2 * i;
    }
    let Some(scratch) = cortex_m::singleton!(: MultisineScratch<1024> = MultisineScratch::new())
    else {
        exit(EXIT_FAILURE)
    };
    ic.reset();
    let ms = Multisine::<1024>::design(
        &MultisineSpec {
            lines: &lines,
            phases: Phases::Random { seed: 3 },
            crest_iterations: 100,
        },
        scratch,
    );
    let t_design = ic.lap();
    let Some(ms_slot) = cortex_m::singleton!(: Option<Multisine<1024>> = ms.ok()) else {
        exit(EXIT_FAILURE)
    };
    if let Some(ms) = ms_slot.as_mut() {
        report(
            "multisine1024_design_100_iterations",
            t_design,
            0,
            ipt,
            1,
            "instr/design",
        );
        defmt::println!(
            "BENCH multisine1024_crest_factor {=f32} ratio",
            ms.crest_factor()
        );
        let t = run(&mut ic, |_| {
            black_box(ms.next_sample());
        });
        report(
            "multisine1024_play",
            t,
            base_gen,
            ipt,
            SAMPLES,
            "instr/sample",
        );
    }
    // Control step (ferrosid_firmware::control): the PID with a roll-off biquad alone, and with
    // each compensation part, per sample, on the recorded (u, y) as reference and measurement.
    let pid = PidConfig {
        kp: 1.2,
        ki_d: 0.05,
        a_d: 0.6,
        b_d: 8.0,
        rolloff: Some(Biquad {
            b: [0.02, 0.04, 0.02],
            a: [1.0, -1.56, 0.64],
        }),
    };
    let ff = FrictionFeedforward {
        coulomb: 0.1,
        viscous: 0.01,
        smoothing_velocity: 0.05,
        velocity: VelocitySource::OutputDifference { alpha: 0.47 },
        lag_aware: None,
    };
    let dz = DeadZoneInverse {
        width: 0.2,
        smoothing: 1e-3,
    };
    let bl = BacklashInverse {
        gap: 0.05,
        smoothing: 0.01,
    };
    let aw = AntiWindup {
        u_min: -0.8,
        u_max: 0.8,
        gain: 0.05,
    };
    let none = CompensationConfig::NONE;
    let variants: [(&str, Option<CompensationConfig>); 6] = [
        ("control_pid", None),
        (
            "control_pid_friction_ff",
            Some(CompensationConfig {
                friction_feedforward: Some(ff),
                ..none
            }),
        ),
        (
            "control_pid_dead_zone_inverse",
            Some(CompensationConfig {
                dead_zone_inverse: Some(dz),
                ..none
            }),
        ),
        (
            "control_pid_backlash_inverse",
            Some(CompensationConfig {
                backlash_inverse: Some(bl),
                ..none
            }),
        ),
        (
            "control_pid_anti_windup",
            Some(CompensationConfig {
                anti_windup: Some(aw),
                ..none
            }),
        ),
        (
            "control_pid_all_compensation",
            Some(CompensationConfig {
                friction_feedforward: Some(ff),
                dead_zone_inverse: Some(dz),
                backlash_inverse: Some(bl),
                anti_windup: Some(aw),
            }),
        ),
    ];
    for (name, comp) in variants {
        let cfg = ControlConfig {
            ts_s: 1e-3,
            pid,
            compensation: comp,
        };
        let Ok(law) = ControlLaw::new(&cfg) else {
            exit(EXIT_FAILURE)
        };
        let mut st = ControlState::new();
        let t = run(&mut ic, |i| {
            black_box(law.step(&mut st, u[i & (REC - 1)], y[i & (REC - 1)]));
        });
        report(name, t, base, ipt, SAMPLES, "instr/step");
    }
    exit(EXIT_SUCCESS)
}
