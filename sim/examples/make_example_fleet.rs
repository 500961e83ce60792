//! Writes the small example fleet in `examples/fleet/` (repository root): six two-mass
//! actuators with spread parameters, each logged at two excitation amplitudes, simulated with
//! the project's plant simulator ([`ferrosid_sim::plant::simulate`]).
//!
//! `cargo run --release -p ferrosid-sim --example make_example_fleet [-- OUT_DIR]`
//!
//! Per unit `SN000k/`: `low.csv` and `high.csv`, 3000 samples at 1 kHz (no time column; the
//! pipeline template gives `fs`), columns `u` (torque command in mN·m, integer: a 1 mN·m DAC
//! step) and `y` (motor speed in mrad/s, integer: a 1 mrad/s encoder speed step). The input is
//! the kind of end-of-line excitation the firmware generates: a random-phase multisine with
//! equal amplitudes on every 2 Hz line from 2 to 200 Hz (period 500 samples, 0.5 s), RMS
//! 80 mN·m (`low`) and 200 mN·m (`high`, other phases); logging starts one period after the
//! excitation, so the six logged periods are in steady state (analyse them with period-aligned
//! rectangular-window segments: no leakage). The speed sensor adds white noise of 2 mrad/s
//! standard deviation before
//! quantisation. Unit SN0004 is the fleet's bad apple: 20 mN·m of Coulomb friction on the
//! motor side (a dragging bearing); the others have none.
//!
//! `units.json` records every unit's physical parameters (the ground truth the fleet test checks
//! the identified resonances against). Parameters: the default two-mass actuator
//! ([`Plant::two_mass`]) with the shaft stiffness k, the load inertia jl and the shaft damping c
//! spread uniformly by ±15 %, ±10 % and ±20 %. Everything is seeded: running this again writes
//! byte-identical files.
use ferrosid::gap::effect::Effect;
use ferrosid_sim::plant::{simulate, Plant, SimSettings, TwoMass};
use ferrosid_sim::rng::Rng;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

const TS: f64 = 1e-3;
const N: usize = 3000;
/// Multisine period, samples.
const PERIOD: usize = 500;
const UNITS: usize = 6;
/// The unit with a dragging bearing (Coulomb friction).
const BAD_UNIT: usize = 4;

fn main() {
    let out = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            let sim = Path::new(env!("CARGO_MANIFEST_DIR"));
            sim.parent().unwrap_or(sim).join("examples/fleet")
        });
    if let Err(e) = run(&out) {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}

fn run(out: &Path) -> Result<(), Box<dyn std::error::Error>> {
    let Plant::TwoMass(base) = Plant::two_mass() else {
        return Err("the default plant must be the two-mass actuator".into());
    };
    let mut rng = Rng::new(20_241_122);
    let mut manifest = String::from("{\n  \"units\": [\n");
    for unit in 1..=UNITS {
        let serial = format!("SN{unit:04}");
        let mut spread = |rel: f64| 1.0 + rel * (2.0 * rng.uniform() - 1.0);
        let p = TwoMass {
            k: base.k * spread(0.15),
            jl: base.jl * spread(0.10),
            c: base.c * spread(0.20),
            ..base
        };
        let plant = Plant::TwoMass(p);
        let coulomb = if unit == BAD_UNIT { 0.020 } else { 0.0 };
        let effect = (coulomb > 0.0).then_some(Effect::CoulombFriction { level: coulomb });
        let dir = out.join(&serial);
        std::fs::create_dir_all(&dir)?;
        for (name, rms, seed) in [
            ("low", 0.08, 2 * unit as u64),
            ("high", 0.20, 2 * unit as u64 + 1),
        ] {
            // Commanded torque, quantised to the 1 mN·m DAC step; the plant sees the quantised
            // value.
            let period = multisine(PERIOD, 2.0, 200.0, rms, &mut rng)?;
            let u: Vec<f64> = period
                .iter()
                .cycle()
                .take(N + PERIOD)
                .map(|v| (v * 1e3).round() / 1e3)
                .collect();
            let y = simulate(
                &plant,
                effect.as_ref(),
                &u,
                &SimSettings {
                    ts: TS,
                    substeps: 8,
                    noise_std: 0.002,
                    seed: 1000 + seed,
                },
            )?;
            let mut text = String::with_capacity(12 * N);
            text.push_str("u,y\n");
            // The first period is the transient before logging starts.
            for (uk, yk) in u.iter().zip(&y).skip(PERIOD) {
                writeln!(
                    text,
                    "{},{}",
                    (uk * 1e3).round() as i64,
                    (yk * 1e3).round() as i64
                )?;
            }
            std::fs::write(dir.join(format!("{name}.csv")), text)?;
        }
        writeln!(
            manifest,
            "    {{\"serial\": \"{serial}\", \"jm\": {:e}, \"jl\": {:e}, \"k\": {:e}, \"c\": {:e}, \
             \"bm\": {:e}, \"bl\": {:e}, \"coulomb\": {:e}}}{}",
            p.jm,
            p.jl,
            p.k,
            p.c,
            p.bm,
            p.bl,
            coulomb,
            if unit < UNITS { "," } else { "" }
        )?;
        eprintln!("wrote {}", dir.display());
    }
    manifest.push_str(
        "  ],\n  \"model\": \"two-mass actuator: torque (N·m) on the motor inertia jm, shaft k, c \
         to the load inertia jl, viscous friction bm, bl, Coulomb friction (N·m) on the motor side; output motor speed (rad/s); logs in \
         mN·m and mrad/s\"\n}\n",
    );
    std::fs::write(out.join("units.json"), manifest)?;
    Ok(())
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
    let df = 1.0 / (n as f64 * TS);
    let mut v = vec![0.0; n];
    for k in 1..n / 2 {
        let f = k as f64 * df;
        if f < f_lo || f > f_hi {
            continue;
        }
        let phase = 2.0 * std::f64::consts::PI * rng.uniform();
        for (i, x) in v.iter_mut().enumerate() {
            *x += (2.0 * std::f64::consts::PI * k as f64 * i as f64 / n as f64 + phase).cos();
        }
    }
    let r = (v.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
    if r.is_nan() || r <= 0.0 {
        return Err("multisine has no line in the requested band".into());
    }
    v.iter_mut().for_each(|x| *x *= rms / r);
    Ok(v)
}
