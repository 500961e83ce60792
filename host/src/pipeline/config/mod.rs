//! `PIPELINE.toml`: what [`super::run_pipeline`] reads, validated with errors that name the
//! file, the line and the key at fault.
//!
//! The full schema with every default is documented in `docs/pipeline-schema.md`; each field
//! below states its unit and default. Unknown keys are errors (a typo must not silently fall
//! back to a default). Paths are relative to the directory of the TOML file.
use crate::error::{Error, Result};
pub use crate::preprocess::Removal;
use crate::preprocess::Step;
use crate::spectral::{Welch, Window};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

mod spans;
mod validate;

use spans::{line_at, KeyTree};

/// Signal selection shared by every log (each log may override it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Signals {
    /// Input column (CSV header), variable (.mat) or 1-based column number (text). Default `u`.
    #[serde(default = "default_input")]
    pub input: String,
    /// Output column/variable. Default `y`.
    #[serde(default = "default_output")]
    pub output: String,
    /// Time column/variable (None: CSV uses `t` when its header has it).
    #[serde(default)]
    pub time: Option<String>,
    /// Seconds per unit of the time column (default 1).
    #[serde(default)]
    pub time_scale: Option<f64>,
    /// Sample rate in Hz, required when there is no time column; with one, it takes
    /// precedence (see [`crate::io`]).
    #[serde(default)]
    pub fs: Option<f64>,
    /// Largest accepted relative jitter of a time column's intervals, in [0, 0.5] (default
    /// [`crate::io::DEFAULT_TIME_JITTER_REL`]).
    #[serde(default)]
    pub time_jitter: Option<f64>,
    /// Unit of the input (actuator command), for tables and plots. Default `u`.
    #[serde(default = "default_input_unit")]
    pub input_unit: String,
    /// Unit of the output (measurement). Default `y`.
    #[serde(default = "default_output_unit")]
    pub output_unit: String,
}

fn default_input() -> String {
    "u".into()
}
fn default_output() -> String {
    "y".into()
}
fn default_input_unit() -> String {
    "input unit".into()
}
fn default_output_unit() -> String {
    "output unit".into()
}

impl Default for Signals {
    fn default() -> Self {
        Self {
            input: default_input(),
            output: default_output(),
            time: None,
            time_scale: None,
            fs: None,
            time_jitter: None,
            input_unit: default_input_unit(),
            output_unit: default_output_unit(),
        }
    }
}

/// One measured log: an excitation run (`[[runs]]`) or the validation log (`[validation]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LogEntry {
    /// Label used in tables, plots and receipts (runs: required and unique; validation:
    /// default `validation`).
    #[serde(default)]
    pub name: Option<String>,
    /// Log file (.csv, .mat, .dat/.txt), relative to the TOML file.
    pub file: PathBuf,
    /// Excitation amplitude (input units, e.g. the RMS), used to order runs in the audit.
    /// Default: the RMS of the input after preprocessing.
    #[serde(default)]
    pub amplitude: Option<f64>,
    /// Overrides of `[signals].input` / `output` / `time` / `fs` for this log.
    #[serde(default)]
    pub input: Option<String>,
    /// See `input`.
    #[serde(default)]
    pub output: Option<String>,
    /// See `input`.
    #[serde(default)]
    pub time: Option<String>,
    /// See `input`.
    #[serde(default)]
    pub fs: Option<f64>,
}

/// `[preprocess]`: applied identically to every log, in this order: removal, decimation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Preprocess {
    /// Offset removal (default `mean`).
    #[serde(default = "default_removal")]
    pub remove: Removal,
    /// Integer decimation factor (1 = none, default), anti-aliased as scipy.signal.decimate.
    #[serde(default = "one")]
    pub decimate: usize,
}

fn default_removal() -> Removal {
    Removal::Mean
}
fn one() -> usize {
    1
}

impl Default for Preprocess {
    fn default() -> Self {
        Self {
            remove: Removal::Mean,
            decimate: 1,
        }
    }
}

impl Preprocess {
    /// The preprocessing steps in the order applied.
    pub fn steps(&self) -> Vec<Step> {
        crate::preprocess::steps(self.remove, self.decimate)
    }
}

/// Window names accepted in `[etfe].window`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WindowName {
    /// Hann (default).
    Hann,
    /// Hamming.
    Hamming,
    /// Blackman.
    Blackman,
    /// Rectangular.
    Rectangular,
}

/// `[etfe]`: Welch H1 settings, the same for every log so the audit can overlay the runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EtfeSettings {
    /// Segment length in samples (default 512); resolution fs/nperseg Hz.
    #[serde(default = "default_nperseg")]
    pub nperseg: usize,
    /// Overlap in samples (default nperseg/2).
    #[serde(default)]
    pub overlap: Option<usize>,
    /// Data window (default `hann`).
    #[serde(default = "default_window")]
    pub window: WindowName,
    /// Coherence gate: bins with magnitude-squared coherence >= this are used for fitting and
    /// validation (default 0.85).
    #[serde(default = "default_gate")]
    pub coherence_gate: f64,
}

fn default_nperseg() -> usize {
    512
}
fn default_window() -> WindowName {
    WindowName::Hann
}
fn default_gate() -> f64 {
    crate::spectral::DEFAULT_COHERENCE_THRESHOLD
}

impl Default for EtfeSettings {
    fn default() -> Self {
        Self {
            nperseg: default_nperseg(),
            overlap: None,
            window: WindowName::Hann,
            coherence_gate: default_gate(),
        }
    }
}

impl EtfeSettings {
    /// The Welch estimator these settings describe.
    pub fn welch(&self) -> Welch {
        let mut w = Welch::new(self.nperseg);
        w.noverlap = self.overlap;
        w.window = match self.window {
            WindowName::Hann => Window::Hann,
            WindowName::Hamming => Window::Hamming,
            WindowName::Blackman => Window::Blackman,
            WindowName::Rectangular => Window::Rectangular,
        };
        w
    }
}

/// `[identification]`: N4SID on the estimation run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Identification {
    /// Name of the run to identify the nominal model from (default: the run with the largest
    /// amplitude).
    #[serde(default)]
    pub run: Option<String>,
    /// Fixed model order (default: automatic).
    #[serde(default)]
    pub order: Option<usize>,
    /// Smallest order of the automatic search (default 1).
    #[serde(default)]
    pub order_min: Option<usize>,
    /// Largest order of the automatic search (default min((i−1), 20)).
    #[serde(default)]
    pub order_max: Option<usize>,
    /// Block rows i (default 20).
    #[serde(default = "default_block_rows")]
    pub block_rows: usize,
    /// Estimate the feedthrough D (default false: a sampled physical plant has none).
    #[serde(default)]
    pub estimate_d: bool,
    /// Enforce discrete poles |z| <= 1 − margin (default: not enforced, reported).
    #[serde(default)]
    pub stability_margin: Option<f64>,
}

fn default_block_rows() -> usize {
    crate::n4sid::N4sidOptions::default().block_rows
}

impl Default for Identification {
    fn default() -> Self {
        Self {
            run: None,
            order: None,
            order_min: None,
            order_max: None,
            block_rows: default_block_rows(),
            estimate_d: false,
            stability_margin: None,
        }
    }
}

/// Largest accepted `[audit]` band factor: the band [f_c/k, f_c·k] then spans 12 decades,
/// more than any log resolves (a larger factor only means "everything").
pub const MAX_BAND_FACTOR: f64 = 1e6;

/// `[audit]`: dual-amplitude nonlinearity audit thresholds (see [`crate::robust::audit`]); a
/// missing key takes the default of [`crate::robust::audit::AuditOptions::new`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AuditSettings {
    /// Audit band [f_c/k, f_c·k] (default 10: a decade each side of the crossover).
    pub band_factor: f64,
    /// Largest tolerated gain shift between runs, dB (default 3).
    pub max_gain_shift_db: f64,
    /// Largest tolerated phase shift between runs, degrees (default 15).
    pub max_phase_shift_deg: f64,
    /// Smallest tolerated coherence near crossover (default 0.6).
    pub min_coherence: f64,
    /// Coherence window [f_c/k, f_c·k] (default 3).
    pub coherence_band_factor: f64,
}

impl Default for AuditSettings {
    fn default() -> Self {
        // The crossover is set by the pipeline later; only the thresholds are taken here.
        let d = crate::robust::audit::AuditOptions::new(1.0);
        Self {
            band_factor: d.band_factor,
            max_gain_shift_db: d.max_gain_shift_db,
            max_phase_shift_deg: d.max_phase_shift_deg,
            min_coherence: d.min_coherence,
            coherence_band_factor: d.coherence_band_factor,
        }
    }
}

/// `[uncertainty]`: multiplicative uncertainty weight W_m (see [`crate::robust::uncertainty`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UncertaintySettings {
    /// Weight order 1..=3 (default 2).
    #[serde(default = "two")]
    pub order: usize,
    /// Envelope floor (dimensionless, default 1e-3).
    #[serde(default = "default_min_level")]
    pub min_level: f64,
    /// Logs whose ETFEs form the family around the nominal model (names of runs, or
    /// `validation`). Default: every run and the validation log.
    #[serde(default)]
    pub family: Option<Vec<String>>,
    /// Relative uncertainty assumed above the highest frequency where every family member
    /// passes the coherence gate, up to 100 × Nyquist (default 1.0 = 100 %: the data say nothing
    /// there). `0` disables it (then W_m is only constrained on measured bins).
    #[serde(default = "one_f")]
    pub beyond_band_level: f64,
    /// Relative uncertainty assumed for the decade below the lowest frequency where every
    /// family member passes the gate (default: hold the largest l_m of the lowest measured
    /// octave). Without it, the weight below the measured band is an unconstrained
    /// extrapolation of the fit.
    #[serde(default)]
    pub below_band_level: Option<f64>,
}

fn two() -> usize {
    2
}
fn default_min_level() -> f64 {
    1e-3
}
fn one_f() -> f64 {
    1.0
}

impl Default for UncertaintySettings {
    fn default() -> Self {
        Self {
            order: 2,
            min_level: default_min_level(),
            family: None,
            beyond_band_level: 1.0,
            below_band_level: None,
        }
    }
}

/// `[control]`: the robust PID design (see [`crate::robust::pid`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Control {
    /// Target (and maximum) gain crossover, Hz. Required.
    pub crossover_hz: f64,
    /// Largest sensitivity peak M_s (default 1.6); the tuner's constraint and the receipt's
    /// limit.
    #[serde(default = "default_ms")]
    pub ms_max: f64,
    /// Symmetric actuator limit in input units (e.g. A or N·m). Required.
    pub actuator_limit: f64,
    /// Reference step height and worst-case reference amplitude, output units (default 1).
    #[serde(default = "one_f")]
    pub reference_amplitude: f64,
    /// Integral action (default true).
    #[serde(default = "yes")]
    pub integral: bool,
    /// Derivative (lead) action (default true).
    #[serde(default = "yes")]
    pub derivative: bool,
    /// Second-order roll-off corner as a multiple of the crossover (default: no roll-off).
    #[serde(default)]
    pub rolloff_ratio: Option<f64>,
    /// Damping of the roll-off (default 0.7).
    #[serde(default = "default_rolloff_zeta")]
    pub rolloff_zeta: f64,
    /// Lowest crossover the search may settle on, as a fraction of the target (default 0.1);
    /// also the `controller_design` receipt's limit.
    #[serde(default = "default_min_scale")]
    pub min_crossover_scale: f64,
    /// Conditional-integration anti-windup in the simulated controller (default true).
    #[serde(default = "yes")]
    pub anti_windup: bool,
    /// Constrain ‖KS‖∞·reference amplitude to the actuator limit while tuning (default true).
    #[serde(default = "yes")]
    pub limit_control_effort: bool,
    /// Controller structure: `pid` (default, the robust PID above), `loopshape` (alias
    /// `pid-notch`: PID + notches), `hinf` (H∞ mixed sensitivity) or `mpc` (condensed MPC
    /// with the actuator limit as its input box); see
    /// [`super::control_stage`]. Omitted from the settings echo when `pid`.
    #[serde(
        default,
        skip_serializing_if = "super::control_stage::ControlMethod::is_pid"
    )]
    pub method: super::control_stage::ControlMethod,
    /// Several methods in one run, the first the primary (its receipts are `receipts.json`,
    /// the others' `receipts.<method>.json`; the report compares them). `method`, when also
    /// written, must equal the first entry; with `methods` alone `method` is set to it
    /// ([`super::control_methods`]). Omitted from the settings echo when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub methods: Option<Vec<super::control_stage::ControlMethod>>,
    /// `loopshape`: plant modes with damping ratio below this are notched (default 0.3).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub notch_max_damping: Option<f64>,
    /// `hinf`: low-frequency floor ε of the performance weight W_S, |S(0)| ≲ γ·ε (default
    /// 1e-3).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hinf_ws_floor: Option<f64>,
    /// `hinf`: the central controller is built at (1 + backoff)·γ_opt (default 0.01).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hinf_backoff: Option<f64>,
    /// `hinf`: balanced truncation of the controller to this many states before Tustin
    /// (default: no reduction; an order at or above the controller's keeps it whole).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hinf_order: Option<usize>,
    /// `mpc`: prediction/control horizon N in samples (default 10).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mpc_horizon: Option<usize>,
    /// `mpc`: output tracking weight q per (output unit)² (default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mpc_output_weight: Option<f64>,
    /// `mpc`: input-rate weight ρ_Δ per (input unit)² (default 0.01).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mpc_rate_weight: Option<f64>,
    /// `mpc`: largest input change per sample, input units (default actuator_limit / 6).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mpc_rate_limit: Option<f64>,
    /// `mpc`: ADMM penalty ρ (default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mpc_rho: Option<f64>,
    /// `mpc`: ADMM iterations per control step (default 60).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mpc_iterations: Option<usize>,
}

fn default_ms() -> f64 {
    crate::robust::pid::PidTuningSpec::new(1.0).ms_max
}
fn yes() -> bool {
    true
}
fn default_rolloff_zeta() -> f64 {
    0.7
}
fn default_min_scale() -> f64 {
    crate::robust::pid::PidTuningSpec::new(1.0).min_crossover_scale
}

/// `[receipts]`: limits (defaults as in [`crate::robust::receipts::ReceiptLimits`]).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReceiptSettings {
    /// Minimum gain margin, dB (default 6).
    #[serde(default)]
    pub gain_margin_db_min: Option<f64>,
    /// Minimum phase margin, degrees (default 30).
    #[serde(default)]
    pub phase_margin_deg_min: Option<f64>,
    /// Maximum M_t (default 1.5).
    #[serde(default)]
    pub mt_max: Option<f64>,
    /// Minimum disturbance-rejection bandwidth, Hz (default 0.25 × crossover).
    #[serde(default)]
    pub disturbance_bandwidth_hz_min: Option<f64>,
    /// Maximum saturated-step overshoot, % (default 25).
    #[serde(default)]
    pub overshoot_pct_max: Option<f64>,
    /// Maximum 2 % settling time, s (default 20 / crossover).
    #[serde(default)]
    pub settling_time_s_max: Option<f64>,
    /// Maximum |phase(G0) − phase(ETFE)|, degrees (default 5).
    #[serde(default)]
    pub etfe_phase_error_deg_max: Option<f64>,
    /// ETFE phase agreement checked up to this multiple of the crossover (default 2).
    #[serde(default)]
    pub etfe_max_freq_factor: Option<f64>,
    /// Minimum cross-validation fit on the validation log, % (default 70).
    #[serde(default)]
    pub cross_validation_fit_min: Option<f64>,
}

/// The whole `PIPELINE.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PipelineConfig {
    /// Title of the report (default: the TOML file name).
    #[serde(default)]
    pub name: Option<String>,
    /// Output directory, relative to the TOML file (default `out`); `--out` overrides.
    #[serde(default)]
    pub output_dir: Option<PathBuf>,
    /// Signal selection and units.
    #[serde(default)]
    pub signals: Signals,
    /// Excitation runs (at least one; two or more at different amplitudes for the audit).
    pub runs: Vec<LogEntry>,
    /// Fresh data for cross-validation (optional but recommended).
    #[serde(default)]
    pub validation: Option<LogEntry>,
    /// Preprocessing.
    #[serde(default)]
    pub preprocess: Preprocess,
    /// Welch/coherence settings.
    #[serde(default)]
    pub etfe: EtfeSettings,
    /// N4SID settings.
    #[serde(default)]
    pub identification: Identification,
    /// Nonlinearity audit thresholds.
    #[serde(default)]
    pub audit: AuditSettings,
    /// Uncertainty weight settings.
    #[serde(default)]
    pub uncertainty: UncertaintySettings,
    /// Controller design.
    pub control: Control,
    /// Receipt limits.
    #[serde(default)]
    pub receipts: ReceiptSettings,
    /// When to run the gap diagnosis of G0 (see [`super::gap_stage`]).
    #[serde(default)]
    pub gap: GapSettings,
    /// The compensation stage after a diagnosis (see [`super::compensation_stage`]).
    #[serde(default)]
    pub compensation: CompensationSettings,
    /// Physical parameters by a grey-box fit (see [`super::physical_stage`]); none when
    /// absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub physical: Option<super::physical_stage::PhysicalConfig>,
}

/// `[gap]`: the pipeline's gap-diagnosis stage ([`super::gap_stage`]).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GapSettings {
    /// `auto` (default: when the audit or a model receipt flags), `always` or `never`.
    #[serde(default)]
    pub run: super::gap_stage::GapRun,
}

/// `[compensation]`: the compensation stage after a gap diagnosis
/// ([`super::compensation_stage`]; keys in docs/pipeline-schema.md).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CompensationSettings {
    /// Allow the choice `compensate` (false: the stage only analyses and chooses between
    /// widening W_m and keeping the design).
    #[serde(default = "yes")]
    pub enabled: bool,
    /// Smoothing band of the friction feedforward, velocity units (output units for a velocity
    /// output). Default: the sensor noise σ the diagnosis measured (NRMSE noise floor × RMS
    /// of the validation output), else 1 % of that RMS.
    #[serde(default)]
    pub velocity_resolution: Option<f64>,
    /// Oscillations with an output amplitude at or below this do not count in the
    /// `limit_cycle` receipt, output units. Default: 3 × the sensor noise σ (as above).
    #[serde(default)]
    pub amplitude_tol: Option<f64>,
    /// Smoothing of the dead-zone and backlash inverses, fraction of width or play, (0, 1].
    #[serde(default = "default_inverse_smoothing")]
    pub inverse_smoothing_rel: f64,
    /// Anti-windup back-calculation time, s. Default: 1/(2π·crossover).
    #[serde(default)]
    pub tracking_time_s: Option<f64>,
    /// Simulated time of each limit-cycle simulation, s (default: 60 periods of the slowest
    /// predicted cycle, 20,000 to 400,000 samples).
    #[serde(default)]
    pub simulate_s: Option<f64>,
}

fn default_inverse_smoothing() -> f64 {
    0.01
}

impl Default for CompensationSettings {
    fn default() -> Self {
        Self {
            enabled: true,
            velocity_resolution: None,
            amplitude_tol: None,
            inverse_smoothing_rel: default_inverse_smoothing(),
            tracking_time_s: None,
            simulate_s: None,
        }
    }
}

/// Default minimum cross-validation fit, percent.
pub const DEFAULT_CV_FIT_MIN: f64 = 70.0;

/// A parsed configuration with where it came from.
#[derive(Debug, Clone)]
pub struct LoadedConfig {
    /// The TOML file.
    pub path: PathBuf,
    /// Its directory (base of relative paths).
    pub base_dir: PathBuf,
    /// Its text (hashed into the provenance, used to locate keys in errors).
    pub text: String,
    /// The parsed and validated configuration.
    pub config: PipelineConfig,
    /// Where each key is written in `text` (for errors).
    keys: KeyTree,
}

impl LoadedConfig {
    /// Reads, parses and validates `path`.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
            file: path.to_path_buf(),
            source,
        })?;
        Self::from_text(path, &text)
    }

    /// Parses and validates `text` as if read from `path`.
    pub fn from_text(path: &Path, text: &str) -> Result<Self> {
        let keys = KeyTree::parse(text);
        let config: PipelineConfig = toml::from_str(text).map_err(|e| {
            let (line, key) = match e.span() {
                Some(span) => (line_at(text, span.start), keys.key_at(span.start)),
                None => (0, None),
            };
            let msg = e.message().trim().to_string();
            let msg = match key {
                Some(k) => format!("key `{k}`: {msg}"),
                None => msg,
            };
            if line > 0 {
                Error::Parse {
                    file: path.to_path_buf(),
                    line,
                    msg,
                }
            } else {
                Error::Data {
                    file: path.to_path_buf(),
                    msg,
                }
            }
        })?;
        let base_dir = path
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from("."));
        let mut loaded = Self {
            path: path.to_path_buf(),
            base_dir,
            text: text.to_string(),
            config,
            keys,
        };
        super::control_methods::resolve_methods(&mut loaded)?;
        loaded.validate()?;
        Ok(loaded)
    }

    /// An error about `key` (dotted, e.g. `control.crossover_hz` or `runs[1].file`), naming the
    /// file and the key's line when it is written in the file.
    pub fn key_error(&self, key: &str, msg: impl std::fmt::Display) -> Error {
        match self.keys.line_of(&self.text, key) {
            Some(line) => Error::Parse {
                file: self.path.clone(),
                line,
                msg: format!("key `{key}`: {msg}"),
            },
            None => Error::Data {
                file: self.path.clone(),
                msg: format!("key `{key}`: {msg}"),
            },
        }
    }

    /// The keys written directly in `table` (e.g. `control`), in file order.
    pub fn keys_written_in<'a>(&'a self, table: &'a str) -> impl Iterator<Item = &'a str> + 'a {
        self.keys.keys_in(table)
    }

    /// The same configuration with no text behind it (errors then name no line).
    pub(crate) fn without_text(mut self) -> Self {
        self.text = String::new();
        self.keys = KeyTree::default();
        self
    }

    /// Resolves a path written in the file against its directory.
    pub fn resolve(&self, p: &Path) -> PathBuf {
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            self.base_dir.join(p)
        }
    }

    /// Run names (`[[runs]].name`, defaulting to `run1`, `run2`, ...).
    pub fn run_names(&self) -> Vec<String> {
        self.config
            .runs
            .iter()
            .enumerate()
            .map(|(i, r)| r.name.clone().unwrap_or_else(|| format!("run{}", i + 1)))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MIN: &str = "[[runs]]\nname = \"a\"\nfile = \"a.csv\"\n\n[control]\ncrossover_hz = 10\nactuator_limit = 1\n";

    #[test]
    fn minimal_config_gets_defaults() {
        let c = LoadedConfig::from_text(Path::new("p.toml"), MIN).unwrap();
        assert_eq!(c.config.etfe.nperseg, 512);
        assert_eq!(c.config.control.ms_max, 1.6);
        assert_eq!(c.run_names(), vec!["a".to_string()]);
    }

    #[test]
    fn errors_name_line_and_key() {
        let t = MIN.replace("crossover_hz = 10", "crossover_hz = -1");
        let e = LoadedConfig::from_text(Path::new("p.toml"), &t).unwrap_err();
        let s = e.to_string();
        assert!(s.starts_with("p.toml:6: key `control.crossover_hz`"), "{s}");
        let t = MIN.replace("crossover_hz = 10", "crossover_hz = \"ten\"");
        let s = LoadedConfig::from_text(Path::new("p.toml"), &t)
            .unwrap_err()
            .to_string();
        assert!(s.starts_with("p.toml:6: key `control.crossover_hz`"), "{s}");
        let t = MIN.replace("file = \"a.csv\"", "file = \"a.csv\"\nfiel = 1");
        let s = LoadedConfig::from_text(Path::new("p.toml"), &t)
            .unwrap_err()
            .to_string();
        assert!(s.contains("p.toml:4") && s.contains("runs[0].fiel"), "{s}");
    }

    #[test]
    fn compensation_keys_default_and_bad_values_name_line_and_key() {
        let c = LoadedConfig::from_text(Path::new("p.toml"), MIN).unwrap();
        assert_eq!(c.config.compensation, CompensationSettings::default());
        assert!(c.config.compensation.enabled);
        let with = |body: &str| format!("{MIN}\n[compensation]\n{body}\n");
        let ok = LoadedConfig::from_text(
            Path::new("p.toml"),
            &with("enabled = false\namplitude_tol = 0.0\nvelocity_resolution = 0.02"),
        )
        .unwrap();
        assert!(!ok.config.compensation.enabled);
        assert_eq!(ok.config.compensation.velocity_resolution, Some(0.02));
        // The [compensation] header is on line 9, its key on line 10.
        for (body, key) in [
            ("amplitude_tol = -1", "compensation.amplitude_tol"),
            (
                "velocity_resolution = 0",
                "compensation.velocity_resolution",
            ),
            (
                "inverse_smoothing_rel = 1.5",
                "compensation.inverse_smoothing_rel",
            ),
            ("tracking_time_s = -0.1", "compensation.tracking_time_s"),
            ("simulate_s = 0", "compensation.simulate_s"),
            ("enabled = \"yes\"", "compensation.enabled"),
            ("smoothing = 1", "compensation.smoothing"),
        ] {
            let e = LoadedConfig::from_text(Path::new("p.toml"), &with(body))
                .unwrap_err()
                .to_string();
            assert!(e.starts_with("p.toml:10"), "{body}: {e}");
            assert!(e.contains(key), "{body}: {e}");
        }
    }
}
