//! The after-the-fact scene transform of `degs stress` (`synth stress`): a pure function from a scene
//! directory and [`SceneTransform`] settings to a new scene directory. It applies the
//! stresses a recording can be given after it was made (fewer train frames, added
//! noise events, a wrong claimed contrast threshold, a gap without events, a burst of
//! events, a corrupted file), so synthetic and recorded bases go through the same code.
//!
//! The output is a copy of the base (files hard-linked where unchanged) with:
//! - `transforms_train.json` rewritten (frames dropped, C changed) when needed;
//! - `events.evs` rewritten when the events change (noise, hot pixels, gap, burst); the
//!   per-event ground truth `gt/event_flow.bin` is then left out (its rows would no
//!   longer match the events), and `gt/train/` is left out when train frames are
//!   dropped (its files are numbered by manifest index);
//! - `stress.json`: the settings and what was done ([`TransformSummary`]).
//!
//! Random choices (noise pixels, times, polarities) come from `seed` only.

use anyhow::{Context, Result, bail};
use scene::events::EventStream;
use scene::manifest::{Scene, TRAIN_FILE};
use serde::{Deserialize, Serialize};
use std::fs;
use std::path::Path;

/// A corrupted input: what a broken copy of a recording looks like.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Corruption {
    /// The events file cut to half its bytes.
    TruncatedEvents,
    /// The middle train frame's image deleted (the manifest still lists it).
    MissingFrame,
    /// A `NaN` (the token Python's json writes) in the middle train frame's pose.
    NanPose,
}

impl Corruption {
    pub const ALL: [Corruption; 3] = [
        Corruption::TruncatedEvents,
        Corruption::MissingFrame,
        Corruption::NanPose,
    ];
    pub fn name(self) -> &'static str {
        match self {
            Corruption::TruncatedEvents => "truncated-events",
            Corruption::MissingFrame => "missing-frame",
            Corruption::NanPose => "nan-pose",
        }
    }
}

/// What to do to a scene; the default changes nothing.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SceneTransform {
    /// Keep a train frame when it is at least `1/train_fps` s after the last kept one
    /// (the first is kept); test frames are untouched.
    pub train_fps: Option<f64>,
    /// Added background activity: uniform events, this many per pixel per second over
    /// the train frames' time span, random polarity.
    pub noise_hz: f64,
    /// This fraction of pixels made hot, each firing `+1` events at `hot_pixel_hz`.
    pub hot_pixel_fraction: f64,
    pub hot_pixel_hz: f64,
    /// True C / claimed C: the events stay, the manifest claims `C / contrast_ratio`
    /// (0.5: the events were made with half the claimed C).
    pub contrast_ratio: Option<f64>,
    /// Remove every event in a window of this fraction of the train span, centred on
    /// its middle.
    pub gap_fraction: f64,
    /// Add this many events (uniform pixels and polarity) within `burst_s` seconds
    /// starting a third of the way through the train span.
    pub burst_events: u64,
    pub burst_s: f64,
    pub corrupt: Option<Corruption>,
    pub seed: u64,
}

/// What [`apply`] did (written to `stress.json` in the new scene).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TransformSummary {
    pub settings: SceneTransform,
    pub train_frames_before: usize,
    pub train_frames: usize,
    pub events_before: usize,
    pub events: usize,
    pub noise_events: usize,
    pub hot_pixels: usize,
    pub hot_events: usize,
    /// `[t0, t1)` of the gap and the events removed from it.
    pub gap: Option<[f64; 2]>,
    pub gap_removed: usize,
    /// `[t0, t1)` of the burst.
    pub burst: Option<[f64; 2]>,
    pub burst_added: usize,
    pub contrast_claimed: Option<f64>,
    /// The file the corruption damaged.
    pub corrupted_file: Option<String>,
}

/// SplitMix64: a small seeded generator (no dependency for a few uniform draws).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn below(&mut self, n: u32) -> u32 {
        (((self.next() >> 32) * n as u64) >> 32) as u32
    }
}

impl SceneTransform {
    /// Checks that each setting is in range.
    pub fn validate(&self) -> Result<()> {
        let finite_pos = |v: f64| v.is_finite() && v > 0.0;
        let finite_nonneg = |v: f64| v.is_finite() && v >= 0.0;
        if self.train_fps.is_some_and(|f| !finite_pos(f)) {
            bail!("train_fps must be > 0");
        }
        if self.contrast_ratio.is_some_and(|c| !finite_pos(c)) {
            bail!("contrast_ratio must be > 0");
        }
        if ![self.noise_hz, self.hot_pixel_hz, self.burst_s]
            .into_iter()
            .all(finite_nonneg)
        {
            bail!("noise_hz, hot_pixel_hz and burst_s must be finite and >= 0");
        }
        if !(0.0..=1.0).contains(&self.hot_pixel_fraction)
            || !(0.0..1.0).contains(&self.gap_fraction)
        {
            bail!("hot_pixel_fraction must be in [0, 1] and gap_fraction in [0, 1)");
        }
        if self.burst_events > 0 && !finite_pos(self.burst_s) {
            bail!("a burst needs burst_s > 0");
        }
        Ok(())
    }

    fn changes_events(&self) -> bool {
        self.noise_hz > 0.0
            || (self.hot_pixel_fraction > 0.0 && self.hot_pixel_hz > 0.0)
            || self.gap_fraction > 0.0
            || self.burst_events > 0
    }
}

/// Write the transformed copy of the scene `base` to `out` (which must not exist; the
/// caller writes into a temp directory and renames it).
pub fn apply(base: &Path, out: &Path, t: &SceneTransform) -> Result<TransformSummary> {
    t.validate()?;
    let scene = Scene::open(base)?;
    let mut train = scene.train.clone();
    let mut summary = TransformSummary {
        settings: t.clone(),
        train_frames_before: train.frames.len(),
        ..Default::default()
    };
    if let Some(fps) = t.train_fps {
        let step = 1.0 / fps;
        let mut last = f64::NEG_INFINITY;
        // 1e-9 s of slack: frame times written as k/fps need not add up exactly
        train.frames.retain(|f| {
            let keep = f.timestamp - last >= step - 1e-9;
            if keep {
                last = f.timestamp;
            }
            keep
        });
    }
    summary.train_frames = train.frames.len();
    let span = (
        train.frames.first().map_or(0.0, |f| f.timestamp),
        train.frames.last().map_or(0.0, |f| f.timestamp),
    );

    let events_path = scene.events_path();
    let mut skip: Vec<std::path::PathBuf> = vec![base.join(TRAIN_FILE), base.join("stress.json")];
    if t.changes_events() {
        let ev = scene.load_events()?;
        summary.events_before = ev.len();
        let ev = change_events(ev, span, t, &mut summary);
        summary.events = ev.len();
        skip.extend(events_path.iter().cloned());
        skip.push(base.join("gt").join("event_flow.bin"));
        copy_tree(base, out, &skip, t.train_fps.is_some())?;
        scene::formats::write_evs(out.join("events.evs"), &ev)?;
        if let Some(e) = train.events.as_mut() {
            e.path = "events.evs".into();
        }
    } else {
        copy_tree(base, out, &skip, t.train_fps.is_some())?;
    }
    if let (Some(r), Some(e)) = (t.contrast_ratio, train.events.as_mut()) {
        e.contrast_threshold /= r;
        summary.contrast_claimed = Some(e.contrast_threshold);
    }
    train.write(out.join(TRAIN_FILE))?;
    if let Some(c) = t.corrupt {
        let copy = Scene {
            root: out.to_path_buf(),
            train: train.clone(),
            ..scene.clone()
        };
        summary.corrupted_file = Some(corrupt(&copy, c)?);
    }
    scene::atomic::write_json_atomic(&out.join("stress.json"), &summary)?;
    Ok(summary)
}

/// Noise, hot pixels, the burst and the gap, in that order (a gap removes noise too).
fn change_events(
    mut ev: EventStream,
    span: (f64, f64),
    t: &SceneTransform,
    s: &mut TransformSummary,
) -> EventStream {
    let mut rng = Rng(t.seed ^ 0x5eed_5eed);
    let (w, h) = (ev.width, ev.height);
    let pixels = w as f64 * h as f64;
    let length = (span.1 - span.0).max(0.0);
    let before = ev.len();
    // the expected count, rounded: the added rate is noise_hz over the sensor exactly
    // up to that rounding
    let n = (t.noise_hz * pixels * length).round() as usize;
    for _ in 0..n {
        let time = span.0 + rng.unit() * length;
        let p = if rng.next() & 1 == 0 { 1 } else { -1 };
        ev.push(time, rng.below(w) as u16, rng.below(h) as u16, p);
    }
    s.noise_events = ev.len() - before;
    if t.hot_pixel_fraction > 0.0 && t.hot_pixel_hz > 0.0 {
        let count = ((t.hot_pixel_fraction * pixels).round() as usize).max(1);
        let per_pixel = (t.hot_pixel_hz * length).round() as usize;
        let before = ev.len();
        for _ in 0..count {
            let (x, y) = (rng.below(w) as u16, rng.below(h) as u16);
            for _ in 0..per_pixel {
                ev.push(span.0 + rng.unit() * length, x, y, 1);
            }
        }
        s.hot_pixels = count;
        s.hot_events = ev.len() - before;
    }
    if t.burst_events > 0 {
        let t0 = span.0 + length / 3.0;
        for _ in 0..t.burst_events {
            let p = if rng.next() & 1 == 0 { 1 } else { -1 };
            ev.push(
                t0 + rng.unit() * t.burst_s,
                rng.below(w) as u16,
                rng.below(h) as u16,
                p,
            );
        }
        s.burst = Some([t0, t0 + t.burst_s]);
        s.burst_added = t.burst_events as usize;
    }
    ev.sort_by_time();
    if t.gap_fraction > 0.0 {
        let mid = 0.5 * (span.0 + span.1);
        let (g0, g1) = (
            mid - 0.5 * t.gap_fraction * length,
            mid + 0.5 * t.gap_fraction * length,
        );
        let r = ev.window_range(g0, g1);
        s.gap_removed = r.len();
        ev.t.drain(r.clone());
        ev.x.drain(r.clone());
        ev.y.drain(r.clone());
        ev.p.drain(r);
        s.gap = Some([g0, g1]);
    }
    ev
}

/// Damage the new scene in `out` as `c` says; the damaged file's name.
fn corrupt(copy: &Scene, c: Corruption) -> Result<String> {
    let (out, train) = (copy.root.as_path(), &copy.train);
    let middle = train.frames.len() / 2;
    match c {
        Corruption::TruncatedEvents => {
            let ev = train
                .events
                .as_ref()
                .context("truncated-events: the scene has no events")?;
            let path = out.join(&ev.path);
            let bytes = fs::read(&path).with_context(|| format!("{}", path.display()))?;
            // a fresh file, not the hard link into the base scene
            fs::remove_file(&path).with_context(|| format!("{}", path.display()))?;
            fs::write(&path, &bytes[..bytes.len() / 2])
                .with_context(|| format!("{}", path.display()))?;
            Ok(ev.path.clone())
        }
        Corruption::MissingFrame => {
            let f = &train.frames[middle];
            let path = copy.image_path(f);
            fs::remove_file(&path).with_context(|| format!("{}", path.display()))?;
            Ok(f.file_path.clone())
        }
        Corruption::NanPose => {
            let path = out.join(TRAIN_FILE);
            let text = fs::read_to_string(&path)?;
            let mut json: serde_json::Value = serde_json::from_str(&text)?;
            let cell = json["frames"][middle]["transform_matrix"][0]
                .get_mut(3)
                .context("nan-pose: no transform_matrix to damage")?;
            *cell = serde_json::Value::String("@NAN@".into());
            let text = serde_json::to_string_pretty(&json)?.replace("\"@NAN@\"", "NaN");
            fs::write(&path, text).with_context(|| format!("{}", path.display()))?;
            Ok(TRAIN_FILE.into())
        }
    }
}

/// Copy `from` into `to` (hard links where the file system allows), leaving out `skip`
/// and, with `drop_train_gt`, `gt/train/`.
fn copy_tree(
    from: &Path,
    to: &Path,
    skip: &[std::path::PathBuf],
    drop_train_gt: bool,
) -> Result<()> {
    fs::create_dir_all(to).with_context(|| format!("{}: cannot create", to.display()))?;
    for e in fs::read_dir(from).with_context(|| format!("{}: cannot list", from.display()))? {
        let e = e?;
        let src = e.path();
        let dst = to.join(e.file_name());
        if skip.contains(&src)
            || src
                .file_name()
                .is_some_and(|n| n == scene::atomic::ENTRY_MANIFEST)
            || (drop_train_gt && src.ends_with("gt/train"))
        {
            continue;
        }
        if e.file_type()?.is_dir() {
            copy_tree(&src, &dst, skip, drop_train_gt)?;
        } else if fs::hard_link(&src, &dst).is_err() {
            fs::copy(&src, &dst).with_context(|| format!("{}: cannot copy", src.display()))?;
        }
    }
    Ok(())
}
