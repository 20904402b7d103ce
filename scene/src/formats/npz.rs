//! `.npz` events (HS-ERGB / TimeLens layout): a NumPy zip archive with 1-D arrays
//! `x`, `y`, `t` (µs) and `p`. Also accepted: `timestamp` for `t`, `polarity` for `p`.
//!
//! - `t`: any integer or float dtype, microseconds; converted to seconds as `t / 1e6`.
//! - `x`, `y`: any integer or float dtype holding whole pixels. HS-ERGB stores
//!   coordinates multiplied by 32 (sub-pixel positions after its rectification): pass
//!   `ReadOptions::coord_scale = Some(32.0)`, and the reader divides by 32 and rounds to
//!   the nearest pixel (pixel centres are at integer coordinates).
//! - `p`: bool or integers, `1` → +1, `0` or `−1` → −1.
//! - The sensor size is not stored: it comes from [`ReadOptions::sensor`].
//!
//! [`write_npz`] writes `x`,`y` as `<u2`, `t` as `<i8` microseconds (rounded) and `p` as
//! `|i1` ±1, uncompressed. Round trips are bit-exact for streams whose timestamps are
//! whole microseconds (`t = k / 1e6`), which is what this format can hold.
//! Read with the `zip` crate and `npyz::NpyFile` (not npyz's own npz feature).

use super::{ReadOptions, check, resolve_sensor};
use crate::atomic::write_atomic;
use crate::error::{Error, IoContext, Result};
use crate::events::EventStream;
use npyz::{TypeChar, WriterBuilder};
use std::io::{Read, Write};
use std::path::Path;

/// Deflate expands its input at most 1032-fold: a member claiming more is corrupt.
const MAX_DEFLATE_RATIO: u64 = 1032;

/// A numeric column as stored (integers kept exact).
enum Column {
    Int(Vec<i64>),
    Float(Vec<f64>),
}

impl Column {
    fn len(&self) -> usize {
        match self {
            Column::Int(v) => v.len(),
            Column::Float(v) => v.len(),
        }
    }
}

/// Read an `.npz` event file.
pub fn read_npz(path: impl AsRef<Path>, opts: &ReadOptions) -> Result<EventStream> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).at(path)?;
    if bytes.is_empty() {
        return Err(Error::invalid(path, "file is empty"));
    }
    let (width, height) = resolve_sensor(path, None, opts)?;
    let scale = opts.coord_scale.unwrap_or(1.0);
    if !(scale.is_finite() && scale > 0.0) {
        return Err(Error::invalid(
            path,
            format!("coord_scale {scale} must be finite and > 0"),
        ));
    }
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(&bytes))
        .map_err(|e| Error::invalid(path, format!("not a valid .npz (zip) archive: {e}")))?;
    let mut column = |names: &[&str]| -> Result<Column> {
        let name = names
            .iter()
            .map(|n| format!("{n}.npy"))
            .find(|n| zip.index_for_name(n).is_some())
            .ok_or_else(|| {
                let have: Vec<String> = zip
                    .file_names()
                    .map(|n| n.map(|c| c.to_string()).unwrap_or_default())
                    .collect();
                Error::invalid(
                    path,
                    format!("no array {:?} in the archive (it holds {have:?})", names[0]),
                )
            })?;
        read_column(path, &mut zip, &name)
    };
    let x = column(&["x"])?;
    let y = column(&["y"])?;
    let t = column(&["t", "timestamp"])?;
    let p = column(&["p", "polarity"])?;
    let n = t.len();
    if x.len() != n || y.len() != n || p.len() != n {
        return Err(Error::invalid(
            path,
            format!(
                "array lengths differ: x {}, y {}, t {n}, p {}",
                x.len(),
                y.len(),
                p.len()
            ),
        ));
    }
    let coords = |c: &Column, axis: &str, size: u32| -> Result<Vec<u16>> {
        let to_pixel = |i: usize, v: f64| -> Result<u16> {
            let px = (v / scale).round();
            if v.is_finite() && px >= 0.0 && px < size as f64 {
                Ok(px as u16)
            } else {
                Err(Error::invalid(
                    path,
                    format!(
                        "event {i}: {axis} = {v} (÷ {scale}) is outside the sensor (0..{size})"
                    ),
                ))
            }
        };
        match c {
            Column::Int(v) => v
                .iter()
                .enumerate()
                .map(|(i, &v)| to_pixel(i, v as f64))
                .collect(),
            Column::Float(v) => v
                .iter()
                .enumerate()
                .map(|(i, &v)| {
                    if scale == 1.0 && v.fract() != 0.0 {
                        Err(Error::invalid(
                            path,
                            format!("event {i}: {axis} = {v} is not a whole pixel (coord_scale?)"),
                        ))
                    } else {
                        to_pixel(i, v)
                    }
                })
                .collect(),
        }
    };
    let ev = EventStream {
        width,
        height,
        x: coords(&x, "x", width)?,
        y: coords(&y, "y", height)?,
        t: match t {
            Column::Int(v) => v.iter().map(|&us| us as f64 / 1e6).collect(),
            Column::Float(v) => v.iter().map(|&us| us / 1e6).collect(),
        },
        p: match p {
            Column::Int(v) => v
                .iter()
                .enumerate()
                .map(|(i, &p)| match p {
                    1 => Ok(1),
                    0 | -1 => Ok(-1),
                    _ => Err(Error::invalid(
                        path,
                        format!("event {i}: polarity {p} is not 0/1/±1"),
                    )),
                })
                .collect::<Result<_>>()?,
            Column::Float(_) => {
                return Err(Error::invalid(path, "polarity array has a float dtype"));
            }
        },
    };
    check(path, &ev)?;
    Ok(ev)
}

/// Read one 1-D numeric `.npy` member of the archive.
fn read_column(
    path: &Path,
    zip: &mut zip::ZipArchive<std::io::Cursor<&Vec<u8>>>,
    name: &str,
) -> Result<Column> {
    let bad = |msg: String| Error::invalid(path, format!("{name}: {msg}"));
    let mut entry = zip
        .by_name(name)
        .map_err(|e| bad(format!("cannot open: {e}")))?;
    // Read the member fully so a lying npy header cannot make the npy reader allocate
    // more than the data holds. The zip's declared size is not trusted for the buffer:
    // it grows with what actually decompresses, at most the declared size and at most
    // what deflate can expand the stored bytes to.
    let limit = entry
        .size()
        .min(entry.compressed_size().saturating_mul(MAX_DEFLATE_RATIO) + 1024);
    let mut data = Vec::new();
    (&mut entry)
        .take(limit)
        .read_to_end(&mut data)
        .map_err(|e| bad(format!("cannot decompress: {e}")))?;
    if (data.len() as u64) < entry.size() {
        return Err(bad(format!(
            "declares {} bytes but holds {} (truncated or corrupt)",
            entry.size(),
            data.len()
        )));
    }
    let mut body: &[u8] = &data;
    let header = npyz::NpyHeader::from_reader(&mut body)
        .map_err(|e| bad(format!("not a valid .npy: {e}")))?;
    let body_len = body.len();
    let npy = npyz::NpyFile::with_header(header, body);
    if npy.shape().len() != 1 {
        return Err(bad(format!(
            "expected a 1-D array, shape is {:?}",
            npy.shape()
        )));
    }
    let ts = match npy.dtype() {
        npyz::DType::Plain(ts) => ts,
        other => return Err(bad(format!("unsupported dtype {}", other.descr()))),
    };
    let n = npy.shape()[0];
    let item = ts.size_field();
    if n.checked_mul(item).is_none_or(|b| b > body_len as u64) {
        return Err(bad(format!(
            "header declares {n} items of {item} bytes but {body_len} data bytes follow (truncated)"
        )));
    }
    // Fast path: little-endian (or byte-sized) plain numbers are decoded straight from
    // the bytes; npyz's element reader handles the rest (big-endian files).
    if ts.endianness() != npyz::Endianness::Big {
        let raw = &data[data.len() - body_len..][..(n * item) as usize];
        if let Some(c) = decode_le(ts.type_char(), item as usize, raw) {
            return Ok(c);
        }
    }
    let io = |e: std::io::Error| bad(format!("cannot read data: {e}"));
    let ints = |v: Vec<i64>| Ok(Column::Int(v));
    match (ts.type_char(), item) {
        (TypeChar::Bool, 1) => ints(
            npy.into_vec::<bool>()
                .map_err(io)?
                .into_iter()
                .map(i64::from)
                .collect(),
        ),
        (TypeChar::Int, 1) => ints(widen(npy.into_vec::<i8>().map_err(io)?)),
        (TypeChar::Int, 2) => ints(widen(npy.into_vec::<i16>().map_err(io)?)),
        (TypeChar::Int, 4) => ints(widen(npy.into_vec::<i32>().map_err(io)?)),
        (TypeChar::Int, 8) => ints(npy.into_vec::<i64>().map_err(io)?),
        (TypeChar::Uint, 1) => ints(widen(npy.into_vec::<u8>().map_err(io)?)),
        (TypeChar::Uint, 2) => ints(widen(npy.into_vec::<u16>().map_err(io)?)),
        (TypeChar::Uint, 4) => ints(widen(npy.into_vec::<u32>().map_err(io)?)),
        (TypeChar::Uint, 8) => npy
            .into_vec::<u64>()
            .map_err(io)?
            .into_iter()
            .map(|v| i64::try_from(v).map_err(|_| bad(format!("value {v} too large"))))
            .collect::<Result<_>>()
            .map(Column::Int),
        (TypeChar::Float, 4) => Ok(Column::Float(
            npy.into_vec::<f32>()
                .map_err(io)?
                .into_iter()
                .map(f64::from)
                .collect(),
        )),
        (TypeChar::Float, 8) => Ok(Column::Float(npy.into_vec::<f64>().map_err(io)?)),
        _ => Err(bad(format!("unsupported dtype {ts}"))),
    }
}

/// Decode little-endian numbers; `None` for types this fast path does not cover.
fn decode_le(kind: TypeChar, item: usize, raw: &[u8]) -> Option<Column> {
    fn ints<const N: usize>(raw: &[u8], f: impl Fn([u8; N]) -> i64) -> Column {
        Column::Int(
            raw.chunks_exact(N)
                .map(|c| f(c.try_into().unwrap_or([0; N])))
                .collect(),
        )
    }
    Some(match (kind, item) {
        (TypeChar::Bool, 1) | (TypeChar::Uint, 1) => ints::<1>(raw, |b| b[0] as i64),
        (TypeChar::Int, 1) => ints::<1>(raw, |b| b[0] as i8 as i64),
        (TypeChar::Int, 2) => ints::<2>(raw, |b| i16::from_le_bytes(b) as i64),
        (TypeChar::Uint, 2) => ints::<2>(raw, |b| u16::from_le_bytes(b) as i64),
        (TypeChar::Int, 4) => ints::<4>(raw, |b| i32::from_le_bytes(b) as i64),
        (TypeChar::Uint, 4) => ints::<4>(raw, |b| u32::from_le_bytes(b) as i64),
        (TypeChar::Int, 8) => ints::<8>(raw, i64::from_le_bytes),
        (TypeChar::Float, 4) => Column::Float(
            raw.chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().unwrap_or([0; 4])) as f64)
                .collect(),
        ),
        (TypeChar::Float, 8) => Column::Float(
            raw.chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8])))
                .collect(),
        ),
        _ => return None,
    })
}

fn widen<T: Into<i64>>(v: Vec<T>) -> Vec<i64> {
    v.into_iter().map(Into::into).collect()
}

/// Serialise one 1-D array as `.npy` bytes.
fn npy_bytes<T: npyz::AutoSerialize>(data: &[T]) -> std::io::Result<Vec<u8>> {
    let mut out = Vec::new();
    let mut w = npyz::WriteOptions::new()
        .default_dtype()
        .shape(&[data.len() as u64])
        .writer(&mut out)
        .begin_nd()?;
    w.extend(data)?;
    w.finish()?;
    Ok(out)
}

/// Write `x`, `y` (`<u2`), `t` (`<i8` µs, rounded) and `p` (`|i1` ±1). Atomic.
pub fn write_npz(path: impl AsRef<Path>, ev: &EventStream) -> Result<()> {
    let path = path.as_ref();
    check(path, ev)?;
    let t_us: Vec<i64> = ev.t.iter().map(|&t| (t * 1e6).round() as i64).collect();
    let members = [
        ("x.npy", npy_bytes(&ev.x)),
        ("y.npy", npy_bytes(&ev.y)),
        ("t.npy", npy_bytes(&t_us)),
        ("p.npy", npy_bytes(&ev.p)),
    ];
    write_atomic(path, |w| {
        let mut zip = zip::ZipWriter::new(w);
        for (name, bytes) in members {
            let bytes = bytes?;
            let options = zip::write::SimpleFileOptions::default()
                .compression_method(zip::CompressionMethod::Stored)
                .large_file(bytes.len() as u64 >= u32::MAX as u64);
            zip.start_file(name, options)
                .map_err(std::io::Error::other)?;
            zip.write_all(&bytes)?;
        }
        zip.finish().map_err(std::io::Error::other)?;
        Ok(())
    })
}
