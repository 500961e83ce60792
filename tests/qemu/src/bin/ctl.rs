//! The generated pid-notch or H∞ controller (issue 14) in closed loop on the emulated
//! Cortex-M4F: a saturated step of the reference on the simulated example axis (the identified
//! model G0 of the bundled example: the header's A, B, C in f32), with the per-step
//! instruction count.
//!
//! Built only with the `ctl` feature and `FERROSID_CTL_MODEL` naming the Rust module written
//! by `ferrosid codegen` for a pipeline run with `[control] method = "pid-notch"` or `"hinf"`
//! (build.rs copies it to `$OUT_DIR/ctl_model.rs` and sets `cfg(ctl_kn)` when the module has
//! the PID + notch block). Run under `qemu-system-arm ... -icount shift=0`.
//!
//! Per sample k: y = C x; u = law.step(r, y) (timed alone with SysTick); x ← A x + B u.
//! The law is `ferrosid_firmware::control::PidNotchLaw` built from the module's `KN_*` consts,
//! or `StateSpaceLaw` from `K_*` (with the rails and back-calculation gain `K_L`).
//! Output (defmt): `CTL law=<kn|ss> order=.. samples=.. r=..`, one `T k y u` line per sample,
//! `ICOUNT mean=.. max=.. ipt=..`, `STACK high_water=..`, `RAILS crossed=.. max_abs_u=..`.
//! Semihosting arguments: `r=<reference>` (default 5), `samples=<n>` (default 1500, at most
//! 20000). Exit code 0; 1 when a rail was crossed, a sample was held, or the counter does not
//! count instructions.
#![no_std]
#![no_main]

use core::hint::black_box;

use cortex_m_rt::entry;
use ferrosid_qemu::{exit, InstructionCounter, EXIT_FAILURE, EXIT_SUCCESS};

#[allow(dead_code, clippy::all)]
mod flashed {
    include!(concat!(env!("OUT_DIR"), "/ctl_model.rs"));
}
use flashed::N_STATES;

#[cfg(ctl_kn)]
mod law {
    use super::flashed as f;
    use ferrosid_firmware::control::{
        Biquad, BiquadCascade, PidConfig, PidNotchConfig, PidNotchLaw, PidNotchState,
    };

    pub const NAME: &str = "kn";
    pub const ORDER: usize = f::KN_SECTIONS;
    pub type State = PidNotchState<{ f::KN_SECTIONS }>;
    pub type Law = PidNotchLaw<{ f::KN_SECTIONS }>;

    const fn bq(b: &f::Biquad) -> Biquad {
        Biquad { b: b.b, a: b.a }
    }

    pub fn build() -> Option<Law> {
        let mut sections = [Biquad {
            b: [1.0, 0.0, 0.0],
            a: [1.0, 0.0, 0.0],
        }; f::KN_SECTIONS];
        for (s, g) in sections.iter_mut().zip(f::KN_SOS.iter()) {
            *s = bq(g);
        }
        PidNotchLaw::new(&PidNotchConfig {
            pid: PidConfig {
                kp: f::KN_PID.kp,
                ki_d: f::KN_PID.ki_d,
                a_d: f::KN_PID.a_d,
                b_d: f::KN_PID.b_d,
                rolloff: match &f::KN_PID.rolloff {
                    Some(r) => Some(bq(r)),
                    None => None,
                },
            },
            cascade: BiquadCascade { sections },
            u_min: f::KN_U_MIN,
            u_max: f::KN_U_MAX,
            anti_windup: f::KN_ANTI_WINDUP,
        })
        .ok()
    }

    pub fn rails() -> (f32, f32) {
        (f::KN_U_MIN, f::KN_U_MAX)
    }
}

#[cfg(not(ctl_kn))]
mod law {
    use super::flashed as f;
    use ferrosid_firmware::control::{StateSpaceConfig, StateSpaceLaw, StateSpaceState};

    pub const NAME: &str = "ss";
    pub const ORDER: usize = f::K_N_STATES;
    pub type State = StateSpaceState<{ f::K_N_STATES }>;
    pub type Law = StateSpaceLaw<{ f::K_N_STATES }>;

    pub fn build() -> Option<Law> {
        StateSpaceLaw::new(&StateSpaceConfig {
            a: f::K_A,
            b: f::K_B,
            c: f::K_C,
            d: f::K_D,
            l: f::K_L,
            u_min: f::K_U_MIN,
            u_max: f::K_U_MAX,
        })
        .ok()
    }

    pub fn rails() -> (f32, f32) {
        (f::K_U_MIN, f::K_U_MAX)
    }
}

/// Most samples one run simulates.
const MAX_SAMPLES: usize = 20_000;

/// `key=<value>` from the semihosting command line, if present and parseable.
fn arg_f32(key: &str) -> Option<f32> {
    let args = semihosting::experimental::env::args::<256>().ok()?;
    for a in (&args).flatten() {
        if let Some(v) = a.strip_prefix(key).and_then(|r| r.strip_prefix('=')) {
            return v.parse::<f32>().ok();
        }
    }
    None
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
    let painted = ferrosid_qemu::stack::paint(32 * 1024);
    let (i1, t1) = ic.calibrate(1_000_000);
    let (i2, t2) = ic.calibrate(3_000_000);
    if t2 <= t1 {
        defmt::println!("CTL error: SysTick does not advance; run under qemu -icount shift=0");
        exit(EXIT_FAILURE)
    }
    let ipt = (i2 - i1) as f64 / (t2 - t1) as f64;
    let r = arg_f32("r").unwrap_or(5.0);
    let samples = arg_f32("samples")
        .map_or(1500, |v| v as usize)
        .min(MAX_SAMPLES);
    let Some(ctl) = law::build() else {
        defmt::println!("CTL error: the flashed controller is invalid");
        exit(EXIT_FAILURE)
    };
    defmt::println!(
        "CTL law={=str} order={=usize} samples={=usize} r={=f32}",
        law::NAME,
        law::ORDER,
        samples,
        r
    );
    let (u_min, u_max) = law::rails();
    let mut st = law::State::new();
    let mut x = [0.0f32; N_STATES];
    let (mut sum_ticks, mut max_ticks, mut empty_max) = (0u64, 0u32, 0u32);
    let (mut max_u, mut bad) = (0.0f32, 0u32);
    for k in 0..samples {
        let mut y = 0.0f32;
        for (c, xv) in flashed::C[0].iter().zip(x.iter()) {
            y += c * xv;
        }
        let mut out = Default::default();
        let ticks = ic.ticks_of(|| {
            out = ctl.step(black_box(&mut st), black_box(r), black_box(y));
        });
        let out: ferrosid_firmware::control::LawOutput = out;
        empty_max = empty_max.max(ic.ticks_of(|| black_box(())));
        sum_ticks += u64::from(ticks);
        max_ticks = max_ticks.max(ticks);
        let u = out.u;
        if !(u >= u_min && u <= u_max) || out.held {
            bad += 1;
        }
        max_u = max_u.max(u.abs());
        defmt::println!("T {=usize} {=f32} {=f32}", k, y, u);
        let mut next = [0.0f32; N_STATES];
        for (i, nv) in next.iter_mut().enumerate() {
            let mut s = flashed::B[i][0] * u;
            for (a, xv) in flashed::A[i].iter().zip(x.iter()) {
                s += a * xv;
            }
            *nv = s;
        }
        x = next;
    }
    let empty = f64::from(empty_max);
    let n = samples.max(1) as f64;
    let mean = (sum_ticks as f64 / n - empty) * ipt;
    let max = (f64::from(max_ticks) - empty) * ipt;
    defmt::println!("ICOUNT mean={=f64} max={=f64} ipt={=f64}", mean, max, ipt);
    defmt::println!("STACK high_water={=usize}", painted.high_water());
    defmt::println!("RAILS crossed={=u32} max_abs_u={=f32}", bad, max_u);
    exit(if bad == 0 { EXIT_SUCCESS } else { EXIT_FAILURE })
}
