//! `powerup`: power-up self-identification of the plant against the flashed model.
//!
//! At boot the image
//! 1. designs a multisine on bins `1..=EXCITATION_MAX_BIN` of a `WELCH_N`-sample period (flat
//!    amplitude, RMS `EXCITATION_RMS`, crest factor optimised) — all constants come from the
//!    Rust module `ferrosid codegen` wrote (included at build time, see `build.rs`);
//! 2. drives it into the plant for `SETTLE_PERIODS` periods (transient), then streams
//!    `AVERAGES` periods of input and measured output into a `Welch<WELCH_N>` (rectangular
//!    window, no overlap: period-synchronous, no leakage) with online coherence;
//! 3. at every check bin evaluates the flashed model's response
//!    `G0(e^{jθ}) = C (e^{jθ}I − A)⁻¹ B + D` and `|W_m(j2πf)|` on target (f32), and checks
//!    `|G_meas − G0| / |G0| <= |W_m|` where the coherence reaches `COHERENCE_GATE` and the
//!    estimate resolves |W_m| (3σ <= |W_m|, σ its normalised random error);
//! 4. logs the receipt and the spectra frame through defmt, and exits with the verdict.
//!
//! Under QEMU there is no hardware: the plant is [`ferrosid_powerup::plant::Axis`], selected
//! and parameterised on the semihosting command line (`-semihosting-config ...,arg=WORD`):
//!
//! * `plant=nominal|inertia|delay|friction` — the scenario (default `nominal`);
//!   `inertia` scales J by `jscale` (default 1.3), `delay` adds `delay` samples (default 3),
//!   `friction` adds Coulomb friction `coulomb` N·m (default 0.15);
//! * `J=` kg·m², `b=` N·m·s/rad, `k=` N·m/rad, `gain=` N·m/unit, `noise=` rad RMS, `seed=`,
//!   `substeps=`, `eps=` rad/s, and `jscale=`, `delay=`, `coulomb=` to override the scenario;
//! * `comp=on|off` — pass the excitation through the flashed compensation block (friction
//!   feedforward, inverses; default `off`), so the check measures the compensated plant.
//!
//! Defaults (the bench of the end-to-end tests): J = 1e-4 kg·m², k = 2.4674011 N·m/rad
//! (25 Hz), b = 3.1415927e-3 N·m·s/rad (ζ = 0.1), gain = k (unit DC gain), noise 1e-3 rad,
//! seed 1, 16 RK4 substeps, ε = 0.1 rad/s.
//!
//! Log lines (decoded defmt; numbers in Rust's shortest round-trip notation):
//! * `POWERUP sha256=<inputs digest> states=<n> fs=<Hz> n=<N> averages=<a> settle=<s> samples=<total>`
//! * `PLANT scenario=<name> J=.. b=.. k=.. gain=.. coulomb=.. delay=.. noise=.. seed=..`
//! * `RECEIPT <bin> <Hz> <coherence> <G0 re> <G0 im> <Gmeas re> <Gmeas im> <rel err> <|Wm|> <σ> <PASS|FAIL|SKIP|UNRESOLVED|UNDEFINED>`
//!   (σ: normalised random error of the estimate; a bin counts only when 3σ <= |W_m|)
//! * `FRAME_BEGIN fs=<Hz> n=<N> averages=<a> dropped=<d> window=rectangular overlap=0 detrend=mean excited_max_bin=<b> gate=<g>`
//! * `FRAME <bin> <S_uu> <S_yy> <Re S_uy> <Im S_uy> <coherence>` for bins 0..=N/2 (one-sided
//!   densities, units²/Hz), then `FRAME_END bins=<N/2+1>`
//! * `STACK <bytes>`, then `VERDICT <PASS|FAIL|INCONCLUSIVE> checked=<c>/<total> failed_hz=[..]`
//!
//! Exit status: 0 pass, 1 fail (a counted frequency exceeds W_m), 2 inconclusive (fewer than
//! `MIN_CHECKED` frequencies passed the coherence gate and were resolved), 3 bad command line
//! or set-up error, 101 panic.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use defmt_semihosting as _;
use ferrosid_firmware::control::{ControlConfig, ControlLaw, ControlState, PidConfig};
use ferrosid_firmware::excitation::{Multisine, MultisineScratch, MultisineSpec, Phases};
use ferrosid_firmware::{Excitation, Welch, WelchConfig, Window};
use ferrosid_powerup::plant::{Axis, AxisParams};
use ferrosid_powerup::{
    evaluate, flat_lines, h1_random_error, CheckConfig, Measured, Model, Weight, C32,
};

/// The generated model module (`ferrosid codegen`), copied into OUT_DIR by build.rs.
#[allow(dead_code)]
mod flashed {
    include!(concat!(env!("OUT_DIR"), "/flashed_model.rs"));
}

/// The generated compensation block in the firmware's form (shared with `closedloop`).
#[path = "flashed_comp.rs"]
mod flashed_comp;

/// The receipt's log lines (shared with the other image).
#[path = "receipt_log.rs"]
mod receipt_log;

/// Welch segment length and multisine period.
const N: usize = flashed::WELCH_N;
/// Number of excited lines.
const LINES: usize = flashed::EXCITATION_MAX_BIN;
/// Crest-factor optimisation rounds of the multisine design.
const CREST_ITERATIONS: u32 = 100;
/// Exit status for a bad command line or set-up error.
const EXIT_SETUP: i32 = 3;
/// Exit status after a panic.
const EXIT_PANIC: i32 = 101;

const _: () = assert!(flashed::N_INPUTS >= 1 && flashed::N_OUTPUTS >= 1);
const _: () = assert!(LINES >= 1 && LINES < N / 2);
// The spectra frame's wire format (ferrosid-frame, shared with the host parser): the segment
// length must be one the host accepts. The defmt format strings below must be literals; the
// frame crate's test `firmware_emitter` checks them against the same definition.
const _: () = assert!(ferrosid_frame::segment_length_ok(N));

fn exit(code: i32) -> ! {
    semihosting::process::exit(code)
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    use semihosting::io::Write as _;
    if let Ok(mut e) = semihosting::io::stderr() {
        let _ = e.write_all(b"powerup: panicked\n");
    }
    exit(EXIT_PANIC)
}

/// Plant scenario and parameters from the command line.
struct Scenario {
    name: &'static str,
    params: AxisParams,
    /// `comp=on`: the excitation goes through the flashed compensation.
    compensate: bool,
}

/// A finite decimal value for `key` (the small parser keeps core's 10.4 KB float-parsing table
/// out of flash; within 1 ulp of the correctly rounded value).
fn parse_f32(key: &'static str, v: &str) -> Result<f32, &'static str> {
    ferrosid_firmware::decimal::parse_f32(v)
        .filter(|x| x.is_finite())
        .ok_or(key)
}

/// Parses the semihosting command line (see the crate docs). Errors name the offending key.
fn parse_args() -> Result<Scenario, &'static str> {
    let k_nom = 2.467_401f32;
    let mut p = AxisParams {
        inertia: 1e-4,
        damping: 3.141_592_7e-3,
        stiffness: k_nom,
        gain: k_nom,
        coulomb: 0.0,
        coulomb_smoothing: 0.1,
        delay_samples: 0,
        noise_rms: 1e-3,
        seed: 1,
        substeps: 16,
        dead_zone: 0.0,
        breakaway: 0.0,
    };
    let mut name = "nominal";
    let mut compensate = false;
    let (mut jscale, mut delay, mut coulomb) = (None, None, None);
    let args = semihosting::experimental::env::args::<1024>().map_err(|_| "command line")?;
    for (i, a) in (&args).enumerate() {
        let a = a.map_err(|_| "command line (not UTF-8)")?;
        if i == 0 {
            continue; // program name
        }
        let (key, v) = a.split_once('=').ok_or("argument without '='")?;
        match key {
            "plant" => {
                name = match v {
                    "nominal" => "nominal",
                    "inertia" => "inertia",
                    "delay" => "delay",
                    "friction" => "friction",
                    _ => return Err("plant (nominal|inertia|delay|friction)"),
                }
            }
            "J" => p.inertia = parse_f32("J", v)?,
            "b" => p.damping = parse_f32("b", v)?,
            "k" => p.stiffness = parse_f32("k", v)?,
            "gain" => p.gain = parse_f32("gain", v)?,
            "noise" => p.noise_rms = parse_f32("noise", v)?,
            "eps" => p.coulomb_smoothing = parse_f32("eps", v)?,
            "seed" => p.seed = v.parse().map_err(|_| "seed")?,
            "substeps" => p.substeps = v.parse().map_err(|_| "substeps")?,
            "jscale" => jscale = Some(parse_f32("jscale", v)?),
            "delay" => delay = Some(v.parse::<u32>().map_err(|_| "delay")?),
            "coulomb" => coulomb = Some(parse_f32("coulomb", v)?),
            "comp" => {
                compensate = match v {
                    "on" => true,
                    "off" => false,
                    _ => return Err("comp (on|off)"),
                }
            }
            _ => return Err("unknown key"),
        }
    }
    let (js, d, fc) = match name {
        "inertia" => (1.3, 0, 0.0),
        "delay" => (1.0, 3, 0.0),
        "friction" => (1.0, 0, 0.15),
        _ => (1.0, 0, 0.0),
    };
    p.inertia *= jscale.unwrap_or(js);
    p.delay_samples = delay.unwrap_or(d);
    p.coulomb = coulomb.unwrap_or(fc);
    Ok(Scenario {
        name,
        params: p,
        compensate,
    })
}

/// Stack high-water mark by painting: the painter the QEMU size probe uses (one source file,
/// shared because both images are cortex-m binaries and the firmware core stays hardware-free).
#[path = "../../../tests/qemu/src/stack.rs"]
mod stack;

/// The Welch estimator (24·N bytes) in .bss.
static mut WELCH: Welch<N> = Welch::unconfigured();

/// Designs the excitation with its 8·N-byte scratch on this function's stack frame, released
/// on return (it is needed only at start-up).
#[inline(never)]
fn design_excitation(spec: &MultisineSpec<'_>) -> Option<Multisine<N>> {
    let mut scratch = MultisineScratch::<N>::new();
    Multisine::design(spec, &mut scratch).ok()
}

#[entry]
fn main() -> ! {
    let painted = stack::paint(48 * 1024);
    let scenario = match parse_args() {
        Ok(s) => s,
        Err(key) => {
            defmt::println!("ERROR bad command line: {=str}", key);
            exit(EXIT_SETUP)
        }
    };
    let p = scenario.params;
    defmt::println!(
        "POWERUP sha256={=str} states={=usize} fs={=f32} n={=usize} averages={=u32} settle={=u32} samples={=u64}",
        flashed::INPUTS_SHA256,
        flashed::N_STATES,
        flashed::FS_HZ,
        N,
        flashed::AVERAGES,
        flashed::SETTLE_PERIODS,
        flashed::SELF_ID_SAMPLES
    );
    defmt::println!(
        "PLANT scenario={=str} J={=f32} b={=f32} k={=f32} gain={=f32} coulomb={=f32} delay={=u32} noise={=f32} seed={=u64}",
        scenario.name,
        p.inertia,
        p.damping,
        p.stiffness,
        p.gain,
        p.coulomb,
        p.delay_samples,
        p.noise_rms,
        p.seed
    );
    let mut axis = match Axis::new(p, flashed::TS_S) {
        Ok(a) => a,
        Err(e) => {
            defmt::println!("ERROR plant parameter out of range: {=str}", e.0);
            exit(EXIT_SETUP)
        }
    };

    // Excitation: flat multisine on bins 1..=LINES with total RMS EXCITATION_RMS.
    let Ok(lines) = flat_lines::<LINES>(flashed::EXCITATION_RMS) else {
        defmt::println!("ERROR check setting out of range: excitation_rms");
        exit(EXIT_SETUP)
    };
    let spec = MultisineSpec {
        lines: &lines,
        phases: Phases::Schroeder,
        crest_iterations: CREST_ITERATIONS,
    };
    let Some(ms) = cortex_m::singleton!(: Multisine<N> = match design_excitation(&spec) {
        Some(m) => m,
        None => {
            defmt::println!("ERROR multisine design rejected the line set");
            exit(EXIT_SETUP)
        }
    }) else {
        exit(EXIT_SETUP)
    };
    // SAFETY: `main` runs once and never returns; this is the only reference ever taken to
    // WELCH, so it is unique. (A `static mut` initialised by the all-zero `unconfigured()`
    // lands in .bss and, unlike `singleton!`, is not first built on the stack.)
    let welch: &'static mut Welch<N> = unsafe { &mut *core::ptr::addr_of_mut!(WELCH) };
    let cfg = WelchConfig {
        fs_hz: flashed::FS_HZ,
        overlap: 0,
        window: Window::Rectangular,
        detrend_mean: true,
    };
    if welch.configure(cfg).is_err() {
        defmt::println!("ERROR Welch rejected fs = {=f32} Hz", flashed::FS_HZ);
        exit(EXIT_SETUP)
    }

    // With `comp=on` the multisine goes through the flashed compensation (friction
    // feedforward from the measured output, inverses) before the plant; the spectra relate the
    // multisine to y, i.e. they measure the compensated plant.
    let compensation = if scenario.compensate {
        let Some(c) = flashed_comp::compensation_config() else {
            defmt::println!("ERROR comp=on, but the flashed module has no enabled compensation");
            exit(EXIT_SETUP)
        };
        let cfg = ControlConfig {
            ts_s: flashed::TS_S,
            pid: PidConfig {
                kp: 0.0,
                ki_d: 0.0,
                a_d: 0.0,
                b_d: 0.0,
                rolloff: None,
            },
            compensation: Some(c),
        };
        match ControlLaw::new(&cfg) {
            Ok(l) => {
                defmt::println!("COMPENSATION on (flashed block applied to the excitation)");
                Some(l)
            }
            Err(_) => {
                defmt::println!("ERROR flashed compensation rejected by the control law");
                exit(EXIT_SETUP)
            }
        }
    } else {
        None
    };
    let mut comp_state = ControlState::new();
    let mut drive = |axis: &mut Axis, u: f32| -> f32 {
        let y = axis.measure();
        let applied = match &compensation {
            Some(l) => l.compensate(&mut comp_state, 0.0, y, u).u,
            None => u,
        };
        axis.advance(applied);
        y
    };

    // Transient, then period-synchronous averaging.
    for _ in 0..flashed::SETTLE_PERIODS as usize * N {
        drive(&mut axis, ms.next_sample());
    }
    for _ in 0..flashed::AVERAGES as usize * N {
        let u = ms.next_sample();
        let y = drive(&mut axis, u);
        welch.push(u, y);
    }
    // `push` spreads a completed segment's FFT over the next hop's pushes; the last segment is
    // still in work here, so finish it before reading the spectra.
    welch.flush();

    // The receipt.
    let check_cfg = CheckConfig {
        fs_hz: flashed::FS_HZ,
        n: N,
        bins: &flashed::CHECK_BIN,
        hz: &flashed::CHECK_HZ,
        gate: flashed::COHERENCE_GATE,
        min_checked: flashed::MIN_CHECKED,
    };
    if let Err(e) = check_cfg.validate() {
        defmt::println!("ERROR check setting out of range: {=str}", e.field());
        exit(EXIT_SETUP)
    }
    let model = Model {
        a: &flashed::A,
        b: &flashed::B,
        c: &flashed::C,
        d: &flashed::D,
    };
    let weight = Weight {
        num: &flashed::WM_NUM,
        den: &flashed::WM_DEN,
    };
    let averages = welch.averages();
    let results = evaluate(&check_cfg, &model, &weight, |k| {
        let coherence = welch.coherence(k);
        Measured {
            coherence,
            sigma: h1_random_error(coherence, averages),
            g: welch.h1(k).map(|(re, im)| C32::new(re, im)),
        }
    });
    receipt_log::rows(&results);

    // The spectra frame, for the host to re-identify from.
    defmt::println!(
        "FRAME_BEGIN fs={=f32} n={=usize} averages={=u32} dropped={=u32} window=rectangular overlap=0 detrend=mean excited_max_bin={=usize} gate={=f32}",
        flashed::FS_HZ,
        N,
        welch.averages(),
        welch.dropped_segments(),
        LINES,
        flashed::COHERENCE_GATE
    );
    for k in 0..welch.bins() {
        let (sre, sim) = welch.suy(k);
        defmt::println!(
            "FRAME {=usize} {=f32} {=f32} {=f32} {=f32} {=f32}",
            k,
            welch.suu(k),
            welch.syy(k),
            sre,
            sim,
            welch.coherence(k)
        );
    }
    defmt::println!("FRAME_END bins={=usize}", welch.bins());

    defmt::println!("STACK {=usize}", painted.high_water());
    let overall = receipt_log::verdict(&results, flashed::MIN_CHECKED);
    exit(overall.exit_code())
}
