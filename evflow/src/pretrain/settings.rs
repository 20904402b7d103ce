//! Settings of a pretraining run and their validation.

use crate::net::NetConfig;
use serde::{Deserialize, Serialize};
use synth::SynthConfig;

/// Settings of a pretraining run (TOML/JSON; every field defaulted).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PretrainSettings {
    /// Base width C of the network.
    pub base: usize,
    /// Voxel-grid bins B.
    pub bins: usize,
    /// Largest flow the network can output, px per window.
    pub max_flow: f64,
    /// Presets of the training scenes (each combined with every training seed).
    pub presets: Vec<String>,
    /// Seeds of the training scenes.
    pub train_seeds: Vec<u64>,
    /// Presets and seeds of the held-out scenes (seeds disjoint from `train_seeds`).
    pub eval_presets: Vec<String>,
    pub eval_seeds: Vec<u64>,
    /// Square sensor size of the synthetic scenes, px.
    pub resolution: u32,
    /// Length of each synthetic recording, s.
    pub scene_duration: f64,
    /// Internal render rate of the event simulator, Hz.
    pub render_rate_hz: f64,
    /// Range of the window length L, s.
    pub window_min_s: f64,
    pub window_max_s: f64,
    /// Range of the per-scene speed factor applied to all motion.
    pub speed_min: f64,
    pub speed_max: f64,
    /// Speed range of the held-out scenes, `[min, max]` (default: the training range).
    pub eval_speed: Option<[f64; 2]>,
    /// Square sizes (px) at which the training scenes are rendered, cycling over the
    /// scenes in order; windows of scenes larger than `resolution` are cropped to
    /// `resolution`² at a random place (finer texture and larger motion in pixels at the
    /// same step cost). Empty: every scene at `resolution`. Held-out scenes are always
    /// at `resolution`.
    pub train_sizes: Vec<u32>,
    /// Also transpose training windows (x ↔ y) at random, besides the flips.
    pub augment_transpose: bool,
    /// Also play training windows backwards at random (`Augment::reverse` in
    /// `pretrain::data`).
    pub augment_reverse: bool,
    /// Adam steps.
    pub iterations: usize,
    /// Windows per step.
    pub batch: usize,
    /// Learning rate at the first and the last step (exponential decay between).
    pub lr: f64,
    pub lr_final: f64,
    /// Weight of the supervised EPE loss.
    pub supervised_weight: f64,
    /// Weight of the contrast-maximisation loss (0 = off).
    pub cm_weight: f64,
    /// Events per window used by the CM loss (even stride; 0 = all).
    pub cm_max_events: usize,
    /// Seed of network initialisation and window sampling.
    pub seed: u64,
    /// Windows per held-out scene.
    pub eval_windows: usize,
    /// Evaluate on the held-out scenes every this many steps (0 = only at the end).
    pub eval_every: usize,
}

impl Default for PretrainSettings {
    fn default() -> Self {
        PretrainSettings {
            base: 16,
            bins: 5,
            max_flow: 32.0,
            presets: ["static", "rigid", "nonrigid", "fast"]
                .map(String::from)
                .to_vec(),
            train_seeds: (1..=6).collect(),
            eval_presets: vec!["rigid".into(), "fast".into()],
            eval_seeds: vec![1001, 1002],
            resolution: 64,
            scene_duration: 1.0,
            render_rate_hz: 500.0,
            window_min_s: 0.05,
            window_max_s: 0.2,
            speed_min: 0.5,
            speed_max: 3.0,
            eval_speed: None,
            train_sizes: Vec::new(),
            augment_transpose: false,
            augment_reverse: false,
            iterations: 1500,
            batch: 4,
            lr: 1e-3,
            lr_final: 1e-4,
            supervised_weight: 1.0,
            cm_weight: 0.0,
            cm_max_events: 20_000,
            seed: 0,
            eval_windows: 8,
            eval_every: 0,
        }
    }
}

impl stagekit::Settings for PretrainSettings {
    /// `Err` with a sentence naming the first bad setting.
    fn validate(&self) -> std::result::Result<(), String> {
        if self.base == 0 || self.bins < 2 {
            return Err("base must be ≥ 1 and bins ≥ 2".into());
        }
        for (name, v) in [
            ("max_flow", self.max_flow),
            ("scene_duration", self.scene_duration),
            ("render_rate_hz", self.render_rate_hz),
            ("window_min_s", self.window_min_s),
            ("speed_min", self.speed_min),
            ("lr", self.lr),
            ("lr_final", self.lr_final),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} = {v} must be finite and > 0"));
            }
        }
        if !(self.window_max_s >= self.window_min_s && self.window_max_s < self.scene_duration) {
            return Err("need window_min_s ≤ window_max_s < scene_duration".into());
        }
        if !(self.speed_max.is_finite() && self.speed_max >= self.speed_min) {
            return Err("speed_max must be finite and ≥ speed_min".into());
        }
        if let Some([lo, hi]) = self.eval_speed
            && !(lo.is_finite() && lo > 0.0 && hi.is_finite() && hi >= lo)
        {
            return Err(format!(
                "eval_speed [{lo}, {hi}] must be finite, > 0, min ≤ max"
            ));
        }
        if let Some(z) = self
            .train_sizes
            .iter()
            .find(|&&z| z < self.resolution || z > 1024)
        {
            return Err(format!(
                "train_sizes entry {z} must be in resolution ({})..=1024",
                self.resolution
            ));
        }
        if !(self.supervised_weight >= 0.0 && self.cm_weight >= 0.0)
            || self.supervised_weight + self.cm_weight <= 0.0
        {
            return Err("supervised_weight and cm_weight must be ≥ 0, not both 0".into());
        }
        if self.batch == 0 || self.presets.is_empty() || self.train_seeds.is_empty() {
            return Err("batch, presets and train_seeds must be non-empty".into());
        }
        if !(16..=1024).contains(&self.resolution) {
            return Err(format!(
                "resolution {} must be in 16..=1024",
                self.resolution
            ));
        }
        for p in self.presets.iter().chain(&self.eval_presets) {
            if SynthConfig::preset(p).is_none() {
                return Err(format!(
                    "unknown preset '{p}' (known: {:?})",
                    synth::PRESETS
                ));
            }
        }
        if let Some(s) = self
            .eval_seeds
            .iter()
            .find(|s| self.train_seeds.contains(s))
        {
            return Err(format!(
                "eval seed {s} is also a training seed; held-out scenes must differ"
            ));
        }
        Ok(())
    }
}

impl PretrainSettings {
    pub(crate) fn net_config(&self) -> NetConfig {
        NetConfig {
            base: self.base,
            bins: self.bins,
            max_flow: self.max_flow,
        }
    }
}
