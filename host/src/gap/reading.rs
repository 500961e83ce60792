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
//!
//! When every offset is below [`NEGLIGIBLE_OFFSET`] of its channel's standard deviation in
//! every log, the two readings are the same signals to that precision (no switching point
//! moves by more than it, the diagnosis would run twice on what it cannot tell apart): only
//! the deviation reading runs, and a note says so. The F-16 model's offsets, e.g., are 1e-5 N
//! and 1.3e-5 m/s² against standard deviations of 12–98 N and 0.36–1.7 m/s².
use crate::data::{Log, OperatingPoint};
use crate::error::Result;
use crate::lti::StateSpace;
use crate::operating_point::logs_at_model_point;

use super::{diagnose, Diagnosis, GapOptions};

/// Largest offset, relative to its channel's standard deviation, at which the deviation and
/// absolute readings count as the same (module docs).
pub const NEGLIGIBLE_OFFSET: f64 = 1e-3;

/// Whether every offset of `op` is below [`NEGLIGIBLE_OFFSET`] times the standard deviation
/// of its channel in each of `logs` (a constant channel makes any non-zero offset count).
pub fn offsets_negligible(op: &OperatingPoint, logs: &[&Log]) -> bool {
    let std = |x: &[f64]| {
        let n = x.len().max(1) as f64;
        let mean = x.iter().sum::<f64>() / n;
        (x.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n).sqrt()
    };
    let small = |offset: f64, x: &[f64]| offset.abs() <= NEGLIGIBLE_OFFSET * std(x);
    logs.iter().all(|log| {
        log.inputs
            .iter()
            .enumerate()
            .all(|(j, c)| small(op.input_offset(j), &c.data))
            && log
                .outputs
                .iter()
                .enumerate()
                .all(|(i, c)| small(op.output_offset(i), &c.data))
    })
}

/// Diagnoses `sim` (discrete, at the rate of the decimated logs) against `train` and `validate`
/// as read, decimated by `decimate` (default: the factor `op` records), in the deviation
/// reading and, when `op` has offsets, the absolute reading too; returns the absolute reading
/// when its validated gap (`gap_after`) is below the deviation reading's by more than
/// `opts.margin` (relative), else the deviation reading. Errors: the deviation reading's error
/// when neither reading succeeds. With [`offsets_negligible`] only the deviation reading runs.
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
    let logs: Vec<&Log> = train.iter().chain(std::iter::once(validate)).collect();
    if offsets_negligible(op, &logs) {
        return deviation.map(|mut d| {
            d.report.notes.push(format!(
                "the model's operating point (u0 = {:?}, y0 = {:?}) is below {} of every \
                 channel's standard deviation: the logs as read and moved to it are the same \
                 signals, diagnosed once",
                op.u0, op.y0, NEGLIGIBLE_OFFSET
            ));
            d
        });
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    fn op(u0: f64, y0: f64) -> OperatingPoint {
        OperatingPoint {
            u0: vec![u0],
            y0: vec![y0],
            detrend: "mean".into(),
            decimation: 1,
            fs_raw_hz: 100.0,
        }
    }

    /// The bar sits at 1e-3 of each channel's standard deviation, per log: a square wave of
    /// ±1 (std 1) around 5 takes an offset of 1e-3 but not 1.1e-3; the log with the smaller
    /// spread decides; a constant channel admits only a zero offset.
    #[test]
    fn offsets_are_negligible_below_a_thousandth_of_each_channels_spread() {
        let square: Vec<f64> = (0..100)
            .map(|i| 5.0 + if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let wide = Log::siso(
            "wide",
            0.01,
            square.clone(),
            square.iter().map(|v| 10.0 * v).collect(),
        );
        let narrow = Log::siso("narrow", 0.01, square.clone(), square.clone());
        assert!(offsets_negligible(&op(1e-3, 1e-3), &[&wide, &narrow]));
        assert!(!offsets_negligible(&op(1.1e-3, 0.0), &[&wide, &narrow]));
        assert!(offsets_negligible(&op(0.0, 1e-2), &[&wide]));
        assert!(!offsets_negligible(&op(0.0, 1e-2), &[&wide, &narrow]));
        let flat = Log::siso("flat", 0.01, square, vec![5.0; 100]);
        assert!(offsets_negligible(&op(0.0, 0.0), &[&flat]));
        assert!(!offsets_negligible(&op(0.0, 1e-12), &[&flat]));
        assert!(!offsets_negligible(&op(f64::NAN, 0.0), &[&narrow]));
    }
}
