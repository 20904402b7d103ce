//! Per-event flow files `.evflow` (`docs/DESIGN.md` §3) and Middlebury `.flo` dense
//! previews: written by `evflow`, read by `deform` and `degs eval` (here, in the data
//! layer, so that a reader of flows needs no flow network).
//!
//! **`.evflow`**, little-endian, an 88-byte header followed by three columns:
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 8 | magic `DEGSEVFL` |
//! | 8 | 4 | version `u32` = 1 |
//! | 12 | 4 | width `u32` (sensor) |
//! | 16 | 4 | height `u32` |
//! | 20 | 4 | reserved, 0 |
//! | 24 | 8 | window start `t_a` (`f64`, s) |
//! | 32 | 8 | window end `t_b` (`f64`, s) |
//! | 40 | 8 | reference time `t_ref` (`f64`, s) |
//! | 48 | 8 | event count `n` (`u64`) |
//! | 56 | 32 | source-stream hash (BLAKE3 of the `.evs` column bytes, [`crate::formats::evs::content_hash`]) |
//! | 88 | 8n | event index into the source stream (`u64`, strictly increasing) |
//! | 88 + 8n | 4n | flow `u`, px/s (`f32`, right) |
//! | 88 + 12n | 4n | flow `v`, px/s (`f32`, down) |
//!
//! The file size must be exactly `88 + 16n`. The flow of event k moves it to
//! `x − (t_k − t_ref)·(u, v)` at `t_ref`. Readers check magic, version, sizes (before
//! allocating: a hostile count cannot make them allocate), the window, finiteness and
//! index order, and name the file in every error.
//!
//! **`.flo`** (Middlebury): `f32` 202021.25, `i32` width, `i32` height, then `u v`
//! interleaved per pixel, row-major, in pixels of displacement over the window.

use crate::atomic::write_atomic;
use crate::error::{Error, IoContext, Result};
use std::io::Write;
use std::path::Path;

pub const MAGIC: &[u8; 8] = b"DEGSEVFL";
pub const VERSION: u32 = 1;
pub const HEADER_LEN: usize = 88;
/// Bytes per event over all columns.
pub(crate) const BYTES_PER_EVENT: usize = 16;
/// Magic number of Middlebury `.flo` files.
pub(crate) const FLO_MAGIC: f32 = 202021.25;

/// The per-event flow of one window.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EvFlow {
    pub width: u32,
    pub height: u32,
    pub t_a: f64,
    pub t_b: f64,
    pub t_ref: f64,
    pub source_hash: [u8; 32],
    /// Index of each event in the source stream.
    pub index: Vec<u64>,
    /// px/s.
    pub u: Vec<f32>,
    /// px/s.
    pub v: Vec<f32>,
}

impl EvFlow {
    pub fn len(&self) -> usize {
        self.index.len()
    }

    pub fn is_empty(&self) -> bool {
        self.index.is_empty()
    }

    /// `Err` with a sentence when the content breaks an invariant of the format.
    pub fn check(&self) -> std::result::Result<(), String> {
        let n = self.index.len();
        if self.u.len() != n || self.v.len() != n {
            return Err(format!(
                "column lengths differ: index {n}, u {}, v {}",
                self.u.len(),
                self.v.len()
            ));
        }
        if self.width == 0 || self.height == 0 {
            return Err(format!(
                "sensor size {}x{} is empty",
                self.width, self.height
            ));
        }
        if !(self.t_a.is_finite() && self.t_b.is_finite() && self.t_ref.is_finite()) {
            return Err("window times are not finite".into());
        }
        if self.t_b < self.t_a {
            return Err(format!(
                "window [{}, {}] ends before it starts",
                self.t_a, self.t_b
            ));
        }
        if let Some(i) = (0..n).find(|&i| !(self.u[i].is_finite() && self.v[i].is_finite())) {
            return Err(format!("event {i}: flow is not finite"));
        }
        if let Some(i) = (1..n).find(|&i| self.index[i] <= self.index[i - 1]) {
            return Err(format!("event {i}: event indices not strictly increasing"));
        }
        Ok(())
    }
}

/// Write `flow` atomically; refuses content that [`EvFlow::check`] rejects.
pub fn write_evflow(path: &Path, flow: &EvFlow) -> Result<()> {
    flow.check().map_err(|m| Error::invalid(path, m))?;
    write_atomic(path, |w| {
        let mut h = [0u8; HEADER_LEN];
        h[..8].copy_from_slice(MAGIC);
        h[8..12].copy_from_slice(&VERSION.to_le_bytes());
        h[12..16].copy_from_slice(&flow.width.to_le_bytes());
        h[16..20].copy_from_slice(&flow.height.to_le_bytes());
        h[24..32].copy_from_slice(&flow.t_a.to_le_bytes());
        h[32..40].copy_from_slice(&flow.t_b.to_le_bytes());
        h[40..48].copy_from_slice(&flow.t_ref.to_le_bytes());
        h[48..56].copy_from_slice(&(flow.len() as u64).to_le_bytes());
        h[56..88].copy_from_slice(&flow.source_hash);
        w.write_all(&h)?;
        let mut buf = Vec::with_capacity(1 << 16);
        for c in flow.index.chunks(8192) {
            buf.clear();
            c.iter()
                .for_each(|x| buf.extend_from_slice(&x.to_le_bytes()));
            w.write_all(&buf)?;
        }
        for col in [&flow.u, &flow.v] {
            for c in col.chunks(8192) {
                buf.clear();
                c.iter()
                    .for_each(|x| buf.extend_from_slice(&x.to_le_bytes()));
                w.write_all(&buf)?;
            }
        }
        Ok(())
    })
}

fn u32_at(b: &[u8], o: usize) -> u32 {
    u32::from_le_bytes(b[o..o + 4].try_into().expect("4 bytes"))
}

fn u64_at(b: &[u8], o: usize) -> u64 {
    u64::from_le_bytes(b[o..o + 8].try_into().expect("8 bytes"))
}

fn f64_at(b: &[u8], o: usize) -> f64 {
    f64::from_le_bytes(b[o..o + 8].try_into().expect("8 bytes"))
}

/// Parse the header of an `.evflow` file: `(flow without columns, event count)`.
fn parse_header(path: &Path, h: &[u8], file_len: u64) -> Result<(EvFlow, usize)> {
    if h.len() < HEADER_LEN {
        return Err(Error::invalid(
            path,
            format!(
                "truncated: {} bytes, shorter than the {HEADER_LEN}-byte header",
                h.len()
            ),
        ));
    }
    if &h[..8] != MAGIC {
        return Err(Error::invalid(path, "not an .evflow file (bad magic)"));
    }
    let version = u32_at(h, 8);
    if version != VERSION {
        return Err(Error::invalid(
            path,
            format!("unsupported .evflow version {version} (this build reads {VERSION})"),
        ));
    }
    let n = u64_at(h, 48);
    let want = n
        .checked_mul(BYTES_PER_EVENT as u64)
        .and_then(|b| b.checked_add(HEADER_LEN as u64));
    if want != Some(file_len) {
        return Err(Error::invalid(
            path,
            format!(
                "size {file_len} bytes does not match the header's {n} events ({}): truncated or corrupt",
                want.map_or("overflow".to_string(), |w| format!("{w} bytes expected"))
            ),
        ));
    }
    let n = usize::try_from(n).map_err(|_| Error::invalid(path, "event count too large"))?;
    let mut source_hash = [0u8; 32];
    source_hash.copy_from_slice(&h[56..88]);
    let flow = EvFlow {
        width: u32_at(h, 12),
        height: u32_at(h, 16),
        t_a: f64_at(h, 24),
        t_b: f64_at(h, 32),
        t_ref: f64_at(h, 40),
        source_hash,
        ..Default::default()
    };
    Ok((flow, n))
}

/// Read an `.evflow` file written by [`write_evflow`], checking everything.
pub fn read_evflow(path: &Path) -> Result<EvFlow> {
    use std::io::Read;
    let mut file = std::fs::File::open(path).at(path)?;
    let file_len = file.metadata().at(path)?.len();
    let mut header = Vec::with_capacity(HEADER_LEN);
    (&mut file)
        .take(HEADER_LEN as u64)
        .read_to_end(&mut header)
        .at(path)?;
    let (mut flow, n) = parse_header(path, &header, file_len)?;
    // The size matches the file on disk, so this allocation is bounded by the file.
    let mut body = Vec::with_capacity(n * BYTES_PER_EVENT);
    file.read_to_end(&mut body).at(path)?;
    if body.len() != n * BYTES_PER_EVENT {
        return Err(Error::invalid(
            path,
            "file changed while reading (truncated)",
        ));
    }
    let (idx, rest) = body.split_at(8 * n);
    let (u, v) = rest.split_at(4 * n);
    flow.index = idx
        .chunks_exact(8)
        .map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes")))
        .collect();
    let f32s = |b: &[u8]| -> Vec<f32> {
        b.chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect()
    };
    flow.u = f32s(u);
    flow.v = f32s(v);
    flow.check().map_err(|m| Error::invalid(path, m))?;
    Ok(flow)
}

/// Write a dense displacement field (px over the window) as Middlebury `.flo`.
pub fn write_flo(path: &Path, width: u32, height: u32, u: &[f32], v: &[f32]) -> Result<()> {
    let n = width as usize * height as usize;
    if u.len() != n || v.len() != n {
        return Err(Error::invalid(
            path,
            "flow field size does not match width x height",
        ));
    }
    if u.iter().chain(v).any(|x| !x.is_finite()) {
        return Err(Error::invalid(path, "flow field is not finite"));
    }
    let (wi, hi) = (
        i32::try_from(width).map_err(|_| Error::invalid(path, "too wide for .flo"))?,
        i32::try_from(height).map_err(|_| Error::invalid(path, "too tall for .flo"))?,
    );
    write_atomic(path, |w| {
        w.write_all(&FLO_MAGIC.to_le_bytes())?;
        w.write_all(&wi.to_le_bytes())?;
        w.write_all(&hi.to_le_bytes())?;
        let mut buf = Vec::with_capacity(8 * n);
        for i in 0..n {
            buf.extend_from_slice(&u[i].to_le_bytes());
            buf.extend_from_slice(&v[i].to_le_bytes());
        }
        w.write_all(&buf)
    })
}

/// Read a Middlebury `.flo` file: `(width, height, u, v)` in px of displacement.
pub fn read_flo(path: &Path) -> Result<(u32, u32, Vec<f32>, Vec<f32>)> {
    let bytes = std::fs::read(path).at(path)?;
    if bytes.len() < 12 {
        return Err(Error::invalid(path, "truncated .flo header"));
    }
    let magic = f32::from_le_bytes(bytes[0..4].try_into().expect("4 bytes"));
    if magic != FLO_MAGIC {
        return Err(Error::invalid(
            path,
            "not a Middlebury .flo file (bad magic)",
        ));
    }
    let w = i32::from_le_bytes(bytes[4..8].try_into().expect("4 bytes"));
    let h = i32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
    if w <= 0 || h <= 0 {
        return Err(Error::invalid(path, format!("bad .flo size {w}x{h}")));
    }
    let n = w as u64 * h as u64;
    if 12 + 8 * n != bytes.len() as u64 {
        return Err(Error::invalid(
            path,
            format!(
                "size {} bytes does not match {w}x{h}: truncated or corrupt",
                bytes.len()
            ),
        ));
    }
    let vals: Vec<f32> = bytes[12..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
        .collect();
    if vals.iter().any(|x| !x.is_finite()) {
        return Err(Error::invalid(path, "flow is not finite"));
    }
    let u = vals.iter().step_by(2).copied().collect();
    let v = vals.iter().skip(1).step_by(2).copied().collect();
    Ok((w as u32, h as u32, u, v))
}

/// Colour-wheel visualisation (Baker et al. / Middlebury colour coding): hue = direction,
/// saturation = magnitude / `max_mag` (the largest magnitude when `None`). Returns
/// interleaved RGB in [0, 1].
pub fn color_wheel(u: &[f32], v: &[f32], max_mag: Option<f32>) -> Vec<f32> {
    let max = max_mag.unwrap_or_else(|| {
        u.iter()
            .zip(v)
            .map(|(a, b)| (a * a + b * b).sqrt())
            .filter(|m| m.is_finite())
            .fold(0.0f32, f32::max)
    });
    let mut out = Vec::with_capacity(3 * u.len());
    for (&a, &b) in u.iter().zip(v) {
        let m = (a * a + b * b).sqrt();
        if !m.is_finite() || max <= 0.0 {
            out.extend_from_slice(&[1.0, 1.0, 1.0]);
            continue;
        }
        let s = (m / max).min(1.0);
        // Hue in [0, 6): 0 = right (red), counter-clockwise in image axes (v down).
        let angle = (-b).atan2(a);
        let hue = (angle / std::f32::consts::TAU).rem_euclid(1.0) * 6.0;
        let sector = hue.floor();
        let f = hue - sector;
        let rgb = match sector as i32 {
            0 => [1.0, f, 0.0],
            1 => [1.0 - f, 1.0, 0.0],
            2 => [0.0, 1.0, f],
            3 => [0.0, 1.0 - f, 1.0],
            4 => [f, 0.0, 1.0],
            _ => [1.0, 0.0, 1.0 - f],
        };
        // White at zero flow, full colour at max.
        out.extend(rgb.iter().map(|c| 1.0 - s * (1.0 - c)));
    }
    out
}
