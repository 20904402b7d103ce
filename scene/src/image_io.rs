//! Images and EXR maps (DESIGN §3).
//!
//! - [`Image`]: `f32` pixels, row-major, channels interleaved. Colour values are in
//!   [0, 1] and **linear in the stored 8-bit code** (`v = code / 255`, no sRGB gamma
//!   curve), so the event generation model (log of these values) and the frames agree.
//! - PNG/JPEG: [`read_image`] always returns 3 channels (grey is replicated; an alpha
//!   channel is composited over a white background, the D-NeRF convention; 16-bit PNGs
//!   are divided by 65535). [`write_png`] writes 8-bit grey or RGB; `read_image` of a
//!   written PNG gives back exactly the codes written.
//! - EXR (f32, lossless ZIP compression, bit-exact round trip): depth in channel `Z`,
//!   optical flow in `U`,`V` (px/s), colour in `R`,`G`,`B`.
//!
//! Every writer is atomic; every reader checks sizes, channel names and finiteness and
//! names the file in its errors. Decoders of third-party crates run under
//! `catch_unwind`, so hostile files give an error, never a panic.

use crate::atomic::write_atomic;
use crate::error::{Error, IoContext, Result};
use exr::prelude as x;
use std::io;
use std::path::Path;

/// An sRGB-encoded value in `[0, 1]` → linear intensity (IEC 61966-2-1): what an 8-bit
/// frame's code means unless its manifest says `frame_encoding: linear`.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.040_45 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear intensity in `[0, 1]` → its sRGB code value, the inverse of [`srgb_to_linear`].
pub fn linear_to_srgb(c: f32) -> f32 {
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// An `f32` image, row-major with interleaved channels.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub channels: u32,
    pub data: Vec<f32>,
}

impl Image {
    /// An image filled with zeros.
    pub fn new(width: u32, height: u32, channels: u32) -> Self {
        Image {
            width,
            height,
            channels,
            data: vec![0.0; width as usize * height as usize * channels as usize],
        }
    }

    /// Number of pixels.
    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Value of channel `c` at pixel `(x, y)`.
    pub fn get(&self, x: u32, y: u32, c: u32) -> f32 {
        self.data
            [(y as usize * self.width as usize + x as usize) * self.channels as usize + c as usize]
    }

    /// Luminance (Rec. 709 weights on the linear values) as a 1-channel image; a
    /// 1-channel image is returned as is.
    pub fn luminance(&self) -> Image {
        if self.channels == 1 {
            return self.clone();
        }
        let c = self.channels as usize;
        let data = self
            .data
            .chunks_exact(c)
            .map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2])
            .collect();
        Image {
            width: self.width,
            height: self.height,
            channels: 1,
            data,
        }
    }

    fn check_len(&self, path: &Path) -> Result<()> {
        let want = self.pixels() * self.channels as usize;
        if self.data.len() != want || self.width == 0 || self.height == 0 {
            return Err(Error::invalid(
                path,
                format!(
                    "image data has {} values, expected {}x{}x{} = {want} (non-empty)",
                    self.data.len(),
                    self.width,
                    self.height,
                    self.channels
                ),
            ));
        }
        Ok(())
    }
}

/// Run a third-party decoder, turning a panic into an error about `path`.
fn guarded<T>(path: &Path, f: impl FnOnce() -> Result<T>) -> Result<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f))
        .unwrap_or_else(|_| Err(Error::invalid(path, "decoder panicked on corrupt input")))
}

/// Read a PNG or JPEG as a 3-channel linear image (values `code / max`).
pub fn read_image(path: impl AsRef<Path>) -> Result<Image> {
    use image::DynamicImage as D;
    let path = path.as_ref();
    let bytes = std::fs::read(path).at(path)?;
    let img = guarded(path, || {
        image::load_from_memory(&bytes)
            .map_err(|e| Error::invalid(path, format!("cannot decode image: {e}")))
    })?;
    let (w, h) = (img.width(), img.height());
    let n = w as usize * h as usize;
    let mut data = Vec::with_capacity(n * 3);
    // `alpha` composites over white: v·a + (1 − a).
    fn push_rgba(data: &mut Vec<f32>, rgb: [f32; 3], a: f32) {
        for v in rgb {
            data.push(v * a + (1.0 - a));
        }
    }
    match &img {
        D::ImageLuma8(b) => b.pixels().for_each(|p| {
            let v = p.0[0] as f32 / 255.0;
            data.extend([v, v, v]);
        }),
        D::ImageLumaA8(b) => b.pixels().for_each(|p| {
            let v = p.0[0] as f32 / 255.0;
            push_rgba(&mut data, [v; 3], p.0[1] as f32 / 255.0);
        }),
        D::ImageRgb8(b) => data.extend(b.as_raw().iter().map(|&c| c as f32 / 255.0)),
        D::ImageRgba8(b) => b.pixels().for_each(|p| {
            let c = p.0.map(|c| c as f32 / 255.0);
            push_rgba(&mut data, [c[0], c[1], c[2]], c[3]);
        }),
        D::ImageLuma16(b) => b.pixels().for_each(|p| {
            let v = p.0[0] as f32 / 65535.0;
            data.extend([v, v, v]);
        }),
        D::ImageLumaA16(b) => b.pixels().for_each(|p| {
            let v = p.0[0] as f32 / 65535.0;
            push_rgba(&mut data, [v; 3], p.0[1] as f32 / 65535.0);
        }),
        D::ImageRgb16(b) => data.extend(b.as_raw().iter().map(|&c| c as f32 / 65535.0)),
        D::ImageRgba16(b) => b.pixels().for_each(|p| {
            let c = p.0.map(|c| c as f32 / 65535.0);
            push_rgba(&mut data, [c[0], c[1], c[2]], c[3]);
        }),
        other => {
            return Err(Error::invalid(
                path,
                format!("unsupported pixel type {:?}", other.color()),
            ));
        }
    }
    Ok(Image {
        width: w,
        height: h,
        channels: 3,
        data,
    })
}

/// Write a 1- or 3-channel image as an 8-bit PNG (`code = round(v · 255)`, values
/// clamped to [0, 1]); non-finite values are an error. Atomic.
pub fn write_png(path: impl AsRef<Path>, img: &Image) -> Result<()> {
    use image::ImageEncoder;
    let path = path.as_ref();
    img.check_len(path)?;
    let color = match img.channels {
        1 => image::ExtendedColorType::L8,
        3 => image::ExtendedColorType::Rgb8,
        c => {
            return Err(Error::invalid(
                path,
                format!("write_png takes 1 or 3 channels, got {c}"),
            ));
        }
    };
    if let Some(i) = img.data.iter().position(|v| !v.is_finite()) {
        return Err(Error::invalid(
            path,
            format!("value {i} is {} (not finite)", img.data[i]),
        ));
    }
    let codes: Vec<u8> = img
        .data
        .iter()
        .map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    write_atomic(path, |w| {
        image::codecs::png::PngEncoder::new(w)
            .write_image(&codes, img.width, img.height, color)
            .map_err(io::Error::other)
    })
}

/// Write named f32 channels of a `w × h` image as a lossless EXR, atomically.
/// Non-finite values are refused (no reader would accept them).
fn write_exr_channels(path: &Path, w: u32, h: u32, channels: &[(&str, &[f32])]) -> Result<()> {
    let n = w as usize * h as usize;
    if n == 0 {
        return Err(Error::invalid(path, format!("EXR size {w}x{h} is empty")));
    }
    for (name, data) in channels {
        if data.len() != n {
            return Err(Error::invalid(
                path,
                format!(
                    "channel {name} has {} values, expected {w}x{h} = {n}",
                    data.len()
                ),
            ));
        }
        if let Some(i) = data.iter().position(|v| !v.is_finite()) {
            return Err(Error::invalid(
                path,
                format!(
                    "channel {name}: pixel ({}, {}) is {} (not finite)",
                    i % w as usize,
                    i / w as usize,
                    data[i]
                ),
            ));
        }
    }
    let list: Vec<x::AnyChannel<x::FlatSamples>> = channels
        .iter()
        .map(|(name, data)| x::AnyChannel::new(*name, x::FlatSamples::F32(data.to_vec())))
        .collect();
    let encoding = x::Encoding {
        compression: x::Compression::ZIP16,
        blocks: x::Blocks::ScanLines,
        line_order: x::LineOrder::Increasing,
    };
    let layer = x::Layer::new(
        (w as usize, h as usize),
        x::LayerAttributes::default(),
        encoding,
        x::AnyChannels::sort(x::SmallVec::from_vec(list)),
    );
    let image = x::Image::from_layer(layer);
    use x::WritableImage;
    write_atomic(path, |out| {
        image
            .write()
            .to_buffered(out)
            .map_err(|e| io::Error::other(e.to_string()))
    })
}

/// Refuse an EXR whose headers declare more pixel data than its bytes can hold, before
/// the decoder allocates for them: at most 1032 decoded bytes per file byte (deflate's
/// largest ratio; the other codecs expand less) and one 8-byte offset per chunk.
fn check_exr_sizes(path: &Path, bytes: &[u8]) -> Result<()> {
    let meta = guarded(path, || {
        x::MetaData::read_from_buffered(bytes, false)
            .map_err(|e| Error::invalid(path, format!("cannot read EXR header: {e}")))
    })?;
    let limit = bytes.len().saturating_mul(1032);
    for (i, h) in meta.headers.iter().enumerate() {
        let (w, ht) = (h.layer_size.width(), h.layer_size.height());
        // Bound the pixel count before anything multiplies it (no overflow below).
        let pixels = w.checked_mul(ht).filter(|&p| p <= limit);
        let sample_bytes = pixels.and_then(|p| {
            h.channels.list.iter().try_fold(0usize, |acc, c| {
                acc.checked_add(p.checked_mul(c.sample_type.bytes_per_sample())?)
            })
        });
        let fits = !h.deep
            && sample_bytes.is_some_and(|b| b <= limit)
            && h.chunk_count
                .checked_mul(8)
                .is_some_and(|b| b <= bytes.len());
        if !fits {
            return Err(Error::invalid(
                path,
                format!(
                    "EXR layer {i} declares {w}x{ht} pixels of {} channels in {} chunks, \
                     more than its {} bytes can hold (corrupt)",
                    h.channels.list.len(),
                    h.chunk_count,
                    bytes.len()
                ),
            ));
        }
    }
    Ok(())
}

/// Read the named channels (f32 or f16; converted to f32) of the first layer of an
/// EXR; returns `(w, h, channel data in the order asked)`.
fn read_exr_channels(path: &Path, names: &[&str]) -> Result<(u32, u32, Vec<Vec<f32>>)> {
    use x::{ReadChannels, ReadLayers};
    let bytes = std::fs::read(path).at(path)?;
    check_exr_sizes(path, &bytes)?;
    let image = guarded(path, || {
        x::read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .first_valid_layer()
            .all_attributes()
            .from_buffered(io::Cursor::new(&bytes))
            .map_err(|e| Error::invalid(path, format!("cannot read EXR: {e}")))
    })?;
    let layer = &image.layer_data;
    let (w, h) = (layer.size.width(), layer.size.height());
    let n = w * h;
    let present: Vec<String> = layer
        .channel_data
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    let mut out = Vec::with_capacity(names.len());
    for name in names {
        let ch = layer
            .channel_data
            .list
            .iter()
            .find(|c| c.name.eq(name))
            .ok_or_else(|| {
                Error::invalid(
                    path,
                    format!("EXR has no channel {name} (channels: {present:?})"),
                )
            })?;
        let data: Vec<f32> = match &ch.sample_data {
            x::FlatSamples::F32(v) => v.clone(),
            x::FlatSamples::F16(v) => v.iter().map(|s| s.to_f32()).collect(),
            x::FlatSamples::U32(_) => {
                return Err(Error::invalid(
                    path,
                    format!("EXR channel {name} holds u32 samples, expected float"),
                ));
            }
        };
        if data.len() != n {
            return Err(Error::invalid(
                path,
                format!("EXR channel {name} has {} samples for {w}x{h}", data.len()),
            ));
        }
        if let Some(i) = data.iter().position(|v| !v.is_finite()) {
            return Err(Error::invalid(
                path,
                format!(
                    "EXR channel {name}: pixel ({}, {}) is {} (not finite)",
                    i % w,
                    i / w,
                    data[i]
                ),
            ));
        }
        out.push(data);
    }
    let (w, h) = (
        u32::try_from(w).map_err(|_| Error::invalid(path, "EXR too wide"))?,
        u32::try_from(h).map_err(|_| Error::invalid(path, "EXR too tall"))?,
    );
    Ok((w, h, out))
}

/// Write a depth map (channel `Z`, camera-space depth) as a single-channel f32 EXR.
pub fn write_exr_depth(path: impl AsRef<Path>, w: u32, h: u32, depth: &[f32]) -> Result<()> {
    write_exr_channels(path.as_ref(), w, h, &[("Z", depth)])
}

/// Read a depth map written by [`write_exr_depth`] (or any EXR with a `Z` channel).
pub fn read_exr_depth(path: impl AsRef<Path>) -> Result<(u32, u32, Vec<f32>)> {
    let (w, h, mut c) = read_exr_channels(path.as_ref(), &["Z"])?;
    Ok((w, h, c.remove(0)))
}

/// Write a dense flow field (channels `U`, `V`, px/s) as a 2-channel f32 EXR.
pub fn write_exr_flow(path: impl AsRef<Path>, w: u32, h: u32, u: &[f32], v: &[f32]) -> Result<()> {
    write_exr_channels(path.as_ref(), w, h, &[("U", u), ("V", v)])
}

/// Read a flow field: `(w, h, u, v)`.
pub fn read_exr_flow(path: impl AsRef<Path>) -> Result<(u32, u32, Vec<f32>, Vec<f32>)> {
    let (w, h, mut c) = read_exr_channels(path.as_ref(), &["U", "V"])?;
    let v = c.pop().unwrap_or_default();
    let u = c.pop().unwrap_or_default();
    Ok((w, h, u, v))
}

/// Write a 3-channel image as an f32 EXR with channels `R`,`G`,`B` (values unclamped).
pub fn write_exr_rgb(path: impl AsRef<Path>, img: &Image) -> Result<()> {
    let path = path.as_ref();
    img.check_len(path)?;
    if img.channels != 3 {
        return Err(Error::invalid(
            path,
            format!("write_exr_rgb takes 3 channels, got {}", img.channels),
        ));
    }
    let n = img.pixels();
    let planes: Vec<Vec<f32>> = (0..3)
        .map(|c| img.data.iter().skip(c).step_by(3).copied().collect())
        .collect();
    debug_assert!(planes.iter().all(|p| p.len() == n));
    write_exr_channels(
        path,
        img.width,
        img.height,
        &[("R", &planes[0]), ("G", &planes[1]), ("B", &planes[2])],
    )
}

/// Read an EXR's `R`,`G`,`B` channels as a 3-channel image.
pub fn read_exr_rgb(path: impl AsRef<Path>) -> Result<Image> {
    let (w, h, c) = read_exr_channels(path.as_ref(), &["R", "G", "B"])?;
    let n = w as usize * h as usize;
    let mut data = Vec::with_capacity(n * 3);
    for ((r, g), b) in c[0].iter().zip(&c[1]).zip(&c[2]) {
        data.extend([*r, *g, *b]);
    }
    Ok(Image {
        width: w,
        height: h,
        channels: 3,
        data,
    })
}
