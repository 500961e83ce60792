//! The "where" and "how far" parts of the gap diagnosis on plants whose mismatch is known in
//! closed form: an exact sim (nothing to find), a sim with 1.5× the plant's gain (multiplicative
//! error exactly 1/3 at every frequency, nominal NRMSE from the closed-form residual −0.5·y),
//! and input nonlinearities that act only at one amplitude (dead zone: small inputs;
//! saturation: large inputs), which must show up as amplitude dependence; for saturation the
//! linear re-fit's residual must concentrate where |u| is largest.
use ferrosid::data::Log;
use ferrosid::gap::effect::Effect;
use ferrosid::gap::{diagnose, Diagnosis, GapOptions};
use ferrosid::lti::StateSpace;
use ferrosid_sim::benchmark::{filtered_noise, multisine};
use ferrosid_sim::plant::{simulate, Plant, SimSettings};
use ferrosid_sim::rng::Rng;

const TS: f64 = 1e-3;
const N: usize = 8192;

fn log(name: &str, u: Vec<f64>, y: Vec<f64>) -> Log {
    Log::siso(name, TS, u, y)
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

fn std_dev(v: &[f64]) -> f64 {
    let m = v.iter().sum::<f64>() / v.len() as f64;
    (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
}

struct Run {
    d: Diagnosis,
    /// Noise-free validation output of the true plant.
    y_val_clean: Vec<f64>,
    /// Measured validation output.
    y_val: Vec<f64>,
    noise_std: f64,
}

/// Two-mass actuator logs (low RMS 0.05 N·m, high 0.15 N·m, multisine validation 0.1 N·m), 1 %
/// noise, with `effect`, diagnosed against `sim`.
fn run(effect: Option<Effect>, sim: &StateSpace) -> Run {
    let plant = Plant::two_mass();
    let mut rng = Rng::new(77);
    let u_low = filtered_noise(N, TS, 120.0, 0.05, &mut rng);
    let u_high = filtered_noise(N, TS, 120.0, 0.15, &mut rng);
    let u_val = multisine(N, TS, 0.2, 120.0, 0.1, &mut rng);
    let clean = SimSettings {
        ts: TS,
        substeps: 8,
        noise_std: 0.0,
        seed: 0,
    };
    let noise_std = 0.01 * rms(&simulate(&plant, None, &u_low, &clean).unwrap());
    let meas = |u: &[f64], seed: u64| {
        simulate(
            &plant,
            effect.as_ref(),
            u,
            &SimSettings {
                noise_std,
                seed,
                ..clean
            },
        )
        .unwrap()
    };
    let train = vec![
        log("low.csv", u_low.clone(), meas(&u_low, 1)),
        log("high.csv", u_high.clone(), meas(&u_high, 2)),
    ];
    let y_val = meas(&u_val, 3);
    let y_val_clean = simulate(&plant, effect.as_ref(), &u_val, &clean).unwrap();
    let val = log("val.csv", u_val, y_val.clone());
    let d = diagnose(sim, &train, &val, &GapOptions::default()).unwrap();
    eprintln!("{}", d.report.to_text());
    Run {
        d,
        y_val_clean,
        y_val,
        noise_std,
    }
}

fn exact_sim() -> StateSpace {
    Plant::two_mass()
        .physical()
        .unwrap()
        .sys
        .c2d_zoh(TS)
        .unwrap()
}

#[test]
fn exact_sim_leaves_only_noise() {
    let r = run(None, &exact_sim());
    let rep = &r.d.report;
    assert_eq!(rep.verdict, "none");
    // The nominal sim's error is the measurement noise alone: NRMSE = σ/std(y) up to the
    // sampling spread of 8192 noise samples (±2 %) and the warm-up.
    let w = rep.settings.warmup_samples;
    let expected = r.noise_std / std_dev(&r.y_val[w..]);
    assert!(
        (rep.gap_before / expected - 1.0).abs() < 0.05,
        "gap_before {} vs noise-only {expected}",
        rep.gap_before
    );
    // Re-fitting cannot beat the noise floor by more than over-fitting allows.
    assert!(rep.gap_linear > 0.95 * expected && rep.gap_linear < 1.05 * expected);
    // The noise floor read off the residual spectrum above the multisine's band (white noise)
    // is that same σ/std(y), within the spread of a median of Welch bins.
    assert_eq!(rep.noise_floor.method, "off_band_residual");
    assert!(
        (rep.noise_floor.nrmse / expected - 1.0).abs() < 0.15,
        "noise floor {} vs {expected}",
        rep.noise_floor.nrmse
    );
    assert!(rep.where_.bands_hz.is_empty(), "{:?}", rep.where_.bands_hz);
    assert!(!rep.where_.amplitude_dependent);
    assert!(rep.where_.worst_error < 0.2);
}

#[test]
fn gain_mismatch_gives_a_flat_one_third_multiplicative_error() {
    let mut sim = exact_sim();
    sim.c = &sim.c * faer::Scale(1.5);
    let r = run(None, &sim);
    let rep = &r.d.report;
    let wh = &rep.where_;
    // |G − 1.5G|/|1.5G| = 1/3 at every frequency; the H1 estimate's noise spreads it a little.
    let mut e: Vec<f64> = wh
        .mult_error
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    assert!(e.len() > 100, "only {} gated bins", e.len());
    e.sort_by(f64::total_cmp);
    let median = e[e.len() / 2];
    assert!(
        (median - 1.0 / 3.0).abs() < 0.01,
        "median multiplicative error {median}"
    );
    // One band covering (nearly) all gated bins, above the 20 % threshold.
    assert!(!wh.bands_hz.is_empty());
    // Nominal residual: y − 1.5·y_clean = −0.5·y_clean + noise.
    let w = rep.settings.warmup_samples;
    let resid: Vec<f64> = r.y_val[w..]
        .iter()
        .zip(&r.y_val_clean[w..])
        .map(|(y, c)| y - 1.5 * c)
        .collect();
    let expected = rms(&resid) / std_dev(&r.y_val[w..]);
    assert!(
        (rep.gap_before - expected).abs() < 1e-3 * expected,
        "{} vs {expected}",
        rep.gap_before
    );
    // The linear re-fit removes the gain error down to the noise floor.
    assert!(rep.gap_linear < 0.02, "gap_linear {}", rep.gap_linear);
    assert_eq!(rep.verdict, "none");
}

#[test]
fn dead_zone_is_amplitude_dependent() {
    let r = run(Some(Effect::Deadzone { width: 0.06 }), &exact_sim());
    let wh = &r.d.report.where_;
    assert!(
        wh.amplitude_dependent,
        "amplitude change {}",
        wh.amplitude_change
    );
    assert_eq!(r.d.report.verdict, "deadzone");
}

#[test]
fn saturation_is_amplitude_dependent_and_concentrates_at_input_extremes() {
    let r = run(Some(Effect::Saturation { limit: 0.12 }), &exact_sim());
    let wh = &r.d.report.where_;
    assert!(
        wh.amplitude_dependent,
        "amplitude change {}",
        wh.amplitude_change
    );
    let ext = wh
        .residual_regions
        .iter()
        .find(|g| g.region == "input_extremes")
        .unwrap();
    assert!(ext.concentrates, "input_extremes ratio {}", ext.rms_ratio);
    assert_eq!(r.d.report.verdict, "saturation");
}
