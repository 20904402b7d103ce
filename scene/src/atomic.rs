//! Atomic outputs (DESIGN §3): a file or directory appears complete or not at all.
//!
//! Files are written to `name.tmp-<pid>` next to the target, fsynced, then renamed.
//! Stage output directories are built under `name.tmp-<pid>` and renamed at the end.
//! A writer that fails (or a process that is killed) leaves only the temp name, which
//! [`remove_stale_temps`] cleans up.

use crate::error::{Error, IoContext, Result};
use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// `path` with `.tmp-<pid>` appended to its file name.
pub fn temp_path(path: &Path) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(format!(".tmp-{}", std::process::id()));
    path.with_file_name(name)
}

/// Write `path` atomically with the bytes `write` produces. On error the temp file is
/// removed and `path` is left as it was.
pub fn write_atomic<F>(path: &Path, write: F) -> Result<()>
where
    F: FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
{
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        fs::create_dir_all(dir).at(dir)?;
    }
    let tmp = temp_path(path);
    let result = (|| -> std::io::Result<()> {
        let file = File::create(&tmp)?;
        let mut w = BufWriter::with_capacity(1 << 20, file);
        write(&mut w)?;
        let file = w.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = fs::remove_file(&tmp);
        return Err(Error::io(path, e));
    }
    Ok(())
}

/// Write a whole byte buffer atomically.
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |w| w.write_all(bytes))
}

/// Serialise `value` as pretty JSON, atomically.
pub fn write_json_atomic<T: serde::Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| Error::invalid(path, format!("cannot serialise JSON: {e}")))?;
    write_bytes_atomic(path, text.as_bytes())
}

/// A directory under construction: everything goes into a temp directory that
/// [`AtomicDir::commit`] renames to the final name. Dropping it uncommitted removes it.
pub struct AtomicDir {
    tmp: PathBuf,
    target: PathBuf,
    committed: bool,
}

impl AtomicDir {
    /// Start building `target` (which must not exist yet unless `replace` is set when
    /// committing). Stale temp dirs of dead processes are removed first.
    pub fn new(target: &Path) -> Result<Self> {
        if let Some(parent) = target.parent().filter(|d| !d.as_os_str().is_empty()) {
            fs::create_dir_all(parent).at(parent)?;
            remove_stale_temps(parent)?;
        }
        let tmp = temp_path(target);
        if tmp.exists() {
            fs::remove_dir_all(&tmp).at(&tmp)?;
        }
        fs::create_dir_all(&tmp).at(&tmp)?;
        Ok(AtomicDir {
            tmp,
            target: target.to_path_buf(),
            committed: false,
        })
    }

    /// Where to write the files of the directory under construction.
    pub fn path(&self) -> &Path {
        &self.tmp
    }

    /// Rename the temp directory to the target. An existing target is replaced.
    pub fn commit(mut self) -> Result<PathBuf> {
        if self.target.exists() {
            fs::remove_dir_all(&self.target).at(&self.target)?;
        }
        fs::rename(&self.tmp, &self.target).at(&self.target)?;
        self.committed = true;
        Ok(self.target.clone())
    }
}

impl Drop for AtomicDir {
    fn drop(&mut self) {
        if !self.committed {
            let _ = fs::remove_dir_all(&self.tmp);
        }
    }
}

/// Remove `*.tmp-<pid>` entries in `dir` whose process no longer runs.
pub fn remove_stale_temps(dir: &Path) -> Result<()> {
    let Ok(entries) = fs::read_dir(dir) else {
        return Ok(());
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        let Some(pos) = name.rfind(".tmp-") else {
            continue;
        };
        let Ok(pid) = name[pos + 5..].parse::<u32>() else {
            continue;
        };
        if pid != std::process::id() && !process_alive(pid) {
            let p = entry.path();
            let _ = if p.is_dir() {
                fs::remove_dir_all(&p)
            } else {
                fs::remove_file(&p)
            };
        }
    }
    Ok(())
}

/// Whether `pid` runs. A zombie (killed, its parent gone too, and not reaped: in a
/// container whose init does not reap) is dead: its temp files are stale.
fn process_alive(pid: u32) -> bool {
    let Ok(stat) = fs::read_to_string(format!("/proc/{pid}/stat")) else {
        return Path::new(&format!("/proc/{pid}")).exists();
    };
    // `pid (comm) S …`: the state follows the last `)`.
    let state = stat
        .rfind(')')
        .and_then(|i| stat[i + 1..].trim_start().chars().next());
    !matches!(state, Some('Z' | 'X'))
}
