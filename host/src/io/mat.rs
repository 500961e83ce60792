//! MATLAB v5 (Level 5, also written by `save -v6`/`-v7`) `.mat` files: a small reader for real
//! numeric variables.
//!
//! Supported: both byte orders; `miCOMPRESSED` (zlib) and plain top-level elements; the
//! small-data-element tag format; `miMATRIX` variables of class double, single, int8..int64,
//! uint8..uint64 (logical included) whose data are stored in any numeric MAT data type (MATLAB
//! stores e.g. integral doubles as `miUINT8`). Everything is converted to `f64`.
//!
//! Skipped without failing (listed in [`MatFile::skipped`] with the reason): class objects
//! (`mxOBJECT`, `mxOPAQUE`, e.g. MCOS objects such as `tf`), function handles, cell arrays,
//! structs, char arrays, sparse matrices, unnamed elements (the MATLAB subsystem /
//! function-workspace block) and unknown element types. Complex variables are listed but
//! reading them is an error (real data only). Not supported: v7.3 files (HDF5) and v4 files;
//! both are reported as such.
//!
//! Variables are located when the file is opened (only a short prefix of each compressed
//! element is inflated to learn its name); a variable's data are inflated when it is read.
use std::io::Read;
use std::path::{Path, PathBuf};

use super::{finish_log, sample_time, Checks, TimeSource};
use crate::data::Channel;
use crate::error::{Error, Result};
use crate::Log;

// MAT data types (tag type field).
const MI_INT8: u32 = 1;
const MI_UINT8: u32 = 2;
const MI_INT16: u32 = 3;
const MI_UINT16: u32 = 4;
const MI_INT32: u32 = 5;
const MI_UINT32: u32 = 6;
const MI_SINGLE: u32 = 7;
const MI_DOUBLE: u32 = 9;
const MI_INT64: u32 = 12;
const MI_UINT64: u32 = 13;
const MI_MATRIX: u32 = 14;
const MI_COMPRESSED: u32 = 15;

/// What to read from a `.mat` log.
#[derive(Debug, Clone, PartialEq)]
pub struct MatOptions {
    /// Input variable names (at least one; no default).
    pub inputs: Vec<String>,
    /// Output variable names (at least one; no default).
    pub outputs: Vec<String>,
    /// Time variable (optional).
    pub time: Option<String>,
    /// Seconds per unit of the time variable (default 1.0).
    pub time_scale: f64,
    /// Sample rate in Hz. Checked against the time variable when both are given.
    pub fs: Option<f64>,
    /// Scalar variable holding the sample rate in Hz. `None`: when neither `fs` nor `time` is
    /// given, a scalar variable named `fs` is used if the file has one.
    pub fs_var: Option<String>,
    /// Plausibility checks.
    pub checks: Checks,
}

impl Default for MatOptions {
    fn default() -> Self {
        Self {
            inputs: Vec::new(),
            outputs: Vec::new(),
            time: None,
            time_scale: 1.0,
            fs: None,
            fs_var: None,
            checks: Checks::default(),
        }
    }
}

/// A real or complex numeric variable found in the file.
#[derive(Debug, Clone, PartialEq)]
pub struct VarInfo {
    /// Variable name.
    pub name: String,
    /// MATLAB class name (`"double"`, `"uint16"`, ...).
    pub class: &'static str,
    /// Dimensions as MATLAB reports them (`size`), at least 2.
    pub dims: Vec<usize>,
    /// True for complex data (which this reader refuses to load).
    pub complex: bool,
}

/// A top-level element that was skipped while opening the file, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct SkippedVar {
    /// Variable name (`""` for unnamed elements such as the MATLAB subsystem block).
    pub name: String,
    /// Why it was skipped, e.g. "MATLAB class object (opaque, class `tf`)".
    pub reason: String,
}

#[derive(Debug, Clone)]
enum Body {
    /// Byte range of the miMATRIX payload (after its tag) in the file.
    Plain(usize, usize),
    /// Byte range of the zlib stream of a miCOMPRESSED element.
    Compressed(usize, usize),
}

#[derive(Debug, Clone)]
struct Entry {
    info: VarInfo,
    body: Body,
}

/// An opened MATLAB v5 file: the directory of its numeric variables.
#[derive(Debug, Clone)]
pub struct MatFile {
    path: PathBuf,
    bytes: Vec<u8>,
    big_endian: bool,
    entries: Vec<Entry>,
    infos: Vec<VarInfo>,
    skipped: Vec<SkippedVar>,
}

/// Errors raised inside the byte-level parser, turned into [`Error`]s with file/variable context.
#[derive(Debug)]
enum Bad {
    /// Ran out of bytes.
    Short,
    /// Structurally invalid.
    Invalid(String),
}

struct Cursor<'a> {
    b: &'a [u8],
    pos: usize,
    big: bool,
}

impl<'a> Cursor<'a> {
    fn u32(&mut self) -> Result<u32, Bad> {
        let s = self.b.get(self.pos..self.pos + 4).ok_or(Bad::Short)?;
        self.pos += 4;
        let a = [s[0], s[1], s[2], s[3]];
        Ok(if self.big {
            u32::from_be_bytes(a)
        } else {
            u32::from_le_bytes(a)
        })
    }
    /// Reads a data-element tag, returning (type, byte count, payload slice) and advancing past
    /// the payload and its padding (small elements occupy exactly 8 bytes).
    fn element(&mut self) -> Result<(u32, &'a [u8]), Bad> {
        let first = self.u32()?;
        if first >> 16 != 0 {
            let (ty, n) = (first & 0xffff, (first >> 16) as usize);
            if n > 4 {
                return Err(Bad::Invalid(format!(
                    "small data element claims {n} bytes (max 4)"
                )));
            }
            let s = self.b.get(self.pos..self.pos + 4).ok_or(Bad::Short)?;
            self.pos += 4;
            return Ok((ty, &s[..n]));
        }
        let n = self.u32()? as usize;
        let end = self.pos.checked_add(n).ok_or(Bad::Short)?;
        let s = self.b.get(self.pos..end).ok_or(Bad::Short)?;
        self.pos = end + (8 - n % 8) % 8;
        Ok((first, s))
    }
}

fn class_name(c: u8) -> &'static str {
    match c {
        1 => "cell",
        2 => "struct",
        3 => "object",
        4 => "char",
        5 => "sparse",
        6 => "double",
        7 => "single",
        8 => "int8",
        9 => "uint8",
        10 => "int16",
        11 => "uint16",
        12 => "int32",
        13 => "uint32",
        14 => "int64",
        15 => "uint64",
        16 => "function_handle",
        17 => "opaque",
        _ => "unknown",
    }
}

/// Parsed head of a miMATRIX payload.
struct Head {
    class: u8,
    complex: bool,
    dims: Vec<usize>,
    name: String,
    /// For opaque objects: their class name (e.g. `tf`).
    object_class: Option<String>,
    /// Offset of the first data subelement within the payload.
    data_pos: usize,
}

fn parse_head(payload: &[u8], big: bool) -> Result<Head, Bad> {
    let mut c = Cursor {
        b: payload,
        pos: 0,
        big,
    };
    let (ty, flags) = c.element()?;
    if ty != MI_UINT32 || flags.len() != 8 {
        return Err(Bad::Invalid("array flags subelement is malformed".into()));
    }
    let f = if big {
        u32::from_be_bytes([flags[0], flags[1], flags[2], flags[3]])
    } else {
        u32::from_le_bytes([flags[0], flags[1], flags[2], flags[3]])
    };
    let class = (f & 0xff) as u8;
    let complex = f & 0x0800 != 0;
    let text = |s: &[u8]| {
        String::from_utf8_lossy(s)
            .trim_end_matches('\0')
            .to_string()
    };
    if class == 17 {
        // mxOPAQUE: name, object type ("MCOS"), class name, then an embedded matrix.
        let (_, name) = c.element()?;
        let name = text(name);
        let (_, _kind) = c.element()?;
        let (_, cls) = c.element()?;
        return Ok(Head {
            class,
            complex: false,
            dims: Vec::new(),
            name,
            object_class: Some(text(cls)),
            data_pos: c.pos,
        });
    }
    let (ty, d) = c.element()?;
    if ty != MI_INT32 || d.len() % 4 != 0 || d.len() < 8 {
        return Err(Bad::Invalid("dimensions subelement is malformed".into()));
    }
    let dims = d
        .chunks_exact(4)
        .map(|q| {
            let a = [q[0], q[1], q[2], q[3]];
            let v = if big {
                i32::from_be_bytes(a)
            } else {
                i32::from_le_bytes(a)
            };
            usize::try_from(v).map_err(|_| Bad::Invalid(format!("negative dimension {v}")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let (ty, name) = c.element()?;
    if ty != MI_INT8 && ty != MI_UINT8 {
        return Err(Bad::Invalid("array name subelement is malformed".into()));
    }
    let name = text(name);
    // Objects (mxOBJECT) carry their class name next.
    let object_class = if class == 3 {
        c.element().ok().map(|(_, s)| text(s))
    } else {
        None
    };
    Ok(Head {
        class,
        complex,
        dims,
        name,
        object_class,
        data_pos: c.pos,
    })
}

fn inflate(bytes: &[u8], limit: Option<usize>) -> std::io::Result<Vec<u8>> {
    let dec = flate2::read::ZlibDecoder::new(bytes);
    let mut out = Vec::new();
    match limit {
        Some(n) => {
            dec.take(n as u64).read_to_end(&mut out)?;
        }
        None => {
            // A zlib stream can inflate a thousandfold: capped like a log file.
            let cap = crate::io::input::MAX_LOG_BYTES;
            dec.take(cap + 1).read_to_end(&mut out)?;
            if out.len() as u64 > cap {
                return Err(std::io::Error::other(format!(
                    "it decompresses to more than {} GiB, the limit of a log (docs/safety.md)",
                    cap >> 30
                )));
            }
        }
    }
    Ok(out)
}

impl MatFile {
    /// Opens a MATLAB v5 file and builds the directory of its variables.
    ///
    /// Errors: [`Error::Io`]; [`Error::Data`] for a file that is not MATLAB v5 (v4, v7.3/HDF5,
    /// other), a corrupt header or a truncated/corrupt element (with its byte offset).
    pub fn open(path: &Path) -> Result<MatFile> {
        let bytes = crate::io::input::read_bytes(path, crate::io::input::MAX_LOG_BYTES)?;
        let data_err = |msg: String| Error::Data {
            file: path.to_path_buf(),
            msg,
        };
        if bytes.len() >= 19 && &bytes[..19] == b"MATLAB 7.3 MAT-file" {
            return Err(data_err(
                "MATLAB v7.3 (HDF5) .mat files are not supported; re-save with `save -v7`".into(),
            ));
        }
        if bytes.len() < 128 || &bytes[..6] != b"MATLAB" {
            return Err(data_err(
                "not a MATLAB v5 .mat file (no `MATLAB` header text; v4 files are not supported)"
                    .into(),
            ));
        }
        let big_endian = match &bytes[126..128] {
            b"IM" => false,
            b"MI" => true,
            _ => {
                return Err(data_err(
                    "corrupt .mat header: endian indicator is neither `IM` nor `MI`".into(),
                ))
            }
        };
        let mut entries = Vec::new();
        let mut skipped = Vec::new();
        let mut pos = 128usize;
        while pos < bytes.len() {
            // Trailing padding shorter than a tag is tolerated.
            if bytes.len() - pos < 8 {
                break;
            }
            let mut c = Cursor {
                b: &bytes,
                pos,
                big: big_endian,
            };
            let ty = c.u32().map_err(|_| data_err("truncated".into()))?;
            let n = c.u32().map_err(|_| data_err("truncated".into()))? as usize;
            let start = pos + 8;
            let end = start
                .checked_add(n)
                .filter(|&e| e <= bytes.len())
                .ok_or_else(|| {
                    data_err(format!(
                        "truncated file: element at byte {pos} claims {n} bytes, only {} remain",
                        bytes.len() - start
                    ))
                })?;
            let elem_err =
                |what: String| data_err(format!("corrupt element at byte {pos}: {what}"));
            match ty {
                MI_MATRIX => {
                    let head = parse_head(&bytes[start..end], big_endian).map_err(|b| {
                        elem_err(match b {
                            Bad::Short => "matrix header is truncated".into(),
                            Bad::Invalid(m) => m,
                        })
                    })?;
                    classify(head, Body::Plain(start, end), &mut entries, &mut skipped);
                    pos = end + (8 - n % 8) % 8;
                }
                MI_COMPRESSED => {
                    let comp = &bytes[start..end];
                    let mut head = None;
                    for limit in [Some(1024), None] {
                        let raw = inflate(comp, limit)
                            .map_err(|e| elem_err(format!("zlib stream is corrupt: {e}")))?;
                        let mut cc = Cursor {
                            b: &raw,
                            pos: 0,
                            big: big_endian,
                        };
                        let parsed = (|| -> Result<Head, Bad> {
                            let first = cc.u32()?;
                            let _len = cc.u32()?;
                            if first != MI_MATRIX {
                                return Err(Bad::Invalid(format!(
                                    "compressed element of type {first}"
                                )));
                            }
                            parse_head(&raw[8..], big_endian)
                        })();
                        match parsed {
                            Ok(h) => {
                                head = Some(Ok(h));
                                break;
                            }
                            Err(Bad::Short) if limit.is_some() && raw.len() == 1024 => continue,
                            Err(b) => {
                                head = Some(Err(b));
                                break;
                            }
                        }
                    }
                    match head {
                        Some(Ok(h)) => {
                            classify(h, Body::Compressed(start, end), &mut entries, &mut skipped)
                        }
                        Some(Err(Bad::Invalid(m))) if m.starts_with("compressed element") => {
                            skipped.push(SkippedVar {
                                name: String::new(),
                                reason: format!("{m} at byte {pos} (not a matrix)"),
                            })
                        }
                        Some(Err(Bad::Invalid(m))) => return Err(elem_err(m)),
                        _ => return Err(elem_err("compressed matrix header is truncated".into())),
                    }
                    pos = end;
                }
                other => {
                    skipped.push(SkippedVar {
                        name: String::new(),
                        reason: format!("top-level element of data type {other} at byte {pos}"),
                    });
                    pos = end + (8 - n % 8) % 8;
                }
            }
        }
        let infos = entries.iter().map(|e: &Entry| e.info.clone()).collect();
        Ok(MatFile {
            path: path.to_path_buf(),
            bytes,
            big_endian,
            entries,
            infos,
            skipped,
        })
    }

    /// The numeric variables, in file order.
    pub fn variables(&self) -> &[VarInfo] {
        &self.infos
    }

    /// The elements that were skipped (class objects, structs, cells, char arrays, ...).
    pub fn skipped(&self) -> &[SkippedVar] {
        &self.skipped
    }

    /// File path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn var_err(&self, var: &str, msg: String) -> Error {
        Error::MatVar {
            file: self.path.clone(),
            var: var.to_string(),
            msg,
        }
    }

    /// Reads a real numeric variable as a flat `f64` vector in MATLAB's column-major order,
    /// together with its dimensions. Non-finite values are allowed here (see [`Self::vector`]).
    ///
    /// Errors ([`Error::MatVar`] naming the variable): missing (the message lists the numeric
    /// variables), skipped (e.g. a class object), complex, or corrupt.
    pub fn array(&self, name: &str) -> Result<(Vec<usize>, Vec<f64>)> {
        let e = match self.entries.iter().find(|e| e.info.name == name) {
            Some(e) => e,
            None => {
                if let Some(s) = self.skipped.iter().find(|s| s.name == name) {
                    return Err(self.var_err(
                        name,
                        format!("cannot be read as numeric data: {}", s.reason),
                    ));
                }
                let names: Vec<&str> = self.infos.iter().map(|v| v.name.as_str()).collect();
                if names.is_empty() {
                    let skipped: Vec<String> = self
                        .skipped
                        .iter()
                        .map(|s| {
                            if s.name.is_empty() {
                                s.reason.clone()
                            } else {
                                format!("`{}`: {}", crate::error::excerpt(&s.name), s.reason)
                            }
                        })
                        .collect();
                    return Err(self.var_err(
                        name,
                        format!(
                            "not found: the file holds no numeric variable at all ({} bytes after \
                             the 128-byte header{}); is it truncated or empty?",
                            self.bytes.len().saturating_sub(128),
                            if skipped.is_empty() {
                                String::new()
                            } else {
                                format!("; skipped: {}", skipped.join("; "))
                            }
                        ),
                    ));
                }
                return Err(self.var_err(
                    name,
                    format!(
                        "not found; numeric variables are: {}",
                        crate::error::excerpt_n(&names.join(", "), 400)
                    ),
                ));
            }
        };
        if e.info.complex {
            return Err(self.var_err(name, "complex data are not supported".into()));
        }
        let inflated;
        let payload: &[u8] = match e.body {
            Body::Plain(s, t) => &self.bytes[s..t],
            Body::Compressed(s, t) => {
                inflated = inflate(&self.bytes[s..t], None)
                    .map_err(|err| self.var_err(name, format!("zlib stream is corrupt: {err}")))?;
                inflated
                    .get(8..)
                    .ok_or_else(|| self.var_err(name, "truncated".into()))?
            }
        };
        let head = parse_head(payload, self.big_endian)
            .map_err(|_| self.var_err(name, "corrupt matrix header".into()))?;
        let mut c = Cursor {
            b: payload,
            pos: head.data_pos,
            big: self.big_endian,
        };
        let (ty, raw) = c.element().map_err(|b| {
            self.var_err(
                name,
                match b {
                    Bad::Short => "data are truncated".into(),
                    Bad::Invalid(m) => m,
                },
            )
        })?;
        let count: usize = head.dims.iter().product();
        let data = convert(ty, raw, self.big_endian).map_err(|m| self.var_err(name, m))?;
        if data.len() != count {
            return Err(self.var_err(
                name,
                format!(
                    "holds {} values but its dimensions {:?} need {count}",
                    data.len(),
                    head.dims
                ),
            ));
        }
        Ok((head.dims, data))
    }

    /// Reads a real numeric vector (`n×1` or `1×n`), all samples finite.
    ///
    /// Errors ([`Error::MatVar`]): as [`Self::array`], plus not a vector, empty, or a non-finite
    /// sample (named by its 1-based index).
    pub fn vector(&self, name: &str) -> Result<Vec<f64>> {
        let (dims, data) = self.array(name)?;
        let non_singleton = dims.iter().filter(|&&d| d != 1).count();
        if non_singleton > 1 {
            return Err(self.var_err(
                name,
                format!("is a {} array, expected a vector", dims_text(&dims)),
            ));
        }
        if data.is_empty() {
            return Err(self.var_err(name, "is empty".into()));
        }
        if let Some(k) = data.iter().position(|v| !v.is_finite()) {
            return Err(self.var_err(
                name,
                format!("sample {} (1-based) is {}, not finite", k + 1, data[k]),
            ));
        }
        Ok(data)
    }

    /// Reads a finite real scalar (`1×1`).
    pub fn scalar(&self, name: &str) -> Result<f64> {
        let (dims, data) = self.array(name)?;
        if data.len() != 1 {
            return Err(self.var_err(
                name,
                format!("is a {} array, expected a scalar", dims_text(&dims)),
            ));
        }
        if !data[0].is_finite() {
            return Err(self.var_err(name, format!("is {}, not finite", data[0])));
        }
        Ok(data[0])
    }
}

fn dims_text(d: &[usize]) -> String {
    d.iter()
        .map(|x| x.to_string())
        .collect::<Vec<_>>()
        .join("×")
}

fn classify(head: Head, body: Body, entries: &mut Vec<Entry>, skipped: &mut Vec<SkippedVar>) {
    let reason = match head.class {
        6..=15 if head.name.is_empty() => {
            Some("unnamed numeric element (MATLAB subsystem / function workspace data)".into())
        }
        6..=15 => None,
        1 => Some("cell array".to_string()),
        2 => Some("struct".to_string()),
        3 => Some(format!(
            "MATLAB class object (class `{}`)",
            head.object_class.as_deref().unwrap_or("?")
        )),
        4 => Some("char array".to_string()),
        5 => Some("sparse matrix".to_string()),
        16 => Some("function handle".to_string()),
        17 => Some(format!(
            "MATLAB class object (opaque, class `{}`)",
            head.object_class.as_deref().unwrap_or("?")
        )),
        c => Some(format!("unknown array class {c}")),
    };
    match reason {
        Some(reason) => skipped.push(SkippedVar {
            name: head.name,
            reason,
        }),
        None => entries.push(Entry {
            info: VarInfo {
                name: head.name,
                class: class_name(head.class),
                dims: head.dims,
                complex: head.complex,
            },
            body,
        }),
    }
}

/// Converts a numeric data subelement to f64.
fn convert(ty: u32, raw: &[u8], big: bool) -> std::result::Result<Vec<f64>, String> {
    macro_rules! conv {
        ($t:ty, $n:expr) => {{
            let width: usize = $n;
            if raw.len() % width != 0 {
                return Err(format!(
                    "data length {} is not a multiple of {} bytes",
                    raw.len(),
                    $n
                ));
            }
            raw.chunks_exact($n)
                .map(|q| {
                    let mut a = [0u8; $n];
                    a.copy_from_slice(q);
                    (if big {
                        <$t>::from_be_bytes(a)
                    } else {
                        <$t>::from_le_bytes(a)
                    }) as f64
                })
                .collect()
        }};
    }
    Ok(match ty {
        MI_INT8 => conv!(i8, 1),
        MI_UINT8 => conv!(u8, 1),
        MI_INT16 => conv!(i16, 2),
        MI_UINT16 => conv!(u16, 2),
        MI_INT32 => conv!(i32, 4),
        MI_UINT32 => conv!(u32, 4),
        MI_SINGLE => conv!(f32, 4),
        MI_DOUBLE => conv!(f64, 8),
        MI_INT64 => conv!(i64, 8),
        MI_UINT64 => conv!(u64, 8),
        other => return Err(format!("unsupported numeric data type {other}")),
    })
}

/// Reads a log from a MATLAB v5 file (see the module documentation for what is supported and
/// [`super`] for the checks).
///
/// Sample time, in order of precedence: the time variable (checked against `fs` if that is also
/// given); else `fs`; else the scalar variable `fs_var`; else a scalar variable named `fs`;
/// else an error.
///
/// Errors: those of [`MatFile::open`] and [`MatFile::vector`]; [`Error::Data`] naming the
/// variables for mismatched lengths, a constant input or too few samples;
/// [`Error::InvalidArgument`] when no input/output is named.
pub fn read_mat(path: &Path, opts: &MatOptions) -> Result<Log> {
    opts.checks.validate()?;
    if opts.inputs.is_empty() || opts.outputs.is_empty() {
        return Err(Error::InvalidArgument(format!(
            "{}: name the input and output variables of the .mat file",
            path.display()
        )));
    }
    if !(opts.time_scale.is_finite() && opts.time_scale > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "time scale must be finite and > 0 s per unit, got {}",
            opts.time_scale
        )));
    }
    let mf = MatFile::open(path)?;
    let read = |names: &[String]| -> Result<Vec<Channel>> {
        names
            .iter()
            .map(|n| {
                Ok(Channel {
                    name: n.clone(),
                    data: mf.vector(n)?,
                })
            })
            .collect()
    };
    let inputs = read(&opts.inputs)?;
    let outputs = read(&opts.outputs)?;
    let n = inputs[0].data.len();
    let mismatch: Vec<String> = inputs
        .iter()
        .chain(outputs.iter())
        .map(|c| format!("`{}` {}", c.name, c.data.len()))
        .collect();
    if inputs
        .iter()
        .chain(outputs.iter())
        .any(|c| c.data.len() != n)
    {
        return Err(Error::Data {
            file: path.to_path_buf(),
            msg: format!("variables have different lengths: {}", mismatch.join(", ")),
        });
    }
    let (ts, time_warning) = if let Some(tv) = &opts.time {
        let mut t = mf.vector(tv)?;
        if t.len() != n {
            return Err(Error::MatVar {
                file: path.to_path_buf(),
                var: tv.clone(),
                msg: format!("has {} samples but the signals have {n}", t.len()),
            });
        }
        for v in &mut t {
            *v *= opts.time_scale;
        }
        let what = format!("time variable `{tv}`");
        let file = path.to_path_buf();
        sample_time(
            TimeSource::Stamps {
                t: &t,
                rounding: &Vec::new,
                fs: opts.fs,
                what: &what,
            },
            &opts.checks,
            &|k, msg| Error::MatVar {
                file: file.clone(),
                var: tv.clone(),
                msg: format!("sample {} (1-based): {msg}", k + 1),
            },
            &|msg| Error::MatVar {
                file: file.clone(),
                var: tv.clone(),
                msg,
            },
        )?
    } else {
        let fs = match (opts.fs, &opts.fs_var) {
            (Some(fs), _) => {
                super::check_fs(fs)?;
                fs
            }
            (None, Some(v)) => mf.scalar(v)?,
            (None, None) => {
                if mf.variables().iter().any(|v| v.name == "fs") {
                    mf.scalar("fs")?
                } else {
                    return Err(Error::Data {
                        file: path.to_path_buf(),
                        msg: "no sample rate: give fs, a scalar sample-rate variable or a time \
                              variable (the file has no scalar `fs`)"
                            .into(),
                    });
                }
            }
        };
        if !(fs.is_finite() && fs > 0.0) {
            return Err(Error::MatVar {
                file: path.to_path_buf(),
                var: opts.fs_var.clone().unwrap_or_else(|| "fs".into()),
                msg: format!("sample rate must be finite and > 0 Hz, got {fs}"),
            });
        }
        (1.0 / fs, None)
    };
    let mut log = finish_log(path, ts, inputs, outputs, &opts.checks)?;
    log.warnings.extend(time_warning);
    Ok(log)
}
