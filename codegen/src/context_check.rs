//! The closed-loop power-up check's settings ([`ClosedLoopCheck`], `self_id.closed_loop`):
//! validation and the literals of the check block in the header and module (`c.clcheck`).
//!
//! The closed-loop check runs the generated controller (with its compensation, if enabled),
//! adds the self-identification multisine (same lines, period, settling, averages and check
//! bins as the open-loop check) to the loop's *reference*, and estimates the plant as
//! `S_ry / S_ru` (`ferrosid_firmware::check::ClosedLoopEstimator`); the reference is the
//! injection point because the flashed control law then runs exactly as in operation and the
//! excitation's amplitude is set and held in output units (see the firmware module's docs).
use serde::{Deserialize, Serialize};

use crate::context::{lit, Lit};
use crate::error::{Error, Result};
use crate::input::{check_f32, CodegenInput};

/// Closed-loop check settings (optional; absent: the module says `None`, the header `0`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClosedLoopCheck {
    /// RMS of the multisine added to the reference, in plant *output* units (it is a
    /// reference, not a command), finite, > 0 and <= 1e9.
    pub reference_rms: f64,
}

/// What the templates see under `c.clcheck`.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct ClCheckLit {
    /// The input has closed-loop check settings.
    pub has: bool,
    /// `1`/`0` for the C macro.
    pub has_c: String,
    /// The reference multisine's RMS (0 when absent).
    pub reference_rms: Lit,
    /// The Rust constant's value: `Some(..)` or `None`.
    pub reference_rms_rs: String,
}

/// Validates `input.self_id.closed_loop` and renders it.
///
/// # Errors
/// [`Error::Input`] naming `self_id.closed_loop.reference_rms` for a non-finite, non-positive
/// or too large RMS, and `self_id.closed_loop` when the input has no controller to close the
/// loop with (neither `pid` nor `state_controller`).
pub(crate) fn clcheck_lit(input: &CodegenInput) -> Result<ClCheckLit> {
    let Some(cl) = &input.self_id.closed_loop else {
        return Ok(ClCheckLit {
            has: false,
            has_c: "0".into(),
            reference_rms: lit(0.0),
            reference_rms_rs: "None".into(),
        });
    };
    let field = "self_id.closed_loop.reference_rms";
    let v = cl.reference_rms;
    check_f32(field, v)?;
    if !(v > 0.0 && v <= 1e9) {
        return Err(Error::input(
            field,
            format!("{v} must be > 0 and <= 1e9 (output units)"),
        ));
    }
    if input.pid.is_none() && input.state_controller.is_none() {
        return Err(Error::input(
            "self_id.closed_loop",
            "the closed-loop check needs the generated controller to close the loop, and the \
             input has neither `pid` nor `state_controller`",
        ));
    }
    let l = lit(v);
    Ok(ClCheckLit {
        has: true,
        has_c: "1".into(),
        reference_rms_rs: format!("Some({})", l.rs),
        reference_rms: l,
    })
}
