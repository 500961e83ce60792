//! Step 1 of the algorithm: the input/output channels identified from, their checks (finite,
//! non-constant, equal length) and their RMS scaling.
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use super::options::{N4sidOptions, OrderSelection, MAX_BLOCK_ROWS};
use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

pub(super) fn data_err(source: &Path, msg: String) -> Error {
    Error::Data {
        file: PathBuf::from(source),
        msg,
    }
}

/// Root mean square, computed on the signal normalised by an exact power of two so that the
/// squares neither overflow (|x| near 1e300) nor underflow (near 1e-300).
pub(super) fn rms(x: &[f64]) -> f64 {
    let g = crate::spectral::power_of_two_scale(crate::spectral::max_abs(x));
    (x.iter().map(|v| (v * g) * (v * g)).sum::<f64>() / x.len() as f64).sqrt() / g
}

/// Checks every channel of `data` (finite, non-constant, equal length); returns the length.
pub(super) fn check_channels(data: &ChannelSet<'_>) -> Result<usize> {
    // Compiled for AVX2 too (the finiteness scan and the largest magnitude vectorise 4 wide;
    // the sums keep their order): the same results.
    super::linalg::with_avx(
        #[inline(always)]
        || check_channels_body(data),
    )
}

#[inline(always)]
fn check_channels_body(data: &ChannelSet<'_>) -> Result<usize> {
    let (source, u, y, un, yn) = (data.source, data.u, data.y, data.u_names, data.y_names);
    if u.is_empty() || y.is_empty() {
        return Err(data_err(
            source,
            format!(
                "need at least one input and one output channel, got {} and {}",
                u.len(),
                y.len()
            ),
        ));
    }
    let n = u[0].len();
    for (ch, name, kind) in u
        .iter()
        .zip(un)
        .map(|(c, n)| (c, n, "input"))
        .chain(y.iter().zip(yn).map(|(c, n)| (c, n, "output")))
    {
        if ch.len() != n {
            return Err(data_err(
                source,
                format!(
                    "{kind} `{name}` has {} samples but `{}` has {n} (mismatched lengths)",
                    ch.len(),
                    un[0]
                ),
            ));
        }
        if let Some(k) = ch.iter().position(|v| !v.is_finite()) {
            return Err(data_err(
                source,
                format!("{kind} `{name}` sample {k} is {} (not finite)", ch[k]),
            ));
        }
        if n > 0 {
            let g = crate::spectral::power_of_two_scale(crate::spectral::max_abs(ch));
            let mean = ch.iter().map(|v| v * g).sum::<f64>() / n as f64;
            let var = ch.iter().map(|v| (v * g - mean).powi(2)).sum::<f64>() / n as f64;
            let r = rms(ch) * g;
            if !(var.sqrt() > 1e-12 * r) {
                let what = if kind == "input" {
                    "no excitation"
                } else {
                    "nothing to identify"
                };
                return Err(data_err(
                    source,
                    format!("{kind} `{name}` is constant ({what})"),
                ));
            }
        }
    }
    Ok(n)
}

/// Named, equal-length input/output channels with their sample time and origin: the data
/// [`super::identify`] works on.
#[derive(Debug, Clone, Copy)]
pub struct ChannelSet<'a> {
    /// Where the data came from (named in error messages): a file, or a description.
    pub source: &'a Path,
    /// Sample time in seconds (finite, > 0).
    pub ts: f64,
    /// Input channels u[j], all of the same length N.
    pub u: &'a [&'a [f64]],
    /// Output channels y[i], of length N.
    pub y: &'a [&'a [f64]],
    /// Names of the input channels (for error messages).
    pub u_names: &'a [String],
    /// Names of the output channels (for error messages).
    pub y_names: &'a [String],
}

/// The channel views and names of a [`Log`](crate::data::Log), which a [`ChannelSet`]
/// borrows: `LogChannels::of(&log).set()` is the log as identification data.
#[derive(Debug, Clone)]
pub struct LogChannels<'a> {
    source: &'a Path,
    ts: f64,
    u: Vec<&'a [f64]>,
    y: Vec<&'a [f64]>,
    u_names: Vec<String>,
    y_names: Vec<String>,
}

impl<'a> LogChannels<'a> {
    /// The inputs and outputs of `log`, named as in the log, with its path and sample time.
    pub fn of(log: &'a crate::data::Log) -> Self {
        LogChannels {
            source: &log.path,
            ts: log.ts,
            u: log.inputs.iter().map(|c| c.data.as_slice()).collect(),
            y: log.outputs.iter().map(|c| c.data.as_slice()).collect(),
            u_names: log.inputs.iter().map(|c| c.name.clone()).collect(),
            y_names: log.outputs.iter().map(|c| c.name.clone()).collect(),
        }
    }

    /// The channels as identification data.
    pub fn set(&self) -> ChannelSet<'_> {
        ChannelSet {
            source: self.source,
            ts: self.ts,
            u: &self.u,
            y: &self.y,
            u_names: &self.u_names,
            y_names: &self.y_names,
        }
    }
}

/// The checked dimensions of one identification problem.
pub(super) struct Problem {
    /// Samples per channel N.
    pub(super) len: usize,
    /// Inputs m.
    pub(super) m: usize,
    /// Outputs p.
    pub(super) p: usize,
    /// Block rows i.
    pub(super) k: usize,
    /// Smallest order considered.
    pub(super) n_lo: usize,
    /// Largest order considered.
    pub(super) n_hi: usize,
    /// The order fixed by the caller, if any.
    pub(super) fixed: Option<usize>,
}

/// Checks the sample time, the options against the data, and every channel (finite,
/// non-constant, equal length, enough samples for the block rows and orders asked for).
pub(super) fn check_problem(data: &ChannelSet<'_>, opts: &N4sidOptions) -> Result<Problem> {
    let (source, ts, u, y) = (data.source, data.ts, data.u, data.y);
    if !(ts.is_finite() && ts > 0.0) {
        return Err(data_err(
            source,
            format!("sample time {ts} s must be finite and > 0"),
        ));
    }
    let k = opts.block_rows;
    if !(2..=MAX_BLOCK_ROWS).contains(&k) {
        return Err(Error::InvalidArgument(format!(
            "block_rows (i) must be in 2..={MAX_BLOCK_ROWS}, got {k}"
        )));
    }
    if let Some(mg) = opts.stability_margin {
        if !(mg > 0.0 && mg < 1.0) {
            return Err(Error::InvalidArgument(format!(
                "stability margin must be in (0, 1), got {mg}"
            )));
        }
    }
    let len = check_channels(data)?;
    let (m, p) = (u.len(), y.len());
    let q = m + p;
    let max_order = (k - 1) * p;
    let (n_lo, n_hi, fixed) = match opts.order {
        OrderSelection::Auto => (1, max_order.min(20), None),
        OrderSelection::Range { min, max } => {
            if min == 0 || min > max || max > max_order {
                return Err(Error::InvalidArgument(format!(
                    "order range {min}..={max} invalid: need 1 <= min <= max <= (i−1)·p = \
                     {max_order} (increase block_rows for higher orders)"
                )));
            }
            (min, max, None)
        }
        OrderSelection::Fixed(n) => {
            if n == 0 || n > max_order {
                return Err(Error::InvalidArgument(format!(
                    "order {n} invalid: need 1 <= n <= (i−1)·p = {max_order} (increase \
                     block_rows for higher orders)"
                )));
            }
            (n, n, Some(n))
        }
    };
    let nrows = 2 * k * q;
    let min_len = 2 * k - 1 + nrows.max(2 * k * q + n_hi);
    if len < min_len {
        return Err(data_err(
            source,
            format!(
                "too few samples for N4SID with i = {k} block rows and {m} input(s), {p} \
                 output(s): have {len}, need at least {min_len} (reduce block_rows or record \
                 longer)"
            ),
        ));
    }
    Ok(Problem {
        len,
        m,
        p,
        k,
        n_lo,
        n_hi,
        fixed,
    })
}

/// The channels divided by their RMS values (step 1).
pub(super) struct Scaled {
    /// w = [u/su; y/sy], inputs first.
    pub(super) w: Vec<Vec<f64>>,
    /// RMS of each input channel.
    pub(super) input_scale: Vec<f64>,
    /// RMS of each output channel.
    pub(super) output_scale: Vec<f64>,
}

/// Step 1: divides every channel by its RMS value.
pub(super) fn scale(data: &ChannelSet<'_>) -> Scaled {
    let su: Vec<f64> = data.u.iter().map(|c| rms(c)).collect();
    let sy: Vec<f64> = data.y.iter().map(|c| rms(c)).collect();
    let w: Vec<Vec<f64>> = data
        .u
        .iter()
        .zip(&su)
        .chain(data.y.iter().zip(&sy))
        .map(|(c, s)| c.iter().map(|v| v / s).collect())
        .collect();
    Scaled {
        w,
        input_scale: su,
        output_scale: sy,
    }
}
