//! The settings of the `evflow` stage (`evflow settings --defaults`): fine-tuning
//! (LoCM) and prediction; every key optional in `settings.toml`.

use crate::budget::{Budget, StopRule};
use crate::net::io::BareWeights;

use serde::{Deserialize, Serialize};
use stagekit::Settings;
use std::path::PathBuf;

/// Which parameters LoCM trains.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// LoRA adapters only (the paper's LoCM).
    #[default]
    Lora,
    /// All base weights ("Full Ft").
    Full,
    /// No fine-tuning ("w/o Flow Ft").
    None,
}

impl std::str::FromStr for Mode {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Mode, String> {
        match s.to_ascii_lowercase().as_str() {
            "lora" => Ok(Mode::Lora),
            "full" => Ok(Mode::Full),
            "none" => Ok(Mode::None),
            _ => Err(format!("mode '{s}' is not lora, full or none")),
        }
    }
}

/// Settings of the `evflow` stage (fine-tuning and prediction); every key optional in
/// `settings.toml`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FlowSettings {
    pub mode: Mode,
    /// A fixed number of passes over the windows; unset (the default) = train until the
    /// CM loss stops improving ([`FlowSettings::stop`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub epochs: Option<usize>,
    /// The stopping rule used when `epochs` is unset.
    pub stop: StopRule,
    /// Adam learning rate at the first step.
    pub lr_start: f64,
    /// Learning rate at the last step (exponential decay in between).
    pub lr_end: f64,
    /// LoRA rank r.
    pub rank: usize,
    /// LoRA α (the update is scaled by α/r).
    pub alpha: f64,
    /// Weight λ of the TV term of the CM loss.
    pub lambda_tv: f64,
    /// Pyramid levels of the CM objective.
    pub cm_scales: usize,
    /// Coarse-to-fine: the first epoch uses only the coarsest CM pyramid level, the
    /// last all of them (the finest level used moves down linearly over the epochs;
    /// with the stopping rule, over the epochs of `stop.min_steps`).
    /// On by default: on large per-window motion it keeps LoRA from sharpening the
    /// events towards a wrong flow (docs/benchmarks/2026-11-23-locm-ablation.md).
    pub cm_coarse_to_fine: bool,
    /// Events per window used by the CM loss (even stride; 0 = all). Prediction always
    /// covers every event.
    pub max_cm_events: usize,
    /// Seed of the LoRA initialisation.
    pub seed: u64,
    /// Base weights (safetensors, with or without a JSON sidecar); `None` = the shipped
    /// weights.
    pub weights: Option<PathBuf>,
    /// Base width C that bare weights (no sidecar) must have; `None` = read it from
    /// `enc1.weight`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub weights_width: Option<usize>,
    /// Scale of the tanh heads (px per window) for bare weights; `None` = 32.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub weights_max_flow: Option<f64>,
    /// Write dense previews (`.flo`, EXR, colour-wheel PNG) per window.
    pub previews: bool,
    /// Scene windows: `S > 0` (default 0.05 s) = one of `S` seconds centred on each train
    /// frame (clamped to the recording and to the midpoints between frames), where
    /// `deform` binds events to Gaussians (within `assoc`'s δt = 10 ms); 0 = one per
    /// interval between consecutive train frames. The network assumes one flow per
    /// window, which a long interval of fast motion breaks (on `fast` at 4 fps: 92 %
    /// outliers with interval windows, 1 % with 50 ms windows;
    /// docs/benchmarks/2026-11-24-joint-training-sessions-17-19.md).
    pub frame_window: f64,
}

impl Default for FlowSettings {
    fn default() -> Self {
        FlowSettings {
            mode: Mode::Lora,
            epochs: None,
            stop: StopRule::default(),
            lr_start: 1e-3,
            lr_end: 2e-4,
            rank: 16,
            alpha: 16.0,
            lambda_tv: 0.01,
            cm_scales: 3,
            cm_coarse_to_fine: true,
            max_cm_events: 200_000,
            seed: 0,
            weights: None,
            weights_width: None,
            weights_max_flow: None,
            previews: true,
            frame_window: 0.05,
        }
    }
}

impl Settings for FlowSettings {
    /// `Err` with a sentence when a setting is out of range.
    fn validate(&self) -> std::result::Result<(), String> {
        let pos = |v: f64| v.is_finite() && v > 0.0;
        if !pos(self.lr_start) || !pos(self.lr_end) {
            return Err("lr_start and lr_end must be finite and > 0".into());
        }
        if self.rank == 0 || !pos(self.alpha) {
            return Err("rank must be > 0 and alpha > 0".into());
        }
        if !(self.lambda_tv.is_finite() && self.lambda_tv >= 0.0) {
            return Err("lambda_tv must be finite and >= 0".into());
        }
        if self.cm_scales == 0 || self.cm_scales > 8 {
            return Err("cm_scales must be in 1..=8".into());
        }
        if !(self.frame_window.is_finite() && self.frame_window >= 0.0) {
            return Err("frame_window must be finite and >= 0 (seconds)".into());
        }
        if self.epochs.is_some_and(|e| e > 10_000) {
            return Err("epochs must be <= 10000".into());
        }
        self.stop.validate()
    }
}

impl FlowSettings {
    /// The file outside the stage graph these settings make `evflow finetune` read:
    /// the base weights (`weights`, else `$EVFLOW_WEIGHTS`, else the shipped file), when
    /// they exist (a missing file is the stage's error to report). `evflow settings
    /// --check` prints it so that the runner keys the stage on the weights' content.
    pub fn input_files(&self) -> Vec<(&'static str, PathBuf)> {
        crate::net::io::resolve_weights(self.weights.as_deref())
            .ok()
            .filter(|p| p.is_file())
            .map(|p| ("weights", p))
            .into_iter()
            .collect()
    }

    /// Settings for base weights without a sidecar.
    pub fn bare_weights(&self) -> BareWeights {
        BareWeights {
            base: self.weights_width,
            max_flow: self.weights_max_flow,
        }
    }

    /// Fixed epochs when set, else the stopping rule.
    pub fn budget(&self) -> Budget {
        match self.epochs {
            Some(e) => Budget::Epochs(e),
            None => Budget::Rule(self.stop.clone()),
        }
    }

    /// Whether this budget trains at all (`epochs = 0` does not).
    pub fn trains(&self) -> bool {
        self.mode != Mode::None && self.epochs != Some(0)
    }

    pub(crate) fn cm_config(&self) -> crate::cm::CmConfig {
        crate::cm::CmConfig {
            scales: self.cm_scales,
            lambda_tv: self.lambda_tv,
            first_level: 0,
        }
    }
}
