//! Headerless whitespace-separated numeric text, such as the DaISy `.dat` benchmark sets.
//!
//! Format: one sample per line, fields separated by spaces and/or tabs, every data line with the
//! same number of fields as the first. Blank lines and lines starting with `#` or `%` are
//! skipped. There is no time column, so the sample rate must be given.
use std::path::Path;

use super::{check_fs, finish_log, Checks};
use crate::data::Channel;
use crate::error::{Error, Result};
use crate::Log;

/// What to read from a whitespace-separated text log.
#[derive(Debug, Clone, PartialEq)]
pub struct TextOptions {
    /// Input columns, **1-based** as a human counts them (default `[1]`).
    pub input_cols: Vec<usize>,
    /// Output columns, 1-based (default `[2]`).
    pub output_cols: Vec<usize>,
    /// Sample rate in Hz (required: these files carry no time information; use 1.0 for
    /// normalised frequency when the rate is unknown, as for the DaISy sets).
    pub fs: Option<f64>,
    /// Plausibility checks.
    pub checks: Checks,
}

impl Default for TextOptions {
    fn default() -> Self {
        Self {
            input_cols: vec![1],
            output_cols: vec![2],
            fs: None,
            checks: Checks::default(),
        }
    }
}

/// Reads a headerless whitespace-separated log. Channels are named `col<k>` (1-based k).
///
/// Errors: [`Error::Io`]; [`Error::Parse`] with the 1-based line for a wrong field count, a
/// non-numeric or non-finite value, or a selected column beyond the field count (first data
/// line); [`Error::Data`] for a file without data lines, a constant input or too few samples;
/// [`Error::InvalidArgument`] for a missing/invalid `fs` or column 0.
pub fn read_columns(path: &Path, opts: &TextOptions) -> Result<Log> {
    opts.checks.validate()?;
    let fs = opts.fs.ok_or_else(|| {
        Error::InvalidArgument(format!(
            "{}: text logs carry no time information; give the sample rate fs (Hz)",
            path.display()
        ))
    })?;
    check_fs(fs)?;
    if opts.input_cols.is_empty() || opts.output_cols.is_empty() {
        return Err(Error::InvalidArgument(
            "select at least one input and one output column".into(),
        ));
    }
    if opts
        .input_cols
        .iter()
        .chain(&opts.output_cols)
        .any(|&c| c == 0)
    {
        return Err(Error::InvalidArgument(
            "text columns are numbered from 1".into(),
        ));
    }
    let bytes = crate::io::input::read_bytes(path, crate::io::input::MAX_LOG_BYTES)?;
    crate::io::input::check_utf8_family(path, &bytes)?;
    let parse_err = |line: usize, msg: String| Error::Parse {
        file: path.to_path_buf(),
        line,
        msg,
    };
    let text = std::str::from_utf8(&bytes).map_err(|e| {
        let line = 1 + bytes[..e.valid_up_to()]
            .iter()
            .filter(|&&b| b == b'\n')
            .count();
        parse_err(line, "invalid UTF-8".into())
    })?;

    let mut nf: Option<usize> = None;
    let mut ins: Vec<Vec<f64>> = vec![Vec::new(); opts.input_cols.len()];
    let mut outs: Vec<Vec<f64>> = vec![Vec::new(); opts.output_cols.len()];
    let mut fields: Vec<&str> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let s = raw.trim();
        if s.is_empty() || s.starts_with('#') || s.starts_with('%') {
            continue;
        }
        fields.clear();
        fields.extend(s.split_ascii_whitespace());
        let n = *nf.get_or_insert(fields.len());
        if fields.len() != n {
            return Err(parse_err(
                line,
                format!(
                    "expected {n} fields as on the first data line, found {}",
                    fields.len()
                ),
            ));
        }
        if let Some(&c) = opts
            .input_cols
            .iter()
            .chain(&opts.output_cols)
            .find(|&&c| c > n)
        {
            return Err(parse_err(
                line,
                format!("column {c} requested but the file has {n} columns"),
            ));
        }
        let get = |c: usize| -> Result<f64> {
            let f = fields[c - 1];
            let v: f64 = f.parse().map_err(|_| {
                parse_err(
                    line,
                    format!("column {c}: `{}` is not a number", crate::error::excerpt(f)),
                )
            })?;
            if !v.is_finite() {
                return Err(parse_err(
                    line,
                    format!(
                        "column {c}: value `{}` is not finite",
                        crate::error::excerpt(f)
                    ),
                ));
            }
            Ok(v)
        };
        for (col, &c) in ins.iter_mut().zip(&opts.input_cols) {
            col.push(get(c)?);
        }
        for (col, &c) in outs.iter_mut().zip(&opts.output_cols) {
            col.push(get(c)?);
        }
    }
    if nf.is_none() {
        return Err(Error::Data {
            file: path.to_path_buf(),
            msg: "no data lines".into(),
        });
    }
    let mk = |cols: &[usize], data: Vec<Vec<f64>>| -> Vec<Channel> {
        cols.iter()
            .zip(data)
            .map(|(c, data)| Channel {
                name: format!("col{c}"),
                data,
            })
            .collect()
    };
    finish_log(
        path,
        1.0 / fs,
        mk(&opts.input_cols, ins),
        mk(&opts.output_cols, outs),
        &opts.checks,
    )
}
