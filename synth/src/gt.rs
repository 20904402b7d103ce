//! Ground-truth files of synthetic scenes (the `gt/` folder of a scene directory).
//!
//! **Per-event flow** `gt/event_flow.bin`, little-endian, columnar:
//!
//! | offset | size | content |
//! |---|---|---|
//! | 0 | 8 | magic `DEGSEVGT` |
//! | 8 | 4 | version (u32, 1) |
//! | 12 | 4 | width (u32) |
//! | 16 | 4 | height (u32) |
//! | 20 | 4 | reserved (0) |
//! | 24 | 8 | event count n (u64) |
//! | 32 | 8n | event index into `events.evs` (u64, strictly increasing) |
//! | … | 4n | flow u, px/s (f32) |
//! | … | 4n | flow v, px/s (f32) |
//! | … | 2n | object id (u16; 0 background, [`NOISE_ID`] for noise events) |
//!
//! **Object ids** `gt/*/object_XXXX.png`: 16-bit grayscale PNG, value = object id.

use scene::atomic::{write_atomic, write_bytes_atomic};
use scene::error::{Error, IoContext, Result};
use std::io::Write;
use std::path::Path;

pub const MAGIC: &[u8; 8] = b"DEGSEVGT";
pub const VERSION: u32 = 1;
const HEADER_LEN: usize = 32;
/// Bytes per event over all columns.
const PER_EVENT: u64 = 8 + 4 + 4 + 2;
/// Object id given to shot-noise and hot-pixel events (their flow is 0).
pub const NOISE_ID: u16 = u16::MAX;

/// Ground-truth flow and object of each event of a stream.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EventFlowGt {
    pub width: u32,
    pub height: u32,
    pub index: Vec<u64>,
    pub u: Vec<f32>,
    pub v: Vec<f32>,
    pub object: Vec<u16>,
}

impl EventFlowGt {
    pub fn len(&self) -> usize {
        self.index.len()
    }

    pub fn is_empty(&self) -> bool {
        self.index.is_empty()
    }

    fn check(&self) -> std::result::Result<(), String> {
        let n = self.index.len();
        if self.u.len() != n || self.v.len() != n || self.object.len() != n {
            return Err("column lengths differ".into());
        }
        if let Some(i) = (0..n).find(|&i| !(self.u[i].is_finite() && self.v[i].is_finite())) {
            return Err(format!("event {i}: flow is not finite"));
        }
        if let Some(i) = (1..n).find(|&i| self.index[i] <= self.index[i - 1]) {
            return Err(format!("event {i}: indices not strictly increasing"));
        }
        Ok(())
    }
}

/// Write `gt` atomically; refuses inconsistent or non-finite columns.
pub fn write_event_flow_gt(path: impl AsRef<Path>, gt: &EventFlowGt) -> Result<()> {
    let path = path.as_ref();
    gt.check().map_err(|m| Error::invalid(path, m))?;
    write_atomic(path, |w| {
        let mut header = [0u8; HEADER_LEN];
        header[..8].copy_from_slice(MAGIC);
        header[8..12].copy_from_slice(&VERSION.to_le_bytes());
        header[12..16].copy_from_slice(&gt.width.to_le_bytes());
        header[16..20].copy_from_slice(&gt.height.to_le_bytes());
        header[24..32].copy_from_slice(&(gt.len() as u64).to_le_bytes());
        w.write_all(&header)?;
        for i in &gt.index {
            w.write_all(&i.to_le_bytes())?;
        }
        for c in [&gt.u, &gt.v] {
            for x in c.iter() {
                w.write_all(&x.to_le_bytes())?;
            }
        }
        for o in &gt.object {
            w.write_all(&o.to_le_bytes())?;
        }
        Ok(())
    })
}

/// Read and check a `gt/event_flow.bin` (magic, version, exact size, finite flow,
/// increasing indices); errors name the file.
pub fn read_event_flow_gt(path: impl AsRef<Path>) -> Result<EventFlowGt> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).at(path)?;
    if bytes.len() < HEADER_LEN {
        return Err(Error::invalid(
            path,
            format!(
                "{} bytes, shorter than the {HEADER_LEN}-byte header",
                bytes.len()
            ),
        ));
    }
    if &bytes[..8] != MAGIC {
        return Err(Error::invalid(
            path,
            "not an event-flow ground-truth file (bad magic)",
        ));
    }
    let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
    let version = u32_at(8);
    if version != VERSION {
        return Err(Error::invalid(
            path,
            format!("unsupported version {version}"),
        ));
    }
    let (width, height) = (u32_at(12), u32_at(16));
    let n = u64::from_le_bytes(bytes[24..32].try_into().unwrap());
    let expected = n
        .checked_mul(PER_EVENT)
        .and_then(|b| b.checked_add(HEADER_LEN as u64));
    if expected != Some(bytes.len() as u64) {
        return Err(Error::invalid(
            path,
            format!(
                "header says {n} events but the file has {} bytes (truncated or corrupt)",
                bytes.len()
            ),
        ));
    }
    let n = n as usize;
    let mut off = HEADER_LEN;
    let mut take = |size: usize| {
        let s = &bytes[off..off + size * n];
        off += size * n;
        s
    };
    let index = take(8)
        .chunks_exact(8)
        .map(|c| u64::from_le_bytes(c.try_into().unwrap()))
        .collect();
    let f32s = |s: &[u8]| -> Vec<f32> {
        s.chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect()
    };
    let u = f32s(take(4));
    let v = f32s(take(4));
    let object = take(2)
        .chunks_exact(2)
        .map(|c| u16::from_le_bytes(c.try_into().unwrap()))
        .collect();
    let gt = EventFlowGt {
        width,
        height,
        index,
        u,
        v,
        object,
    };
    gt.check().map_err(|m| Error::invalid(path, m))?;
    Ok(gt)
}

/// Write object ids as a 16-bit grayscale PNG, atomically.
pub fn write_object_png(path: impl AsRef<Path>, w: u32, h: u32, ids: &[u16]) -> Result<()> {
    use image::ImageEncoder;
    let path = path.as_ref();
    if ids.len() != w as usize * h as usize || ids.is_empty() {
        return Err(Error::invalid(
            path,
            format!("{} ids for a {w}x{h} image", ids.len()),
        ));
    }
    // The encoder takes 16-bit samples in native byte order.
    let bytes: Vec<u8> = ids.iter().flat_map(|v| v.to_ne_bytes()).collect();
    let mut buf = Vec::new();
    image::codecs::png::PngEncoder::new(&mut buf)
        .write_image(&bytes, w, h, image::ExtendedColorType::L16)
        .map_err(|e| Error::invalid(path, format!("cannot encode PNG: {e}")))?;
    write_bytes_atomic(path, &buf)
}

/// Read an object-id PNG written by [`write_object_png`] (8- or 16-bit grayscale).
pub fn read_object_png(path: impl AsRef<Path>) -> Result<(u32, u32, Vec<u16>)> {
    let path = path.as_ref();
    let img = image::open(path).map_err(|e| Error::invalid(path, format!("cannot read: {e}")))?;
    match img {
        image::DynamicImage::ImageLuma16(b) => Ok((b.width(), b.height(), b.into_raw())),
        image::DynamicImage::ImageLuma8(b) => Ok((
            b.width(),
            b.height(),
            b.into_raw().into_iter().map(u16::from).collect(),
        )),
        other => Err(Error::invalid(
            path,
            format!("expected a grayscale id image, got {:?}", other.color()),
        )),
    }
}
