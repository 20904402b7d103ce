//! `assoc --scene DIR --model DIR --out DIR`: event–Gaussian bindings at every train
//! frame (thin CLI over [`assoc::stage`]).

use std::io::IsTerminal;
use std::path::PathBuf;

use clap::Parser;

use assoc::AssocSettings;

/// Tie events to the Gaussians that caused them: each event near a train-frame time is
/// lifted to 3D through the warm-up's depth map, and every Gaussian binds to its k
/// nearest lifted events within a radius (inverse-distance weights). Writes
/// OUT/assoc.bin, OUT/report.json, OUT/settings.toml and OUT/preview/NNNN.png.
#[derive(Parser, Debug)]
#[command(name = "assoc", version)]
struct Cli {
    /// Scene directory (transforms_train.json with an events entry).
    #[arg(long)]
    scene: PathBuf,
    /// Warm-up model directory written by `gaussians train` (point_cloud.ply, field,
    /// depth/NNNN.exr).
    #[arg(long)]
    model: PathBuf,
    /// Output directory (appears complete or not at all).
    #[arg(long)]
    out: PathBuf,
    /// Settings file (TOML with the keys below); flags override it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Half-width of the event window around each frame time, seconds [default 0.01].
    #[arg(long)]
    delta_t: Option<f64>,
    /// Events each Gaussian binds to [default 3].
    #[arg(long)]
    k: Option<usize>,
    /// Search radius in pixels at the Gaussian's depth [default 2].
    #[arg(long)]
    radius_px: Option<f64>,
    /// Events on pixels with rendered alpha below this are dropped [default 0.5].
    #[arg(long)]
    min_alpha: Option<f32>,
}

fn settings(cli: &Cli) -> anyhow::Result<AssocSettings> {
    let mut s = match &cli.config {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| anyhow::anyhow!("{}: cannot read: {e}", path.display()))?;
            toml::from_str::<AssocSettings>(&text)
                .map_err(|e| anyhow::anyhow!("{}: {}", path.display(), e.message()))?
        }
        None => AssocSettings::default(),
    };
    if let Some(v) = cli.delta_t {
        s.delta_t = v;
    }
    if let Some(v) = cli.k {
        s.k = v;
    }
    if let Some(v) = cli.radius_px {
        s.radius_px = v;
    }
    if let Some(v) = cli.min_alpha {
        s.min_alpha = v;
    }
    s.validate().map_err(|e| anyhow::anyhow!("settings: {e}"))?;
    Ok(s)
}

fn main() {
    let cli = Cli::parse();
    let result = settings(&cli).and_then(|s| {
        let terminal = std::io::stderr().is_terminal();
        let bar = indicatif::ProgressBar::new(0);
        if !terminal {
            bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
        }
        let report = assoc::stage::run(&cli.scene, &cli.model, &cli.out, &s, |done, total| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
            if !terminal {
                eprintln!("assoc: frame {done}/{total}");
            }
        })?;
        bar.finish_and_clear();
        eprintln!(
            "assoc: {} frames, {:.0}% of {} Gaussians bound on average, {:.2} s -> {}",
            report.frames.len(),
            100.0 * report.bound_fraction_mean,
            report.gaussians,
            report.wall_s,
            cli.out.display()
        );
        Ok(())
    });
    if let Err(e) = result {
        // `{e}`, not `{e:#}`: scene errors already print their source after the file
        // name, and the alternate form would repeat it ("…: No such file …: No such file …").
        eprintln!("assoc: error: {e}");
        std::process::exit(1);
    }
}
