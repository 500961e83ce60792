//! The real-data sets that live outside the repository (`../shared/data`, see its README.md):
//! the tests that use them read them in place and skip with a notice when they are absent.
use std::path::{Path, PathBuf};

/// `shared/data/<rel>` in the nearest ancestor of the crate directory that has it (the project
/// checkout's `../shared/data`, also from a git worktree elsewhere); `None`, with a notice
/// that `test` is skipped, when no ancestor has it.
pub fn shared_data(rel: &str, test: &str) -> Option<PathBuf> {
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    for dir in here.ancestors() {
        let p = dir.join("shared/data").join(rel);
        if p.exists() {
            return Some(p);
        }
    }
    println!(
        "notice: shared/data/{rel} not found above {}; skipping {test} (see \
         ../shared/data/README.md)",
        here.display()
    );
    None
}
