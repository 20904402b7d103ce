//! The HS-ERGB layout (Tulyakov et al., TimeLens, CVPR 2021; the paper's real data): a
//! static rig of an RGB camera and an event camera aligned to it.
//!
//! ```text
//! SRC/images_corrected/NNNNNN.png   frames (or SRC/images/), sorted by name
//! SRC/images_corrected/timestamp.txt one timestamp per frame, seconds (or µs: detected)
//! SRC/events_aligned/NNNNNN.npz     events per frame interval (or SRC/events/), sorted
//!                                   by name: x, y stored ×32, t in µs, p
//! ```
//!
//! The camera does not move: every frame gets the identity pose. The intrinsics come
//! from an ECD-style `calib.txt` (`--calib`), else a guess (fx = fy = width, centred)
//! with a warning. The npz files are concatenated in name order (the result must be
//! sorted); a file whose events fall outside its frame interval gets a warning (the
//! clocks may disagree). Frames are ordinary camera PNGs: `frame_encoding: srgb`.

use crate::ecd::calib_or_guess;
use crate::recording::{FrameImage, Recording, SourceFrame};
use crate::table::{check_increasing, number, read_text, rows};
use scene::atomic::{AtomicDir, OutputRule, write_bytes_atomic};
use scene::error::{Error, IoContext, Result};
use scene::events::EventStream;
use scene::formats::{ReadOptions, read_npz, write_npz};
use scene::manifest::FrameEncoding;
use scene::{Pose, Scene};
use std::path::{Path, PathBuf};

/// HS-ERGB stores event coordinates multiplied by this.
pub(crate) const COORD_SCALE: f64 = 32.0;

/// Events whose coordinates were read raw (as stored, 16 bits), in pixels of the
/// `(w, h)` frames: divided by [`COORD_SCALE`] as HS-ERGB stores them, unless their
/// range shows plain pixels (all below the frame size, and beyond what ×32 data could
/// reach there), which are kept with a warning. A stored value of 2¹⁵ or more is a small
/// negative coordinate wrapped through 16 bits (the real recordings hold some: public
/// converters subtract 65 536); those events lie off the sensor and are dropped, with a
/// warning. Coordinates that fit neither reading are an error naming the folder.
fn pixel_coordinates(
    ev: EventStream,
    (w, h): (u32, u32),
    dir: &Path,
    warnings: &mut Vec<String>,
) -> Result<EventStream> {
    let wrapped = |v: u16| v >= 1 << 15;
    let keep: Vec<usize> = (0..ev.len())
        .filter(|&i| !wrapped(ev.x[i]) && !wrapped(ev.y[i]))
        .collect();
    let dropped = ev.len() - keep.len();
    if dropped > 0 {
        warnings.push(format!(
            "{}: {dropped} events with negative coordinates (stored wrapped through 16 \
             bits) lie off the sensor: dropped",
            dir.display()
        ));
    }
    let mut out = EventStream::with_capacity(w, h, keep.len());
    let max = |v: &[u16]| keep.iter().map(|&i| u32::from(v[i])).max().unwrap_or(0);
    let (mx, my) = (max(&ev.x), max(&ev.y));
    let s = COORD_SCALE;
    let plain =
        mx < w && my < h && (f64::from(mx) > f64::from(w) / s || f64::from(my) > f64::from(h) / s);
    if plain {
        warnings.push(format!(
            "{}: the npz coordinates span 0..{mx} × 0..{my}, within the frames' {w}×{h}: \
             read as plain pixels, not ×32 as HS-ERGB stores them",
            dir.display()
        ));
    }
    // ×32 values round to the nearest pixel; the last column's may round up onto the
    // frame's edge (kept on the last pixel); anything further is no HS-ERGB file.
    let pixel = |c: u16, size: u32, axis: &str| -> Result<u16> {
        if plain {
            return Ok(c);
        }
        let px = (f64::from(c) / s).round();
        if px > f64::from(size) {
            return Err(Error::invalid(
                dir,
                format!(
                    "an event's {axis} = {c} (÷ 32 = {px}) is outside the frames' {w}×{h}: \
                     neither ×32 nor plain pixels"
                ),
            ));
        }
        Ok((px as u32).min(size - 1) as u16)
    };
    for &i in &keep {
        let (x, y) = (pixel(ev.x[i], w, "x")?, pixel(ev.y[i], h, "y")?);
        out.push(ev.t[i], x, y, ev.p[i]);
    }
    Ok(out)
}

/// The first of `names` that is a directory under `src`.
fn find_dir(src: &Path, names: &[&str]) -> Result<PathBuf> {
    names
        .iter()
        .map(|n| src.join(n))
        .find(|p| p.is_dir())
        .ok_or_else(|| {
            Error::invalid(
                src,
                format!("HS-ERGB layout: none of the folders {names:?} exists"),
            )
        })
}

/// Files in `dir` with extension `ext`, sorted by name.
fn files(dir: &Path, ext: &str) -> Result<Vec<PathBuf>> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .at(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension()
                .is_some_and(|e| e.to_string_lossy().eq_ignore_ascii_case(ext))
        })
        .collect();
    v.sort();
    Ok(v)
}

/// The unit of `timestamp.txt` in seconds: 1 (seconds), or 1e-6 when the values read as
/// microseconds overlap the events' time span better (loaders of the dataset compare
/// frame timestamps with the npz `t` directly, so files in µs exist). Overlap is the
/// intersection over union of the two spans.
fn timestamp_unit(times: &[f64], events: &EventStream) -> f64 {
    let (Some(&e0), Some(&e1)) = (events.t.first(), events.t.last()) else {
        return 1.0;
    };
    let score = |unit: f64| {
        let (f0, f1) = (times[0] * unit, times[times.len() - 1] * unit);
        let inter = (f1.min(e1) - f0.max(e0)).max(0.0);
        let union = f1.max(e1) - f0.min(e0);
        if union > 0.0 { inter / union } else { 1.0 }
    };
    if score(1e-6) > score(1.0) { 1e-6 } else { 1.0 }
}

/// Read an HS-ERGB sequence folder.
pub(crate) fn read_hsergb(src: &Path, calib: Option<&Path>) -> Result<Recording> {
    let img_dir = find_dir(src, &["images_corrected", "images"])?;
    let ev_dir = find_dir(src, &["events_aligned", "events"])?;
    let images = files(&img_dir, "png")?;
    let ts_path = img_dir.join("timestamp.txt");
    let text = read_text(&ts_path)?;
    let rows = rows(&ts_path, &text, 1, 1)?;
    let times = rows
        .iter()
        .map(|r| number(&ts_path, r, 0, "timestamp"))
        .collect::<Result<Vec<f64>>>()?;
    check_increasing(&ts_path, &rows, &times)?;
    if times.len() != images.len() || images.is_empty() {
        return Err(Error::invalid(
            &ts_path,
            format!(
                "{} timestamps for {} PNG frames in {} (need one per frame, at least one)",
                times.len(),
                images.len(),
                img_dir.display()
            ),
        ));
    }
    let (w, h) = image::image_dimensions(&images[0])
        .map_err(|e| Error::invalid(&images[0], format!("cannot read image header: {e}")))?;
    // The raw coordinates first: whether they are ×32 is read off their range.
    // Every 16-bit value passes the reader: [`pixel_coordinates`] reads them.
    let opts = ReadOptions {
        sensor: Some((1 << 16, 1 << 16)),
        coord_scale: None,
    };
    let mut events = EventStream::new(1 << 16, 1 << 16);
    let mut warnings = Vec::new();
    let npz = files(&ev_dir, "npz")?;
    if npz.is_empty() {
        return Err(Error::invalid(&ev_dir, "no .npz event files"));
    }
    let mut spans = Vec::with_capacity(npz.len());
    for p in &npz {
        let part = read_npz(p, &opts)?;
        if let (Some(&a), Some(&b)) = (part.t.first(), part.t.last()) {
            if events.t.last().is_some_and(|&l| a < l) {
                return Err(Error::invalid(
                    p,
                    format!("events start at {a} s, before the previous file's last event"),
                ));
            }
            spans.push(Some((a, b)));
        } else {
            spans.push(None);
        }
        events.t.extend_from_slice(&part.t);
        events.x.extend_from_slice(&part.x);
        events.y.extend_from_slice(&part.y);
        events.p.extend_from_slice(&part.p);
    }
    let events = pixel_coordinates(events, (w, h), &ev_dir, &mut warnings)?;
    let unit = timestamp_unit(&times, &events);
    let times: Vec<f64> = times.iter().map(|t| t * unit).collect();
    if unit != 1.0 {
        warnings.push(format!(
            "timestamp.txt read as microseconds: its values span the events' µs clock \
             ({} … {} s), not seconds",
            times[0],
            times[times.len() - 1]
        ));
    }
    // File k should hold the events between frames k and k+1.
    let outside = spans
        .iter()
        .enumerate()
        .filter(|(k, span)| {
            span.is_some_and(|(a, b)| {
                let lo = times.get(*k).copied().unwrap_or(f64::NEG_INFINITY);
                let hi = times.get(k + 1).copied().unwrap_or(f64::INFINITY);
                a < lo - (hi - lo) || b > hi + (hi - lo)
            })
        })
        .count();
    if outside > 0 {
        warnings.push(format!(
            "{outside} of {} event files lie outside their frame interval: are timestamp.txt and the npz t (µs) on one clock?",
            npz.len()
        ));
    }
    let camera = calib_or_guess(calib, w, h, &mut warnings)?;
    let frames = images
        .into_iter()
        .zip(&times)
        .map(|(p, &t)| SourceFrame {
            image: FrameImage::File(p),
            timestamp: t,
            pose: Pose::default(),
        })
        .collect();
    Ok(Recording {
        layout: "hsergb",
        camera,
        frames,
        events,
        frame_encoding: FrameEncoding::Srgb,
        warnings,
        held_out: None,
    })
}

/// Write `scene` (train and test frames in time order, its events) in the HS-ERGB
/// layout at `out`, with its camera as `calib.txt` beside the folders: the events before
/// frame 1 go to file 0, those in [t_k, t_k+1) to file k, the rest to the last file.
/// Poses are not written (the layout has none). For tests.
pub fn export_hsergb(scene: &Scene, out: &Path) -> Result<()> {
    let cam = &scene.train.camera;
    if cam.width * 32 > 65536 || cam.height * 32 > 65536 {
        return Err(Error::Other(format!(
            "HS-ERGB export: {}x{} ×32 does not fit the npz's 16-bit coordinates",
            cam.width, cam.height
        )));
    }
    let dir = AtomicDir::new(out, &OutputRule::new("export"))?;
    let root = dir.path();
    let frames = crate::recording::frames_by_time(scene);
    let mut ts = String::new();
    for (k, f) in frames.iter().enumerate() {
        let src = scene.image_path(f);
        let bytes = std::fs::read(&src).at(&src)?;
        write_bytes_atomic(&root.join(format!("images_corrected/{k:06}.png")), &bytes)?;
        ts.push_str(&format!("{}\n", f.timestamp));
    }
    write_bytes_atomic(&root.join("images_corrected/timestamp.txt"), ts.as_bytes())?;
    let ev = scene.load_events()?;
    let n = frames.len();
    for k in 0..n.saturating_sub(1).max(1) {
        let lo = if k == 0 {
            f64::NEG_INFINITY
        } else {
            frames[k].timestamp
        };
        let hi = if k + 2 >= n {
            f64::INFINITY
        } else {
            frames[k + 1].timestamp
        };
        let r = ev.window_range(lo, hi);
        let s = 32u32;
        let mut part = EventStream::new(ev.width * s, ev.height * s);
        for i in r {
            part.push(ev.t[i], ev.x[i] * s as u16, ev.y[i] * s as u16, ev.p[i]);
        }
        write_npz(root.join(format!("events_aligned/{k:06}.npz")), &part)?;
    }
    let k = &scene.train.camera;
    let d = k.distortion.unwrap_or_default();
    let calib = format!(
        "{} {} {} {} {} {} {} {} {}\n",
        k.fx, k.fy, k.cx, k.cy, d.k1, d.k2, d.p1, d.p2, d.k3
    );
    write_bytes_atomic(&root.join("calib.txt"), calib.as_bytes())?;
    dir.commit()?;
    Ok(())
}
