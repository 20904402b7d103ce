//! A lock per cache entry, so that two runners (threads of one `degs` or two `degs`
//! processes on one cache) never build the same entry at once: the one that takes the
//! lock builds, the other waits and then finds the entry cached.
//!
//! The lock is an advisory `flock` on `cache/<stage>/<key>.lock`, held while the stage
//! runs and until its output is sealed and moved into place. The kernel drops it when
//! the holder exits, killed or not, so a crashed runner never leaves a stale lock. Lock
//! files are left in place (removing one that another runner holds open would let a
//! third take a second lock on a new file); `degs gc` removes those nobody holds.

use crate::cache::Cache;
use anyhow::{Context as _, Result};
use std::fs::{self, File, OpenOptions};
use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};

/// The suffix of lock files in a stage's cache folder.
pub const LOCK_SUFFIX: &str = ".lock";

/// A held lock on one cache entry; released when dropped.
#[derive(Debug)]
pub struct EntryLock {
    file: File,
    path: PathBuf,
}

impl EntryLock {
    /// The lock file of `(stage, key)`.
    pub fn path(cache: &Cache, stage: &str, key: &str) -> PathBuf {
        cache.stage_dir(stage).join(format!("{key}{LOCK_SUFFIX}"))
    }

    /// Take the lock of `(stage, key)` if nobody holds it; `None` if someone does.
    pub fn try_take(cache: &Cache, stage: &str, key: &str) -> Result<Option<EntryLock>> {
        Self::take_at(&Self::path(cache, stage, key), false)
    }

    /// Take the lock of `(stage, key)`, waiting for whoever holds it.
    pub fn take(cache: &Cache, stage: &str, key: &str) -> Result<EntryLock> {
        let path = Self::path(cache, stage, key);
        Self::take_at(&path, true)?.with_context(|| format!("{}: lock not taken", path.display()))
    }

    /// Take the lock at `path` (waiting when `wait`).
    pub fn take_at(path: &Path, wait: bool) -> Result<Option<EntryLock>> {
        if let Some(dir) = path.parent() {
            fs::create_dir_all(dir).with_context(|| format!("{}", dir.display()))?;
        }
        let file = OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(path)
            .with_context(|| format!("{}: cannot open the lock file", path.display()))?;
        let op = if wait {
            libc::LOCK_EX
        } else {
            libc::LOCK_EX | libc::LOCK_NB
        };
        loop {
            // SAFETY: flock on a file descriptor this function owns.
            let rc = unsafe { libc::flock(file.as_raw_fd(), op) };
            if rc == 0 {
                return Ok(Some(EntryLock {
                    file,
                    path: path.to_path_buf(),
                }));
            }
            let err = std::io::Error::last_os_error();
            match err.raw_os_error() {
                Some(libc::EINTR) => continue,
                Some(libc::EWOULDBLOCK) if !wait => return Ok(None),
                _ => {
                    return Err(err).with_context(|| format!("{}: cannot lock", path.display()));
                }
            }
        }
    }

    /// Where the lock file lies.
    pub fn file(&self) -> &Path {
        &self.path
    }
}

impl Drop for EntryLock {
    fn drop(&mut self) {
        // SAFETY: unlocking the descriptor this value owns; closing it would as well.
        unsafe {
            libc::flock(self.file.as_raw_fd(), libc::LOCK_UN);
        }
    }
}

/// Remove the lock files under `cache/` that nobody holds; returns how many.
pub fn remove_free_locks(cache: &Cache) -> Result<usize> {
    let mut removed = 0;
    let Ok(stages) = fs::read_dir(cache.root.join("cache")) else {
        return Ok(0);
    };
    for s in stages.flatten().filter(|s| s.path().is_dir()) {
        let Ok(files) = fs::read_dir(s.path()) else {
            continue;
        };
        for f in files.flatten() {
            let p = f.path();
            let is_lock = p
                .file_name()
                .is_some_and(|n| n.to_string_lossy().ends_with(LOCK_SUFFIX));
            if is_lock && p.is_file() {
                // Held while removed: nobody else can take it in between.
                if let Some(lock) = EntryLock::take_at(&p, false)? {
                    fs::remove_file(&p).with_context(|| format!("{}", p.display()))?;
                    drop(lock);
                    removed += 1;
                }
            }
        }
    }
    Ok(removed)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::mpsc;
    use std::time::{Duration, Instant};

    #[test]
    fn a_held_lock_is_refused_then_free_after_drop() {
        let d = tempfile::tempdir().unwrap();
        let cache = Cache::new(d.path());
        let a = EntryLock::try_take(&cache, "gaussians", "k1").unwrap();
        assert!(a.is_some());
        // flock locks belong to the open file description: a second open in the same
        // process conflicts as another process would.
        assert!(
            EntryLock::try_take(&cache, "gaussians", "k1")
                .unwrap()
                .is_none()
        );
        assert!(
            EntryLock::try_take(&cache, "gaussians", "k2")
                .unwrap()
                .is_some()
        );
        drop(a);
        assert!(
            EntryLock::try_take(&cache, "gaussians", "k1")
                .unwrap()
                .is_some()
        );
    }

    #[test]
    fn take_waits_for_the_holder() {
        let d = tempfile::tempdir().unwrap();
        let cache = Cache::new(d.path());
        let held = EntryLock::take(&cache, "evflow", "k").unwrap();
        let (tx, rx) = mpsc::channel();
        let root = d.path().to_path_buf();
        let waiter = std::thread::spawn(move || {
            let t = Instant::now();
            let _l = EntryLock::take(&Cache::new(root), "evflow", "k").unwrap();
            tx.send(t.elapsed()).unwrap();
        });
        std::thread::sleep(Duration::from_millis(300));
        assert!(
            rx.try_recv().is_err(),
            "the waiter must not have the lock yet"
        );
        drop(held);
        let waited = rx.recv_timeout(Duration::from_secs(10)).unwrap();
        waiter.join().unwrap();
        assert!(waited >= Duration::from_millis(250), "waited {waited:?}");
    }

    #[test]
    fn gc_removes_only_free_lock_files() {
        let d = tempfile::tempdir().unwrap();
        let cache = Cache::new(d.path());
        let held = EntryLock::take(&cache, "assoc", "busy").unwrap();
        drop(EntryLock::take(&cache, "assoc", "idle").unwrap());
        assert_eq!(remove_free_locks(&cache).unwrap(), 1);
        assert!(held.file().exists());
        assert!(!EntryLock::path(&cache, "assoc", "idle").exists());
    }
}
