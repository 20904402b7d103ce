//! Where the events of a flow run come from, cut into windows.
//!
//! - **A scene directory** (`docs/DESIGN.md` §3): the events of the train manifest, one
//!   window per interval between consecutive train frames, `[t_i, t_{i+1})` (the last
//!   one includes its end), or with a frame window `S > 0` one window of `S` seconds
//!   centred on each train frame (`FlowSettings::frame_window`). Window `i` is written as
//!   `flow/iiii.evflow`. A scene with a
//!   single train frame has no interval: that is an error naming
//!   `transforms_train.json` (give the event file with `--events` and `--window`
//!   instead).
//! - **A bare event file** (`--events FILE --sensor WxH [--calib calib.txt]
//!   [--window T0,T1]… [--window-length S]`): the windows given; else consecutive windows
//!   of `S` seconds from the first event; else one window over the whole stream.
//!
//! With distortion (a scene camera with `k1…k3`, or a `calib.txt`), every event is
//! undistorted to the ideal pixel grid of the same K; the voxel grid, the CM loss and
//! the flow all live on that grid. An event whose undistorted position falls outside the
//! sensor still gets the flow of the nearest pixel but does not vote in the voxel grid.

use crate::cm::CmEvents;
use scene::error::{Error, IoContext, Result};
use scene::events::EventStream;
use scene::{Distortion, Intrinsics};
use std::ops::Range;
use std::path::{Path, PathBuf};

/// One window of events.
#[derive(Clone, Debug, PartialEq)]
pub struct Window {
    /// Position in the run (= train interval index for scenes).
    pub index: usize,
    pub t_a: f64,
    pub t_b: f64,
    /// Indices of the window's events in the source stream.
    pub range: Range<usize>,
}

impl Window {
    pub fn len(&self) -> usize {
        self.range.len()
    }

    pub fn is_empty(&self) -> bool {
        self.range.is_empty()
    }

    pub fn duration(&self) -> f64 {
        self.t_b - self.t_a
    }
}

/// Events, their undistorted positions and the windows to process.
#[derive(Clone, Debug)]
pub struct Source {
    /// The file the events were read from.
    pub events_path: PathBuf,
    pub events: EventStream,
    /// Undistorted sub-pixel positions (equal to the raw pixels without distortion).
    pub xu: Vec<f32>,
    pub yu: Vec<f32>,
    pub intrinsics: Option<Intrinsics>,
    pub windows: Vec<Window>,
    /// BLAKE3 of the stream's `.evs` column bytes (the `.evflow` source hash).
    pub source_hash: [u8; 32],
}

/// How windows of a bare event file are chosen.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WindowSpec {
    /// Explicit windows `(t0, t1)`, seconds.
    pub windows: Vec<(f64, f64)>,
    /// Consecutive windows of this length when no explicit windows are given.
    pub window_length: Option<f64>,
}

/// Parse `WxH` (e.g. `240x180`).
pub fn parse_sensor(s: &str) -> std::result::Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("sensor '{s}' is not WIDTHxHEIGHT"))?;
    let w: u32 = w
        .trim()
        .parse()
        .map_err(|_| format!("bad sensor width in '{s}'"))?;
    let h: u32 = h
        .trim()
        .parse()
        .map_err(|_| format!("bad sensor height in '{s}'"))?;
    if w == 0 || h == 0 || w > 1 << 15 || h > 1 << 15 {
        return Err(format!("sensor '{s}' is empty or larger than 32768"));
    }
    Ok((w, h))
}

/// Parse `T0,T1` (seconds, T0 < T1, finite).
pub fn parse_window(s: &str) -> std::result::Result<(f64, f64), String> {
    let (a, b) = s
        .split_once(',')
        .ok_or_else(|| format!("window '{s}' is not T0,T1"))?;
    let a: f64 = a
        .trim()
        .parse()
        .map_err(|_| format!("bad window start in '{s}'"))?;
    let b: f64 = b
        .trim()
        .parse()
        .map_err(|_| format!("bad window end in '{s}'"))?;
    if !(a.is_finite() && b.is_finite() && a < b) {
        return Err(format!("window '{s}' must have finite T0 < T1"));
    }
    Ok((a, b))
}

/// Read an ECD `calib.txt`: `fx fy cx cy [k1 k2 p1 p2 [k3]]` on the first non-comment line.
pub fn read_calib(path: &Path, sensor: (u32, u32)) -> Result<Intrinsics> {
    let text = std::fs::read_to_string(path).at(path)?;
    let line = text
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with('#'))
        .ok_or_else(|| Error::invalid(path, "empty calibration file"))?;
    let vals: Vec<f64> = line
        .split_whitespace()
        .map(|t| {
            t.parse::<f64>()
                .map_err(|_| Error::invalid(path, format!("'{t}' is not a number")))
        })
        .collect::<Result<_>>()?;
    if !matches!(vals.len(), 4 | 8 | 9) {
        return Err(Error::invalid(
            path,
            format!(
                "{} numbers; expected fx fy cx cy [k1 k2 p1 p2 [k3]]",
                vals.len()
            ),
        ));
    }
    if vals.iter().any(|v| !v.is_finite()) || vals[0] <= 0.0 || vals[1] <= 0.0 {
        return Err(Error::invalid(
            path,
            "focal lengths must be positive and all values finite",
        ));
    }
    let d = |i: usize| vals.get(i).copied().unwrap_or(0.0);
    let distortion = Distortion {
        k1: d(4),
        k2: d(5),
        p1: d(6),
        p2: d(7),
        k3: d(8),
    };
    Ok(Intrinsics {
        width: sensor.0,
        height: sensor.1,
        fx: vals[0],
        fy: vals[1],
        cx: vals[2],
        cy: vals[3],
        distortion: (!distortion.is_zero()).then_some(distortion),
    })
}

/// Undistorted positions of every event (identity without distortion).
fn undistort_all(ev: &EventStream, k: Option<&Intrinsics>) -> (Vec<f32>, Vec<f32>) {
    match k.filter(|k| k.distortion.is_some_and(|d| !d.is_zero())) {
        None => (
            ev.x.iter().map(|&x| x as f32).collect(),
            ev.y.iter().map(|&y| y as f32).collect(),
        ),
        Some(k) => {
            // Undistort each sensor pixel once, then look events up.
            let (w, h) = (ev.width as usize, ev.height as usize);
            let mut lut = Vec::with_capacity(w * h);
            for y in 0..h {
                for x in 0..w {
                    let p = k.undistort_pixel(glam::DVec2::new(x as f64, y as f64));
                    lut.push((p.x as f32, p.y as f32));
                }
            }
            ev.x.iter()
                .zip(&ev.y)
                .map(|(&x, &y)| lut[y as usize * w + x as usize])
                .unzip()
        }
    }
}

/// Windows of `len` seconds centred on each frame time, clamped to `[first, last]` frame
/// time and to the midpoints between neighbouring frames (no event in two windows); the
/// last one includes its end time.
pub(crate) fn windows_around(ev: &EventStream, times: &[f64], len: f64) -> Vec<Window> {
    let n = times.len();
    (0..n)
        .map(|i| {
            let lo = if i > 0 {
                0.5 * (times[i - 1] + times[i])
            } else {
                times[0]
            };
            let hi = if i + 1 < n {
                0.5 * (times[i] + times[i + 1])
            } else {
                times[n - 1]
            };
            let t_a = (times[i] - 0.5 * len).max(lo);
            let t_b = (times[i] + 0.5 * len).min(hi);
            window(ev, i, t_a, t_b, i + 1 == n)
        })
        .collect()
}

/// Window `index` over `[t_a, t_b)`, or `[t_a, t_b]` for the `last` one.
fn window(ev: &EventStream, index: usize, t_a: f64, t_b: f64, last: bool) -> Window {
    let end = if last { t_b.next_up() } else { t_b };
    Window {
        index,
        t_a,
        t_b,
        range: ev.window_range(t_a, end),
    }
}

/// Windows between consecutive frame times; the last one includes its end time.
pub(crate) fn windows_between(ev: &EventStream, times: &[f64]) -> Vec<Window> {
    let n = times.len().saturating_sub(1);
    (0..n)
        .map(|i| window(ev, i, times[i], times[i + 1], i + 1 == n))
        .collect()
}

impl Source {
    fn build(
        events_path: PathBuf,
        events: EventStream,
        intrinsics: Option<Intrinsics>,
        windows: Vec<Window>,
    ) -> Source {
        let (xu, yu) = undistort_all(&events, intrinsics.as_ref());
        let source_hash = scene::formats::evs::content_hash(&events);
        Source {
            events_path,
            events,
            xu,
            yu,
            intrinsics,
            windows,
            source_hash,
        }
    }

    /// The events of a scene directory, one window per train interval (`frame_window`
    /// 0) or one of `frame_window` seconds around each train frame.
    pub fn from_scene(dir: &Path, frame_window: f64) -> Result<Source> {
        let scene = scene::Scene::open(dir)?;
        let train = dir.join(scene::manifest::TRAIN_FILE);
        let events_path = scene
            .events_path()
            .ok_or_else(|| Error::invalid(&train, "the scene has no events entry"))?;
        if scene.train.frames.len() < 2 {
            return Err(Error::invalid(
                &train,
                "a single train frame has no interval to compute flow over; \
                 use --events FILE --sensor WxH --window T0,T1 instead",
            ));
        }
        let events = scene.load_events()?;
        // Events off the frames' clock: one error up front, not a warning per window.
        let findings = scene::check::check_frames(&scene.train.frames, &[], Some(&events.t));
        if let Some(e) = scene::check::first_error(&events_path, &findings) {
            return Err(e);
        }
        let times: Vec<f64> = scene.train.frames.iter().map(|f| f.timestamp).collect();
        let windows = if frame_window > 0.0 {
            windows_around(&events, &times, frame_window)
        } else {
            windows_between(&events, &times)
        };
        Ok(Source::build(
            events_path,
            events,
            Some(scene.train.camera),
            windows,
        ))
    }

    /// A bare event file with the given sensor (None: the size the file stores, as
    /// `.es`, `.raw` and `.aedat4` do), optional calibration and windows.
    pub fn from_events(
        path: &Path,
        sensor: Option<(u32, u32)>,
        calib: Option<&Path>,
        spec: &WindowSpec,
    ) -> Result<Source> {
        let opts = scene::ReadOptions {
            sensor,
            coord_scale: None,
        };
        let events = scene::read_events(path, &opts)?;
        let sensor = (events.width, events.height);
        let intrinsics = calib.map(|c| read_calib(c, sensor)).transpose()?;
        let (first, last) = match (events.t.first(), events.t.last()) {
            (Some(&a), Some(&b)) => (a, b),
            _ => return Err(Error::invalid(path, "the event file has no events")),
        };
        let windows: Vec<(f64, f64)> = if !spec.windows.is_empty() {
            spec.windows.clone()
        } else if let Some(len) = spec.window_length {
            if !(len.is_finite() && len > 0.0) {
                return Err(Error::Other(format!("--window-length {len} must be > 0")));
            }
            let count = (((last - first) / len).floor() as usize + 1).min(1_000_000);
            (0..count)
                .map(|k| (first + k as f64 * len, first + (k + 1) as f64 * len))
                .collect()
        } else {
            vec![(first, last)]
        };
        let n = windows.len();
        let windows = windows
            .into_iter()
            .enumerate()
            .map(|(i, (t_a, t_b))| {
                // The whole-stream window (and the last of a tiling) includes its end.
                let end = if spec.windows.is_empty() && i + 1 == n {
                    t_b.next_up()
                } else {
                    t_b
                };
                Window {
                    index: i,
                    t_a,
                    t_b,
                    range: events.window_range(t_a, end),
                }
            })
            .collect();
        Ok(Source::build(
            path.to_path_buf(),
            events,
            intrinsics,
            windows,
        ))
    }

    pub fn width(&self) -> u32 {
        self.events.width
    }

    pub fn height(&self) -> u32 {
        self.events.height
    }

    /// The window's events for the CM loss, undistorted, with times normalised to
    /// `[0, 1]` over the window (so the flow is in px per window). At most `max`
    /// events, taken at an even stride (all when `max == 0`).
    pub fn cm_events(&self, w: &Window, max: usize) -> CmEvents {
        let n = w.len();
        let stride = if max > 0 && n > max {
            n.div_ceil(max)
        } else {
            1
        };
        let span = w.duration();
        let inv = if span > 0.0 { 1.0 / span } else { 0.0 };
        let mut ev = CmEvents::default();
        for i in w.range.clone().step_by(stride) {
            ev.x.push(self.xu[i] as f64);
            ev.y.push(self.yu[i] as f64);
            ev.t.push((self.events.t[i] - w.t_a) * inv);
        }
        ev
    }

    /// Normalised voxel grid (`bins × H × W`, Eq. 15) of the window's undistorted events.
    pub fn voxel(&self, w: &Window, bins: usize) -> Vec<f32> {
        let (wd, ht) = (self.width(), self.height());
        let mut ev = EventStream::with_capacity(wd, ht, w.len());
        for i in w.range.clone() {
            let (x, y) = (self.xu[i].round(), self.yu[i].round());
            if x >= 0.0 && y >= 0.0 && (x as u32) < wd && (y as u32) < ht {
                ev.push(self.events.t[i], x as u16, y as u16, self.events.p[i]);
            }
        }
        crate::voxel::voxel_grid(&ev.as_slice(), w.t_a, w.t_b, bins, wd, ht)
    }

    /// Pixel whose flow event `i` uses (nearest pixel of its undistorted position).
    pub fn event_pixel(&self, i: usize) -> usize {
        crate::cm::event_pixel(
            self.xu[i] as f64,
            self.yu[i] as f64,
            self.width() as usize,
            self.height() as usize,
        )
    }

    /// Total events over all windows.
    pub fn window_events(&self) -> usize {
        self.windows.iter().map(Window::len).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One event every millisecond over [0, 1] s.
    fn stream() -> EventStream {
        let mut ev = EventStream::with_capacity(8, 8, 1001);
        for k in 0..=1000 {
            ev.push(k as f64 / 1000.0, 1, 2, 1);
        }
        ev
    }

    #[test]
    fn frame_windows_are_centred_clamped_and_disjoint() {
        let ev = stream();
        let times = [0.0, 0.25, 0.3, 1.0];
        let w = windows_around(&ev, &times, 0.1);
        let spans: Vec<(f64, f64)> = w.iter().map(|w| (w.t_a, w.t_b)).collect();
        // First clamped to the first frame, 2nd/3rd to their midpoint 0.275, last to 1.
        assert_eq!(
            spans,
            vec![(0.0, 0.05), (0.2, 0.275), (0.275, 0.35), (0.95, 1.0)]
        );
        // Events [t_a, t_b), the last window including its end: 50, 75, 75, 51 events.
        let counts: Vec<usize> = w.iter().map(Window::len).collect();
        assert_eq!(counts, vec![50, 75, 75, 51]);
        for p in w.windows(2) {
            assert!(p[0].range.end <= p[1].range.start);
        }
        // Interval windows cover everything once.
        let b = windows_between(&ev, &times);
        assert_eq!(b.iter().map(Window::len).sum::<usize>(), 1001);
    }
}
