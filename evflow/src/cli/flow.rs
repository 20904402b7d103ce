//! `evflow finetune`, `predict` and `eval`: the pipeline's `evflow` stage
//! ([`crate::stage`]) from the command line, with a progress bar on a terminal.

use super::args::{CommonArgs, InputArgs};
use crate::finetune::{FlowSettings, Mode};
use crate::stage::{Event, Input};
use clap::Args;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub struct FinetuneArgs {
    #[command(flatten)]
    pub input: InputArgs,
    #[command(flatten)]
    pub common: CommonArgs,
    /// What to train: lora (adapters r=16, default), full (all weights), none.
    #[arg(long)]
    pub mode: Option<Mode>,
    /// Passes over the windows [default 3].
    #[arg(long)]
    pub epochs: Option<usize>,
    /// Adam learning rate at the first step [default 5e-4].
    #[arg(long)]
    pub lr_start: Option<f64>,
    /// Learning rate at the last step, exponential decay in between [default 1e-4].
    #[arg(long)]
    pub lr_end: Option<f64>,
    /// LoRA rank [default 16].
    #[arg(long)]
    pub rank: Option<usize>,
    /// Seed of the LoRA initialisation [default 0].
    #[arg(long)]
    pub seed: Option<u64>,
}

impl FinetuneArgs {
    /// Fine-tune, then predict into `--out`.
    pub fn run(&self) -> anyhow::Result<()> {
        let mut s = self.common.settings()?;
        if let Some(v) = self.mode {
            s.mode = v;
        }
        if let Some(v) = self.epochs {
            s.epochs = v;
        }
        if let Some(v) = self.lr_start {
            s.lr_start = v;
        }
        if let Some(v) = self.lr_end {
            s.lr_end = v;
        }
        if let Some(v) = self.rank {
            s.rank = v;
        }
        if let Some(v) = self.seed {
            s.seed = v;
        }
        run_stage(&self.input.input()?, &self.common.out, &s, true, None)
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
        let mut s = self.common.settings()?;
        s.mode = Mode::None;
        run_stage(
            &self.input.input()?,
            &self.common.out,
            &s,
            false,
            self.adapter.as_deref(),
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
        let e =
            crate::stage::eval_flows(&self.input.input()?, &self.flows, self.gt_flow.as_deref())?;
        let text = serde_json::to_string_pretty(&e)?;
        if let Some(p) = &self.out {
            scene::atomic::write_bytes_atomic(p, text.as_bytes())?;
        }
        println!("{text}");
        Ok(())
    }
}

/// Run the stage with a progress bar on a terminal, plain lines otherwise.
fn run_stage(
    input: &Input,
    out: &Path,
    s: &FlowSettings,
    train: bool,
    adapter: Option<&Path>,
) -> anyhow::Result<()> {
    let terminal = std::io::stderr().is_terminal();
    let bar = indicatif::ProgressBar::new(0);
    if !terminal {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    bar.set_style(
        indicatif::ProgressStyle::with_template("{prefix:>9} [{bar:30}] {pos}/{len} {msg}")
            .expect("valid template")
            .progress_chars("=> "),
    );
    let report = crate::stage::run(input, out, s, train, adapter, |e| match e {
        Event::Phase(p) => {
            bar.set_prefix(p.to_string());
            bar.set_position(0);
            if !terminal {
                eprintln!("evflow: {p}");
            }
        }
        Event::Step(st) => {
            bar.set_length((st.epochs * st.steps) as u64);
            bar.set_position((st.epoch * st.steps + st.step + 1) as u64);
            bar.set_message(format!("epoch {} loss {:.4}", st.epoch + 1, st.loss));
            if !terminal {
                eprintln!(
                    "evflow: epoch {}/{} window {} ({}/{}) loss {:.5} lr {:.2e}",
                    st.epoch + 1,
                    st.epochs,
                    st.window,
                    st.step + 1,
                    st.steps,
                    st.loss,
                    st.lr
                );
            }
        }
        Event::Predicted(d, t) => {
            bar.set_length(t as u64);
            bar.set_position(d as u64);
            if !terminal {
                eprintln!("evflow: predicted window {d}/{t}");
            }
        }
        Event::Warning(w) => bar.suspend(|| eprintln!("evflow: warning: {w}")),
    })?;
    bar.finish_and_clear();
    let ft = &report.finetune;
    eprintln!(
        "evflow: {} windows, {} events, CM loss {:.4} -> {:.4}, warp gain {:.3}{}, {:.1} s -> {}",
        report.windows,
        report.events,
        ft.cm_loss_before,
        ft.cm_loss_after,
        report.warp_gain,
        report
            .flow_epe_px_s
            .map_or(String::new(), |e| format!(", EPE {e:.3} px/s")),
        report.wall_s,
        out.display()
    );
    Ok(())
}
