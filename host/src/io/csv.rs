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
    read_csv_impl(path, opts, RowReader::default())
}

/// Files with fewer data bytes than this are parsed on one thread (a thread costs more than
/// it saves below it).
const PARALLEL_MIN_BYTES: usize = 256 * 1024;

/// How the data rows are read: the fast row parser ([`fast_rows`]) allowed or not, and into
/// how many pieces it splits the rows (tests compare every way).
#[derive(Debug, Clone, Copy)]
struct RowReader {
    fast: bool,
    /// Most pieces parsed concurrently (1: one thread).
    pieces: usize,
    /// Fewest data bytes per piece.
    piece_min_bytes: usize,
}

impl Default for RowReader {
    fn default() -> Self {
        RowReader {
            fast: true,
            pieces: std::thread::available_parallelism().map_or(1, |n| n.get().min(8)),
            piece_min_bytes: PARALLEL_MIN_BYTES,
        }
    }
}

/// [`read_csv`], with the rows read as `how` says (the same log or the same error every way).
fn read_csv_impl(path: &Path, opts: &CsvOptions, how: RowReader) -> Result<Log> {
    check_options(opts)?;
    let bytes = crate::io::input::read_bytes(path, crate::io::input::MAX_LOG_BYTES)?;
    crate::io::input::check_utf8_family(path, &bytes)?;
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
    let header = read_header(&mut rdr, &mut rec, &bytes, path)?;
    let cols = select_columns(&header, opts, path)?;
    // Rows: the fast path for plain ASCII rows without quotes; anything else, and every error,
    // goes through the csv crate (which then produces the error).
    let sel = Select {
        delimiter,
        nf: header.names.len(),
        inputs: &cols.inputs,
        outputs: &cols.outputs,
        time: cols.time,
        time_scale: opts.time_scale,
    };
    let body = rdr.position().byte() as usize;
    let fast = if how.fast {
        fast_rows_split(&bytes, body, &sel, how)
    } else {
        None
    };
    let rows = match fast {
        Some(rows) => rows,
        None => csv_rows(&mut rdr, &mut rec, &bytes, &header, &sel, path)?,
    };
    finish_csv(path, opts, &bytes, &header, &cols, &sel, rows)
}

fn parse_err(file: &Path, line: usize, msg: String) -> Error {
    Error::Parse {
        file: file.to_path_buf(),
        line,
        msg,
    }
}

fn data_err(file: &Path, msg: String) -> Error {
    Error::Data {
        file: file.to_path_buf(),
        msg,
    }
}

/// The options that do not depend on the file.
fn check_options(opts: &CsvOptions) -> Result<()> {
    opts.checks.validate()?;
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
    Ok(())
}

/// The next record from the csv crate (`false` at the end), errors naming the line.
fn next_record(
    rdr: &mut ::csv::Reader<&[u8]>,
    rec: &mut ::csv::StringRecord,
    file: &Path,
) -> Result<bool> {
    rdr.read_record(rec).map_err(|e| {
        let line = e.position().map_or(0, |p| p.line() as usize);
        match e.kind() {
            ::csv::ErrorKind::Utf8 { .. } => parse_err(file, line, "invalid UTF-8".into()),
            _ => parse_err(file, line, format!("malformed CSV: {e}")),
        }
    })
}

/// The line a record is on. The csv crate reports a record's position as the start of any
/// blank/comment lines skipped before it; walk past those to name the line the record is
/// really on.
fn record_line(bytes: &[u8], rec: &::csv::StringRecord) -> usize {
    rec.position().map_or(0, |p| {
        true_line(bytes, p.byte() as usize, p.line() as usize)
    })
}

/// The header: column names and the line they are on.
struct Header {
    names: Vec<String>,
    line: usize,
}

/// Reads the first record that is not blank: the header.
fn read_header(
    rdr: &mut ::csv::Reader<&[u8]>,
    rec: &mut ::csv::StringRecord,
    bytes: &[u8],
    file: &Path,
) -> Result<Header> {
    loop {
        if !next_record(rdr, rec, file)? {
            return Err(data_err(file, "empty file: no header line".into()));
        }
        if !(rec.len() == 1 && rec[0].is_empty()) {
            break;
        }
    }
    Ok(Header {
        names: rec.iter().map(|s| s.to_string()).collect(),
        line: record_line(bytes, rec),
    })
}

/// Field indices of the selected columns.
struct Columns {
    inputs: Vec<usize>,
    outputs: Vec<usize>,
    time: Option<usize>,
}

/// Finds the selected columns in the header (each exactly once).
fn select_columns(header: &Header, opts: &CsvOptions, file: &Path) -> Result<Columns> {
    let names = &header.names;
    let find = |name: &str| -> Result<usize> {
        let hits: Vec<usize> = names
            .iter()
            .enumerate()
            .filter(|(_, h)| h.as_str() == name)
            .map(|(i, _)| i)
            .collect();
        match hits.as_slice() {
            [i] => Ok(*i),
            [] => Err(parse_err(
                file,
                header.line,
                format!(
                    "column `{}` not found in the header; columns are: {}",
                    crate::error::excerpt(name),
                    crate::error::excerpt_n(&names.join(", "), 400)
                ),
            )),
            _ => Err(parse_err(
                file,
                header.line,
                format!(
                    "column `{}` appears {} times in the header",
                    crate::error::excerpt(name),
                    hits.len()
                ),
            )),
        }
    };
    let inputs: Vec<usize> = opts.inputs.iter().map(|n| find(n)).collect::<Result<_>>()?;
    let outputs: Vec<usize> = opts
        .outputs
        .iter()
        .map(|n| find(n))
        .collect::<Result<_>>()?;
    let time: Option<usize> = match &opts.time {
        Some(name) => Some(find(name)?),
        None => names.iter().position(|h| h == "t"),
    };
    if time.is_none() && opts.fs.is_none() {
        return Err(parse_err(
            file,
            header.line,
            "no time column (`t` by default) and no sample rate given: add a time column or \
             give fs"
                .into(),
        ));
    }
    Ok(Columns {
        inputs,
        outputs,
        time,
    })
}

/// The data rows read by the csv crate (any CSV; every error with its line and column).
fn csv_rows(
    rdr: &mut ::csv::Reader<&[u8]>,
    rec: &mut ::csv::StringRecord,
    bytes: &[u8],
    header: &Header,
    sel: &Select<'_>,
    file: &Path,
) -> Result<Rows> {
    let nf = sel.nf;
    let mut r = Rows::new(sel.inputs.len(), sel.outputs.len());
    let mut t_text = Vec::new();
    let field = |rec: &::csv::StringRecord, i: usize, line: usize| -> Result<f64> {
        let s = rec.get(i).unwrap_or("");
        let v: f64 = s.parse().map_err(|_| {
            parse_err(
                file,
                line,
                format!(
                    "column `{}`: `{}` is not a number",
                    crate::error::excerpt(&header.names[i]),
                    crate::error::excerpt(s)
                ),
            )
        })?;
        if !v.is_finite() {
            return Err(parse_err(
                file,
                line,
                format!(
                    "column `{}`: value `{}` is not finite",
                    crate::error::excerpt(&header.names[i]),
                    crate::error::excerpt(s)
                ),
            ));
        }
        Ok(v)
    };
    while next_record(rdr, rec, file)? {
        let line = record_line(bytes, rec);
        if rec.len() == 1 && rec[0].is_empty() {
            continue; // a line of whitespace only
        }
        if rec.len() != nf {
            return Err(parse_err(
                file,
                line,
                format!("expected {nf} fields as in the header, found {}", rec.len()),
            ));
        }
        for (col, &i) in r.ins.iter_mut().zip(sel.inputs) {
            col.push(field(rec, i, line)?);
        }
        for (col, &i) in r.outs.iter_mut().zip(sel.outputs) {
            col.push(field(rec, i, line)?);
        }
        if let Some(i) = sel.time {
            r.t.push(field(rec, i, line)? * sel.time_scale);
            t_text.push(rec.get(i).unwrap_or("").to_string());
        }
        r.lines.push(line);
    }
    r.t_text = TimeTexts::Owned(t_text);
    Ok(r)
}

/// From the rows to the log: at least one row, the sample time (from the stamps or the rate),
/// the shared checks of [`finish_log`].
fn finish_csv(
    path: &Path,
    opts: &CsvOptions,
    bytes: &[u8],
    header: &Header,
    cols: &Columns,
    sel: &Select<'_>,
    rows: Rows,
) -> Result<Log> {
    let Rows {
        ins,
        outs,
        t,
        t_text,
        lines,
    } = rows;
    if lines.is_empty() {
        return Err(data_err(
            path,
            format!("no data rows after the header (line {})", header.line),
        ));
    }
    let row_err = |k: usize, msg: String| parse_err(path, lines.line(k), msg);
    let file_err = |msg: String| data_err(path, msg);
    let (ts, time_warning) = match cols.time {
        Some(i) => {
            let what = format!("time column `{}`", header.names[i]);
            // How each time stamp was printed (for its rounding, see `super::printed`): only
            // looked at when the stamps are not uniform to the tolerance.
            let t_rounding = || {
                let printed: Vec<Option<super::printed::Printed>> = match &t_text {
                    TimeTexts::Owned(texts) => texts
                        .iter()
                        .map(|s| super::printed::Printed::parse(s))
                        .collect(),
                    // The fast path read these rows, so the same scan finds one span per row;
                    // the spans are ASCII.
                    TimeTexts::Rescan { body } => fast_time_spans(bytes, *body, sel)
                        .filter(|spans| spans.len() == t.len())
                        .map_or_else(
                            || vec![None; t.len()],
                            |spans| {
                                spans
                                    .iter()
                                    .map(|&(a, b)| {
                                        let text = bytes.get(a..b).unwrap_or_default();
                                        super::printed::Printed::parse(
                                            std::str::from_utf8(text).unwrap_or(""),
                                        )
                                    })
                                    .collect()
                            },
                        ),
                };
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
                &row_err,
                &file_err,
            )?
        }
        None => sample_time(
            TimeSource::Rate(opts.fs.unwrap_or(f64::NAN)),
            &opts.checks,
            &row_err,
            &file_err,
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

/// The text of the time stamps, for their printed rounding (only looked at when the stamps are
/// not uniform to the tolerance).
enum TimeTexts {
    /// Read by the fast path: the stamps are found again in the file's bytes by scanning the
    /// rows once more ([`fast_time_spans`]), so the common case stores no text per row.
    Rescan { body: usize },
    /// Read by the csv crate: a copy of each stamp.
    Owned(Vec<String>),
}

/// Row index → 1-based line number, as runs of rows on consecutive lines (one run for a file
/// without blank or comment lines among its rows).
#[derive(Debug, Default, Clone, PartialEq)]
struct Lines {
    rows: usize,
    /// (first row, its line) of each run, by row.
    runs: Vec<(usize, usize)>,
}

impl Lines {
    /// Row `self.rows` is on `line`.
    fn push(&mut self, line: usize) {
        self.push_run(self.rows, line);
        self.rows += 1;
    }

    /// A run starts at `row` on `line`, unless the last run already puts it there.
    fn push_run(&mut self, row: usize, line: usize) {
        match self.runs.last() {
            Some(&(r, l)) if row >= r && l + (row - r) == line => {}
            _ => self.runs.push((row, line)),
        }
    }

    /// The rows of `more` follow, their lines shifted by `line_offset`.
    fn append(&mut self, more: &Lines, line_offset: usize) {
        for &(r, l) in &more.runs {
            self.push_run(self.rows + r, l + line_offset);
        }
        self.rows += more.rows;
    }

    fn is_empty(&self) -> bool {
        self.rows == 0
    }

    /// The line of row `k` (`k` < the row count).
    fn line(&self, k: usize) -> usize {
        let i = self.runs.partition_point(|&(r, _)| r <= k);
        match i.checked_sub(1).and_then(|i| self.runs.get(i)) {
            Some(&(r, l)) => l + (k - r),
            None => 0,
        }
    }

    #[cfg(test)]
    fn to_vec(&self) -> Vec<usize> {
        (0..self.rows).map(|k| self.line(k)).collect()
    }
}

/// The data rows: selected columns, time stamps (s) with their text, and the 1-based line of
/// each row.
struct Rows {
    ins: Vec<Vec<f64>>,
    outs: Vec<Vec<f64>>,
    t: Vec<f64>,
    t_text: TimeTexts,
    lines: Lines,
}

impl Rows {
    fn new(inputs: usize, outputs: usize) -> Self {
        Rows {
            ins: vec![Vec::new(); inputs],
            outs: vec![Vec::new(); outputs],
            t: Vec::new(),
            t_text: TimeTexts::Owned(Vec::new()),
            lines: Lines::default(),
        }
    }
}

/// The number of rows `bytes` can hold at most: its lines.
fn max_rows(bytes: &[u8]) -> usize {
    count_newlines(bytes) + usize::from(bytes.last() != Some(&b'\n'))
}

/// The number of `\n` in `bytes`, counted in blocks of 128 bytes with 8-bit sums (a block's
/// count fits in a `u8`), which the compiler turns into byte-wise vector compares: about 0.1
/// instruction per byte instead of 5 for a filtered count.
fn count_newlines(bytes: &[u8]) -> usize {
    let mut blocks = bytes.chunks_exact(128);
    let mut n = 0;
    for block in &mut blocks {
        n += usize::from(
            block
                .iter()
                .fold(0u8, |acc, &b| acc.wrapping_add(u8::from(b == b'\n'))),
        );
    }
    n + blocks.remainder().iter().filter(|&&b| b == b'\n').count()
}

/// `col` cut into consecutive slices of `lens` elements (short ones if it runs out).
fn cut_slices<'a>(mut col: &'a mut [f64], lens: &[usize]) -> Vec<&'a mut [f64]> {
    lens.iter()
        .map(|&n| {
            let n = n.min(col.len());
            let (a, rest) = std::mem::take(&mut col).split_at_mut(n);
            col = rest;
            a
        })
        .collect()
}

/// The selected columns of one piece of the body, written in place into the log's columns.
struct PieceOut<'a> {
    ins: Vec<&'a mut [f64]>,
    outs: Vec<&'a mut [f64]>,
    t: &'a mut [f64],
}

/// [`fast_rows`] over the whole body (from byte `body`, just after the header record), split
/// at line boundaries into up to `how.pieces` pieces of at least `how.piece_min_bytes` bytes
/// that are parsed concurrently. Each piece writes its rows straight into its own part of the
/// columns (sized by the lines of the piece, so each value is written once and never copied),
/// parsed exactly as one pass would parse it (rows are independent), so the rows are the same
/// to the bit; `None` when any piece leaves the fast path's subset.
fn fast_rows_split(bytes: &[u8], body: usize, sel: &Select<'_>, how: RowReader) -> Option<Rows> {
    if body == 0 || body > bytes.len() {
        return None;
    }
    let first_line = 1 + count_newlines(&bytes[..body]);
    let cuts = piece_cuts(bytes, body, how);
    let caps: Vec<usize> = cuts
        .windows(2)
        .map(|w| max_rows(&bytes[w[0]..w[1]]))
        .collect();
    let total: usize = caps.iter().sum();
    // Zeroed allocations: the pages a piece does not fill are never touched.
    let column = |_| vec![0.0; total];
    let mut ins: Vec<Vec<f64>> = sel.inputs.iter().map(column).collect();
    let mut outs: Vec<Vec<f64>> = sel.outputs.iter().map(column).collect();
    let mut t: Vec<f64> = match sel.time {
        Some(_) => vec![0.0; total],
        None => Vec::new(),
    };
    let parsed: Vec<Option<(usize, Lines, usize)>> = {
        let mut ins_cut: Vec<_> = ins
            .iter_mut()
            .map(|c| cut_slices(c, &caps).into_iter())
            .collect();
        let mut outs_cut: Vec<_> = outs
            .iter_mut()
            .map(|c| cut_slices(c, &caps).into_iter())
            .collect();
        let mut t_cut = cut_slices(&mut t, &caps).into_iter();
        let mut pieces: Vec<PieceOut<'_>> = caps
            .iter()
            .map(|_| PieceOut {
                ins: ins_cut
                    .iter_mut()
                    .map(|c| c.next().unwrap_or_default())
                    .collect(),
                outs: outs_cut
                    .iter_mut()
                    .map(|c| c.next().unwrap_or_default())
                    .collect(),
                t: t_cut.next().unwrap_or_default(),
            })
            .collect();
        if pieces.len() == 1 {
            let out = pieces.pop()?;
            vec![fast_rows(bytes, body, bytes.len(), first_line, sel, out)]
        } else {
            // Pieces after the first count their lines from 0; shifted once the earlier ones
            // are known.
            let mut pieces = pieces.into_iter();
            let first = pieces.next()?;
            std::thread::scope(|scope| {
                let handles: Vec<_> = cuts[1..]
                    .windows(2)
                    .zip(pieces)
                    .map(|(w, out)| scope.spawn(move || fast_rows(bytes, w[0], w[1], 0, sel, out)))
                    .collect();
                let first = fast_rows(bytes, cuts[0], cuts[1], first_line, sel, first);
                std::iter::once(first)
                    .chain(handles.into_iter().map(|h| {
                        h.join()
                            .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
                    }))
                    .collect()
            })
        }
    };
    // Join the pieces: rows moved down over the lines a piece skipped (none in a file without
    // blank or comment lines), line numbers shifted (the first piece's are the file's already).
    let mut lines = Lines::default();
    let mut next_line = first_line;
    let (mut at, mut from) = (0, 0);
    for (k, (piece, cap)) in parsed.into_iter().zip(&caps).enumerate() {
        let (n, piece_lines, read) = piece?;
        if from != at {
            for c in ins.iter_mut().chain(outs.iter_mut()).chain([&mut t]) {
                if !c.is_empty() {
                    c.copy_within(from..from + n, at);
                }
            }
        }
        lines.append(&piece_lines, if k == 0 { 0 } else { next_line });
        next_line += read;
        at += n;
        from += cap;
    }
    for c in ins.iter_mut().chain(outs.iter_mut()).chain([&mut t]) {
        c.truncate(at);
        c.shrink_to_fit();
    }
    Some(Rows {
        ins,
        outs,
        t,
        t_text: TimeTexts::Rescan { body },
        lines,
    })
}

/// Where the body `bytes[body..]` is cut into pieces for [`fast_rows_split`]: byte offsets
/// from `body` to `bytes.len()`, each inner cut just after a `\n`, increasing.
fn piece_cuts(bytes: &[u8], body: usize, how: RowReader) -> Vec<usize> {
    let len = bytes.len() - body;
    let pieces = how
        .pieces
        .min(len / how.piece_min_bytes.max(1))
        .clamp(1, len.max(1));
    let mut cuts = vec![body];
    for k in 1..pieces {
        let guess = body + len * k / pieces;
        let last = cuts[cuts.len() - 1];
        if guess < last {
            continue;
        }
        match bytes[guess..].iter().position(|&b| b == b'\n') {
            Some(i) if guess + i + 1 < bytes.len() && guess + i + 1 > last => {
                cuts.push(guess + i + 1)
            }
            Some(_) => {}
            None => break,
        }
    }
    cuts.push(bytes.len());
    cuts
}

/// Parses the data rows in `bytes[start..end]` into `out` (room for [`max_rows`] rows): see
/// [`scan_rows`]. Returns the number of rows, their lines (counted from `line`) and the number
/// of lines read, or `None` where [`scan_rows`] gives up.
fn fast_rows(
    bytes: &[u8],
    start: usize,
    end: usize,
    line: usize,
    sel: &Select<'_>,
    mut out: PieceOut<'_>,
) -> Option<(usize, Lines, usize)> {
    let mut n = 0;
    let mut lines = Lines::default();
    let read = scan_rows(bytes, start, end, line, sel, |scan, line| {
        for (col, &i) in out.ins.iter_mut().zip(sel.inputs) {
            match col.get_mut(n) {
                Some(v) => *v = scan.values[i],
                None => return false,
            }
        }
        for (col, &i) in out.outs.iter_mut().zip(sel.outputs) {
            match col.get_mut(n) {
                Some(v) => *v = scan.values[i],
                None => return false,
            }
        }
        if let Some(i) = sel.time {
            match out.t.get_mut(n) {
                Some(v) => *v = scan.values[i] * sel.time_scale,
                None => return false,
            }
        }
        lines.push(line);
        n += 1;
        true
    })?;
    Some((n, lines, read))
}

/// The byte spans of the time stamps of the data rows after `body`, found by the same scan as
/// [`fast_rows`] (so for a body the fast path read, one span per row, in order).
fn fast_time_spans(bytes: &[u8], body: usize, sel: &Select<'_>) -> Option<Vec<(usize, usize)>> {
    let i = sel.time?;
    let mut spans = Vec::new();
    scan_rows(bytes, body, bytes.len(), 1, sel, |scan, _| {
        spans.push(scan.spans[i]);
        true
    })?;
    Some(spans)
}

/// Parses the data rows in `bytes[start..end]` (`start` just after the header record or
/// after a `\n`, `end` after a `\n` or the end of the file) without the csv crate's record
/// machinery, for the common case: every line plain ASCII without a quote character, ended by
/// `\n` or `\r\n`; `#` comment lines and blank lines skipped as the csv crate skips them.
/// `line` is the line number of the first line. Calls `row` with the scan of each row (its
/// values and spans) and the row's line; returns the number of lines read, or `None` as soon
/// as the text leaves that subset, a row would be an error (field count, a value that is not a
/// finite number) or `row` returns `false`: the caller then reads the rows with the csv crate,
/// which yields the same values and reports the error with its line.
fn scan_rows(
    bytes: &[u8],
    start: usize,
    end: usize,
    mut line: usize,
    sel: &Select<'_>,
    mut row: impl FnMut(&RowScan, usize) -> bool,
) -> Option<usize> {
    let first_line = line;
    let bytes = &bytes[..end];
    // The header record must end at a line boundary (the byte before `start` is `\n`, or
    // `start` sits on the `\n` of a `\r\n` whose `\r` ended the header).
    // Delimiters the line splitting below would confuse with what it refuses or skips.
    // Delimiters that can be part of a number's text (the parse would run across them) are
    // left to the csv crate too.
    if start > bytes.len()
        || start == 0
        || matches!(
            sel.delimiter,
            b'"' | b'#' | b'\r' | b'\n' | b'.' | b'+' | b'-'
        )
        || sel.delimiter.is_ascii_alphanumeric()
        || sel.delimiter >= 0x80
    {
        return None;
    }
    let boundary =
        bytes[start - 1] == b'\n' || bytes.get(start) == Some(&b'\n') || start == bytes.len();
    if !boundary {
        return None;
    }
    let mut scan = RowScan::new(sel);
    let len = bytes.len();
    let mut pos = start;
    while pos < len {
        let this_line = line;
        if bytes[pos] == b'#' {
            // A comment line (whatever it holds, up to the next `\n`, as the csv crate skips it).
            pos = bytes[pos..]
                .iter()
                .position(|&b| b == b'\n')
                .map_or(len, |k| pos + k + 1);
            line += 1;
            continue;
        }
        // A line of whitespace only (one empty field after trimming) is skipped.
        let mut q = pos;
        while q < len && scan.space(bytes[q]) {
            q += 1;
        }
        if q < len && bytes[q] == b'\r' && bytes.get(q + 1) == Some(&b'\n') {
            q += 1;
        }
        if q == len || bytes[q] == b'\n' {
            pos = q + 1;
            line += 1;
            continue;
        }
        pos = scan.fields(bytes, pos)? + 1;
        line += 1;
        if !row(&scan, this_line) {
            return None;
        }
    }
    Some(line - first_line)
}

/// The field scan of one row for [`fast_rows`]: which fields are parsed, the byte classes for
/// The field scan of one row for [`fast_rows`]: which fields are parsed, the byte classes for
/// the skipped ones, and the parsed values and spans of the current row.
struct RowScan {
    delim: u8,
    /// Byte classes of the scan of skipped fields.
    class: [u8; 256],
    /// Field i is selected (parsed as a number).
    parse_field: Vec<bool>,
    values: Vec<f64>,
    spans: Vec<(usize, usize)>,
}

const PLAIN: u8 = 0;
const NEWLINE: u8 = 1;
const DELIMITER: u8 = 2;
const CR: u8 = 3;
const REFUSED: u8 = 4;

impl RowScan {
    fn new(sel: &Select<'_>) -> Self {
        let mut class = [PLAIN; 256];
        class[0x80..].fill(REFUSED);
        class[b'"' as usize] = REFUSED;
        class[b'\n' as usize] = NEWLINE;
        class[b'\r' as usize] = CR;
        class[sel.delimiter as usize] = DELIMITER;
        let mut parse_field = vec![false; sel.nf];
        for &i in sel.inputs.iter().chain(sel.outputs).chain(&sel.time) {
            parse_field[i] = true;
        }
        RowScan {
            delim: sel.delimiter,
            class,
            parse_field,
            values: vec![0.0; sel.nf],
            spans: vec![(0, 0); sel.nf],
        }
    }

    /// Whitespace trimmed around a field, other than the delimiter (a `\r` only before `\n`).
    #[inline]
    fn space(&self, b: u8) -> bool {
        b != self.delim && matches!(b, b' ' | b'\t' | 0x0b | 0x0c)
    }

    /// Reads the fields of the row at `pos` (not blank, not a comment) into `values`/`spans`
    /// and returns the position of its `\n` (or the end): a selected field is parsed where it
    /// starts (after leading whitespace) and must be followed by whitespace only, then the
    /// delimiter or the end of the line; a skipped one is scanned to the delimiter, refusing
    /// what the csv crate treats specially (quotes, lone carriage returns) and non-ASCII
    /// bytes. `None` for anything else, or a field count other than the header's.
    #[inline]
    fn fields(&mut self, bytes: &[u8], mut pos: usize) -> Option<usize> {
        let len = bytes.len();
        let nf = self.parse_field.len();
        let mut f = 0;
        loop {
            if self.parse_field[f] {
                let mut a = pos;
                while a < len && self.space(bytes[a]) {
                    a += 1;
                }
                let (v, used) = parse_f64_prefix(&bytes[a..])?;
                if !v.is_finite() {
                    return None;
                }
                self.values[f] = v;
                self.spans[f] = (a, a + used);
                pos = a + used;
                while pos < len && self.space(bytes[pos]) {
                    pos += 1;
                }
                if pos < len && bytes[pos] == b'\r' && bytes.get(pos + 1) == Some(&b'\n') {
                    pos += 1;
                }
            } else {
                while pos < len {
                    match self.class[bytes[pos] as usize] {
                        PLAIN => {}
                        NEWLINE | DELIMITER => break,
                        CR if bytes.get(pos + 1) == Some(&b'\n') => {}
                        _ => return None,
                    }
                    pos += 1;
                }
            }
            if pos < len && bytes[pos] == self.delim {
                f += 1;
                if f == nf {
                    return None; // more fields than the header
                }
                pos += 1;
            } else if pos == len || bytes[pos] == b'\n' {
                break;
            } else {
                return None; // text after a number, a quote, a lone `\r`, ...
            }
        }
        (f + 1 == nf).then_some(pos)
    }
}

/// The number at the start of `s` and the length of its text: the longest prefix that
/// fast-float2 reads, without the `&str` round trip (only ASCII reaches it). fast-float2
/// implements the same correctly rounded algorithm (Eisel–Lemire with a big-decimal fallback)
/// as the standard library; where the prefix is a whole field, it is the field's value as
/// `str::parse::<f64>` reads it (tests compare both on edge cases, random strings and 100k
/// numbers in the peer log's format).
fn parse_f64_prefix(s: &[u8]) -> Option<(f64, usize)> {
    fast_float2::parse_partial::<f64, _>(s).ok()
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

    /// The whole text `s` as fast-float2 reads it.
    fn parse_f64(s: &[u8]) -> Option<f64> {
        fast_float2::parse::<f64, _>(s).ok()
    }

    /// The ways the tests read a file: the csv crate only, the fast row parser on one thread,
    /// and the fast row parser split into up to 3 or 7 concurrent pieces of any size.
    const WAYS: [(&str, RowReader); 4] = [
        (
            "csv crate",
            RowReader {
                fast: false,
                pieces: 1,
                piece_min_bytes: 1,
            },
        ),
        (
            "fast, one piece",
            RowReader {
                fast: true,
                pieces: 1,
                piece_min_bytes: 1,
            },
        ),
        (
            "fast, 3 pieces",
            RowReader {
                fast: true,
                pieces: 3,
                piece_min_bytes: 1,
            },
        ),
        (
            "fast, 7 pieces",
            RowReader {
                fast: true,
                pieces: 7,
                piece_min_bytes: 1,
            },
        ),
    ];

    /// Reads `content` every way of [`WAYS`].
    fn every_way(name: &str, content: &[u8], opts: &CsvOptions) -> Vec<Result<Log>> {
        let dir = std::env::temp_dir().join(format!("ferrosid-csv-fast-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let p = dir.join(name);
        std::fs::write(&p, content).expect("write");
        let out = WAYS
            .iter()
            .map(|(_, how)| read_csv_impl(&p, opts, *how))
            .collect();
        let _ = std::fs::remove_file(&p);
        out
    }

    /// The same log (every sample bit for bit, ts, warnings) or the same error message, every
    /// way of reading.
    fn assert_same(name: &str, content: &[u8], opts: &CsvOptions) {
        let all = every_way(name, content, opts);
        let reference = &all[0];
        for ((way, _), got) in WAYS.iter().zip(&all).skip(1) {
            match (got, reference) {
                (Ok(a), Ok(b)) => {
                    assert_eq!(a.ts.to_bits(), b.ts.to_bits(), "{name}, {way}: ts");
                    assert_eq!(a.warnings, b.warnings, "{name}, {way}: warnings");
                    for (ca, cb) in a
                        .inputs
                        .iter()
                        .chain(&a.outputs)
                        .zip(b.inputs.iter().chain(&b.outputs))
                    {
                        assert_eq!(ca.name, cb.name, "{name}, {way}");
                        let bits =
                            |c: &Channel| c.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                        assert_eq!(bits(ca), bits(cb), "{name}, {way}: channel {}", ca.name);
                    }
                    assert_eq!(a, b, "{name}, {way}");
                }
                (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string(), "{name}, {way}"),
                (a, b) => panic!("{name}: {way} {a:?}, csv crate {b:?}"),
            }
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
        for (name, content, opts) in &agreement_cases() {
            assert_same(name, content, opts);
        }
    }

    /// The files of [`fast_rows_agree_with_the_csv_crate`]: name, content, options.
    fn agreement_cases() -> Vec<(&'static str, Vec<u8>, CsvOptions)> {
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
        cases.extend(row_error_cases());
        cases.extend(delimiter_cases());
        cases
    }

    /// One odd row among plain ones: errors, and rows the fast path must refuse.
    fn row_error_cases() -> Vec<(&'static str, Vec<u8>, CsvOptions)> {
        let d = CsvOptions::default();
        let mut cases = Vec::new();
        for (name, row) in [
            ("number then text", "0.3,1.5x,2\n"),
            ("space inside a number", "0.3,1 5,2\n"),
            ("lone CR after a number", "0.3,1\r,2\n"),
            (
                "vertical tab and form feed around a number",
                "0.3,\x0b1\x0c,2\n",
            ),
            ("empty selected field", "0.3,,2\n"),
            ("too many fields", "0.3,1,2,4\n"),
            ("too few fields", "0.3,1\n"),
            ("exponents and signs", "0.3,+1e-0,-2.5E+1\n"),
            ("nan", "0.3,nan,2\n"),
            ("infinity", "0.3,1,-infinity\n"),
            ("hex", "0.3,0x1,2\n"),
        ] {
            cases.push((
                name,
                format!("t,u,y\n{}{row}{}", rows(150, "\n"), rows(3, "\n")).into_bytes(),
                d.clone(),
            ));
        }
        cases
    }

    /// Other columns, delimiters and selections.
    fn delimiter_cases() -> Vec<(&'static str, Vec<u8>, CsvOptions)> {
        let d = CsvOptions::default();
        let mut cases = Vec::new();
        cases.push((
            "unselected text column",
            format!(
                "t,note,u,y\n{}",
                rows(200, "\n")
                    .lines()
                    .map(|l| l.replacen(',', ",a b; c d,", 1) + "\n")
                    .collect::<String>()
            )
            .into_bytes(),
            d.clone(),
        ));
        cases.push((
            "blank line of delimiters (tab)",
            format!(
                "t\tu\ty\n{}\t\t\n{}",
                rows(100, "\n").replace(',', "\t"),
                rows(3, "\n").replace(',', "\t")
            )
            .into_bytes(),
            d.clone(),
        ));
        cases.push((
            "space delimiter",
            format!("t u y\n{}", rows(100, "\n").replace(',', " ")).into_bytes(),
            CsvOptions {
                delimiter: Some(b' '),
                ..d.clone()
            },
        ));
        cases.push((
            "delimiter that is part of numbers",
            format!("tEuEy\n{}", rows(100, "\n").replace(',', "E")).into_bytes(),
            CsvOptions {
                delimiter: Some(b'E'),
                ..d.clone()
            },
        ));
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
        cases
    }

    /// The plain format is read by the fast path (not only by the fallback), split into
    /// pieces with the right line numbers.
    #[test]
    fn plain_rows_take_the_fast_path() {
        let text = format!("t,u,y\n# c\n\n{}", rows(20, "\r\n"));
        let sel = Select {
            delimiter: b',',
            nf: 3,
            inputs: &[1],
            outputs: &[2],
            time: Some(0),
            time_scale: 1.0,
        };
        let (_, one) = WAYS[1];
        let (_, three) = WAYS[2];
        assert_eq!(piece_cuts(text.as_bytes(), 6, three).len(), 4, "3 pieces");
        for how in [one, three] {
            let r = fast_rows_split(text.as_bytes(), 6, &sel, how).expect("fast path");
            assert_eq!(r.lines.to_vec(), (4..24).collect::<Vec<_>>());
            assert_eq!(r.t[19], 19.0 * 1e-3);
            let spans = fast_time_spans(text.as_bytes(), 6, &sel).expect("spans");
            assert_eq!(spans.len(), 20);
            assert_eq!(&text[spans[19].0..spans[19].1], "0.019");
        }
        // Whitespace around fields, other delimiters, a skipped text column: still fast.
        let plain = rows(20, "\n");
        for (text, delimiter, nf, inputs, outputs) in [
            (
                format!("t,u,y\n{}", plain.replace(',', " ,\t ")),
                b',',
                3,
                &[1usize][..],
                &[2usize][..],
            ),
            (
                format!("t;u;y\n{}", plain.replace(',', ";")),
                b';',
                3,
                &[1],
                &[2],
            ),
            (
                format!("t\tu\ty\n{}", plain.replace(',', "\t")),
                b'\t',
                3,
                &[1],
                &[2],
            ),
            (
                format!(
                    "t,n,u,y\n{}",
                    plain
                        .lines()
                        .map(|l| l.replacen(',', ",x y? z ,", 1) + "\n")
                        .collect::<String>()
                ),
                b',',
                4,
                &[2],
                &[3],
            ),
        ] {
            let sel = Select {
                delimiter,
                nf,
                inputs,
                outputs,
                time: Some(0),
                time_scale: 1.0,
            };
            let start = text.find('\n').expect("header") + 1;
            for how in [one, three] {
                let r = fast_rows_split(text.as_bytes(), start, &sel, how);
                let r = r.unwrap_or_else(|| panic!("fast path refused {text:?}"));
                assert_eq!(r.lines.to_vec(), (2..22).collect::<Vec<_>>());
                let spans = fast_time_spans(text.as_bytes(), start, &sel).expect("spans");
                assert_eq!(&text[spans[19].0..spans[19].1], "0.019");
            }
        }
        // A quote anywhere in a row leaves the fast path, in any piece.
        for at in [0, 10, 19] {
            let mut quoted: Vec<String> = rows(20, "\n").lines().map(String::from).collect();
            quoted[at] = "0,\"1\",2".into();
            let quoted = format!("t,u,y\n{}\n", quoted.join("\n"));
            for how in [one, three] {
                assert!(fast_rows_split(quoted.as_bytes(), 6, &sel, how).is_none());
            }
        }
    }

    /// The blocked newline count equals a plain count at every length and alignment around
    /// the block size.
    #[test]
    fn count_newlines_equals_plain_count() {
        let text: Vec<u8> = (0..1000u32)
            .map(|k| {
                if k % 7 == 0 || k % 11 == 3 {
                    b'\n'
                } else {
                    b'0' + (k % 10) as u8
                }
            })
            .collect();
        for start in [0, 1, 5, 127] {
            for end in (start..text.len()).step_by(13).chain([text.len()]) {
                let s = &text[start..end];
                assert_eq!(
                    count_newlines(s),
                    s.iter().filter(|&&b| b == b'\n').count(),
                    "{start}..{end}"
                );
            }
        }
        assert_eq!(count_newlines(&[b'\n'; 1000]), 1000);
    }

    /// Lines kept as runs give back every row's line, appended pieces shifted.
    #[test]
    fn lines_as_runs() {
        let want = [3usize, 4, 5, 7, 8, 12, 13, 14, 15];
        let mut lines = Lines::default();
        for &l in &want {
            lines.push(l);
        }
        assert_eq!(lines.to_vec(), want);
        assert_eq!(lines.runs.len(), 3);
        let mut more = Lines::default();
        for l in [0, 1, 3] {
            more.push(l);
        }
        lines.append(&more, 16);
        assert_eq!(lines.to_vec(), [&want[..], &[16, 17, 19]].concat());
        assert_eq!(lines.runs.len(), 4, "16 continues the run of 12..=15");
        assert!(Lines::default().is_empty());
    }

    /// Cuts fall just after a `\n`, increase, and cover the body; a body without a newline
    /// is one piece.
    #[test]
    fn piece_cuts_are_line_starts() {
        let text = format!("t,u,y\n{}", rows(1000, "\n"));
        let bytes = text.as_bytes();
        for pieces in 1..10 {
            let how = RowReader {
                fast: true,
                pieces,
                piece_min_bytes: 100,
            };
            let cuts = piece_cuts(bytes, 6, how);
            assert_eq!((cuts[0], cuts[cuts.len() - 1]), (6, bytes.len()));
            assert_eq!(cuts.len(), pieces + 1, "{pieces} pieces");
            for w in cuts.windows(2) {
                assert!(w[0] < w[1]);
            }
            for &c in &cuts[1..cuts.len() - 1] {
                assert_eq!(bytes[c - 1], b'\n');
            }
        }
        let how = RowReader {
            fast: true,
            pieces: 4,
            piece_min_bytes: 1,
        };
        assert_eq!(piece_cuts(b"t,u\n1,2,3,4,5,6,7,8", 4, how), vec![4, 19]);
        // Pieces of at least `piece_min_bytes`: a small body is not split.
        let big = RowReader {
            fast: true,
            pieces: 4,
            piece_min_bytes: 1 << 20,
        };
        assert_eq!(piece_cuts(bytes, 6, big).len(), 2);
    }

    /// fast-float2 reads every string as `str::parse::<f64>` does (the same bits, or both
    /// refuse it): edge cases of the syntax, rounding boundaries, and random strings.
    #[test]
    fn fast_float_parses_as_std() {
        let mut cases: Vec<String> = [
            "0",
            "-0",
            "+0",
            "1",
            "-1",
            "+1",
            ".5",
            "5.",
            "-.5",
            "+.5",
            ".",
            "-",
            "+",
            "",
            "e5",
            "1e",
            "1e+",
            "1e-",
            "1E5",
            "1e+5",
            "1e-5",
            "1.e5",
            ".1e5",
            "1e5.",
            "1.5e",
            "--1",
            "+-1",
            "1..2",
            "1.2.3",
            "0x10",
            "1_000",
            " 1",
            "1 ",
            "1,5",
            "inf",
            "-inf",
            "+inf",
            "INF",
            "infinity",
            "Infinity",
            "-infinity",
            "infinit",
            "infinityx",
            "nan",
            "NaN",
            "-nan",
            "+nan",
            "nan(1)",
            "1e308",
            "1.7976931348623157e308",
            "1.7976931348623158e308",
            "1.7976931348623159e308",
            "2e308",
            "4.9e-324",
            "5e-324",
            "2.4703282292062327e-324",
            "2.4703282292062328e-324",
            "2.2250738585072011e-308",
            "2.2250738585072014e-308",
            "1e-400",
            "1e400",
            "0e999999999999",
            "1e-99999999999999999999",
            "9007199254740993",
            "9007199254740992.5",
            "9007199254740993.0000000000000000001",
            "0.1000000000000000055511151231257827021181583404541015625",
            "0.1000000000000000055511151231257827021181583404541015624",
            "0.1000000000000000055511151231257827021181583404541015626",
            "123456789012345678901234567890",
            "0.000000000000000000000000000001234567890123456789012",
            "00000000000000000000000000000000001",
            "1.00000000000000000000000000000000000000001",
            "7.038531e-26",
            "1.7e-7",
            "4.35679e-10",
            "1d5",
            "1f",
            "0.5\n",
            "1\0",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        // Halfway points between neighbouring doubles, printed with 40 digits, and just off.
        let mut rng = ferrosid_firmware::rng::SplitMix64::new(0x2545_f491_4f6c_dd1d);
        let mut next = || rng.next_u64();
        for _ in 0..2000 {
            let x = f64::from_bits(next() >> 2);
            if x.is_finite() && x > 0.0 {
                let up = f64::from_bits(x.to_bits() + 1);
                cases.push(format!("{:.40e}", (x + up) / 2.0));
                cases.push(format!("{x:e}"));
                cases.push(format!("{x:.17e}"));
                cases.push(format!("{x}"));
            }
            // Random strings over the float alphabet.
            let alphabet = b"0123456789.eE+-";
            let n = (next() % 12) as usize;
            let r: String = (0..n)
                .map(|_| alphabet[(next() % alphabet.len() as u64) as usize] as char)
                .collect();
            cases.push(r);
            cases.push(format!("{}", (next() % 2_000_001) as f64 / 1000.0 - 1000.0));
        }
        // The peer log's format (`%.17g`, 17 significant digits): 100k values of every
        // magnitude of a noisy output, and times k·1e-3.
        for k in 0..100_000u64 {
            let x = (f64::from_bits(next() >> 12 | 0x3ff0_0000_0000_0000) - 1.5)
                * 10f64.powi((k % 9) as i32 - 6);
            cases.push(format!("{:.16e}", x));
            cases.push(format!("{}", k as f64 * 1e-3));
        }
        for c in &cases {
            let std: Option<f64> = c.parse().ok();
            let ff = parse_f64(c.as_bytes());
            assert_eq!(
                std.map(f64::to_bits),
                ff.map(f64::to_bits),
                "`{}`: std {std:?}, fast-float2 {ff:?}",
                c.escape_debug()
            );
            // As a field followed by the delimiter: the prefix read is the whole text exactly
            // when the text is a finite number, with the same bits.
            let finite = std.filter(|v| v.is_finite());
            let field = format!("{c},9");
            let prefix = parse_f64_prefix(field.as_bytes())
                .filter(|&(v, used)| used == c.len() && v.is_finite())
                .map(|(v, _)| v);
            assert_eq!(
                finite.map(f64::to_bits),
                prefix.map(f64::to_bits),
                "field `{}`: std {finite:?}, prefix {prefix:?}",
                c.escape_debug()
            );
        }
    }
}
