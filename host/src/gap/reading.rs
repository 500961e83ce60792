//! Where a model with an operating point applies to the logs: the two readings the diagnosis
//! compares.
//!
//! A model written by `identify`/`run` maps deviations from the operating point it was
//! identified at (`u − u0`, `y − y0`). The diagnosis can read the logs that way (moved to the
//! model's operating point, *deviation* reading) or as read, with the model applied about zero
//! (*absolute* reading). Which one is right depends on the mechanism: Coulomb friction switches
//! at zero *absolute* speed and a dead zone acts around zero *absolute* command, so moving the
//! logs by `y0` moves the effect's switching point with them and hides it (the bundled example:
//! Coulomb friction 0.008 N·m fitted as 0.00096 in the deviation reading, 0.00802 in the
//! absolute one); a plant with a bias (gravity, a preload) is only linear about its operating
//! point. [`diagnose_at_operating_point`] runs both when the model has offsets. The deviation
//! reading is the model's own semantics and stays the answer unless the absolute one leaves a
//! validated gap smaller by more than the verdict margin ([`GapOptions::margin`], 10 %: the
//! same bar an effect must clear; NRMSE is normalised by the mean-removed output, so the two
//! compare). The report's notes say which reading was kept and both gaps.
use crate::data::{Log, OperatingPoint};
use crate::error::Result;
use crate::lti::StateSpace;
use crate::operating_point::logs_at_model_point;

use super::{diagnose, Diagnosis, GapOptions};

/// Diagnoses `sim` (discrete, at the rate of the decimated logs) against `train` and `validate`
/// as read, decimated by `decimate` (default: the factor `op` records), in the deviation
/// reading and, when `op` has offsets, the absolute reading too; returns the absolute reading
/// when its validated gap (`gap_after`) is below the deviation reading's by more than
/// `opts.margin` (relative), else the deviation reading. Errors: the deviation reading's error
/// when neither reading succeeds.
pub fn diagnose_at_operating_point(
    sim: &StateSpace,
    op: Option<&OperatingPoint>,
    decimate: Option<usize>,
    train: &[Log],
    validate: &Log,
    opts: &GapOptions,
) -> Result<Diagnosis> {
    let deviation = reading(sim, op, decimate, train, validate, opts);
    let Some(op) = op.filter(|o| o.has_offsets()) else {
        return deviation;
    };
    let factor = decimate.unwrap_or(op.decimation);
    let absolute = reading(sim, None, Some(factor), train, validate, opts);
    match (deviation, absolute) {
        (Ok(dev), Ok(mut abs))
            if abs.report.gap_after < (1.0 - opts.margin) * dev.report.gap_after =>
        {
            abs.report.notes.push(format!(
                "diagnosed on the logs as read (absolute signals, the model applied about zero): \
                 validated gap after {:.4}, against {:.4} with the logs moved to the model's \
                 operating point (u0 = {:?}, y0 = {:?})",
                abs.report.gap_after, dev.report.gap_after, op.u0, op.y0
            ));
            Ok(abs)
        }
        (Ok(mut dev), Ok(abs)) => {
            dev.report.notes.push(format!(
                "diagnosed on the logs moved to the model's operating point: validated gap \
                 after {:.4}, against {:.4} on the logs as read",
                dev.report.gap_after, abs.report.gap_after
            ));
            Ok(dev)
        }
        (Ok(dev), Err(_)) => Ok(dev),
        (Err(_), Ok(abs)) => Ok(abs),
        (Err(e), Err(_)) => Err(e),
    }
}

/// One reading: the logs moved to `op` (or only decimated when `op` is `None`), then diagnosed.
fn reading(
    sim: &StateSpace,
    op: Option<&OperatingPoint>,
    decimate: Option<usize>,
    train: &[Log],
    validate: &Log,
    opts: &GapOptions,
) -> Result<Diagnosis> {
    let mut logs: Vec<Log> = train
        .iter()
        .chain(std::iter::once(validate))
        .cloned()
        .collect();
    logs_at_model_point(op, decimate, &mut logs)?;
    let validate = logs.pop().ok_or_else(|| {
        crate::error::Error::InvalidArgument("the gap diagnosis needs a validation log".into())
    })?;
    diagnose(sim, &logs, &validate, opts)
}
