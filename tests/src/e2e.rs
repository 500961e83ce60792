//! End-to-end pipeline of "control with receipts": logs → identification → uncertainty weight →
//! robust PID → receipts → generated headers → power-up firmware under QEMU → re-identification
//! from the target's spectra frame.
//!
//! The bench is a flexible axis (gimbal, compliant joint) driven by a torque actuator,
//! `J θ'' + b θ' + k θ = K u`: J = 1e-4 kg·m², k = 2.4674011 N·m/rad (25 Hz natural frequency),
//! b = 3.1415927e-3 N·m·s/rad (ζ = 0.1), K = k (unit DC gain), controlled at 1 kHz. Three units
//! are "measured" (J × 1, 0.96, 1.04: the unit-to-unit spread the uncertainty weight must
//! cover) by simulating the ZOH-discretised model on the host (`ferrosid::lti`, matrix
//! exponential) with a uniform random input and 1e-3 rad of output noise; their logs are
//! written as CSV and read back through `ferrosid::io`.
//!
//! The firmware (`firmware/app`, image `powerup`) simulates the same physics independently
//! (RK4 sub-steps in f32) with the parameters passed on its command line
//! ([`Axis::firmware_args`]).
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use faer::Mat;
use ferrosid::cli::Cli;
use ferrosid::io::{read_log, LogSpec};
use ferrosid::lti::{StateSpace, StateSpaceData};
use ferrosid::n4sid::{n4sid, N4sidOptions};
use ferrosid::robust::pid::{tune_pid, PidTuningSpec, TunedPid};
use ferrosid::robust::receipts::{compute_receipts, EtfeView, ReceiptInputs, ReceiptLimits};
use ferrosid::robust::uncertainty::{
    fit_uncertainty_weight, multiplicative_envelope, UncertaintyWeight, WeightFitOptions,
};
use ferrosid::spectral::Welch;
use ferrosid::target_frame::{ReceiptRow, TargetFrame};
use ferrosid_sim::rng::Rng;
use num_complex::Complex64;

use crate::{decode_defmt, image_target_dir, run_qemu, Error, LogLine, RunOptions, TARGET};

/// Control (and identification, and self-identification) sample time, s.
pub const TS: f64 = 1e-3;
/// Samples per identification log (16.4 s).
pub const LOG_SAMPLES: usize = 16_384;
/// RMS of the additive output noise, rad (logs and firmware).
pub const NOISE_RMS: f64 = 1e-3;
/// Units measured for the uncertainty weight: (name, inertia scale).
pub const UNITS: [(&str, f64); 3] = [("unit_a", 1.0), ("unit_b", 0.96), ("unit_c", 1.04)];
/// Welch segment length of the power-up self-identification (also of the host ETFEs).
pub const WELCH_N: usize = 512;
/// Check frequencies requested from the generator, Hz.
pub const CHECK_HZ: [f64; 9] = [4.0, 8.0, 14.0, 20.0, 25.0, 30.0, 45.0, 70.0, 100.0];
/// Prefix of the generated files (sanitised to `AXIS_1`, files `axis_1.h`/`axis_1.rs`).
pub const PREFIX: &str = "axis-1";

/// Physical parameters of the flexible axis (units in the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Axis {
    /// Inertia J, kg·m².
    pub inertia: f64,
    /// Viscous damping b, N·m·s/rad.
    pub damping: f64,
    /// Stiffness k, N·m/rad.
    pub stiffness: f64,
    /// Actuator gain K, N·m per input unit.
    pub gain: f64,
}

impl Axis {
    /// The bench's nominal unit.
    pub const fn nominal() -> Self {
        Axis {
            inertia: 1e-4,
            damping: 3.141_592_7e-3,
            stiffness: 2.467_401_1,
            gain: 2.467_401_1,
        }
    }

    /// The same axis with the inertia scaled by `s`.
    pub fn with_inertia_scale(self, s: f64) -> Self {
        Axis {
            inertia: self.inertia * s,
            ..self
        }
    }

    /// Continuous model, states (θ, ω), output θ.
    pub fn continuous(&self) -> StateSpace {
        let (j, b, k, g) = (self.inertia, self.damping, self.stiffness, self.gain);
        let a = Mat::from_fn(2, 2, |i, c| match (i, c) {
            (0, 1) => 1.0,
            (1, 0) => -k / j,
            (1, 1) => -b / j,
            _ => 0.0,
        });
        let bm = Mat::from_fn(2, 1, |i, _| if i == 1 { g / j } else { 0.0 });
        let cm = Mat::from_fn(1, 2, |_, c| if c == 0 { 1.0 } else { 0.0 });
        let d = Mat::zeros(1, 1);
        // Shapes and values are valid by construction; a failure here is a test bug.
        StateSpace::new(a, bm, cm, d, 0.0).expect("axis model")
    }

    /// The ZOH discretisation at [`TS`] (host matrix exponential).
    pub fn discrete(&self) -> StateSpace {
        self.continuous().c2d_zoh(TS).expect("c2d_zoh of the axis")
    }

    /// Frequency response at `f_hz` of the sampled axis followed by `delay` samples of
    /// transport delay: the plant the firmware simulates (without friction).
    pub fn response_hz(&self, f_hz: f64, delay: u32) -> Complex64 {
        let g = self
            .discrete()
            .freq_response_siso(f_hz)
            .expect("axis response");
        g * Complex64::from_polar(
            1.0,
            -2.0 * std::f64::consts::PI * f_hz * TS * f64::from(delay),
        )
    }

    /// Command-line words for the `powerup` image (`J= b= k= gain= noise=`).
    pub fn firmware_args(&self) -> Vec<String> {
        vec![
            format!("J={:?}", self.inertia),
            format!("b={:?}", self.damping),
            format!("k={:?}", self.stiffness),
            format!("gain={:?}", self.gain),
            format!("noise={NOISE_RMS:?}"),
        ]
    }
}

/// Simulates `n` samples of `axis` (host ZOH model) driven by uniform noise of unit RMS, with
/// [`NOISE_RMS`] of white Gaussian output noise, both drawn from the workspace's generator
/// (`ferrosid_sim::rng::Rng`, seeded with `seed`: the n inputs first, then the n noise samples).
/// Returns (u, y).
pub fn simulate_log(axis: &Axis, n: usize, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let mut rng = Rng::new(seed);
    let u: Vec<f64> = (0..n)
        .map(|_| (rng.uniform() - 0.5) * 12f64.sqrt())
        .collect();
    let y0 = axis.discrete().simulate_siso(&u, None).expect("simulate");
    let noise = rng.noise(n, NOISE_RMS);
    let y = y0.iter().zip(&noise).map(|(v, e)| v + e).collect();
    (u, y)
}

/// Writes `text` to `path` unless it already holds exactly that (keeps mtimes, so cargo's
/// rerun-if-changed of the firmware build stays quiet on reruns).
pub fn write_if_changed(path: &Path, text: &str) -> Result<(), String> {
    if std::fs::read(path).ok().as_deref() == Some(text.as_bytes()) {
        return Ok(());
    }
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    std::fs::write(path, text).map_err(|e| format!("{}: {e}", path.display()))
}

/// Everything the pipeline produced.
#[derive(Debug, Clone)]
pub struct Pipeline {
    /// Working directory.
    pub dir: PathBuf,
    /// The unit logs (CSV).
    pub logs: Vec<PathBuf>,
    /// Order N4SID chose.
    pub order: usize,
    /// Identified model (unit A), discrete at [`TS`].
    pub model: StateSpace,
    /// Fitted multiplicative uncertainty weight.
    pub weight: UncertaintyWeight,
    /// Envelope frequencies (Hz) and values the weight was fitted to.
    pub envelope: (Vec<f64>, Vec<f64>),
    /// Tuned PID.
    pub tuned: TunedPid,
    /// Whether every receipt passed.
    pub receipts_all_pass: bool,
    /// JSON inputs of the code generator: model, PID, W_m, receipts.
    pub json: [PathBuf; 4],
    /// Generated C header.
    pub c_header: PathBuf,
    /// Generated Rust module.
    pub rust_module: PathBuf,
}

fn json_to(path: &Path, v: &impl serde::Serialize) -> Result<(), String> {
    let text =
        serde_json::to_string_pretty(v).map_err(|e| format!("JSON {}: {e}", path.display()))?;
    write_if_changed(path, &(text + "\n"))
}

/// The codegen command line of the pipeline, writing into `out_dir`.
pub fn codegen_args(p: &Pipeline, out_dir: &Path) -> Vec<OsString> {
    let mut a: Vec<OsString> = vec!["ferrosid".into(), "codegen".into()];
    for (flag, path) in ["--model", "--pid", "--wm", "--receipts"]
        .iter()
        .zip(&p.json)
    {
        a.push((*flag).into());
        a.push(path.into());
    }
    for l in &p.logs {
        a.push("--source".into());
        a.push(l.into());
    }
    let checks = CHECK_HZ.map(|f| f.to_string()).join(",");
    for (k, v) in [
        ("--prefix", PREFIX.to_string()),
        ("--check-hz", checks),
        ("--welch-n", WELCH_N.to_string()),
        ("--averages", "4".into()),
        ("--settle-periods", "1".into()),
        ("--excitation-rms", "1.0".into()),
        ("--gate", "0.9".into()),
    ] {
        a.push(k.into());
        a.push(v.into());
    }
    a.push("--out-dir".into());
    a.push(out_dir.into());
    a
}

/// Runs `ferrosid codegen` (in process, through the command-line parser) for `p` into
/// `out_dir`.
pub fn run_codegen(p: &Pipeline, out_dir: &Path) -> Result<(), String> {
    use clap::Parser as _;
    let cli = Cli::try_parse_from(codegen_args(p, out_dir)).map_err(|e| e.to_string())?;
    ferrosid::cli::run(&cli)
        .map(|_| ())
        .map_err(|e| format!("ferrosid codegen: {e}"))
}

/// Runs the host side of the pipeline in `dir`: unit logs, N4SID on unit A, Welch ETFEs of all
/// units, envelope and W_m fit, robust PID tuning, receipts, JSON files, `ferrosid codegen`.
pub fn run_pipeline(dir: &Path) -> Result<Pipeline, String> {
    let nominal = Axis::nominal();
    let mut logs = Vec::new();
    for (i, (name, scale)) in UNITS.iter().enumerate() {
        let (u, y) = simulate_log(
            &nominal.with_inertia_scale(*scale),
            LOG_SAMPLES,
            11 + i as u64,
        );
        let mut csv = String::from("t,u,y\n");
        for (k, (a, b)) in u.iter().zip(&y).enumerate() {
            csv.push_str(&format!("{:?},{a:?},{b:?}\n", k as f64 * TS));
        }
        let path = dir.join("logs").join(format!("{name}.csv"));
        write_if_changed(&path, &csv)?;
        logs.push(path);
    }
    let spec = LogSpec::default();
    let read: Vec<_> = logs
        .iter()
        .map(|p| read_log(p, &spec).map_err(|e| e.to_string()))
        .collect::<Result<_, _>>()?;

    // Identification of unit A.
    let id = n4sid(&read[0], &N4sidOptions::default()).map_err(|e| format!("n4sid: {e}"))?;
    let model = id.model.clone();

    // ETFEs of every unit and the multiplicative envelope around G0 on the commonly gated bins
    // up to 200 Hz.
    let welch = Welch::new(WELCH_N);
    let etfes: Vec<_> = read
        .iter()
        .map(|l| welch.etfe_log(l, 0, 0).map_err(|e| e.to_string()))
        .collect::<Result<_, _>>()?;
    let bins: Vec<usize> = (2..etfes[0].freq_hz.len())
        .filter(|&k| etfes[0].freq_hz[k] <= 200.0 && etfes.iter().all(|e| e.coherence[k] >= 0.95))
        .collect();
    let f: Vec<f64> = bins.iter().map(|&k| etfes[0].freq_hz[k]).collect();
    let g0 = model
        .freq_responses_siso_hz(&f)
        .map_err(|e| e.to_string())?;
    let family: Vec<Vec<Complex64>> = etfes
        .iter()
        .map(|e| bins.iter().map(|&k| e.h[k]).collect())
        .collect();
    let env = multiplicative_envelope(&g0, &family).map_err(|e| e.to_string())?;
    let weight = fit_uncertainty_weight(&f, &env, &WeightFitOptions::default())
        .map_err(|e| format!("W_m fit: {e}"))?;

    // Robust PID for a 10 Hz target crossover (below the 25 Hz resonance), with roll-off.
    let mut ps = PidTuningSpec::new(10.0);
    ps.weight = Some(weight.clone());
    ps.rolloff_ratio = Some((6.0, 0.7));
    let tuned = tune_pid(&model, &ps).map_err(|e| format!("tune_pid: {e}"))?;

    // Receipts of the tuned loop.
    let gate_a = etfes[0].gate(0.9);
    let limits = ReceiptLimits::for_crossover(tuned.design.crossover_hz);
    let report = compute_receipts(&ReceiptInputs {
        plant: &model,
        pid: &tuned.pid,
        controller_ts: None,
        crossover_hz: tuned.design.crossover_hz,
        weight: Some(&weight),
        actuator_limit: 5.0,
        actuator_unit: "unit",
        reference_amplitude: 0.2,
        etfe: Some(EtfeView::from_etfe(&etfes[0], Some(&gate_a))),
        cross_validation: None,
        limits,
        anti_windup: true,
    })
    .map_err(|e| format!("receipts: {e}"))?;

    let json = [
        dir.join("model.json"),
        dir.join("pid.json"),
        dir.join("wm.json"),
        dir.join("receipts.json"),
    ];
    json_to(&json[0], &StateSpaceData::from(&model))?;
    json_to(&json[1], &tuned)?;
    json_to(&json[2], &weight)?;
    json_to(&json[3], &report.receipts)?;

    let p = Pipeline {
        dir: dir.to_path_buf(),
        logs,
        order: id.order,
        model,
        weight,
        envelope: (f, env),
        tuned,
        receipts_all_pass: report.receipts.all_pass,
        json,
        c_header: dir.join("generated").join("axis_1.h"),
        rust_module: dir.join("generated").join("axis_1.rs"),
    };
    run_codegen(&p, &dir.join("generated"))?;
    Ok(p)
}

/// Manifest of the power-up firmware application.
pub fn powerup_manifest() -> PathBuf {
    crate::repo_root()
        .join("firmware")
        .join("app")
        .join("Cargo.toml")
}

/// Builds the `powerup` image (release, [`TARGET`]) around the generated Rust module
/// `model_rs` (absolute path), in the QEMU image target directory; returns the ELF path.
pub fn build_powerup(model_rs: &Path) -> Result<PathBuf, Error> {
    build_app_image(model_rs, "powerup", &image_target_dir())
}

/// Builds the image `bin` of `firmware/app` (release, [`TARGET`], default features) around the
/// generated Rust module `model_rs` (absolute path) in `target_dir`; returns the ELF path.
/// Images built around different modules need different target directories (the module is an
/// input of the whole crate).
pub fn build_app_image(model_rs: &Path, bin: &str, target_dir: &Path) -> Result<PathBuf, Error> {
    build_app_image_with(model_rs, bin, &[], target_dir)
}

/// [`build_app_image`] with the cargo `features` of `firmware/app` enabled (e.g.
/// `closed-loop-check`). Use a target directory per feature set as well as per module: the
/// ELF's path does not depend on the features, so two variants in one directory would
/// overwrite (and rebuild) each other.
pub fn build_app_image_with(
    model_rs: &Path,
    bin: &str,
    features: &[&str],
    target_dir: &Path,
) -> Result<PathBuf, Error> {
    let cargo: OsString = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut cmd = Command::new(&cargo);
    cmd.args([
        "build",
        "--release",
        "--target",
        TARGET,
        "--bin",
        bin,
        "--manifest-path",
    ])
    .arg(powerup_manifest());
    if !features.is_empty() {
        cmd.arg("--features").arg(features.join(","));
    }
    crate::scrub_cargo_env(&mut cmd);
    cmd.env("CARGO_TARGET_DIR", target_dir)
        .env("DEFMT_LOG", "info")
        .env("FERROSID_POWERUP_MODEL", model_rs)
        .stdin(Stdio::null());
    let command = format!("{cmd:?}");
    let out = cmd.output().map_err(|source| Error::Io {
        context: format!("starting {command}"),
        source,
    })?;
    if !out.status.success() {
        let stderr = String::from_utf8_lossy(&out.stderr);
        let tail: Vec<&str> = stderr.lines().rev().take(60).collect();
        return Err(Error::Build {
            command,
            stderr: tail.into_iter().rev().collect::<Vec<_>>().join("\n"),
        });
    }
    Ok(target_dir.join(TARGET).join("release").join(bin))
}

/// One run of the power-up image.
#[derive(Debug, Clone)]
pub struct PowerupRun {
    /// Exit status: 0 pass, 1 fail, 2 inconclusive, 3 set-up error, 101 panic.
    pub exit_code: i32,
    /// Decoded log lines.
    pub lines: Vec<LogLine>,
    /// The log as text (one line per log line).
    pub text: String,
    /// The receipt and spectra frame read back by the host parser.
    pub frame: Option<TargetFrame>,
    /// Frequencies listed as failed on the `VERDICT` line, Hz.
    pub failed_hz: Vec<f64>,
}

impl PowerupRun {
    /// The receipt rows (empty without a frame).
    pub fn receipt(&self) -> &[ReceiptRow] {
        self.frame.as_ref().map_or(&[], |f| &f.receipt)
    }
    /// The verdict word.
    pub fn verdict(&self) -> Option<&str> {
        self.frame.as_ref().and_then(|f| f.verdict.as_deref())
    }
}

/// Runs the power-up image with the plant scenario words `args` and parses its output.
pub fn run_powerup(elf: &Path, args: &[String]) -> Result<PowerupRun, Error> {
    let opts = RunOptions {
        args: args.to_vec(),
        timeout: std::time::Duration::from_secs(120),
        ..RunOptions::default()
    };
    let run = run_qemu(elf, &opts)?;
    let lines = decode_defmt(elf, &run.stdout)?;
    let text: String = lines.iter().map(|l| format!("{}\n", l.text)).collect();
    let frame = TargetFrame::parse(&text, Path::new("powerup")).ok();
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
    Ok(PowerupRun {
        exit_code: run.exit_code,
        lines,
        text,
        frame,
        failed_hz,
    })
}
