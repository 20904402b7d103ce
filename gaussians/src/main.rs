//! `gaussians`: the RGB warm-up of a dynamic 3DGS (`train`) and rendering of a saved
//! model (`render`). Logic lives in [`gaussians::stage`].

use clap::{Parser, Subcommand};
use gaussians::stage::{self, Progress, Split, TrainArgs};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "gaussians", version, about)]
struct Cli {
    #[command(subcommand)]
    verb: Verb,
}

#[derive(Subcommand)]
enum Verb {
    /// Train canonical Gaussians + deformation field on a scene's RGB frames (the DEGS
    /// warm-up; with more iterations, the RGB-only baseline). Writes point_cloud.ply,
    /// dynamic.safetensors, model.json, field.safetensors, depth/NNNN.exr (train
    /// frames), renders/NNNN.png (test frames) and report.json (test PSNR/SSIM, time
    /// per phase). Ctrl-C stops at the next iteration and still writes a usable model.
    Train(TrainArgs),
    /// Render a saved model at the frames of a scene split, with PSNR/SSIM.
    Render {
        /// Model directory written by `gaussians train`
        #[arg(long)]
        model: PathBuf,
        /// Scene directory whose cameras, times and images are used
        #[arg(long)]
        scene: PathBuf,
        /// Output directory: renders/NNNN.png, depth/NNNN.exr, report.json
        #[arg(long)]
        out: PathBuf,
        /// Which frames of the scene to render
        #[arg(long, value_enum, default_value_t = Split::Test)]
        split: Split,
    },
    /// Write an RGB-only synthetic scene (no events), for tests and benchmarks.
    #[command(hide = true)]
    SynthRgb {
        /// Preset: static, rigid, nonrigid, fast
        #[arg(long, default_value = "static")]
        preset: String,
        /// Output scene directory
        #[arg(long)]
        out: PathBuf,
        /// Image width and height
        #[arg(long)]
        size: Option<u32>,
    },
}

fn main() -> ExitCode {
    match Cli::parse().verb {
        Verb::Train(args) => {
            let total = match stage::resolve_settings(&args) {
                Ok(s) => s.iterations,
                Err(e) => return fail(e),
            };
            let stop = stage::sigint_flag();
            let mut progress = Progress::new(total);
            let result = stage::train(&args, stop, |s| progress.step(s));
            progress.finish();
            match result {
                Ok(o) => {
                    let r = &o.report;
                    eprintln!(
                        "{}: {} iterations, {} Gaussians, test PSNR {:.2} dB, SSIM {:.4}{}",
                        o.out.display(),
                        r.iterations,
                        r.gaussians,
                        r.test.psnr_mean,
                        r.test.ssim_mean,
                        if r.interrupted { " (interrupted)" } else { "" }
                    );
                    if r.interrupted {
                        ExitCode::from(130)
                    } else {
                        ExitCode::SUCCESS
                    }
                }
                Err(e) => fail(e),
            }
        }
        Verb::Render {
            model,
            scene,
            out,
            split,
        } => match stage::render(&model, &scene, &out, split) {
            Ok(r) => {
                eprintln!(
                    "{}: {} frames, PSNR {:.2} dB, SSIM {:.4}",
                    out.display(),
                    r.evaluation.frames,
                    r.evaluation.psnr_mean,
                    r.evaluation.ssim_mean
                );
                ExitCode::SUCCESS
            }
            Err(e) => fail(e),
        },
        Verb::SynthRgb { preset, out, size } => {
            let Some(mut cfg) = synth::SynthConfig::preset(&preset) else {
                return fail(format!("unknown preset {preset}"));
            };
            if let Some(n) = size {
                (cfg.width, cfg.height) = (n, n);
            }
            match synth::write_rgb_synthetic_scene(&cfg, &out) {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => fail(e),
            }
        }
    }
}

fn fail(e: impl std::fmt::Display) -> ExitCode {
    eprintln!("error: {e}");
    ExitCode::from(1)
}
