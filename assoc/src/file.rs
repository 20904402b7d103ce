//! `assoc.bin`: the bindings of every train-frame time of a scene.
//!
//! Layout (little-endian; one file holds all frames, so DESIGN §3's per-frame header
//! — frame time t0, window δt, k — is repeated per frame section):
//!
//! ```text
//! magic      8 bytes  "DEGSASC\0"
//! version    u32      1
//! frames     u32      number of frame sections
//! per frame:
//!   t0         f64    frame time (seconds, event clock)
//!   delta_t    f64    event window half-width (s)
//!   k          u32    maximum bindings per Gaussian
//!   gaussians  u32    number of Gaussians in the model
//!   bound      u32    number of bound Gaussians (records below)
//!   per bound Gaussian (a record of 8 + 12·k bytes):
//!     index    u32    Gaussian index (< gaussians, strictly increasing)
//!     count    u32    1..=k bindings
//!     events   k × u64 event indices into the source stream (unused slots 0)
//!     weights  k × f32 weights (unused slots 0; used ones sum to 1)
//! checksum   32 bytes blake3 of everything before it
//! ```

use std::path::Path;

use scene::{Error, IoContext, Result};

use crate::Bindings;

const MAGIC: &[u8; 8] = b"DEGSASC\0";
const VERSION: u32 = 1;
/// Upper bound on k accepted from a file (hostile headers cannot make us allocate).
const MAX_K: u32 = 64;
/// Largest model a file may describe (offsets cost 4 bytes per Gaussian; a
/// hostile header must not make the reader allocate gigabytes).
const MAX_GAUSSIANS: usize = 1 << 25;

/// The bindings at one frame time.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameBindings {
    pub t0: f64,
    pub delta_t: f64,
    pub k: u32,
    pub bindings: Bindings,
}

/// Writes `frames` to `path` atomically.
pub fn write_assoc(path: &Path, frames: &[FrameBindings]) -> Result<()> {
    let mut buf = Vec::new();
    buf.extend_from_slice(MAGIC);
    buf.extend_from_slice(&VERSION.to_le_bytes());
    buf.extend_from_slice(&(frames.len() as u32).to_le_bytes());
    for f in frames {
        let b = &f.bindings;
        if f.k == 0 || f.k > MAX_K {
            return Err(Error::invalid(
                path,
                format!("k = {} outside 1..={MAX_K}", f.k),
            ));
        }
        if b.gaussians() > MAX_GAUSSIANS {
            return Err(Error::invalid(
                path,
                format!(
                    "{} Gaussians exceed the format's limit {MAX_GAUSSIANS}",
                    b.gaussians()
                ),
            ));
        }
        buf.extend_from_slice(&f.t0.to_le_bytes());
        buf.extend_from_slice(&f.delta_t.to_le_bytes());
        buf.extend_from_slice(&f.k.to_le_bytes());
        buf.extend_from_slice(&(b.gaussians() as u32).to_le_bytes());
        buf.extend_from_slice(&(b.bound() as u32).to_le_bytes());
        let k = f.k as usize;
        for g in 0..b.gaussians() {
            let (ev, w) = b.of(g);
            if ev.is_empty() {
                continue;
            }
            if ev.len() > k {
                return Err(Error::invalid(
                    path,
                    format!("Gaussian {g} has {} bindings, more than k = {k}", ev.len()),
                ));
            }
            buf.extend_from_slice(&(g as u32).to_le_bytes());
            buf.extend_from_slice(&(ev.len() as u32).to_le_bytes());
            for j in 0..k {
                buf.extend_from_slice(&ev.get(j).copied().unwrap_or(0).to_le_bytes());
            }
            for j in 0..k {
                buf.extend_from_slice(&w.get(j).copied().unwrap_or(0.0).to_le_bytes());
            }
        }
    }
    let hash = blake3::hash(&buf);
    buf.extend_from_slice(hash.as_bytes());
    scene::atomic::write_bytes_atomic(path, &buf)
}

/// A bounds-checked little-endian cursor that names the file in its errors.
struct Cursor<'a> {
    path: &'a Path,
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let Some(end) = end else {
            return Err(Error::invalid(
                self.path,
                format!("truncated: {what} at byte {} needs {n} bytes", self.at),
            ));
        };
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn u32(&mut self, what: &str) -> Result<u32> {
        Ok(u32::from_le_bytes(self.take(4, what)?.try_into().unwrap()))
    }
    fn u64(&mut self, what: &str) -> Result<u64> {
        Ok(u64::from_le_bytes(self.take(8, what)?.try_into().unwrap()))
    }
    fn f64(&mut self, what: &str) -> Result<f64> {
        Ok(f64::from_le_bytes(self.take(8, what)?.try_into().unwrap()))
    }
    fn f32(&mut self, what: &str) -> Result<f32> {
        Ok(f32::from_le_bytes(self.take(4, what)?.try_into().unwrap()))
    }
}

/// Reads an `assoc.bin`, checking magic, version, checksum, counts and weights. Its
/// in-memory form holds 4 bytes per Gaussian per frame however few are bound, so without
/// the model at hand the Gaussians of all frames together are limited to
/// [`MAX_GAUSSIANS`] (128 MiB); [`read_assoc_for`] takes the model's counts instead.
pub fn read_assoc(path: &Path) -> Result<Vec<FrameBindings>> {
    read_checked(path, None)
}

/// [`read_assoc`] for a model of `gaussians` Gaussians and `frames` train frames: a file
/// for another model is refused before anything is allocated for it, so a damaged
/// header cannot make the reader allocate more than the bindings of this model take.
pub fn read_assoc_for(path: &Path, frames: usize, gaussians: usize) -> Result<Vec<FrameBindings>> {
    read_checked(path, Some((frames, gaussians)))
}

fn read_checked(path: &Path, expect: Option<(usize, usize)>) -> Result<Vec<FrameBindings>> {
    let bytes = std::fs::read(path).at(path)?;
    if bytes.len() < 8 + 8 + 32 || &bytes[..8] != MAGIC {
        return Err(Error::invalid(
            path,
            "not an assoc.bin file (bad magic or too short)",
        ));
    }
    let (body, sum) = bytes.split_at(bytes.len() - 32);
    if blake3::hash(body).as_bytes() != sum {
        return Err(Error::invalid(
            path,
            "checksum mismatch: the file is corrupt or truncated",
        ));
    }
    let mut c = Cursor {
        path,
        bytes: body,
        at: 8,
    };
    let version = c.u32("version")?;
    if version != VERSION {
        return Err(Error::invalid(
            path,
            format!("unsupported version {version}"),
        ));
    }
    let n_frames = c.u32("frame count")?;
    if let Some((want, _)) = expect
        && n_frames as usize != want
    {
        return Err(Error::invalid(
            path,
            format!("{n_frames} frames of bindings for {want} train frames"),
        ));
    }
    // Offsets allocated so far over all frames (bounded when no model is given).
    let mut offsets_total = 0usize;
    let mut frames = Vec::new();
    for fi in 0..n_frames {
        let t0 = c.f64("t0")?;
        let delta_t = c.f64("delta_t")?;
        let k = c.u32("k")?;
        let gaussians = c.u32("Gaussian count")? as usize;
        let bound = c.u32("bound count")? as usize;
        if !(t0.is_finite() && delta_t >= 0.0 && delta_t.is_finite()) {
            return Err(Error::invalid(
                path,
                format!("frame {fi}: non-finite t0 or delta_t"),
            ));
        }
        if k == 0 || k > MAX_K || bound > gaussians || gaussians > MAX_GAUSSIANS {
            return Err(Error::invalid(
                path,
                format!("frame {fi}: k = {k}, {bound} bound of {gaussians} Gaussians"),
            ));
        }
        if let Some((_, want)) = expect
            && gaussians != want
        {
            return Err(Error::invalid(
                path,
                format!(
                    "frame {fi}: bindings for {gaussians} Gaussians but the model has {want}: \
                     from another warm-up?"
                ),
            ));
        }
        offsets_total += gaussians + 1;
        if expect.is_none() && offsets_total > MAX_GAUSSIANS + n_frames as usize {
            return Err(Error::invalid(
                path,
                format!(
                    "frame {fi}: more than {MAX_GAUSSIANS} Gaussians over all frames \
                     (read it with the model's counts: read_assoc_for)"
                ),
            ));
        }
        let record = 8 + 12 * k as usize;
        if bound.saturating_mul(record) > body.len() - c.at {
            return Err(Error::invalid(
                path,
                format!("frame {fi}: {bound} records do not fit in the file"),
            ));
        }
        let mut b = Bindings {
            offsets: Vec::with_capacity(bound + 1),
            ..Default::default()
        };
        b.offsets.push(0);
        let mut next = 0usize;
        for _ in 0..bound {
            let g = c.u32("Gaussian index")? as usize;
            let count = c.u32("binding count")? as usize;
            if g < next || g >= gaussians || count == 0 || count > k as usize {
                return Err(Error::invalid(
                    path,
                    format!("frame {fi}: bad record (Gaussian {g}, {count} bindings)"),
                ));
            }
            b.offsets.resize(g + 1, b.events.len() as u32);
            let mut ev = [0u64; MAX_K as usize];
            for e in ev.iter_mut().take(k as usize) {
                *e = c.u64("event index")?;
            }
            let mut wsum = 0.0f32;
            for (j, &event) in ev.iter().enumerate().take(k as usize) {
                let w = c.f32("weight")?;
                if j < count {
                    if !(w.is_finite() && w >= 0.0) {
                        return Err(Error::invalid(path, format!("frame {fi}: bad weight {w}")));
                    }
                    wsum += w;
                    b.events.push(event);
                    b.weights.push(w);
                }
            }
            if (wsum - 1.0).abs() > 1e-4 {
                return Err(Error::invalid(
                    path,
                    format!("frame {fi}: Gaussian {g} weights sum to {wsum}, not 1"),
                ));
            }
            b.offsets.push(b.events.len() as u32);
            next = g + 1;
        }
        b.offsets.resize(gaussians + 1, b.events.len() as u32);
        frames.push(FrameBindings {
            t0,
            delta_t,
            k,
            bindings: b,
        });
    }
    if c.at != body.len() {
        return Err(Error::invalid(path, "trailing bytes after the last frame"));
    }
    Ok(frames)
}
