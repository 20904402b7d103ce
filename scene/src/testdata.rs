//! The project's real recordings for tests and examples: the `shared/data/` folder
//! beside the checkout (or `$DEGS_SHARED_DATA`).

use std::path::PathBuf;

/// Environment variable that points at the shared data folder when it is elsewhere.
pub const SHARED_DATA_ENV: &str = "DEGS_SHARED_DATA";

/// Path of `rel` inside the shared data folder: `$DEGS_SHARED_DATA/rel` when that is set,
/// else `../shared/data/rel` from the workspace root. Panics with the path it expected
/// and how to fix it when the file is missing: tests that need the real recordings
/// cannot run without them.
pub fn shared_data(rel: &str) -> PathBuf {
    let root = std::env::var_os(SHARED_DATA_ENV)
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data"))
        });
    let path = root.join(rel);
    if !path.exists() {
        panic!(
            "real recording {rel} not found at {}: these tests need the shared data folder \
             (shared/data/ beside the checkout, as CI has it), or {SHARED_DATA_ENV}=DIR \
             pointing at a copy",
            path.display()
        );
    }
    path
}
