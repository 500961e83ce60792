//! CSV logs with a header line.
//!
//! Format: an optional block of comment lines starting with `#`, then one header line naming the
//! columns, then one row per sample. Fields are separated by `,` (or `;` / tab, detected from
//! the header line when [`CsvOptions::delimiter`] is `None`); whitespace around fields is
//! ignored, blank lines are skipped, `#` lines may appear anywhere. Every row must have as many
//! fields as the header. Only the selected columns are parsed as numbers; a non-numeric or
//! non-finite value there is an error naming the line and column.
use std::path::Path;

use super::{finish_log, sample_time, Checks, TimeSource};
use crate::data::Channel;
use crate::error::{Error, Result};
use crate::Log;

/// What to read from a CSV log.
#[derive(Debug, Clone, PartialEq)]
pub struct CsvOptions {
    /// Input column names (default `["u"]`).
    pub inputs: Vec<String>,
    /// Output column names (default `["y"]`).
    pub outputs: Vec<String>,
    /// Time column. `None` (default): use column `t` if the header has one, otherwise require
    /// [`CsvOptions::fs`].
    pub time: Option<String>,
    /// Seconds per unit of the time column (default 1.0: the column is in seconds).
    pub time_scale: f64,
    /// Sample rate in Hz; required without a time column, checked against it otherwise.
    pub fs: Option<f64>,
    /// Field separator; `None` (default) detects `,`, `;` or tab from the header line.
    pub delimiter: Option<u8>,
    /// Plausibility checks.
    pub checks: Checks,
}

impl Default for CsvOptions {
    fn default() -> Self {
        Self {
            inputs: vec!["u".into()],
            outputs: vec!["y".into()],
            time: None,
            time_scale: 1.0,
            fs: None,
            delimiter: None,
            checks: Checks::default(),
        }
    }
}

/// Reads a CSV log (see the module documentation for the format and [`super`] for the checks).
///
/// Errors: [`Error::Io`] when unreadable; [`Error::Parse`] with the 1-based line for a missing
/// column (header line), a wrong field count, a non-numeric or non-finite value, non-monotonic
/// or non-uniform time; [`Error::Data`] for an empty file, a header without rows, a constant
/// input or too few samples.
pub fn read_csv(path: &Path, opts: &CsvOptions) -> Result<Log> {
    opts.checks.validate()?;
    let bytes = std::fs::read(path).map_err(|source| Error::Io {
        file: path.to_path_buf(),
        source,
    })?;
    let file = path.to_path_buf();
    let parse_err = |line: usize, msg: String| Error::Parse {
        file: file.clone(),
        line,
        msg,
    };
    let data_err = |msg: String| Error::Data {
        file: file.clone(),
        msg,
    };
    if opts.inputs.is_empty() || opts.outputs.is_empty() {
        return Err(Error::InvalidArgument(
            "select at least one input and one output column".into(),
        ));
    }
    if !(opts.time_scale.is_finite() && opts.time_scale > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "time scale must be finite and > 0 s per unit, got {}",
            opts.time_scale
        )));
    }

    let delimiter = match opts.delimiter {
        Some(d) => d,
        None => detect_delimiter(&bytes),
    };
    let mut rdr = ::csv::ReaderBuilder::new()
        .has_headers(false)
        .comment(Some(b'#'))
        .flexible(true)
        .trim(::csv::Trim::All)
        .delimiter(delimiter)
        .from_reader(&bytes[..]);

    let mut rec = ::csv::StringRecord::new();
    let read = |rdr: &mut ::csv::Reader<&[u8]>, rec: &mut ::csv::StringRecord| -> Result<bool> {
        rdr.read_record(rec).map_err(|e| {
            let line = e.position().map_or(0, |p| p.line() as usize);
            match e.kind() {
                ::csv::ErrorKind::Utf8 { .. } => parse_err(line, "invalid UTF-8".into()),
                _ => parse_err(line, format!("malformed CSV: {e}")),
            }
        })
    };
    // The csv crate reports a record's position as the start of any blank/comment lines skipped
    // before it; walk past those to name the line the record is really on.
    let line_of = |rec: &::csv::StringRecord| {
        rec.position().map_or(0, |p| {
            true_line(&bytes, p.byte() as usize, p.line() as usize)
        })
    };

    // Header.
    loop {
        if !read(&mut rdr, &mut rec)? {
            return Err(data_err("empty file: no header line".into()));
        }
        if !(rec.len() == 1 && rec[0].is_empty()) {
            break;
        }
    }
    let header_line = line_of(&rec);
    let header: Vec<String> = rec.iter().map(|s| s.to_string()).collect();
    let find = |name: &str| -> Result<usize> {
        let hits: Vec<usize> = header
            .iter()
            .enumerate()
            .filter(|(_, h)| h.as_str() == name)
            .map(|(i, _)| i)
            .collect();
        match hits.as_slice() {
            [i] => Ok(*i),
            [] => Err(parse_err(
                header_line,
                format!(
                    "column `{}` not found in the header; columns are: {}",
                    crate::error::excerpt(name),
                    crate::error::excerpt_n(&header.join(", "), 400)
                ),
            )),
            _ => Err(parse_err(
                header_line,
                format!(
                    "column `{}` appears {} times in the header",
                    crate::error::excerpt(name),
                    hits.len()
                ),
            )),
        }
    };
    let in_idx: Vec<usize> = opts.inputs.iter().map(|n| find(n)).collect::<Result<_>>()?;
    let out_idx: Vec<usize> = opts
        .outputs
        .iter()
        .map(|n| find(n))
        .collect::<Result<_>>()?;
    let time_idx: Option<usize> = match &opts.time {
        Some(name) => Some(find(name)?),
        None => header.iter().position(|h| h == "t"),
    };
    if time_idx.is_none() && opts.fs.is_none() {
        return Err(parse_err(
            header_line,
            "no time column (`t` by default) and no sample rate given: add a time column or \
             give fs"
                .into(),
        ));
    }
    let time_name = time_idx.map(|i| header[i].clone());

    // Rows.
    let nf = header.len();
    let mut ins: Vec<Vec<f64>> = vec![Vec::new(); in_idx.len()];
    let mut outs: Vec<Vec<f64>> = vec![Vec::new(); out_idx.len()];
    let mut t: Vec<f64> = Vec::new();
    // How each time stamp was printed (for its rounding, see `super::printed`).
    let mut t_printed: Vec<Option<super::printed::Printed>> = Vec::new();
    let mut lines: Vec<usize> = Vec::new();
    let field = |rec: &::csv::StringRecord, i: usize, line: usize| -> Result<f64> {
        let s = rec.get(i).unwrap_or("");
        let v: f64 = s.parse().map_err(|_| {
            parse_err(
                line,
                format!(
                    "column `{}`: `{}` is not a number",
                    crate::error::excerpt(&header[i]),
                    crate::error::excerpt(s)
                ),
            )
        })?;
        if !v.is_finite() {
            return Err(parse_err(
                line,
                format!(
                    "column `{}`: value `{}` is not finite",
                    crate::error::excerpt(&header[i]),
                    crate::error::excerpt(s)
                ),
            ));
        }
        Ok(v)
    };
    while read(&mut rdr, &mut rec)? {
        let line = line_of(&rec);
        if rec.len() == 1 && rec[0].is_empty() {
            continue; // a line of whitespace only
        }
        if rec.len() != nf {
            return Err(parse_err(
                line,
                format!("expected {nf} fields as in the header, found {}", rec.len()),
            ));
        }
        for (col, &i) in ins.iter_mut().zip(&in_idx) {
            col.push(field(&rec, i, line)?);
        }
        for (col, &i) in outs.iter_mut().zip(&out_idx) {
            col.push(field(&rec, i, line)?);
        }
        if let Some(i) = time_idx {
            t.push(field(&rec, i, line)? * opts.time_scale);
            t_printed.push(super::printed::Printed::parse(rec.get(i).unwrap_or("")));
        }
        lines.push(line);
    }
    if lines.is_empty() {
        return Err(data_err(format!(
            "no data rows after the header (line {header_line})"
        )));
    }

    let (ts, time_warning) = match &time_name {
        Some(name) => {
            let what = format!("time column `{name}`");
            let t_rounding = super::printed::column_rounding(&t_printed, opts.time_scale);
            sample_time(
                TimeSource::Stamps {
                    t: &t,
                    rounding: &t_rounding,
                    fs: opts.fs,
                    what: &what,
                },
                &opts.checks,
                &|k, msg| parse_err(lines[k], msg),
                &|msg| data_err(msg),
            )?
        }
        None => sample_time(
            TimeSource::Rate(opts.fs.unwrap_or(f64::NAN)),
            &opts.checks,
            &|k, msg| parse_err(lines[k], msg),
            &|msg| data_err(msg),
        )?,
    };

    let mk = |names: &[String], cols: Vec<Vec<f64>>| -> Vec<Channel> {
        names
            .iter()
            .zip(cols)
            .map(|(n, data)| Channel {
                name: n.clone(),
                data,
            })
            .collect()
    };
    let mut log = finish_log(
        path,
        ts,
        mk(&opts.inputs, ins),
        mk(&opts.outputs, outs),
        &opts.checks,
    )?;
    log.warnings.extend(time_warning);
    Ok(log)
}

/// Delimiter of the first non-comment, non-blank line: `,` if present, else `;`, else tab,
/// else `,`.
fn detect_delimiter(bytes: &[u8]) -> u8 {
    for line in bytes.split(|&b| b == b'\n') {
        let trimmed: &[u8] = {
            let s = line
                .iter()
                .position(|b| !b.is_ascii_whitespace())
                .unwrap_or(line.len());
            &line[s..]
        };
        if trimmed.is_empty() || trimmed[0] == b'#' {
            continue;
        }
        for d in [b',', b';', b'\t'] {
            if trimmed.contains(&d) {
                return d;
            }
        }
        return b',';
    }
    b','
}

/// Line of the first byte at or after `byte` that is not part of a blank or `#` comment line.
fn true_line(bytes: &[u8], mut byte: usize, mut line: usize) -> usize {
    while byte < bytes.len() {
        match bytes[byte] {
            b'\n' => {
                line += 1;
                byte += 1;
            }
            b'\r' => byte += 1,
            b'#' => match bytes[byte..].iter().position(|&b| b == b'\n') {
                Some(k) => {
                    byte += k + 1;
                    line += 1;
                }
                None => break,
            },
            _ => break,
        }
    }
    line
}
