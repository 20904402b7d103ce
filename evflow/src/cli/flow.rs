//! `evflow finetune`, `predict` and `eval`: the pipeline's `evflow` stage
//! ([`crate::stage`]) from the command line, with a progress bar on a terminal.

use super::args::{CommonArgs, InputArgs};
use crate::settings::{FlowSettings, Mode};
use crate::stage::{Event, Input};
use clap::Args;
use stagekit::Progress;
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub struct FinetuneArgs {
    #[command(flatten)]
    pub input: InputArgs,
    #[command(flatten)]
    pub common: CommonArgs,
    /// What to train: lora (LoRA adapters of --rank), full (all weights), none.
    #[arg(long)]
    pub mode: Option<Mode>,
    /// A fixed number of passes over the windows (unset: until the CM loss stops
    /// improving, the `stop` settings).
    #[arg(long)]
    pub epochs: Option<usize>,
    /// Stopping rule: steps that always run.
    #[arg(long)]
    pub min_steps: Option<usize>,
    /// Stopping rule: steps never exceeded.
    #[arg(long)]
    pub max_steps: Option<usize>,
    /// Adam learning rate at the first step.
    #[arg(long)]
    pub lr_start: Option<f64>,
    /// Learning rate at the last step, exponential decay in between.
    #[arg(long)]
    pub lr_end: Option<f64>,
    /// LoRA rank.
    #[arg(long)]
    pub rank: Option<usize>,
    /// Seed of the LoRA initialisation.
    #[arg(long)]
    pub seed: Option<u64>,
}

/// The flags of [`FinetuneArgs`] that override a setting, each with its key in
/// [`FlowSettings`] (their `--help` shows its default: [`stagekit::show_defaults`]).
pub(crate) const FINETUNE_SETTING_FLAGS: &[(&str, &str)] = &[
    ("mode", "mode"),
    ("min_steps", "stop.min_steps"),
    ("max_steps", "stop.max_steps"),
    ("lr_start", "lr_start"),
    ("lr_end", "lr_end"),
    ("rank", "rank"),
    ("seed", "seed"),
];

impl FinetuneArgs {
    /// Fine-tune, then predict into `--out`.
    pub fn run(&self) -> anyhow::Result<()> {
        let s = self.common.settings(|s| {
            s.mode = self.mode.unwrap_or(s.mode);
            s.epochs = self.epochs.or(s.epochs);
            s.stop.min_steps = self.min_steps.unwrap_or(s.stop.min_steps);
            s.stop.max_steps = self.max_steps.unwrap_or(s.stop.max_steps);
            s.lr_start = self.lr_start.unwrap_or(s.lr_start);
            s.lr_end = self.lr_end.unwrap_or(s.lr_end);
            s.rank = self.rank.unwrap_or(s.rank);
            s.seed = self.seed.unwrap_or(s.seed);
        })?;
        run_stage(
            &self.input.input()?,
            &self.common.output.out,
            &s,
            true,
            None,
            self.common.output.force,
        )
    }
}

#[derive(Args, Debug)]
pub struct PredictArgs {
    #[command(flatten)]
    pub input: InputArgs,
    #[command(flatten)]
    pub common: CommonArgs,
    /// LoRA adapter: the output directory of `evflow finetune`, or the
    /// adapter.safetensors in it (with its .json sidecar).
    #[arg(long)]
    pub adapter: Option<PathBuf>,
}

impl PredictArgs {
    /// Predict into `--out` without training.
    pub fn run(&self) -> anyhow::Result<()> {
        let s = self.common.settings(|s| s.mode = Mode::None)?;
        run_stage(
            &self.input.input()?,
            &self.common.output.out,
            &s,
            false,
            self.adapter.as_deref(),
            self.common.output.force,
        )
    }
}

#[derive(Args, Debug)]
pub struct EvalArgs {
    #[command(flatten)]
    pub input: InputArgs,
    /// Directory written by `evflow finetune`/`predict`.
    #[arg(long)]
    pub flows: PathBuf,
    /// Dense ground truth `.npy` (1x2xHxW, px of displacement over the window, e.g.
    /// the ECD slice's flow.npy) for bare event files.
    #[arg(long)]
    pub gt_flow: Option<PathBuf>,
    /// Write the figures to this JSON file too.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

impl EvalArgs {
    /// Score the flow files; print the figures as JSON (and write them to `--out`).
    pub fn run(&self) -> anyhow::Result<()> {
        // The windows the flows were computed over: their run's settings.toml, if any,
        // else the default's.
        let settings = self.flows.join("settings.toml");
        let frame_window = if settings.is_file() {
            let text = std::fs::read_to_string(&settings)?;
            stagekit::settings::parse::<crate::settings::FlowSettings>(&text, &settings)?
                .frame_window
        } else {
            crate::settings::FlowSettings::default().frame_window
        };
        let e = crate::stage::eval_flows(
            &self.input.input()?,
            &self.flows,
            self.gt_flow.as_deref(),
            frame_window,
        )?;
        let text = serde_json::to_string_pretty(&e)?;
        if let Some(p) = &self.out {
            scene::atomic::write_bytes_atomic(p, text.as_bytes())?;
        }
        println!("{text}");
        Ok(())
    }
}

/// Run the stage with a progress display per phase that has steps (fine-tuning,
/// prediction): a bar on a terminal, plain lines otherwise.
fn run_stage(
    input: &Input,
    out: &Path,
    s: &FlowSettings,
    train: bool,
    adapter: Option<&Path>,
    force: bool,
) -> anyhow::Result<()> {
    let mut phase = String::new();
    let mut bar: Option<Progress> = None;
    let report = crate::stage::run(input, out, s, train, adapter, force, |e| match e {
        Event::Phase(p) => {
            if let Some(b) = bar.take() {
                b.finish();
            }
            phase = p.to_string();
        }
        Event::Step(st) => {
            let b = bar.get_or_insert_with(|| Progress::new(&phase, 0));
            b.set_length((st.epochs * st.steps) as u64);
            b.set((st.epoch * st.steps + st.step + 1) as u64, || {
                format!(
                    "epoch {}/{} window {} loss {:.5} lr {:.2e}",
                    st.epoch + 1,
                    st.epochs,
                    st.window,
                    st.loss,
                    st.lr
                )
            });
        }
        Event::Predicted(d, t) => {
            let b = bar.get_or_insert_with(|| Progress::new(&phase, 0));
            b.set_length(t as u64);
            b.set(d as u64, String::new);
        }
        Event::Warning(w) => {
            let line = format!("evflow: warning: {w}");
            match &bar {
                Some(b) => b.println(&line),
                None => eprintln!("{line}"),
            }
        }
    })?;
    if let Some(b) = bar {
        b.finish();
    }
    let ft = &report.finetune;
    let cm = if ft.mode == crate::settings::Mode::None {
        "no fine-tuning".to_string()
    } else {
        format!(
            "CM loss {:.4} -> {:.4}",
            ft.cm_loss_before, ft.cm_loss_after
        )
    };
    eprintln!(
        "evflow: {} windows, {} events, {cm}, warp gain {:.3}{}, {:.1} s -> {}",
        report.windows,
        report.events,
        report.warp_gain,
        report
            .flow_epe_px_s
            .map_or(String::new(), |e| format!(", EPE {e:.3} px/s")),
        report.wall_s,
        out.display()
    );
    Ok(())
}
