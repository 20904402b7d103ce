//! A lock per cache entry, so that two runners (threads of one `degs` or two `degs`
//! processes on one cache) never build the same entry at once: the one that takes the
//! lock builds, the other waits and then finds the entry cached.
//!
//! The lock is an advisory `flock` on `cache/<stage>/<key>.lock`, held while the stage
//! runs and until its output is sealed and moved into place. The kernel drops it when
//! the holder exits, killed or not, so a crashed runner never leaves a stale lock. The
//! holder removes the file before it lets go; a runner that took the lock of a file
//! removed meanwhile (it waited on the old one) sees that its file is no longer the one
//! at the path and tries again, so two runners never hold locks on two different files of
//! one entry. A killed holder's file stays until the next runner of that entry (or `degs
//! gc`) removes it.

use crate::cache::Cache;
use anyhow::{Context as _, Result};
use std::fs::{self, File, OpenOptions};
use std::os::fd::AsRawFd;
use std::os::unix::fs::MetadataExt;
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
        loop {
            let file = OpenOptions::new()
                .create(true)
                .truncate(false)
                .write(true)
                .open(path)
                .with_context(|| format!("{}: cannot open the lock file", path.display()))?;
            if !flock(&file, wait).with_context(|| format!("{}: cannot lock", path.display()))? {
                return Ok(None);
            }
            // The holder before us may have removed the file we waited on: ours only
            // counts when it is still the file at `path`.
            let ours = file.metadata()?;
            match fs::metadata(path) {
                Ok(m) if m.dev() == ours.dev() && m.ino() == ours.ino() => {
                    return Ok(Some(EntryLock {
                        file,
                        path: path.to_path_buf(),
                    }));
                }
                _ => continue,
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
        // Removed while still held: nobody can take this file's lock in between.
        let _ = fs::remove_file(&self.path);
        // SAFETY: unlocking the descriptor this value owns; closing it would as well.
        unsafe {
            libc::flock(self.file.as_raw_fd(), libc::LOCK_UN);
        }
    }
}

/// `flock` the file exclusively: Ok(true) when taken, Ok(false) when someone holds it
/// and `wait` is false.
fn flock(file: &File, wait: bool) -> std::io::Result<bool> {
    let op = if wait {
        libc::LOCK_EX
    } else {
        libc::LOCK_EX | libc::LOCK_NB
    };
    loop {
        // SAFETY: flock on a file descriptor that `file` owns for the whole call.
        if unsafe { libc::flock(file.as_raw_fd(), op) } == 0 {
            return Ok(true);
        }
        let err = std::io::Error::last_os_error();
        match err.raw_os_error() {
            Some(libc::EINTR) => continue,
            Some(libc::EWOULDBLOCK) if !wait => return Ok(false),
            _ => return Err(err),
        }
    }
}

/// Remove the lock files under `cache/` that nobody holds (left by killed runners);
/// returns how many.
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
                // Taking it removes it when let go.
                if let Some(lock) = EntryLock::take_at(&p, false)? {
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
    fn a_lock_leaves_no_file_and_gc_removes_only_free_leftovers() {
        let d = tempfile::tempdir().unwrap();
        let cache = Cache::new(d.path());
        drop(EntryLock::take(&cache, "assoc", "done").unwrap());
        assert!(!EntryLock::path(&cache, "assoc", "done").exists());
        let held = EntryLock::take(&cache, "assoc", "busy").unwrap();
        // What a killed runner leaves: the file, no lock.
        fs::write(EntryLock::path(&cache, "assoc", "killed"), "").unwrap();
        assert_eq!(remove_free_locks(&cache).unwrap(), 1);
        assert!(held.file().exists());
        assert!(!EntryLock::path(&cache, "assoc", "killed").exists());
    }

    #[test]
    fn waiters_on_a_removed_file_never_hold_the_lock_together() {
        // Many threads take and let go of one entry's lock; each, while it holds it,
        // checks that nobody else does.
        let d = tempfile::tempdir().unwrap();
        let inside = std::sync::atomic::AtomicUsize::new(0);
        std::thread::scope(|s| {
            for _ in 0..6 {
                s.spawn(|| {
                    let cache = Cache::new(d.path());
                    for _ in 0..200 {
                        let _l = EntryLock::take(&cache, "deform", "k").unwrap();
                        let n = inside.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                        assert_eq!(n, 0, "two holders at once");
                        std::thread::yield_now();
                        inside.fetch_sub(1, std::sync::atomic::Ordering::SeqCst);
                    }
                });
            }
        });
    }
}
