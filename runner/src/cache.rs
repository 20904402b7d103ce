//! The content-addressed cache (docs/DESIGN.md §4).
//!
//! ```text
//! <root>/cache/<stage>/<key>/                 a finished stage output, never rewritten
//! <root>/cache/<stage>/<key>/.degs-entry.json blake3, size and mtime of every output file
//! <root>/cache/<stage>/<key>.degs-tmp-<pid>/       a stage being written (removed when stale)
//! <root>/cache/.binary-hashes.json            hashes of stage binaries by (size, mtime, inode)
//! <root>/runs/<name>/run.json                 which entries a run used, times, memory
//! <root>/runs/<name>/<stage>.log              the stage's command, exit status, output tail
//! ```

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fs;
use std::io::Read;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

/// Name of the manifest inside each entry.
pub const MANIFEST: &str = scene::atomic::ENTRY_MANIFEST;

/// Paths of a cache root.
#[derive(Clone, Debug)]
pub struct Cache {
    pub root: PathBuf,
}

impl Cache {
    pub fn new(root: impl Into<PathBuf>) -> Cache {
        Cache { root: root.into() }
    }
    pub fn stage_dir(&self, stage: &str) -> PathBuf {
        self.root.join("cache").join(stage)
    }
    pub fn entry(&self, stage: &str, key: &str) -> PathBuf {
        self.stage_dir(stage).join(key)
    }
    /// Where a stage writes while it runs (our pid, so a dead runner's dir is stale).
    pub fn temp_entry(&self, stage: &str, key: &str) -> PathBuf {
        self.stage_dir(stage).join(format!(
            "{key}{}{}",
            scene::atomic::TEMP_SUFFIX,
            std::process::id()
        ))
    }
    pub fn run_dir(&self, name: &str) -> PathBuf {
        self.root.join("runs").join(name)
    }
    pub fn run_record(&self, name: &str) -> PathBuf {
        self.run_dir(name).join("run.json")
    }

    /// Remove the temp dirs and files of runners that no longer run.
    pub fn remove_stale_temps(&self) -> Result<()> {
        let cache = self.root.join("cache");
        scene::atomic::remove_stale_temps(&cache)?;
        if let Ok(stages) = fs::read_dir(&cache) {
            for s in stages.flatten() {
                if s.path().is_dir() {
                    scene::atomic::remove_stale_temps(&s.path())?;
                }
            }
        }
        if let Ok(runs) = fs::read_dir(self.root.join("runs")) {
            for r in runs.flatten() {
                if r.path().is_dir() {
                    scene::atomic::remove_stale_temps(&r.path())?;
                }
            }
        }
        Ok(())
    }

    /// All `(stage, key)` entries present, with their paths.
    pub fn entries(&self) -> Vec<(String, String, PathBuf)> {
        let mut out = Vec::new();
        let Ok(stages) = fs::read_dir(self.root.join("cache")) else {
            return out;
        };
        for s in stages.flatten().filter(|s| s.path().is_dir()) {
            let stage = s.file_name().to_string_lossy().to_string();
            let Ok(keys) = fs::read_dir(s.path()) else {
                continue;
            };
            for k in keys.flatten().filter(|k| k.path().is_dir()) {
                let key = k.file_name().to_string_lossy().to_string();
                if !key.contains(scene::atomic::TEMP_SUFFIX) {
                    out.push((stage.clone(), key, k.path()));
                }
            }
        }
        out.sort();
        out
    }
}

/// blake3 of a file's bytes, hex.
pub fn hash_file(path: &Path) -> Result<String> {
    let mut f = fs::File::open(path).with_context(|| format!("{}: cannot open", path.display()))?;
    let mut h = blake3::Hasher::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = f
            .read(&mut buf)
            .with_context(|| format!("{}: cannot read", path.display()))?;
        if n == 0 {
            break;
        }
        h.update(&buf[..n]);
    }
    Ok(h.finalize().to_hex().to_string())
}

fn mtime_ns(m: &fs::Metadata) -> i128 {
    m.mtime() as i128 * 1_000_000_000 + m.mtime_nsec() as i128
}

/// Hashes of stage binaries, remembered by (path, size, mtime, inode) so an all-cached
/// run does not re-read hundreds of megabytes of executables.
#[derive(Default, Serialize, Deserialize)]
pub struct BinaryHashes {
    entries: BTreeMap<String, BinaryHash>,
    #[serde(skip)]
    dirty: bool,
}

#[derive(Clone, Serialize, Deserialize)]
struct BinaryHash {
    size: u64,
    mtime_ns: i128,
    inode: u64,
    blake3: String,
}

impl BinaryHashes {
    fn path(cache: &Cache) -> PathBuf {
        cache.root.join("cache").join(".binary-hashes.json")
    }
    pub fn load(cache: &Cache) -> BinaryHashes {
        fs::read(Self::path(cache))
            .ok()
            .and_then(|b| serde_json::from_slice(&b).ok())
            .unwrap_or_default()
    }
    pub fn save(&self, cache: &Cache) -> Result<()> {
        if self.dirty {
            scene::atomic::write_json_atomic(&Self::path(cache), self)?;
        }
        Ok(())
    }
    /// The blake3 of the binary at `path`.
    pub fn hash(&mut self, path: &Path) -> Result<String> {
        let m = fs::metadata(path).with_context(|| format!("{}: cannot stat", path.display()))?;
        let id = path.display().to_string();
        if let Some(e) = self.entries.get(&id)
            && e.size == m.len()
            && e.mtime_ns == mtime_ns(&m)
            && e.inode == m.ino()
        {
            return Ok(e.blake3.clone());
        }
        let blake3 = hash_file(path)?;
        self.entries.insert(
            id,
            BinaryHash {
                size: m.len(),
                mtime_ns: mtime_ns(&m),
                inode: m.ino(),
                blake3: blake3.clone(),
            },
        );
        self.dirty = true;
        Ok(blake3)
    }
}

/// Files under `dir` (relative paths, sorted), the manifest excluded.
pub fn list_files(dir: &Path) -> Result<Vec<PathBuf>> {
    fn walk(base: &Path, dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
        for e in fs::read_dir(dir).with_context(|| format!("{}: cannot list", dir.display()))? {
            let e = e.with_context(|| format!("{}: cannot list", dir.display()))?;
            let p = e.path();
            let ft = e.file_type()?;
            if ft.is_dir() {
                walk(base, &p, out)?;
            } else {
                let rel = p.strip_prefix(base).unwrap_or(&p).to_path_buf();
                if rel != Path::new(MANIFEST) {
                    out.push(rel);
                }
            }
        }
        Ok(())
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out)?;
    out.sort();
    Ok(out)
}

/// A key for a scene directory that is not a cache entry: blake3 over the relative
/// path, size and mtime of every file (reading gigabytes of events on every run would
/// defeat the cache; editing or replacing any file changes the key).
pub(crate) fn dir_fingerprint(dir: &Path) -> Result<String> {
    if !dir.is_dir() {
        anyhow::bail!("{}: scene directory not found", dir.display());
    }
    let mut h = blake3::Hasher::new();
    let mut add = |name: &Path, m: &fs::Metadata| {
        h.update(name.to_string_lossy().as_bytes());
        h.update(&[0]);
        h.update(&m.len().to_le_bytes());
        h.update(&mtime_ns(m).to_le_bytes());
    };
    for rel in list_files(dir)? {
        add(&rel, &fs::metadata(dir.join(&rel))?);
    }
    // Files the manifests name outside the directory (an events file beside it, frames
    // elsewhere) are part of the scene too.
    for p in external_files(dir) {
        let m = fs::metadata(&p).with_context(|| format!("{}: cannot read", p.display()))?;
        add(&p, &m);
    }
    Ok(h.finalize().to_hex()[..32].to_string())
}

/// The files a scene's manifests reference outside `dir` (absolute paths), sorted; none
/// when the scene cannot be opened (its stages will say why).
fn external_files(dir: &Path) -> Vec<PathBuf> {
    let Ok(scene) = scene::Scene::open(dir) else {
        return Vec::new();
    };
    let inside = fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf());
    let frames = [&scene.train, &scene.test, &scene.novel]
        .into_iter()
        .flat_map(|m| m.frames.iter().map(|f| scene.image_path(f)));
    let mut out: Vec<PathBuf> = frames
        .chain(scene.events_path())
        .filter_map(|p| fs::canonicalize(p).ok())
        .filter(|p| !p.starts_with(&inside))
        .collect();
    out.sort();
    out.dedup();
    out
}

/// The manifest of a finished entry.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct EntryManifest {
    pub stage: String,
    pub key: String,
    pub created_unix: u64,
    /// Wall time and peak memory of the run that built it.
    pub wall_s: f64,
    pub peak_rss_kib: Option<u64>,
    pub files: Vec<FileRecord>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FileRecord {
    pub path: String,
    pub size: u64,
    pub mtime_ns: i128,
    pub blake3: String,
}

/// What checking an entry found.
#[derive(Clone, Debug, PartialEq)]
pub enum Verdict {
    Ok,
    /// No (readable) manifest: written outside `degs run` (e.g. from `degs plan`).
    Unsealed,
    /// A file is missing or its bytes changed; the message names it.
    Tampered(String),
}

/// Hash every file of `dir` and write its manifest (atomically).
pub fn seal(dir: &Path, stage: &str, key: &str, wall_s: f64, peak: Option<u64>) -> Result<()> {
    let mut files = Vec::new();
    for rel in list_files(dir)? {
        let p = dir.join(&rel);
        let m = fs::metadata(&p)?;
        files.push(FileRecord {
            path: rel.to_string_lossy().to_string(),
            size: m.len(),
            mtime_ns: mtime_ns(&m),
            blake3: hash_file(&p)?,
        });
    }
    let manifest = EntryManifest {
        stage: stage.into(),
        key: key.into(),
        created_unix: crate::record::now_unix(),
        wall_s,
        peak_rss_kib: peak,
        files,
    };
    scene::atomic::write_json_atomic(&dir.join(MANIFEST), &manifest)?;
    Ok(())
}

pub fn read_manifest(dir: &Path) -> Option<EntryManifest> {
    fs::read(dir.join(MANIFEST))
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok())
}

/// Check an entry against its manifest. `full` re-hashes every file; otherwise a file
/// is re-hashed only when its size or mtime differs from the manifest.
pub fn verify(dir: &Path, full: bool) -> Verdict {
    let Some(m) = read_manifest(dir) else {
        return Verdict::Unsealed;
    };
    for f in &m.files {
        // A manifest lists files inside its entry: a path that leaves it (absolute, `..`)
        // is never opened.
        let inside = Path::new(&f.path)
            .components()
            .all(|c| matches!(c, std::path::Component::Normal(_)));
        if !inside || f.path.is_empty() {
            return Verdict::Tampered(format!("{:?} is not a path inside the entry", f.path));
        }
        let p = dir.join(&f.path);
        let Ok(meta) = fs::metadata(&p) else {
            return Verdict::Tampered(format!("{} is missing", f.path));
        };
        if meta.len() != f.size {
            return Verdict::Tampered(format!(
                "{} changed size ({} → {} bytes)",
                f.path,
                f.size,
                meta.len()
            ));
        }
        if full || mtime_ns(&meta) != f.mtime_ns {
            match hash_file(&p) {
                Ok(h) if h == f.blake3 => {}
                Ok(_) => return Verdict::Tampered(format!("{}: blake3 mismatch", f.path)),
                Err(e) => return Verdict::Tampered(format!("{e:#}")),
            }
        }
    }
    Verdict::Ok
}

/// The wall time a stage's `report.json` gives for itself (`wall_s` or
/// `wall_seconds`), seconds; None when it has none.
pub(crate) fn report_wall_s(dir: &Path) -> Option<f64> {
    let v: serde_json::Value =
        serde_json::from_slice(&fs::read(dir.join("report.json")).ok()?).ok()?;
    ["wall_s", "wall_seconds", "total_s"]
        .iter()
        .find_map(|k| v.get(*k)?.as_f64())
        .filter(|t| t.is_finite() && *t >= 0.0)
}

/// Total size in bytes of the files under `dir`.
pub(crate) fn dir_size(dir: &Path) -> u64 {
    list_files(dir)
        .unwrap_or_default()
        .iter()
        .filter_map(|r| fs::metadata(dir.join(r)).ok())
        .map(|m| m.len())
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seal_then_verify_detects_changes() {
        let d = tempfile::tempdir().unwrap();
        fs::create_dir_all(d.path().join("sub")).unwrap();
        fs::write(d.path().join("a.bin"), b"hello").unwrap();
        fs::write(d.path().join("sub/b.txt"), b"world").unwrap();
        assert_eq!(verify(d.path(), false), Verdict::Unsealed);
        seal(d.path(), "s", "k", 1.0, None).unwrap();
        assert_eq!(verify(d.path(), true), Verdict::Ok);
        let m = read_manifest(d.path()).unwrap();
        assert_eq!(m.files.len(), 2);
        assert_eq!(m.files[1].path, "sub/b.txt");
        assert_eq!(
            m.files[0].blake3,
            blake3::hash(b"hello").to_hex().to_string()
        );

        // same size, different bytes, original mtime restored: only a full check sees it
        let p = d.path().join("a.bin");
        let before = fs::metadata(&p).unwrap().modified().unwrap();
        fs::write(&p, b"jello").unwrap();
        fs::File::options()
            .write(true)
            .open(&p)
            .unwrap()
            .set_modified(before)
            .unwrap();
        assert_eq!(verify(d.path(), false), Verdict::Ok);
        assert!(matches!(verify(d.path(), true), Verdict::Tampered(m) if m.contains("a.bin")));

        fs::write(&p, b"hello!").unwrap();
        assert!(matches!(verify(d.path(), false), Verdict::Tampered(m) if m.contains("size")));
        fs::remove_file(d.path().join("sub/b.txt")).unwrap();
        fs::write(&p, b"hello").unwrap();
        assert!(matches!(verify(d.path(), false), Verdict::Tampered(m) if m.contains("missing")));
    }

    /// A manifest naming files outside its entry (a hostile or mangled cache) is refused
    /// before anything is opened: the outside file exists and has the listed size.
    #[test]
    fn manifest_paths_outside_the_entry_are_tampering() {
        let root = tempfile::tempdir().unwrap();
        let entry = root.path().join("entry");
        fs::create_dir_all(&entry).unwrap();
        fs::write(entry.join("a.bin"), b"hello").unwrap();
        fs::write(root.path().join("secret"), b"hello").unwrap();
        seal(&entry, "s", "k", 1.0, None).unwrap();
        let good = fs::read_to_string(entry.join(MANIFEST)).unwrap();
        let outside = root.path().join("secret").display().to_string();
        for bad in ["../secret", outside.as_str(), "", "./a.bin/../../secret"] {
            let text = good.replace("\"a.bin\"", &serde_json::to_string(bad).unwrap());
            assert_ne!(text, good);
            fs::write(entry.join(MANIFEST), &text).unwrap();
            for full in [false, true] {
                let v = verify(&entry, full);
                assert!(
                    matches!(&v, Verdict::Tampered(m) if m.contains("not a path inside")),
                    "{bad:?}: {v:?}"
                );
            }
        }
    }

    #[test]
    fn corrupt_manifest_reads_as_unsealed() {
        let d = tempfile::tempdir().unwrap();
        fs::write(d.path().join(MANIFEST), b"{not json").unwrap();
        assert_eq!(verify(d.path(), true), Verdict::Unsealed);
        fs::write(d.path().join(MANIFEST), b"").unwrap();
        assert_eq!(verify(d.path(), true), Verdict::Unsealed);
    }

    #[test]
    fn binary_hashes_are_remembered_and_refreshed() {
        let d = tempfile::tempdir().unwrap();
        let cache = Cache::new(d.path());
        let bin = d.path().join("tool");
        fs::write(&bin, b"v1").unwrap();
        let mut hs = BinaryHashes::load(&cache);
        let h1 = hs.hash(&bin).unwrap();
        assert_eq!(h1, blake3::hash(b"v1").to_hex().to_string());
        hs.save(&cache).unwrap();
        let mut again = BinaryHashes::load(&cache);
        assert_eq!(again.hash(&bin).unwrap(), h1);
        fs::write(&bin, b"v2-longer").unwrap();
        assert_ne!(again.hash(&bin).unwrap(), h1);
        assert!(hs.hash(&d.path().join("missing")).is_err());
    }

    #[test]
    fn fingerprint_changes_with_content() {
        let d = tempfile::tempdir().unwrap();
        fs::write(d.path().join("x"), b"1").unwrap();
        let a = dir_fingerprint(d.path()).unwrap();
        assert_eq!(a, dir_fingerprint(d.path()).unwrap());
        fs::write(d.path().join("y"), b"2").unwrap();
        assert_ne!(a, dir_fingerprint(d.path()).unwrap());
        assert!(dir_fingerprint(&d.path().join("nope")).is_err());
    }
}
