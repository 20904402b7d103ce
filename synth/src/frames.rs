//! Simulate the events of a directory of frames (the `evflow simulate` command): the
//! images sorted by file name at the times of `timestamps.txt`, through
//! [`crate::sim::Simulator`].

use crate::sim::{SimConfig, Simulator, luminance};
use scene::error::{Error, IoContext, Result};
use scene::events::EventStream;
use scene::manifest::FrameEncoding;
use serde::{Deserialize, Serialize};
use stagekit::Settings;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What [`simulate_frames`] did.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SimSummary {
    pub frames: usize,
    pub events: usize,
    pub width: u32,
    pub height: u32,
    pub seconds: f64,
}

/// Image files (`.png`, `.jpg`, `.jpeg`) of `dir`, sorted by file name.
fn list_images(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .at(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "png" | "jpg" | "jpeg"))
        })
        .collect();
    files.sort();
    Ok(files)
}

/// Read `timestamps.txt`: one time in seconds per line (blank lines and `#` comments
/// skipped), strictly increasing.
pub fn read_timestamps(path: &Path) -> Result<Vec<f64>> {
    let text = std::fs::read_to_string(path).at(path)?;
    let mut times = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let t: f64 = line.parse().map_err(|_| {
            Error::invalid(path, format!("line {}: '{line}' is not a number", i + 1))
        })?;
        if !t.is_finite() {
            return Err(Error::invalid(
                path,
                format!("line {}: time {t} is not finite", i + 1),
            ));
        }
        if let Some(&prev) = times.last()
            && t <= prev
        {
            return Err(Error::invalid(
                path,
                format!(
                    "line {}: time {t} does not increase (previous {prev})",
                    i + 1
                ),
            ));
        }
        times.push(t);
    }
    Ok(times)
}

/// Simulate the events of a directory of frames: the images of `frames_dir` (sorted by
/// file name; 8- or 16-bit, their codes decoded by `encoding`: the event model works on
/// linear intensity) at the times of `frames_dir/timestamps.txt`, written to `out_path`
/// as `.evs`.
pub fn simulate_frames(
    frames_dir: &Path,
    out_path: &Path,
    cfg: &SimConfig,
    seed: u64,
    encoding: FrameEncoding,
) -> Result<SimSummary> {
    let start = Instant::now();
    cfg.validate()
        .map_err(|e| Error::Other(format!("simulator settings: {e}")))?;
    let ts_path = frames_dir.join("timestamps.txt");
    let times = read_timestamps(&ts_path)?;
    let files = list_images(frames_dir)?;
    if files.is_empty() {
        return Err(Error::invalid(
            frames_dir,
            "no .png/.jpg images in the directory",
        ));
    }
    if files.len() != times.len() {
        return Err(Error::invalid(
            &ts_path,
            format!("{} timestamps for {} images", times.len(), files.len()),
        ));
    }
    let mut sim: Option<Simulator> = None;
    let mut events = EventStream::default();
    for (file, &t) in files.iter().zip(&times) {
        let mut img = scene::image_io::read_image(file)?;
        if encoding.is_srgb() {
            img.data
                .iter_mut()
                .for_each(|v| *v = scene::image_io::srgb_to_linear(*v));
        }
        let lum = match img.channels {
            1 => img.data.clone(),
            3 => luminance(&img.data),
            c => {
                return Err(Error::invalid(
                    file,
                    format!("{c} channels, expected 1 or 3"),
                ));
            }
        };
        let sim = sim.get_or_insert_with(|| {
            events = EventStream::new(img.width, img.height);
            Simulator::new(img.width, img.height, cfg, seed)
        });
        if (img.width, img.height) != (events.width, events.height) {
            return Err(Error::invalid(
                file,
                format!(
                    "size {}x{} differs from the first frame's {}x{}",
                    img.width, img.height, events.width, events.height
                ),
            ));
        }
        sim.push_frame(t, &lum, &mut events)
            .map_err(|e| Error::invalid(file, e.to_string()))?;
    }
    scene::formats::write_evs(out_path, &events)?;
    Ok(SimSummary {
        frames: files.len(),
        events: events.len(),
        width: events.width,
        height: events.height,
        seconds: start.elapsed().as_secs_f64(),
    })
}
