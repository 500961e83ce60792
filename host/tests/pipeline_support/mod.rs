//! Shared by the pipeline, report and fleet tests: a known plant simulated with the library's
//! LTI simulation (not the gap simulator the example data come from), logs written as CSV, and
//! a pipeline file around them.
#![allow(dead_code)]
use ferrosid::lti::{StateSpace, TransferFunction};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

/// Sample time of the simulated logs, s.
pub const TS: f64 = 1e-3;
/// Multisine period, samples (2 Hz line spacing at 1 kHz).
pub const PERIOD: usize = 500;
/// Static gain of the test plant (output units per input unit).
pub const DC_GAIN: f64 = 100.0;
/// Real pole, Hz.
pub const F_POLE: f64 = 1.5;
/// Anti-resonance (zero pair), Hz, and its damping.
pub const F_ANTI: f64 = 20.0;
/// Zero-pair damping.
pub const ZETA_ANTI: f64 = 0.05;
/// Resonance (pole pair), Hz.
pub const F_RES: f64 = 40.0;
/// Resonance damping.
pub const ZETA_RES: f64 = 0.05;

/// G(s) = K·(s²/ωa² + 2ζa·s/ωa + 1) / ((s/ωp + 1)(s²/ωr² + 2ζr·s/ωr + 1)): a collocated
/// two-mass actuator (torque → motor speed) with viscous friction. Continuous, s in rad/s.
pub fn plant_tf() -> TransferFunction {
    let (wp, wa, wr) = (2.0 * PI * F_POLE, 2.0 * PI * F_ANTI, 2.0 * PI * F_RES);
    let num = vec![DC_GAIN / (wa * wa), DC_GAIN * 2.0 * ZETA_ANTI / wa, DC_GAIN];
    // (s/wp + 1)(s²/wr² + 2ζ s/wr + 1)
    let a = [1.0 / wp, 1.0];
    let b = [1.0 / (wr * wr), 2.0 * ZETA_RES / wr, 1.0];
    let den = vec![
        a[0] * b[0],
        a[0] * b[1] + a[1] * b[0],
        a[0] * b[2] + a[1] * b[1],
        a[1] * b[2],
    ];
    TransferFunction::new(num, den, 0.0).expect("test plant")
}

/// The test plant sampled with a zero-order hold at [`TS`].
pub fn plant_discrete() -> StateSpace {
    plant_tf()
        .to_state_space()
        .and_then(|s| s.c2d_zoh(TS))
        .expect("test plant discretisation")
}

/// The workspace's seeded generator (`ferrosid_sim::rng`: the firmware's SplitMix64, Box–Muller
/// normals).
pub use ferrosid_sim::rng::Rng;

/// `periods` periods of a random-phase multisine on the 2 Hz lines 2..=200 Hz, RMS `rms`.
pub fn multisine(periods: usize, rms: f64, rng: &mut Rng) -> Vec<f64> {
    let n = PERIOD;
    let mut v = vec![0.0; n];
    for k in 1..=100 {
        let ph = 2.0 * PI * rng.uniform();
        for (i, x) in v.iter_mut().enumerate() {
            *x += (2.0 * PI * (k * i) as f64 / n as f64 + ph).cos();
        }
    }
    let r = (v.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
    v.iter()
        .map(|x| x * rms / r)
        .cycle()
        .take(periods * n)
        .collect()
}

/// Simulates the plant for `u` (one period of warm-up is simulated and dropped, so the log is
/// in periodic steady state) and adds white output noise of `noise` standard deviation.
pub fn simulate(u: &[f64], noise: f64, rng: &mut Rng) -> Vec<f64> {
    let g = plant_discrete();
    let mut uu = u[u.len() - PERIOD..].to_vec();
    uu.extend_from_slice(u);
    let y = g.simulate_siso(&uu, None).expect("simulation");
    y[PERIOD..]
        .iter()
        .map(|v| v + noise * rng.normal())
        .collect()
}

/// Writes a headerless-time CSV `u,y` with full precision.
pub fn write_csv(path: &Path, u: &[f64], y: &[f64]) {
    let mut s = String::from("u,y\n");
    for (a, b) in u.iter().zip(y) {
        s.push_str(&format!("{a:e},{b:e}\n"));
    }
    std::fs::write(path, s).expect("write csv");
}

/// A fresh scratch directory under the system temp dir.
pub fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ferrosid-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("scratch dir");
    d
}

/// Writes `low.csv` (RMS 0.5), `high.csv` (RMS 1.5) and `val.csv` (RMS 1.0, other phases),
/// 8 periods (4000 samples) each, output noise 0.5 % of the high run's output RMS.
pub fn write_dataset(dir: &Path) {
    let mut rng = Rng::new(0x5eed_1234);
    for (name, rms) in [("low", 0.5), ("high", 1.5), ("val", 1.0)] {
        let u = multisine(8, rms, &mut rng);
        let y = simulate(&u, 0.4, &mut rng);
        write_csv(&dir.join(format!("{name}.csv")), &u, &y);
    }
}

/// The pipeline file used by the tests; `extra_control` and `extra` are appended to the
/// `[control]` table and to the end.
pub fn pipeline_toml(extra_control: &str, extra: &str) -> String {
    format!(
        r#"name = "simulated two-mass plant"

[signals]
fs = 1000.0
input_unit = "A"
output_unit = "rad/s"

[[runs]]
name = "low"
file = "low.csv"

[[runs]]
name = "high"
file = "high.csv"

[validation]
file = "val.csv"

[etfe]
nperseg = 500
overlap = 0
window = "rectangular"

[control]
crossover_hz = 6.0
rolloff_ratio = 4.0
actuator_limit = 2.0
reference_amplitude = 5.0
{extra_control}
{extra}"#
    )
}

/// Writes the dataset and a pipeline file into a scratch directory; returns the TOML path.
pub fn setup(name: &str, extra_control: &str, extra: &str) -> PathBuf {
    let d = scratch(name);
    write_dataset(&d);
    let p = d.join("pipeline.toml");
    std::fs::write(&p, pipeline_toml(extra_control, extra)).expect("write toml");
    p
}

/// Roots of a real polynomial (descending coefficients) by Durand–Kerner iteration: an
/// independent reference for the test plant's and the fleet's modes.
pub fn roots(p: &[f64]) -> Vec<(f64, f64)> {
    let n = p.len() - 1;
    let a: Vec<(f64, f64)> = p.iter().map(|c| (c / p[0], 0.0)).collect();
    let mul = |x: (f64, f64), y: (f64, f64)| (x.0 * y.0 - x.1 * y.1, x.0 * y.1 + x.1 * y.0);
    let div = |x: (f64, f64), y: (f64, f64)| {
        let d = y.0 * y.0 + y.1 * y.1;
        ((x.0 * y.0 + x.1 * y.1) / d, (x.1 * y.0 - x.0 * y.1) / d)
    };
    let eval = |z: (f64, f64)| {
        let mut acc = (0.0, 0.0);
        for c in &a {
            acc = mul(acc, z);
            acc = (acc.0 + c.0, acc.1 + c.1);
        }
        acc
    };
    let scale = a.iter().map(|c| c.0.abs()).fold(1.0, f64::max);
    let mut z: Vec<(f64, f64)> = (0..n)
        .map(|k| {
            let t = 2.0 * PI * k as f64 / n as f64 + 0.4;
            (scale * t.cos(), scale * t.sin())
        })
        .collect();
    for _ in 0..2000 {
        for i in 0..n {
            let mut den = (1.0, 0.0);
            for j in 0..n {
                if i != j {
                    den = mul(den, (z[i].0 - z[j].0, z[i].1 - z[j].1));
                }
            }
            let d = div(eval(z[i]), den);
            z[i] = (z[i].0 - d.0, z[i].1 - d.1);
        }
    }
    z
}

/// Natural frequency (Hz) and damping of the complex root with Im > 0 of a continuous
/// polynomial, sorted by frequency.
pub fn oscillatory_modes(den: &[f64]) -> Vec<(f64, f64)> {
    let mut m: Vec<(f64, f64)> = roots(den)
        .into_iter()
        .filter(|r| r.1 > 1e-6 * r.0.hypot(r.1))
        .map(|(re, im)| {
            let w = re.hypot(im);
            (w / (2.0 * PI), -re / w)
        })
        .collect();
    m.sort_by(|a, b| a.0.total_cmp(&b.0));
    m
}
