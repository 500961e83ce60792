//! The generated MPC in closed loop on the emulated Cortex-M4F: a constrained step of the
//! reference on the simulated example axis (the identified model G0 of the bundled example,
//! whose state the MPC feeds back), with the per-step instruction count.
//!
//! Built only with the `mpc` feature and `FERROSID_MPC_MODEL` naming the Rust module written
//! by `ferrosid codegen` for a pipeline run with `[control] method = "mpc"` (build.rs copies it
//! to `$OUT_DIR/mpc_model.rs`). Run under `qemu-system-arm ... -icount shift=0`.
//!
//! Per sample k: y = C x; u = MpcQp::step(x, r, u_prev) (timed alone with SysTick);
//! x ← A x + B u (f32, the header's matrices). Output (defmt): `MPC n=.. nx=.. iterations=..
//! samples=.. r=..`, one `T k y u` line per sample, `ICOUNT mean=.. max=.. ipt=..` (instructions
//! per `step`, calibrated instructions per tick), `STACK high_water=..` (bytes of stack used
//! from the top, the whole image: main's frame with the warm start, the step, the logging) and
//! `RAILS crossed=.. max_abs_u=..
//! max_abs_du=..`. Exit code 0, 1 when a rail or the rate limit was crossed (or the counter is
//! not an instruction counter).
#![no_std]
#![no_main]

use core::hint::black_box;

use cortex_m_rt::entry;
use ferrosid_firmware::mpc::{MpcQp, MpcWarm};
use ferrosid_qemu::{exit, InstructionCounter, EXIT_FAILURE, EXIT_SUCCESS};

#[allow(dead_code, clippy::all)]
mod flashed {
    include!(concat!(env!("OUT_DIR"), "/mpc_model.rs"));
}
use flashed::{MPC_N, MPC_NX, N_STATES};

/// Samples simulated.
const SAMPLES: usize = 1500;

/// The flashed QP, built from the generated consts.
static QP: MpcQp<MPC_N, MPC_NX> = MpcQp {
    k: flashed::MPC_K,
    gx: flashed::MPC_GX,
    gr: flashed::MPC_GR,
    two_r_rate: flashed::MPC_TWO_R_RATE,
    sigma: flashed::MPC_SIGMA,
    rho: flashed::MPC_RHO,
    u_min: flashed::MPC_U_MIN,
    u_max: flashed::MPC_U_MAX,
    du_max: flashed::MPC_DU_MAX,
    iterations: flashed::MPC_ITERATIONS,
};

/// The same ADMM step as `MpcQp::step` with nalgebra's fixed-size matrices for the dense
/// products (K·rhs and G_x·x) and vectors for the iterate: the comparison the issue asks for.
mod na {
    use super::{MPC_N, MPC_NX, QP};
    use nalgebra::{SMatrix, SVector};

    type V = SVector<f32, MPC_N>;

    /// The iterate (warm start).
    #[derive(Default)]
    pub struct Warm {
        u: V,
        z_box: V,
        z_rate: V,
        l_box: V,
        l_rate: V,
    }

    /// K and G_x as nalgebra matrices (built once).
    pub struct Mats {
        k: SMatrix<f32, MPC_N, MPC_N>,
        gx: SMatrix<f32, MPC_N, MPC_NX>,
        gr: V,
    }

    impl Mats {
        pub fn new() -> Self {
            Mats {
                k: SMatrix::from_fn(|i, j| QP.k[i][j]),
                gx: SMatrix::from_fn(|i, j| QP.gx[i][j]),
                gr: V::from_fn(|i, _| QP.gr[i]),
            }
        }

        fn clamp(v: f32, lo: f32, hi: f32) -> f32 {
            if v < lo {
                lo
            } else if v > hi {
                hi
            } else {
                v
            }
        }

        pub fn step(&self, w: &mut Warm, x: &[f32; MPC_NX], r: f32, u_prev: f32) -> f32 {
            let xv = SVector::<f32, MPC_NX>::from_fn(|i, _| x[i]);
            let mut f = self.gx * xv - self.gr * r;
            f[0] -= QP.two_r_rate * u_prev;
            let (rho, inv_rho) = (QP.rho, 1.0 / QP.rho);
            for _ in 0..QP.iterations {
                let a = w.z_box * rho - w.l_box;
                let b = w.z_rate * rho - w.l_rate;
                let mut rhs = w.u * QP.sigma - f + a + b;
                for j in 0..MPC_N - 1 {
                    rhs[j] -= b[j + 1];
                }
                w.u = self.k * rhs;
                for i in 0..MPC_N {
                    let mb = w.u[i];
                    let zb = Self::clamp(mb + w.l_box[i] * inv_rho, QP.u_min, QP.u_max);
                    w.l_box[i] += rho * (mb - zb);
                    w.z_box[i] = zb;
                    let (mr, lo, hi) = if i == 0 {
                        (w.u[0], u_prev - QP.du_max, u_prev + QP.du_max)
                    } else {
                        (w.u[i] - w.u[i - 1], -QP.du_max, QP.du_max)
                    };
                    let zr = Self::clamp(mr + w.l_rate[i] * inv_rho, lo, hi);
                    w.l_rate[i] += rho * (mr - zr);
                    w.z_rate[i] = zr;
                }
            }
            let u = Self::clamp(w.z_box[0], u_prev - QP.du_max, u_prev + QP.du_max);
            let u = Self::clamp(u, QP.u_min, QP.u_max);
            for v in [
                &mut w.u,
                &mut w.z_box,
                &mut w.z_rate,
                &mut w.l_box,
                &mut w.l_rate,
            ] {
                for i in 0..MPC_N - 1 {
                    v[i] = v[i + 1];
                }
            }
            u
        }
    }
}

/// Reference step height: the first semihosting argument `r=<value>` (default 5).
fn reference() -> f32 {
    let mut r = 5.0f32;
    if let Ok(args) = semihosting::experimental::env::args::<256>() {
        for a in (&args).flatten() {
            if let Some(v) = a.strip_prefix("r=") {
                if let Ok(v) = v.parse::<f32>() {
                    r = v;
                }
            }
        }
    }
    r
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
        defmt::println!("MPC error: SysTick does not advance; run under qemu -icount shift=0");
        exit(EXIT_FAILURE)
    }
    let ipt = (i2 - i1) as f64 / (t2 - t1) as f64;
    let r = reference();
    defmt::println!(
        "MPC n={=usize} nx={=usize} iterations={=u16} samples={=usize} r={=f32}",
        MPC_N,
        MPC_NX,
        QP.iterations,
        SAMPLES,
        r
    );
    let use_na = ferrosid_qemu::has_arg("nalgebra");
    defmt::println!("SOLVER {=str}", if use_na { "nalgebra" } else { "loops" });
    let mats = na::Mats::new();
    let mut na_warm = na::Warm::default();
    let mut warm = MpcWarm::<MPC_N>::default();
    let mut x = [0.0f32; N_STATES];
    let mut u_prev = 0.0f32;
    let (mut sum_ticks, mut max_ticks, mut empty_max) = (0u64, 0u32, 0u32);
    let (mut max_u, mut max_du) = (0.0f32, 0.0f32);
    let mut crossed = 0u32;
    for k in 0..SAMPLES {
        let mut y = 0.0f32;
        for (c, xv) in flashed::C[0].iter().zip(x.iter()) {
            y += c * xv;
        }
        let mut u = 0.0f32;
        let ticks = ic.ticks_of(|| {
            u = if use_na {
                mats.step(black_box(&mut na_warm), black_box(&x), black_box(r), u_prev)
            } else {
                QP.step(black_box(&mut warm), black_box(&x), black_box(r), u_prev)
            };
        });
        empty_max = empty_max.max(ic.ticks_of(|| black_box(())));
        sum_ticks += u64::from(ticks);
        max_ticks = max_ticks.max(ticks);
        let du = u - u_prev;
        if u < QP.u_min || u > QP.u_max || du.abs() > QP.du_max * (1.0 + 1e-6) {
            crossed += 1;
        }
        max_u = max_u.max(u.abs());
        max_du = max_du.max(du.abs());
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
        u_prev = u;
    }
    // Per step: ticks minus the counter reads (the empty closure), in instructions.
    let empty = f64::from(empty_max);
    let mean = (sum_ticks as f64 / SAMPLES as f64 - empty) * ipt;
    let max = (f64::from(max_ticks) - empty) * ipt;
    defmt::println!("ICOUNT mean={=f64} max={=f64} ipt={=f64}", mean, max, ipt);
    defmt::println!("STACK high_water={=usize}", painted.high_water());
    defmt::println!(
        "RAILS crossed={=u32} max_abs_u={=f32} max_abs_du={=f32}",
        crossed,
        max_u,
        max_du
    );
    exit(if crossed == 0 {
        EXIT_SUCCESS
    } else {
        EXIT_FAILURE
    })
}
