//! The APS frames of an AEDAT 4.0 file (`FRME` streams of DAVIS cameras), so one DAVIS
//! recording gives both modalities. The container (header, packets, compression) is
//! read by [`super::aedat4`].
//!
//! A frame packet's decompressed body is a size-prefixed FlatBuffer with file identifier
//! `FRME` whose root table is one frame (dv-processing's `Frame`): fields 0 `timestamp`
//! (i64 µs, the exposure midpoint), 1–2 start/end of frame, 3–4 start/end of exposure
//! (i64 µs), 5 `format` (i8: 0 grey, 16 BGR, 24 BGRA, OpenCV's `CV_8UCn`), 6–7
//! `sizeX`/`sizeY` (i16), 8–9 `positionX`/`positionY` (i16, the region of interest's
//! offset), 10 `pixels` (u8 vector, row-major, channels interleaved). Frames of the
//! lowest-numbered `FRME` stream are returned in file order, timestamps as seconds
//! (`µs / 1e6`, the events' clock), colour as RGB (alpha dropped).

use super::aedat4::{Flat, decompress, open};
use crate::error::{Error, Result};
use rayon::prelude::*;
use std::path::Path;

/// One APS frame.
#[derive(Clone, Debug, PartialEq)]
pub struct ApsFrame {
    /// Exposure midpoint, seconds.
    pub timestamp: f64,
    /// Start and end of the exposure, seconds.
    pub exposure: (f64, f64),
    pub width: u32,
    pub height: u32,
    /// Offset of the frame in the sensor (0, 0 for a full frame).
    pub position: (u32, u32),
    /// 1 (grey) or 3 (RGB).
    pub channels: u32,
    /// Row-major, channels interleaved.
    pub pixels: Vec<u8>,
}

/// Read the frames of the first `FRME` stream (empty when the file has none).
pub fn read_aedat4_frames(path: impl AsRef<Path>) -> Result<Vec<ApsFrame>> {
    let path = path.as_ref();
    let file = open(path)?;
    let Some(stream) = file
        .streams
        .iter()
        .filter(|s| s.type_id == "FRME")
        .min_by_key(|s| s.id)
    else {
        return Ok(Vec::new());
    };
    let decoded: Vec<Result<Option<ApsFrame>>> = file
        .packets
        .par_iter()
        .filter(|(_, id, _, _)| *id == stream.id)
        .map(|(k, _, at, range)| {
            decompress(file.compression, &file.data[range.clone()])
                .and_then(|buf| decode_frame(&buf))
                .map_err(|m| Error::invalid(path, format!("packet {k} at byte {at}: {m}")))
        })
        .collect();
    let mut frames = Vec::new();
    for f in decoded {
        if let Some(f) = f? {
            frames.push(f);
        }
    }
    if let Some(i) = frames
        .windows(2)
        .position(|w| w[1].timestamp < w[0].timestamp)
    {
        return Err(Error::invalid(
            path,
            format!(
                "frame {}: timestamp {} s before the previous frame's {} s",
                i + 1,
                frames[i + 1].timestamp,
                frames[i].timestamp
            ),
        ));
    }
    Ok(frames)
}

/// Decode one decompressed `FRME` body; `Ok(None)` if it is another packet type.
fn decode_frame(buf: &[u8]) -> std::result::Result<Option<ApsFrame>, String> {
    let size = Flat { buf }.u32(0)? as usize;
    let fb = buf
        .get(4..)
        .filter(|b| b.len() >= size && size >= 8)
        .ok_or_else(|| format!("size prefix {size} does not fit the {} bytes", buf.len()))?;
    if &fb[4..8] != b"FRME" {
        return Ok(None);
    }
    let f = Flat { buf: &fb[..size] };
    let root = f.root()?;
    let int64 = |i: usize| -> std::result::Result<i64, String> {
        f.field(root, i)?.map_or(Ok(0), |p| f.i64(p))
    };
    let int16 = |i: usize| -> std::result::Result<i64, String> {
        f.field(root, i)?
            .map_or(Ok(0), |p| f.u16(p).map(|v| v as i16 as i64))
    };
    let format = match f.field(root, 5)? {
        Some(p) => f.bytes::<1>(p)?[0] as i8,
        None => 0,
    };
    let channels: usize = match format {
        0 => 1,
        16 => 3,
        24 => 4,
        other => return Err(format!("frame format {other} is not grey, BGR or BGRA")),
    };
    let (w, h, px, py) = (int16(6)?, int16(7)?, int16(8)?, int16(9)?);
    if w <= 0 || h <= 0 || px < 0 || py < 0 {
        return Err(format!(
            "frame size {w}x{h} at ({px}, {py}) is not a usable region"
        ));
    }
    let (w, h) = (w as usize, h as usize);
    let pixels = match f.field(root, 10)? {
        Some(p) => f.vector(f.deref(p)?, 1)?,
        None => &[][..],
    };
    if pixels.len() != w * h * channels {
        return Err(format!(
            "frame of {w}x{h}x{channels} has {} pixel bytes, expected {}",
            pixels.len(),
            w * h * channels
        ));
    }
    // BGR(A) → RGB.
    let pixels = if channels == 1 {
        pixels.to_vec()
    } else {
        pixels
            .chunks_exact(channels)
            .flat_map(|c| [c[2], c[1], c[0]])
            .collect()
    };
    let us = |v: i64| v as f64 / 1e6;
    Ok(Some(ApsFrame {
        timestamp: us(int64(0)?),
        exposure: (us(int64(3)?), us(int64(4)?)),
        width: w as u32,
        height: h as u32,
        position: (px as u32, py as u32),
        channels: channels.min(3) as u32,
        pixels,
    }))
}
