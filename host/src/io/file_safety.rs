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
use std::collections::BTreeSet;
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// Lock file in an output directory while a run writes into it.
pub const LOCK_FILE: &str = ".ferrosid.lock";
/// Manifest of the files ferrosid wrote in an output directory (one relative path a line).
pub const MANIFEST_FILE: &str = ".ferrosid-manifest";

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

/// Writes `bytes` to `path` atomically: to a temporary sibling first, then renamed over
/// `path` (the temporary file is removed when anything fails).
///
/// # Errors
/// [`Error::Io`] naming `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    let tmp = path.with_file_name(format!(".{name}.ferrosid-tmp-{}", std::process::id()));
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
    /// Files listed in the manifest before this run (relative paths with `/`).
    previous: BTreeSet<String>,
    /// Files written by this run.
    written: BTreeSet<String>,
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
                    let holder = std::fs::read_to_string(&lock)
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
        let previous = std::fs::read_to_string(dir.join(MANIFEST_FILE))
            .map(|s| {
                s.lines()
                    .map(str::trim)
                    .filter(|l| !l.is_empty())
                    .map(str::to_string)
                    .collect()
            })
            .unwrap_or_default();
        Ok(Self {
            dir: dir.to_path_buf(),
            lock,
            previous,
            written: BTreeSet::new(),
        })
    }

    /// The directory.
    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// Checks, before computing, that each of `rels` (relative paths) may be written: it does
    /// not exist, or ferrosid wrote it (it is in the manifest).
    ///
    /// # Errors
    /// [`Error::Io`] naming the first file that exists and was not written by ferrosid.
    pub fn check_replaceable<'a>(&self, rels: impl IntoIterator<Item = &'a Path>) -> Result<()> {
        for rel in rels {
            let p = self.dir.join(rel);
            if p.exists() && !self.previous.contains(&rel_key(rel)) {
                return Err(Error::Io {
                    file: p,
                    source: std::io::Error::other(format!(
                        "exists and was not written by ferrosid (not listed in {}): refusing \
                         to replace it; move it or choose another output directory",
                        MANIFEST_FILE
                    )),
                });
            }
        }
        Ok(())
    }

    /// Writes `text` to `rel` inside the directory (atomically, creating parent
    /// directories), after checking it may be replaced; records it in the manifest.
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
        self.written.insert(rel_key(rel));
        self.save_manifest()?;
        Ok(p)
    }

    /// Deletes `rel` when ferrosid wrote it in an earlier run (listed in the manifest) and
    /// this run did not; anything else is left alone.
    ///
    /// # Errors
    /// [`Error::Io`] when an existing listed file cannot be removed.
    pub fn remove_stale(&mut self, rel: &Path) -> Result<()> {
        let key = rel_key(rel);
        if !self.previous.contains(&key) || self.written.contains(&key) {
            return Ok(());
        }
        let p = self.dir.join(rel);
        match std::fs::remove_file(&p) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(source) => return Err(Error::Io { file: p, source }),
        }
        self.previous.remove(&key);
        self.save_manifest()
    }

    fn save_manifest(&self) -> Result<()> {
        let all: BTreeSet<&String> = self.previous.iter().chain(&self.written).collect();
        let mut text = String::new();
        for k in all {
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
