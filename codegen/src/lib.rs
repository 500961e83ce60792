//! ferrosid-codegen: emits a C header and a `no_std` Rust module from an identified model.
//!
//! What the files hold (see `templates/model.h` and `templates/model.rs`):
//! * the discrete model A, B, C, D at the control rate as `float`/`f32` arrays, its dimensions as
//!   constants, and the continuous model as documentation comments;
//! * the PID controller in its discrete firmware form (gains and filter coefficients);
//! * the compensation of a diagnosed nonlinearity ([`Compensation`]: friction feedforward,
//!   dead-zone and backlash inverses, anti-windup) as a separate block with its parameters,
//!   units, provenance and enabled flag, applied after the PID by the firmware's control step
//!   (`ferrosid_firmware::control`); absent from the input, the block says so and the firmware
//!   runs the plain PID;
//! * the multiplicative uncertainty weight W_m(s) as continuous coefficients (s in rad/s), from
//!   which the firmware evaluates |W_m(j2πf)| at the check frequencies;
//! * the power-up self-identification settings and the check frequencies (Hz and Welch bins for
//!   the firmware's segment length N and sample rate);
//! * a provenance block: SHA-256 of the canonical input (every number and setting, and the
//!   SHA-256 of each source log) and the receipts summary.
//!
//! Determinism: no time stamp, no host name, no map iteration; numbers are printed as the
//! shortest decimal that reads back to the same `f32` (Rust's `{:?}`), so the same
//! [`CodegenInput`] always gives byte-identical files.
//!
//! Identifiers: the C names are `PREFIX_...` with the prefix sanitised by [`sanitize_prefix`];
//! the Rust module uses plain names (`A`, `N_STATES`, ...) and is meant to be included inside a
//! module of the caller's choosing.
//!
//! # Templates and user overrides
//! The built-in templates are compiled in with askama ([`generate`]): a syntax error or an
//! unknown variable in them is a build error. askama is compile-time only, so a user's own
//! templates are rendered at run time by minijinja instead ([`generate_with_templates`],
//! `ferrosid codegen --templates DIR`): copy `codegen/templates/` to `DIR`, edit, and pass the
//! directory. Both engines see the same context (`c`, see [`context_variables`]) and the
//! built-in templates use only the syntax the two share (`{{ c.x }}`, `{% for %}`, `{% if %}`
//! with `{% else %}`, `>` comparisons), so an unedited copy renders byte-identically through
//! either engine (tested). Numbers arrive pre-formatted (`v.c` / `v.rs` literals), so a template
//! needs no filters.
//!
//! ```
//! # use ferrosid_codegen::*;
//! let input = CodegenInput {
//!     prefix: "axis-1".into(),
//!     model: DiscreteModel {
//!         ts_s: 1e-3,
//!         matrices: Matrices {
//!             a: vec![vec![0.9]], b: vec![vec![1.0]], c: vec![vec![0.1]], d: vec![vec![0.0]],
//!         },
//!     },
//!     continuous: None,
//!     pid: None,
//!     weight: WeightCoefficients { num: vec![0.1], den: vec![1.0], note: "flat 10 %".into() },
//!     self_id: SelfIdSettings {
//!         welch_n: 256, check_hz: vec![10.0, 50.0], coherence_gate: 0.9, averages: 4,
//!         settle_periods: 1, excitation_rms: 1.0, excitation_max_hz: 100.0, min_checked: 1,
//!         closed_loop: None,
//!     },
//!     provenance: Provenance {
//!         tool: "example".into(), sources: vec![], receipts: vec![], notes: vec![],
//!     },
//!     operating_point: None,
//!     compensation: None,
//!     state_controller: None,
//! };
//! let out = generate(&input)?;
//! assert_eq!(out.c_file_name, "axis_1.h");
//! assert!(out.c_header.contains("static const float AXIS_1_A[AXIS_1_N_STATES][AXIS_1_N_STATES]"));
//! assert!(out.rust_module.contains("pub static CHECK_BIN: [u16; CHECK_COUNT] = [3, 13];"));
//! # Ok::<(), ferrosid_codegen::Error>(())
//! ```
#![forbid(unsafe_code)]

mod compensation;
mod context;
mod context_check;
mod context_comp;
mod context_sk;
mod error;
mod input;
mod text;

use std::path::Path;

use askama::Template;
use sha2::{Digest, Sha256};

pub use compensation::{
    AntiWindup, BacklashInverse, Compensation, CompensationProvenance, DeadZoneInverse,
    FrictionFeedforward, LagAwareFriction, VelocitySource, MAX_COMPENSATION_VALUE,
    MAX_HORIZON_LAGS, MIN_COMPENSATION_BAND,
};
pub use context::{snap_checks, CheckPoint, MAX_CHECKS};
pub use context_check::ClosedLoopCheck;
pub use context_sk::{MAX_CONTROLLER_ORDER, MAX_NOTCH_SECTIONS};
pub use error::{Error, Result};
pub use input::{
    Biquad, CodegenInput, ContinuousModel, ContinuousPid, Dims, DiscreteModel, Matrices,
    MpcController, OperatingPointValues, PidGains, PidNotchController, Provenance, ReceiptLine,
    SelfIdSettings, SourceDigest, StateController, StateSaturation, WeightCoefficients,
};
pub use text::{c_float, comment_text, f32_literal, sanitize_prefix};

/// File name of the built-in C template (also the name a user's override must have).
pub const C_TEMPLATE: &str = "model.h";
/// Largest accepted user template, bytes (the built-in ones have a few kB).
pub const MAX_TEMPLATE_BYTES: u64 = 1 << 20;
/// Engine instructions a user template may execute (minijinja fuel). The built-in templates
/// need a few thousand for a 20-state model; ten million is far above any sane template and
/// ends a runaway (e.g. nested loops over `range(100000)`) after about a second.
pub const TEMPLATE_FUEL: u64 = 10_000_000;
/// File name of the built-in Rust template (also the name a user's override must have).
pub const RUST_TEMPLATE: &str = "model.rs";

#[derive(Template)]
#[template(path = "model.h")]
struct CHeader<'a> {
    c: &'a context::Context,
}

#[derive(Template)]
#[template(path = "model.rs")]
struct RustModule<'a> {
    c: &'a context::Context,
}

/// The generated files and what was derived while generating them.
#[derive(Debug, Clone, PartialEq)]
pub struct Generated {
    /// Sanitised prefix of the C identifiers.
    pub prefix: String,
    /// Suggested C header file name (`<prefix lower case>.h`).
    pub c_file_name: String,
    /// Suggested Rust module file name (`<prefix lower case>.rs`).
    pub rs_file_name: String,
    /// The C header.
    pub c_header: String,
    /// The Rust module.
    pub rust_module: String,
    /// SHA-256 of the canonical input (also written into both files).
    pub inputs_sha256: String,
    /// The check frequencies after snapping to the Welch bins, ascending.
    pub checks: Vec<CheckPoint>,
}

/// Lower-case hex SHA-256 of `bytes`.
pub fn sha256_hex(bytes: &[u8]) -> String {
    let digest = Sha256::digest(bytes);
    let mut s = String::with_capacity(64);
    for b in digest {
        s.push_str(&format!("{b:02x}"));
    }
    s
}

/// SHA-256 of the canonical JSON of `input` (serde field order, shortest round-trip floats):
/// the "inputs" digest of the provenance block. The tool name is excluded so that a version
/// bump alone does not change it.
pub fn inputs_digest(input: &CodegenInput) -> String {
    let mut canon = input.clone();
    canon.provenance.tool.clear();
    // Serialising plain structs of numbers/strings/vectors cannot fail.
    let json = serde_json::to_vec(&canon).unwrap_or_default();
    sha256_hex(&json)
}

fn finish(mut s: String) -> String {
    // Both engines drop the template's final newline; files end with exactly one.
    while s.ends_with('\n') {
        s.pop();
    }
    s.push('\n');
    s
}

/// Renders the built-in (compiled-in askama) templates.
///
/// # Errors
/// [`Error::Input`] naming the offending field when the input is inconsistent (shapes,
/// non-finite or out-of-`f32`-range values, check frequencies off the excited bin grid, ...).
pub fn generate(input: &CodegenInput) -> Result<Generated> {
    let digest = inputs_digest(input);
    let (ctx, checks) = context::build(input, &digest)?;
    let render_err = |template: &str, e: askama::Error| Error::Render {
        template: template.into(),
        msg: e.to_string(),
    };
    let c_header = CHeader { c: &ctx }
        .render()
        .map_err(|e| render_err(C_TEMPLATE, e))?;
    let rust_module = RustModule { c: &ctx }
        .render()
        .map_err(|e| render_err(RUST_TEMPLATE, e))?;
    Ok(Generated {
        prefix: ctx.p.clone(),
        c_file_name: ctx.c_file.clone(),
        rs_file_name: ctx.rs_file.clone(),
        c_header: finish(c_header),
        rust_module: finish(rust_module),
        inputs_sha256: digest,
        checks,
    })
}

/// Renders the user's templates `dir/model.h` and `dir/model.rs` at run time (minijinja, strict
/// about undefined variables, no escaping); a file missing from `dir` falls back to the built-in
/// template. See the crate docs.
///
/// Bounds: a user template may have at most [`MAX_TEMPLATE_BYTES`] bytes, and its rendering
/// may execute at most [`TEMPLATE_FUEL`] engine instructions (minijinja's fuel), so nested
/// loops over huge ranges end with an error instead of running unbounded.
///
/// # Errors
/// As [`generate`]; [`Error::TemplateIo`] when `dir` is not a directory, or a template exists
/// but cannot be read or is too large; [`Error::Render`] naming the file and line for syntax
/// errors, unknown variables or a template that runs out of fuel.
pub fn generate_with_templates(input: &CodegenInput, dir: &Path) -> Result<Generated> {
    if !dir.is_dir() {
        return Err(Error::TemplateIo {
            file: dir.to_path_buf(),
            source: std::io::Error::new(
                std::io::ErrorKind::NotFound,
                "template directory not found (write a starting point with --write-templates DIR)",
            ),
        });
    }
    if ![C_TEMPLATE, RUST_TEMPLATE]
        .iter()
        .any(|name| dir.join(name).is_file())
    {
        return Err(Error::TemplateIo {
            file: dir.to_path_buf(),
            source: std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("holds neither {C_TEMPLATE} nor {RUST_TEMPLATE}"),
            ),
        });
    }
    let mut out = generate(input)?;
    let digest = out.inputs_sha256.clone();
    let (ctx, _) = context::build(input, &digest)?;
    for (name, slot) in [
        (C_TEMPLATE, &mut out.c_header),
        (RUST_TEMPLATE, &mut out.rust_module),
    ] {
        let path = dir.join(name);
        if !path.exists() {
            continue;
        }
        let meta = std::fs::metadata(&path).map_err(|source| Error::TemplateIo {
            file: path.clone(),
            source,
        })?;
        // Checked before opening: a FIFO would block the read, a device never end it.
        if !meta.is_file() {
            return Err(Error::TemplateIo {
                file: path.clone(),
                source: std::io::Error::other(
                    "not a regular file (a FIFO, device or directory); a template must be a file",
                ),
            });
        }
        let size = meta.len();
        if size > MAX_TEMPLATE_BYTES {
            return Err(Error::TemplateIo {
                file: path.clone(),
                source: std::io::Error::other(format!(
                    "{size} bytes; a template may have at most {MAX_TEMPLATE_BYTES}"
                )),
            });
        }
        let source = std::fs::read_to_string(&path).map_err(|source| Error::TemplateIo {
            file: path.clone(),
            source,
        })?;
        *slot = finish(render_runtime(&path, &source, &ctx)?);
    }
    Ok(out)
}

/// Renders `source` with the runtime engine (the same context the built-in templates see).
fn render_runtime(path: &Path, source: &str, ctx: &context::Context) -> Result<String> {
    let mut env = minijinja::Environment::new();
    env.set_fuel(Some(TEMPLATE_FUEL));
    env.set_undefined_behavior(minijinja::UndefinedBehavior::Strict);
    env.set_auto_escape_callback(|_| minijinja::AutoEscape::None);
    let name = path.display().to_string();
    let mut root = std::collections::BTreeMap::new();
    root.insert("c", ctx);
    env.render_named_str(&name, source, &root)
        .map_err(|e| Error::Render {
            template: name.clone(),
            msg: match e.line() {
                Some(l) => format!("line {l}: {e}"),
                None => e.to_string(),
            },
        })
}

/// Renders the built-in templates' source text with the runtime engine (used to show that the
/// two engines agree; also what `--templates` would produce from an unedited copy).
///
/// # Errors
/// As [`generate`].
pub fn generate_builtin_runtime(input: &CodegenInput) -> Result<Generated> {
    let mut out = generate(input)?;
    let (ctx, _) = context::build(input, &out.inputs_sha256)?;
    out.c_header = finish(render_runtime(
        Path::new(C_TEMPLATE),
        builtin_template(C_TEMPLATE).unwrap_or_default(),
        &ctx,
    )?);
    out.rust_module = finish(render_runtime(
        Path::new(RUST_TEMPLATE),
        builtin_template(RUST_TEMPLATE).unwrap_or_default(),
        &ctx,
    )?);
    Ok(out)
}

/// Source text of a built-in template by file name (`model.h`, `model.rs`), e.g. to write a
/// starting point for a user override.
pub fn builtin_template(name: &str) -> Option<&'static str> {
    match name {
        C_TEMPLATE => Some(include_str!("../templates/model.h")),
        RUST_TEMPLATE => Some(include_str!("../templates/model.rs")),
        _ => None,
    }
}

/// Names of the context variables under `c` available to templates, with what they hold
/// (for the `--templates` documentation).
pub fn context_variables() -> &'static [(&'static str, &'static str)] {
    &[
        ("c.p", "sanitised C prefix (upper case)"),
        ("c.guard", "include guard macro"),
        ("c.c_file, c.rs_file", "file names"),
        ("c.tool", "producing tool and version"),
        ("c.n_states, c.n_inputs, c.n_outputs", "dimensions"),
        (
            "c.ts.c / c.ts.rs, c.control_rate_hz.*",
            "sample time (s) and rate (Hz) literals",
        ),
        (
            "c.a.rows_c / c.a.rows_rs / c.a.rows_doc",
            "A rows (also c.b, c.cm for C, c.d)",
        ),
        (
            "c.has_continuous, c.cont_note, c.cont_a..c.cont_d",
            "continuous model rows (f64 text)",
        ),
        (
            "c.has_pid, c.pid_kp.*, c.pid_ki_d.*, c.pid_a_d.*, c.pid_b_d.*",
            "discrete PID",
        ),
        (
            "c.pid_has_rolloff, c.pid_rolloff_b_c/_rs, c.pid_rolloff_a_c/_rs",
            "roll-off biquad",
        ),
        ("c.pid_doc", "PID documentation lines"),
        (
            "c.wm_order, c.wm_num_c/_rs, c.wm_den_c/_rs, c.wm_doc",
            "W_m(s) coefficients",
        ),
        (
            "c.welch_n, c.fs_hz.*, c.coherence_gate.*, c.averages, c.settle_periods",
            "self-ID",
        ),
        (
            "c.self_id_samples, c.excitation_rms.*, c.excitation_max_bin, c.min_checked",
            "self-ID",
        ),
        (
            "c.check_count, c.checks[].bin/.hz/.requested, c.check_bins, c.check_hz_c/_rs",
            "checks",
        ),
        (
            "c.inputs_sha256, c.sources[].comment/.c_str/.rs_str/.sha256, c.source_count",
            "provenance",
        ),
        (
            "c.receipts[].comment/.name_c/.name_rs/.value_rs/.condition_rs/.pass",
            "receipts",
        ),
        (
            "c.receipt_count, c.receipts_all_pass, c.notes",
            "receipts and notes",
        ),
        (
            "c.comp.has, c.comp.enabled_c/_rs, c.comp.doc, c.comp.effect_c/_rs (also place, verdict, source)",
            "compensation block and its provenance",
        ),
        (
            "c.comp.has_ff, c.comp.ff_coulomb/ff_viscous/ff_smoothing_velocity/ff_filter_hz/ff_filter_alpha, c.comp.ff_velocity_c/_rs",
            "friction feedforward (velocity source 0 output, 1 output difference, 2 reference)",
        ),
        (
            "c.comp.has_ff_lag, c.comp.ff_lag_s/ff_lag_horizon_s/ff_lag_stick_band/ff_lag_pole/ff_lag_prediction_s",
            "lag-aware friction feedforward (pole = exp(-ts/lag), prediction = horizon + estimate delay)",
        ),
        (
            "c.comp.has_dz, c.comp.dz_width/dz_smoothing, c.comp.has_bl, c.comp.bl_gap/bl_smoothing",
            "dead-zone and backlash inverses",
        ),
        (
            "c.comp.has_aw, c.comp.aw_u_min/aw_u_max/aw_tracking_time_s/aw_gain",
            "anti-windup (aw_gain = ts/T_t)",
        ),
        (
            "c.u0_c, c.u0_rs, c.y0_c, c.y0_rs, c.op_note",
            "operating point U0/Y0 (C and Rust literals) and how it was obtained",
        ),
    ]
}
