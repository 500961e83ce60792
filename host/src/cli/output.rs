//! Printing helpers shared by the `frf` and `identify` commands: aligned text tables, stable
//! number formatting, JSON on stdout, and progress indicators on stderr.
//!
//! Determinism: every number printed goes through Rust's `format!` with a fixed precision (text)
//! or serde_json's shortest round-trip representation (JSON), neither of which depends on the
//! locale or the clock, so the same inputs give byte-identical output. Nothing printed to stdout
//! contains a time stamp or a duration.
use crate::error::{Error, Result};
use crate::ops::frf::LogSummary;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::Serialize;
use std::io::{IsTerminal, Write};
use std::path::PathBuf;

/// Column alignment in a [`Table`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Align {
    /// Pad on the right.
    Left,
    /// Pad on the left (numbers).
    Right,
}

/// A plain-text table with a header row, columns padded to their widest cell and separated by
/// two spaces.
#[derive(Debug, Clone, Default)]
pub struct Table {
    headers: Vec<(String, Align)>,
    rows: Vec<Vec<String>>,
}

impl Table {
    /// A table with the given `(header, alignment)` columns.
    pub fn new(headers: &[(&str, Align)]) -> Self {
        Self {
            headers: headers.iter().map(|(h, a)| (h.to_string(), *a)).collect(),
            rows: Vec::new(),
        }
    }

    /// Appends a row; missing cells are empty, extra cells are dropped.
    pub fn row(&mut self, cells: Vec<String>) {
        let mut cells = cells;
        cells.resize(self.headers.len(), String::new());
        self.rows.push(cells);
    }

    /// Number of data rows.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// True when there is no data row.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// The table as text, every line (header included) indented by `indent` spaces and ended
    /// by `\n`; trailing spaces are trimmed.
    pub fn render(&self, indent: usize) -> String {
        let width = |j: usize| {
            self.rows
                .iter()
                .map(|r| r[j].chars().count())
                .chain(std::iter::once(self.headers[j].0.chars().count()))
                .max()
                .unwrap_or(0)
        };
        let widths: Vec<usize> = (0..self.headers.len()).map(width).collect();
        let mut out = String::new();
        let line = |cells: &mut dyn Iterator<Item = &str>| -> String {
            let mut s = " ".repeat(indent);
            for (j, c) in cells.enumerate() {
                if j > 0 {
                    s.push_str("  ");
                }
                let pad = widths[j].saturating_sub(c.chars().count());
                match self.headers[j].1 {
                    Align::Left => {
                        s.push_str(c);
                        s.push_str(&" ".repeat(pad));
                    }
                    Align::Right => {
                        s.push_str(&" ".repeat(pad));
                        s.push_str(c);
                    }
                }
            }
            let mut s = s.trim_end().to_string();
            s.push('\n');
            s
        };
        out.push_str(&line(&mut self.headers.iter().map(|h| h.0.as_str())));
        for r in &self.rows {
            out.push_str(&line(&mut r.iter().map(|c| c.as_str())));
        }
        out
    }
}

/// `x` with `decimals` digits after the point, or `-` when `x` is not finite. Negative zero is
/// printed as zero so that tiny sign flips never change the text.
pub fn fixed(x: f64, decimals: usize) -> String {
    if !x.is_finite() {
        return "-".into();
    }
    let s = format!("{x:.decimals$}");
    if s.starts_with('-') && s[1..].chars().all(|c| c == '0' || c == '.') {
        s[1..].to_string()
    } else {
        s
    }
}

/// `x` in scientific notation with `sig` significant digits (`1.234e-3`), or `-` when `x` is
/// not finite.
pub fn sci(x: f64, sig: usize) -> String {
    if !x.is_finite() {
        return "-".into();
    }
    format!("{:.*e}", sig.saturating_sub(1), x)
}

/// Compact general format: fixed with `decimals` digits when `1e-3 <= |x| < 1e6` (or x = 0),
/// otherwise scientific with `decimals + 1` significant digits.
pub fn general(x: f64, decimals: usize) -> String {
    let a = x.abs();
    if x == 0.0 || (1e-3..1e6).contains(&a) {
        fixed(x, decimals)
    } else {
        sci(x, decimals + 1)
    }
}

/// The text reports' line for one log read (`ferrosid frf`, `ferrosid identify`): path, samples,
/// rate and channels.
pub fn log_line(l: &LogSummary) -> String {
    format!(
        "log {}: {} samples at {} Hz, inputs [{}], outputs [{}]",
        l.path,
        l.samples,
        general(l.fs_hz, 3),
        l.inputs.join(", "),
        l.outputs.join(", ")
    )
}

/// Writes `text` to stdout. A closed pipe (e.g. `| head`) is not an error.
pub fn emit(text: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|_| out.flush()) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        Err(source) => Err(Error::Io {
            file: PathBuf::from("<stdout>"),
            source,
        }),
    }
}

/// `value` as pretty-printed JSON followed by a newline. Non-finite floats become `null`.
pub fn json_string<T: Serialize>(value: &T) -> Result<String> {
    let mut s = serde_json::to_string_pretty(value)
        .map_err(|e| Error::Numerical(format!("serialising JSON output: {e}")))?;
    s.push('\n');
    Ok(s)
}

/// Writes `text` to `path` (creating or truncating it); errors name the file.
pub fn write_file(path: &std::path::Path, text: &str) -> Result<()> {
    std::fs::write(path, text).map_err(|source| Error::Io {
        file: path.to_path_buf(),
        source,
    })
}

/// Prints a note line on stderr (a closed or full stderr is ignored, never a panic).
pub fn note(msg: &str) {
    let _ = writeln!(std::io::stderr().lock(), "note: {msg}");
}

/// Prints a warning line on stderr.
pub fn warn(msg: &str) {
    let _ = writeln!(std::io::stderr().lock(), "warning: {msg}");
}

/// A progress bar over `len` steps on stderr, drawn only when stderr is a terminal.
pub fn progress(len: u64, msg: &str) -> ProgressBar {
    let pb = if std::io::stderr().is_terminal() {
        ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr())
    } else {
        ProgressBar::hidden()
    };
    if let Ok(style) = ProgressStyle::with_template("{msg:<28} [{bar:30}] {pos}/{len} {elapsed}") {
        pb.set_style(style.progress_chars("=> "));
    }
    pb.set_message(msg.to_string());
    pb
}

/// A spinner with a message on stderr for work of unknown length, drawn only when stderr is a
/// terminal. Ticks by itself every 100 ms.
pub fn spinner(msg: &str) -> ProgressBar {
    let pb = if std::io::stderr().is_terminal() {
        ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr())
    } else {
        ProgressBar::hidden()
    };
    if let Ok(style) = ProgressStyle::with_template("{spinner} {msg} {elapsed}") {
        pb.set_style(style);
    }
    pb.set_message(msg.to_string());
    if !pb.is_hidden() {
        pb.enable_steady_tick(std::time::Duration::from_millis(100));
    }
    pb
}

/// The library's [`crate::ops::Progress`] drawn on stderr: a bar for steps of known length, a
/// spinner otherwise (hidden when stderr is not a terminal).
#[derive(Debug, Default)]
pub struct TerminalProgress {
    bar: std::sync::Mutex<Option<ProgressBar>>,
}

impl crate::ops::Progress for TerminalProgress {
    fn begin(&self, what: &str, total: Option<u64>) {
        let pb = match total {
            Some(n) => progress(n, what),
            None => spinner(what),
        };
        if let Ok(mut b) = self.bar.lock() {
            if let Some(old) = b.replace(pb) {
                old.finish_and_clear();
            }
        }
    }

    fn advance(&self, n: u64) {
        if let Ok(b) = self.bar.lock() {
            if let Some(pb) = b.as_ref() {
                pb.inc(n);
            }
        }
    }

    fn end(&self) {
        if let Ok(mut b) = self.bar.lock() {
            if let Some(pb) = b.take() {
                pb.finish_and_clear();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_pads_and_aligns() {
        let mut t = Table::new(&[("name", Align::Left), ("value", Align::Right)]);
        t.row(vec!["a".into(), "1.5".into()]);
        t.row(vec!["long name".into(), "-12.25".into()]);
        assert_eq!(
            t.render(2),
            "  name        value\n  a             1.5\n  long name  -12.25\n"
        );
    }

    #[test]
    fn numbers_are_stable() {
        assert_eq!(fixed(-0.0001, 2), "0.00");
        assert_eq!(fixed(f64::NAN, 2), "-");
        assert_eq!(fixed(-1.005, 1), "-1.0");
        assert_eq!(sci(0.00012345, 3), "1.23e-4");
        assert_eq!(general(2.5e-5, 3), "2.500e-5");
        assert_eq!(general(12.0, 3), "12.000");
    }
}
