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
}

/// `[gap]`: the pipeline's gap-diagnosis stage ([`super::gap_stage`]).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GapSettings {
    /// `auto` (default: when the audit or a model receipt flags), `always` or `never`.
    #[serde(default)]
    pub run: super::gap_stage::GapRun,
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
        let config: PipelineConfig = toml::from_str(text).map_err(|e| {
            let (line, key) = match e.span() {
                Some(span) => {
                    let line = text[..span.start.min(text.len())].matches('\n').count() + 1;
                    (line, key_at_line(text, line))
                }
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
        let loaded = Self {
            path: path.to_path_buf(),
            base_dir,
            text: text.to_string(),
            config,
        };
        loaded.validate()?;
        Ok(loaded)
    }

    /// An error about `key` (dotted, e.g. `control.crossover_hz` or `runs[1].file`), naming the
    /// file and the key's line when it is written in the file.
    pub fn key_error(&self, key: &str, msg: impl std::fmt::Display) -> Error {
        match find_key_line(&self.text, key) {
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

    fn validate(&self) -> Result<()> {
        let c = &self.config;
        let pos = |key: &str, v: f64| -> Result<()> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(self.key_error(key, format!("must be finite and > 0, got {v}")))
            }
        };
        if c.runs.is_empty() {
            return Err(Error::Data {
                file: self.path.clone(),
                msg: "no `[[runs]]`: give at least one excitation log".into(),
            });
        }
        let names = self.run_names();
        for (i, n) in names.iter().enumerate() {
            if n.is_empty() || n == "validation" {
                return Err(self.key_error(
                    &format!("runs[{i}].name"),
                    format!("`{n}` is reserved or empty; choose another name"),
                ));
            }
            if names[..i].contains(n) {
                return Err(self.key_error(
                    &format!("runs[{i}].name"),
                    format!("duplicate run name `{n}`"),
                ));
            }
        }
        let mut entries: Vec<(String, &LogEntry)> = c
            .runs
            .iter()
            .enumerate()
            .map(|(i, r)| (format!("runs[{i}]"), r))
            .collect();
        if let Some(v) = &c.validation {
            entries.push(("validation".into(), v));
        }
        for (k, e) in &entries {
            if e.file.as_os_str().is_empty() {
                return Err(self.key_error(&format!("{k}.file"), "empty path"));
            }
            if let Some(a) = e.amplitude {
                pos(&format!("{k}.amplitude"), a)?;
            }
            if let Some(fs) = e.fs {
                pos(&format!("{k}.fs"), fs)?;
            }
        }
        if let Some(fs) = c.signals.fs {
            pos("signals.fs", fs)?;
        }
        if let Some(s) = c.signals.time_scale {
            pos("signals.time_scale", s)?;
        }
        if let Some(j) = c.signals.time_jitter {
            if !(0.0..=crate::io::MAX_TIME_JITTER_REL).contains(&j) {
                return Err(self.key_error(
                    "signals.time_jitter",
                    format!(
                        "must lie in [0, {}], got {j}",
                        crate::io::MAX_TIME_JITTER_REL
                    ),
                ));
            }
        }
        let max_q = crate::preprocess::MAX_DECIMATION;
        if !(1..=max_q).contains(&c.preprocess.decimate) {
            return Err(self.key_error(
                "preprocess.decimate",
                format!(
                    "must be in 1..={max_q} (1 = no decimation), got {}",
                    c.preprocess.decimate
                ),
            ));
        }
        let e = &c.etfe;
        let (lo, hi) = (crate::spectral::MIN_NPERSEG, crate::spectral::MAX_NPERSEG);
        if !(lo..=hi).contains(&e.nperseg) {
            return Err(self.key_error(
                "etfe.nperseg",
                format!("must be in {lo}..={hi}, got {}", e.nperseg),
            ));
        }
        if let Some(o) = e.overlap {
            if o >= e.nperseg {
                return Err(self.key_error(
                    "etfe.overlap",
                    format!("must be < nperseg = {}, got {o}", e.nperseg),
                ));
            }
        }
        if !(e.coherence_gate > 0.0 && e.coherence_gate <= 1.0) {
            return Err(self.key_error(
                "etfe.coherence_gate",
                format!("must lie in (0, 1], got {}", e.coherence_gate),
            ));
        }
        let id = &c.identification;
        if let Some(r) = &id.run {
            if !names.contains(r) {
                return Err(self.key_error(
                    "identification.run",
                    format!("no run named `{r}` (runs: {})", names.join(", ")),
                ));
            }
        }
        let max_i = crate::n4sid::MAX_BLOCK_ROWS;
        if !(2..=max_i).contains(&id.block_rows) {
            return Err(self.key_error(
                "identification.block_rows",
                format!("must be in 2..={max_i}, got {}", id.block_rows),
            ));
        }
        if id.order == Some(0) {
            return Err(self.key_error("identification.order", "must be >= 1"));
        }
        if id.order.is_some() && (id.order_min.is_some() || id.order_max.is_some()) {
            return Err(self.key_error(
                "identification.order",
                "give either a fixed `order` or `order_min`/`order_max`, not both",
            ));
        }
        if let (Some(lo), Some(hi)) = (id.order_min, id.order_max) {
            if lo == 0 || hi < lo {
                return Err(self.key_error(
                    "identification.order_max",
                    format!("order range {lo}..={hi} is empty or starts at 0"),
                ));
            }
        }
        if let Some(m) = id.stability_margin {
            if !(m > 0.0 && m < 1.0) {
                return Err(self.key_error(
                    "identification.stability_margin",
                    format!("must lie in (0, 1), got {m}"),
                ));
            }
        }
        let a = &c.audit;
        if !(a.band_factor > 1.0 && a.band_factor <= MAX_BAND_FACTOR) {
            return Err(self.key_error(
                "audit.band_factor",
                format!("must lie in (1, {MAX_BAND_FACTOR}], got {}", a.band_factor),
            ));
        }
        pos("audit.max_gain_shift_db", a.max_gain_shift_db)?;
        pos("audit.max_phase_shift_deg", a.max_phase_shift_deg)?;
        if !(0.0..=1.0).contains(&a.min_coherence) {
            return Err(self.key_error(
                "audit.min_coherence",
                format!("must lie in [0, 1], got {}", a.min_coherence),
            ));
        }
        if !(a.coherence_band_factor >= 1.0 && a.coherence_band_factor <= MAX_BAND_FACTOR) {
            return Err(self.key_error(
                "audit.coherence_band_factor",
                format!(
                    "must lie in [1, {MAX_BAND_FACTOR}], got {}",
                    a.coherence_band_factor
                ),
            ));
        }
        let u = &c.uncertainty;
        if !(1..=3).contains(&u.order) {
            return Err(self.key_error(
                "uncertainty.order",
                format!("must be 1, 2 or 3, got {}", u.order),
            ));
        }
        pos("uncertainty.min_level", u.min_level)?;
        if !(u.beyond_band_level.is_finite() && u.beyond_band_level >= 0.0) {
            return Err(self.key_error(
                "uncertainty.beyond_band_level",
                format!("must be finite and >= 0, got {}", u.beyond_band_level),
            ));
        }
        if let Some(b) = u.below_band_level {
            if !(b.is_finite() && b > 0.0) {
                return Err(self.key_error(
                    "uncertainty.below_band_level",
                    format!("must be finite and > 0, got {b}"),
                ));
            }
        }
        if let Some(fam) = &u.family {
            if fam.is_empty() {
                return Err(self.key_error("uncertainty.family", "is empty"));
            }
            for m in fam {
                let known = names.contains(m) || (m == "validation" && c.validation.is_some());
                if !known {
                    return Err(self.key_error(
                        "uncertainty.family",
                        format!(
                            "no log named `{m}` (runs: {}{})",
                            names.join(", "),
                            if c.validation.is_some() {
                                ", validation"
                            } else {
                                ""
                            }
                        ),
                    ));
                }
            }
        }
        let k = &c.control;
        pos("control.crossover_hz", k.crossover_hz)?;
        if !(k.ms_max.is_finite() && k.ms_max > 1.0) {
            return Err(self.key_error(
                "control.ms_max",
                format!(
                    "must be finite and > 1 (|S| >= 1 somewhere for every loop), got {}",
                    k.ms_max
                ),
            ));
        }
        pos("control.actuator_limit", k.actuator_limit)?;
        pos("control.reference_amplitude", k.reference_amplitude)?;
        if let Some(r) = k.rolloff_ratio {
            if !(r.is_finite() && r > 1.0) {
                return Err(self.key_error(
                    "control.rolloff_ratio",
                    format!("must be > 1 (corner above the crossover), got {r}"),
                ));
            }
        }
        pos("control.rolloff_zeta", k.rolloff_zeta)?;
        if !(k.min_crossover_scale > 0.0 && k.min_crossover_scale <= 1.0) {
            return Err(self.key_error(
                "control.min_crossover_scale",
                format!("must lie in (0, 1], got {}", k.min_crossover_scale),
            ));
        }
        let r = &c.receipts;
        for (key, v) in [
            ("receipts.gain_margin_db_min", r.gain_margin_db_min),
            ("receipts.phase_margin_deg_min", r.phase_margin_deg_min),
            ("receipts.mt_max", r.mt_max),
            (
                "receipts.disturbance_bandwidth_hz_min",
                r.disturbance_bandwidth_hz_min,
            ),
            ("receipts.overshoot_pct_max", r.overshoot_pct_max),
            ("receipts.settling_time_s_max", r.settling_time_s_max),
            (
                "receipts.etfe_phase_error_deg_max",
                r.etfe_phase_error_deg_max,
            ),
            ("receipts.etfe_max_freq_factor", r.etfe_max_freq_factor),
        ] {
            if let Some(v) = v {
                pos(key, v)?;
            }
        }
        if let Some(v) = r.cross_validation_fit_min {
            if !(v.is_finite() && v <= 100.0) {
                return Err(self.key_error(
                    "receipts.cross_validation_fit_min",
                    format!("must be finite and <= 100 %, got {v}"),
                ));
            }
        }
        Ok(())
    }
}

/// The dotted key written on 1-based `line` of a TOML text (table header + key), if any.
fn key_at_line(text: &str, line: usize) -> Option<String> {
    let mut table = String::new();
    let mut counts: std::collections::BTreeMap<String, usize> = Default::default();
    for (i, l) in text.lines().enumerate() {
        let t = strip_comment(l).trim();
        if let Some(h) = header(t) {
            table = h.0.clone();
            if h.1 {
                let c = counts.entry(h.0.clone()).or_insert(0);
                table = format!("{}[{}]", h.0, *c);
                *c += 1;
            }
            if i + 1 == line {
                return Some(table);
            }
            continue;
        }
        if i + 1 == line {
            let key = t.split('=').next()?.trim().trim_matches('"');
            if key.is_empty() {
                return None;
            }
            return Some(if table.is_empty() {
                key.to_string()
            } else {
                format!("{table}.{key}")
            });
        }
    }
    None
}

/// 1-based line of a dotted key (`control.crossover_hz`, `runs[1].file`, or a table
/// `runs[1]`), if written in the text.
fn find_key_line(text: &str, key: &str) -> Option<usize> {
    let mut table = String::new();
    let mut counts: std::collections::BTreeMap<String, usize> = Default::default();
    let mut table_line = None;
    for (i, l) in text.lines().enumerate() {
        let t = strip_comment(l).trim();
        if let Some(h) = header(t) {
            table = h.0.clone();
            if h.1 {
                let c = counts.entry(h.0.clone()).or_insert(0);
                table = format!("{}[{}]", h.0, *c);
                *c += 1;
            }
            if table == key {
                return Some(i + 1);
            }
            if key.starts_with(&format!("{table}.")) {
                table_line = Some(i + 1);
            }
            continue;
        }
        if let Some(k) = t.split('=').next() {
            if !t.contains('=') {
                continue;
            }
            let k = k.trim().trim_matches('"');
            let full = if table.is_empty() {
                k.to_string()
            } else {
                format!("{table}.{k}")
            };
            if full == key {
                return Some(i + 1);
            }
        }
    }
    table_line
}

/// (`name`, is_array_of_tables) of a `[name]` / `[[name]]` header line.
fn header(t: &str) -> Option<(String, bool)> {
    if let Some(inner) = t.strip_prefix("[[").and_then(|s| s.strip_suffix("]]")) {
        return Some((inner.trim().to_string(), true));
    }
    if let Some(inner) = t.strip_prefix('[').and_then(|s| s.strip_suffix(']')) {
        return Some((inner.trim().to_string(), false));
    }
    None
}

fn strip_comment(l: &str) -> &str {
    // Good enough for locating keys: a '#' outside a quoted string starts a comment.
    let mut in_str = false;
    for (i, ch) in l.char_indices() {
        match ch {
            '"' => in_str = !in_str,
            '#' if !in_str => return &l[..i],
            _ => {}
        }
    }
    l
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
}
