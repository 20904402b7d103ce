//! `evaluate --scene DIR [--model DIR] [--flows DIR] --out DIR`: score a model's renders
//! (thin CLI over [`evaluate::stage`]).

use clap::Parser;
use evaluate::settings::EvalSettings;
use evaluate::stage::{self, Inputs};
use stagekit::{StageArgs, exit_on_error, settings};
use std::path::PathBuf;
use std::process::ExitCode;

/// Score a model's renders against the scene's held-out test frames and novel views
/// (PSNR, SSIM, LPIPS; on the moving objects' and the co-visible pixels too), with the
/// 2D baselines (nearest frame, linear blend, two-sided event pseudo image) and the flow
/// error against ground truth. Writes OUT/metrics.json, OUT/novel_sheet.png and
/// OUT/settings.toml; `degs eval RUN` runs it over a run's outputs.
///
/// `evaluate settings --defaults` prints the settings' defaults as TOML; `evaluate
/// settings --check FILE` checks a settings file (the runner learns the settings this way).
#[derive(Parser)]
#[command(name = "evaluate", version)]
struct Cli {
    #[command(flatten)]
    stage: StageArgs,
    /// A render stage's output (`renders/`, `renders/novel/`, `report.json`).
    #[arg(long)]
    model: Option<PathBuf>,
    /// The flow stage's output (`flow/*.evflow`, `report.json`).
    #[arg(long)]
    flows: Option<PathBuf>,
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    let (scene, out) = (&cli.stage.scene, &cli.stage.output.out);
    let s = settings::resolve::<EvalSettings>(cli.stage.output.config.as_deref(), |_| {})?;
    let inputs = Inputs {
        scene,
        model: cli.model.as_deref(),
        flows: cli.flows.as_deref(),
    };
    let m = stage::run(inputs, &s, out, cli.stage.output.force)?;
    let f = |v: Option<f64>| v.map_or("-".to_string(), |x| format!("{x:.2}"));
    eprintln!(
        "evaluate: {} test frames, PSNR {} dB; {} novel views, PSNR {} dB -> {}",
        m.frames.len(),
        f(m.psnr_mean),
        m.novel_frames.len(),
        f(m.novel_psnr_mean),
        out.display()
    );
    Ok(ExitCode::SUCCESS)
}

fn main() -> ExitCode {
    if let Some(code) =
        stagekit::verb::intercept::<EvalSettings>("evaluate", stagekit::verb::no_files)
    {
        return code;
    }
    exit_on_error("evaluate", || run(Cli::parse()))
}
