//! Atomic outputs (DESIGN §3): a file or directory appears complete or not at all.
//!
//! Files are written to `name.degs-tmp-<pid>.<n>` (a count per process) next to the target, fsynced, then renamed.
//! Output directories are built under `name.degs-tmp-<pid>` and renamed at the end; an
//! [`OutputRule`] says what an existing one may be (never an input, nor a user's folder).
//! A writer that fails (or a process that is killed) leaves only the temp name, which
//! [`remove_stale_temps`] cleans up.

use crate::error::{Error, IoContext, Result};
use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// The suffix of every temp name degs writes, before the writer's pid.
pub const TEMP_SUFFIX: &str = ".degs-tmp-";

/// The manifest the runner writes into each cache entry it seals (a copy of an entry,
/// e.g. a transformed scene, leaves it out).
pub const ENTRY_MANIFEST: &str = ".degs-entry.json";

/// `path` with `.degs-tmp-<pid>` appended to its file name.
pub fn temp_path(path: &Path) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(format!("{TEMP_SUFFIX}{}", std::process::id()));
    path.with_file_name(name)
}

/// `path` with `.degs-tmp-<pid>.<n>` appended to its file name: `n` counts the temp
/// files this process made, so that two threads writing the same file (experiments of
/// a sweep run at once saving one record) never share a temp file.
fn unique_temp_path(path: &Path) -> PathBuf {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(format!("{TEMP_SUFFIX}{}.{n}", std::process::id()));
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
    let tmp = unique_temp_path(path);
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
///
/// What an existing target may be is the [`OutputRule`]'s to say: nothing that holds a
/// source, nothing that is not an earlier output of the same command, and an earlier
/// output only when forced (DESIGN §3, "Outputs never destroy inputs").
#[derive(Debug)]
pub struct AtomicDir {
    tmp: PathBuf,
    target: PathBuf,
    rule: OutputRule,
    committed: bool,
}

impl AtomicDir {
    /// Start building `target` under the rule's checks (made again at commit). Stale
    /// temp dirs of dead processes beside it are removed first.
    pub fn new(target: &Path, rule: &OutputRule) -> Result<Self> {
        rule.check(target)?;
        if let Some(parent) = target.parent().filter(|d| !d.as_os_str().is_empty()) {
            fs::create_dir_all(parent).at(parent)?;
            remove_stale_temps(parent)?;
        }
        let tmp = temp_path(target);
        if tmp.exists() {
            // Only a temp dir this process left (same pid) can be here: one we marked.
            if !is_output_of(&tmp, &rule.command) {
                return Err(Error::invalid(
                    &tmp,
                    "exists and is not a temp folder of degs; move it away",
                ));
            }
            fs::remove_dir_all(&tmp).at(&tmp)?;
        }
        fs::create_dir_all(&tmp).at(&tmp)?;
        fs::write(tmp.join(OUTPUT_MARKER), format!("{}\n", rule.command))
            .at(tmp.join(OUTPUT_MARKER))?;
        Ok(AtomicDir {
            tmp,
            target: target.to_path_buf(),
            rule: rule.clone(),
            committed: false,
        })
    }

    /// Where to write the files of the directory under construction.
    pub fn path(&self) -> &Path {
        &self.tmp
    }

    /// Rename the temp directory to the target. An earlier output there (allowed by the
    /// rule, checked again now) is moved aside first and removed after.
    pub fn commit(mut self) -> Result<PathBuf> {
        self.rule.check(&self.target)?;
        if self.target.exists() {
            let mut old = self.target.as_os_str().to_os_string();
            old.push(".old");
            let old = temp_path(Path::new(&old));
            fs::rename(&self.target, &old).at(&self.target)?;
            if let Err(e) = fs::rename(&self.tmp, &self.target) {
                // Put the earlier output back: nothing is lost when the swap fails.
                let _ = fs::rename(&old, &self.target);
                return Err(Error::io(&self.target, e));
            }
            fs::remove_dir_all(&old).at(&old)?;
        } else {
            fs::rename(&self.tmp, &self.target).at(&self.target)?;
        }
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

/// The file every output directory of degs holds: the command that wrote it.
pub const OUTPUT_MARKER: &str = ".degs-output";

/// Whether `dir` is an output of `command` (its marker names it).
pub(crate) fn is_output_of(dir: &Path, command: &str) -> bool {
    fs::read_to_string(dir.join(OUTPUT_MARKER)).is_ok_and(|s| s.trim() == command)
}

/// What an output directory may replace: the command writing it (recorded in the
/// output's [`OUTPUT_MARKER`]), whether an earlier output of it may be replaced
/// (`--force`), and the inputs it must never hold.
#[derive(Clone, Debug)]
pub struct OutputRule {
    command: String,
    force: bool,
    sources: Vec<PathBuf>,
}

impl OutputRule {
    /// The rule for `command` (e.g. `"degs import"`): no replacing, no sources yet.
    pub fn new(command: impl Into<String>) -> Self {
        OutputRule {
            command: command.into(),
            force: false,
            sources: Vec::new(),
        }
    }

    /// Allow replacing an earlier output of the same command.
    pub fn force(mut self, force: bool) -> Self {
        self.force = force;
        self
    }

    /// An input the output must never be, nor hold.
    pub fn source(mut self, path: impl AsRef<Path>) -> Self {
        self.sources.push(path.as_ref().to_path_buf());
        self
    }

    /// Refuse a `target` that is or holds a source, that exists and is not a folder,
    /// that holds files and is not an earlier output of this command, or that is an
    /// earlier output while not forced. An empty folder is fine.
    pub fn check(&self, target: &Path) -> Result<()> {
        let t = resolved(target);
        for s in &self.sources {
            let s = resolved(s);
            if s.starts_with(&t) {
                let what = if s == t { "is" } else { "holds" };
                return Err(Error::invalid(
                    target,
                    format!(
                        "{what} the input {}; the output folder must lie elsewhere \
                         (it is replaced as a whole)",
                        s.display()
                    ),
                ));
            }
        }
        let meta = match fs::symlink_metadata(target) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
            Err(e) => return Err(Error::io(target, e)),
            Ok(m) => m,
        };
        if !meta.is_dir() {
            return Err(Error::invalid(
                target,
                "exists and is not a folder; choose a new output folder",
            ));
        }
        let first = fs::read_dir(target)
            .at(target)?
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .next();
        let Some(first) = first else {
            return Ok(()); // an empty folder
        };
        if !is_output_of(target, &self.command) {
            return Err(Error::invalid(
                target,
                format!(
                    "exists and is not an output of `{}` (it holds {first}, …); \
                     choose a new or empty output folder",
                    self.command
                ),
            ));
        }
        if !self.force {
            return Err(Error::invalid(
                target,
                format!(
                    "holds an earlier output of `{}`; pass --force to replace it",
                    self.command
                ),
            ));
        }
        Ok(())
    }
}

/// `path` made absolute, symlinks of its existing part resolved (the rest appended).
fn resolved(path: &Path) -> PathBuf {
    let abs = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut existing = abs.as_path();
    let mut rest = Vec::new();
    loop {
        if let Ok(c) = fs::canonicalize(existing) {
            let mut out = c;
            for part in rest.iter().rev() {
                out.push(part);
            }
            return out;
        }
        match (existing.parent(), existing.file_name()) {
            (Some(p), Some(name)) => {
                rest.push(name.to_os_string());
                existing = p;
            }
            _ => return abs,
        }
    }
}

/// Remove `*.degs-tmp-<pid>` and `*.degs-tmp-<pid>.<n>` entries in `dir` whose process
/// no longer runs (nothing else: a user's `notes.tmp-12` is not ours).
pub fn remove_stale_temps(dir: &Path) -> Result<()> {
    let Ok(entries) = fs::read_dir(dir) else {
        return Ok(());
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        let Some(pos) = name.rfind(TEMP_SUFFIX) else {
            continue;
        };
        let tail = &name[pos + TEMP_SUFFIX.len()..];
        let pid = match tail.split_once('.') {
            Some((pid, n)) if n.bytes().all(|b| b.is_ascii_digit()) && !n.is_empty() => pid,
            Some(_) => continue,
            None => tail,
        };
        let Ok(pid) = pid.parse::<u32>() else {
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
