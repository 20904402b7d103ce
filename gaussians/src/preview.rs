//! Animated previews of rendered frames: a looping GIF (the `image` crate's encoder,
//! 256 colours per frame) and an MP4 by `ffmpeg` when it is on the PATH.

use scene::image_io::Image;
use scene::{Error, Result};
use std::path::Path;
use std::process::Command;

/// Write `frames` (RGB in [0, 1], one size) as a GIF at `fps` that loops forever.
pub fn write_gif(path: &Path, frames: &[Image], fps: f64) -> Result<()> {
    use image::codecs::gif::{GifEncoder, Repeat};
    use image::{Delay, Frame, RgbaImage};
    let file = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
    let mut enc = GifEncoder::new_with_speed(std::io::BufWriter::new(file), 10);
    let gif_err = |e: image::ImageError| Error::invalid(path, format!("GIF encoding: {e}"));
    enc.set_repeat(Repeat::Infinite).map_err(gif_err)?;
    let delay = Delay::from_numer_denom_ms((1000.0 / fps).round().max(10.0) as u32, 1);
    for f in frames {
        let c = f.channels as usize;
        let rgba: Vec<u8> = (f.data.chunks_exact(c))
            .flat_map(|p| {
                let g = |k: usize| (p[k.min(c - 1)].clamp(0.0, 1.0) * 255.0).round() as u8;
                [g(0), g(1), g(2), 255]
            })
            .collect();
        let img = RgbaImage::from_raw(f.width, f.height, rgba)
            .ok_or_else(|| Error::invalid(path, "a frame of the wrong size"))?;
        enc.encode_frame(Frame::from_parts(img, 0, 0, delay))
            .map_err(gif_err)?;
    }
    Ok(())
}

/// `dir/frames/NNNN.png` (from 0001) → `dir/name` (H.264, yuv420p, even size) at `fps`
/// with `ffmpeg`; `Err` says why there is none (not on the PATH, or its error).
pub fn write_mp4(dir: &Path, name: &str, fps: f64) -> std::result::Result<(), String> {
    let out = Command::new("ffmpeg")
        .current_dir(dir)
        .args(["-y", "-loglevel", "error", "-framerate"])
        .arg(format!("{fps}"))
        .args([
            "-i",
            "frames/%04d.png",
            "-vf",
            "pad=ceil(iw/2)*2:ceil(ih/2)*2",
        ])
        .args(["-pix_fmt", "yuv420p", name])
        .output();
    match out {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            Err("no MP4: ffmpeg is not on the PATH (the GIF and the PNG frames are there)".into())
        }
        Err(e) => Err(format!("no MP4: ffmpeg did not start: {e}")),
        Ok(o) if !o.status.success() => Err(format!(
            "no MP4: ffmpeg failed ({}): {}",
            o.status,
            String::from_utf8_lossy(&o.stderr).trim()
        )),
        Ok(_) => Ok(()),
    }
}
