//! `.evs`: this project's columnar event file, the fast path (DESIGN §3).
//!
//! Layout, all little-endian, a 64-byte header followed by the columns:
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 8 | magic `DEGSEVS\0` |
//! | 8 | 4 | version `u32` = 1 |
//! | 12 | 4 | width `u32` |
//! | 16 | 4 | height `u32` |
//! | 20 | 4 | reserved, 0 |
//! | 24 | 8 | event count `n` (`u64`) |
//! | 32 | 32 | BLAKE3 hash of all column bytes (offset 64 to the end) |
//! | 64 | 8n | `t`: `f64` seconds |
//! | 64 + 8n | 2n | `x`: `u16` |
//! | 64 + 10n | 2n | `y`: `u16` |
//! | 64 + 12n | n | `p`: `i8` (±1) |
//!
//! The file size must be exactly `64 + 13n`. Every column starts at an offset that is
//! a multiple of its element size, so a memory map ([`EvsMap`]) gives the columns as
//! slices without copying. The hash doubles as the stream's identity for caches and
//! for the source-stream hash of `.evflow` files ([`EvsMap::hash`], [`content_hash`]).

use super::{ReadOptions, check, resolve_sensor};
use crate::atomic::write_atomic;
use crate::error::{Error, IoContext, Result};
use crate::events::EventStream;
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

pub const MAGIC: &[u8; 8] = b"DEGSEVS\0";
pub const VERSION: u32 = 1;
pub const HEADER_LEN: usize = 64;
/// Bytes per event over all columns.
pub(crate) const BYTES_PER_EVENT: usize = 13;

/// Elements serialised per write call.
const BLOCK: usize = 1 << 16;

/// Visit the column bytes exactly as they are stored (little-endian), in blocks.
fn for_each_column_block(
    ev: &EventStream,
    mut f: impl FnMut(&[u8]) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let mut buf = Vec::with_capacity(BLOCK * 8);
    for c in ev.t.chunks(BLOCK) {
        buf.clear();
        c.iter()
            .for_each(|v| buf.extend_from_slice(&v.to_le_bytes()));
        f(&buf)?;
    }
    for col in [&ev.x, &ev.y] {
        for c in col.chunks(BLOCK) {
            buf.clear();
            c.iter()
                .for_each(|v| buf.extend_from_slice(&v.to_le_bytes()));
            f(&buf)?;
        }
    }
    for c in ev.p.chunks(BLOCK) {
        buf.clear();
        buf.extend(c.iter().map(|&v| v as u8));
        f(&buf)?;
    }
    Ok(())
}

/// BLAKE3 hash of a stream's `.evs` column bytes (what the header stores).
pub fn content_hash(ev: &EventStream) -> [u8; 32] {
    let mut h = blake3::Hasher::new();
    let _ = for_each_column_block(ev, |b| {
        h.update(b);
        Ok(())
    });
    *h.finalize().as_bytes()
}

/// Write a stream as `.evs`, atomically. The stream must be valid.
pub fn write_evs(path: impl AsRef<Path>, ev: &EventStream) -> Result<()> {
    let path = path.as_ref();
    check(path, ev)?;
    write_atomic(path, |w| {
        let mut header = [0u8; HEADER_LEN];
        header[..8].copy_from_slice(MAGIC);
        header[8..12].copy_from_slice(&VERSION.to_le_bytes());
        header[12..16].copy_from_slice(&ev.width.to_le_bytes());
        header[16..20].copy_from_slice(&ev.height.to_le_bytes());
        header[24..32].copy_from_slice(&(ev.len() as u64).to_le_bytes());
        w.write_all(&header)?;
        let mut hasher = blake3::Hasher::new();
        for_each_column_block(ev, |b| {
            hasher.update(b);
            w.write_all(b)
        })?;
        w.seek(SeekFrom::Start(32))?;
        w.write_all(hasher.finalize().as_bytes())?;
        w.seek(SeekFrom::End(0))?;
        Ok(())
    })
}

/// A memory-mapped `.evs` file whose header, size and hash were checked.
pub struct EvsMap {
    path: PathBuf,
    map: memmap2::Mmap,
    pub width: u32,
    pub height: u32,
    len: usize,
}

impl EvsMap {
    /// Map and check `path`: magic, version, size `64 + 13n`, hash. The events
    /// themselves are checked by [`read_evs`] (or call [`EvsMap::to_stream`]).
    pub fn open(path: impl AsRef<Path>) -> Result<EvsMap> {
        let path = path.as_ref();
        let file = std::fs::File::open(path).at(path)?;
        // SAFETY: the map is read-only; like every mmap reader we assume the file is
        // not truncated by another process while mapped (files are written atomically
        // and never modified in place).
        let map = unsafe { memmap2::Mmap::map(&file) }.at(path)?;
        let bad = |msg: String| Error::invalid(path, msg);
        if map.is_empty() {
            return Err(bad("file is empty".into()));
        }
        if map.len() < HEADER_LEN {
            return Err(bad(format!(
                "truncated: {} bytes, shorter than the {HEADER_LEN}-byte header",
                map.len()
            )));
        }
        if &map[..8] != MAGIC {
            return Err(bad(format!(
                "not an .evs file (magic {:?}, expected {:?})",
                String::from_utf8_lossy(&map[..8]),
                String::from_utf8_lossy(MAGIC)
            )));
        }
        let u32_at = |o: usize| u32::from_le_bytes([map[o], map[o + 1], map[o + 2], map[o + 3]]);
        let version = u32_at(8);
        if version != VERSION {
            return Err(bad(format!(
                "unsupported .evs version {version} (this build reads {VERSION})"
            )));
        }
        let (width, height) = (u32_at(12), u32_at(16));
        let mut n8 = [0u8; 8];
        n8.copy_from_slice(&map[24..32]);
        let n = u64::from_le_bytes(n8);
        let expected = n
            .checked_mul(BYTES_PER_EVENT as u64)
            .and_then(|b| b.checked_add(HEADER_LEN as u64));
        if expected != Some(map.len() as u64) {
            return Err(bad(format!(
                "size {} bytes does not match the header's {n} events ({} bytes expected): truncated or corrupt",
                map.len(),
                expected.map_or("overflow".to_string(), |e| e.to_string())
            )));
        }
        let hash = blake3::hash(&map[HEADER_LEN..]);
        if hash.as_bytes()[..] != map[32..64] {
            return Err(bad("content hash mismatch: the file is corrupt".into()));
        }
        Ok(EvsMap {
            path: path.to_path_buf(),
            map,
            width,
            height,
            len: n as usize,
        })
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The stored BLAKE3 hash of the columns.
    pub fn hash(&self) -> [u8; 32] {
        let mut h = [0u8; 32];
        h.copy_from_slice(&self.map[32..64]);
        h
    }

    fn column(&self, start: usize, bytes: usize) -> &[u8] {
        &self.map[HEADER_LEN + start..HEADER_LEN + start + bytes]
    }

    /// Timestamps without copying (little-endian hosts; aligned by the layout).
    #[cfg(target_endian = "little")]
    pub fn t(&self) -> &[f64] {
        cast(self.column(0, 8 * self.len))
    }

    #[cfg(target_endian = "little")]
    pub fn x(&self) -> &[u16] {
        cast(self.column(8 * self.len, 2 * self.len))
    }

    #[cfg(target_endian = "little")]
    pub fn y(&self) -> &[u16] {
        cast(self.column(10 * self.len, 2 * self.len))
    }

    #[cfg(target_endian = "little")]
    pub fn p(&self) -> &[i8] {
        cast(self.column(12 * self.len, self.len))
    }

    /// Copy into an owned stream and validate it.
    pub(crate) fn to_stream(&self) -> Result<EventStream> {
        let ev = self.copy_columns();
        check(&self.path, &ev)?;
        Ok(ev)
    }

    #[cfg(target_endian = "little")]
    fn copy_columns(&self) -> EventStream {
        EventStream {
            width: self.width,
            height: self.height,
            t: self.t().to_vec(),
            x: self.x().to_vec(),
            y: self.y().to_vec(),
            p: self.p().to_vec(),
        }
    }

    #[cfg(not(target_endian = "little"))]
    fn copy_columns(&self) -> EventStream {
        let n = self.len;
        let u16s = |b: &[u8]| -> Vec<u16> {
            b.chunks_exact(2)
                .map(|c| u16::from_le_bytes([c[0], c[1]]))
                .collect()
        };
        EventStream {
            width: self.width,
            height: self.height,
            t: self
                .column(0, 8 * n)
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8])))
                .collect(),
            x: u16s(self.column(8 * n, 2 * n)),
            y: u16s(self.column(10 * n, 2 * n)),
            p: self.column(12 * n, n).iter().map(|&b| b as i8).collect(),
        }
    }
}

/// Reinterpret little-endian column bytes as a slice of `T` (plain numbers only).
#[cfg(target_endian = "little")]
fn cast<T: Copy>(bytes: &[u8]) -> &[T] {
    let size = std::mem::size_of::<T>();
    assert!(
        bytes.as_ptr().align_offset(std::mem::align_of::<T>()) == 0
            && bytes.len().is_multiple_of(size),
        "evs column misaligned (layout invariant)"
    );
    // SAFETY: alignment and length checked above; T is a plain number type (f64, u16,
    // i8) for which every bit pattern is valid; the bytes live as long as `bytes`.
    unsafe { std::slice::from_raw_parts(bytes.as_ptr().cast::<T>(), bytes.len() / size) }
}

/// Read an `.evs` file (memory-mapped, hash and events checked).
pub fn read_evs(path: impl AsRef<Path>, opts: &ReadOptions) -> Result<EventStream> {
    let path = path.as_ref();
    let map = EvsMap::open(path)?;
    resolve_sensor(path, Some((map.width, map.height)), opts)?;
    map.to_stream()
}
