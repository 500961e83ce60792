//! Writes the bundled example logs in `examples/data/` (repository root) with the project's own
//! plant simulator ([`ferrosid_sim::plant::simulate`]).
//!
//! `cargo run --release -p ferrosid-sim --example make_example_data [-- OUT_DIR]`
//! (default `OUT_DIR`: `examples/data` relative to the workspace root).
//!
//! The plant is the two-mass actuator [`Plant::two_mass`] (torque in N·m → motor speed in
//! rad/s): motor inertia jm = 2e-4 kg·m², load inertia jl = 6e-4 kg·m², shaft stiffness
//! k = 15 N·m/rad, shaft damping c = 4.7e-3 N·m·s/rad, viscous friction bm = 2e-3 and
//! bl = 3e-3 N·m·s/rad; anti-resonance 25.16 Hz, resonance 50.33 Hz (damping ratio 0.063),
//! real pole 0.995 Hz (roots of the closed-form transfer function in examples/README.md). The
//! "real" plant also has Coulomb friction of 0.008 N·m on
//! the motor side (the effect `ferrosid gap` should find) and white speed-sensor noise of
//! 0.01 rad/s standard deviation. Samples are written with 5 significant digits.
//! Everything is seeded: running this again writes byte-identical files.
//!
//! Files (1 kHz, columns `t` in s, `u` in N·m, `y` in rad/s):
//! * `two_mass_low.csv`  — filtered Gaussian noise (two first-order low-pass sections at
//!   120 Hz), input RMS 0.05 N·m, 4000 samples;
//! * `two_mass_high.csv` — another realisation of the same kind, RMS 0.15 N·m, 4000 samples;
//! * `two_mass_validate.csv` — random-phase multisine, flat on the 1 Hz lines 1..200 Hz, period
//!   1000 samples (1 s), 4 periods, RMS 0.10 N·m — a different excitation, for validation;
//! * `two_mass_sim.json` — the designer's nominal linear model (the `--sim` file of
//!   `ferrosid gap`), continuous time, with the CAD values k = 16.5 N·m/rad (+10 %) and
//!   jl = 5.7e-4 kg·m² (−5 %), other parameters as above, and no Coulomb friction.
use ferrosid::gap::effect::Effect;
use ferrosid_sim::plant::{simulate, Plant, SimSettings, TwoMass};
use ferrosid_sim::rng::Rng;
use num_complex::Complex64;
use realfft::RealFftPlanner;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Sample time, s.
const TS: f64 = 1e-3;
/// Samples per log.
const N: usize = 4000;
/// Coulomb friction of the "real" plant, N·m.
const COULOMB: f64 = 0.008;
/// Speed-sensor noise standard deviation, rad/s.
const NOISE_STD: f64 = 0.01;

fn main() {
    let out = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            let sim = Path::new(env!("CARGO_MANIFEST_DIR"));
            sim.parent().unwrap_or(sim).join("examples/data")
        });
    if let Err(e) = run(&out) {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}

fn run(out: &Path) -> Result<(), Box<dyn std::error::Error>> {
    std::fs::create_dir_all(out)?;
    let plant = Plant::two_mass();
    let effect = Effect::CoulombFriction { level: COULOMB };
    let mut rng = Rng::new(20_240_611);
    let u_low = filtered_noise(N, 120.0, 0.05, &mut rng);
    let u_high = filtered_noise(N, 120.0, 0.15, &mut rng);
    let period = multisine(1000, 1.0, 200.0, 0.10, &mut rng)?;
    let u_val: Vec<f64> = period.iter().copied().cycle().take(N).collect();
    for (name, u, seed) in [
        ("two_mass_low.csv", &u_low, 11u64),
        ("two_mass_high.csv", &u_high, 12),
        ("two_mass_validate.csv", &u_val, 13),
    ] {
        let y = simulate(
            &plant,
            Some(&effect),
            u,
            &SimSettings {
                ts: TS,
                substeps: 8,
                noise_std: NOISE_STD,
                seed,
            },
        )?;
        let mut text = String::with_capacity(32 * N);
        text.push_str("t,u,y\n");
        for (k, (uk, yk)) in u.iter().zip(&y).enumerate() {
            writeln!(text, "{:.3},{:.4e},{:.4e}", k as f64 * TS, uk, yk)?;
        }
        std::fs::write(out.join(name), text)?;
        eprintln!("wrote {}", out.join(name).display());
    }
    let Plant::TwoMass(p) = plant else {
        return Err("the example plant must be the two-mass actuator".into());
    };
    let nominal = Plant::TwoMass(TwoMass {
        k: p.k * 1.10,
        jl: p.jl * 0.95,
        ..p
    });
    let mut json = nominal.sim_json()?;
    json.push('\n');
    std::fs::write(out.join("two_mass_sim.json"), json)?;
    eprintln!("wrote {}", out.join("two_mass_sim.json").display());
    Ok(())
}

/// Gaussian noise through two first-order low-pass sections at `f_c` Hz, scaled to `rms`.
fn filtered_noise(n: usize, f_c: f64, rms: f64, rng: &mut Rng) -> Vec<f64> {
    let alpha = (-2.0 * std::f64::consts::PI * f_c * TS).exp();
    let (mut s1, mut s2) = (0.0, 0.0);
    let mut v: Vec<f64> = (0..n)
        .map(|_| {
            s1 = alpha * s1 + (1.0 - alpha) * rng.normal();
            s2 = alpha * s2 + (1.0 - alpha) * s1;
            s2
        })
        .collect();
    scale_to_rms(&mut v, rms);
    v
}

/// One period (`n` samples) of a random-phase multisine with equal amplitudes on the DFT lines
/// in `[f_lo, f_hi]` Hz, scaled to `rms`.
fn multisine(
    n: usize,
    f_lo: f64,
    f_hi: f64,
    rms: f64,
    rng: &mut Rng,
) -> Result<Vec<f64>, Box<dyn std::error::Error>> {
    let ifft = RealFftPlanner::<f64>::new().plan_fft_inverse(n);
    let mut spec = ifft.make_input_vec();
    let df = 1.0 / (n as f64 * TS);
    for (k, c) in spec.iter_mut().enumerate() {
        let f = k as f64 * df;
        if k > 0 && 2 * k < n && f >= f_lo && f <= f_hi {
            *c = Complex64::from_polar(1.0, 2.0 * std::f64::consts::PI * rng.uniform());
        }
    }
    let mut v = ifft.make_output_vec();
    ifft.process(&mut spec, &mut v)?;
    scale_to_rms(&mut v, rms);
    Ok(v)
}

fn scale_to_rms(v: &mut [f64], rms: f64) {
    let r = (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
    if r > 0.0 {
        v.iter_mut().for_each(|x| *x *= rms / r);
    }
}
