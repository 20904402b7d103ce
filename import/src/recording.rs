//! What every layout converter produces ([`Recording`]: camera, frames with poses,
//! events) and the one writer that turns it into a degs scene directory
//! ([`write_scene`]), choosing the train and test frames ([`split_frames`]).

use crate::aligned::EventsAlignment;
use scene::atomic::{AtomicDir, OutputRule, write_json_atomic};
use scene::error::{Error, IoContext, Result};
use scene::events::EventStream;
use scene::image_io::{Image, write_png};
use scene::manifest::{
    DEFAULT_CONTRAST_THRESHOLD, EventsRef, Frame, FrameEncoding, Manifest, TEST_FILE, TRAIN_FILE,
};
use scene::{Intrinsics, Pose};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Name of the event file in an imported scene.
pub const EVENTS_FILE: &str = "events.evs";

/// Where a frame's pixels come from.
#[derive(Clone, Debug, PartialEq)]
pub enum FrameImage {
    /// An image file (PNG or JPEG), copied byte for byte.
    File(PathBuf),
    /// 8-bit pixels, row-major, 1 (grey) or 3 (RGB) channels interleaved (AEDAT4 APS
    /// frames), written as a PNG.
    Pixels {
        width: u32,
        height: u32,
        channels: u32,
        pixels: Vec<u8>,
    },
}

/// One frame of a recording: its image, its time on the events' clock, its
/// camera-to-world pose in the manifest's axes (OpenGL: −Z forward, +Y up).
#[derive(Clone, Debug, PartialEq)]
pub struct SourceFrame {
    pub image: FrameImage,
    pub timestamp: f64,
    pub pose: Pose,
}

/// A recording read from some layout, in degs' conventions.
#[derive(Clone, Debug)]
pub struct Recording {
    /// The layout's name (`ecd`, `hsergb`, …), for the summary.
    pub layout: &'static str,
    pub camera: Intrinsics,
    /// Sorted by strictly increasing timestamp.
    pub frames: Vec<SourceFrame>,
    pub events: EventStream,
    pub frame_encoding: FrameEncoding,
    /// What the converter assumed or left out (printed and kept in `import.json`).
    pub warnings: Vec<String>,
    /// The layout's own test split (one flag per frame), used unless `--test-every`.
    pub held_out: Option<Vec<bool>>,
}

/// How [`write_scene`] chooses and labels the frames.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportOptions {
    /// Hold out every N-th frame (the N-th, 2N-th, … counting from 1) as a test frame.
    pub test_every: Option<usize>,
    /// Thin the remaining (train) frames to at most this rate (frames per second).
    pub train_fps: Option<f64>,
    /// Contrast threshold C written to the manifest.
    pub contrast_threshold: f64,
    /// Overrides the layout's frame encoding.
    pub frame_encoding: Option<FrameEncoding>,
    /// Layouts without poses (AEDAT4): accept a camera that did not move (identity poses).
    pub static_camera: bool,
    /// Layouts without a calibration (AEDAT4, HS-ERGB): an ECD-style `calib.txt`.
    pub calib: Option<PathBuf>,
    /// Blender, nerfies: the event file, and how normalised frame times map to seconds.
    pub alignment: EventsAlignment,
    /// Nerfies: read the frames of `rgb/{N}x/` (default: 1, else the smallest there).
    pub downscale: Option<u32>,
    /// COLMAP: the frames' times (`NAME SECONDS` lines; default SRC/timestamps.txt).
    pub timestamps: Option<PathBuf>,
    /// COLMAP without a timestamps file: seconds per unit of the number in each image's
    /// name (default 1).
    pub name_seconds: Option<f64>,
    /// Replace an earlier output of `degs import` at the output folder.
    pub force: bool,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions {
            test_every: None,
            train_fps: None,
            contrast_threshold: DEFAULT_CONTRAST_THRESHOLD,
            frame_encoding: None,
            static_camera: false,
            calib: None,
            alignment: Default::default(),
            downscale: None,
            timestamps: None,
            name_seconds: None,
            force: false,
        }
    }
}

/// Indices of the train and test frames, and how many frames `train_fps` dropped.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Split {
    pub train: Vec<usize>,
    pub test: Vec<usize>,
    pub dropped: usize,
}

/// Choose train and test frames from increasing `times`: with `test_every = N` the
/// frames N−1, 2N−1, … (0-based) are test frames; the others are train frames, thinned
/// with `train_fps = F` by keeping a frame only when it is at least 1/F after the
/// previous kept one (the first is always kept). `Err` for N < 2 or F ≤ 0.
pub fn split_frames(
    times: &[f64],
    test_every: Option<usize>,
    train_fps: Option<f64>,
) -> std::result::Result<Split, String> {
    if let Some(n) = test_every
        && n < 2
    {
        return Err(format!(
            "--test-every {n}: must be at least 2 (1 would hold out every frame)"
        ));
    }
    split_by(
        times,
        |i| test_every.is_some_and(|n| i % n == n - 1),
        train_fps,
    )
}

/// [`split_frames`] with the test frames chosen by `is_test(index)`.
pub fn split_by(
    times: &[f64],
    is_test: impl Fn(usize) -> bool,
    train_fps: Option<f64>,
) -> std::result::Result<Split, String> {
    if let Some(f) = train_fps
        && !(f.is_finite() && f > 0.0)
    {
        return Err(format!("--train-fps {f}: must be finite and > 0"));
    }
    let mut split = Split {
        train: Vec::new(),
        test: Vec::new(),
        dropped: 0,
    };
    // A relative slack so that frames exactly 1/F apart (up to rounding) are all kept.
    let period = train_fps.map(|f| (1.0 / f) * (1.0 - 1e-9));
    for (i, &t) in times.iter().enumerate() {
        if is_test(i) {
            split.test.push(i);
            continue;
        }
        let keep = match (period, split.train.last()) {
            (Some(p), Some(&last)) => t - times[last] >= p,
            _ => true,
        };
        if keep {
            split.train.push(i);
        } else {
            split.dropped += 1;
        }
    }
    Ok(split)
}

/// Events per interval between consecutive frames (all frames, train and test).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct IntervalCounts {
    pub min: usize,
    pub mean: f64,
    pub max: usize,
}

/// What an import found and wrote (printed by `degs import`, saved as `import.json`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ImportSummary {
    pub layout: String,
    pub out_dir: PathBuf,
    pub width: u32,
    pub height: u32,
    pub distortion: bool,
    pub frames: usize,
    pub train_frames: usize,
    pub test_frames: usize,
    /// Frames dropped by `--train-fps`.
    pub dropped_frames: usize,
    /// First and last frame timestamp (s, the events' clock).
    pub t_first: f64,
    pub t_last: f64,
    pub events: usize,
    pub events_t_first: f64,
    pub events_t_last: f64,
    /// `None` with fewer than two frames.
    pub events_per_interval: Option<IntervalCounts>,
    pub frame_encoding: FrameEncoding,
    pub contrast_threshold: f64,
    pub warnings: Vec<String>,
}

impl std::fmt::Display for ImportSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "{} recording → {}", self.layout, self.out_dir.display())?;
        writeln!(
            f,
            "  camera     {}x{}{}",
            self.width,
            self.height,
            if self.distortion {
                ", with lens distortion (k1 k2 p1 p2 k3 kept)"
            } else {
                ""
            }
        )?;
        writeln!(
            f,
            "  frames     {} over {:.6} s ({:.6} … {:.6}): {} train, {} test, {} dropped by --train-fps",
            self.frames,
            self.t_last - self.t_first,
            self.t_first,
            self.t_last,
            self.train_frames,
            self.test_frames,
            self.dropped_frames
        )?;
        writeln!(
            f,
            "  events     {} ({:.6} … {:.6} s)",
            self.events, self.events_t_first, self.events_t_last
        )?;
        if let Some(c) = &self.events_per_interval {
            writeln!(
                f,
                "  per frame interval: min {}, mean {:.1}, max {}",
                c.min, c.mean, c.max
            )?;
        }
        writeln!(
            f,
            "  encoding   {:?} frames, contrast threshold {}",
            self.frame_encoding, self.contrast_threshold
        )?;
        for w in &self.warnings {
            writeln!(f, "  warning: {w}")?;
        }
        Ok(())
    }
}

/// A scene's train and test frames together, by time (for the exporters).
pub(crate) fn frames_by_time(scene: &scene::Scene) -> Vec<&scene::manifest::Frame> {
    let mut frames: Vec<_> = scene
        .train
        .frames
        .iter()
        .chain(&scene.test.frames)
        .collect();
    frames.sort_by(|a, b| a.timestamp.total_cmp(&b.timestamp));
    frames
}

/// The command whose outputs [`write_scene`] marks.
pub(crate) const IMPORT_COMMAND: &str = "degs import";

/// Write `rec` as a scene directory at `out` (atomically; an earlier import there is
/// replaced only under `opts.force`, anything else there is refused):
/// `transforms_train.json`, `transforms_test.json`, `images/{train,test}_NNNN.*`,
/// `events.evs`, `import.json` (the summary). Frame `time` is the timestamp normalised
/// over the first and last frame.
pub fn write_scene(rec: &Recording, opts: &ImportOptions, out: &Path) -> Result<ImportSummary> {
    write_scene_with(
        rec,
        opts,
        out,
        &OutputRule::new(IMPORT_COMMAND).force(opts.force),
    )
}

/// [`write_scene`] under `rule` (which names the source files the output must not hold).
pub(crate) fn write_scene_with(
    rec: &Recording,
    opts: &ImportOptions,
    out: &Path,
    rule: &OutputRule,
) -> Result<ImportSummary> {
    rule.check(out)?;
    check_recording(rec)?;
    let c = opts.contrast_threshold;
    if !(c.is_finite() && c > 0.0) {
        return Err(Error::Other(format!(
            "contrast threshold {c}: must be finite and > 0"
        )));
    }
    let times: Vec<f64> = rec.frames.iter().map(|f| f.timestamp).collect();
    let split = match (&rec.held_out, opts.test_every) {
        (Some(h), None) => split_by(&times, |i| h.get(i) == Some(&true), opts.train_fps),
        _ => split_frames(&times, opts.test_every, opts.train_fps),
    }
    .map_err(Error::Other)?;
    let (t0, t1) = (times[0], times[times.len() - 1]);
    let span = t1 - t0;
    let encoding = opts.frame_encoding.unwrap_or(rec.frame_encoding);

    // The scene checks, before any frame is decoded or written: findings that make the
    // scene meaningless refuse it; the others go in the summary.
    let planned = |idx: &[usize]| -> Vec<Frame> {
        idx.iter()
            .map(|&i| Frame {
                file_path: String::new(),
                timestamp: rec.frames[i].timestamp,
                time: 0.0,
                cam_to_world: rec.frames[i].pose,
            })
            .collect()
    };
    let findings = scene::check::check_frames(
        &planned(&split.train),
        &planned(&split.test),
        Some(&rec.events.t),
    );
    if let Some(e) = scene::check::first_error(out, &findings) {
        return Err(e);
    }
    let mut warnings = rec.warnings.clone();
    warnings.extend(
        findings
            .into_iter()
            .filter(|f| f.level == scene::check::Level::Warning)
            .map(|f| f.message),
    );

    let dir = AtomicDir::new(out, rule)?;
    let root = dir.path().to_path_buf();
    let write_split = |name: &str, idx: &[usize]| -> Result<Vec<Frame>> {
        let mut frames = Vec::with_capacity(idx.len());
        for (k, &i) in idx.iter().enumerate() {
            let f = &rec.frames[i];
            let file_path = write_image(&root, &format!("images/{name}_{k:04}"), &f.image)?;
            frames.push(Frame {
                file_path,
                timestamp: f.timestamp,
                time: if span > 0.0 {
                    ((f.timestamp - t0) / span).clamp(0.0, 1.0)
                } else {
                    0.0
                },
                cam_to_world: f.pose,
            });
        }
        Ok(frames)
    };
    let train = Manifest {
        camera: rec.camera,
        frames: write_split("train", &split.train)?,
        events: Some(EventsRef {
            path: EVENTS_FILE.into(),
            contrast_threshold: c,
        }),
        frame_encoding: Some(encoding),
    };
    let test = Manifest {
        frames: write_split("test", &split.test)?,
        events: None,
        ..train.clone()
    };
    scene::formats::write_evs(root.join(EVENTS_FILE), &rec.events)?;
    train.write(root.join(TRAIN_FILE))?;
    test.write(root.join(TEST_FILE))?;

    let ev = &rec.events;
    let summary = ImportSummary {
        layout: rec.layout.into(),
        out_dir: out.to_path_buf(),
        width: rec.camera.width,
        height: rec.camera.height,
        distortion: rec.camera.distortion.is_some_and(|d| !d.is_zero()),
        frames: rec.frames.len(),
        train_frames: split.train.len(),
        test_frames: split.test.len(),
        dropped_frames: split.dropped,
        t_first: t0,
        t_last: t1,
        events: ev.len(),
        events_t_first: ev.t.first().copied().unwrap_or(0.0),
        events_t_last: ev.t.last().copied().unwrap_or(0.0),
        events_per_interval: interval_counts(ev, &times),
        frame_encoding: encoding,
        contrast_threshold: c,
        warnings,
    };
    write_json_atomic(&root.join("import.json"), &summary)?;
    dir.commit()?;
    Ok(summary)
}

/// Frames sorted, in the camera's size, finite; events on the camera's sensor.
fn check_recording(rec: &Recording) -> Result<()> {
    let cam = &rec.camera;
    if rec.frames.is_empty() {
        return Err(Error::Other(format!(
            "{} recording: no frames to import",
            rec.layout
        )));
    }
    if (rec.events.width, rec.events.height) != (cam.width, cam.height) {
        return Err(Error::Other(format!(
            "{} recording: the events' sensor is {}x{} but the camera is {}x{}",
            rec.layout, rec.events.width, rec.events.height, cam.width, cam.height
        )));
    }
    // Times increase within each split; a layout's own test split may share times with
    // its train split (D-NeRF: other cameras at the train times).
    let name = |i: usize| match &rec.frames[i].image {
        FrameImage::File(p) => format!("frame {i} ({})", p.display()),
        FrameImage::Pixels { .. } => format!("frame {i}"),
    };
    let mut last: [Option<usize>; 2] = [None, None];
    for (i, f) in rec.frames.iter().enumerate() {
        if !f.timestamp.is_finite() {
            return Err(Error::Other(format!(
                "{} recording: {}: timestamp {} is not finite",
                rec.layout,
                name(i),
                f.timestamp
            )));
        }
        let split = usize::from(
            rec.held_out
                .as_ref()
                .is_some_and(|h| h.get(i) == Some(&true)),
        );
        let prev = if rec.held_out.is_some() {
            last[split]
        } else {
            i.checked_sub(1)
        };
        if let Some(j) = prev.filter(|&j| f.timestamp <= rec.frames[j].timestamp) {
            let which = match (&rec.held_out, split) {
                (None, _) => "",
                (Some(_), 0) => " in the train split",
                (Some(_), _) => " in the test split",
            };
            return Err(Error::Other(format!(
                "{} recording: {} at {} s is not after {} at {} s{which}",
                rec.layout,
                name(i),
                f.timestamp,
                name(j),
                rec.frames[j].timestamp
            )));
        }
        last[split] = Some(i);
        let size = match &f.image {
            FrameImage::File(p) => image::image_dimensions(p)
                .map_err(|e| Error::invalid(p, format!("cannot read image header: {e}")))?,
            FrameImage::Pixels { width, height, .. } => (*width, *height),
        };
        if size != (cam.width, cam.height) {
            return Err(Error::Other(format!(
                "{} recording: frame {i} is {}x{} but the camera is {}x{}",
                rec.layout, size.0, size.1, cam.width, cam.height
            )));
        }
    }
    Ok(())
}

/// Write one frame under `root` as `stem.<ext>`; returns the manifest's `file_path`.
fn write_image(root: &Path, stem: &str, image: &FrameImage) -> Result<String> {
    match image {
        FrameImage::File(src) => {
            let ext = src
                .extension()
                .map(|e| e.to_string_lossy().to_ascii_lowercase())
                .unwrap_or_else(|| "png".into());
            let rel = format!("{stem}.{ext}");
            let bytes = std::fs::read(src).at(src)?;
            // Decoded whole, so that a truncated or corrupt frame fails here, not in a
            // stage minutes later.
            image::load_from_memory(&bytes)
                .map_err(|e| Error::invalid(src, format!("cannot decode the frame: {e}")))?;
            scene::atomic::write_bytes_atomic(&root.join(&rel), &bytes)?;
            Ok(rel)
        }
        FrameImage::Pixels {
            width,
            height,
            channels,
            pixels,
        } => {
            let rel = format!("{stem}.png");
            let img = Image {
                width: *width,
                height: *height,
                channels: *channels,
                data: pixels.iter().map(|&c| c as f32 / 255.0).collect(),
            };
            write_png(root.join(&rel), &img)?;
            Ok(rel)
        }
    }
}

/// Min / mean / max events per interval between consecutive frame times.
pub(crate) fn interval_counts(ev: &EventStream, times: &[f64]) -> Option<IntervalCounts> {
    let counts: Vec<usize> = times
        .windows(2)
        .map(|w| ev.window_range(w[0], w[1]).len())
        .collect();
    let (&min, &max) = (counts.iter().min()?, counts.iter().max()?);
    Some(IntervalCounts {
        min,
        mean: counts.iter().sum::<usize>() as f64 / counts.len() as f64,
        max,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_holds_out_every_nth_and_thins_train() {
        let t: Vec<f64> = (0..10).map(|i| i as f64 * 0.1).collect();
        let s = split_frames(&t, Some(3), None).unwrap();
        assert_eq!(s.test, vec![2, 5, 8]);
        assert_eq!(s.train, vec![0, 1, 3, 4, 6, 7, 9]);
        // 2 fps over 10 fps frames: one train frame every 0.5 s (frames 0 and 5), the
        // other 8 dropped.
        let s = split_frames(&t, None, Some(2.0)).unwrap();
        assert_eq!(s.train, vec![0, 5]);
        assert_eq!((s.test.len(), s.dropped), (0, 8));
        let s = split_frames(&t, Some(2), Some(5.0)).unwrap();
        assert_eq!(s.test, vec![1, 3, 5, 7, 9]);
        assert_eq!(s.train, vec![0, 2, 4, 6, 8]);
        assert_eq!(s.dropped, 0);
        assert!(
            split_frames(&t, Some(1), None)
                .unwrap_err()
                .contains("at least 2")
        );
        assert!(split_frames(&t, None, Some(0.0)).is_err());
        assert!(split_frames(&t, None, Some(f64::NAN)).is_err());
    }

    #[test]
    fn interval_counts_count_half_open_windows() {
        let mut ev = EventStream::new(4, 4);
        for t in [0.0, 0.05, 0.1, 0.15, 0.19, 0.2] {
            ev.push(t, 0, 0, 1);
        }
        let c = interval_counts(&ev, &[0.0, 0.1, 0.2]).unwrap();
        assert_eq!((c.min, c.max), (2, 3));
        assert_eq!(c.mean, 2.5);
        assert!(interval_counts(&ev, &[0.0]).is_none());
    }
}
