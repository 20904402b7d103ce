//! `evaluate --scene DIR [--model DIR] [--flows DIR] --out DIR`: score a model's renders
//! (thin CLI over [`evaluate::stage`]).

use clap::{Parser, Subcommand};
use evaluate::settings::EvalSettings;
use evaluate::stage::{self, Inputs};
use stagekit::{SettingsArgs, exit_on_error, settings};
use std::path::PathBuf;
use std::process::ExitCode;

/// Score a model's renders against the scene's held-out test frames and novel views
/// (PSNR, SSIM, LPIPS; on the moving objects' and the co-visible pixels too), with the
/// 2D baselines (nearest frame, linear blend, two-sided event pseudo image) and the flow
/// error against ground truth. `degs eval RUN` runs it over a run's outputs.
#[derive(Parser)]
#[command(name = "evaluate", version)]
struct Cli {
    #[command(subcommand)]
    verb: Option<Verb>,
    #[command(flatten)]
    args: Args,
}

#[derive(Subcommand)]
enum Verb {
    /// The settings: `--defaults` prints them as TOML, `--check FILE` checks a file.
    Settings(SettingsArgs),
}

#[derive(clap::Args)]
struct Args {
    /// Scene directory (test frames, novel views, ground truth).
    #[arg(long, required = false)]
    scene: Option<PathBuf>,
    /// A render stage's output (`renders/`, `renders/novel/`, `report.json`).
    #[arg(long)]
    model: Option<PathBuf>,
    /// The flow stage's output (`flow/*.evflow`, `report.json`).
    #[arg(long)]
    flows: Option<PathBuf>,
    /// Output directory: metrics.json, novel_sheet.png, settings.toml.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Settings file (TOML: `lpips = "fetch" | "cached" | "off"`).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Replace an earlier output of `evaluate` at OUT.
    #[arg(long)]
    force: bool,
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    if let Some(Verb::Settings(a)) = &cli.verb {
        return Ok(stagekit::verb::run::<EvalSettings>(
            a,
            stagekit::verb::no_files,
        )?);
    }
    let a = cli.args;
    let (Some(scene), Some(out)) = (a.scene, a.out) else {
        anyhow::bail!("--scene DIR and --out DIR are needed (see --help)");
    };
    let s = settings::resolve::<EvalSettings>(a.config.as_deref(), |_| {})?;
    let inputs = Inputs {
        scene: &scene,
        model: a.model.as_deref(),
        flows: a.flows.as_deref(),
    };
    let m = stage::run(inputs, &s, &out, a.force)?;
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
    exit_on_error("evaluate", || run(Cli::parse()))
}
