//! Checked, bounded reading of input files (docs/safety.md, "Input files").
//!
//! Every file ferrosid reads goes through [`read_bytes`] (or is checked with
//! [`check_input_file`] first when another module reads it):
//! * **Regular files only.** The file type is taken from `metadata` (symbolic links followed)
//!   *before* the file is opened, so a FIFO without a writer never blocks and a character
//!   device (`/dev/zero`, `/dev/urandom`) is never read: both are refused naming the file and
//!   what it is.
//! * **Size caps.** A log (CSV, text, .mat) is refused above [`MAX_LOG_BYTES`], every other
//!   input (JSON model/PID/W_m/receipts/sim files, frames, TOML pipelines, templates) above
//!   [`MAX_DOC_BYTES`]. The read itself stops one byte past the cap, so a file that grows
//!   while it is read cannot exhaust memory either.
//! * **Text encodings.** UTF-16/UTF-32 (with a byte-order mark, or UTF-16 recognised by its
//!   zero bytes) is named as such ("file is UTF-16; save it as UTF-8"), not reported as invalid
//!   UTF-8 or as column names with NUL characters. A UTF-8 byte-order mark is skipped.
//! * **JSON.** [`read_json_text`] is the one rule of every JSON reader: the text must be valid
//!   JSON and no object may repeat a key (serde's "last one wins" would silently drop a value).
use crate::error::{Error, Result};
use std::io::Read as _;
use std::path::Path;

/// Largest log file (CSV, whitespace text, MATLAB .mat) ferrosid reads: 2 GiB. A 5-million-row
/// three-column CSV is about 0.4 GB.
pub const MAX_LOG_BYTES: u64 = 2 << 30;
/// Largest other input file (JSON, TOML, templates, target frames): 64 MiB.
pub const MAX_DOC_BYTES: u64 = 64 << 20;

fn io_error(path: &Path, msg: String) -> Error {
    Error::Io {
        file: path.to_path_buf(),
        source: std::io::Error::other(msg),
    }
}

/// What a non-regular file is, in words.
fn kind_of(ft: &std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt as _;
        if ft.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if ft.is_char_device() {
            return "a character device";
        }
        if ft.is_block_device() {
            return "a block device";
        }
        if ft.is_socket() {
            return "a socket";
        }
    }
    if ft.is_dir() {
        return "a directory";
    }
    "not a regular file"
}

fn human_bytes(n: u64) -> String {
    if n >= 1 << 30 && n.is_multiple_of(1 << 30) {
        format!("{} GiB", n >> 30)
    } else if n >= 1 << 20 && n.is_multiple_of(1 << 20) {
        format!("{} MiB", n >> 20)
    } else {
        format!("{n} bytes")
    }
}

/// Checks, without opening it, that `path` is a regular file (symbolic links followed) of at
/// most `cap` bytes; returns its size.
///
/// # Errors
/// [`Error::Io`] naming the file: missing or unreadable metadata, a FIFO, device, socket or
/// directory, or a file above `cap`.
pub fn check_input_file(path: &Path, cap: u64) -> Result<u64> {
    let meta = std::fs::metadata(path).map_err(|source| Error::Io {
        file: path.to_path_buf(),
        source,
    })?;
    let ft = meta.file_type();
    if !ft.is_file() {
        return Err(io_error(
            path,
            format!(
                "is {}, not a regular file: ferrosid reads inputs only from regular files \
                 (size known before reading); copy the data into a file first",
                kind_of(&ft)
            ),
        ));
    }
    if meta.len() > cap {
        return Err(io_error(
            path,
            format!(
                "is {} bytes, above the {} limit for this kind of input (docs/safety.md)",
                meta.len(),
                human_bytes(cap)
            ),
        ));
    }
    Ok(meta.len())
}

/// Reads a whole regular file of at most `cap` bytes ([`check_input_file`] first; the read
/// stops one byte past `cap` in case the file grows meanwhile).
///
/// # Errors
/// Those of [`check_input_file`]; [`Error::Io`] for a read error or a file that grew past `cap`.
pub fn read_bytes(path: &Path, cap: u64) -> Result<Vec<u8>> {
    let len = check_input_file(path, cap)?;
    let f = std::fs::File::open(path).map_err(|source| Error::Io {
        file: path.to_path_buf(),
        source,
    })?;
    let mut out = Vec::with_capacity(len as usize);
    f.take(cap + 1)
        .read_to_end(&mut out)
        .map_err(|source| Error::Io {
            file: path.to_path_buf(),
            source,
        })?;
    if out.len() as u64 > cap {
        return Err(io_error(
            path,
            format!(
                "grew above the {} limit for this kind of input while it was read",
                human_bytes(cap)
            ),
        ));
    }
    Ok(out)
}

/// The text encoding `bytes` evidently is when it is not UTF-8: a UTF-16/32 byte-order mark,
/// or UTF-16 without one (every second byte zero in the first line of ASCII text).
pub fn foreign_encoding(bytes: &[u8]) -> Option<&'static str> {
    if bytes.starts_with(&[0xFF, 0xFE, 0, 0]) || bytes.starts_with(&[0, 0, 0xFE, 0xFF]) {
        return Some("UTF-32");
    }
    if bytes.starts_with(&[0xFF, 0xFE]) || bytes.starts_with(&[0xFE, 0xFF]) {
        return Some("UTF-16");
    }
    let head = &bytes[..bytes.len().min(64)];
    if head.len() >= 4 {
        let zeros_even = head.iter().step_by(2).filter(|&&b| b == 0).count();
        let zeros_odd = head.iter().skip(1).step_by(2).filter(|&&b| b == 0).count();
        let half = head.len() / 2;
        if zeros_odd * 10 >= half * 9 || zeros_even * 10 >= half * 9 {
            return Some("UTF-16");
        }
    }
    None
}

/// Refuses text in another encoding than UTF-8 ([`foreign_encoding`]), naming the file.
///
/// # Errors
/// [`Error::Data`]: "file is UTF-16; save it as UTF-8".
pub fn check_utf8_family(path: &Path, bytes: &[u8]) -> Result<()> {
    match foreign_encoding(bytes) {
        Some(enc) => Err(Error::Data {
            file: path.to_path_buf(),
            msg: format!("file is {enc}; save it as UTF-8 (or plain ASCII) and try again"),
        }),
        None => Ok(()),
    }
}

/// `bytes` as UTF-8 text (a leading UTF-8 byte-order mark dropped).
///
/// # Errors
/// [`Error::Data`] for UTF-16/32 ([`check_utf8_family`]); [`Error::Parse`] with the line of
/// the first invalid UTF-8 byte.
pub fn decode_text(path: &Path, bytes: Vec<u8>) -> Result<String> {
    check_utf8_family(path, &bytes)?;
    let mut bytes = bytes;
    if bytes.starts_with(&[0xEF, 0xBB, 0xBF]) {
        bytes.drain(..3);
    }
    String::from_utf8(bytes).map_err(|e| {
        let valid = e.utf8_error().valid_up_to();
        let line = 1 + e.as_bytes()[..valid]
            .iter()
            .filter(|&&b| b == b'\n')
            .count();
        Error::Parse {
            file: path.to_path_buf(),
            line,
            msg: "invalid UTF-8; save the file as UTF-8".into(),
        }
    })
}

/// A text input of at most [`MAX_DOC_BYTES`] ([`read_bytes`] then [`decode_text`]).
///
/// # Errors
/// Those of [`read_bytes`] and [`decode_text`].
pub fn read_text(path: &Path) -> Result<String> {
    decode_text(path, read_bytes(path, MAX_DOC_BYTES)?)
}

/// A JSON input: [`read_text`], valid JSON, and no object repeating a key — the one rule of
/// every JSON reader of ferrosid.
///
/// # Errors
/// Those of [`read_text`]; [`Error::Parse`] with the line for malformed JSON or a repeated key.
pub fn read_json_text(path: &Path) -> Result<String> {
    let text = read_text(path)?;
    check_json(path, &text)?;
    Ok(text)
}

/// Checks that `text` is JSON without a repeated key in any object.
///
/// # Errors
/// [`Error::Parse`] naming `path` and the line.
pub fn check_json(path: &Path, text: &str) -> Result<()> {
    use serde::de::Deserializer as _;
    let mut de = serde_json::Deserializer::from_str(text);
    let r = (&mut de)
        .deserialize_any(NoDuplicates)
        .and_then(|()| de.end());
    r.map_err(|e| Error::Parse {
        file: path.to_path_buf(),
        line: e.line(),
        msg: format!("not valid JSON: {e}"),
    })
}

/// Walks a JSON value and fails on the first object with a repeated key.
struct NoDuplicates;

impl<'de> serde::de::DeserializeSeed<'de> for NoDuplicates {
    type Value = ();
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> std::result::Result<(), D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> serde::de::Visitor<'de> for NoDuplicates {
    type Value = ();

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a JSON value")
    }

    fn visit_bool<E: serde::de::Error>(self, _: bool) -> std::result::Result<(), E> {
        Ok(())
    }
    fn visit_i64<E: serde::de::Error>(self, _: i64) -> std::result::Result<(), E> {
        Ok(())
    }
    fn visit_u64<E: serde::de::Error>(self, _: u64) -> std::result::Result<(), E> {
        Ok(())
    }
    fn visit_f64<E: serde::de::Error>(self, _: f64) -> std::result::Result<(), E> {
        Ok(())
    }
    fn visit_str<E: serde::de::Error>(self, _: &str) -> std::result::Result<(), E> {
        Ok(())
    }
    fn visit_unit<E: serde::de::Error>(self) -> std::result::Result<(), E> {
        Ok(())
    }
    fn visit_none<E: serde::de::Error>(self) -> std::result::Result<(), E> {
        Ok(())
    }

    fn visit_seq<A: serde::de::SeqAccess<'de>>(
        self,
        mut seq: A,
    ) -> std::result::Result<(), A::Error> {
        while seq.next_element_seed(NoDuplicates)?.is_some() {}
        Ok(())
    }

    fn visit_map<A: serde::de::MapAccess<'de>>(
        self,
        mut map: A,
    ) -> std::result::Result<(), A::Error> {
        let mut seen = std::collections::BTreeSet::new();
        while let Some(key) = map.next_key::<String>()? {
            if !seen.insert(key.clone()) {
                return Err(serde::de::Error::custom(format!(
                    "duplicate key `{key}` in one object (a reader would silently keep only \
                     one of the values)"
                )));
            }
            map.next_value_seed(NoDuplicates)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encodings_are_recognised() {
        assert_eq!(foreign_encoding(&[0xFF, 0xFE, b't', 0]), Some("UTF-16"));
        assert_eq!(foreign_encoding(b"t\0,\0u\0,\0y\0\n\0"), Some("UTF-16"));
        assert_eq!(foreign_encoding(b"t,u,y\n0,1,2\n"), None);
        assert_eq!(foreign_encoding(&[0xFF, 0xFE, 0, 0]), Some("UTF-32"));
    }

    #[test]
    fn repeated_keys_are_refused_at_any_depth() {
        let p = Path::new("x.json");
        assert!(check_json(p, r#"{"a": 1, "b": [{"c": 1}]}"#).is_ok());
        let e = check_json(p, "{\"a\": 1,\n \"b\": {\"c\": 1, \"c\": 2}}").unwrap_err();
        assert!(e.to_string().contains("duplicate key `c`"), "{e}");
        assert!(e.to_string().contains("x.json:2"), "{e}");
        assert!(check_json(p, "{} x").is_err());
    }
}
