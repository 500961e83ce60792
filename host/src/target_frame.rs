//! The spectra frame a target emits after its power-up self-identification, read back on the
//! host (the `powerup` firmware of `firmware/app`; `ferrosid reidentify`).
//!
//! The firmware logs text lines (defmt, decoded by `defmt-print` or the test harness); the
//! frame is the block
//!
//! ```text
//! FRAME_BEGIN fs=<Hz> n=<N> averages=<a> dropped=<d> window=<w> overlap=<o> detrend=<m> excited_max_bin=<b> gate=<g>
//! FRAME <bin> <S_uu> <S_yy> <Re S_uy> <Im S_uy> <coherence>      (bins 0..=N/2, ascending)
//! FRAME_END bins=<N/2+1>
//! ```
//!
//! with one-sided Welch densities (units²/Hz) and magnitude-squared coherence. Lines may carry a
//! prefix (log level, time stamp): a line is recognised by its first token that is one of the
//! keywords. The receipt lines of the same run (`RECEIPT ...`, `VERDICT ...`) are collected
//! too. `key=value` fields of `FRAME_BEGIN` other than `fs` and `n` are optional; unknown keys
//! are kept in [`TargetFrame::header`].
//!
//! Every malformed line is an [`Error::Parse`] naming the file and the 1-based line.
use crate::error::{Error, Result};
use ferrosid_frame::{self as frame, Keyword};
use num_complex::Complex64;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// One frequency bin of the frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FrameBin {
    /// Bin index k (frequency k·fs/N).
    pub bin: usize,
    /// Input auto-spectral density S_uu.
    pub suu: f64,
    /// Output auto-spectral density S_yy.
    pub syy: f64,
    /// Cross-spectral density S_uy = mean conj(U)·Y (scaled); JSON `[re, im]`.
    #[serde(serialize_with = "ser_c64")]
    pub suy: Complex64,
    /// Magnitude-squared coherence, [0, 1].
    pub coherence: f64,
}

/// One `RECEIPT` line: a check frequency of the on-target check.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReceiptRow {
    /// Welch bin.
    pub bin: usize,
    /// Frequency, Hz.
    pub hz: f64,
    /// Coherence at the bin.
    pub coherence: f64,
    /// The flashed model's response evaluated on target; JSON `[re, im]`.
    #[serde(serialize_with = "ser_c64")]
    pub g0: Complex64,
    /// The measured H1 on target; JSON `[re, im]`.
    #[serde(serialize_with = "ser_c64")]
    pub g_meas: Complex64,
    /// |G_meas − G0|/|G0| (NaN when undefined).
    pub rel_error: f64,
    /// |W_m(j2πf)| evaluated on target.
    pub wm: f64,
    /// Normalised random error σ of the target's estimate (the bin counts when 3σ <= |W_m|).
    pub sigma: f64,
    /// PASS, FAIL, SKIP, UNRESOLVED or UNDEFINED.
    pub verdict: String,
}

/// Everything read from a target's log.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TargetFrame {
    /// File (or stream name) it was read from.
    pub source: PathBuf,
    /// Sample rate, Hz.
    pub fs_hz: f64,
    /// Welch segment length N.
    pub n: usize,
    /// Segments averaged (if reported).
    pub averages: Option<u64>,
    /// Highest excited bin (if reported).
    pub excited_max_bin: Option<usize>,
    /// The target's coherence gate (if reported).
    pub gate: Option<f64>,
    /// All `key=value` fields of `FRAME_BEGIN`, in order.
    pub header: Vec<(String, String)>,
    /// Bins 0..=N/2 in ascending order.
    pub bins: Vec<FrameBin>,
    /// The receipt lines, in order.
    pub receipt: Vec<ReceiptRow>,
    /// The verdict word of the `VERDICT` line, if present.
    pub verdict: Option<String>,
}

/// Frequency-response points selected from a frame (see [`TargetFrame::gated_h1`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrfPoints {
    /// Bins used.
    pub bins: Vec<usize>,
    /// Their frequencies, Hz.
    pub freq_hz: Vec<f64>,
    /// H1 = S_uy / S_uu; JSON `[[re, im], ...]`.
    #[serde(serialize_with = "ser_c64_vec")]
    pub h: Vec<Complex64>,
    /// Coherence.
    pub coherence: Vec<f64>,
}

fn ser_c64<S: serde::Serializer>(z: &Complex64, s: S) -> std::result::Result<S::Ok, S::Error> {
    [z.re, z.im].serialize(s)
}

fn ser_c64_vec<S: serde::Serializer>(
    v: &[Complex64],
    s: S,
) -> std::result::Result<S::Ok, S::Error> {
    s.collect_seq(v.iter().map(|z| [z.re, z.im]))
}

fn parse_num<T: std::str::FromStr>(
    tok: Option<&str>,
    what: &str,
    file: &Path,
    line: usize,
) -> Result<T> {
    let t = tok.ok_or_else(|| Error::Parse {
        file: file.to_path_buf(),
        line,
        msg: format!("missing {what}"),
    })?;
    t.parse::<T>().map_err(|_| Error::Parse {
        file: file.to_path_buf(),
        line,
        msg: format!("{what} \"{}\" is not a number", crate::error::excerpt(t)),
    })
}

fn parse_f64(tok: Option<&str>, what: &str, file: &Path, line: usize) -> Result<f64> {
    // NaN is a legal value in receipts (undefined relative error), so parse it as such.
    parse_num::<f64>(tok, what, file, line)
}

/// The state of [`TargetFrame::parse`] between lines.
struct FrameParser<'a> {
    file: &'a Path,
    frame: Option<TargetFrame>,
    open: bool,
    closed: bool,
    receipt: Vec<ReceiptRow>,
    verdict: Option<String>,
}

impl<'a> FrameParser<'a> {
    fn perr(&self, line: usize, msg: String) -> Error {
        Error::Parse {
            file: self.file.to_path_buf(),
            line,
            msg,
        }
    }

    /// The frame still open at line `ln`, or the error naming `what` outside a frame.
    fn open_frame(&mut self, ln: usize, what: &str) -> Result<&mut TargetFrame> {
        match (&mut self.frame, self.open) {
            (Some(f), true) => Ok(f),
            _ => Err(Error::Parse {
                file: self.file.to_path_buf(),
                line: ln,
                msg: what.to_string(),
            }),
        }
    }

    fn begin(&mut self, ln: usize, rest: &[&str]) -> Result<()> {
        let file = self.file;
        if self.frame.is_some() {
            return Err(self.perr(ln, "a second FRAME_BEGIN: one frame per log".into()));
        }
        let mut header = Vec::new();
        for t in rest {
            let (k, v) = frame::header_field(t).ok_or_else(|| {
                self.perr(
                    ln,
                    format!(
                        "FRAME_BEGIN field \"{}\" is not key=value",
                        crate::error::excerpt(t)
                    ),
                )
            })?;
            header.push((k.to_string(), v.to_string()));
        }
        let get = |k: &str| {
            header
                .iter()
                .find(|(hk, _)| hk == k)
                .map(|(_, v)| v.as_str())
        };
        let fs_hz: f64 = parse_num(get(frame::KEY_FS), frame::KEY_FS, file, ln)?;
        if !(fs_hz.is_finite() && fs_hz > 0.0) {
            return Err(self.perr(ln, format!("fs = {fs_hz} Hz must be finite and > 0")));
        }
        let n: usize = parse_num(get(frame::KEY_N), frame::KEY_N, file, ln)?;
        if !frame::segment_length_ok(n) {
            return Err(self.perr(
                ln,
                format!(
                    "n = {n} is not a power of two in {}..={}",
                    frame::MIN_SEGMENT,
                    frame::MAX_SEGMENT
                ),
            ));
        }
        let optional = |key: &'static str| get(key).map(|v| (v, key));
        let averages = optional(frame::KEY_AVERAGES)
            .map(|(v, k)| parse_num::<u64>(Some(v), k, file, ln))
            .transpose()?;
        let excited_max_bin = optional(frame::KEY_EXCITED_MAX_BIN)
            .map(|(v, k)| parse_num::<usize>(Some(v), k, file, ln))
            .transpose()?;
        let gate = optional(frame::KEY_GATE)
            .map(|(v, k)| parse_num::<f64>(Some(v), k, file, ln))
            .transpose()?;
        if let Some(g) = gate {
            if !(0.0..=1.0).contains(&g) {
                return Err(self.perr(ln, format!("gate = {g} is not a coherence in [0, 1]")));
            }
        }
        self.frame = Some(TargetFrame {
            source: file.to_path_buf(),
            fs_hz,
            n,
            averages,
            excited_max_bin,
            gate,
            header,
            bins: Vec::with_capacity(frame::bin_count(n)),
            receipt: Vec::new(),
            verdict: None,
        });
        self.open = true;
        Ok(())
    }

    fn bin(&mut self, ln: usize, rest: &[&str]) -> Result<()> {
        let file = self.file;
        let (expect, half) = {
            let f = self.open_frame(ln, "FRAME line outside FRAME_BEGIN..FRAME_END")?;
            (f.bins.len(), f.n / 2)
        };
        let perr = |msg: String| Error::Parse {
            file: file.to_path_buf(),
            line: ln,
            msg,
        };
        if rest.len() != frame::BIN_FIELDS.len() {
            return Err(perr(format!(
                "FRAME needs {} fields (bin S_uu S_yy ReS_uy ImS_uy coherence), got {}",
                frame::BIN_FIELDS.len(),
                rest.len()
            )));
        }
        let names = &frame::BIN_FIELDS[1..];
        let bin: usize = parse_num(Some(rest[0]), frame::BIN_FIELDS[0], file, ln)?;
        if bin != expect {
            return Err(perr(format!(
                "bin {bin} out of order: expected bin {expect}"
            )));
        }
        if bin > half {
            return Err(perr(format!("bin {bin} is beyond N/2 = {half}")));
        }
        let mut v = [0.0f64; 5];
        for (j, slot) in v.iter_mut().enumerate() {
            *slot = parse_f64(Some(rest[j + 1]), names[j], file, ln)?;
            if !slot.is_finite() {
                return Err(perr(format!("{} = {} is not finite", names[j], slot)));
            }
        }
        if v[0] < 0.0 || v[1] < 0.0 {
            return Err(perr("an auto-spectral density is negative".into()));
        }
        if !(0.0..=1.0 + 1e-6).contains(&v[4]) {
            return Err(perr(format!("coherence {} is outside [0, 1]", v[4])));
        }
        let f = self.open_frame(ln, "FRAME line outside FRAME_BEGIN..FRAME_END")?;
        f.bins.push(FrameBin {
            bin,
            suu: v[0],
            syy: v[1],
            suy: Complex64::new(v[2], v[3]),
            coherence: v[4].min(1.0),
        });
        Ok(())
    }

    fn end(&mut self, ln: usize, rest: &[&str]) -> Result<()> {
        let file = self.file;
        let (have, n) = {
            let f = self.open_frame(ln, "FRAME_END without FRAME_BEGIN")?;
            (f.bins.len(), f.n)
        };
        let want = frame::bin_count(n);
        if have != want {
            return Err(self.perr(ln, format!("frame holds {have} bins, N = {n} needs {want}")));
        }
        if let Some(t) = rest.first() {
            let count: usize = parse_num(
                t.strip_prefix(frame::END_COUNT_PREFIX),
                "FRAME_END bins=",
                file,
                ln,
            )?;
            if count != want {
                return Err(self.perr(ln, format!("FRAME_END says {count} bins, expected {want}")));
            }
        }
        self.open = false;
        self.closed = true;
        Ok(())
    }

    fn receipt(&mut self, ln: usize, rest: &[&str]) -> Result<()> {
        let file = self.file;
        let names = frame::RECEIPT_FIELDS;
        if rest.len() != names.len() {
            return Err(self.perr(
                ln,
                format!("RECEIPT needs {} fields, got {}", names.len(), rest.len()),
            ));
        }
        let g = |j: usize| parse_f64(Some(rest[j]), names[j], file, ln);
        self.receipt.push(ReceiptRow {
            bin: parse_num(Some(rest[0]), names[0], file, ln)?,
            hz: g(1)?,
            coherence: g(2)?,
            g0: Complex64::new(g(3)?, g(4)?),
            g_meas: Complex64::new(g(5)?, g(6)?),
            rel_error: g(7)?,
            wm: g(8)?,
            sigma: g(9)?,
            verdict: rest[10].to_string(),
        });
        Ok(())
    }

    fn finish(self) -> Result<TargetFrame> {
        let file = self.file;
        let mut f = self.frame.ok_or_else(|| Error::Data {
            file: file.to_path_buf(),
            msg: "no FRAME_BEGIN line: not a target spectra log".into(),
        })?;
        if !self.closed {
            return Err(Error::Data {
                file: file.to_path_buf(),
                msg: format!(
                    "the frame ends after {} of {} bins without FRAME_END (truncated log?)",
                    f.bins.len(),
                    frame::bin_count(f.n)
                ),
            });
        }
        f.receipt = self.receipt;
        f.verdict = self.verdict;
        Ok(f)
    }
}

impl TargetFrame {
    /// Reads a frame from a text file of decoded target log lines.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
            file: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses decoded target log lines; `source` names the origin in errors. The wire format
    /// (keywords, header keys, fields) is defined once in the `ferrosid-frame` crate.
    ///
    /// Errors ([`Error::Parse`] with the line, or [`Error::Data`] for the whole stream): no
    /// `FRAME_BEGIN`; a second frame; `fs` not finite and positive; `n` not a power of two in
    /// 64..=4096 (the firmware's sizes); a `FRAME` line outside a frame, with a field missing
    /// or not a number, with a non-finite or negative density, coherence outside [0, 1], or a
    /// bin out of order; `FRAME_END` count not matching; a frame without `FRAME_END`
    /// (truncated log); a `RECEIPT` line without exactly eleven fields.
    pub fn parse(text: &str, source: &Path) -> Result<Self> {
        let mut p = FrameParser {
            file: source,
            frame: None,
            open: false,
            closed: false,
            receipt: Vec::new(),
            verdict: None,
        };
        for (idx, raw) in text.lines().enumerate() {
            let ln = idx + 1;
            let Some((kw, tokens)) = frame::split_line(raw) else {
                continue;
            };
            let rest: Vec<&str> = tokens.collect();
            match kw {
                Keyword::Begin => p.begin(ln, &rest)?,
                Keyword::Bin => p.bin(ln, &rest)?,
                Keyword::End => p.end(ln, &rest)?,
                Keyword::Receipt => p.receipt(ln, &rest)?,
                Keyword::Verdict => p.verdict = rest.first().map(|s| s.to_string()),
            }
        }
        p.finish()
    }

    /// Frequency of bin `k`, Hz.
    pub fn bin_hz(&self, k: usize) -> f64 {
        k as f64 * self.fs_hz / self.n as f64
    }

    /// Sample time 1/fs, s.
    pub fn ts(&self) -> f64 {
        1.0 / self.fs_hz
    }

    /// H1 = S_uy/S_uu at the bins usable for fitting: `1 <= k < N/2`, `k <=
    /// excited_max_bin` when the frame reports it, coherence >= `gate`, and S_uu at least
    /// `min_rel_suu` times the largest S_uu (excludes lines the excitation did not drive).
    pub fn gated_h1(&self, gate: f64, min_rel_suu: f64) -> FrfPoints {
        let max_suu = self.bins.iter().map(|b| b.suu).fold(0.0f64, f64::max);
        let mut pts = FrfPoints {
            bins: Vec::new(),
            freq_hz: Vec::new(),
            h: Vec::new(),
            coherence: Vec::new(),
        };
        for b in &self.bins {
            let excited = self.excited_max_bin.is_none_or(|m| b.bin <= m);
            if b.bin == 0
                || b.bin >= self.n / 2
                || !excited
                || b.coherence.is_nan()
                || b.coherence < gate
                || !(b.suu > min_rel_suu * max_suu && b.suu > 0.0)
            {
                continue;
            }
            let h = b.suy / b.suu;
            if !(h.re.is_finite() && h.im.is_finite()) {
                continue;
            }
            pts.bins.push(b.bin);
            pts.freq_hz.push(self.bin_hz(b.bin));
            pts.h.push(h);
            pts.coherence.push(b.coherence);
        }
        pts
    }
}
