//! `gaussians`: the RGB warm-up of a dynamic 3DGS (`train`) and rendering of a saved
//! model (`render`). Logic lives in [`gaussians::stage`].

use clap::{Parser, Subcommand};
use gaussians::progress::TrainProgress;
use gaussians::stage::{self, Split, TrainArgs};
use gaussians::train::TrainSettings;
use stagekit::{exit_on_error, parse_with, show_defaults, sigint_flag};
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
    /// frames), renders/NNNN.png (test frames), renders/novel/NNNN.png (novel views, if
    /// the scene has them) and report.json (test and novel PSNR/SSIM, time per phase). Ctrl-C stops at the next iteration and still writes a usable model.
    Train(TrainArgs),
    /// The settings of `gaussians train`: `--defaults` prints them as TOML, `--check
    /// FILE` checks a settings file. The runner learns the settings this way.
    Settings(stagekit::SettingsArgs),
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
        /// Replace an earlier output of `gaussians render` at OUT
        #[arg(long)]
        force: bool,
    },
    /// Export a saved model as a sequence of standard 3DGS PLY files, the Gaussians
    /// deformed to each time in world coordinates: OUT/frame_0001.ply … (SuperSplat plays
    /// such a sequence), OUT/sequence.zip (the same files; brush plays it), times.json and
    /// report.json. Times: every train and test frame's, or --fps N over the recording.
    Export(gaussians::export::ExportArgs),
    /// Render a saved model along a path (recorded, orbit or a cameras FILE) over the
    /// recording: OUT/frames/NNNN.png, preview.gif, preview.mp4 (with ffmpeg on the
    /// PATH), cameras.json (a manifest usable as --path FILE), report.json.
    Video(gaussians::video::VideoArgs),
    /// Write an RGB-only synthetic scene (no events), for tests and benchmarks.
    #[command(hide = true)]
    SynthRgb {
        /// Preset: static, rigid, nonrigid, fast, moderate
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
    let cli: Cli = parse_with(|c| {
        c.mut_subcommand("train", |t| {
            show_defaults::<TrainSettings>(t, stage::SETTING_FLAGS)
        })
    });
    exit_on_error("gaussians", || run(cli.verb))
}

fn run(verb: Verb) -> scene::Result<ExitCode> {
    match verb {
        Verb::Settings(a) => stagekit::verb::run::<TrainSettings>(&a, stagekit::verb::no_files),
        Verb::Train(args) => {
            let (iterations, schedule) = stage::work_schedule(&args)?;
            let progress = TrainProgress::new(iterations, schedule);
            let result = stage::train(&args, sigint_flag(), |s| progress.step(s));
            progress.finish();
            let o = result?;
            let r = &o.report;
            let novel = r
                .novel
                .as_ref()
                .map_or(String::new(), |n| format!(", novel views {}", n.figures()));
            let test = if r.test.frames == 0 {
                "no test frames to score".to_string()
            } else {
                let note = r.test.lpips_note.as_ref();
                let note = note.map_or(String::new(), |n| format!(" ({n})"));
                format!("test {}{note}", r.test.figures())
            };
            eprintln!(
                "{}: {} iterations, {} Gaussians, {test}{novel}{}",
                o.out.display(),
                r.iterations,
                r.gaussians,
                if r.interrupted { " (interrupted)" } else { "" }
            );
            Ok(if r.interrupted {
                ExitCode::from(130)
            } else {
                ExitCode::SUCCESS
            })
        }
        Verb::Render {
            model,
            scene,
            out,
            split,
            force,
        } => {
            let r = stage::render(&model, &scene, &out, split, force)?;
            eprintln!(
                "{}: {} frames, {}",
                out.display(),
                r.evaluation.frames,
                r.evaluation.figures()
            );
            Ok(ExitCode::SUCCESS)
        }
        Verb::Export(args) => {
            args.run()?;
            Ok(ExitCode::SUCCESS)
        }
        Verb::Video(args) => {
            args.run()?;
            Ok(ExitCode::SUCCESS)
        }
        Verb::SynthRgb { preset, out, size } => {
            let mut cfg = synth::SynthConfig::preset(&preset)
                .ok_or_else(|| scene::Error::Other(format!("unknown preset {preset}")))?;
            if let Some(n) = size {
                (cfg.width, cfg.height) = (n, n);
            }
            synth::write_rgb_synthetic_scene(&cfg, &out)?;
            Ok(ExitCode::SUCCESS)
        }
    }
}
