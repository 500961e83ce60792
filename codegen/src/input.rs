//! The plain-data input of the generators: everything a header holds, as numbers and text.
//!
//! Deliberately free of host types (no faer matrices, no `ferrosid` structs) so that the
//! `ferrosid` host crate can depend on this crate without a cycle: the host fills a
//! [`CodegenInput`] from its identified model, tuned PID, uncertainty weight and receipts.
//!
//! Units: seconds, Hz (frequencies at which things are checked), rad/s (the Laplace variable of
//! the continuous W_m(s) and continuous model). Matrices are row-major `Vec<Vec<f64>>`:
//! `a[i][j]` is row `i`, column `j`.
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// A state-space quadruple, row-major. Shapes: A n×n, B n×m, C p×n, D p×m (n, m, p >= 1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Matrices {
    /// State matrix A, n rows of n.
    pub a: Vec<Vec<f64>>,
    /// Input matrix B, n rows of m.
    pub b: Vec<Vec<f64>>,
    /// Output matrix C, p rows of n.
    pub c: Vec<Vec<f64>>,
    /// Feedthrough matrix D, p rows of m.
    pub d: Vec<Vec<f64>>,
}

/// Dimensions of a [`Matrices`]: states, inputs, outputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dims {
    /// Number of states n.
    pub n: usize,
    /// Number of inputs m.
    pub m: usize,
    /// Number of outputs p.
    pub p: usize,
}

impl Matrices {
    /// Checks shapes (A n×n, B n×m, C p×n, D p×m with n, m, p >= 1), that every entry is finite
    /// and that it fits an `f32` (the headers store `float`). `what` names the model in errors.
    pub fn validate(&self, what: &str) -> Result<Dims> {
        let n = self.a.len();
        let m = self.d.first().map_or(0, Vec::len);
        let p = self.d.len();
        if n == 0 {
            return Err(Error::input(
                format!("{what}.a"),
                "the model has no states; a static gain has no dynamics to check on target",
            ));
        }
        if m == 0 || p == 0 {
            return Err(Error::input(
                format!("{what}.d"),
                "D must have at least one row (output) and one column (input)",
            ));
        }
        check_shape(&format!("{what}.a"), &self.a, n, n)?;
        check_shape(&format!("{what}.b"), &self.b, n, m)?;
        check_shape(&format!("{what}.c"), &self.c, p, n)?;
        check_shape(&format!("{what}.d"), &self.d, p, m)?;
        for (name, mat) in [
            ("a", &self.a),
            ("b", &self.b),
            ("c", &self.c),
            ("d", &self.d),
        ] {
            for (i, row) in mat.iter().enumerate() {
                for (j, &v) in row.iter().enumerate() {
                    check_f32(&format!("{what}.{name}[{i}][{j}]"), v)?;
                }
            }
        }
        Ok(Dims { n, m, p })
    }
}

fn check_shape(field: &str, rows: &[Vec<f64>], nr: usize, nc: usize) -> Result<()> {
    if rows.len() != nr {
        return Err(Error::input(
            field,
            format!("has {} rows, expected {nr}", rows.len()),
        ));
    }
    if let Some((i, r)) = rows.iter().enumerate().find(|(_, r)| r.len() != nc) {
        return Err(Error::input(
            format!("{field}[{i}]"),
            format!("has {} entries, expected {nc}", r.len()),
        ));
    }
    Ok(())
}

/// Checks that `v` is finite and representable as a finite `f32`.
pub(crate) fn check_f32(field: &str, v: f64) -> Result<()> {
    if !v.is_finite() {
        return Err(Error::input(field, format!("{v} is not finite")));
    }
    if v.abs() > f64::from(f32::MAX) {
        return Err(Error::input(
            field,
            format!("{v:e} does not fit a 32-bit float (|v| > 3.4e38)"),
        ));
    }
    Ok(())
}

/// The discrete model the firmware runs and checks, at the control rate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DiscreteModel {
    /// Sample time, s (> 0): x[k+1] = A x[k] + B u[k], y[k] = C x[k] + D u[k].
    pub ts_s: f64,
    /// A, B, C, D.
    pub matrices: Matrices,
}

/// The continuous model, emitted as documentation comments only (x' = A x + B u, t in s).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ContinuousModel {
    /// A, B, C, D of the continuous model.
    pub matrices: Matrices,
    /// How it relates to the discrete model (e.g. "inverse ZOH of the discrete model").
    pub note: String,
}

/// Continuous PID parameters, for documentation next to the discrete gains.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ContinuousPid {
    /// Proportional gain Kp.
    pub kp: f64,
    /// Integral gain Ki, 1/s.
    pub ki: f64,
    /// Derivative gain Kd, s.
    pub kd: f64,
    /// Derivative filter time constant τ_f, s.
    pub tau_f: f64,
}

/// A second-order section `y[k] = b0 x[k] + b1 x[k-1] + b2 x[k-2] - a1 y[k-1] - a2 y[k-2]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Biquad {
    /// `[b0, b1, b2]`.
    pub b: [f64; 3],
    /// `[1, a1, a2]` (a0 must be 1).
    pub a: [f64; 3],
}

/// The discrete PID law the firmware runs (Tustin, see `ferrosid::robust::pid`):
/// `p = kp·e[k]`, `i[k] = i[k-1] + ki_d·(e[k] + e[k-1])`, `d[k] = a_d·d[k-1] + b_d·(e[k] - e[k-1])`,
/// `v = p + i + d`, `u = rolloff(v)` when a roll-off biquad is present, else `u = v`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PidGains {
    /// Sample time, s (must equal the model's).
    pub ts_s: f64,
    /// Proportional gain.
    pub kp: f64,
    /// Trapezoidal integrator coefficient (Ki·ts/2 for plain Tustin).
    pub ki_d: f64,
    /// Derivative filter pole.
    pub a_d: f64,
    /// Derivative gain per sample.
    pub b_d: f64,
    /// Optional roll-off section applied to v.
    pub rolloff: Option<Biquad>,
    /// Tustin prewarp frequency, Hz (documentation).
    pub prewarp_hz: Option<f64>,
    /// The continuous controller it came from (documentation).
    pub continuous: Option<ContinuousPid>,
}

/// A general discrete SISO controller u = K·e in state-space form (H∞ mixed sensitivity,
/// PID + notch), emitted next to (and run instead of) the PID:
/// `xi[k+1] = A xi[k] + B e[k]`, `u[k] = C xi[k] + D e[k]`, e = r − y, u clamped to the rails
/// by the caller.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StateController {
    /// Design method (documentation), e.g. `hinf`.
    pub method: String,
    /// Sample time, s (must equal the model's).
    pub ts_s: f64,
    /// A (n×n), B (n×1), C (1×n), D (1×1).
    pub matrices: Matrices,
    /// Where it came from (documentation).
    pub note: String,
    /// The condensed MPC (method `mpc`): then `matrices` is the prediction model whose state
    /// the MPC feeds back (D = 0), not a controller u = K·e, and no K_* block is emitted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mpc: Option<MpcController>,
    /// The rails and the back-calculation gain of the state-space law (observer form,
    /// `ferrosid_firmware::control::StateSpaceLaw`): `v = C ξ + D e`, `u = clamp(v, u_min,
    /// u_max)`, `ξ⁺ = A ξ + B e + L (u − v)`. None: the step returns v and the caller clamps.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub saturation: Option<StateSaturation>,
    /// Method `pid-notch`: the same controller in the firmware's form, PID then notch biquads
    /// (`ferrosid_firmware::control::PidNotchLaw`), emitted next to the state-space block.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pid_notch: Option<PidNotchController>,
}

/// Rails and anti-windup gain of a [`StateController`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StateSaturation {
    /// Back-calculation gain L, one entry per controller state (all zero: plain clamping).
    pub l: Vec<f64>,
    /// Lower rail, input units.
    pub u_min: f64,
    /// Upper rail (> `u_min`).
    pub u_max: f64,
}

/// PID + notch cascade in the firmware's form: `w = PID(e)` (with its roll-off), `n =` the
/// biquads in series, `u = clamp(n, u_min, u_max)`; with `anti_windup` the PID's integration
/// is dropped for a step whose `w` lies beyond a rail in the direction it integrates
/// (conditional integration, as the host's design simulation).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PidNotchController {
    /// The PID part (Tustin, its own sample time must equal the model's).
    pub pid: PidGains,
    /// The notch (or lead) sections, applied in order.
    pub sections: Vec<Biquad>,
    /// Lower rail, input units.
    pub u_min: f64,
    /// Upper rail.
    pub u_max: f64,
    /// Conditional integration at the rails.
    pub anti_windup: bool,
}

/// The data of a condensed MPC for `ferrosid_firmware::mpc::MpcQp` (host design
/// `ferrosid::synth::mpc`): QP ½UᵀHU + fᵀU over the input sequence U (horizon N) with
/// f = G_x·x − g_r·r − 2ρ_Δ·e₁·u_prev, box u_min ≤ U ≤ u_max and |U_i − U_{i−1}| ≤ Δu_max,
/// solved by ADMM with K = (H + σI + ρMᵀM)⁻¹ and a fixed iteration budget per sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MpcController {
    /// Horizon N (samples).
    pub horizon: usize,
    /// K (N×N).
    pub k: Vec<Vec<f64>>,
    /// G_x = 2q·ΓᵀΦ (N×n): the prediction matrices Φ (free response) and Γ (forced
    /// response) folded with the output weight.
    pub gx: Vec<Vec<f64>>,
    /// g_r = 2q·Γᵀ·1 (N).
    pub gr: Vec<f64>,
    /// 2ρ_Δ.
    pub two_r_rate: f64,
    /// ADMM proximal weight σ.
    pub sigma: f64,
    /// ADMM penalty ρ (> 0).
    pub rho: f64,
    /// Input box lower limit, input units.
    pub u_min: f64,
    /// Input box upper limit.
    pub u_max: f64,
    /// Largest |u_k − u_{k−1}| per sample (> 0).
    pub du_max: f64,
    /// ADMM iterations per control step (1..=65535).
    pub iterations: u32,
}

/// The multiplicative uncertainty weight W_m(s) = num(s)/den(s), continuous, s in rad/s,
/// descending powers. The firmware evaluates |W_m(j·2πf)| at the check frequencies from these
/// coefficients. `num.len() == den.len()` (a proper weight of order `len - 1`, 0 for a constant
/// relative tolerance).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WeightCoefficients {
    /// Numerator, descending powers of s.
    pub num: Vec<f64>,
    /// Denominator, descending powers of s, leading coefficient non-zero.
    pub den: Vec<f64>,
    /// Where it came from (documentation).
    pub note: String,
}

/// Settings of the power-up self-identification the firmware runs, and the frequencies it checks.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SelfIdSettings {
    /// Welch segment length N (power of two, 64..=4096); also the multisine period.
    pub welch_n: usize,
    /// Requested check frequencies, Hz; each is snapped to the nearest bin `k·fs/N`.
    pub check_hz: Vec<f64>,
    /// Magnitude-squared coherence a bin needs for its check to count, in (0, 1).
    pub coherence_gate: f64,
    /// Segments (periods) averaged.
    pub averages: u32,
    /// Periods played before averaging starts (transient decay).
    pub settle_periods: u32,
    /// RMS of the multisine excitation, in plant input units.
    pub excitation_rms: f64,
    /// Highest excited frequency, Hz (lines `1..=floor(f·N/fs)` are excited, flat amplitude).
    pub excitation_max_hz: f64,
    /// Fewest check frequencies that must pass the coherence gate for a verdict.
    pub min_checked: usize,
    /// The closed-loop check's settings (the multisine at the reference of the generated
    /// controller's loop), see [`crate::ClosedLoopCheck`]. None: no closed-loop check (and the
    /// digest of an input without one is unchanged).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub closed_loop: Option<crate::ClosedLoopCheck>,
}

/// SHA-256 digest of one source file (a log, a settings file).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SourceDigest {
    /// How the file is referred to (its name as given on the command line).
    pub label: String,
    /// Lower-case hex SHA-256 of the file's bytes.
    pub sha256: String,
}

/// One line of the receipts summary.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReceiptLine {
    /// Receipt name (e.g. `sensitivity_peak`).
    pub name: String,
    /// Readable value with unit.
    pub value: String,
    /// Readable condition, e.g. `<= 1.6`.
    pub condition: String,
    /// Whether it passed.
    pub pass: bool,
}

/// Where the generated numbers came from. No wall-clock time: same inputs, same bytes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// Producing tool and version, e.g. `ferrosid 0.1.0`.
    pub tool: String,
    /// Digests of the source logs and settings files.
    pub sources: Vec<SourceDigest>,
    /// Receipts summary (may be empty).
    pub receipts: Vec<ReceiptLine>,
    /// Free-form notes (one line each), e.g. the identification command.
    pub notes: Vec<String>,
}

/// Everything a header holds. Filled by the host (`ferrosid codegen`), consumed by
/// [`crate::generate`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CodegenInput {
    /// Identifier prefix as given by the user; sanitised by [`crate::sanitize_prefix`].
    pub prefix: String,
    /// The discrete model at the control rate.
    pub model: DiscreteModel,
    /// The continuous model (documentation only).
    pub continuous: Option<ContinuousModel>,
    /// Discrete PID gains.
    pub pid: Option<PidGains>,
    /// Uncertainty weight W_m(s).
    pub weight: WeightCoefficients,
    /// Power-up self-identification settings.
    pub self_id: SelfIdSettings,
    /// Provenance block.
    pub provenance: Provenance,
    /// Operating point the model was identified at (None: the model maps raw signals, and the
    /// headers state U0 = Y0 = 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub operating_point: Option<OperatingPointValues>,
    /// Compensation of a diagnosed nonlinearity (friction feedforward, dead-zone and backlash
    /// inverses, anti-windup), see [`crate::Compensation`]. None: the headers carry no
    /// compensation block (and the digest of an input without one is unchanged).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compensation: Option<crate::Compensation>,
    /// A state-space controller chosen instead of the PID (`[control] method` other than
    /// `pid`). None: no such block in the files (and the digest of an input without one is
    /// unchanged).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub state_controller: Option<StateController>,
}

/// The operating point of the model: it maps deviations, `y − y0 = G (u − u0)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OperatingPointValues {
    /// Input offsets, one per input (plant input units).
    pub u0: Vec<f64>,
    /// Output offsets, one per output (plant output units).
    pub y0: Vec<f64>,
    /// How it was obtained, e.g. `means removed before identification, no decimation`.
    pub note: String,
}
