//! The design card's crates on the target (issue 16): each candidate measured against what it
//! would replace, on the emulated Cortex-M4F under `qemu-system-arm ... -icount shift=0`.
//!
//! * **Model evaluation** `G0 = C (zI − A)⁻¹ B + D` at the 16 check bins of three discrete models
//!   (`eval_models.rs`, 2, 4 and 6 states, written by `tests/qemu/ref/eval_models.py` with a
//!   numpy complex128 reference of the same f32 matrices): the firmware's hand-written complex
//!   Gaussian elimination (`ferrosid_firmware::check::model_response`) against nalgebra's
//!   fixed-size complex LU and QR (`eval_alt.rs`).
//! * **The unit-circle point** `z = e^{j2π·bin/N}` of each check bin: the firmware's
//!   `C32::unit_circle` (now the oscillator table `trig::cos_turns` for power-of-two N) against
//!   the f64 series it used before (`trig::cos_frac`), micromath's f32 `cos`/`sin` and libm's
//!   `cosf`/`sinf`; and what each does to G0's error.
//! * **Scalar functions** the firmware calls or could call: `sqrt` (`|z|` in the check,
//!   `h1_random_error`), `sin` of a phase (excitation oscillators), `atan2`, `exp` (the log
//!   chirp's per-sample rate): libm / the firmware's own against micromath.
//! * **Fixed-capacity list**: the VERDICT line's failing-frequency list, hand-rolled array plus
//!   count against `heapless::Vec`.
//!
//! Output (defmt): `CMP job=<job> variant=<name> instr=<instructions per call> err=<max error>
//! kind=<rel|abs|none>` per measurement, `CALIB ipt=<instructions per tick>`, then `END`.
//! Instruction counts: ticks of `REPS` calls minus ticks of the same loop without the call,
//! times the calibrated instructions per tick, divided by the calls. Errors: against f64
//! references (numpy for G0, libm's f64 functions for the scalars), computed on the target.
//! Exit code 0, or 1 when the counter does not advance (not run with `-icount`).
#![no_std]
#![no_main]

use core::hint::black_box;

use cortex_m_rt::entry;
use ferrosid_firmware::check::{model_response, CheckResult, Verdict, C32};
use ferrosid_qemu::{exit, InstructionCounter, EXIT_FAILURE, EXIT_SUCCESS};
use micromath::F32Ext;

#[path = "../eval_alt.rs"]
mod eval_alt;
#[allow(dead_code)]
#[path = "../eval_models.rs"]
mod eval_models;

use eval_alt::model_response_nalgebra;
use eval_models::{axis2, threemass6, twomass4, BINS, N};

/// Check bins per model.
const NB: usize = BINS.len();
/// Repetitions of a whole sweep for the model-evaluation counts.
const SWEEPS: u32 = 20;
/// Calls per scalar-function count.
const REPS: usize = 4096;

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    ferrosid_qemu::report_panic(info)
}

/// Prints one measurement.
fn report(job: &str, variant: &str, instr: f64, err: f64, kind: &str) {
    defmt::println!(
        "CMP job={=str} variant={=str} instr={=f64} err={=f64} kind={=str}",
        job,
        variant,
        instr,
        err,
        kind
    );
}

/// A model as the check flashes it (1 input, 1 output).
struct Case<const NS: usize> {
    name: &'static str,
    a: &'static [[f32; NS]; NS],
    b: &'static [[f32; 1]; NS],
    c: &'static [[f32; NS]; 1],
    d: &'static [[f32; 1]; 1],
    re: &'static [f64; NB],
    im: &'static [f64; NB],
}

/// Largest relative error of `g` against the case's f64 reference (infinite for a `None`).
fn max_rel<const NS: usize>(case: &Case<NS>, g: &[Option<C32>; NB]) -> f64 {
    let mut worst = 0.0f64;
    for ((gi, &re), &im) in g.iter().zip(case.re.iter()).zip(case.im.iter()) {
        let e = match gi {
            Some(v) => {
                let (dr, di) = (f64::from(v.re) - re, f64::from(v.im) - im);
                libm::sqrt(dr * dr + di * di) / libm::sqrt(re * re + im * im)
            }
            None => f64::INFINITY,
        };
        worst = worst.max(e);
    }
    worst
}

/// The unit-circle points of the check bins, by one method.
fn points(f: impl Fn(u32) -> C32) -> [C32; NB] {
    let mut z = [C32::default(); NB];
    for (zi, &k) in z.iter_mut().zip(BINS.iter()) {
        *zi = f(k);
    }
    z
}

/// The four ways to get `z = e^{j2π·bin/N}`: the firmware's `C32::unit_circle` (the
/// oscillator table for a power-of-two N), the f64 series it used before for every N, micromath
/// and libm.
fn z_exact(k: u32) -> C32 {
    C32::unit_circle(k, N)
}
fn z_series(k: u32) -> C32 {
    let (n, d) = (u64::from(k), u64::from(N));
    C32::new(
        ferrosid_firmware::trig::cos_frac(n, d) as f32,
        ferrosid_firmware::trig::sin_frac(n, d) as f32,
    )
}
fn z_micromath(k: u32) -> C32 {
    let th = 2.0 * core::f32::consts::PI * k as f32 / N as f32;
    C32::new(th.cos(), th.sin())
}
fn z_libm(k: u32) -> C32 {
    let th = 2.0 * core::f32::consts::PI * k as f32 / N as f32;
    C32::new(libm::cosf(th), libm::sinf(th))
}

/// Instructions per call of `f` over the check bins (`SWEEPS` sweeps).
fn per_bin(ic: &mut InstructionCounter, ipt: f64, mut f: impl FnMut(usize)) -> f64 {
    let t = ic.ticks_of(|| {
        for _ in 0..SWEEPS {
            for i in 0..NB {
                f(black_box(i));
            }
        }
    });
    let e = ic.ticks_of(|| {
        for _ in 0..SWEEPS {
            for i in 0..NB {
                black_box(i);
            }
        }
    });
    (f64::from(t) - f64::from(e)) * ipt / f64::from(SWEEPS * NB as u32)
}

/// One evaluation by the firmware's hand-written elimination, kept out of line so that its
/// code is one symbol (`eval_hand`, the callee inlined or not) whose size the host test reads.
#[inline(never)]
fn eval_hand<const NS: usize>(case: &Case<NS>, z: C32) -> Option<C32> {
    model_response(case.a, case.b, case.c, case.d, z, 0, 0)
}

/// One evaluation by nalgebra's LU, out of line (`eval_nalgebra`).
#[inline(never)]
fn eval_nalgebra<const NS: usize>(case: &Case<NS>, z: C32) -> Option<C32>
where
    nalgebra::Const<NS>: nalgebra::DimMin<nalgebra::Const<NS>, Output = nalgebra::Const<NS>>,
{
    model_response_nalgebra(case.a, case.b, case.c, case.d, z, 0, 0)
}

/// One evaluation by nalgebra's QR, out of line (`eval_qr`).
#[inline(never)]
fn eval_qr<const NS: usize>(case: &Case<NS>, z: C32) -> Option<C32>
where
    nalgebra::Const<NS>: nalgebra::DimMin<nalgebra::Const<NS>, Output = nalgebra::Const<NS>>,
{
    eval_alt::model_response_qr(case.a, case.b, case.c, case.d, z, 0, 0)
}

/// Model evaluation, hand-written against nalgebra, and G0's error with each way of getting z.
fn model_case<const NS: usize>(ic: &mut InstructionCounter, ipt: f64, case: &Case<NS>)
where
    nalgebra::Const<NS>: nalgebra::DimMin<nalgebra::Const<NS>, Output = nalgebra::Const<NS>>,
{
    let z = points(z_exact);
    let (a, b, c, d) = (case.a, case.b, case.c, case.d);
    let mut g = [None; NB];
    let instr = per_bin(ic, ipt, |i| {
        g[i % NB] = black_box(eval_hand(black_box(case), z[i % NB]))
    });
    report(case.name, "hand", instr, max_rel(case, &g), "rel");
    let mut g = [None; NB];
    let instr = per_bin(ic, ipt, |i| {
        g[i % NB] = black_box(eval_nalgebra(black_box(case), z[i % NB]))
    });
    report(case.name, "nalgebra", instr, max_rel(case, &g), "rel");
    let mut g = [None; NB];
    let instr = per_bin(ic, ipt, |i| {
        g[i % NB] = black_box(eval_qr(black_box(case), z[i % NB]))
    });
    report(case.name, "nalgebra_qr", instr, max_rel(case, &g), "rel");
    // G0 error when z comes from each trig variant (the firmware's solve in all four).
    for (variant, zf) in [
        ("z_table", z_exact as fn(u32) -> C32),
        ("z_f64series", z_series),
        ("z_micromath", z_micromath),
        ("z_libm", z_libm),
    ] {
        let z = points(zf);
        let mut g = [None; NB];
        for (gi, zi) in g.iter_mut().zip(z.iter()) {
            *gi = model_response(a, b, c, d, *zi, 0, 0);
        }
        report(case.name, variant, 0.0, max_rel(case, &g), "rel");
    }
}

/// Instructions per call of `f` over `REPS` inputs from `xs` (the loop without the call
/// subtracted).
fn per_call(
    ic: &mut InstructionCounter,
    ipt: f64,
    xs: &[f32; REPS],
    f: impl Fn(f32) -> f32,
) -> f64 {
    let t = ic.ticks_of(|| {
        for &x in xs.iter() {
            black_box(f(black_box(x)));
        }
    });
    let e = ic.ticks_of(|| {
        for &x in xs.iter() {
            black_box(black_box(x));
        }
    });
    (f64::from(t) - f64::from(e)) * ipt / REPS as f64
}

/// Largest error of `f` against the f64 reference `r` on `xs` (relative or absolute).
fn max_err(xs: &[f32; REPS], f: impl Fn(f32) -> f32, r: impl Fn(f64) -> f64, rel: bool) -> f64 {
    let mut worst = 0.0f64;
    for &x in xs.iter() {
        let want = r(f64::from(x));
        let e = (f64::from(f(x)) - want).abs();
        worst = worst.max(if rel { e / want.abs() } else { e });
    }
    worst
}

/// The VERDICT line's failing-frequency list, as `receipt_log::verdict` built it before: an
/// array and a count.
#[inline(never)]
fn failed_array(results: &[CheckResult; NB]) -> ([f32; NB], usize) {
    let mut failed = [0.0f32; NB];
    let mut n = 0;
    for r in results {
        if matches!(r.verdict, Verdict::Fail | Verdict::Undefined) {
            if let Some(slot) = failed.get_mut(n) {
                *slot = r.hz;
                n += 1;
            }
        }
    }
    (failed, n)
}

/// The same list as a `heapless::Vec` (capacity = number of check frequencies, so the push
/// cannot fail; a full Vec would drop the frequency, as the array's `get_mut` did).
#[inline(never)]
fn failed_heapless(results: &[CheckResult; NB]) -> heapless::Vec<f32, NB> {
    let mut failed = heapless::Vec::new();
    for r in results {
        if matches!(r.verdict, Verdict::Fail | Verdict::Undefined) {
            let _ = failed.push(r.hz);
        }
    }
    failed
}

#[entry]
fn main() -> ! {
    let Some(p) = cortex_m::Peripherals::take() else {
        exit(EXIT_FAILURE)
    };
    let mut ic = InstructionCounter::new(p.SYST);
    let (i1, t1) = ic.calibrate(1_000_000);
    let (i2, t2) = ic.calibrate(3_000_000);
    if t2 <= t1 {
        defmt::println!("CMP error: SysTick does not advance; run under qemu -icount shift=0");
        exit(EXIT_FAILURE)
    }
    let ipt = (i2 - i1) as f64 / (t2 - t1) as f64;
    defmt::println!("CALIB ipt={=f64}", ipt);

    model_case(
        &mut ic,
        ipt,
        &Case {
            name: "model_axis2",
            a: &axis2::A,
            b: &axis2::B,
            c: &axis2::C,
            d: &axis2::D,
            re: &axis2::REF_RE,
            im: &axis2::REF_IM,
        },
    );
    model_case(
        &mut ic,
        ipt,
        &Case {
            name: "model_twomass4",
            a: &twomass4::A,
            b: &twomass4::B,
            c: &twomass4::C,
            d: &twomass4::D,
            re: &twomass4::REF_RE,
            im: &twomass4::REF_IM,
        },
    );
    model_case(
        &mut ic,
        ipt,
        &Case {
            name: "model_threemass6",
            a: &threemass6::A,
            b: &threemass6::B,
            c: &threemass6::C,
            d: &threemass6::D,
            re: &threemass6::REF_RE,
            im: &threemass6::REF_IM,
        },
    );

    // z = e^{j2π·bin/N}: instructions per point and the largest |z − e^{jθ}| (f64 libm).
    for (variant, zf) in [
        ("table", z_exact as fn(u32) -> C32),
        ("f64series", z_series),
        ("micromath", z_micromath),
        ("libm", z_libm),
    ] {
        let instr = per_bin(&mut ic, ipt, |i| {
            black_box(zf(black_box(BINS[i % NB])));
        });
        let mut err = 0.0f64;
        for k in 0..N / 2 {
            let th = 2.0 * core::f64::consts::PI * f64::from(k) / f64::from(N);
            let z = zf(k);
            let (dr, di) = (
                f64::from(z.re) - libm::cos(th),
                f64::from(z.im) - libm::sin(th),
            );
            err = err.max(libm::sqrt(dr * dr + di * di));
        }
        report("unit_circle", variant, instr, err, "abs");
    }

    // Scalar functions on sweeps of REPS inputs.
    let Some(xs) = cortex_m::singleton!(: [f32; REPS] = [0.0; REPS]) else {
        exit(EXIT_FAILURE)
    };
    // sqrt: |z| and σ see arguments over many decades: 1e-6 .. 1e6, log-spaced.
    for (i, x) in xs.iter_mut().enumerate() {
        *x = libm::pow(10.0, -6.0 + 12.0 * i as f64 / REPS as f64) as f32;
    }
    let (i_l, i_m) = (
        per_call(&mut ic, ipt, xs, libm::sqrtf),
        per_call(&mut ic, ipt, xs, |x| x.sqrt()),
    );
    report(
        "sqrt",
        "libm",
        i_l,
        max_err(xs, libm::sqrtf, libm::sqrt, true),
        "rel",
    );
    report(
        "sqrt",
        "micromath",
        i_m,
        max_err(xs, |x| x.sqrt(), libm::sqrt, true),
        "rel",
    );
    // exp: the log chirp's argument range (n·ln(f1/f0)/len) is [0, ln(f1/f0)] ⊂ [0, 10].
    for (i, x) in xs.iter_mut().enumerate() {
        *x = 10.0 * i as f32 / REPS as f32;
    }
    let (i_l, i_m) = (
        per_call(&mut ic, ipt, xs, libm::expf),
        per_call(&mut ic, ipt, xs, |x| x.exp()),
    );
    report(
        "exp",
        "libm",
        i_l,
        max_err(xs, libm::expf, libm::exp, true),
        "rel",
    );
    report(
        "exp",
        "micromath",
        i_m,
        max_err(xs, |x| x.exp(), libm::exp, true),
        "rel",
    );
    // atan2 around the unit circle (angles in (−π, π]).
    for (i, x) in xs.iter_mut().enumerate() {
        *x = (2.0 * core::f64::consts::PI * (i as f64 + 0.5) / REPS as f64 - core::f64::consts::PI)
            as f32;
    }
    let at_l = |t: f32| libm::atan2f(libm::sinf(t), libm::cosf(t));
    let at_m = |t: f32| F32Ext::atan2(libm::sinf(t), libm::cosf(t));
    let base = per_call(&mut ic, ipt, xs, |t| libm::sinf(t) + libm::cosf(t));
    let (i_l, i_m) = (
        per_call(&mut ic, ipt, xs, at_l) - base,
        per_call(&mut ic, ipt, xs, at_m) - base,
    );
    let atan2_ref = |t: f64| libm::atan2(libm::sin(t), libm::cos(t));
    report(
        "atan2",
        "libm",
        i_l,
        max_err(xs, at_l, atan2_ref, false),
        "abs",
    );
    report(
        "atan2",
        "micromath",
        i_m,
        max_err(xs, at_m, atan2_ref, false),
        "abs",
    );
    // sin of an oscillator phase (one turn = 2^32): the firmware's table against micromath
    // (phase converted to radians in f32) and libm. The phases are 24-bit multiples of 2^8,
    // stored exactly as f32 integers.
    for (i, x) in xs.iter_mut().enumerate() {
        *x = ((i as u32).wrapping_mul(4_093) & 0x00FF_FFFF) as f32;
    }
    const RAD_PER_LSB: f32 = (2.0 * core::f64::consts::PI / 4_294_967_296.0) as f32;
    let s_t = |x: f32| ferrosid_firmware::trig::sin_turns((x as u32) << 8);
    let s_m = |x: f32| (((x as u32) << 8) as f32 * RAD_PER_LSB).sin();
    let s_l = |x: f32| libm::sinf(((x as u32) << 8) as f32 * RAD_PER_LSB);
    let sin_ref = |x: f64| libm::sin(x * 256.0 * (2.0 * core::f64::consts::PI / 4_294_967_296.0));
    for (variant, f) in [
        ("table", &s_t as &dyn Fn(f32) -> f32),
        ("micromath", &s_m),
        ("libm", &s_l),
    ] {
        let instr = per_call(&mut ic, ipt, xs, f);
        report(
            "sin_phase",
            variant,
            instr,
            max_err(xs, f, sin_ref, false),
            "abs",
        );
    }

    // The failing-frequency list over NB results of which every third fails.
    let mut results = [CheckResult::EMPTY; NB];
    for (i, r) in results.iter_mut().enumerate() {
        r.hz = i as f32;
        r.verdict = if i % 3 == 0 {
            Verdict::Fail
        } else {
            Verdict::Pass
        };
    }
    let mut sum = 0.0f32;
    let t_a = ic.ticks_of(|| {
        for _ in 0..SWEEPS {
            let (l, n) = failed_array(black_box(&results));
            sum += l.get(..n).unwrap_or(&[]).iter().sum::<f32>();
        }
    });
    let t_h = ic.ticks_of(|| {
        for _ in 0..SWEEPS {
            let l = failed_heapless(black_box(&results));
            sum += l.iter().sum::<f32>();
        }
    });
    black_box(sum);
    let per = |t: u32| f64::from(t) * ipt / f64::from(SWEEPS);
    let (l, n) = failed_array(&results);
    let v = failed_heapless(&results);
    let same = l.get(..n) == Some(v.as_slice());
    report("failed_list", "array", per(t_a), 0.0, "none");
    report(
        "failed_list",
        "heapless",
        per(t_h),
        if same { 0.0 } else { 1.0 },
        "none",
    );
    defmt::println!("END");
    exit(EXIT_SUCCESS)
}
