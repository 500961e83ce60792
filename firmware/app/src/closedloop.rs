//! `closedloop`: the generated controller (PID + compensation of the flashed module) closing
//! the loop around a simulated axis with a nonlinearity, to show a limit cycle on target and
//! its removal by the compensation.
//!
//! Each sample: measure y (the plant's position θ), run [`ControlLaw::step`] with reference r,
//! apply the command (plus the start-up kick during the first `kick_samples`) to the plant over
//! the same period (no computation delay, as the host's loop model).
//! The last [`TAIL`] samples of y, the controller's command u and the true velocity ω are
//! kept; at the end
//! the image analyses each with [`analyse_oscillation`] and logs the tail.
//!
//! Command line (`-semihosting-config ...,arg=WORD`), all optional:
//! * `comp=on|off|ff|ffplain|dz|bl|aw` — apply the flashed compensation: all of it, none
//!   (default), or only its friction feedforward (`ffplain`: without its lag-aware form, the
//!   plain law with the same numbers), dead-zone inverse, backlash inverse or anti-windup
//!   (one image serves several scenarios); asking for a block or part the module does not
//!   have, or a disabled block, is a set-up error;
//! * plant: `J=` kg·m², `b=` N·m·s/rad, `k=` N·m/rad, `gain=` N·m/unit, `coulomb=` N·m,
//!   `breakaway=` N·m (> 0: stick-slip), `deadzone=` input units (full width), `lag=` s (the
//!   torque's first-order lag, `Axis::with_torque_lag`; default 0), `noise=` rad,
//!   `seed=`, `substeps=`; defaults J = 1e-4, b = k = 0, gain = 1, no friction, no dead zone,
//!   no noise, 32 sub-steps;
//! * `r=` reference (rad, default 0), `kick=` input units added for `kick_samples=` samples
//!   (default 0.5 for 5), `seconds=` simulated time (default 8), `floor=` the smallest
//!   amplitude of y (rad) that counts as an oscillation (default 1e-3, the bench's sensor
//!   noise: a smaller cycle is not observable).
//!
//! * `check=on` — instead of the free run: the closed-loop power-up check
//!   (`ferrosid_firmware::check::ClosedLoopEstimator`), only in an image built with the cargo
//!   feature `closed-loop-check` (see Cargo.toml for why a feature and not a second bin; an
//!   image without it answers `check=on` with a set-up error naming the feature and costs
//!   none of the check's flash or RAM). The self-identification multisine of
//!   the module (bins 1..=EXCITATION_MAX_BIN of a WELCH_N period, RMS
//!   CLOSED_LOOP_REFERENCE_RMS in output units) is added to the reference `r`; SETTLE_PERIODS
//!   periods settle, AVERAGES periods feed the estimator with (excitation, the PID's command,
//!   y); at every check bin `G = S_ry / S_ru` is compared with the flashed model ± |W_m| as
//!   the open-loop check does (`check_rms=` overrides the RMS, for exploring the amplitude on a
//!   bench). `seconds` and the kick are not used. Logs
//!   `CLCHECK n=.. averages=.. settle=.. reference_rms=.. comp=..`, one `C <r> <u> <y>` per
//!   averaged sample (the first [`TAIL`]), `RECEIPT ..` lines in the power-up image's format
//!   (coherence: the smaller of γ²_ry and γ²_ru; σ: their summed normalised random errors),
//!   `ICOUNT push_mean=.. push_max=.. evaluate=.. ipt=..` (instructions per sample for the
//!   excitation sample + estimator push, and for the final evaluation, under
//!   `qemu -icount shift=0`; meaningless without it), `STACK <bytes>` and
//!   `VERDICT <PASS|FAIL|INCONCLUSIVE> checked=<c>/<total> failed_hz=[..]`; exit status 0 pass,
//!   1 fail, 2 inconclusive.
//!
//! Log lines (decoded defmt):
//! * `CLOSEDLOOP sha256=<digest> comp=<on|off|ff|ffplain|dz|bl|aw> samples=<n> ts=<s> J=.. b=.. k=.. gain=.. coulomb=.. breakaway=.. deadzone=.. lag=..`
//! * `T <y> <u> <omega>` for each of the last [`TAIL`] samples, oldest first;
//! * `CYCLE <y|u|omega> freq_hz=<f> amplitude=<a> mean=<m> crossings=<c> oscillating=<bool>`;
//! * `END`.
//!
//! Exit status 0 (free run), 0/1/2 (check), 3 for a bad command line or set-up error, 101 panic.
#![no_std]
#![no_main]

use cortex_m as _;
use cortex_m_rt::entry;
use defmt_semihosting as _;
use ferrosid_firmware::control::{
    analyse_oscillation, Biquad, CompensationConfig, ControlConfig, ControlLaw, ControlState,
    FrictionFeedforward, PidConfig,
};
#[cfg(feature = "closed-loop-check")]
use ferrosid_firmware::excitation::{Multisine, MultisineScratch, MultisineSpec, Phases};
#[cfg(feature = "closed-loop-check")]
use ferrosid_firmware::Excitation;
use ferrosid_powerup::plant::{Axis, AxisParams};
#[cfg(feature = "closed-loop-check")]
use ferrosid_powerup::{evaluate, flat_lines, CheckConfig, ClosedLoopEstimator, Model, Weight};

/// The generated module (`ferrosid codegen`), copied into OUT_DIR by build.rs.
#[allow(dead_code)]
mod flashed {
    include!(concat!(env!("OUT_DIR"), "/flashed_model.rs"));
}

/// The generated compensation block in the firmware's form (shared with `powerup`).
#[path = "flashed_comp.rs"]
mod flashed_comp;

/// The receipt's log lines (shared with the other image).
#[cfg(feature = "closed-loop-check")]
#[path = "receipt_log.rs"]
mod receipt_log;
use flashed_comp::compensation_config;

/// Samples kept for the analysis and the log (4.096 s at 1 kHz).
const TAIL: usize = 4096;
/// Exit status for a bad command line or set-up error.
const EXIT_SETUP: i32 = 3;
/// Exit status after a panic.
const EXIT_PANIC: i32 = 101;
/// Cycles a record needs to count as oscillating.
const MIN_CYCLES: u32 = 5;

fn exit(code: i32) -> ! {
    semihosting::process::exit(code)
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    use semihosting::io::Write as _;
    if let Ok(mut e) = semihosting::io::stderr() {
        let _ = e.write_all(b"closedloop: panicked\n");
    }
    exit(EXIT_PANIC)
}

fn setup_error(what: &str) -> ! {
    defmt::println!("ERROR {=str}", what);
    exit(EXIT_SETUP)
}

/// Which parts of the flashed compensation run.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Parts {
    None,
    All,
    Friction,
    FrictionPlain,
    DeadZone,
    Backlash,
    AntiWindup,
}

impl Parts {
    fn as_str(self) -> &'static str {
        match self {
            Parts::None => "off",
            Parts::All => "on",
            Parts::Friction => "ff",
            Parts::FrictionPlain => "ffplain",
            Parts::DeadZone => "dz",
            Parts::Backlash => "bl",
            Parts::AntiWindup => "aw",
        }
    }
}

/// The run's settings from the command line.
struct Settings {
    plant: AxisParams,
    comp: Parts,
    r: f32,
    kick: f32,
    kick_samples: u32,
    seconds: f32,
    floor: f32,
    lag: f32,
    /// `check=on`: run the closed-loop check instead of the free run.
    check: bool,
    /// `check_rms=`: overrides the module's CLOSED_LOOP_REFERENCE_RMS (bench exploration).
    /// Parsed in both variants (same command line), read only by the check.
    #[cfg_attr(not(feature = "closed-loop-check"), allow(dead_code))]
    check_rms: Option<f32>,
}

fn parse_f32(key: &'static str, v: &str) -> Result<f32, &'static str> {
    ferrosid_firmware::decimal::parse_f32(v)
        .filter(|x| x.is_finite())
        .ok_or(key)
}

fn parse_args() -> Result<Settings, &'static str> {
    let mut s = Settings {
        plant: AxisParams {
            inertia: 1e-4,
            damping: 0.0,
            stiffness: 0.0,
            gain: 1.0,
            coulomb: 0.0,
            coulomb_smoothing: 0.1,
            delay_samples: 0,
            noise_rms: 0.0,
            seed: 1,
            substeps: 32,
            dead_zone: 0.0,
            breakaway: 0.0,
        },
        comp: Parts::None,
        r: 0.0,
        kick: 0.5,
        kick_samples: 5,
        seconds: 8.0,
        floor: 1e-3,
        lag: 0.0,
        check: false,
        check_rms: None,
    };
    let args = semihosting::experimental::env::args::<1024>().map_err(|_| "command line")?;
    for (i, a) in (&args).enumerate() {
        let a = a.map_err(|_| "command line (not UTF-8)")?;
        if i == 0 {
            continue;
        }
        let (key, v) = a.split_once('=').ok_or("argument without '='")?;
        let p = &mut s.plant;
        match key {
            "comp" => {
                s.comp = match v {
                    "on" => Parts::All,
                    "off" => Parts::None,
                    "ff" => Parts::Friction,
                    "ffplain" => Parts::FrictionPlain,
                    "dz" => Parts::DeadZone,
                    "bl" => Parts::Backlash,
                    "aw" => Parts::AntiWindup,
                    _ => return Err("comp (on|off|ff|ffplain|dz|bl|aw)"),
                }
            }
            "J" => p.inertia = parse_f32("J", v)?,
            "b" => p.damping = parse_f32("b", v)?,
            "k" => p.stiffness = parse_f32("k", v)?,
            "gain" => p.gain = parse_f32("gain", v)?,
            "coulomb" => p.coulomb = parse_f32("coulomb", v)?,
            "breakaway" => p.breakaway = parse_f32("breakaway", v)?,
            "deadzone" => p.dead_zone = parse_f32("deadzone", v)?,
            "noise" => p.noise_rms = parse_f32("noise", v)?,
            "seed" => p.seed = v.parse().map_err(|_| "seed")?,
            "substeps" => p.substeps = v.parse().map_err(|_| "substeps")?,
            "r" => s.r = parse_f32("r", v)?,
            "kick" => s.kick = parse_f32("kick", v)?,
            "kick_samples" => s.kick_samples = v.parse().map_err(|_| "kick_samples")?,
            "seconds" => s.seconds = parse_f32("seconds", v)?,
            "floor" => s.floor = parse_f32("floor", v)?,
            "lag" => s.lag = parse_f32("lag", v)?,
            "check_rms" => s.check_rms = Some(parse_f32("check_rms", v)?),
            "check" => {
                s.check = match v {
                    "on" => true,
                    "off" => false,
                    _ => return Err("check (on|off)"),
                }
            }
            _ => return Err("unknown key"),
        }
    }
    if !(s.seconds > 0.0 && s.seconds <= 600.0) {
        return Err("seconds (0 < s <= 600)");
    }
    Ok(s)
}

/// The generated PID in the firmware's form (set-up error when the module has none).
fn pid_config() -> PidConfig {
    let Some(p) = flashed::PID else {
        setup_error("the flashed module has no PID")
    };
    PidConfig {
        kp: p.kp,
        ki_d: p.ki_d,
        a_d: p.a_d,
        b_d: p.b_d,
        rolloff: p.rolloff.map(|r| Biquad { b: r.b, a: r.a }),
    }
}

/// Ring buffers of the tail, in .bss.
static mut TAIL_Y: [f32; TAIL] = [0.0; TAIL];
static mut TAIL_U: [f32; TAIL] = [0.0; TAIL];
static mut TAIL_W: [f32; TAIL] = [0.0; TAIL];

#[entry]
fn main() -> ! {
    let s = match parse_args() {
        Ok(s) => s,
        Err(key) => {
            defmt::println!("ERROR bad command line: {=str}", key);
            exit(EXIT_SETUP)
        }
    };
    let compensation = match (s.comp, compensation_config()) {
        (Parts::None, _) => None,
        (_, None) => setup_error("comp: the flashed module has no enabled compensation"),
        (Parts::All, Some(c)) => Some(c),
        (part, Some(c)) => {
            let only = CompensationConfig {
                friction_feedforward: match part {
                    Parts::Friction => c.friction_feedforward,
                    Parts::FrictionPlain => c.friction_feedforward.map(|f| FrictionFeedforward {
                        lag_aware: None,
                        ..f
                    }),
                    _ => None,
                },
                dead_zone_inverse: c.dead_zone_inverse.filter(|_| part == Parts::DeadZone),
                backlash_inverse: c.backlash_inverse.filter(|_| part == Parts::Backlash),
                anti_windup: c.anti_windup.filter(|_| part == Parts::AntiWindup),
            };
            if only == CompensationConfig::NONE {
                setup_error("comp: the flashed compensation has no such part")
            }
            Some(only)
        }
    };
    let cfg = ControlConfig {
        ts_s: flashed::TS_S,
        pid: pid_config(),
        compensation,
    };
    let law = match ControlLaw::new(&cfg) {
        Ok(l) => l,
        Err(e) => {
            if let ferrosid_firmware::Error::InvalidControlParameter { what } = e {
                defmt::println!("ERROR control parameter out of range: {=str}", what);
            }
            exit(EXIT_SETUP)
        }
    };
    let p = s.plant;
    let mut axis = match Axis::new(p, flashed::TS_S).and_then(|a| a.with_torque_lag(s.lag)) {
        Ok(a) => a,
        Err(e) => {
            defmt::println!("ERROR plant parameter out of range: {=str}", e.0);
            exit(EXIT_SETUP)
        }
    };
    if s.check {
        run_check(&law, &mut axis, &s)
    }
    let samples = (s.seconds / flashed::TS_S) as usize;
    defmt::println!(
        "CLOSEDLOOP sha256={=str} comp={=str} samples={=usize} ts={=f32} J={=f32} b={=f32} k={=f32} gain={=f32} coulomb={=f32} breakaway={=f32} deadzone={=f32} lag={=f32}",
        flashed::INPUTS_SHA256,
        s.comp.as_str(),
        samples,
        flashed::TS_S,
        p.inertia,
        p.damping,
        p.stiffness,
        p.gain,
        p.coulomb,
        p.breakaway,
        p.dead_zone,
        s.lag
    );
    // SAFETY: `main` runs once and never returns; these are the only references ever taken
    // to the three buffers, so they are unique.
    let (ty, tu, tw) = unsafe {
        (
            &mut *core::ptr::addr_of_mut!(TAIL_Y),
            &mut *core::ptr::addr_of_mut!(TAIL_U),
            &mut *core::ptr::addr_of_mut!(TAIL_W),
        )
    };
    let mut st = ControlState::new();
    // The last TAIL samples are stored in time order from `first_kept` on.
    let first_kept = samples.saturating_sub(TAIL);
    for k in 0..samples {
        let y = axis.measure();
        let u = law.step(&mut st, s.r, y).u;
        if let Some(slot) = k.checked_sub(first_kept) {
            if let (Some(a), Some(b), Some(c)) =
                (ty.get_mut(slot), tu.get_mut(slot), tw.get_mut(slot))
            {
                *a = y;
                *b = u;
                *c = axis.velocity();
            }
        }
        let kick = if (k as u64) < u64::from(s.kick_samples) {
            s.kick
        } else {
            0.0
        };
        axis.advance(u + kick);
    }
    let n = samples - first_kept;
    for j in 0..n {
        if let (Some(a), Some(b), Some(c)) = (ty.get(j), tu.get(j), tw.get(j)) {
            defmt::println!("T {=f32} {=f32} {=f32}", *a, *b, *c);
        }
    }
    for (name, buf, floor) in [("y", &*ty, s.floor), ("u", &*tu, 0.0), ("omega", &*tw, 0.0)] {
        let o = analyse_oscillation(
            buf.get(..n).unwrap_or(&[]),
            flashed::TS_S,
            MIN_CYCLES,
            floor,
        );
        defmt::println!(
            "CYCLE {=str} freq_hz={=f32} amplitude={=f32} mean={=f32} crossings={=u32} oscillating={=bool}",
            name,
            o.freq_hz,
            o.amplitude,
            o.mean,
            o.crossings,
            o.oscillating
        );
    }
    defmt::println!("END");
    exit(0)
}

/// Welch segment length and multisine period of the check.
#[cfg(feature = "closed-loop-check")]
const N: usize = flashed::WELCH_N;
/// Excited lines.
#[cfg(feature = "closed-loop-check")]
const LINES: usize = flashed::EXCITATION_MAX_BIN;
#[cfg(feature = "closed-loop-check")]
const _: () = assert!(LINES >= 1 && LINES < N / 2);

/// SysTick instruction counter under `qemu -icount` (shared with the QEMU bench images).
#[cfg(feature = "closed-loop-check")]
#[path = "../../../tests/qemu/src/icount.rs"]
#[allow(dead_code)] // `free` and the held SYST are for the bench images
mod icount;
/// Stack high-water mark by painting (the painter the power-up image and the QEMU probe use).
#[cfg(feature = "closed-loop-check")]
#[path = "../../../tests/qemu/src/stack.rs"]
mod stack;

/// The closed-loop estimator (48·N bytes) in .bss.
#[cfg(feature = "closed-loop-check")]
static mut ESTIMATOR: ClosedLoopEstimator<N> = ClosedLoopEstimator::unconfigured();

/// The multisine design with its 8·N-byte scratch on this frame only.
#[cfg(feature = "closed-loop-check")]
#[inline(never)]
fn design_excitation(spec: &MultisineSpec<'_>) -> Option<Multisine<N>> {
    let mut scratch = MultisineScratch::<N>::new();
    Multisine::design(spec, &mut scratch).ok()
}

/// Without the feature `closed-loop-check` the image carries no check: `check=on` is a set-up
/// error that says how to build an image that has one.
#[cfg(not(feature = "closed-loop-check"))]
fn run_check(_: &ControlLaw, _: &mut Axis, _: &Settings) -> ! {
    setup_error("check=on: this image has no closed-loop check (build it with --features closed-loop-check)")
}

/// The closed-loop check (`check=on`, see the crate docs); exits with its verdict.
#[cfg(feature = "closed-loop-check")]
fn run_check(law: &ControlLaw, axis: &mut Axis, s: &Settings) -> ! {
    let painted = stack::paint(32 * 1024);
    let Some(p) = cortex_m::Peripherals::take() else {
        setup_error("peripherals already taken")
    };
    let mut ic = icount::InstructionCounter::new(p.SYST);
    let (i1, t1) = ic.calibrate(100_000);
    let (i2, t2) = ic.calibrate(300_000);
    // Instructions per SysTick tick (0 without -icount: the counts are then not reported as
    // meaningful, ipt=0).
    let ipt = if t2 > t1 {
        (i2 - i1) as f64 / (t2 - t1) as f64
    } else {
        0.0
    };
    let Some(rms) = s.check_rms.or(flashed::CLOSED_LOOP_REFERENCE_RMS) else {
        setup_error("check=on, but the flashed module has no closed-loop check settings")
    };
    let cfg = CheckConfig {
        fs_hz: flashed::FS_HZ,
        n: N,
        bins: &flashed::CHECK_BIN,
        hz: &flashed::CHECK_HZ,
        gate: flashed::COHERENCE_GATE,
        min_checked: flashed::MIN_CHECKED,
    };
    if let Err(e) = cfg.validate() {
        defmt::println!("ERROR check setting out of range: {=str}", e.field());
        exit(EXIT_SETUP)
    }
    let Ok(lines) = flat_lines::<LINES>(rms) else {
        setup_error("check setting out of range: reference_rms")
    };
    let spec = MultisineSpec {
        lines: &lines,
        phases: Phases::Schroeder,
        crest_iterations: 100,
    };
    let Some(ms) = cortex_m::singleton!(: Multisine<N> = match design_excitation(&spec) {
        Some(m) => m,
        None => setup_error("multisine design rejected the line set"),
    }) else {
        exit(EXIT_SETUP)
    };
    // SAFETY: `run_check` runs once (it never returns) and this is the only reference ever
    // taken to ESTIMATOR, so it is unique.
    let est: &'static mut ClosedLoopEstimator<N> =
        unsafe { &mut *core::ptr::addr_of_mut!(ESTIMATOR) };
    if let Err(e) = est.configure(flashed::FS_HZ) {
        defmt::println!("ERROR check setting out of range: {=str}", e.field());
        exit(EXIT_SETUP)
    }
    // SAFETY: as in `main` (which does not use the buffers on this path): unique references.
    let (tr, tu, ty) = unsafe {
        (
            &mut *core::ptr::addr_of_mut!(TAIL_W),
            &mut *core::ptr::addr_of_mut!(TAIL_U),
            &mut *core::ptr::addr_of_mut!(TAIL_Y),
        )
    };
    let settle = flashed::SETTLE_PERIODS as usize * N;
    let total = settle + flashed::AVERAGES as usize * N;
    defmt::println!(
        "CLCHECK sha256={=str} n={=usize} averages={=u32} settle={=u32} reference_rms={=f32} comp={=str} lag={=f32} coulomb={=f32}",
        flashed::INPUTS_SHA256,
        N,
        flashed::AVERAGES,
        flashed::SETTLE_PERIODS,
        rms,
        s.comp.as_str(),
        s.lag,
        axis.params().coulomb
    );
    let mut st = ControlState::new();
    let (mut sum_ticks, mut max_ticks, mut empty_max, mut pushes) = (0u64, 0u32, 0u32, 0u64);
    for k in 0..total {
        let y = axis.measure();
        let mut r = 0.0f32;
        let t_exc = ic.ticks_of(|| r = ms.next_sample());
        let out = law.step(&mut st, s.r + r, y);
        if let Some(j) = k.checked_sub(settle) {
            let t_push = ic.ticks_of(|| est.push(r, out.u_pid, y));
            empty_max = empty_max.max(ic.ticks_of(|| ()));
            let t = t_exc.saturating_add(t_push);
            sum_ticks += u64::from(t);
            max_ticks = max_ticks.max(t);
            pushes += 1;
            if let (Some(a), Some(b), Some(c)) = (tr.get_mut(j), tu.get_mut(j), ty.get_mut(j)) {
                *a = r;
                *b = out.u_pid;
                *c = y;
            }
        }
        axis.advance(out.u);
    }
    est.flush();
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
    let mut results = [ferrosid_powerup::CheckResult::EMPTY; flashed::CHECK_COUNT];
    let t_eval = ic.ticks_of(|| results = evaluate(&cfg, &model, &weight, |k| est.measured(k)));
    let kept = (total - settle).min(TAIL);
    for j in 0..kept {
        if let (Some(a), Some(b), Some(c)) = (tr.get(j), tu.get(j), ty.get(j)) {
            defmt::println!("C {=f32} {=f32} {=f32}", *a, *b, *c);
        }
    }
    receipt_log::rows(&results);
    let empty = f64::from(empty_max);
    let mean = if pushes > 0 {
        (sum_ticks as f64 / pushes as f64 - 2.0 * empty) * ipt
    } else {
        0.0
    };
    defmt::println!(
        "ICOUNT push_mean={=f64} push_max={=f64} evaluate={=f64} ipt={=f64} dropped={=u32}",
        mean,
        (f64::from(max_ticks) - 2.0 * empty) * ipt,
        (f64::from(t_eval) - empty) * ipt,
        ipt,
        est.dropped_segments()
    );
    defmt::println!("STACK {=usize}", painted.high_water());
    let overall = receipt_log::verdict(&results, flashed::MIN_CHECKED);
    exit(overall.exit_code())
}
