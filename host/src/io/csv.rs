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
    read_csv_impl(path, opts, true)
}

/// [`read_csv`], with the fast row parser ([`fast_rows`]) allowed or not (tests compare both).
fn read_csv_impl(path: &Path, opts: &CsvOptions, allow_fast: bool) -> Result<Log> {
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

    // Rows: the fast path for plain ASCII rows without quotes; anything else, and every error,
    // goes through the csv crate (which then produces the error).
    let nf = header.len();
    let body = rdr.position().byte() as usize;
    let fast = if allow_fast {
        fast_rows(
            &bytes,
            body,
            &Select {
                delimiter,
                nf,
                inputs: &in_idx,
                outputs: &out_idx,
                time: time_idx,
                time_scale: opts.time_scale,
            },
        )
    } else {
        None
    };
    let rows = match fast {
        Some(rows) => rows,
        None => {
            let mut r = Rows::new(in_idx.len(), out_idx.len());
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
                for (col, &i) in r.ins.iter_mut().zip(&in_idx) {
                    col.push(field(&rec, i, line)?);
                }
                for (col, &i) in r.outs.iter_mut().zip(&out_idx) {
                    col.push(field(&rec, i, line)?);
                }
                if let Some(i) = time_idx {
                    r.t.push(field(&rec, i, line)? * opts.time_scale);
                    r.t_text
                        .push(TimeText::Owned(rec.get(i).unwrap_or("").to_string()));
                }
                r.lines.push(line);
            }
            r
        }
    };
    let Rows {
        ins,
        outs,
        t,
        t_text,
        lines,
    } = rows;
    if lines.is_empty() {
        return Err(data_err(format!(
            "no data rows after the header (line {header_line})"
        )));
    }

    let (ts, time_warning) = match &time_name {
        Some(name) => {
            let what = format!("time column `{name}`");
            // How each time stamp was printed (for its rounding, see `super::printed`): only
            // looked at when the stamps are not uniform to the tolerance.
            let t_rounding = || {
                let printed: Vec<Option<super::printed::Printed>> = t_text
                    .iter()
                    .map(|s| super::printed::Printed::parse(s.text(&bytes)))
                    .collect();
                super::printed::column_rounding(&printed, opts.time_scale)
            };
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

/// Where the selected columns are and how many fields a row has.
struct Select<'a> {
    delimiter: u8,
    nf: usize,
    inputs: &'a [usize],
    outputs: &'a [usize],
    time: Option<usize>,
    time_scale: f64,
}

/// The text of one time stamp: a byte range of the file (fast path) or a copy (csv crate).
enum TimeText {
    Span(usize, usize),
    Owned(String),
}

impl TimeText {
    fn text<'b>(&'b self, bytes: &'b [u8]) -> &'b str {
        match self {
            // The fast path only records ASCII spans.
            TimeText::Span(a, b) => std::str::from_utf8(&bytes[*a..*b]).unwrap_or(""),
            TimeText::Owned(s) => s,
        }
    }
}

/// The data rows: selected columns, time stamps (s) with their text, and the 1-based line of
/// each row.
struct Rows {
    ins: Vec<Vec<f64>>,
    outs: Vec<Vec<f64>>,
    t: Vec<f64>,
    t_text: Vec<TimeText>,
    lines: Vec<usize>,
}

impl Rows {
    fn new(inputs: usize, outputs: usize) -> Self {
        Rows {
            ins: vec![Vec::new(); inputs],
            outs: vec![Vec::new(); outputs],
            t: Vec::new(),
            t_text: Vec::new(),
            lines: Vec::new(),
        }
    }
}

/// Whitespace that `str::trim` removes, among ASCII bytes (the csv crate's `Trim::All`).
fn is_trim_byte(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\n' | 0x0b | 0x0c | b'\r')
}

/// `bytes[a..b]` without leading and trailing [`is_trim_byte`] bytes.
fn trim_span(bytes: &[u8], mut a: usize, mut b: usize) -> (usize, usize) {
    while a < b && is_trim_byte(bytes[a]) {
        a += 1;
    }
    while b > a && is_trim_byte(bytes[b - 1]) {
        b -= 1;
    }
    (a, b)
}

/// Parses the data rows from byte `start` (just after the header record) without the csv
/// crate's record machinery, for the common case: every line plain ASCII without a quote
/// character, ended by `\n` or `\r\n`; `#` comment lines and blank lines skipped as the csv
/// crate skips them. Returns `None` as soon as the text leaves that subset or a row would be an
/// error (field count, a value that is not a finite number): the caller then reads the rows
/// with the csv crate, which yields the same values and reports the error with its line.
fn fast_rows(bytes: &[u8], start: usize, sel: &Select<'_>) -> Option<Rows> {
    // The header record must end at a line boundary (the byte before `start` is `\n`, or
    // `start` sits on the `\n` of a `\r\n` whose `\r` ended the header).
    // Delimiters the line splitting below would confuse with what it refuses or skips.
    if start > bytes.len()
        || start == 0
        || matches!(sel.delimiter, b'"' | b'#' | b'\r' | b'\n')
        || sel.delimiter >= 0x80
    {
        return None;
    }
    let boundary =
        bytes[start - 1] == b'\n' || bytes.get(start) == Some(&b'\n') || start == bytes.len();
    if !boundary {
        return None;
    }
    let mut line = 1 + bytes[..start].iter().filter(|&&b| b == b'\n').count();
    let mut rows = Rows::new(sel.inputs.len(), sel.outputs.len());
    // A guess of the row count from the first line's length (capacity only).
    if let Some(first) = bytes[start..].iter().take(4096).position(|&b| b == b'\n') {
        let guess = (bytes.len() - start) / (first + 1).max(8);
        for c in rows.ins.iter_mut().chain(rows.outs.iter_mut()) {
            c.reserve(guess);
        }
        rows.lines.reserve(guess);
        if sel.time.is_some() {
            rows.t.reserve(guess);
            rows.t_text.reserve(guess);
        }
    }
    let parse = |(a, b): (usize, usize)| -> Option<f64> {
        let v: f64 = std::str::from_utf8(&bytes[a..b]).ok()?.parse().ok()?;
        v.is_finite().then_some(v)
    };
    // Byte classes of the line scan.
    const PLAIN: u8 = 0;
    const NEWLINE: u8 = 1;
    const DELIMITER: u8 = 2;
    const CR: u8 = 3;
    const REFUSED: u8 = 4;
    let mut class = [PLAIN; 256];
    class[0x80..].fill(REFUSED);
    class[b'"' as usize] = REFUSED;
    class[b'\n' as usize] = NEWLINE;
    class[b'\r' as usize] = CR;
    class[sel.delimiter as usize] = DELIMITER;
    let mut fields: Vec<(usize, usize)> = Vec::with_capacity(sel.nf);
    let mut pos = start;
    while pos < bytes.len() {
        let this_line = line;
        let (a, mut end) = (pos, pos);
        if bytes[a] == b'#' {
            // A comment line (whatever it holds, up to the next `\n`, as the csv crate skips it).
            pos = bytes[a..]
                .iter()
                .position(|&b| b == b'\n')
                .map_or(bytes.len(), |k| a + k + 1);
            line += 1;
            continue;
        }
        fields.clear();
        let mut field_start = a;
        // One pass over the line: split at the delimiter, refuse what the csv crate treats
        // specially (quotes, lone carriage returns) and non-ASCII bytes.
        while end < bytes.len() {
            let b = bytes[end];
            match class[b as usize] {
                PLAIN => {}
                NEWLINE => break,
                DELIMITER => {
                    fields.push((field_start, end));
                    field_start = end + 1;
                }
                CR if bytes.get(end + 1) == Some(&b'\n') => {}
                _ => return None,
            }
            end += 1;
        }
        fields.push((field_start, end));
        pos = end + 1;
        line += 1;
        if fields.len() == 1 {
            let (fa, fb) = trim_span(bytes, fields[0].0, fields[0].1);
            if fa == fb {
                continue; // blank line
            }
        }
        if fields.len() != sel.nf {
            return None;
        }
        for (col, &i) in rows.ins.iter_mut().zip(sel.inputs) {
            let (fa, fb) = fields[i];
            col.push(parse(trim_span(bytes, fa, fb))?);
        }
        for (col, &i) in rows.outs.iter_mut().zip(sel.outputs) {
            let (fa, fb) = fields[i];
            col.push(parse(trim_span(bytes, fa, fb))?);
        }
        if let Some(i) = sel.time {
            let (fa, fb) = trim_span(bytes, fields[i].0, fields[i].1);
            rows.t.push(parse((fa, fb))? * sel.time_scale);
            rows.t_text.push(TimeText::Span(fa, fb));
        }
        rows.lines.push(this_line);
    }
    Some(rows)
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Reads `content` both ways: with the fast row parser allowed and with the csv crate only.
    fn both(name: &str, content: &[u8], opts: &CsvOptions) -> (Result<Log>, Result<Log>) {
        let dir = std::env::temp_dir().join(format!("ferrosid-csv-fast-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let p = dir.join(name);
        std::fs::write(&p, content).expect("write");
        let out = (
            read_csv_impl(&p, opts, true),
            read_csv_impl(&p, opts, false),
        );
        let _ = std::fs::remove_file(&p);
        out
    }

    /// The same log (every sample bit for bit, ts, warnings) or the same error message.
    fn assert_same(name: &str, content: &[u8], opts: &CsvOptions) {
        match both(name, content, opts) {
            (Ok(a), Ok(b)) => {
                assert_eq!(a.ts.to_bits(), b.ts.to_bits(), "{name}: ts");
                assert_eq!(a.warnings, b.warnings, "{name}: warnings");
                for (ca, cb) in a
                    .inputs
                    .iter()
                    .chain(&a.outputs)
                    .zip(b.inputs.iter().chain(&b.outputs))
                {
                    assert_eq!(ca.name, cb.name, "{name}");
                    let bits = |c: &Channel| c.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(ca), bits(cb), "{name}: channel {}", ca.name);
                }
                assert_eq!(a, b, "{name}");
            }
            (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string(), "{name}"),
            (a, b) => panic!("{name}: fast path {a:?}, csv crate {b:?}"),
        }
    }

    fn rows(n: usize, eol: &str) -> String {
        let mut s = String::new();
        for k in 0..n {
            s += &format!(
                "{},{},{}{eol}",
                k as f64 * 1e-3,
                if (k * 7919) % 3 == 0 {
                    -1.0
                } else {
                    0.5 + k as f64 / 7.0
                },
                (0.37 * k as f64).sin() * 1e-3
            );
        }
        s
    }

    /// Every variant of the quote-free format, and every error, reads exactly as the csv crate
    /// reads it; variants outside the fast path's subset fall back and agree as well.
    #[test]
    fn fast_rows_agree_with_the_csv_crate() {
        let d = CsvOptions::default();
        let body = rows(300, "\n");
        let mut cases: Vec<(&str, Vec<u8>, CsvOptions)> = vec![
            ("plain", format!("t,u,y\n{body}").into_bytes(), d.clone()),
            (
                "crlf",
                format!("t,u,y\r\n{}", rows(300, "\r\n")).into_bytes(),
                d.clone(),
            ),
            (
                "comments and blanks",
                format!("# head\n\n t , u ,y \n# mid\n\n   \n{body}# end °C \"q\"\n\n")
                    .into_bytes(),
                d.clone(),
            ),
            (
                "no final newline",
                format!("t,u,y\n{}", body.trim_end()).into_bytes(),
                d.clone(),
            ),
            (
                "spaces and tabs around fields",
                format!("t,u,y\n{}", body.replace(',', " ,\t ")).into_bytes(),
                d.clone(),
            ),
            (
                "semicolons",
                format!("t;u;y\n{}", body.replace(',', ";")).into_bytes(),
                d.clone(),
            ),
            (
                "tabs",
                format!("t\tu\ty\n{}", body.replace(',', "\t")).into_bytes(),
                d.clone(),
            ),
            (
                "quoted field falls back",
                format!("t,u,y\n{body}0.3,\"1\",2\n").into_bytes(),
                d.clone(),
            ),
            (
                "non-ASCII falls back",
                format!("t,u,y\n{body}0.3,1,2 µ\n").into_bytes(),
                d.clone(),
            ),
            (
                "lone CR falls back",
                format!("t,u,y\r{body}").into_bytes(),
                d.clone(),
            ),
            (
                "wrong field count",
                format!("t,u,y\n{body}0.3,1\n").into_bytes(),
                d.clone(),
            ),
            (
                "not a number",
                format!("t,u,y\n{}0.3,x1,2\n{body}", rows(5, "\n")).into_bytes(),
                d.clone(),
            ),
            (
                "not finite",
                format!("t,u,y\n{body}0.3,1,inf\n").into_bytes(),
                d.clone(),
            ),
            (
                "invalid UTF-8",
                [b"t,u,y\n0,1,2\n1,\xe92,3\n".as_slice()].concat(),
                d.clone(),
            ),
            ("header only", b"# c\nt,u,y\n\n# x\n".to_vec(), d.clone()),
            (
                "non-uniform time",
                format!("t,u,y\n{}0.0061,1,2\n", rows(6, "\n")).into_bytes(),
                d.clone(),
            ),
            (
                "stamps rounded to their printed digits",
                (0..400)
                    .map(|k| {
                        format!(
                            "{:.4},{},{}\n",
                            1000.0 + k as f64 / 3.0 * 1e-3,
                            k % 5,
                            k % 3
                        )
                    })
                    .fold("t,u,y\n".to_string(), |a, l| a + &l)
                    .into_bytes(),
                d.clone(),
            ),
            (
                "constant input",
                format!("t,u,y\n{}", "0,1,2\n".repeat(3)).into_bytes(),
                d.clone(),
            ),
        ];
        cases.push((
            "several selected columns, fs, no time",
            format!("a,b,c,d\n{}", "1,2,3,4\n2,4,1,0\n3,1,5,2\n").into_bytes(),
            CsvOptions {
                inputs: vec!["a".into(), "b".into()],
                outputs: vec!["d".into(), "a".into()],
                fs: Some(100.0),
                ..CsvOptions::default()
            },
        ));
        cases.push((
            "time in milliseconds",
            (0..50)
                .map(|k| format!("{k},{},{}\n", k % 4, k % 3))
                .fold("ms,u,y\n".to_string(), |a, l| a + &l)
                .into_bytes(),
            CsvOptions {
                time: Some("ms".into()),
                time_scale: 1e-3,
                ..CsvOptions::default()
            },
        ));
        for (name, content, opts) in &cases {
            assert_same(name, content, opts);
        }
    }

    /// The plain format is read by the fast path (not only by the fallback).
    #[test]
    fn plain_rows_take_the_fast_path() {
        let text = format!("t,u,y\n# c\n\n{}", rows(20, "\r\n"));
        let r = fast_rows(
            text.as_bytes(),
            6,
            &Select {
                delimiter: b',',
                nf: 3,
                inputs: &[1],
                outputs: &[2],
                time: Some(0),
                time_scale: 1.0,
            },
        )
        .expect("fast path");
        assert_eq!(r.lines.first(), Some(&4));
        assert_eq!(r.lines.len(), 20);
        assert_eq!(r.t[19], 19.0 * 1e-3);
        assert_eq!(r.t_text[19].text(text.as_bytes()), "0.019");
        // A quote anywhere in a row leaves the fast path.
        let quoted = format!("t,u,y\n0,\"1\",2\n{}", rows(3, "\n"));
        assert!(fast_rows(
            quoted.as_bytes(),
            6,
            &Select {
                delimiter: b',',
                nf: 3,
                inputs: &[1],
                outputs: &[2],
                time: Some(0),
                time_scale: 1.0,
            },
        )
        .is_none());
    }
}
