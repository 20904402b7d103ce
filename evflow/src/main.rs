//! `evflow`: per-event optical flow from events. This file only parses the command line
//! and dispatches; the commands live in [`evflow::cli`].

use clap::{Parser, Subcommand};
use evflow::cli::flow::{EvalArgs, FinetuneArgs, PredictArgs};
use evflow::cli::pretrain::PretrainArgs;
use evflow::cli::simulate::SimulateArgs;
use std::process::ExitCode;

/// Event-based optical flow for degs: EV-FlowNet adapted to one recording by LoCM
/// (LoRA + contrast maximisation). Outputs per-event flow files (`flow/NNNN.evflow`,
/// px/s) that `assoc` and `deform` read, dense previews and report.json.
#[derive(Parser, Debug)]
#[command(name = "evflow", version, after_help = evflow::net::io::TENSOR_NAMES_HELP)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Simulate events from a directory of frames (images sorted by name +
    /// timestamps.txt, one time in seconds per line) and write them as .evs.
    Simulate(SimulateArgs),
    /// LoCM: fine-tune the pretrained flow network on the recording with the
    /// contrast-maximisation loss (no ground truth), then predict the flow of every
    /// event. Writes OUT/adapter.safetensors (lora) or OUT/weights.safetensors (full),
    /// OUT/flow/NNNN.evflow, OUT/previews/, OUT/settings.toml, OUT/report.json.
    /// This is the pipeline's `evflow` stage.
    Finetune(FinetuneArgs),
    /// Predict per-event flow with the pretrained network (plus an optional adapter from
    /// `evflow finetune`), no training. Same outputs as finetune, without the adapter.
    Predict(PredictArgs),
    /// Score existing flow files (FLOWS/flow/NNNN.evflow): end-point error and outliers
    /// (> 3 px) against the scene's ground truth where it has one, flow-warp gain (IWE
    /// variance with the flow ÷ without) always. Prints JSON; writes it to --out FILE.
    Eval(EvalArgs),
    /// Pretrain the flow network on synthetic scenes with ground-truth flow (supervised
    /// and/or CM loss). Writes OUT/weights.safetensors (+ .json sidecar), report.json
    /// (loss curve, held-out EPE) and settings.toml. The shipped default weights were made
    /// with `evflow pretrain --config evflow/weights/pretrain_c16.toml --out DIR`.
    Pretrain(PretrainArgs),
    /// The settings of `evflow finetune` (the pipeline's stage): `--defaults` prints
    /// them as TOML, `--check FILE` checks a settings file and prints the base weights
    /// it makes the stage read. The runner learns the settings this way.
    Settings(stagekit::SettingsArgs),
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.cmd {
        Cmd::Simulate(a) => a.run(),
        Cmd::Finetune(a) => a.run(),
        Cmd::Predict(a) => a.run(),
        Cmd::Eval(a) => a.run(),
        Cmd::Pretrain(a) => a.run(),
        Cmd::Settings(a) => {
            return Ok(stagekit::verb::run::<evflow::settings::FlowSettings>(
                &a,
                evflow::settings::FlowSettings::input_files,
            )?);
        }
    }?;
    Ok(ExitCode::SUCCESS)
}

fn main() -> ExitCode {
    let cli: Cli = stagekit::parse_with(evflow::cli::show_defaults);
    stagekit::exit_on_error("evflow", || run(cli))
}
