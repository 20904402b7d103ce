//! Where things are: the cache root, the stage binaries and the running `degs`.

use crate::cache::Cache;
use anyhow::Result;
use std::path::{Path, PathBuf};

/// Where to find things.
#[derive(Clone, Debug)]
pub struct Context {
    pub cache: Cache,
    /// Look for stage binaries only here (tests, custom builds).
    pub stage_dir: Option<PathBuf>,
    /// The `degs` executable (stage binaries are looked for beside it).
    pub degs: PathBuf,
}

impl Context {
    pub fn new(cache: Cache, stage_dir: Option<PathBuf>) -> Result<Context> {
        let degs = std::env::current_exe()?;
        Ok(Context {
            cache,
            stage_dir,
            degs,
        })
    }

    /// The executable `binary` of a stage (see [`find_stage_binary`]).
    pub fn stage_binary(&self, binary: &str) -> Option<PathBuf> {
        find_stage_binary(binary, self.stage_dir.as_deref(), &self.degs)
    }
}

/// The executable `binary`: in `stage_dir` when given (only there), else next to the
/// running `degs`, else on `PATH`.
pub(crate) fn find_stage_binary(
    binary: &str,
    stage_dir: Option<&Path>,
    degs: &Path,
) -> Option<PathBuf> {
    let is_exe = |p: &Path| {
        use std::os::unix::fs::PermissionsExt;
        p.metadata()
            .map(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
            .unwrap_or(false)
    };
    if let Some(d) = stage_dir {
        let p = d.join(binary);
        return is_exe(&p).then_some(p);
    }
    let beside = degs.parent().map(|d| d.join(binary));
    if let Some(p) = beside.filter(|p| is_exe(p)) {
        return Some(p);
    }
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|d| d.join(binary))
        .find(|p| is_exe(p))
}
