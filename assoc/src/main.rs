//! `assoc --scene DIR --model DIR --out DIR`: event–Gaussian bindings at every train
//! frame (thin CLI over [`assoc::stage`]).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;

use assoc::AssocSettings;
use stagekit::{Progress, StageArgs, exit_on_error, parse_with, settings, show_defaults};

/// Tie events to the Gaussians that caused them: each event near a train-frame time is
/// lifted to 3D through the warm-up's depth map, and every Gaussian binds to its k
/// nearest lifted events within a radius (inverse-distance weights). Writes
/// OUT/assoc.bin, OUT/report.json, OUT/settings.toml and OUT/preview/NNNN.png.
///
/// `assoc settings --defaults` prints the settings' defaults as TOML; `assoc settings
/// --check FILE` checks a settings file (the runner learns the settings this way).
#[derive(Parser, Debug)]
#[command(name = "assoc", version)]
struct Cli {
    #[command(flatten)]
    stage: StageArgs,
    /// Warm-up model directory written by `gaussians train` (point_cloud.ply, field,
    /// depth/NNNN.exr).
    #[arg(long)]
    model: PathBuf,
    /// Half-width of the event window around each frame time, seconds.
    #[arg(long)]
    delta_t: Option<f64>,
    /// Events each Gaussian binds to.
    #[arg(long)]
    k: Option<usize>,
    /// Search radius in pixels at the Gaussian's depth.
    #[arg(long)]
    radius_px: Option<f64>,
    /// Events on pixels with rendered alpha below this are dropped.
    #[arg(long)]
    min_alpha: Option<f32>,
}

/// The flags that override a setting, each with its key (their help shows the default).
const SETTING_FLAGS: &[(&str, &str)] = &[
    ("delta_t", "delta_t"),
    ("k", "k"),
    ("radius_px", "radius_px"),
    ("min_alpha", "min_alpha"),
];

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    let s = settings::resolve::<AssocSettings>(cli.stage.output.config.as_deref(), |s| {
        s.delta_t = cli.delta_t.unwrap_or(s.delta_t);
        s.k = cli.k.unwrap_or(s.k);
        s.radius_px = cli.radius_px.unwrap_or(s.radius_px);
        s.min_alpha = cli.min_alpha.unwrap_or(s.min_alpha);
    })?;
    let mut progress = Progress::new("frame", 0);
    let report = assoc::stage::run(
        &cli.stage.scene,
        &cli.model,
        &cli.stage.output.out,
        &s,
        cli.stage.output.force,
        |done, total| {
            progress.set_length(total as u64);
            progress.set(done as u64, String::new);
        },
    )?;
    progress.finish();
    eprintln!(
        "assoc: {} frames, {:.0}% of {} Gaussians bound on average, {:.2} s -> {}",
        report.frames.len(),
        100.0 * report.bound_fraction_mean,
        report.gaussians,
        report.wall_s,
        cli.stage.output.out.display()
    );
    Ok(ExitCode::SUCCESS)
}

fn main() -> ExitCode {
    if let Some(code) =
        stagekit::verb::intercept::<AssocSettings>("assoc", stagekit::verb::no_files)
    {
        return code;
    }
    let cli: Cli = parse_with(|c| show_defaults::<AssocSettings>(c, SETTING_FLAGS));
    exit_on_error("assoc", || run(cli))
}
