//! The project's real recordings for tests and examples: `testdata/` in the repository
//! (copies of third-party recordings, each folder with its licence and provenance in
//! `testdata/README.md`), or `$DEGS_SHARED_DATA` when set.

use std::path::PathBuf;

/// Environment variable that points at another copy of the test recordings.
pub(crate) const SHARED_DATA_ENV: &str = "DEGS_SHARED_DATA";

/// Path of `rel` inside the test recordings: `$DEGS_SHARED_DATA/rel` when that is set,
/// else `testdata/rel` in the workspace. Panics with the path it expected when the file
/// is missing: tests that need the real recordings cannot run without them.
pub fn shared_data(rel: &str) -> PathBuf {
    let root = std::env::var_os(SHARED_DATA_ENV)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../testdata")));
    let path = root.join(rel);
    if !path.exists() {
        panic!(
            "real recording {rel} not found at {}: the repository keeps them in testdata/ \
             (unset {SHARED_DATA_ENV}, or point it at a folder holding a copy)",
            path.display()
        );
    }
    path
}
