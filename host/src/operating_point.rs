//! The operating point a model was identified at, and how to use a model on raw logs.
//!
//! `identify` and `run` remove each channel's mean (or line) before N4SID, so the model maps
//! *deviations* from an operating point: `y − y0 = G (u − u0)`. A consumer that simulates the
//! model on a raw log (validation on fresh data, the gap diagnosis, a firmware check) must
//! subtract `u0` from the input first and add `y0` to the output, or it compares a zero-mean
//! model with offset data. Model files therefore carry an [`OperatingPoint`] (optional in the
//! JSON, so files written before it still load), and [`simulate_raw`] is the one function that
//! applies it.
//!
//! * `u0`, `y0`: the means removed from the estimation data, per channel in the log's units
//!   (with several estimation logs, their sample-weighted average). With trend removal they
//!   are the means of the removed lines over the estimation data; the slopes are not part of an
//!   operating point and are not re-applied.
//! * `detrend`: `mean`, `trend` or `none` (then `u0 = y0 = 0`).
//! * `decimation`: the factor the raw logs were decimated by (1 = none); raw logs handed to
//!   [`simulate_raw`] must already be at the model's rate (`fs_raw_hz / decimation`).
pub use crate::data::OperatingPoint;
use crate::error::{Error, Result};
use crate::lti::StateSpace;
use crate::preprocess::{Preprocessing, StepRecord};

/// The operating point of estimation logs preprocessed as `records` say (one record per
/// log, inputs listed before outputs in each step, as [`crate::preprocess::preprocess`]
/// writes them), with `m` inputs and `p` outputs (`u0`/`y0` are zeros when no offset was
/// removed).
///
/// # Errors
/// [`Error::InvalidArgument`] for no record or records with different channel counts.
pub fn operating_point_of(records: &[Preprocessing], m: usize, p: usize) -> Result<OperatingPoint> {
    let first = records
        .first()
        .ok_or_else(|| Error::InvalidArgument("operating point of no log".into()))?;
    let mut detrend = "none";
    let mut decimation = 1usize;
    let mut sums: Vec<f64> = Vec::new();
    let mut total = 0.0f64;
    for r in records {
        let w = r.samples_in as f64;
        let mut offsets: Option<Vec<f64>> = None;
        for s in &r.steps {
            match s {
                StepRecord::RemoveMean { channels } => {
                    detrend = "mean";
                    offsets = Some(channels.iter().map(|c| c.mean).collect());
                }
                StepRecord::RemoveTrend { channels } => {
                    detrend = "trend";
                    // Mean of the line offset + slope·t over t in [0, (n−1)·ts].
                    let half_span = 0.5 * (r.samples_in.saturating_sub(1)) as f64 * r.ts_in;
                    offsets = Some(
                        channels
                            .iter()
                            .map(|c| c.offset + c.slope_per_s * half_span)
                            .collect(),
                    );
                }
                StepRecord::Decimate { factor, .. } => decimation = *factor,
            }
        }
        if let Some(o) = offsets {
            if sums.is_empty() {
                sums = vec![0.0; o.len()];
            }
            if o.len() != sums.len() {
                return Err(Error::InvalidArgument(format!(
                    "operating point: {} has {} channels, {} has {}",
                    r.source,
                    o.len(),
                    first.source,
                    sums.len()
                )));
            }
            for (s, v) in sums.iter_mut().zip(o) {
                *s += w * v;
            }
            total += w;
        }
    }
    let means: Vec<f64> = if total > 0.0 {
        sums.iter().map(|s| s / total).collect()
    } else {
        Vec::new()
    };
    let (u0, y0) = if means.is_empty() {
        (vec![0.0; m], vec![0.0; p])
    } else {
        if m + p != means.len() {
            return Err(Error::InvalidArgument(format!(
                "operating point: {m} inputs and {p} outputs but {} channels recorded",
                means.len()
            )));
        }
        (means[..m].to_vec(), means[m..].to_vec())
    };
    Ok(OperatingPoint {
        u0,
        y0,
        detrend: detrend.into(),
        decimation,
        fs_raw_hz: 1.0 / first.ts_in,
    })
}

/// Free-run simulation of `model` on raw input signals `u` (log units, at the model's sample
/// rate), through the operating point: `y = y0 + G (u − u0)` with initial state `x0` (zero when
/// `None`). Without an operating point (`op = None`, an old model file) the signals are used
/// as they are.
///
/// # Errors
/// As [`StateSpace::simulate`] (channel count or length mismatch).
pub fn simulate_raw(
    model: &StateSpace,
    op: Option<&OperatingPoint>,
    u: &[&[f64]],
    x0: Option<&[f64]>,
) -> Result<Vec<Vec<f64>>> {
    let shifted: Vec<Vec<f64>> = u
        .iter()
        .enumerate()
        .map(|(j, c)| {
            let u0 = op.map_or(0.0, |o| o.input_offset(j));
            c.iter().map(|v| v - u0).collect()
        })
        .collect();
    let mut y = model.simulate(&shifted, x0)?;
    if let Some(o) = op {
        for (i, yi) in y.iter_mut().enumerate() {
            let y0 = o.output_offset(i);
            for v in yi.iter_mut() {
                *v += y0;
            }
        }
    }
    Ok(y)
}

/// Raw output signals `y` (log units) as deviations from the operating point (`y − y0`), the
/// quantity the model predicts from `u − u0`.
pub fn output_deviation(op: Option<&OperatingPoint>, y: &[&[f64]]) -> Vec<Vec<f64>> {
    y.iter()
        .enumerate()
        .map(|(i, c)| {
            let y0 = op.map_or(0.0, |o| o.output_offset(i));
            c.iter().map(|v| v - y0).collect()
        })
        .collect()
}

/// Raw logs brought to where a model with operating point `op` applies: inputs `u − u0`,
/// outputs `y − y0` ([`output_deviation`]), then decimated by `decimate` (default: the factor
/// `op` records) — what `ferrosid gap` and the pipeline's gap stage hand the diagnosis. Returns
/// the decimation factor applied (1 for none).
///
/// # Errors
/// As [`crate::preprocess::preprocess`] (a log too short to decimate).
pub fn logs_at_model_point(
    op: Option<&OperatingPoint>,
    decimate: Option<usize>,
    logs: &mut [crate::data::Log],
) -> Result<usize> {
    if let Some(op) = op {
        for log in logs.iter_mut() {
            let y: Vec<&[f64]> = log.outputs.iter().map(|c| c.data.as_slice()).collect();
            let y_dev = output_deviation(Some(op), &y);
            for (c, d) in log.outputs.iter_mut().zip(y_dev) {
                c.data = d;
            }
            for (j, c) in log.inputs.iter_mut().enumerate() {
                let u0 = op.input_offset(j);
                c.data.iter_mut().for_each(|v| *v -= u0);
            }
        }
    }
    let factor = decimate.or_else(|| op.map(|o| o.decimation)).unwrap_or(1);
    if factor > 1 {
        let steps = [crate::preprocess::Step::Decimate { factor }];
        for log in logs.iter_mut() {
            *log = crate::preprocess::preprocess(log, &steps)?.0;
        }
    }
    Ok(factor.max(1))
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::Mat;

    #[test]
    fn raw_simulation_goes_through_the_operating_point() {
        // y[k+1]-state model: x+ = 0.5 x + u, y = x (DC gain 2).
        let g = StateSpace::new(
            Mat::from_fn(1, 1, |_, _| 0.5),
            Mat::from_fn(1, 1, |_, _| 1.0),
            Mat::from_fn(1, 1, |_, _| 1.0),
            Mat::zeros(1, 1),
            1e-3,
        )
        .unwrap();
        let op = OperatingPoint {
            u0: vec![3.0],
            y0: vec![-7.0],
            detrend: "mean".into(),
            decimation: 1,
            fs_raw_hz: 1000.0,
        };
        // The raw input sits at the operating point: the output stays at y0.
        let u = vec![3.0; 50];
        let y = simulate_raw(&g, Some(&op), &[&u], None).unwrap();
        assert!(y[0].iter().all(|v| (v + 7.0).abs() < 1e-12), "{:?}", y[0]);
        // One unit above it: the output settles at y0 + 2.
        let u = vec![4.0; 60];
        let y = simulate_raw(&g, Some(&op), &[&u], None).unwrap();
        assert!((y[0][59] - (-5.0)).abs() < 1e-12);
        // Without an operating point the signals are used as they are.
        let y = simulate_raw(&g, None, &[&u], None).unwrap();
        assert!((y[0][59] - 8.0).abs() < 1e-12);
        assert_eq!(
            output_deviation(Some(&op), &[&[-7.0, -6.0][..]]),
            vec![vec![0.0, 1.0]]
        );
    }
}
