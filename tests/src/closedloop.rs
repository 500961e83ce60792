//! The closed-loop proof on target: a position servo (pure inertia J θ'' = K·w − F, θ measured)
//! under the generated PID, with a dead zone on the drive or stick-slip friction, run by the
//! `closedloop` image of `firmware/app` under QEMU, next to the host's limit-cycle analysis
//! (`ferrosid::limit_cycle`) of the same loop.
//!
//! Why a limit cycle genuinely exists here:
//! * The loop gain L(s) = K·(K_d s² + K_p s + K_i)/(J s³) of a PID on an inertia is of type 3:
//!   its Nyquist curve starts at phase −270° and crosses the negative real axis at
//!   ω₁₈₀ ≈ √(K_i/K_d) with |L| = K K_p K_d/(J K_i) > 1 (Routh: stable iff K K_p K_d > J K_i).
//!   It is *conditionally* stable: a gain below 1/|L(jω₁₈₀)| destabilises it. A dead zone's
//!   describing function N(A) grows from 0 (A <= width/2) to 1, so at small amplitude it
//!   lowers the gain into the unstable range, at large amplitude it does not: the oscillation
//!   grows or decays to the amplitude where N(A) = 1/|L(jω₁₈₀)|, a stable limit cycle near
//!   ω₁₈₀ (harmonic balance, Loeb's criterion).
//! * Stick-slip friction with a breakaway level above the sliding level makes the integrator
//!   "hunt": stuck off target, the integral of the error winds the torque up to the breakaway
//!   level, the mass breaks free against the lower sliding friction, overshoots and sticks on
//!   the other side (Armstrong-Hélouvry; Olsson & Åström 2001). Pure Coulomb friction
//!   (breakaway = sliding level) does not hunt in this loop: the friction's linear part
//!   G_v/(1 + C G) = S/(J s) crosses the negative real axis only where Re L = −1 with Im L > 0,
//!   which this L never reaches (the describing function predicts no cycle, and the simulation
//!   settles).
use std::path::{Path, PathBuf};

use faer::Mat;
use ferrosid::lti::StateSpace;
use ferrosid::robust::pid::{DiscretePid, Pid};
use ferrosid_codegen as cg;
use num_complex::Complex64;

use crate::e2e::{build_app_image_with, write_if_changed};
use crate::{decode_defmt, repo_root, run_qemu, Error, LogLine, RunOptions};

/// Control sample time, s.
pub const TS: f64 = 1e-3;
/// Inertia J, kg·m².
pub const INERTIA: f64 = 1e-4;
/// Actuator gain K, N·m per input unit (1: friction levels in N·m are input units).
pub const GAIN: f64 = 1.0;

/// The continuous PID: triple closed-loop pole at 62.8 rad/s for K_p and K_d, integral gain
/// raised to 110 1/s so the conditionally stable crossing sits at |L| ≈ 2 (a cycle with a
/// near-sinusoidal command, where the describing function is accurate), derivative filter
/// 0.5 ms.
pub fn pid() -> Pid {
    Pid {
        kp: 1.184,
        ki: 110.0,
        kd: 0.018_85,
        tau_f: 5e-4,
        rolloff: None,
    }
}

/// The Tustin form of [`pid`] at [`TS`] (no prewarp).
pub fn discrete_pid() -> DiscretePid {
    pid().discretize(TS, None).expect("discretize the PID")
}

/// The plant θ(s)/u(s) = K/(J s²), states (θ, ω).
pub fn plant_continuous() -> StateSpace {
    let a = Mat::from_fn(2, 2, |i, j| if (i, j) == (0, 1) { 1.0 } else { 0.0 });
    let b = Mat::from_fn(2, 1, |i, _| if i == 1 { GAIN / INERTIA } else { 0.0 });
    let c = Mat::from_fn(1, 2, |_, j| if j == 0 { 1.0 } else { 0.0 });
    StateSpace::new(a, b, c, Mat::zeros(1, 1), 0.0).expect("plant")
}

fn rows(m: &Mat<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|i| (0..m.ncols()).map(|j| m[(i, j)]).collect())
        .collect()
}

/// Torque lag of the Coulomb-friction loop, s (a motor's current loop).
pub const LAG: f64 = 3e-3;

/// The PID of the Coulomb-friction loop behind the torque lag: integral time K_p/K_i = 1.2 ms,
/// shorter than [`LAG`], the condition for a Coulomb cycle (host/tests/limit_cycle_coulomb_lag.rs
/// explains it); derivative time 24 ms keeps the frictionless loop stable.
pub fn lag_pid() -> Pid {
    Pid {
        kp: 3.0,
        ki: 2500.0,
        kd: 0.072,
        tau_f: 5e-4,
        rolloff: None,
    }
}

/// The motor with the torque lag: states (θ rad, ω rad/s, T N·m), θ' = ω, J ω' = T,
/// τ T' = K u − T, θ measured.
pub fn lag_plant_continuous() -> StateSpace {
    let a = Mat::from_fn(3, 3, |i, j| match (i, j) {
        (0, 1) => 1.0,
        (1, 2) => 1.0 / INERTIA,
        (2, 2) => -1.0 / LAG,
        _ => 0.0,
    });
    let b = Mat::from_fn(3, 1, |i, _| if i == 2 { GAIN / LAG } else { 0.0 });
    let c = Mat::from_fn(1, 3, |_, j| if j == 0 { 1.0 } else { 0.0 });
    StateSpace::new(a, b, c, Mat::zeros(1, 1), 0.0).expect("lag plant")
}

/// The generator input: the ZOH plant, the discrete PID and `compensation`.
pub fn codegen_input(prefix: &str, compensation: Option<cg::Compensation>) -> cg::CodegenInput {
    codegen_input_for(prefix, &plant_continuous(), &pid(), compensation)
}

/// [`codegen_input`] for another plant and PID.
pub fn codegen_input_for(
    prefix: &str,
    plant: &StateSpace,
    pid: &Pid,
    compensation: Option<cg::Compensation>,
) -> cg::CodegenInput {
    let zoh = plant.c2d_zoh(TS).expect("ZOH plant");
    let dp = pid.discretize(TS, None).expect("discretize the PID");
    cg::CodegenInput {
        prefix: prefix.into(),
        model: cg::DiscreteModel {
            ts_s: TS,
            matrices: cg::Matrices {
                a: rows(&zoh.a),
                b: rows(&zoh.b),
                c: rows(&zoh.c),
                d: rows(&zoh.d),
            },
        },
        continuous: None,
        pid: Some(cg::PidGains {
            ts_s: TS,
            kp: dp.kp,
            ki_d: dp.ki_d,
            a_d: dp.a_d,
            b_d: dp.b_d,
            rolloff: dp.rolloff.map(|r| cg::Biquad { b: r.b, a: r.a }),
            prewarp_hz: None,
            continuous: None,
        }),
        state_controller: None,
        weight: cg::WeightCoefficients {
            num: vec![0.2],
            den: vec![1.0],
            note: "flat 20 % (not used by the closed-loop image)".into(),
        },
        self_id: cg::SelfIdSettings {
            welch_n: 256,
            check_hz: vec![10.0],
            coherence_gate: 0.9,
            averages: 2,
            settle_periods: 1,
            excitation_rms: 0.1,
            excitation_max_hz: 100.0,
            min_checked: 1,
            closed_loop: None,
        },
        provenance: cg::Provenance {
            tool: "ferrosid-tests closedloop".into(),
            sources: vec![],
            receipts: vec![],
            notes: vec!["closed-loop limit-cycle proof (tests/src/closedloop.rs)".into()],
        },
        operating_point: None,
        compensation,
    }
}

/// Generates the Rust module for `input` into `dir` and builds the plain `closedloop` image
/// (free run only: `check=on` is a set-up error) around it in its own target directory
/// (`target/qemu-closedloop-<prefix>`).
pub fn build_image(input: &cg::CodegenInput, dir: &Path) -> Result<PathBuf, String> {
    build_variant(input, dir, false)
}

/// [`build_image`] with the closed-loop power-up check (`check=on`; the app's cargo feature
/// `closed-loop-check`), in `target/qemu-closedloop-<prefix>-check`.
pub fn build_check_image(input: &cg::CodegenInput, dir: &Path) -> Result<PathBuf, String> {
    build_variant(input, dir, true)
}

fn build_variant(input: &cg::CodegenInput, dir: &Path, check: bool) -> Result<PathBuf, String> {
    let g = cg::generate(input).map_err(|e| e.to_string())?;
    let module = dir.join(&g.rs_file_name);
    write_if_changed(&module, &g.rust_module)?;
    let (suffix, features): (&str, &[&str]) = if check {
        ("-check", &["closed-loop-check"])
    } else {
        ("", &[])
    };
    let target = repo_root().join("target").join(format!(
        "qemu-closedloop-{}{suffix}",
        g.prefix.to_lowercase()
    ));
    build_app_image_with(&module, "closedloop", features, &target).map_err(|e| e.to_string())
}

/// One signal's oscillation as the target reported it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetCycle {
    /// Frequency of the mean crossings, Hz.
    pub freq_hz: f64,
    /// Half peak-to-peak.
    pub amplitude: f64,
    /// Upward mean crossings.
    pub crossings: u32,
    /// The target's verdict.
    pub oscillating: bool,
}

/// A run of the `closedloop` image.
#[derive(Debug, Clone)]
pub struct ClosedLoopRun {
    /// Exit status.
    pub exit_code: i32,
    /// Decoded lines (without the `T` trace lines).
    pub lines: Vec<LogLine>,
    /// Trace of the tail: (y, u, ω) per sample.
    pub trace: Vec<(f64, f64, f64)>,
    /// The target's analysis of y, u and ω.
    pub y: Option<TargetCycle>,
    /// See `y`.
    pub u: Option<TargetCycle>,
    /// See `y`.
    pub omega: Option<TargetCycle>,
}

fn field(text: &str, key: &str) -> Option<String> {
    text.split_whitespace()
        .find_map(|w| w.strip_prefix(key).and_then(|r| r.strip_prefix('=')))
        .map(str::to_string)
}

fn cycle_of(lines: &[LogLine], name: &str) -> Option<TargetCycle> {
    let l = lines
        .iter()
        .find(|l| l.text.starts_with(&format!("CYCLE {name} ")))?;
    Some(TargetCycle {
        freq_hz: field(&l.text, "freq_hz")?.parse().ok()?,
        amplitude: field(&l.text, "amplitude")?.parse().ok()?,
        crossings: field(&l.text, "crossings")?.parse().ok()?,
        oscillating: field(&l.text, "oscillating")?.parse().ok()?,
    })
}

/// Runs the image with the command-line words `args` and parses its log.
pub fn run(elf: &Path, args: &[&str]) -> Result<ClosedLoopRun, Error> {
    let opts = RunOptions {
        args: args.iter().map(|s| s.to_string()).collect(),
        timeout: std::time::Duration::from_secs(60),
        ..RunOptions::default()
    };
    let q = run_qemu(elf, &opts)?;
    let all = decode_defmt(elf, &q.stdout)?;
    let mut trace = Vec::new();
    let mut lines = Vec::new();
    for l in all {
        if let Some(rest) = l.text.strip_prefix("T ") {
            let v: Vec<f64> = rest
                .split_whitespace()
                .filter_map(|t| t.parse().ok())
                .collect();
            if let [y, u, w] = v[..] {
                trace.push((y, u, w));
            }
        } else {
            lines.push(l);
        }
    }
    Ok(ClosedLoopRun {
        exit_code: q.exit_code,
        y: cycle_of(&lines, "y"),
        u: cycle_of(&lines, "u"),
        omega: cycle_of(&lines, "omega"),
        lines,
        trace,
    })
}

/// First-harmonic amplitude of `x` (sampled every `ts` s) at `freq_hz`, over the largest whole
/// number of periods at the end of the record (mean removed): 2/N·|Σ x e^{−jωkT}|.
pub fn first_harmonic(x: &[f64], ts: f64, freq_hz: f64) -> f64 {
    let period = 1.0 / (freq_hz * ts);
    let periods = (x.len() as f64 / period).floor();
    let n = (periods * period).round() as usize;
    if n < 2 || n > x.len() {
        return 0.0;
    }
    let tail = &x[x.len() - n..];
    let mean = tail.iter().sum::<f64>() / n as f64;
    let w = 2.0 * std::f64::consts::PI * freq_hz * ts;
    let (mut re, mut im) = (0.0, 0.0);
    for (k, v) in tail.iter().enumerate() {
        let (s, c) = (w * k as f64).sin_cos();
        re += (v - mean) * c;
        im -= (v - mean) * s;
    }
    2.0 * (re * re + im * im).sqrt() / n as f64
}

// ---------------------------------------------------------------------------------------------
// The closed-loop power-up check (`closedloop` image, `check=on`).

/// [`codegen_input_for`] with the closed-loop check configured: `welch_n`-sample periods,
/// lines up to `max_hz`, the check frequencies `check_hz`, `averages` periods after
/// `settle` periods, the multisine's RMS `reference_rms` (rad, at the reference), the
/// uncertainty weight `weight` (`(num, den)`, s in rad/s) and the coherence gate 0.9.
#[allow(clippy::too_many_arguments)]
pub fn check_codegen_input(
    prefix: &str,
    plant: &StateSpace,
    pid: &Pid,
    compensation: Option<cg::Compensation>,
    welch_n: usize,
    check_hz: &[f64],
    max_hz: f64,
    averages: u32,
    settle: u32,
    reference_rms: f64,
    weight: (Vec<f64>, Vec<f64>),
) -> cg::CodegenInput {
    let mut input = codegen_input_for(prefix, plant, pid, compensation);
    input.weight = cg::WeightCoefficients {
        num: weight.0,
        den: weight.1,
        note: "closed-loop check weight (tests/src/closedloop.rs)".into(),
    };
    input.self_id = cg::SelfIdSettings {
        welch_n,
        check_hz: check_hz.to_vec(),
        coherence_gate: 0.9,
        averages,
        settle_periods: settle,
        // The open-loop excitation is not used by the closed-loop image; a valid value.
        excitation_rms: 0.1,
        excitation_max_hz: max_hz,
        min_checked: check_hz.len().div_ceil(2),
        closed_loop: Some(cg::ClosedLoopCheck { reference_rms }),
    };
    input
}

/// One `RECEIPT` line of the target: the power-up image's format (`ferrosid_frame::RECEIPT_FIELDS`),
/// read into the host's row type (closed loop: the coherence is the smaller of γ²_ry, γ²_ru).
pub type CheckRow = ferrosid::target_frame::ReceiptRow;

/// A run of the closed-loop check.
#[derive(Debug, Clone)]
pub struct CheckRun {
    /// Exit status: 0 pass, 1 fail, 2 inconclusive, 3 set-up error.
    pub exit_code: i32,
    /// Decoded lines without the `C` trace lines.
    pub lines: Vec<LogLine>,
    /// The averaged samples (excitation r, PID command u, output y), first 4096.
    pub trace: Vec<(f64, f64, f64)>,
    /// The receipt.
    pub rows: Vec<CheckRow>,
    /// PASS, FAIL or INCONCLUSIVE.
    pub verdict: Option<String>,
    /// Frequencies listed as failed, Hz.
    pub failed_hz: Vec<f64>,
    /// Mean and max instructions per sample of excitation + estimator push, instructions of
    /// the final evaluation (valid under `-icount`).
    pub icount: Option<(f64, f64, f64)>,
    /// Stack high-water mark, bytes.
    pub stack: Option<usize>,
}

fn parse_row(text: &str) -> Option<CheckRow> {
    let w: Vec<&str> = text.strip_prefix("RECEIPT ")?.split_whitespace().collect();
    if w.len() != 11 {
        return None;
    }
    let f = |i: usize| w[i].parse::<f64>().ok();
    Some(CheckRow {
        bin: w[0].parse().ok()?,
        hz: f(1)?,
        coherence: f(2)?,
        g0: Complex64::new(f(3)?, f(4)?),
        g_meas: Complex64::new(f(5)?, f(6)?),
        rel_error: f(7)?,
        wm: f(8)?,
        sigma: f(9)?,
        verdict: w[10].to_string(),
    })
}

/// Runs the image (one from [`build_check_image`]: a plain image refuses `check=on`) with
/// `check=on` and the words `args` (with `-icount shift=0` when `icount`).
pub fn run_check(elf: &Path, args: &[&str], icount: bool) -> Result<CheckRun, Error> {
    let mut words: Vec<String> = vec!["check=on".into()];
    words.extend(args.iter().map(|s| s.to_string()));
    let opts = RunOptions {
        args: words,
        timeout: std::time::Duration::from_secs(120),
        icount,
    };
    let q = run_qemu(elf, &opts)?;
    let all = decode_defmt(elf, &q.stdout)?;
    let mut trace = Vec::new();
    let mut lines = Vec::new();
    for l in all {
        if let Some(rest) = l.text.strip_prefix("C ") {
            let v: Vec<f64> = rest
                .split_whitespace()
                .filter_map(|t| t.parse().ok())
                .collect();
            if let [r, u, y] = v[..] {
                trace.push((r, u, y));
            }
        } else {
            lines.push(l);
        }
    }
    let rows = lines.iter().filter_map(|l| parse_row(&l.text)).collect();
    let verdict = lines.iter().find_map(|l| {
        l.text
            .strip_prefix("VERDICT ")
            .and_then(|r| r.split_whitespace().next())
            .map(str::to_string)
    });
    let failed_hz = lines
        .iter()
        .find_map(|l| l.text.split_once("failed_hz=["))
        .map(|(_, rest)| {
            rest.trim_end_matches(']')
                .split(',')
                .filter_map(|t| t.trim().parse::<f64>().ok())
                .collect()
        })
        .unwrap_or_default();
    let icount = lines
        .iter()
        .find(|l| l.text.starts_with("ICOUNT "))
        .and_then(|l| {
            Some((
                field(&l.text, "push_mean")?.parse().ok()?,
                field(&l.text, "push_max")?.parse().ok()?,
                field(&l.text, "evaluate")?.parse().ok()?,
            ))
        });
    let stack = lines.iter().find_map(|l| {
        l.text
            .strip_prefix("STACK ")
            .and_then(|s| s.trim().parse().ok())
    });
    Ok(CheckRun {
        exit_code: q.exit_code,
        lines,
        trace,
        rows,
        verdict,
        failed_hz,
        icount,
        stack,
    })
}

/// The f64 reference of the closed-loop estimate, a second implementation: over every whole
/// `n`-sample period of the records, the DFT at `bin` of r, u and y (direct sums in f64, mean
/// of the period removed as the target's Welch does — it does not change a bin ≥ 1), then
/// `G = Σ conj(R)·Y / Σ conj(R)·U` (the indirect estimate) and the naive open-loop
/// `H1 = Σ conj(U)·Y / Σ |U|²`.
pub fn reference_estimate(
    r: &[f64],
    u: &[f64],
    y: &[f64],
    n: usize,
    bin: usize,
) -> (Complex64, Complex64) {
    let periods = r.len().min(u.len()).min(y.len()) / n;
    let (mut ry, mut ru, mut uy, mut uu) = (
        Complex64::default(),
        Complex64::default(),
        Complex64::default(),
        0.0,
    );
    let dft = |x: &[f64]| -> Complex64 {
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        x.iter()
            .enumerate()
            .map(|(i, v)| {
                let ph = -2.0 * std::f64::consts::PI * ((bin * i) % n) as f64 / n as f64;
                Complex64::from_polar(v - mean, ph)
            })
            .sum()
    };
    for p in 0..periods {
        let s = p * n..(p + 1) * n;
        let (rk, uk, yk) = (dft(&r[s.clone()]), dft(&u[s.clone()]), dft(&y[s]));
        ry += rk.conj() * yk;
        ru += rk.conj() * uk;
        uy += uk.conj() * yk;
        uu += uk.norm_sqr();
    }
    (ry / ru, uy / uu)
}

/// Coulomb friction level of the loop behind the torque lag, N·m (= input units, gain 1).
pub const LAG_COULOMB: f64 = 0.1;

/// The friction feedforward for Coulomb friction [`LAG_COULOMB`] at the motor behind the
/// [`LAG`] torque lag, in its lag-aware form (`cg::LagAwareFriction`: velocity from the
/// filtered output difference at 200 Hz predicted one sample ahead, ramp band 0.05 rad/s,
/// stuck branch over ±1e-4 N·m of the lagged PID command, the lag's deadbeat inverse),
/// designed by `ferrosid::compensation::design_from` at the true level and lag. The image runs
/// it as designed (`comp=ff`) or as the plain feedforward with the same numbers
/// (`comp=ffplain`).
pub fn lag_aware_feedforward() -> cg::Compensation {
    use ferrosid::compensation::design::{design_from, DesignOptions};
    use ferrosid::gap::report::VerdictEffect;
    let mut opts = DesignOptions::new("tests/tests/e2e_closedloop.rs (true level)", 0.05, 0.02);
    opts.velocity = cg::VelocitySource::OutputDifference { filter_hz: 200.0 };
    opts.lag_aware = Some(cg::LagAwareFriction {
        lag_s: LAG,
        horizon_s: TS,
        stick_band: 1e-4,
    });
    let effect = VerdictEffect {
        effect: "coulomb_friction".into(),
        place: "motor".into(),
        params: [("level".to_string(), LAG_COULOMB)].into_iter().collect(),
        share: 1.0,
    };
    design_from("coulomb_friction", &[effect], f64::NAN, f64::NAN, &opts)
        .expect("compensation design")
}
