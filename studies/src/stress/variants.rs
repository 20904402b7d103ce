//! Stress files and their expansion into scene variants and experiments.
//!
//! ```toml
//! name = "stress-nonrigid"      # runs/<name>/: stress.json, report.md, charts
//! base = "nonrigid-64.toml"     # an experiment file (relative to this file), or [base]
//!
//! [stresses]                    # absent: every stress at the levels below (the issue's)
//! fps = [40, 20, 10, 5]         # train frame rate, Hz (test frames fixed)
//! noise_hz = [0.5, 5, 20]       # background activity, events per pixel per second
//! hot_pixels = [0.001, 0.01]    # fraction of pixels firing at settings.hot_pixel_hz
//! contrast_ratio = [0.5, 2]     # true C / the C the manifest claims
//! blur_subframes = [8, 16, 32]  # train frames averaged over n renders (synthetic only)
//! gap_fraction = [0.25]         # no events in this share of the recording (centred)
//! burst_events = [10000000]     # events in one burst of settings.burst_s, counted on
//!                               # a settings.burst_reference_sensor (scaled to ours)
//! corrupt = ["truncated-events", "missing-frame", "nan-pose"]
//!
//! [settings]
//! hot_pixel_hz = 50.0
//! burst_s = 0.01
//! burst_reference_sensor = [1280, 720]
//! seed = 1
//! ```
//!
//! Each level is one scene variant, plus the unstressed `clean` one. On a synthetic
//! base, frame rate, noise, hot pixels and blur are `degs synth` settings (the scene is
//! generated so); everything else, and every stress of a scene directory, is the
//! after-the-fact [`SceneTransform`] of the clean scene. Each variant runs twice: DEGS
//! (the base's settings) and RGB-only (`deform` with `schedule.gamma1 = gamma2_max = 0`).

use crate::sweep::{self, Sweep};
use anyhow::{Result, anyhow, bail};
use runner::experiment::{Experiment, SceneSource};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use synth::transform::{Corruption, SceneTransform};
use toml::{Table, Value};

/// One kind of stress.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StressKind {
    Fps,
    NoiseHz,
    HotPixels,
    ContrastRatio,
    BlurSubframes,
    GapFraction,
    BurstEvents,
    Corrupt,
}

impl StressKind {
    pub const ALL: [StressKind; 8] = [
        StressKind::Fps,
        StressKind::NoiseHz,
        StressKind::HotPixels,
        StressKind::ContrastRatio,
        StressKind::BlurSubframes,
        StressKind::GapFraction,
        StressKind::BurstEvents,
        StressKind::Corrupt,
    ];
    /// The key in `[stresses]` and in variant names.
    pub fn key(self) -> &'static str {
        match self {
            StressKind::Fps => "fps",
            StressKind::NoiseHz => "noise_hz",
            StressKind::HotPixels => "hot_pixels",
            StressKind::ContrastRatio => "contrast_ratio",
            StressKind::BlurSubframes => "blur_subframes",
            StressKind::GapFraction => "gap_fraction",
            StressKind::BurstEvents => "burst_events",
            StressKind::Corrupt => "corrupt",
        }
    }
    /// The x axis of its chart.
    pub(crate) fn axis_label(self) -> &'static str {
        match self {
            StressKind::Fps => "train frame rate (Hz)",
            StressKind::NoiseHz => "background activity (events / pixel / s)",
            StressKind::HotPixels => "hot pixels (fraction of the sensor)",
            StressKind::ContrastRatio => "true C / claimed C (ratio)",
            StressKind::BlurSubframes => "exposure (sub-frames averaged)",
            StressKind::GapFraction => "gap without events (fraction of the recording)",
            StressKind::BurstEvents => "burst (events per 10 ms at the reference sensor)",
            StressKind::Corrupt => "corruption",
        }
    }
    /// The issue's levels (#18 item 1).
    fn default_levels(self) -> Vec<Value> {
        let f = |v: &[f64]| v.iter().map(|&x| Value::Float(x)).collect();
        match self {
            StressKind::Fps => f(&[40.0, 20.0, 10.0, 5.0]),
            StressKind::NoiseHz => f(&[0.5, 5.0, 20.0]),
            StressKind::HotPixels => f(&[0.001, 0.01]),
            StressKind::ContrastRatio => f(&[0.5, 2.0]),
            StressKind::BlurSubframes => vec![8.into(), 16.into(), 32.into()],
            StressKind::GapFraction => f(&[0.25]),
            StressKind::BurstEvents => vec![10_000_000.into()],
            StressKind::Corrupt => Corruption::ALL
                .iter()
                .map(|c| Value::String(c.name().into()))
                .collect(),
        }
    }
}

/// `[settings]` of a stress file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StressSettings {
    pub hot_pixel_hz: f64,
    pub burst_s: f64,
    /// The sensor a `burst_events` level is counted on; ours gets the same events per
    /// pixel (10 M on 1280×720 is 10.9 per pixel: 44 k on 64×64).
    pub burst_reference_sensor: [u32; 2],
    pub seed: u64,
}

impl Default for StressSettings {
    fn default() -> Self {
        StressSettings {
            hot_pixel_hz: 50.0,
            burst_s: 0.01,
            burst_reference_sensor: [1280, 720],
            seed: 1,
        }
    }
}

/// How a variant's scene is made.
#[derive(Clone, Debug, PartialEq)]
pub enum Recipe {
    /// The base scene.
    Clean,
    /// The base's synthetic scene with these `scene.settings.*` values.
    Synth(Vec<(String, Value)>),
    /// The clean scene through [`synth::transform::apply`].
    Transform(SceneTransform),
}

/// One scene variant.
#[derive(Clone, Debug, PartialEq)]
pub struct Variant {
    /// `clean`, `fps-20`, `corrupt-nan-pose`.
    pub name: String,
    /// None for the clean variant.
    pub kind: Option<StressKind>,
    /// The level on the chart (None for a corruption).
    pub level: Option<f64>,
    /// The level as written in the file.
    pub label: String,
    pub recipe: Recipe,
}

/// The two methods every variant runs with, and the `deform` settings that make them.
pub(crate) const METHODS: [(&str, &[(&str, f64)]); 2] = [
    ("degs", &[]),
    (
        "rgb",
        &[
            ("deform.schedule.gamma1", 0.0),
            ("deform.schedule.gamma2_max", 0.0),
        ],
    ),
];

/// A parsed stress file.
#[derive(Clone, Debug)]
pub struct StressFile {
    pub name: String,
    pub file: PathBuf,
    /// The base experiment as a sweep without axes (makes the variants' experiments).
    pub sweep: Sweep,
    pub base: Experiment,
    pub stresses: Vec<(StressKind, Vec<Value>)>,
    pub settings: StressSettings,
    /// The sensor size and train frame rate of the base scene.
    pub sensor: (u32, u32),
    pub base_fps: f64,
}

const KEYS: [&str; 4] = ["name", "base", "stresses", "settings"];

impl StressFile {
    pub fn load(path: &Path) -> Result<StressFile> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| anyhow!("{}: cannot read stress file: {e}", path.display()))?;
        Self::parse(&text, path)
    }

    pub fn parse(text: &str, path: &Path) -> Result<StressFile> {
        let at = |e: String| anyhow!("{}: {e}", path.display());
        let (mut top, name) = sweep::parse_named_table(text, path, &KEYS, "a stress file")?;
        let (base_table, base_file) = sweep::take_base(&mut top, path)?;
        let sweep = Sweep::over_base(&name, path, base_table, base_file);
        let base = sweep.experiment(&name, &[])?;
        let settings: StressSettings = match top.remove("settings") {
            Some(v) => v
                .try_into()
                .map_err(|e: toml::de::Error| at(format!("[settings]: {}", e.message())))?,
            None => StressSettings::default(),
        };
        let stresses = match top.remove("stresses") {
            None => StressKind::ALL
                .iter()
                .map(|&k| (k, k.default_levels()))
                .collect(),
            Some(Value::Table(t)) => {
                parse_stresses(t).map_err(|e| at(format!("[stresses]: {e}")))?
            }
            Some(_) => return Err(at("[stresses] must be a table of stress = [levels]".into())),
        };
        let (sensor, base_fps) =
            base_sensor(&base).map_err(|e| at(format!("base scene: {e:#}")))?;
        let file = StressFile {
            name,
            file: path.to_path_buf(),
            sweep,
            base,
            stresses,
            settings,
            sensor,
            base_fps,
        };
        // every variant and experiment must build before anything runs
        for v in file.variants()? {
            file.experiments(&v, Path::new("/"))?;
        }
        Ok(file)
    }

    fn synthetic(&self) -> Option<&synth::SynthConfig> {
        match &self.base.scene {
            SceneSource::Synth(cfg) => Some(cfg),
            SceneSource::Dir(_) => None,
        }
    }

    /// The level a stress has on the clean scene (its chart's reference point).
    pub(crate) fn neutral_level(&self, kind: StressKind) -> Option<f64> {
        match kind {
            StressKind::Fps => Some(self.base_fps),
            StressKind::NoiseHz => Some(self.synthetic().map_or(0.0, |c| c.events.shot_noise_hz)),
            StressKind::HotPixels => Some(
                self.synthetic()
                    .map_or(0.0, |c| c.events.hot_pixel_fraction),
            ),
            StressKind::ContrastRatio => Some(1.0),
            StressKind::BlurSubframes => {
                Some(self.synthetic().map_or(1.0, |c| c.blur_subframes as f64))
            }
            StressKind::GapFraction | StressKind::BurstEvents => Some(0.0),
            StressKind::Corrupt => None,
        }
    }

    /// `clean` first, then every level of every stress, in file order.
    pub fn variants(&self) -> Result<Vec<Variant>> {
        let file = self.file.display();
        let mut out = vec![Variant {
            name: "clean".into(),
            kind: None,
            level: None,
            label: "clean".into(),
            recipe: Recipe::Clean,
        }];
        let synth = self.synthetic();
        for (kind, levels) in &self.stresses {
            for v in levels {
                let label = level_text(v);
                let name = format!("{}-{label}", kind.key()).replace('_', "-");
                let bad = |why: &str| anyhow!("{file}: [stresses] {} = {v}: {why}", kind.key());
                let level = v.as_float().or(v.as_integer().map(|i| i as f64));
                let transform = |t: SceneTransform| -> Result<Recipe> {
                    t.validate().map_err(|e| bad(&e.to_string()))?;
                    Ok(Recipe::Transform(t))
                };
                let seed = self.settings.seed;
                let recipe = match (kind, level, synth) {
                    (StressKind::Corrupt, _, _) => {
                        let c = Corruption::ALL
                            .into_iter()
                            .find(|c| Some(c.name()) == v.as_str())
                            .ok_or_else(|| {
                                bad("not one of truncated-events, missing-frame, nan-pose")
                            })?;
                        Recipe::Transform(SceneTransform {
                            corrupt: Some(c),
                            seed,
                            ..Default::default()
                        })
                    }
                    (_, None, _) => return Err(bad("a level is a number")),
                    (StressKind::Fps, Some(f), Some(_)) => {
                        Recipe::Synth(vec![("train_fps".into(), Value::Float(f))])
                    }
                    (StressKind::NoiseHz, Some(h), Some(_)) => {
                        Recipe::Synth(vec![("events.shot_noise_hz".into(), Value::Float(h))])
                    }
                    (StressKind::HotPixels, Some(h), Some(_)) => Recipe::Synth(vec![
                        ("events.hot_pixel_fraction".into(), Value::Float(h)),
                        (
                            "events.hot_pixel_hz".into(),
                            Value::Float(self.settings.hot_pixel_hz),
                        ),
                    ]),
                    (StressKind::BlurSubframes, Some(n), Some(cfg)) => {
                        if n < 1.0 || n.fract() != 0.0 {
                            return Err(bad("a whole number of sub-frames"));
                        }
                        // sub-frames at the simulator's render rate: n of them span n/rate s
                        Recipe::Synth(vec![
                            ("blur_subframes".into(), Value::Integer(n as i64)),
                            ("exposure_s".into(), Value::Float(n / cfg.render_rate_hz)),
                        ])
                    }
                    (StressKind::BlurSubframes, Some(_), None) => {
                        return Err(bad(
                            "blur needs a synthetic base (a recorded frame cannot be re-exposed)",
                        ));
                    }
                    (StressKind::Fps, Some(f), None) => transform(SceneTransform {
                        train_fps: Some(f),
                        ..Default::default()
                    })?,
                    (StressKind::NoiseHz, Some(h), None) => transform(SceneTransform {
                        noise_hz: h,
                        seed,
                        ..Default::default()
                    })?,
                    (StressKind::HotPixels, Some(h), None) => transform(SceneTransform {
                        hot_pixel_fraction: h,
                        hot_pixel_hz: self.settings.hot_pixel_hz,
                        seed,
                        ..Default::default()
                    })?,
                    (StressKind::ContrastRatio, Some(r), _) => transform(SceneTransform {
                        contrast_ratio: Some(r),
                        ..Default::default()
                    })?,
                    (StressKind::GapFraction, Some(g), _) => transform(SceneTransform {
                        gap_fraction: g,
                        ..Default::default()
                    })?,
                    (StressKind::BurstEvents, Some(n), _) => transform(SceneTransform {
                        burst_events: self.scaled_burst(n),
                        burst_s: self.settings.burst_s,
                        seed,
                        ..Default::default()
                    })?,
                };
                out.push(Variant {
                    name,
                    kind: Some(*kind),
                    level: level.filter(|_| *kind != StressKind::Corrupt),
                    label,
                    recipe,
                });
            }
        }
        Ok(out)
    }

    /// A burst of `n` events on the reference sensor, as many per pixel on ours.
    pub(crate) fn scaled_burst(&self, n: f64) -> u64 {
        let [rw, rh] = self.settings.burst_reference_sensor;
        let ours = self.sensor.0 as f64 * self.sensor.1 as f64;
        (n * ours / (rw as f64 * rh as f64).max(1.0)).round() as u64
    }

    /// The experiment name of a variant run with a method.
    pub(crate) fn experiment_name(&self, variant: &Variant, method: &str) -> String {
        format!("{}_{}_{method}", self.name, variant.name)
    }

    /// The variant's experiments (one per method); `scene_dir` is the transformed
    /// scene of a [`Recipe::Transform`] variant.
    pub fn experiments(&self, v: &Variant, scene_dir: &Path) -> Result<Vec<Experiment>> {
        let mut scene_values: Vec<(String, Value)> = match &v.recipe {
            Recipe::Clean => Vec::new(),
            Recipe::Synth(values) => values
                .iter()
                .map(|(k, x)| (format!("scene.settings.{k}"), x.clone()))
                .collect(),
            Recipe::Transform(_) => {
                let mut t = Table::new();
                t.insert("dir".into(), Value::String(scene_dir.display().to_string()));
                vec![("scene".into(), Value::Table(t))]
            }
        };
        let n = scene_values.len();
        METHODS
            .iter()
            .map(|(method, values)| {
                scene_values.truncate(n);
                scene_values.extend(
                    values
                        .iter()
                        .map(|(k, x)| (k.to_string(), Value::Float(*x))),
                );
                let name = self.experiment_name(v, method);
                self.sweep
                    .experiment(&name, &scene_values)
                    .map_err(|e| anyhow!("{}: variant {}: {e:#}", self.file.display(), v.name))
            })
            .collect()
    }
}

/// A level as it appears in names and tables: `40` for 40.0, strings bare; characters
/// a run name cannot hold become `-`.
fn level_text(v: &Value) -> String {
    let text = match v {
        Value::String(s) => s.clone(),
        Value::Float(f) if f.fract() == 0.0 && f.abs() < 1e15 => format!("{}", *f as i64),
        other => other.to_string(),
    };
    text.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '.' | '-') {
                c
            } else {
                '-'
            }
        })
        .collect()
}

fn parse_stresses(t: Table) -> std::result::Result<Vec<(StressKind, Vec<Value>)>, String> {
    let mut out = Vec::new();
    for (key, v) in t {
        let kind = StressKind::ALL
            .into_iter()
            .find(|k| k.key() == key)
            .ok_or_else(|| {
                let keys: Vec<&str> = StressKind::ALL.iter().map(|k| k.key()).collect();
                format!("unknown stress `{key}` (stresses: {})", keys.join(", "))
            })?;
        match v {
            Value::Array(levels) if !levels.is_empty() => out.push((kind, levels)),
            _ => return Err(format!("`{key}` must be a non-empty list of levels")),
        }
    }
    out.sort_by_key(|(k, _)| *k);
    Ok(out)
}

/// The sensor size and the train frame rate (frames per second of the train span) of
/// the base scene.
fn base_sensor(base: &Experiment) -> Result<((u32, u32), f64)> {
    match &base.scene {
        SceneSource::Synth(cfg) => Ok(((cfg.width, cfg.height), cfg.train_fps)),
        SceneSource::Dir(dir) => {
            let m = scene::manifest::Manifest::read(dir.join(scene::manifest::TRAIN_FILE))?;
            let fps = match (m.frames.first(), m.frames.last()) {
                (Some(a), Some(b)) if b.timestamp > a.timestamp => {
                    (m.frames.len() - 1) as f64 / (b.timestamp - a.timestamp)
                }
                _ => bail!("the train split needs two frames at different times"),
            };
            Ok(((m.camera.width, m.camera.height), fps))
        }
    }
}
