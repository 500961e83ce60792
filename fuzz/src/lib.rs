//! Helpers shared by the fuzz targets: the path-based readers get the fuzz input through a
//! scratch file (one per process and extension).
use std::path::PathBuf;

/// Writes `data` to a per-process scratch file with extension `ext` and returns its path.
pub fn scratch_file(ext: &str, data: &[u8]) -> PathBuf {
    let dir = std::env::temp_dir().join("ferrosid-fuzz");
    let _ = std::fs::create_dir_all(&dir);
    let p = dir.join(format!("input-{}.{ext}", std::process::id()));
    std::fs::write(&p, data).expect("scratch file");
    p
}
