//! File safety: ferrosid never destroys a file it did not write.
//!
//! The rules (README "File safety"):
//! * **No output over an input.** An output path that resolves (after canonicalisation, so
//!   `./x.csv`, `dir/../x.csv` and symbolic links count) to one of the command's input files is
//!   refused before any work ([`refuse_input_overwrite`]).
//! * **Writable before computing.** Output paths are checked before the analysis starts
//!   ([`check_writable`]): the parent directory must exist (or be creatable) and accept a
//!   file, and the path must not be a directory.
//! * **Atomic replacement.** Every output is written to a temporary sibling
//!   (`.NAME.ferrosid-tmp-PID`) and renamed into place ([`write_atomic`]), so a crash or a full
//!   disk never leaves a half-written file where a good one was.
//! * **Output directories** ([`OutputDir`], used by `run` and `fleet`): a lock file
//!   [`LOCK_FILE`] holds the writer's process id while it writes (a second run into the same
//!   directory is refused with the holder named; a lock whose process is gone is taken over);
//!   a manifest [`MANIFEST_FILE`] lists every file ferrosid wrote there. ferrosid only replaces
//!   or deletes files listed in the manifest: a file of the same name that it did not write is
//!   an error naming the file, and nothing is deleted that is not in the manifest.
use crate::error::{Error, Result};
use std::collections::BTreeMap;
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// Lock file in an output directory while a run writes into it.
pub const LOCK_FILE: &str = ".ferrosid.lock";
/// Manifest of the files ferrosid wrote in an output directory (one relative path a line).
pub const MANIFEST_FILE: &str = ".ferrosid-manifest";
/// Present in an output directory only while [`OutputDir::write_all`] renames a finished run's
/// files into place: found afterwards, it means that run was killed in between and the folder
/// mixes two runs.
pub const INCOMPLETE_FILE: &str = ".ferrosid-incomplete";

fn temp_sibling(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    path.with_file_name(format!(".{name}.ferrosid-tmp-{}", std::process::id()))
}

fn io_err(file: &Path) -> impl FnOnce(std::io::Error) -> Error + '_ {
    move |source| Error::Io {
        file: file.to_path_buf(),
        source,
    }
}

/// The absolute, symlink-resolved form of `p`; for a path that does not exist yet, its
/// canonical parent joined with the file name (so two spellings of one new file compare equal).
pub fn canonical_or_parent(p: &Path) -> PathBuf {
    if let Ok(c) = std::fs::canonicalize(p) {
        return c;
    }
    let parent = match p.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    match (std::fs::canonicalize(&parent), p.file_name()) {
        (Ok(d), Some(name)) => d.join(name),
        _ => p.to_path_buf(),
    }
}

/// Refuses `out` (given with option `flag`, e.g. `--out`) when it is the same file as any of
/// `inputs` (canonicalised paths compared).
///
/// # Errors
/// [`Error::InvalidArgument`] naming both the option and the input.
pub fn refuse_input_overwrite(out: &Path, flag: &str, inputs: &[&Path]) -> Result<()> {
    let o = canonical_or_parent(out);
    for i in inputs {
        if canonical_or_parent(i) == o {
            return Err(Error::InvalidArgument(format!(
                "{flag} {} is the input file {}: refusing to overwrite an input; choose another \
                 output path",
                out.display(),
                i.display()
            )));
        }
    }
    Ok(())
}

/// Checks, before any work, that a file can be written at `path`: not a directory, parent
/// directory existing (created when missing) and accepting a new file (a probe file is
/// created and removed).
///
/// # Errors
/// [`Error::Io`] naming the path or its directory.
pub fn check_writable(path: &Path) -> Result<()> {
    if path.is_dir() {
        return Err(Error::Io {
            file: path.to_path_buf(),
            source: std::io::Error::other("is a directory, expected a file path"),
        });
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    check_dir_writable(&dir)
}

/// Creates `dir` if missing and checks that it accepts a new file (probe created and removed).
///
/// # Errors
/// [`Error::Io`] naming the directory.
pub fn check_dir_writable(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(io_err(dir))?;
    let probe = dir.join(format!(".ferrosid-probe-{}", std::process::id()));
    std::fs::File::create(&probe).map_err(io_err(dir))?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

/// How ferrosid recognises a file it wrote itself at an output path, by content (never by
/// name): only such a file is replaced without `--force` ([`check_output_file`]).
#[derive(Debug, Clone, Copy)]
pub enum Own {
    /// Text carrying this marker in its first [`MARKER_WINDOW`] bytes (generated C/Rust
    /// sources: "Generated by ferrosid"; SVG figures: [`SVG_MARKER`]).
    Marker(&'static str),
    /// Content a function of the caller recognises (e.g. `cli::own_model_file`: a model
    /// file exactly as ferrosid prints one, for `identify --out` and `reidentify --out`).
    Content(fn(&[u8]) -> bool),
    /// A JSON object holding all of these top-level keys (`identify --params-out`).
    JsonKeys(&'static [&'static str]),
}

/// Bytes at the start of a file searched for an [`Own::Marker`].
pub const MARKER_WINDOW: usize = 4096;
/// The comment ferrosid puts at the top of every SVG figure it writes outside a manifest
/// directory (`gap --figures`).
pub const SVG_MARKER: &str = "<!-- written by ferrosid -->";

/// `svg` with [`SVG_MARKER`] as the first node inside its `<svg …>` element (the file still
/// starts with `<svg`), so the figure is recognised as ferrosid's when it is written again.
pub fn mark_svg(svg: &str) -> String {
    if svg.contains(SVG_MARKER) {
        return svg.to_string();
    }
    let at = svg
        .find("<svg")
        .and_then(|i| svg[i..].find('>').map(|j| i + j + 1))
        .unwrap_or(0);
    let (head, tail) = svg.split_at(at);
    format!("{head}\n{SVG_MARKER}{tail}")
}

impl Own {
    /// True when `bytes` is a file ferrosid wrote (see the variants).
    pub fn recognises(self, bytes: &[u8]) -> bool {
        match self {
            Own::Marker(m) => {
                let head = &bytes[..bytes.len().min(MARKER_WINDOW)];
                head.windows(m.len()).any(|w| w == m.as_bytes())
            }
            Own::Content(f) => f(bytes),
            Own::JsonKeys(keys) => match serde_json::from_slice::<serde_json::Value>(bytes) {
                Ok(serde_json::Value::Object(m)) => keys.iter().all(|k| m.contains_key(*k)),
                _ => false,
            },
        }
    }
}

/// Checks, before any work, that an output may be written at `path` (given with `flag`):
/// [`check_writable`]; an existing character device (`/dev/null`) is accepted and later written
/// in place; a FIFO, socket or block device is refused; an existing regular file (symbolic
/// links followed) must be one ferrosid wrote ([`Own`]) unless `force`.
///
/// # Errors
/// [`Error::Io`] naming the path and what to do.
pub fn check_output_file(path: &Path, flag: &str, own: Own, force: bool) -> Result<()> {
    check_writable(path)?;
    let Ok(meta) = std::fs::metadata(path) else {
        return Ok(());
    };
    if !meta.is_file() {
        return if is_char_device(&meta) {
            Ok(())
        } else {
            Err(Error::Io {
                file: path.to_path_buf(),
                source: std::io::Error::other(format!(
                    "{flag} names a FIFO, socket or block device: refusing to write to it; \
                     give a regular file path"
                )),
            })
        };
    }
    if force {
        return Ok(());
    }
    let cap = MARKER_WINDOW.max(64 << 20) as u64;
    let bytes = crate::io::input::read_bytes(path, cap).unwrap_or_default();
    if own.recognises(&bytes) {
        return Ok(());
    }
    Err(Error::Io {
        file: path.to_path_buf(),
        source: std::io::Error::other(format!(
            "{flag}: the file exists and was not written by ferrosid: refusing to replace it; \
             choose another path, move the file, or pass --force to replace it"
        )),
    })
}

fn is_char_device(meta: &std::fs::Metadata) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt as _;
        meta.file_type().is_char_device()
    }
    #[cfg(not(unix))]
    {
        let _ = meta;
        false
    }
}

/// Writes `bytes` to `path` atomically: to a temporary sibling first, then renamed over
/// `path` (the temporary file is removed when anything fails). Never renames over a file that
/// is not a regular file: a character device (`/dev/null`, `/dev/full`) at `path` (symbolic
/// links followed) is written in place, any other non-regular file is refused.
///
/// # Errors
/// [`Error::Io`] naming `path` (for a device, its write error: `/dev/full` gives "No space
/// left on device").
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    if let Ok(meta) = std::fs::metadata(path) {
        if is_char_device(&meta) {
            let r = std::fs::OpenOptions::new()
                .write(true)
                .open(path)
                .and_then(|mut f| f.write_all(bytes).and_then(|()| f.flush()));
            return r.map_err(io_err(path));
        }
        if !meta.is_file() {
            return Err(Error::Io {
                file: path.to_path_buf(),
                source: std::io::Error::other(
                    "not a regular file (a FIFO, socket, block device or directory): refusing \
                     to write to it or replace it",
                ),
            });
        }
    }
    let tmp = temp_sibling(path);
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        std::fs::rename(&tmp, path)
    })();
    if let Err(source) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(Error::Io {
            file: path.to_path_buf(),
            source,
        });
    }
    Ok(())
}

/// An output directory held for writing: lock file, manifest of what ferrosid wrote there,
/// atomic writes (see the module docs). The lock is released when the value is dropped.
#[derive(Debug)]
pub struct OutputDir {
    dir: PathBuf,
    lock: PathBuf,
    /// Files listed in the manifest before this run (relative paths with `/`) and the
    /// SHA-256 each had when ferrosid wrote it (`None` for a line of an older manifest
    /// without digests: such a file is neither replaced nor deleted).
    previous: BTreeMap<String, Option<String>>,
    /// Files written by this run, with their SHA-256.
    written: BTreeMap<String, String>,
}

/// SHA-256 of `bytes`, lower-case hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest as _;
    let d = sha2::Sha256::digest(bytes);
    let mut s = String::with_capacity(64);
    for b in d {
        s.push_str(&format!("{b:02x}"));
    }
    s
}

/// A manifest entry's relative path when it stays inside the directory: no absolute path,
/// no `..`, no empty name. Others are dropped when the manifest is read.
fn inside(rel: &str) -> bool {
    let p = Path::new(rel);
    !rel.is_empty()
        && !rel.contains('\\')
        && p.components()
            .all(|c| matches!(c, std::path::Component::Normal(_)))
}

/// Parses a manifest: `<sha256 hex>  <relative path>` a line (the `sha256sum` format), or a
/// bare relative path (older manifests). Entries pointing outside the directory are dropped.
fn parse_manifest(text: &str) -> BTreeMap<String, Option<String>> {
    let mut out = BTreeMap::new();
    for line in text.lines() {
        let line = line.trim_end();
        if line.trim().is_empty() {
            continue;
        }
        let (digest, rel) = match line.split_once("  ") {
            Some((h, r)) if h.len() == 64 && h.bytes().all(|b| b.is_ascii_hexdigit()) => {
                (Some(h.to_ascii_lowercase()), r)
            }
            _ => (None, line.trim()),
        };
        if inside(rel) {
            out.insert(rel.to_string(), digest);
        }
    }
    out
}

fn process_alive(pid: u32) -> Option<bool> {
    let proc_dir = Path::new("/proc");
    if proc_dir.join("self").exists() {
        Some(proc_dir.join(pid.to_string()).exists())
    } else {
        None
    }
}

fn rel_key(rel: &Path) -> String {
    rel.to_string_lossy().replace('\\', "/")
}

impl OutputDir {
    /// Creates `dir` when missing and takes its lock.
    ///
    /// # Errors
    /// [`Error::Io`] when the directory cannot be created or written, or when another running
    /// ferrosid holds the lock (the message names the lock file and its process id).
    pub fn acquire(dir: &Path) -> Result<Self> {
        check_dir_writable(dir)?;
        let lock = dir.join(LOCK_FILE);
        for attempt in 0..2 {
            match std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&lock)
            {
                Ok(mut f) => {
                    let _ = writeln!(f, "{}", std::process::id());
                    break;
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && attempt == 0 => {
                    // Bounded and regular files only: a FIFO planted as the lock never blocks.
                    let holder = crate::io::input::read_text(&lock)
                        .ok()
                        .and_then(|s| s.trim().parse::<u32>().ok());
                    let stale = matches!(holder.map(process_alive), Some(Some(false)));
                    if stale {
                        let _ = std::fs::remove_file(&lock);
                        continue;
                    }
                    return Err(Error::Io {
                        file: lock.clone(),
                        source: std::io::Error::other(format!(
                            "another ferrosid ({}) is writing into {}; wait for it, or delete \
                             the lock file if no ferrosid is running",
                            match holder {
                                Some(p) => format!("process {p}"),
                                None => "unknown process".into(),
                            },
                            dir.display()
                        )),
                    });
                }
                Err(source) => {
                    return Err(Error::Io { file: lock, source });
                }
            }
        }
        let previous = crate::io::input::read_text(&dir.join(MANIFEST_FILE))
            .map(|t| parse_manifest(&t))
            .unwrap_or_default();
        Ok(Self {
            dir: dir.to_path_buf(),
            lock,
            previous,
            written: BTreeMap::new(),
        })
    }

    /// The directory.
    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// True when the file at `rel` is, byte for byte, what ferrosid wrote there (its digest
    /// matches the manifest's).
    fn still_ours(&self, rel: &str) -> bool {
        let digest = match (self.written.get(rel), self.previous.get(rel)) {
            (Some(d), _) | (None, Some(Some(d))) => d,
            _ => return false,
        };
        let p = self.dir.join(rel);
        match std::fs::symlink_metadata(&p) {
            Ok(m) if m.is_file() => {}
            _ => return false,
        }
        crate::io::input::read_bytes(&p, crate::io::input::MAX_LOG_BYTES)
            .is_ok_and(|b| sha256_hex(&b) == *digest)
    }

    /// Checks, before computing, that each of `rels` (relative paths) may be written: it does
    /// not exist, or ferrosid wrote it and it has not changed since (its SHA-256 matches the
    /// manifest's).
    ///
    /// # Errors
    /// [`Error::Io`] naming the first file that exists and is not ferrosid's unchanged output.
    pub fn check_replaceable<'a>(&self, rels: impl IntoIterator<Item = &'a Path>) -> Result<()> {
        for rel in rels {
            let p = self.dir.join(rel);
            let key = rel_key(rel);
            if std::fs::symlink_metadata(&p).is_ok() && !self.still_ours(&key) {
                let why = match self.previous.get(&key) {
                    None => format!("was not written by ferrosid (not listed in {MANIFEST_FILE})"),
                    Some(None) => format!(
                        "is listed in {MANIFEST_FILE} without a digest (older ferrosid), so it \
                         cannot be told from a file of yours"
                    ),
                    Some(Some(_)) => format!(
                        "changed since ferrosid wrote it (its SHA-256 differs from {MANIFEST_FILE})"
                    ),
                };
                return Err(Error::Io {
                    file: p,
                    source: std::io::Error::other(format!(
                        "exists and {why}: refusing to replace it; move it or choose another \
                         output directory"
                    )),
                });
            }
        }
        Ok(())
    }

    /// Writes `text` to `rel` inside the directory (atomically, creating parent
    /// directories), after checking it may be replaced; records it and its digest in the
    /// manifest.
    ///
    /// # Errors
    /// [`Error::Io`] naming the file.
    pub fn write(&mut self, rel: &Path, text: &str) -> Result<PathBuf> {
        self.check_replaceable([rel])?;
        let p = self.dir.join(rel);
        if let Some(parent) = p.parent() {
            std::fs::create_dir_all(parent).map_err(io_err(parent))?;
        }
        write_atomic(&p, text.as_bytes())?;
        self.written
            .insert(rel_key(rel), sha256_hex(text.as_bytes()));
        self.save_manifest()?;
        Ok(p)
    }

    /// Deletes `rel` when ferrosid wrote it in an earlier run, this run did not, and it is
    /// unchanged since (digest in the manifest); anything else is left alone. An entry whose
    /// file is gone or changed is dropped from the manifest.
    ///
    /// # Errors
    /// [`Error::Io`] when an existing listed file cannot be removed.
    pub fn remove_stale(&mut self, rel: &Path) -> Result<()> {
        let key = rel_key(rel);
        if !self.previous.contains_key(&key) || self.written.contains_key(&key) {
            return Ok(());
        }
        if self.still_ours(&key) {
            let p = self.dir.join(rel);
            match std::fs::remove_file(&p) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(source) => return Err(Error::Io { file: p, source }),
            }
        }
        self.previous.remove(&key);
        self.save_manifest()
    }

    /// Writes a whole set of files as one step: every file is first written (and synced) to a
    /// temporary sibling; only when all of them are on disk are they renamed into place, then
    /// `stale` files are removed ([`Self::remove_stale`]) and the manifest is saved. A full
    /// disk or any write error leaves every previous file untouched (the temporaries are
    /// removed); a kill can only fall between renames, a window of microseconds, and
    /// [`INCOMPLETE_FILE`] then stays behind to say so (the next run warns and replaces it).
    ///
    /// # Errors
    /// [`Error::Io`] naming the file that could not be written, replaced or removed.
    pub fn write_all(
        &mut self,
        files: &[(PathBuf, String)],
        stale: &[PathBuf],
    ) -> Result<Vec<PathBuf>> {
        self.check_replaceable(files.iter().map(|(r, _)| r.as_path()))?;
        let mut temps: Vec<(PathBuf, PathBuf)> = Vec::with_capacity(files.len());
        let staged = (|| -> Result<()> {
            for (rel, text) in files {
                let p = self.dir.join(rel);
                if let Some(parent) = p.parent() {
                    std::fs::create_dir_all(parent).map_err(io_err(parent))?;
                }
                let tmp = temp_sibling(&p);
                temps.push((tmp.clone(), p.clone()));
                (|| {
                    let mut f = std::fs::File::create(&tmp)?;
                    f.write_all(text.as_bytes())?;
                    f.sync_all()
                })()
                .map_err(io_err(&p))?;
            }
            Ok(())
        })();
        let cleanup = |temps: &[(PathBuf, PathBuf)]| {
            for (t, _) in temps {
                let _ = std::fs::remove_file(t);
            }
        };
        if let Err(e) = staged {
            cleanup(&temps);
            return Err(e);
        }
        let marker = self.dir.join(INCOMPLETE_FILE);
        let _ = std::fs::write(&marker, format!("{}\n", std::process::id()));
        for (i, (tmp, p)) in temps.iter().enumerate() {
            if let Err(source) = std::fs::rename(tmp, p) {
                cleanup(&temps[i..]);
                return Err(Error::Io {
                    file: p.clone(),
                    source,
                });
            }
        }
        for (rel, text) in files {
            self.written
                .insert(rel_key(rel), sha256_hex(text.as_bytes()));
        }
        for rel in stale {
            self.remove_stale(rel)?;
        }
        self.save_manifest()?;
        let _ = std::fs::remove_file(&marker);
        Ok(temps.into_iter().map(|(_, p)| p).collect())
    }

    fn save_manifest(&self) -> Result<()> {
        let mut all: BTreeMap<&String, Option<&String>> =
            self.previous.iter().map(|(k, d)| (k, d.as_ref())).collect();
        for (k, d) in &self.written {
            all.insert(k, Some(d));
        }
        let mut text = String::new();
        for (k, d) in all {
            if let Some(d) = d {
                text.push_str(d);
                text.push_str("  ");
            }
            text.push_str(k);
            text.push('\n');
        }
        write_atomic(&self.dir.join(MANIFEST_FILE), text.as_bytes())
    }
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.lock);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("ferrosid-fs-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn output_dir_replaces_only_its_own_files_and_locks() {
        let d = scratch("outdir");
        std::fs::write(d.join("mine.txt"), "user data").unwrap();
        {
            let mut o = OutputDir::acquire(&d).unwrap();
            assert!(
                OutputDir::acquire(&d).is_err(),
                "second writer must be refused"
            );
            assert!(o.write(Path::new("mine.txt"), "x").is_err());
            o.write(Path::new("a/b.txt"), "1").unwrap();
        }
        assert_eq!(
            std::fs::read_to_string(d.join("mine.txt")).unwrap(),
            "user data"
        );
        let mut o = OutputDir::acquire(&d).unwrap();
        o.write(Path::new("a/b.txt"), "2").unwrap();
        o.remove_stale(Path::new("mine.txt")).unwrap();
        assert!(d.join("mine.txt").exists());
        drop(o);
        let mut o = OutputDir::acquire(&d).unwrap();
        o.remove_stale(Path::new("a/b.txt")).unwrap();
        assert!(!d.join("a/b.txt").exists());
        assert!(!d.join(LOCK_FILE).exists() || OutputDir::acquire(&d).is_err());
    }

    #[test]
    fn stale_lock_of_a_dead_process_is_taken_over() {
        let d = scratch("stale");
        // Process ids above /proc/sys/kernel/pid_max (at most 2^22) never exist.
        std::fs::write(d.join(LOCK_FILE), "4294967295\n").unwrap();
        if process_alive(1).is_some() {
            assert!(OutputDir::acquire(&d).is_ok());
        }
    }
}
