//! Arguments shared by `finetune`, `predict` and `eval`, and what they resolve to.

use crate::settings::FlowSettings;
use crate::source::{WindowSpec, parse_sensor, parse_window};
use crate::stage::Input;
use clap::Args;
use std::path::PathBuf;

/// Where the events come from: a scene directory, or a bare event file.
#[derive(Args, Debug)]
pub struct InputArgs {
    /// Scene directory (transforms_train.json with an events entry): one window around
    /// each train frame (`frame_window` seconds wide), or with `frame_window = 0` one
    /// per interval between consecutive train frames.
    #[arg(long, conflicts_with = "events", required_unless_present = "events")]
    pub scene: Option<PathBuf>,
    /// Bare event file (.txt t x y p, .npz, .evs, .aedat4, .raw, .es) instead of a scene.
    #[arg(long)]
    pub events: Option<PathBuf>,
    /// Sensor size WxH of the event file, e.g. 240x180 (files that store it, .evs,
    /// .aedat4, .raw, .es, need none).
    #[arg(long, requires = "events")]
    pub sensor: Option<String>,
    /// Calibration `fx fy cx cy k1 k2 p1 p2 k3` (ECD calib.txt): events are undistorted
    /// and the flow lives on the undistorted grid of the same K.
    #[arg(long, requires = "events")]
    pub calib: Option<PathBuf>,
    /// A window T0,T1 in seconds (repeatable). Default: consecutive windows of
    /// --window-length, else one window over the whole stream.
    #[arg(long = "window", requires = "events")]
    pub windows: Vec<String>,
    /// Length of consecutive windows in seconds.
    #[arg(long, requires = "events")]
    pub window_length: Option<f64>,
}

impl InputArgs {
    /// The stage's input: the scene, or the event file with its sensor and windows.
    pub fn input(&self) -> anyhow::Result<Input> {
        if let Some(dir) = &self.scene {
            return Ok(Input::Scene(dir.clone()));
        }
        let path = self
            .events
            .clone()
            .ok_or_else(|| anyhow::anyhow!("give --scene or --events"))?;
        let sensor = self
            .sensor
            .as_deref()
            .map(parse_sensor)
            .transpose()
            .map_err(anyhow::Error::msg)?;
        let windows = self
            .windows
            .iter()
            .map(|w| parse_window(w))
            .collect::<Result<Vec<_>, _>>()
            .map_err(anyhow::Error::msg)?;
        Ok(Input::Events {
            path,
            sensor,
            calib: self.calib.clone(),
            spec: WindowSpec {
                windows,
                window_length: self.window_length,
            },
        })
    }
}

#[derive(Args, Debug)]
pub struct CommonArgs {
    #[command(flatten)]
    pub output: stagekit::OutputArgs,
    /// Base network weights: safetensors with a .json sidecar, or bare (tensor names in
    /// `evflow --help`). Default: $EVFLOW_WEIGHTS, else the weights shipped in
    /// evflow/weights/.
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Base width C of bare --weights (no sidecar); checked against enc1.weight, which
    /// gives it when omitted.
    #[arg(long, requires = "weights")]
    pub width: Option<usize>,
    /// Largest flow of bare --weights' tanh heads, px per window.
    #[arg(long, requires = "weights")]
    pub max_flow: Option<f64>,
    /// Skip the dense previews (.flo, EXR, PNG).
    #[arg(long)]
    pub no_previews: bool,
}

impl CommonArgs {
    /// The settings of `--config` (or the defaults) with these flags and then `more`
    /// (the command's own flags) applied, validated; errors name the file.
    pub fn settings(&self, more: impl FnOnce(&mut FlowSettings)) -> scene::Result<FlowSettings> {
        stagekit::settings::resolve(self.output.config.as_deref(), |s: &mut FlowSettings| {
            if let Some(w) = &self.weights {
                s.weights = Some(w.clone());
            }
            if self.width.is_some() {
                s.weights_width = self.width;
            }
            if self.max_flow.is_some() {
                s.weights_max_flow = self.max_flow;
            }
            if self.no_previews {
                s.previews = false;
            }
            more(s);
        })
    }
}
