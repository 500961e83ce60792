//! Logs from arrays in memory, for front ends that do not read files (the Python package
//! hands numpy arrays in): the same checks the file readers apply ([`crate::io`]: equal
//! channel lengths, finite samples, a sample rate, an excited input; clipping and constant
//! outputs as warnings), with `source` standing for the file name in every message.
//! Given a sample time `ts` in seconds (not a rate) so that a log read from a file and handed
//! back as arrays keeps its sample time bit for bit.
use crate::data::{Channel, Log};
use crate::error::{Error, Result};
use crate::io::{check_fs, finish_log, Checks};
use std::path::Path;

/// A log of `inputs` and `outputs` (name, samples) sampled every `ts_s` seconds, checked like
/// a file read by [`crate::io::read_log`]; `source` names the log in reports and errors.
///
/// # Errors
/// [`Error::InvalidArgument`] for a sample time whose rate 1/ts is not finite and positive;
/// [`Error::Data`] naming `source` and the channel for a non-finite sample (with its index),
/// no channel, channels of different lengths, no samples or a constant input.
pub fn log_from_arrays(
    source: &str,
    ts_s: f64,
    inputs: Vec<(String, Vec<f64>)>,
    outputs: Vec<(String, Vec<f64>)>,
) -> Result<Log> {
    if !(ts_s.is_finite() && ts_s > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "sample time must be a finite positive number of seconds, got {ts_s}"
        )));
    }
    check_fs(1.0 / ts_s)?;
    let channels = |v: Vec<(String, Vec<f64>)>| -> Result<Vec<Channel>> {
        v.into_iter()
            .map(|(name, data)| {
                if let Some(i) = data.iter().position(|x| !x.is_finite()) {
                    return Err(Error::Data {
                        file: Path::new(source).to_path_buf(),
                        msg: format!(
                            "channel `{}` sample {i} (0-based) is {}: every sample must be a \
                             finite number",
                            crate::error::excerpt(&name),
                            data[i]
                        ),
                    });
                }
                Ok(Channel { name, data })
            })
            .collect()
    };
    let (inputs, outputs) = (channels(inputs)?, channels(outputs)?);
    finish_log(Path::new(source), ts_s, inputs, outputs, &Checks::default())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arrays_are_checked_like_files() {
        let ch = |n: &str, v: &[f64]| vec![(n.to_string(), v.to_vec())];
        let ok = log_from_arrays(
            "mem",
            0.01,
            ch("u", &[0.0, 1.0, -1.0]),
            ch("y", &[0.0, 2.0, 1.0]),
        )
        .expect("log");
        assert_eq!(
            (ok.len(), ok.ts, ok.inputs[0].name.as_str()),
            (3, 0.01, "u")
        );
        let err = |r: Result<Log>| r.unwrap_err().to_string();
        let nan = err(log_from_arrays(
            "mem",
            0.01,
            ch("u", &[0.0, f64::NAN]),
            ch("y", &[0.0, 1.0]),
        ));
        assert!(
            nan.contains("mem") && nan.contains("`u` sample 1") && nan.contains("NaN"),
            "{nan}"
        );
        let len = err(log_from_arrays(
            "mem",
            0.01,
            ch("u", &[0.0, 1.0]),
            ch("y", &[0.0]),
        ));
        assert!(len.contains("has 1 samples but `u` has 2"), "{len}");
        let empty = err(log_from_arrays("mem", 0.01, ch("u", &[]), ch("y", &[])));
        assert!(empty.contains("no samples"), "{empty}");
        assert!(
            log_from_arrays("mem", f64::NAN, ch("u", &[0.0, 1.0]), ch("y", &[0.0, 1.0])).is_err()
        );
        let flat = err(log_from_arrays(
            "mem",
            1.0,
            ch("u", &[1.0, 1.0]),
            ch("y", &[0.0, 1.0]),
        ));
        assert!(flat.contains("constant"), "{flat}");
    }
}
