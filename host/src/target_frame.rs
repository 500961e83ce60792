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

const KEYWORDS: [&str; 5] = ["FRAME_BEGIN", "FRAME", "FRAME_END", "RECEIPT", "VERDICT"];

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

impl TargetFrame {
    /// Reads a frame from a text file of decoded target log lines.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
            file: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses decoded target log lines; `source` names the origin in errors.
    ///
    /// Errors ([`Error::Parse`] with the line, or [`Error::Data`] for the whole stream): no
    /// `FRAME_BEGIN`; a second frame; `fs` not finite and positive; `n` not a power of two in
    /// 64..=4096 (the firmware's sizes); a `FRAME` line outside a frame, with a field missing
    /// or not a number, with a non-finite or negative density, coherence outside [0, 1], or a
    /// bin out of order; `FRAME_END` count not matching; a frame without `FRAME_END`
    /// (truncated log); a `RECEIPT` line without exactly eleven fields.
    pub fn parse(text: &str, source: &Path) -> Result<Self> {
        let file = source;
        let perr = |line: usize, msg: String| Error::Parse {
            file: file.to_path_buf(),
            line,
            msg,
        };
        let mut frame: Option<TargetFrame> = None;
        let mut open = false;
        let mut closed = false;
        let mut receipt = Vec::new();
        let mut verdict = None;
        for (idx, raw) in text.lines().enumerate() {
            let ln = idx + 1;
            let toks: Vec<&str> = raw.split_whitespace().collect();
            let Some(pos) = toks.iter().position(|t| KEYWORDS.contains(t)) else {
                continue;
            };
            let kw = toks[pos];
            let rest = &toks[pos + 1..];
            match kw {
                "FRAME_BEGIN" => {
                    if frame.is_some() {
                        return Err(perr(ln, "a second FRAME_BEGIN: one frame per log".into()));
                    }
                    let mut header = Vec::new();
                    for t in rest {
                        let (k, v) = t.split_once('=').ok_or_else(|| {
                            perr(
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
                    let fs_hz: f64 = parse_num(get("fs"), "fs", file, ln)?;
                    if !(fs_hz.is_finite() && fs_hz > 0.0) {
                        return Err(perr(ln, format!("fs = {fs_hz} Hz must be finite and > 0")));
                    }
                    let n: usize = parse_num(get("n"), "n", file, ln)?;
                    if !(n.is_power_of_two() && (64..=4096).contains(&n)) {
                        return Err(perr(
                            ln,
                            format!("n = {n} is not a power of two in 64..=4096"),
                        ));
                    }
                    let averages = get("averages")
                        .map(|v| parse_num::<u64>(Some(v), "averages", file, ln))
                        .transpose()?;
                    let excited_max_bin = get("excited_max_bin")
                        .map(|v| parse_num::<usize>(Some(v), "excited_max_bin", file, ln))
                        .transpose()?;
                    let gate = get("gate")
                        .map(|v| parse_num::<f64>(Some(v), "gate", file, ln))
                        .transpose()?;
                    if let Some(g) = gate {
                        if !(0.0..=1.0).contains(&g) {
                            return Err(perr(
                                ln,
                                format!("gate = {g} is not a coherence in [0, 1]"),
                            ));
                        }
                    }
                    frame = Some(TargetFrame {
                        source: file.to_path_buf(),
                        fs_hz,
                        n,
                        averages,
                        excited_max_bin,
                        gate,
                        header,
                        bins: Vec::with_capacity(n / 2 + 1),
                        receipt: Vec::new(),
                        verdict: None,
                    });
                    open = true;
                }
                "FRAME" => {
                    let f = match (&mut frame, open) {
                        (Some(f), true) => f,
                        _ => {
                            return Err(perr(
                                ln,
                                "FRAME line outside FRAME_BEGIN..FRAME_END".into(),
                            ))
                        }
                    };
                    if rest.len() != 6 {
                        return Err(perr(
                            ln,
                            format!(
                                "FRAME needs 6 fields (bin S_uu S_yy ReS_uy ImS_uy coherence), got {}",
                                rest.len()
                            ),
                        ));
                    }
                    let bin: usize = parse_num(Some(rest[0]), "bin", file, ln)?;
                    let expect = f.bins.len();
                    if bin != expect {
                        return Err(perr(
                            ln,
                            format!("bin {bin} out of order: expected bin {expect}"),
                        ));
                    }
                    if bin > f.n / 2 {
                        return Err(perr(ln, format!("bin {bin} is beyond N/2 = {}", f.n / 2)));
                    }
                    let names = ["S_uu", "S_yy", "Re S_uy", "Im S_uy", "coherence"];
                    let mut v = [0.0f64; 5];
                    for (j, slot) in v.iter_mut().enumerate() {
                        *slot = parse_f64(Some(rest[j + 1]), names[j], file, ln)?;
                        if !slot.is_finite() {
                            return Err(perr(ln, format!("{} = {} is not finite", names[j], slot)));
                        }
                    }
                    if v[0] < 0.0 || v[1] < 0.0 {
                        return Err(perr(ln, "an auto-spectral density is negative".into()));
                    }
                    if !(0.0..=1.0 + 1e-6).contains(&v[4]) {
                        return Err(perr(ln, format!("coherence {} is outside [0, 1]", v[4])));
                    }
                    f.bins.push(FrameBin {
                        bin,
                        suu: v[0],
                        syy: v[1],
                        suy: Complex64::new(v[2], v[3]),
                        coherence: v[4].min(1.0),
                    });
                }
                "FRAME_END" => {
                    let f = match (&frame, open) {
                        (Some(f), true) => f,
                        _ => return Err(perr(ln, "FRAME_END without FRAME_BEGIN".into())),
                    };
                    let want = f.n / 2 + 1;
                    if f.bins.len() != want {
                        return Err(perr(
                            ln,
                            format!(
                                "frame holds {} bins, N = {} needs {want}",
                                f.bins.len(),
                                f.n
                            ),
                        ));
                    }
                    if let Some(t) = rest.first() {
                        let count: usize =
                            parse_num(t.strip_prefix("bins="), "FRAME_END bins=", file, ln)?;
                        if count != want {
                            return Err(perr(
                                ln,
                                format!("FRAME_END says {count} bins, expected {want}"),
                            ));
                        }
                    }
                    open = false;
                    closed = true;
                }
                "RECEIPT" => {
                    if rest.len() != 11 {
                        return Err(perr(
                            ln,
                            format!("RECEIPT needs 11 fields, got {}", rest.len()),
                        ));
                    }
                    let g = |j: usize, what: &str| parse_f64(Some(rest[j]), what, file, ln);
                    receipt.push(ReceiptRow {
                        bin: parse_num(Some(rest[0]), "bin", file, ln)?,
                        hz: g(1, "hz")?,
                        coherence: g(2, "coherence")?,
                        g0: Complex64::new(g(3, "G0 re")?, g(4, "G0 im")?),
                        g_meas: Complex64::new(g(5, "Gmeas re")?, g(6, "Gmeas im")?),
                        rel_error: g(7, "relative error")?,
                        wm: g(8, "|W_m|")?,
                        sigma: g(9, "sigma")?,
                        verdict: rest[10].to_string(),
                    });
                }
                _ => {
                    verdict = rest.first().map(|s| s.to_string());
                }
            }
        }
        let mut f = frame.ok_or_else(|| Error::Data {
            file: file.to_path_buf(),
            msg: "no FRAME_BEGIN line: not a target spectra log".into(),
        })?;
        if !closed {
            return Err(Error::Data {
                file: file.to_path_buf(),
                msg: format!(
                    "the frame ends after {} of {} bins without FRAME_END (truncated log?)",
                    f.bins.len(),
                    f.n / 2 + 1
                ),
            });
        }
        f.receipt = receipt;
        f.verdict = verdict;
        Ok(f)
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
